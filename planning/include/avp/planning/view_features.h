#pragma once

#include <cstddef>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>
#include <avp/planning/gain_grid.h>
#include <avp/planning/isler_utilities.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

class AvpGainEvaluator;

/// The features of a candidate view that a learned gain reads (docs/planning.md, "A learned
/// gain"). Only what a robot has at run time goes in: the map (through the planning step's gain
/// grid), the arm's candidate poses and motion costs, the fused views, the ROI and the target
/// class. Nothing reads the scene, its generator or the truth.
///
/// A model is trained on one version of this list: its manifest carries kViewFeatureVersion,
/// the names in order and ViewFeatureHash(), and the planner refuses a model whose list differs.
/// Change a feature's definition: bump the version.
inline constexpr int kViewFeatureVersion = 2;

/// The names, in the order of a feature row.
std::span<const std::string_view> ViewFeatureNames();
/// ViewFeatureNames().size().
size_t ViewFeatureCount();
/// FNV-1a (64 bit, 16 hex digits) of "avp-view-features/<version>" and every name, each
/// followed by '\n'.
std::string ViewFeatureHash();

/// How the per-ray statistics are sampled. Fixed for a feature version (a model is trained on
/// them); not planner options.
struct ViewFeatureSampling {
  int ray_stride_px = 40;      ///< 16 x 12 rays on a 640 x 480 camera
  double max_range_m = 1.0;    ///< ray length
  double near_plant_m = 0.05;  ///< "near the seen plant": within this of an occupied voxel
  double core_band_m = 0.10;   ///< "at the plant's core": within this of PlantCoreDistance 0
};

/// Computes feature rows for the candidates of one planning step. Build once per step (it
/// fits the target spheres, builds a proximity field and counts the ROI's voxels), then
/// Compute any number of candidates (in parallel over them; the rows do not depend on the thread
/// count).
class ViewFeatureExtractor {
 public:
  /// `grid` must be built from request.map for request.target_class and request.roi, and
  /// outlive the extractor; so must `request`. Errors: the proximity field's (size limits).
  static Result<ViewFeatureExtractor> Build(const PlanningRequest& request, const GainGrid& grid,
                                            const ViewFeatureSampling& sampling = {});

  /// Row-major rows, candidates.size() x ViewFeatureCount(), one per candidate in order (an
  /// unreachable candidate gets a row too). Every value is finite.
  std::vector<float> Compute(std::span<const ViewCandidate> candidates) const;

 private:
  ViewFeatureExtractor() = default;
  void ComputeRow(const ViewCandidate& c, std::span<float> row) const;

  const PlanningRequest* request_ = nullptr;
  const GainGrid* grid_ = nullptr;
  ViewFeatureSampling sampling_;
  std::shared_ptr<const AvpGainEvaluator> gain_;
  ProximityField proximity_;
  std::vector<TargetSphere> spheres_;
  std::vector<Eigen::Vector3d> dirs_C_;
  std::vector<float> plan_;  ///< the features that are the same for every candidate of the step
};

}  // namespace avp::planning

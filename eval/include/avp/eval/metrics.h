#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/voxel_key.h>
#include <avp/eval/ground_truth.h>
#include <avp/mapping/semantic_map.h>

namespace avp::eval {

/// Voxel precision / recall of a predicted set against the ground truth (docs/evaluation.md).
///
/// Exact (tolerance 0): tp = predicted voxels that are GT voxels, fp = predicted - tp,
/// fn = GT - tp. With a tolerance of t voxels (Chebyshev, t = 1: the 26-neighbourhood) the two
/// sides are counted separately: tp = GT voxels with a predicted voxel within t (recalled),
/// fn = GT - tp, fp = predicted voxels with no GT voxel within t; precision =
/// (predicted - fp) / predicted, recall = tp / GT. With t = 0 both definitions agree.
/// f1 = 2 p r / (p + r); each ratio is 0 when its denominator is 0.
struct VoxelScores {
  size_t tp = 0;
  size_t fp = 0;
  size_t fn = 0;
  double precision = 0.0;
  double recall = 0.0;
  double f1 = 0.0;
  size_t predicted = 0;     ///< distinct predicted voxels
  size_t ground_truth = 0;  ///< GT voxels
};

/// Fruit-level results (docs/evaluation.md).
struct FruitScores {
  /// GT fruits found (see EvalOptions), of `total` fruits in the scene, `observable` of which have
  /// at least one GT voxel.
  size_t found = 0;
  size_t total = 0;
  size_t observable = 0;
  /// found / total (0 when total is 0).
  double found_fraction = 0.0;
  /// Over the found fruits: mean |fitted centre - true centre| and |fitted radius - true mean
  /// radius|, metres; NaN when no fruit is found.
  double mean_center_error_m = std::numeric_limits<double>::quiet_NaN();
  double mean_radius_error_m = std::numeric_limits<double>::quiet_NaN();
  /// Instances of the target class in the map (SemanticMap::Instances()).
  size_t map_instances = 0;
};

struct EvalOptions {
  /// The class whose occupied, labelled voxels are the prediction.
  SemanticClass target = SemanticClass::kFruit;
  /// A GT fruit is found when at least max(found_min_voxels, found_min_fraction x its observable
  /// voxels) of its GT voxels are recalled with the one-voxel tolerance.
  double found_min_fraction = 0.10;
  size_t found_min_voxels = 3;
  /// Region whose coverage (fraction of its voxels the map knows) is reported; empty = skip.
  Box3 roi;

  /// OK, or InvalidArgument naming every bad field and its value.
  Status Validate() const;
};

struct MapMetrics {
  VoxelScores exact;     ///< voxel identity (comparable with the paper)
  VoxelScores tolerant;  ///< one-voxel tolerance
  FruitScores fruits;
  /// Binary entropy (bits) of the confidence of every target-labelled voxel, occupied or not:
  /// sum and mean (0 when there is none).
  double entropy_sum_bits = 0.0;
  double entropy_mean_bits = 0.0;
  size_t labelled_voxels = 0;   ///< target-labelled voxels the entropy is taken over
  size_t predicted_voxels = 0;  ///< target-labelled and occupied
  /// Known voxels / voxels whose centre lies in EvalOptions::roi (0 when the ROI is empty).
  double roi_coverage = 0.0;
  size_t roi_voxels = 0;
  size_t roi_known_voxels = 0;
};

/// One ground-truth fruit's result (docs/evaluation.md, "Per-fruit results"). EvaluateFruits fills
/// the map's fields; the episode runner (experiment::RunEpisodeWithRobot) fills the episode's.
struct FruitResult {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  uint16_t instance_id = 0;
  std::string name;
  Eigen::Vector3d center_W = Eigen::Vector3d::Zero();  ///< true centre, metres
  Eigen::Vector3d radii = Eigen::Vector3d::Zero();     ///< true semi-axes, metres
  double radius_m = 0.0;                               ///< their mean
  /// GroundTruth::best_visible_fraction (how observable it is from the ground truth's reachable
  /// observation views); NaN when the ground truth has none (a file).
  double best_visible_fraction = kNaN;
  size_t observable_voxels = 0;  ///< its GT voxels (GroundTruth::voxels_per_fruit)
  /// Its GT voxels with a predicted voxel in their 26-neighbourhood (FoundFruitIds' count).
  size_t recalled_voxels = 0;
  /// Predicted voxels whose nearest GT voxel (26-neighbourhood) is this fruit's: the points of
  /// its estimate.
  size_t matched_voxels = 0;
  /// FoundFruitIds' rule; FruitScores::found counts these.
  bool found = false;
  /// The map's estimate, for a found fruit with matched voxels (FitSphere of their centres):
  /// centre, radius, whether the least-squares fit held (false: the centroid fallback), and the
  /// errors |estimated centre - true centre| and |estimated radius - true mean radius|, metres,
  /// whose means over the fruits that have them are FruitScores::mean_center_error_m /
  /// mean_radius_error_m. NaN (estimated = false) otherwise.
  bool estimated = false;
  bool sphere_fitted = false;
  Eigen::Vector3d estimated_center_W = Eigen::Vector3d::Constant(kNaN);
  double estimated_radius_m = kNaN;
  double center_error_m = kNaN;
  double radius_error_m = kNaN;

  // ---- The episode's (experiment::RunEpisodeWithRobot; -1 / NaN elsewhere). Views are 0-based
  // fused-view indices (pipeline::StepRecord::view; record.json writes them 1-based).
  /// The first fused view after which the fruit counted as found; -1 when it never did.
  int found_view = -1;
  /// The view from which it stayed found to the end (a map can lose a fruit again: voxels freed
  /// or relabelled by later views); -1 when it is not found at the end. found_view when found
  /// never lapsed.
  int found_since_view = -1;
  /// The largest visible fraction of the fruit over the episode's fused views (its pixels in the
  /// view's simulator labels over segmentation::ExpectedFruitAreaPx, best_visible_fraction's
  /// rule at the episode camera), and the view it came from; NaN / -1 when no fused view had
  /// simulator labels (a live camera) or the episode has no ground truth.
  double episode_visible_fraction = kNaN;
  int episode_best_view = -1;
};

/// The prediction EvaluateMap scores: the occupied voxels labelled `target`, ascending.
std::vector<VoxelKey> PredictedVoxels(const mapping::SemanticMap& map, SemanticClass target);

/// The ids (ascending) of the GT fruits that `predicted` finds by EvalOptions' rule: at least one
/// and at least max(found_min_voxels, found_min_fraction x observable) of the fruit's GT voxels
/// with a predicted voxel in their 26-neighbourhood. FruitScores::found counts them.
std::vector<uint16_t> FoundFruitIds(const std::vector<VoxelKey>& predicted, const GroundTruth& gt,
                                    const EvalOptions& options);

/// Scores a map against a ground truth. Predicted voxels: labelled `options.target` and occupied.
/// @throws avp::Error if the options are invalid or the map's voxel size differs from gt's.
/// With `fruits` not null it receives EvaluateFruits' list from the same evaluation: its found
/// flags are the ones FruitScores counts and its errors the ones it averages.
MapMetrics EvaluateMap(const mapping::SemanticMap& map, const GroundTruth& gt,
                       const EvalOptions& options = {}, std::vector<FruitResult>* fruits = nullptr);

/// Every fruit of gt.fruits (instance-id order) with the map's result for it (FruitResult's map
/// fields; the episode fields are left unset). Empty for a ground truth without fruits (a file
/// read without a scene). @throws avp::Error as EvaluateMap.
std::vector<FruitResult> EvaluateFruits(const mapping::SemanticMap& map, const GroundTruth& gt,
                                        const EvalOptions& options = {});

/// Scores a set of predicted keys (duplicates ignored) on gt's lattice with a Chebyshev tolerance
/// of `tolerance_voxels` (0 = exact, 1 = 26-neighbourhood). O(N (2t + 1)^3) with hashed sets.
/// @throws avp::Error unless 0 <= tolerance_voxels <= 8.
VoxelScores ScoreVoxelSets(const std::vector<VoxelKey>& predicted, const GroundTruth& gt,
                           int tolerance_voxels);

/// An episode's per-fruit results as its views are fused (experiment::RunEpisodeWithRobot feeds it
/// the evaluation it computes after every view): the view that first found each fruit, the view
/// from which it stayed found, and its largest visible fraction over the views.
class FruitTracker {
 public:
  /// After view `view` (0-based, in order) was fused: `now` is EvaluateFruits of the map then
  /// (the same fruits every time), `visible` each fruit's visible fraction in that view (a fruit
  /// missing from it: 0), or nullopt when the view had none (no simulator labels, a failed
  /// capture).
  void AfterView(int view, std::vector<FruitResult> now,
                 const std::optional<std::unordered_map<uint16_t, double>>& visible);

  /// The last evaluation with the episode's fields (found_view, found_since_view,
  /// episode_visible_fraction, episode_best_view); empty before the first view.
  std::vector<FruitResult> Result() const;

 private:
  std::vector<FruitResult> last_;
  std::vector<int> first_found_, found_since_, best_view_;
  std::vector<double> best_visible_;
};

/// A sphere fitted to points.
struct SphereFit {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double radius_m = 0.0;
  /// True for the least-squares fit; false for the centroid fallback (fewer than 10 points or a
  /// degenerate fit), whose radius is the mean distance of the points to their centroid.
  bool fitted = false;
};

/// Algebraic (linear) least-squares sphere fit: minimises sum (|p|^2 - 2 c.p - d)^2 over c and
/// d = r^2 - |c|^2, on points centred on their centroid. Falls back to the centroid with fewer than
/// 10 points or when the fit is degenerate: rank-deficient, r^2 <= 0, not finite, or a radius
/// larger than twice the diagonal of the points' bounding box (a nearly flat patch).
/// @pre points is not empty (throws avp::Error otherwise).
SphereFit FitSphere(const std::vector<Eigen::Vector3d>& points);

}  // namespace avp::eval

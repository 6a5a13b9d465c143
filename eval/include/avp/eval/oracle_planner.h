#pragma once

#include <limits>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include <avp/eval/ground_truth.h>
#include <avp/eval/metrics.h>
#include <avp/planning/candidates.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/view_planner.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scene.h>

namespace avp::eval {

/// The diagnostic planners that know the truth, as upper bounds for the greedy planners. Each
/// reachable candidate is rendered in the true scene and scored with what it would really add:
///
/// - "oracle-nbv" (Objective::kVoxels, avp-nbv's shell candidates): the number of ground-truth
///   fruit-surface voxels the view would see that the map does not yet hold as occupied fruit. It
///   shows how much F1 a planner could reach by choosing better among the same views.
/// - "oracle-detect" (Objective::kDetections, the shells plus the ground truth's reachable
///   observation views, which are aimed at every fruit, hidden or not): the *expected* result of
///   the view under the oracle segmenter's detection model. Each fruit the view shows counts with
///   its detection probability p_det(v) at its visible fraction v (segmentation::OracleOptions),
///   worth kFruitValue voxels while it is not yet found (EvalOptions' rule) plus its new voxels.
///   It bounds fruits found: what the best greedy choice reaches when it knows where every fruit
///   is and how likely the detector is to see it.
///
/// No robot has this knowledge (docs/planning.md, docs/experiments.md).
struct OracleNbvOptions {
  enum class Objective { kVoxels, kDetections };
  Objective objective = Objective::kVoxels;
  planning::ShellCandidateOptions candidates;
  /// Also every reachable observation view of the ground truth (GroundTruth::views) not near a
  /// fused view, IK-checked from the current joints.
  bool observation_view_candidates = false;
  /// The detector model of kDetections: p_det(v) and min_pixels (the segmenter's options).
  segmentation::OracleOptions detector;
  /// The "found" rule of kDetections (FoundFruitIds with these options' found_min_voxels and
  /// found_min_fraction; the target class is the request's).
  EvalOptions found_rule;
  /// The candidates are rendered at this fraction of the camera's resolution (field of view
  /// kept): 0.25 renders 160 x 120 for a 640 x 480 camera.
  double render_scale = 0.25;
  /// Motion cost weight, as avp-nbv's: U = G / max G - w_motion |dq| / max |dq|.
  double w_motion = 0.1;
};

/// The configurable fields of OracleNbvOptions: candidates.*, render_scale and w_motion (the
/// objective and the observation-view candidates come with the planner's name, the detector
/// model with the run's segmenter: PlannerTruth::detector).
const OptionTable<OracleNbvOptions>& OracleNbvOptionTable();

/// What the oracle planners know (planning::PlannerContext::truth): the true scene, its ground
/// truth, and the detector model of the run's segmenter (the oracle segmenter's options; the
/// default noise model for any other segmenter, whose misses it cannot know). The scene and the
/// ground truth must outlive the planners built with it.
struct PlannerTruth final : planning::PlannerTruth {
  PlannerTruth(const sim::Scene& s, const GroundTruth& g, segmentation::OracleOptions d)
      : scene(s), gt(g), detector(std::move(d)) {}
  const sim::Scene& scene;
  const GroundTruth& gt;
  segmentation::OracleOptions detector;
};

/// Registers the diagnostic planners that need the ground truth (needs_ground_truth = true):
/// "oracle-nbv" and "oracle-detect". @throws avp::Error if a name is already taken.
void RegisterOraclePlanners(planning::PlannerRegistry& registry);

/// kDetections: a fruit not yet found is worth this many voxels (more than any fruit has), so
/// the expected number of newly found fruits ranks views first and new voxels break ties.
inline constexpr double kFruitValue = 1000.0;

class OracleNbvPlanner final : public planning::ViewPlanner {
 public:
  /// `scene` and `gt` must outlive the planner.
  OracleNbvPlanner(const sim::Scene& scene, const GroundTruth& gt,
                   const OracleNbvOptions& options = {});
  ~OracleNbvPlanner() override;
  std::string_view name() const override {
    return options_.objective == OracleNbvOptions::Objective::kVoxels ? "oracle-nbv"
                                                                      : "oracle-detect";
  }
  planning::PlanResult Plan(const planning::PlanningRequest& request, Rng& rng) override;

  /// The true gain of a camera at X_WC given `map`: ground-truth voxels it sees (rendered at
  /// render_scale) that `map` does not hold as occupied `target` voxels.
  size_t TrueGain(const mapping::SemanticMap& map, SemanticClass target, const CameraIntrinsics& K,
                  const RigidTransform& X_WC) const;

  /// kDetections' gain of a camera at X_WC: sum over the fruits it shows (at least
  /// detector.min_pixels at full resolution) of p_det(v) x (new voxels + kFruitValue if the fruit
  /// is not found in `map` and the view shows new voxels of it); `found` is FoundFruits(map).
  double ExpectedDetectionGain(const mapping::SemanticMap& map, SemanticClass target,
                               const CameraIntrinsics& K, const RigidTransform& X_WC,
                               const std::unordered_set<uint16_t>& found) const;

  /// The fruits `map` has found: FoundFruitIds of its PredictedVoxels under found_rule.
  std::unordered_set<uint16_t> FoundFruits(const mapping::SemanticMap& map,
                                           SemanticClass target) const;

 private:
  /// Ground-truth voxels the view (rendered with Ks) sees that `map` does not hold as occupied
  /// `target`; with `pixels`, also counts the render's pixels with a return per instance id.
  std::unordered_set<VoxelKey, VoxelKeyHash> NewVoxels(
      const mapping::SemanticMap& map, SemanticClass target, const CameraIntrinsics& Ks,
      const RigidTransform& X_WC, std::unordered_map<uint16_t, size_t>* pixels) const;

  const GroundTruth& gt_;
  OracleNbvOptions options_;
  std::unique_ptr<sim::RgbdRenderer> renderer_;
};

/// How well a planner ranked its candidates at one plan step, measured with the truth
/// (RegretProbe).
/// One ranked candidate of a plan with what the truth says of it (RegretProbe).
struct ScoredCandidate {
  Eigen::Vector3d eye = Eigen::Vector3d::Zero();       ///< camera position, world frame
  Eigen::Vector3d forward = Eigen::Vector3d::UnitZ();  ///< optical axis, world frame
  double gain = 0.0, utility = 0.0, cost = 0.0;        ///< the planner's
  double true_gain = 0.0;                              ///< OracleNbvPlanner::TrueGain
  std::string source;
  std::vector<std::pair<std::string, double>> gain_terms;  ///< ViewCandidate::gain_terms
  /// With RegretProbe's record_features: the candidate's row of planning::ViewFeatureNames().
  std::vector<float> features;
};

struct StepRegret {
  int step = 0;           ///< plan call, from 0
  size_t candidates = 0;  ///< the ranked (reachable) candidates scored
  /// OracleNbvPlanner::TrueGain (new ground-truth fruit voxels) of the chosen candidate (ranked
  /// first) and the largest over the candidates.
  double chosen_true_gain = 0.0;
  double best_true_gain = 0.0;
  /// 1 − chosen / best: the share of the best candidate's new voxels the choice forgoes (0 when
  /// the best sees nothing new).
  double regret = 0.0;
  /// 1 + the candidates with a larger true gain than the chosen one (1: it was the truly best).
  size_t chosen_true_rank = 1;
  /// Spearman correlation of the planner's gain with the true gain over the candidates; NaN when
  /// undefined (fewer than 2 candidates, or either gain constant).
  double rank_correlation = std::numeric_limits<double>::quiet_NaN();
  /// Every ranked candidate, in rank order (the chosen one first): the planner's numbers beside
  /// the true gain, the data to calibrate a gain on (docs/planning.md, "Regret of any planner").
  std::vector<ScoredCandidate> scored;
  /// With RegretProbe's record_features: why this step has no feature rows (empty: it has them).
  std::string features_error;
  /// With feature rows: their columns (planning::ViewFeatureNames, kViewFeatureVersion,
  /// ViewFeatureHash), so that a data set names what it holds.
  std::vector<std::string> feature_names;
  int feature_version = 0;
  std::string feature_hash;
};

/// Wraps a planner and, after each of its plans, renders every ranked candidate in the true scene
/// (OracleNbvPlanner::TrueGain) to measure the regret of its choice and how its gain ranks the
/// candidates (`avp run --oracle-regret`). It returns the wrapped planner's result unchanged, so
/// the episode is the same as without it; only the plan times include the probe's rendering.
class RegretProbe final : public planning::ViewPlanner {
 public:
  /// `inner` and `oracle` must outlive the probe. With `record_features`, each scored candidate
  /// also gets its feature row (planning::ViewFeatureExtractor on a gain grid with the default
  /// options): the data a learned gain is trained on.
  RegretProbe(planning::ViewPlanner& inner, const OracleNbvPlanner& oracle,
              bool record_features = false)
      : inner_(inner), oracle_(oracle), record_features_(record_features) {}
  std::string_view name() const override { return inner_.name(); }
  planning::PlanResult Plan(const planning::PlanningRequest& request, Rng& rng) override;
  /// One entry per plan call that returned candidates, in order.
  const std::vector<StepRegret>& steps() const { return steps_; }

 private:
  planning::ViewPlanner& inner_;
  const OracleNbvPlanner& oracle_;
  bool record_features_ = false;
  int calls_ = 0;
  std::vector<StepRegret> steps_;
};

}  // namespace avp::eval

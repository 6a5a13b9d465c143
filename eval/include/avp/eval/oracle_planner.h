#pragma once

#include <memory>
#include <string_view>

#include <avp/eval/ground_truth.h>
#include <avp/planning/candidates.h>
#include <avp/planning/view_planner.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scene.h>

namespace avp::eval {

/// "oracle-nbv": a planner that knows the truth, as an upper bound for the greedy planners on the
/// same candidate set (avp-nbv's 3-D shells). Each reachable candidate is rendered in the true
/// scene, and its gain is the number of ground-truth fruit-surface voxels it would see that the
/// map does not yet hold as occupied fruit. No robot has this: it shows how much of a scenario's
/// F1 a planner could reach by choosing better among the same views (docs/planning.md).
struct OracleNbvOptions {
  planning::ShellCandidateOptions candidates;
  /// The candidates are rendered at this fraction of the camera's resolution (field of view
  /// kept): 0.25 renders 160 x 120 for a 640 x 480 camera.
  double render_scale = 0.25;
  /// Motion cost weight, as avp-nbv's: U = G / max G - w_motion |dq| / max |dq|.
  double w_motion = 0.1;
  int num_threads = 0;
};

class OracleNbvPlanner final : public planning::ViewPlanner {
 public:
  /// `scene` and `gt` must outlive the planner.
  OracleNbvPlanner(const sim::Scene& scene, const GroundTruth& gt,
                   const OracleNbvOptions& options = {});
  ~OracleNbvPlanner() override;
  std::string_view name() const override { return "oracle-nbv"; }
  planning::PlanResult Plan(const planning::PlanningRequest& request, Rng& rng) override;

  /// The true gain of a camera at X_WC given `map`: ground-truth voxels it sees (rendered at
  /// render_scale) that `map` does not hold as occupied `target` voxels.
  size_t TrueGain(const mapping::SemanticMap& map, SemanticClass target, const CameraIntrinsics& K,
                  const RigidTransform& X_WC) const;

 private:
  const GroundTruth& gt_;
  OracleNbvOptions options_;
  std::unique_ptr<sim::RgbdRenderer> renderer_;
};

}  // namespace avp::eval

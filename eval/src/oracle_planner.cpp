#include <algorithm>
#include <unordered_set>

#include <avp/core/parallel.h>
#include <avp/eval/oracle_planner.h>
#include <avp/mapping/semantic_map.h>
#include <avp/planning/gain_grid.h>

namespace avp::eval {

OracleNbvPlanner::OracleNbvPlanner(const sim::Scene& scene, const GroundTruth& gt,
                                   const OracleNbvOptions& options)
    : gt_(gt), options_(options) {
  sim::RendererOptions ro;
  ro.num_threads = 1;  // candidates are rendered in parallel instead
  renderer_ = std::make_unique<sim::RgbdRenderer>(scene, ro);
}

OracleNbvPlanner::~OracleNbvPlanner() = default;

size_t OracleNbvPlanner::TrueGain(const mapping::SemanticMap& map, SemanticClass target,
                                  const CameraIntrinsics& K, const RigidTransform& X_WC) const {
  const CameraIntrinsics Ks = K.Scaled(options_.render_scale);
  const sim::RenderedFrame f = renderer_->Render(Ks, X_WC);
  const double s = map.voxel_size_m();
  std::unordered_set<VoxelKey, VoxelKeyHash> seen;
  for (int v = 0; v < Ks.height; ++v) {
    for (int u = 0; u < Ks.width; ++u) {
      const float z = f.rgbd.depth_m.at(u, v);
      if (!(z > 0.0f)) continue;
      const Eigen::Vector3d p_C = Ks.BackProject(Eigen::Vector2d(u, v), z);
      const VoxelKey k = VoxelKey::FromPoint(X_WC * p_C, s);
      if (gt_.voxels.count(k) == 0) continue;
      const mapping::SemanticCell* cell = map.Semantic(k);
      if (map.State(k) == mapping::VoxelState::kOccupied && cell != nullptr &&
          cell->cls() == target) {
        continue;
      }
      seen.insert(k);
    }
  }
  return seen.size();
}

planning::PlanResult OracleNbvPlanner::Plan(const planning::PlanningRequest& request, Rng& rng) {
  planning::PlanResult result;
  if (Status st = planning::ValidateRequest(request); !st.ok()) {
    result.status = st;
    return result;
  }
  Result<planning::GainGrid> grid =
      planning::GainGrid::Build(*request.map, request.target_class, request.roi);
  if (!grid.ok()) {
    result.status = grid.status();
    return result;
  }
  const auto targets = planning::FindViewTargets(request, *grid, options_.candidates);
  std::vector<planning::ViewCandidate> candidates =
      planning::GenerateShellCandidates(request, *grid, targets, options_.candidates, rng);
  const size_t generated = candidates.size();
  ParallelFor(candidates.size(), options_.num_threads, [&](size_t i) {
    planning::ViewCandidate& c = candidates[i];
    if (!c.reachable) return;
    c.gain = static_cast<double>(TrueGain(*request.map, request.target_class, request.K, c.X_WC));
  });
  double max_gain = 0.0, max_cost = 0.0;
  for (const auto& c : candidates) {
    if (!c.reachable) continue;
    max_gain = std::max(max_gain, c.gain);
    max_cost = std::max(max_cost, c.cost);
  }
  for (auto& c : candidates) {
    c.utility = (max_gain > 0.0 ? c.gain / max_gain : 0.0) -
                options_.w_motion * (max_cost > 0.0 ? c.cost / max_cost : 0.0);
  }
  return planning::RankCandidates(std::move(candidates), generated, name());
}

}  // namespace avp::eval

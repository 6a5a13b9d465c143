#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/planning/farthest_view_planner.h>

namespace avp::planning {

namespace {

/// Distance from `eye` to the nearest of `fused` (infinite when nothing is fused).
double DistanceToNearest(const Eigen::Vector3d& eye, const std::vector<RigidTransform>& fused) {
  double d = std::numeric_limits<double>::infinity();
  for (const RigidTransform& f : fused) d = std::min(d, (f.translation() - eye).norm());
  return d;
}

}  // namespace

const OptionTable<FarthestViewOptions>& FarthestViewOptionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<FarthestViewOptions>("farthest-view option");
    t->Nested("candidates", &FarthestViewOptions::candidates, ShellCandidateOptionTable());
    t->Real("w_motion", &FarthestViewOptions::w_motion, "", ValueRange::AtLeast(0),
            "weight of the joint-space motion cost");
    return t;
  }();
  return *table;
}

Status FarthestViewOptions::Validate() const { return FarthestViewOptionTable().Validate(*this); }

FarthestViewPlanner::FarthestViewPlanner(const FarthestViewOptions& options) : options_(options) {
  const Status s = options_.Validate();
  AVP_THROW_UNLESS(s.ok(), s.message());
}

PlanResult FarthestViewPlanner::Plan(const PlanningRequest& request, Rng& rng) {
  PlanResult result;
  if (Status s = ValidateRequest(request); !s.ok()) {
    result.status = s.WithContext(name());
    return result;
  }
  // The gain grid only places the candidates (targets, clearance, no camera in unmapped
  // foliage); no gain is computed.
  Result<GainGrid> grid = GainGrid::Build(*request.map, request.target_class, request.roi);
  if (!grid.ok()) {
    result.status = grid.status().WithContext(name());
    return result;
  }
  ShellCandidateOptions shells = options_.candidates;
  const std::vector<ViewTarget> targets = FindViewTargets(request, *grid, shells);
  std::vector<ViewCandidate> candidates =
      GenerateShellCandidates(request, *grid, targets, shells, rng);
  double max_d = 0.0, max_cost = 0.0;
  for (ViewCandidate& c : candidates) {
    if (!c.reachable) continue;
    c.gain = DistanceToNearest(c.X_WC.translation(), request.fused_views);
    if (std::isfinite(c.gain)) max_d = std::max(max_d, c.gain);
    max_cost = std::max(max_cost, c.cost);
  }
  for (ViewCandidate& c : candidates) {
    const double d = max_d > 0.0 ? std::min(c.gain / max_d, 1.0) : 0.0;
    c.utility = d - options_.w_motion * (max_cost > 0.0 ? c.cost / max_cost : 0.0);
  }
  const size_t generated = candidates.size();
  return RankCandidates(std::move(candidates), generated, name());
}

PlannerEntry FarthestViewPlannerEntry() {
  return MakePlannerEntry<FarthestViewOptions>(
      "farthest-view",
      "a coverage baseline: the reachable shell view farthest from every fused view "
      "(docs/extending.md)",
      FarthestViewOptionTable(), FarthestViewOptions{},
      [](FarthestViewOptions o, const PlannerContext&) {
        return Result<std::unique_ptr<ViewPlanner>>(std::make_unique<FarthestViewPlanner>(o));
      });
}

}  // namespace avp::planning

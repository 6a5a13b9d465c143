#include <memory>

#include <avp/planning/random_planner.h>

namespace avp::planning {

PlanResult RandomPlanner::Plan(const PlanningRequest& request, Rng& rng) {
  PlanResult result;
  if (Status s = ValidateRequest(request); !s.ok()) {
    result.status = s;
    return result;
  }
  Result<GainGrid> grid = GainGrid::Build(*request.map, request.target_class, request.roi);
  if (!grid.ok()) {
    result.status = grid.status();
    return result;
  }
  const std::vector<ViewTarget> targets = FindViewTargets(request, *grid, options_);
  std::vector<ViewCandidate> candidates =
      GenerateShellCandidates(request, *grid, targets, options_, rng);
  const size_t generated = candidates.size();
  for (ViewCandidate& c : candidates) c.utility = rng.Uniform01();
  return RankCandidates(std::move(candidates), generated, name());
}

PlannerEntry RandomPlannerEntry() {
  return MakePlannerEntry<ShellCandidateOptions>(
      "random", "random reachable views from avp-nbv's candidate shells (a baseline)",
      ShellCandidateOptionTable(), ShellCandidateOptions{},
      [](ShellCandidateOptions o, const PlannerContext&) {
        return Result<std::unique_ptr<ViewPlanner>>(std::make_unique<RandomPlanner>(o));
      });
}

}  // namespace avp::planning

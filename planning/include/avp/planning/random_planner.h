#pragma once

#include <string_view>

#include <avp/planning/candidates.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

/// Random reachable views from avp-nbv's candidate generator (a baseline and a floor for every
/// planner): the shell candidates ranked in a seeded random order.
class RandomPlanner final : public ViewPlanner {
 public:
  explicit RandomPlanner(const ShellCandidateOptions& options = {}) : options_(options) {}
  std::string_view name() const override { return "random"; }
  PlanResult Plan(const PlanningRequest& request, Rng& rng) override;

 private:
  ShellCandidateOptions options_;
};

/// "random"'s registry entry: its options are the candidate shells' (ShellCandidateOptionTable).
PlannerEntry RandomPlannerEntry();

}  // namespace avp::planning

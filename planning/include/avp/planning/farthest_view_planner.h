#pragma once

#include <string_view>

#include <avp/core/options.h>
#include <avp/planning/candidates.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

/// Options of the farthest-view planner.
struct FarthestViewOptions {
  /// The candidate shells (the same generator as avp-nbv, so the planners compete on the same
  /// views).
  ShellCandidateOptions candidates;
  /// Motion cost weight: U = d / max d - w_motion |dq| / max |dq|.
  double w_motion = 0.1;

  Status Validate() const;
};

/// The fields of FarthestViewOptions: candidates.* and w_motion.
const OptionTable<FarthestViewOptions>& FarthestViewOptionTable();

/// "farthest-view": a geometric coverage baseline that looks at no voxel. Among avp-nbv's
/// reachable shell candidates it ranks first the one whose eye is farthest from every eye fused so
/// far (the distance d to the nearest fused eye, normalised over the candidates), with a small
/// motion cost. It spreads the views around the plant the way a surveyor would, which is what
/// avp-nbv's diversity term adds to its gain; comparing the two shows what the map's gain buys.
/// The worked example of docs/extending.md ("Adding a planner").
class FarthestViewPlanner final : public ViewPlanner {
 public:
  /// @throws avp::Error if options.Validate() fails.
  explicit FarthestViewPlanner(const FarthestViewOptions& options = {});
  std::string_view name() const override { return "farthest-view"; }
  PlanResult Plan(const PlanningRequest& request, Rng& rng) override;

 private:
  FarthestViewOptions options_;
};

/// "farthest-view"'s registry entry (RegisterBuiltinPlanners).
PlannerEntry FarthestViewPlannerEntry();

}  // namespace avp::planning

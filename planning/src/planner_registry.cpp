#include <algorithm>
#include <string>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/planning/avp_nbv_planner.h>
#include <avp/planning/farthest_view_planner.h>
#include <avp/planning/isler_utilities.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/predefined_planner.h>
#include <avp/planning/random_planner.h>
#include <avp/planning/reference_nbv_planner.h>

namespace avp::planning {

Result<std::unique_ptr<ViewPlanner>> PlannerRegistry::Make(std::string_view name,
                                                           const AnyOptions& options,
                                                           const PlannerContext& context) const {
  AVP_ASSIGN_OR_RETURN(const PlannerEntry* entry, Get(name));
  if (entry->needs_ground_truth && context.truth == nullptr) {
    return FailedPreconditionError(fmt::format(
        "planner '{}' needs the true scene and its ground truth (a diagnostic bound): it is "
        "built only where the truth is known",
        name));
  }
  AVP_RETURN_IF_ERROR(options.Validate());
  return entry->make(options, context);
}

void RegisterBuiltinPlanners(PlannerRegistry& registry) {
  std::vector<PlannerEntry> entries;
  entries.push_back(AvpNbvPlannerEntry());
  for (PlannerEntry& e : PredefinedPlannerEntries()) entries.push_back(std::move(e));
  entries.push_back(ReferenceNbvPlannerEntry());
  entries.push_back(RandomPlannerEntry());
  for (PlannerEntry& e : IslerPlannerEntries()) entries.push_back(std::move(e));
  entries.push_back(FarthestViewPlannerEntry());
  AddAll(registry, std::move(entries));
}

}  // namespace avp::planning

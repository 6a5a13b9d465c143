#pragma once

#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/options.h>
#include <avp/core/registry.h>
#include <avp/core/status.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

/// Whatever a diagnostic planner may know about the true scene; the module that owns the truth
/// derives from it (eval::PlannerTruth) and its planners' factories cast it back.
class PlannerTruth {
 public:
  virtual ~PlannerTruth() = default;
};

/// What a planner's factory gets besides its options.
struct PlannerContext {
  /// The truth, for planners registered with needs_ground_truth; null otherwise.
  const PlannerTruth* truth = nullptr;
};

/// One planner a user can pick by name (`avp run --planner NAME`, `avp bench --planners ...`).
struct PlannerEntry {
  std::string name;
  /// One line for `--planner help`.
  std::string description;
  /// The options type with its defaults (no fields: the planner has no options).
  AnyOptions options;
  /// The planner needs the ground truth (a diagnostic bound, not a robot's planner): it is built
  /// only where the truth is known, and PlannerContext::truth is set.
  bool needs_ground_truth = false;
  /// Builds the planner from options of `options`' type (already validated).
  std::function<Result<std::unique_ptr<ViewPlanner>>(const AnyOptions&, const PlannerContext&)>
      make;

  bool Matches(std::string_view spec) const { return name == spec; }
  std::string DisplayName() const { return name; }
  bool HasFactory() const { return static_cast<bool>(make); }
};

/// An entry for a planner with options of type Options (table `table`, defaults `defaults`):
/// `make` receives the options as that type.
template <typename Options>
PlannerEntry MakePlannerEntry(
    std::string name, std::string description, const OptionTable<Options>& table, Options defaults,
    std::function<Result<std::unique_ptr<ViewPlanner>>(const Options&, const PlannerContext&)>
        make) {
  PlannerEntry e;
  e.name = std::move(name);
  e.description = std::move(description);
  e.options = AnyOptions(table, std::move(defaults));
  e.make = [make = std::move(make)](const AnyOptions& o, const PlannerContext& c) {
    return make(o.As<Options>(), c);
  };
  return e;
}

/// The planners a program knows, by name, in registration order (NamedRegistry: Add, Find, Get,
/// Names, entries). Built once at start-up (RegisterBuiltinPlanners, then any others), read-only
/// afterwards.
class PlannerRegistry : public NamedRegistry<PlannerEntry> {
 public:
  PlannerRegistry() : NamedRegistry("planner") {}
  /// Builds `name` with `options` (of its entry's type; validated here). FailedPrecondition when
  /// the planner needs the ground truth and the context has none.
  Result<std::unique_ptr<ViewPlanner>> Make(std::string_view name, const AnyOptions& options,
                                            const PlannerContext& context) const;
};

/// Registers every planner of this module, in this order: avp-nbv, predefined, predefined-wide,
/// predefined-generic, reference-nbv, random, isler-ae, isler-oa, isler-uv, isler-rsv,
/// isler-rse, isler-pc, farthest-view. @throws avp::Error if a name is already taken.
void RegisterBuiltinPlanners(PlannerRegistry& registry);

}  // namespace avp::planning

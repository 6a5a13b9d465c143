#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/planning/avp_nbv_planner.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/predefined_planner.h>

namespace avp::planning {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;

PlannerRegistry Builtins() {
  PlannerRegistry builtins;
  RegisterBuiltinPlanners(builtins);
  return builtins;
}

TEST(PlannerRegistryTest, RegistersTheBuiltinsInOrder) {
  const PlannerRegistry r = Builtins();
  EXPECT_THAT(r.Names(),
              ElementsAre("avp-nbv", "predefined", "predefined-wide", "predefined-generic",
                          "reference-nbv", "random", "isler-ae", "isler-oa", "isler-uv",
                          "isler-rsv", "isler-rse", "isler-pc", "farthest-view"));
  for (const PlannerEntry& e : r.entries()) {
    EXPECT_FALSE(e.description.empty()) << e.name;
    EXPECT_FALSE(e.needs_ground_truth) << e.name;
    EXPECT_TRUE(e.options.Validate().ok()) << e.name;  // the defaults are valid
    // Each builds with its defaults, and the planner reports its registered name (all the
    // zig-zags report "predefined").
    auto planner = r.Make(e.name, e.options, {});
    ASSERT_TRUE(planner.ok()) << e.name << ": " << planner.status().ToString();
    if (e.name.rfind("predefined", 0) != 0) {
      EXPECT_EQ((*planner)->name(), e.name);
    }
  }
  PlannerRegistry again = Builtins();
  EXPECT_THROW(RegisterBuiltinPlanners(again), Error);  // every name is taken
}

TEST(PlannerRegistryTest, OptionsApplyOverridesOverTheEntrysDefaults) {
  const PlannerRegistry r = Builtins();
  Result<AnyOptions> o =
      r.Options("avp-nbv", {{"p_unknown", "0.1"}, {"candidates.max_targets", "4"}});
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  EXPECT_EQ(o->As<AvpNbvOptions>().p_unknown, 0.1);
  EXPECT_EQ(o->As<AvpNbvOptions>().candidates.max_targets, 4);
  EXPECT_EQ(o->As<AvpNbvOptions>().w_diversity, AvpNbvOptions{}.w_diversity);
  // The set a zig-zag plays comes from its name, not from an option.
  EXPECT_EQ(r.Options("predefined-wide")->As<PredefinedOptions>().set,
            PredefinedOptions::Set::kWide);
  EXPECT_THAT(r.Options("avp-nbv", {{"p_unknown", "1.5"}}).status().message(),
              HasSubstr("p_unknown (1.5) must be in [0, 1)"));
  EXPECT_THAT(r.Options("random", {{"p_unknown", "0.1"}}).status().message(),
              HasSubstr("unknown candidate shell option 'p_unknown' (known: radii_m"));
  const Status unknown = r.Options("nope").status();
  EXPECT_EQ(unknown.code(), StatusCode::kNotFound);
  EXPECT_THAT(unknown.message(), HasSubstr("unknown planner 'nope' (known: avp-nbv, predefined"));
}

TEST(PlannerRegistryTest, AddRefusesDuplicatesAndEntriesWithoutFactory) {
  PlannerRegistry r;
  EXPECT_TRUE(r.Add(AvpNbvPlannerEntry()).ok());
  EXPECT_THAT(r.Add(AvpNbvPlannerEntry()).message(), HasSubstr("'avp-nbv' is already registered"));
  PlannerEntry e;
  e.name = "no-factory";
  EXPECT_THAT(r.Add(e).message(), HasSubstr("has no factory"));
  EXPECT_FALSE(r.Add(PlannerEntry{}).ok());
}

TEST(PlannerRegistryTest, PlannersThatNeedTheTruthAreNotBuiltWithoutIt) {
  PlannerRegistry r;
  PlannerEntry e = AvpNbvPlannerEntry();
  e.name = "needs-truth";
  e.needs_ground_truth = true;
  ASSERT_TRUE(r.Add(e).ok());
  const auto made = r.Make("needs-truth", e.options, {});
  EXPECT_EQ(made.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(made.status().message(), HasSubstr("needs the true scene"));
  const PlannerTruth truth;
  EXPECT_TRUE(r.Make("needs-truth", e.options, {.truth = &truth}).ok());
}

}  // namespace
}  // namespace avp::planning

#include <algorithm>
#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/planning/farthest_view_planner.h>
#include <avp/planning/planner_registry.h>
#include <avp/robot/arm_model.h>

namespace avp::planning {
namespace {

using ::testing::HasSubstr;

/// An empty map and a plant-sized ROI in front of the arm: the shells are built around the ROI's
/// centre, the only target an empty map has.
class FarthestViewPlannerTest : public ::testing::Test {
 protected:
  FarthestViewPlannerTest() : arm_(robot::LoadDefaultArm().value()) {}

  PlanningRequest Request(std::vector<RigidTransform> fused) const {
    PlanningRequest r;
    r.map = &map_;
    r.arm = &arm_;
    r.q_current = r.q_start = arm_.home_joints();
    r.X_WC_current = r.X_WC_start = arm_.CameraPose(r.q_current);
    r.K = CameraIntrinsics::RealSenseD435();
    r.roi = Box3(Eigen::Vector3d(0.55, -0.15, 0.35), Eigen::Vector3d(0.85, 0.15, 0.75));
    r.fused_views = std::move(fused);
    return r;
  }

  robot::ArmModel arm_;
  mapping::SemanticMap map_;
};

double NearestFused(const ViewCandidate& c, const std::vector<RigidTransform>& fused) {
  double d = std::numeric_limits<double>::infinity();
  for (const RigidTransform& f : fused)
    d = std::min(d, (f.translation() - c.X_WC.translation()).norm());
  return d;
}

TEST_F(FarthestViewPlannerTest, RanksTheViewFarthestFromTheFusedOnesFirst) {
  const std::vector<RigidTransform> fused = {arm_.CameraPose(arm_.home_joints()),
                                             RigidTransform(Eigen::Vector3d(0.3, 0.3, 0.6))};
  FarthestViewOptions o;
  o.w_motion = 0.0;  // distance alone
  FarthestViewPlanner planner(o);
  Rng a(5), b(5);
  const PlanResult r = planner.Plan(Request(fused), a);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  ASSERT_GT(r.ranked.size(), 10u);
  // Utility = distance to the nearest fused eye over the largest such distance.
  const double best = NearestFused(r.ranked.front(), fused);
  for (const ViewCandidate& c : r.ranked) {
    EXPECT_TRUE(c.reachable);
    EXPECT_DOUBLE_EQ(c.gain, NearestFused(c, fused));
    EXPECT_LE(c.gain, best);
    EXPECT_NEAR(c.utility, c.gain / best, 1e-12);
  }
  EXPECT_GT(best, NearestFused(r.ranked.back(), fused));
  // Deterministic by seed.
  const PlanResult again = planner.Plan(Request(fused), b);
  ASSERT_EQ(again.ranked.size(), r.ranked.size());
  EXPECT_EQ(again.ranked.front().X_WC.translation(), r.ranked.front().X_WC.translation());
}

TEST_F(FarthestViewPlannerTest, MotionCostBreaksTiesTowardsShortMoves) {
  FarthestViewOptions o;
  o.w_motion = 10.0;  // motion dominates
  Rng rng(5);
  const PlanResult r =
      FarthestViewPlanner(o).Plan(Request({arm_.CameraPose(arm_.home_joints())}), rng);
  ASSERT_TRUE(r.status.ok());
  for (const ViewCandidate& c : r.ranked) EXPECT_LE(r.ranked.front().cost, c.cost + 0.1);
}

TEST_F(FarthestViewPlannerTest, IsRegisteredWithItsOptions) {
  PlannerRegistry registry;
  RegisterBuiltinPlanners(registry);
  const PlannerEntry* entry = registry.Find("farthest-view");
  ASSERT_NE(entry, nullptr);
  EXPECT_FALSE(entry->needs_ground_truth);
  const Result<AnyOptions> options =
      registry.Options("farthest-view", {{"w_motion", "0"}, {"candidates.max_targets", "3"}});
  ASSERT_TRUE(options.ok()) << options.status().ToString();
  EXPECT_EQ(options->As<FarthestViewOptions>().candidates.max_targets, 3);
  auto planner = registry.Make("farthest-view", *options, {.truth = nullptr});
  ASSERT_TRUE(planner.ok());
  EXPECT_EQ((*planner)->name(), "farthest-view");
  EXPECT_THAT(
      registry.Options("farthest-view", {{"candidates.max_candidates", "0"}}).status().message(),
      HasSubstr("candidates.max_candidates (0) must be in [1, 20000]"));
  Rng rng(1);
  PlanningRequest bad = Request({});
  bad.map = nullptr;
  EXPECT_THAT((*planner)->Plan(bad, rng).status.message(), HasSubstr("map must not be null"));
}

}  // namespace
}  // namespace avp::planning

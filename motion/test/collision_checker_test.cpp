#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <avp/core/rng.h>
#include <avp/motion/collision_checker.h>

#include "motion_test_util.h"

namespace avp::motion {
namespace {

using testing::DefaultArm;
using testing::DefaultGeometry;
using testing::Deg;
using testing::FillOccupied;

CollisionOptions KnownOnly() {
  CollisionOptions o;
  o.field.unknown_is_obstacle = false;
  return o;
}

CollisionChecker Checker(const CollisionOptions& options = KnownOnly(),
                         const std::vector<robot::CollisionShape>& world = {}) {
  return CollisionChecker::Create(DefaultGeometry(), world, options).value();
}

TEST(CollisionCheckerTest, HomeIsFreeInAnEmptyWorld) {
  const CollisionChecker c = Checker();
  EXPECT_TRUE(c.IsFree(DefaultArm().home_joints())) << c.Check(DefaultArm().home_joints()).detail;
}

TEST(CollisionCheckerTest, AnOccupiedVoxelNearTheCameraIsNamedWithItsClearance) {
  CollisionChecker c = Checker();
  mapping::OccupancyGrid grid;
  // The camera's glass is at x = 0.22 m at home (eye (0.22, 0, 0.677)): a leaf 1 cm in front.
  FillOccupied(grid, Box3(Eigen::Vector3d(0.23, -0.03, 0.66), Eigen::Vector3d(0.235, 0.03, 0.70)));
  ASSERT_TRUE(
      c.SetMap(grid, Box3(Eigen::Vector3d(0.1, -0.3, 0.3), Eigen::Vector3d(0.6, 0.3, 1.0))).ok());
  const StateCheck check = c.Check(DefaultArm().home_joints());
  EXPECT_EQ(check.obstacle, Obstacle::kMap);
  EXPECT_NE(check.detail.find("flange/d435"), std::string::npos) << check.detail;
  EXPECT_LT(c.MapClearance(DefaultArm().home_joints()), 0.02);
  // Moved 15 cm away, it is outside the margin.
  mapping::OccupancyGrid far;
  FillOccupied(far, Box3(Eigen::Vector3d(0.40, -0.03, 0.66), Eigen::Vector3d(0.405, 0.03, 0.70)));
  ASSERT_TRUE(
      c.SetMap(far, Box3(Eigen::Vector3d(0.1, -0.3, 0.3), Eigen::Vector3d(0.6, 0.3, 1.0))).ok());
  EXPECT_TRUE(c.IsFree(DefaultArm().home_joints())) << c.Check(DefaultArm().home_joints()).detail;
  EXPECT_GT(c.MapClearance(DefaultArm().home_joints()), 0.1);
}

TEST(CollisionCheckerTest, UnknownVoxelsInTheRoiAreObstaclesUntilTheArmHasBeenThere) {
  CollisionOptions options;  // unknown_is_obstacle: true
  CollisionChecker c = Checker(options);
  mapping::OccupancyGrid grid;  // nothing known
  const Box3 roi(Eigen::Vector3d(0.15, -0.1, 0.55), Eigen::Vector3d(0.35, 0.1, 0.8));
  ASSERT_TRUE(c.SetMap(grid, roi).ok());
  const Eigen::VectorXd home = DefaultArm().home_joints();
  EXPECT_EQ(c.Check(home).obstacle, Obstacle::kMap);
  EXPECT_GT(c.field().unknown_cells(), 0);
  // The arm stands there: that space holds nothing.
  c.MarkSwept(home);
  ASSERT_TRUE(c.SetMap(grid, roi).ok());
  EXPECT_TRUE(c.IsFree(home)) << c.Check(home).detail;
  // But an occupied voxel there still is an obstacle.
  FillOccupied(grid, Box3(Eigen::Vector3d(0.23, -0.03, 0.66), Eigen::Vector3d(0.235, 0.03, 0.70)));
  ASSERT_TRUE(c.SetMap(grid, roi).ok());
  EXPECT_EQ(c.Check(home).obstacle, Obstacle::kMap);
  // Outside the ROI unknown space is free.
  c.ClearMap();
  ASSERT_TRUE(c.SetMap(mapping::OccupancyGrid(),
                       Box3(Eigen::Vector3d(0.5, 0.5, 0.0), Eigen::Vector3d(0.7, 0.7, 0.3)))
                  .ok());
  EXPECT_TRUE(c.IsFree(home)) << c.Check(home).detail;
}

TEST(CollisionCheckerTest, DeclaredWorldObjectsAreNamed) {
  const robot::CollisionShape table = robot::CollisionShape::Box(
      "table", Eigen::Vector3d(0.2, 0.4, 0.05), RigidTransform(Eigen::Vector3d(0.25, 0, 0.62)));
  const robot::CollisionShape ground = robot::CollisionShape::Plane("ground", RigidTransform());
  const CollisionChecker c = Checker(KnownOnly(), {ground, table});
  const StateCheck check = c.Check(DefaultArm().home_joints());
  EXPECT_EQ(check.obstacle, Obstacle::kWorld);
  EXPECT_NE(check.detail.find("'table'"), std::string::npos) << check.detail;
  // The ground: some state puts a moving body below its plane (plus margin), and only such.
  const CollisionChecker ground_only = Checker(KnownOnly(), {ground});
  EXPECT_TRUE(ground_only.IsFree(DefaultArm().home_joints()));
  Rng rng(5);
  int below = 0;
  for (int k = 0; k < 500; ++k) {
    const Eigen::VectorXd q = DefaultArm().RandomJoints(rng);
    const StateCheck s = ground_only.Check(q);
    if (s.obstacle != Obstacle::kWorld) continue;
    ++below;
    EXPECT_NE(s.detail.find("'ground'"), std::string::npos) << s.detail;
    double lowest = 1e9;
    const std::vector<Eigen::Isometry3d> links = DefaultGeometry().LinkPoses(q);
    for (const RobotBody& b : DefaultGeometry().bodies()) {
      if (!b.moves) continue;
      for (const Sphere& sp : b.spheres) {
        lowest = std::min(lowest, (links[static_cast<size_t>(b.link)] * sp.center).z() - sp.radius);
      }
    }
    EXPECT_LT(lowest, 0.02);
  }
  EXPECT_GT(below, 0);
}

TEST(CollisionCheckerTest, IsFreeAgreesWithCheckOnEveryKindOfObstacle) {
  // IsFree skips the message; its verdict must be Check's, whatever the arm meets.
  const robot::CollisionShape table = robot::CollisionShape::Box(
      "table", Eigen::Vector3d(0.3, 0.6, 0.05), RigidTransform(Eigen::Vector3d(0.45, 0, 0.3)));
  const robot::CollisionShape ground = robot::CollisionShape::Plane("ground", RigidTransform());
  CollisionChecker c = Checker(KnownOnly(), {ground, table});
  mapping::OccupancyGrid grid;
  FillOccupied(grid, Box3(Eigen::Vector3d(0.3, -0.2, 0.5), Eigen::Vector3d(0.35, 0.2, 0.7)));
  ASSERT_TRUE(
      c.SetMap(grid, Box3(Eigen::Vector3d(0.1, -0.3, 0.3), Eigen::Vector3d(0.6, 0.3, 1.0))).ok());
  Rng rng(11);
  std::map<Obstacle, int> seen;
  for (int k = 0; k < 3000; ++k) {
    Eigen::VectorXd q = DefaultArm().RandomJoints(rng);
    if (k % 100 == 0) q[1] = DefaultArm().upper_limits()[1] + 0.1;
    const StateCheck check = c.Check(q);
    ASSERT_EQ(c.IsFree(q), check.free()) << "state " << k << ": " << check.detail;
    EXPECT_EQ(check.free(), check.detail.empty()) << check.detail;
    ++seen[check.obstacle];
  }
  for (const Obstacle kind : {Obstacle::kNone, Obstacle::kJointLimits, Obstacle::kMap,
                              Obstacle::kWorld, Obstacle::kSelf}) {
    EXPECT_GT(seen[kind], 0) << ToString(kind) << " never met: the test does not cover it";
  }
}

TEST(CollisionCheckerTest, ASegmentIsCheckedFinelyEnoughToCatchAThinObstacle) {
  CollisionChecker c = Checker();
  mapping::OccupancyGrid grid;
  // A 5 mm post in the camera's path as joint1 turns from -60 to +60 degrees.
  FillOccupied(grid,
               Box3(Eigen::Vector3d(0.235, -0.0025, 0.55), Eigen::Vector3d(0.24, 0.0025, 0.8)));
  ASSERT_TRUE(
      c.SetMap(grid, Box3(Eigen::Vector3d(0.1, -0.3, 0.3), Eigen::Vector3d(0.6, 0.3, 1.0))).ok());
  Eigen::VectorXd a = DefaultArm().home_joints();
  Eigen::VectorXd b = a;
  a[0] = -M_PI / 3;
  b[0] = M_PI / 3;
  ASSERT_TRUE(c.IsFree(a));
  ASSERT_TRUE(c.IsFree(b));
  const SegmentCheck s = c.CheckSegment(a, b, /*in_order=*/true);
  EXPECT_FALSE(s.free);
  EXPECT_EQ(s.first_collision.obstacle, Obstacle::kMap);
  EXPECT_GT(s.at_fraction, 0.3);
  EXPECT_LT(s.at_fraction, 0.7);
  // The states are no more than max_step_m of travel apart.
  EXPECT_GE(s.states, static_cast<int>(0.3 * DefaultGeometry().MaxDisplacement(b - a) /
                                       c.options().max_step_m));
}

TEST(CollisionCheckerTest, BadOptionsAreNamed) {
  CollisionOptions o;
  o.margin_m = -1;
  Result<CollisionChecker> c = CollisionChecker::Create(DefaultGeometry(), {}, o);
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("margin_m (-1 m)"), std::string::npos)
      << c.status().ToString();
  o = CollisionOptions{};
  o.margin_m = 0.001;
  o.max_step_m = 0.01;
  c = CollisionChecker::Create(DefaultGeometry(), {}, o);
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("max_step_m (0.01) must be at most 2 x margin_m (0.001)"),
            std::string::npos)
      << c.status().ToString();
  const robot::CollisionShape negative = robot::CollisionShape::Box(
      "crate", Eigen::Vector3d(0.2, -0.1, 0.3), RigidTransform(Eigen::Vector3d(1, 0, 0)));
  c = CollisionChecker::Create(DefaultGeometry(), {negative}, CollisionOptions{});
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("'crate': box size (0.2, -0.1, 0.3)"), std::string::npos)
      << c.status().ToString();
}

}  // namespace
}  // namespace avp::motion

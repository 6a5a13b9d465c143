#include <cstdio>
#include <string>
#include <vector>

#include <fcl/geometry/shape/box.h>
#include <fcl/narrowphase/collision.h>
#include <gtest/gtest.h>

#include <avp/core/rng.h>
#include <avp/motion/motion_planner.h>

#include "motion_test_util.h"

namespace avp::motion {
namespace {

using testing::DefaultArm;
using testing::DefaultGeometry;
using testing::Deg;
using testing::FillOccupied;

/// A post in front of the arm: the wrist and the camera sweep through it when joint1 turns from
/// -60 to +60 degrees at the home pose (the camera's glass is at x = 0.22 m at joint1 = 0).
const Box3 kPost(Eigen::Vector3d(0.21, -0.02, 0.45), Eigen::Vector3d(0.25, 0.02, 0.95));
const Box3 kRoi(Eigen::Vector3d(0.1, -0.4, 0.2), Eigen::Vector3d(0.7, 0.4, 1.1));

struct PostScene {
  mapping::OccupancyGrid grid;
  CollisionChecker checker;
  Eigen::VectorXd a;
  Eigen::VectorXd b;

  explicit PostScene(const Box3& post = kPost)
      : checker(CollisionChecker::Create(DefaultGeometry(), {}, Options()).value()) {
    FillOccupied(grid, post);
    EXPECT_TRUE(checker.SetMap(grid, kRoi).ok());
    a = DefaultArm().home_joints();
    b = a;
    a[0] = -M_PI / 3;
    b[0] = M_PI / 3;
  }
  static CollisionOptions Options() {
    CollisionOptions o;
    o.field.unknown_is_obstacle = false;
    return o;
  }
};

/// Independent of the planner: does any body (its true shape, FCL) touch the post's box at q?
bool TouchesBox(const Eigen::VectorXd& q, const Box3& box) {
  const auto post = std::make_shared<fcl::Boxd>(box.max() - box.min());
  Eigen::Isometry3d X_WB = Eigen::Isometry3d::Identity();
  X_WB.translation() = box.center();
  const fcl::CollisionObjectd ob(post, X_WB);
  const std::vector<Eigen::Isometry3d> poses = DefaultGeometry().BodyPoses(q);
  for (size_t i = 0; i < DefaultGeometry().bodies().size(); ++i) {
    const fcl::CollisionObjectd oa(
        std::const_pointer_cast<fcl::CollisionGeometryd>(DefaultGeometry().bodies()[i].geometry),
        poses[i]);
    fcl::CollisionRequestd request;
    fcl::CollisionResultd result;
    if (fcl::collide(&oa, &ob, request, result) > 0) return true;
  }
  return false;
}

/// The trajectory's polyline, re-checked every 1 mm of travel against the true post.
int DenseContacts(const robot::JointTrajectory& t, const Box3& box) {
  int contacts = 0;
  for (size_t k = 1; k < t.points.size(); ++k) {
    const Eigen::VectorXd& q0 = t.points[k - 1].q;
    const Eigen::VectorXd& q1 = t.points[k].q;
    const int steps =
        std::max(1, static_cast<int>(DefaultGeometry().MaxDisplacement(q1 - q0) / 0.001));
    for (int i = 0; i <= steps; ++i)
      contacts += TouchesBox(q0 + (q1 - q0) * i / steps, box) ? 1 : 0;
  }
  return contacts;
}

TEST(MotionPlannerTest, TheStraightLineHitsThePostAndThePlannedPathProvablyDoesNot) {
  PostScene scene;
  // The straight line collides (dense check of the true shapes, independent of the planner).
  robot::JointTrajectory straight;
  straight.points = {{scene.a, {}, 0.0}, {scene.b, {}, 1.0}};
  ASSERT_GT(DenseContacts(straight, kPost), 0);

  const MotionPlanner planner(scene.checker, MotionOptions{});
  Rng rng(42);
  const MotionPlan plan = planner.Plan(scene.a, scene.b, rng);
  ASSERT_TRUE(plan.ok()) << plan.status.ToString();
  EXPECT_FALSE(plan.straight);
  EXPECT_FALSE(plan.straight_check.free);
  EXPECT_GT(plan.samples, 0);
  ASSERT_GE(plan.path.size(), 3u);
  EXPECT_TRUE(plan.path.front().isApprox(scene.a));
  EXPECT_TRUE(plan.path.back().isApprox(scene.b));
  EXPECT_EQ(DenseContacts(plan.trajectory, kPost), 0);
  // It keeps the margin too (the checker's own dense check of each segment).
  for (size_t k = 1; k < plan.path.size(); ++k) {
    EXPECT_TRUE(scene.checker.CheckSegment(plan.path[k - 1], plan.path[k]).free) << k;
  }
  EXPECT_TRUE(plan.trajectory.Validate(DefaultArm()).ok())
      << plan.trajectory.Validate(DefaultArm()).ToString();
  EXPECT_GT(plan.path_length, (scene.b - scene.a).norm());
}

TEST(MotionPlannerTest, AFreeStraightLineIsTakenAsIs) {
  PostScene scene(Box3(Eigen::Vector3d(0.6, -0.02, 0.45), Eigen::Vector3d(0.64, 0.02, 0.95)));
  const MotionPlanner planner(scene.checker, MotionOptions{});
  Rng rng(1);
  const MotionPlan plan = planner.Plan(scene.a, scene.b, rng);
  ASSERT_TRUE(plan.ok()) << plan.status.ToString();
  EXPECT_TRUE(plan.straight);
  EXPECT_EQ(plan.samples, 0);
  ASSERT_EQ(plan.path.size(), 2u);
  EXPECT_NEAR(plan.path_length, 2 * M_PI / 3, 1e-9);
}

TEST(MotionPlannerTest, TheSameSeedGivesTheSamePath) {
  PostScene scene;
  const MotionPlanner planner(scene.checker, MotionOptions{});
  Rng r1(42);
  const MotionPlan p1 = planner.Plan(scene.a, scene.b, r1);
  Rng r2(42);
  const MotionPlan p2 = planner.Plan(scene.a, scene.b, r2);
  ASSERT_TRUE(p1.ok() && p2.ok());
  ASSERT_EQ(p1.path.size(), p2.path.size());
  for (size_t i = 0; i < p1.path.size(); ++i) EXPECT_EQ(p1.path[i], p2.path[i]) << i;
  EXPECT_EQ(p1.samples, p2.samples);
  // Another seed searches elsewhere.
  Rng r3(43);
  const MotionPlan p3 = planner.Plan(scene.a, scene.b, r3);
  ASSERT_TRUE(p3.ok());
  EXPECT_FALSE(p3.path.size() == p1.path.size() && p3.path[1] == p1.path[1]);
}

TEST(MotionPlannerTest, PartialShortcutsShortenTheSearchedPathAndKeepItFree) {
  // The same search (the seed's first draw) shortened with vertex shortcuts only, and with the
  // partial shortcuts after them: never longer, shorter on most seeds, still free of the post.
  PostScene scene;
  MotionOptions partial;
  partial.shortcut_tries = 100;
  const MotionPlanner planner(scene.checker, partial);
  const MotionPlanner greedy(scene.checker, MotionOptions{});  // vertex shortcuts only
  int shorter = 0;
  double sum_ratio = 0.0;
  constexpr int kSeeds = 10;
  for (int seed = 0; seed < kSeeds; ++seed) {
    Rng r1(static_cast<uint64_t>(seed)), r2(static_cast<uint64_t>(seed));
    const MotionPlan full = planner.Plan(scene.a, scene.b, r1);
    const MotionPlan vertex = greedy.Plan(scene.a, scene.b, r2);
    ASSERT_TRUE(full.ok() && vertex.ok()) << full.status.ToString() << vertex.status.ToString();
    ASSERT_FALSE(full.straight);
    EXPECT_EQ(full.samples, vertex.samples) << "seed " << seed << ": not the same search";
    EXPECT_LE(full.path_length, vertex.path_length + 1e-9) << "seed " << seed;
    shorter += full.path_length < vertex.path_length - 1e-6 ? 1 : 0;
    sum_ratio += full.path_length / vertex.path_length;
    EXPECT_EQ(DenseContacts(full.trajectory, kPost), 0) << "seed " << seed;
    for (size_t k = 1; k < full.path.size(); ++k) {
      EXPECT_TRUE(scene.checker.CheckSegment(full.path[k - 1], full.path[k]).free) << k;
    }
  }
  EXPECT_GE(shorter, kSeeds / 2);
  EXPECT_LT(sum_ratio / kSeeds, 0.8);  // measured: 0.48
  std::printf("partial shortcuts: %d of %d paths shorter, mean length ratio %.3f\n", shorter,
              kSeeds, sum_ratio / kSeeds);
}

TEST(MotionPlannerTest, StartOrGoalInCollisionAndTimeoutsAreNamed) {
  PostScene scene;
  const MotionPlanner planner(scene.checker, MotionOptions{});
  Rng rng(1);
  const Eigen::VectorXd home = DefaultArm().home_joints();  // the post overlaps the wrist
  MotionPlan plan = planner.Plan(home, scene.b, rng);
  EXPECT_EQ(plan.status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(plan.status.message().find("the start state is in collision (map: '"),
            std::string::npos)
      << plan.status.ToString();
  plan = planner.Plan(scene.b, home, rng);
  EXPECT_EQ(plan.status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(plan.status.message().find("the goal is in collision (map:"), std::string::npos)
      << plan.status.ToString();
  // A start closer than the margin but clear of the obstacles may back away: a post moved out
  // until the home pose's clearance is in (0, margin).
  bool tried = false;
  for (double x = 0.22; x < 0.32 && !tried; x += 0.0025) {
    PostScene near(Box3(Eigen::Vector3d(x, -0.02, 0.45), Eigen::Vector3d(x + 0.04, 0.02, 0.95)));
    const double clearance = near.checker.MapClearance(home);
    if (!(clearance > 0.0 && clearance < near.checker.options().margin_m)) continue;
    tried = true;
    const MotionPlanner near_planner(near.checker, MotionOptions{});
    plan = near_planner.Plan(home, near.b, rng);
    EXPECT_TRUE(plan.ok()) << plan.status.ToString() << " (clearance " << clearance << ")";
  }
  EXPECT_TRUE(tried) << "no post position gives the home pose a clearance inside the margin";
  // Outside the joint limits.
  Eigen::VectorXd beyond = scene.b;
  beyond[1] = 3.0;
  plan = planner.Plan(scene.a, beyond, rng);
  EXPECT_EQ(plan.status.code(), StatusCode::kOutOfRange);
  EXPECT_NE(plan.status.message().find("motion goal"), std::string::npos) << plan.status.ToString();
  // No time to search.
  MotionOptions hurried;
  hurried.max_samples = 10;
  hurried.timeout_s = 1e-4;
  const MotionPlanner hurried_planner(scene.checker, hurried);
  plan = hurried_planner.Plan(scene.a, scene.b, rng);
  EXPECT_EQ(plan.status.code(), StatusCode::kUnreachable);
  EXPECT_NE(plan.status.message().find("no collision-free path found"), std::string::npos)
      << plan.status.ToString();
  EXPECT_NE(plan.status.message().find("the straight line hits map"), std::string::npos)
      << plan.status.ToString();
}

TEST(MotionPlannerTest, BadOptionsAreNamed) {
  MotionOptions o;
  o.velocity_scaling = 0;
  o.max_samples = 1;
  const Status s = o.Validate();
  EXPECT_NE(s.message().find("velocity_scaling (0)"), std::string::npos) << s.ToString();
  EXPECT_NE(s.message().find("max_samples (1)"), std::string::npos) << s.ToString();
}

/// Nothing is known around the arm at home (all of it inside the ROI): the start clearance is the
/// free space avp assumes there. The arm at home is that far from the unseen space (within a
/// field cell); a move of the camera 1 cm into it is planned when the assumption covers it and
/// refused with 0, where only the space the bodies fill is free and the first move keeps the
/// start's own clearance.
TEST(MotionPlannerTest, StartClearanceIsTheFreeSpaceAssumedAroundTheStartPose) {
  const robot::ArmModel& arm = DefaultArm();
  const Eigen::VectorXd home = arm.home_joints();
  const Eigen::Vector3d eye = arm.CameraPose(home).translation();
  const Box3 roi(eye - Eigen::Vector3d(0.5, 0.5, 0.5), eye + Eigen::Vector3d(0.5, 0.5, 0.5));
  // Joint 2 tilts the arm forward: the camera 1 cm from where it stands.
  Eigen::VectorXd forward = home;
  while ((arm.CameraPose(forward).translation() - eye).norm() < 0.01) forward[1] += 0.0005;
  const mapping::OccupancyGrid unknown;
  for (const double start_clearance : {0.0, 0.02, 0.05}) {
    SCOPED_TRACE(start_clearance);
    CollisionOptions options;
    options.field.start_clearance_m = start_clearance;
    CollisionChecker checker = CollisionChecker::Create(DefaultGeometry(), {}, options).value();
    checker.MarkStart(home);
    ASSERT_TRUE(checker.SetMap(unknown, roi).ok());
    // Measured: 3.9, 23.3 and 54.3 mm.
    EXPECT_GE(checker.MapClearance(home), start_clearance);
    EXPECT_LE(checker.MapClearance(home), start_clearance + options.field.resolution_m);
    EXPECT_EQ(checker.IsFree(home), start_clearance >= options.margin_m);
    const MotionPlanner planner(checker, MotionOptions{});
    Rng rng(3);
    const MotionPlan into = planner.Plan(home, forward, rng);
    if (start_clearance == 0.0) {
      EXPECT_NE(into.status.message().find("the goal is in collision (map"), std::string::npos)
          << into.status.ToString();
    } else if (start_clearance == 0.05) {
      EXPECT_TRUE(into.ok()) << into.status.ToString();
    }
  }
}

}  // namespace
}  // namespace avp::motion

// PredefinedPlanner: the reference's narrow and wide zig-zag waypoints (in limits, in order, the
// narrow set looking along +x), the generic zig-zag from an ROI (reachable, looking at the ROI),
// exhaustion and out-of-limit waypoints as NotFound.
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/ray.h>
#include <avp/core/rng.h>
#include <avp/planning/predefined_planner.h>
#include <avp/robot/arm_model.h>

namespace avp::planning {
namespace {

using ::testing::HasSubstr;
using Set = PredefinedOptions::Set;

const robot::ArmModel& Arm() {
  static const robot::ArmModel model = robot::LoadDefaultArm(AVP_CONFIG_DIR).value();
  return model;
}

Eigen::VectorXd DegToRadVec(const Eigen::VectorXd& deg) { return deg * (EIGEN_PI / 180.0); }

/// A request at the reference start pose (view 1 of an 8-view episode).
PlanningRequest StartRequest(const mapping::SemanticMap& map, const robot::ArmModel& arm) {
  PlanningRequest r;
  r.map = &map;
  r.arm = &arm;
  r.q_start = arm.FromReferenceJoints(DegToRadVec(ReferenceStartJointsDeg()));
  r.q_current = r.q_start;
  r.X_WC_start = arm.CameraPose(r.q_start);
  r.X_WC_current = r.X_WC_start;
  r.K = CameraIntrinsics::RealSenseD435();
  r.roi = Box3(Eigen::Vector3d(0.55, -0.2, 0.3), Eigen::Vector3d(0.85, 0.2, 0.9));
  r.view_index = 1;
  r.views_total = 8;
  r.fused_views = {r.X_WC_start};
  return r;
}

TEST(PredefinedPlannerTest, ReferenceStartPoseIsTheArmsHome) {
  const Eigen::VectorXd q = Arm().FromReferenceJoints(DegToRadVec(ReferenceStartJointsDeg()));
  Eigen::VectorXd expected(6);
  expected << 0, -70, 60, 0, 47.5, 0;
  EXPECT_TRUE(q.isApprox(DegToRadVec(expected), 1e-12));
  EXPECT_TRUE(q.isApprox(Arm().home_joints(), 1e-12));
}

TEST(PredefinedPlannerTest, NarrowSetPlaysStartThenP1ToP7LookingAlongPlusX) {
  const mapping::SemanticMap map;
  PredefinedPlanner planner;  // narrow is the default
  EXPECT_EQ(planner.name(), "predefined");
  EXPECT_EQ(planner.options().set, Set::kNarrow);
  const std::vector<Eigen::VectorXd> waypoints = ReferenceWaypointsDeg(Set::kNarrow);
  ASSERT_EQ(waypoints.size(), 8u);
  Eigen::VectorXd p1(6);
  p1 << -65, 19, 1, 66, 82, -18;
  EXPECT_EQ(waypoints[0], p1);

  PlanningRequest request = StartRequest(map, Arm());
  Rng rng(1);
  // An episode of 8 fused views: view 0 is the start, views 1..7 are p1..p7.
  double previous_z = 10.0;
  for (int view = 1; view <= 8; ++view) {
    request.view_index = view;
    const PlanResult plan = planner.Plan(request, rng);
    ASSERT_TRUE(plan.status.ok()) << plan.status.ToString();
    ASSERT_EQ(plan.ranked.size(), 1u);
    EXPECT_EQ(plan.generated, 1u);
    EXPECT_EQ(plan.reachable, 1u);
    EXPECT_FALSE(plan.stop);
    const ViewCandidate& c = plan.ranked[0];
    const Eigen::VectorXd q = Arm().FromReferenceJoints(DegToRadVec(waypoints[view - 1]));
    EXPECT_TRUE(c.q.isApprox(q, 1e-12)) << "view " << view;
    EXPECT_TRUE(Arm().WithinLimits(c.q)) << "view " << view;
    EXPECT_TRUE(c.reachable);
    EXPECT_EQ(c.source, "waypoint");
    EXPECT_NEAR(c.cost, (q - request.q_current).norm(), 1e-12);
    // Camera on the plane x = 0.224 m, looking along +x, image upright, alternating
    // y < 0 (p1, p3, ...) and y > 0, descending.
    const RigidTransform& X = c.X_WC;
    EXPECT_TRUE(X.translation().isApprox(Arm().CameraPose(q).translation(), 1e-12));
    EXPECT_GT(X.rotation().col(2).x(), std::cos(DegToRad(3.0))) << "view " << view;
    EXPECT_GT(-X.rotation().col(1).z(), std::cos(DegToRad(3.0))) << "view " << view;
    EXPECT_NEAR(X.translation().x(), 0.224, 0.005) << "view " << view;
    EXPECT_EQ(X.translation().y() < 0.0, view % 2 == 1) << "view " << view;
    EXPECT_LT(X.translation().z(), previous_z) << "view " << view;
    previous_z = X.translation().z();
    // The next view starts where this one went.
    request.q_current = c.q;
    request.X_WC_current = c.X_WC;
    request.fused_views.push_back(c.X_WC);
  }
  // Exhausted: the set has p1..p8 only.
  request.view_index = 9;
  const PlanResult exhausted = planner.Plan(request, rng);
  EXPECT_EQ(exhausted.status.code(), StatusCode::kNotFound);
  EXPECT_THAT(exhausted.status.message(), HasSubstr("exhausted"));
  EXPECT_THAT(exhausted.status.message(), HasSubstr("view_index 9"));
  EXPECT_THAT(exhausted.status.message(), HasSubstr("8 waypoints"));
  EXPECT_TRUE(exhausted.ranked.empty());
}

TEST(PredefinedPlannerTest, WideSetIsInLimitsAndWiderThanTheNarrowOne) {
  const mapping::SemanticMap map;
  PredefinedOptions options;
  options.set = Set::kWide;
  PredefinedPlanner planner(options);
  PlanningRequest request = StartRequest(map, Arm());
  Rng rng(2);
  const std::vector<Eigen::VectorXd> wide = ReferenceWaypointsDeg(Set::kWide);
  const std::vector<Eigen::VectorXd> narrow = ReferenceWaypointsDeg(Set::kNarrow);
  ASSERT_EQ(wide.size(), 8u);
  Eigen::VectorXd p8(6);
  p8 << 72, 10, 116, -100, 77, 128;
  EXPECT_EQ(wide[7], p8);
  for (int view = 1; view <= 8; ++view) {
    request.view_index = view;
    const PlanResult plan = planner.Plan(request, rng);
    ASSERT_TRUE(plan.status.ok()) << plan.status.ToString();
    ASSERT_EQ(plan.ranked.size(), 1u);
    const ViewCandidate& c = plan.ranked[0];
    EXPECT_TRUE(c.q.isApprox(Arm().FromReferenceJoints(DegToRadVec(wide[view - 1])), 1e-12));
    EXPECT_TRUE(Arm().WithinLimits(c.q));
    const RigidTransform X_narrow =
        Arm().CameraPose(Arm().FromReferenceJoints(DegToRadVec(narrow[view - 1])));
    const Eigen::Vector3d& p = c.X_WC.translation();
    std::printf("[ wide ] p%d camera xyz (%.3f, %.3f, %.3f) m, optical z (%.3f, %.3f, %.3f)\n",
                view, p.x(), p.y(), p.z(), c.X_WC.rotation()(0, 2), c.X_WC.rotation()(1, 2),
                c.X_WC.rotation()(2, 2));
    // Same side as the narrow waypoint, farther out, and facing the plant (+x).
    EXPECT_EQ(p.y() < 0.0, view % 2 == 1) << "view " << view;
    EXPECT_GT(std::abs(p.y()), std::abs(X_narrow.translation().y())) << "view " << view;
    EXPECT_GT(c.X_WC.rotation().col(2).x(), std::cos(DegToRad(3.0))) << "view " << view;
  }
}

TEST(PredefinedPlannerTest, GenericZigZagPosesAlternateClimbAndFaceTheRoi) {
  const Box3 roi(Eigen::Vector3d(0.55, -0.2, 0.3), Eigen::Vector3d(0.85, 0.2, 0.9));
  PredefinedOptions options;
  options.generic_lateral_fraction = 0.6;
  options.generic_bottom_fraction = 0.25;
  options.generic_top_fraction = 0.8;
  const std::vector<RigidTransform> poses = GenericZigZagPoses(roi, 7, options);
  ASSERT_EQ(poses.size(), 7u);
  for (size_t i = 0; i < poses.size(); ++i) {
    const Eigen::Vector3d& p = poses[i].translation();
    // On the plane 0.45 m before the axis x = 0.7: x = 0.25; y = -+0.6 * 0.2.
    EXPECT_NEAR(p.x(), 0.25, 1e-12) << i;
    EXPECT_NEAR(p.y(), i % 2 == 0 ? -0.12 : 0.12, 1e-12) << i;
    // Climbing from 0.3 + 0.25 * 0.6 = 0.45 to 0.3 + 0.8 * 0.6 = 0.78 in 6 equal steps.
    EXPECT_NEAR(p.z(), 0.45 + 0.055 * static_cast<double>(i), 1e-12) << i;
    // Looking horizontally at the axis point (0.7, 0, z), image upright.
    const Eigen::Vector3d toward = (Eigen::Vector3d(0.7, 0.0, p.z()) - p).normalized();
    EXPECT_TRUE(poses[i].rotation().col(2).isApprox(toward, 1e-12)) << i;
    EXPECT_NEAR(poses[i].rotation().col(1).z(), -1.0, 1e-12) << i;
  }
  // An ROI off the x axis: the plane faces it from the base.
  const Box3 side(Eigen::Vector3d(-0.1, 0.5, 0.2), Eigen::Vector3d(0.1, 0.7, 0.6));
  const std::vector<RigidTransform> side_poses = GenericZigZagPoses(side, 1, options);
  ASSERT_EQ(side_poses.size(), 1u);
  const Eigen::Vector3d eye = side_poses[0].translation();
  EXPECT_NEAR(eye.y(), 0.6 - 0.45, 1e-12);
  EXPECT_NEAR(eye.x(), 0.6 * 0.1, 1e-12);  // the camera's right, looking along +y, is +x
  EXPECT_NEAR(eye.z(), 0.2 + 0.25 * 0.4, 1e-12);
  EXPECT_TRUE(side_poses[0].rotation().col(2).isApprox(
      (Eigen::Vector3d(0.0, 0.6, eye.z()) - eye).normalized(), 1e-12));
  EXPECT_TRUE(GenericZigZagPoses(roi, 0, options).empty());
  EXPECT_THROW(GenericZigZagPoses(Box3(), 3, options), Error);
}

TEST(PredefinedPlannerTest, GenericZigZagGivesReachableViewsThatLookAtTheRoi) {
  const mapping::SemanticMap map;
  PredefinedOptions options;
  options.set = Set::kGeneric;
  PredefinedPlanner planner(options);
  PlanningRequest request = StartRequest(map, Arm());
  Rng rng(3);
  const PredefinedPlanner::Waypoints& w = planner.WaypointsFor(request, rng);
  EXPECT_EQ(w.q.size() + w.dropped, 7u);
  EXPECT_EQ(w.dropped, 0u) << "all seven generic poses are reachable for this ROI";
  int right = 0, left = 0;
  for (int view = 1; view <= 7; ++view) {
    request.view_index = view;
    const PlanResult plan = planner.Plan(request, rng);
    ASSERT_TRUE(plan.status.ok()) << plan.status.ToString();
    ASSERT_EQ(plan.ranked.size(), 1u);
    const ViewCandidate& c = plan.ranked[0];
    EXPECT_TRUE(c.reachable);
    EXPECT_TRUE(Arm().WithinLimits(c.q));
    EXPECT_TRUE(c.X_WC.IsNearlyEqualTo(Arm().CameraPose(c.q), 1e-9, 1e-9));
    // The IK solution reaches the generated pose.
    const RigidTransform goal = GenericZigZagPoses(request.roi, 7, options)[view - 1];
    EXPECT_TRUE(c.X_WC.IsNearlyEqualTo(goal, 2e-4, 2e-3)) << "view " << view;
    // Outside the ROI, and its optical axis passes through the ROI.
    EXPECT_FALSE(request.roi.Contains(c.X_WC.translation()));
    const Ray axis = Ray::FromDirection(c.X_WC.translation(), c.X_WC.rotation().col(2));
    EXPECT_TRUE(request.roi.Intersect(axis).has_value()) << "view " << view;
    (c.X_WC.translation().y() < 0.0 ? right : left)++;
    request.q_current = c.q;
    request.X_WC_current = c.X_WC;
  }
  EXPECT_EQ(right, 4);
  EXPECT_EQ(left, 3);
  request.view_index = 8;
  const PlanResult exhausted = planner.Plan(request, rng);
  EXPECT_EQ(exhausted.status.code(), StatusCode::kNotFound);
  EXPECT_THAT(exhausted.status.message(), HasSubstr("generic"));

  // Up to 0.95 of the ROI's height: the top pose (horizontal, high) is out of reach, so it is
  // pulled towards the start camera (lower, less lateral) until the arm reaches it; the others
  // stay where they were generated.
  PredefinedOptions high = options;
  high.generic_top_fraction = 0.95;
  PredefinedPlanner high_planner(high);
  PlanningRequest high_request = StartRequest(map, Arm());
  const PredefinedPlanner::Waypoints& hw = high_planner.WaypointsFor(high_request, rng);
  const std::vector<RigidTransform> high_poses = GenericZigZagPoses(high_request.roi, 7, high);
  ASSERT_FALSE(Arm().IsReachable(high_poses[6]));
  ASSERT_EQ(hw.q.size(), 7u);
  EXPECT_EQ(hw.dropped, 0u);
  for (size_t i = 0; i < 6; ++i) {
    EXPECT_TRUE(Arm().CameraPose(hw.q[i]).IsNearlyEqualTo(high_poses[i], 2e-4, 2e-3)) << i;
  }
  const Eigen::Vector3d pulled = Arm().CameraPose(hw.q[6]).translation();
  const Eigen::Vector3d start = high_request.X_WC_start.translation();
  EXPECT_LT((pulled - start).norm(), (high_poses[6].translation() - start).norm());
  EXPECT_LT(pulled.z(), high_poses[6].translation().z());

  // An ROI out of reach: every generic pose is dropped, and the planner says so.
  PlanningRequest far = StartRequest(map, Arm());
  far.roi = Box3(Eigen::Vector3d(2.5, -0.2, 0.3), Eigen::Vector3d(2.8, 0.2, 0.9));
  PredefinedPlanner far_planner(options);
  const PlanResult none = far_planner.Plan(far, rng);
  EXPECT_EQ(none.status.code(), StatusCode::kNotFound);
  EXPECT_THAT(none.status.message(), HasSubstr("7 unreachable generic poses dropped"));
}

TEST(PredefinedPlannerTest, OutOfLimitWaypointIsNotFound) {
  auto config =
      robot::ArmConfig::LoadYaml(std::string(AVP_CONFIG_DIR) + "/arms/igus_rebel_d435.yaml");
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  config->joint_limit_overrides.push_back({"joint1", DegToRad(-10.0), DegToRad(10.0)});
  const auto arm = robot::ArmModel::Create(*config);
  ASSERT_TRUE(arm.ok()) << arm.status().ToString();
  const mapping::SemanticMap map;
  PredefinedPlanner planner;
  PlanningRequest request = StartRequest(map, *arm);
  Rng rng(4);
  const PlanResult plan = planner.Plan(request, rng);  // p1 has joint1 = 65 deg (URDF)
  EXPECT_EQ(plan.status.code(), StatusCode::kNotFound);
  EXPECT_THAT(plan.status.message(), HasSubstr("p1 is outside the joint limits"));
  EXPECT_THAT(plan.status.message(), HasSubstr("joint1"));
  EXPECT_TRUE(plan.ranked.empty());
}

TEST(PredefinedPlannerTest, RejectsBadRequestsAndOptions) {
  const mapping::SemanticMap map;
  PredefinedPlanner planner;
  PlanningRequest request = StartRequest(map, Arm());
  request.arm = nullptr;
  Rng rng(5);
  const PlanResult plan = planner.Plan(request, rng);
  EXPECT_EQ(plan.status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(plan.status.message(), HasSubstr("arm must not be null"));
  PredefinedOptions bad;
  bad.generic_distance_m = -1.0;
  bad.generic_bottom_fraction = 0.8;
  bad.generic_top_fraction = 0.5;
  EXPECT_THAT(bad.Validate().message(), HasSubstr("generic_distance_m (-1 m) must be > 0"));
  EXPECT_THAT(bad.Validate().message(), HasSubstr("generic_bottom_fraction (0.8) must be <="));
  EXPECT_THROW(PredefinedPlanner{bad}, Error);
  EXPECT_EQ(PredefinedSetFromString("wide"), Set::kWide);
  EXPECT_EQ(PredefinedSetFromString("square"), std::nullopt);
  EXPECT_EQ(ToString(Set::kGeneric), "generic");
}

}  // namespace
}  // namespace avp::planning

#include <cmath>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include <avp/core/rng.h>
#include <avp/robot/arm.h>
#include <avp/sim/sim_arm.h>

#include "test_util.h"

namespace avp::robot {
namespace {

using sim::SimArm;
using testing::DefaultArm;
using testing::Deg;

TEST(SimArmTest, StartsAtHome) {
  const SimArm arm(DefaultArm());
  EXPECT_EQ(arm.CurrentJoints(), DefaultArm().home_joints());
  EXPECT_TRUE(arm.CurrentCameraPose().IsNearlyEqualTo(
      DefaultArm().CameraPose(DefaultArm().home_joints()), 1e-12, 1e-12));
  EXPECT_EQ(arm.num_moves(), 0);
  EXPECT_EQ(arm.total_joint_path_length(), 0.0);
}

TEST(SimArmTest, MovesAndRecordsPathLength) {
  SimArm arm(DefaultArm(), Eigen::VectorXd::Zero(6));
  const Eigen::VectorXd a = Deg({30, 0, 0, 0, 0, 0});
  const Eigen::VectorXd b = Deg({30, 40, 0, 0, 0, 0});
  const MoveResult ma = arm.MoveToJoints(a);
  ASSERT_TRUE(ma.ok()) << ma.status.ToString();
  EXPECT_NEAR(ma.joint_path_length, DegToRad(30), 1e-12);
  EXPECT_EQ(ma.q, a);
  const MoveResult mb = arm.MoveToJoints(b);
  ASSERT_TRUE(mb.ok());
  EXPECT_NEAR(mb.joint_path_length, DegToRad(40), 1e-12);
  EXPECT_EQ(arm.CurrentJoints(), b);
  // Back to zero: a diagonal move of length sqrt(30² + 40²) = 50°.
  const MoveResult mc = arm.MoveToJoints(Eigen::VectorXd::Zero(6));
  EXPECT_NEAR(mc.joint_path_length, DegToRad(50), 1e-12);
  EXPECT_EQ(arm.num_moves(), 3);
  EXPECT_NEAR(arm.total_joint_path_length(), DegToRad(120), 1e-12);
  EXPECT_EQ(arm.num_refused_moves(), 0);
}

TEST(SimArmTest, RefusesOutOfLimitJointsNamingTheValue) {
  SimArm arm(DefaultArm());
  const Eigen::VectorXd before = arm.CurrentJoints();
  const MoveResult r = arm.MoveToJoints(Deg({0, 0, 0, 0, 120, 0}));
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(r.status.code(), StatusCode::kOutOfRange);
  EXPECT_NE(r.status.message().find("joint5"), std::string::npos) << r.status.message();
  EXPECT_NE(r.status.message().find("120.000 deg"), std::string::npos) << r.status.message();
  EXPECT_NE(r.status.message().find("102.500"), std::string::npos) << r.status.message();
  EXPECT_EQ(r.joint_path_length, 0.0);
  EXPECT_EQ(r.q, before);
  EXPECT_EQ(arm.CurrentJoints(), before);
  EXPECT_EQ(arm.num_moves(), 0);
  EXPECT_EQ(arm.num_refused_moves(), 1);
  // A huge angle is named in six digits, not echoed as a 300-digit number.
  const MoveResult huge = arm.MoveToJoints(Deg({1e300, 0, 0, 0, 0, 0}));
  EXPECT_FALSE(huge.ok());
  EXPECT_NE(huge.status.message().find("(1e+300 deg)"), std::string::npos) << huge.status.message();
  EXPECT_LT(huge.status.message().size(), 300u) << huge.status.message();
}

TEST(SimArmTest, RefusesNaNAndWrongSize) {
  SimArm arm(DefaultArm());
  const Eigen::VectorXd before = arm.CurrentJoints();
  Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  q[3] = std::numeric_limits<double>::quiet_NaN();
  const MoveResult r = arm.MoveToJoints(q);
  EXPECT_EQ(r.status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status.message().find("joint4"), std::string::npos) << r.status.message();
  EXPECT_NE(r.status.message().find("nan"), std::string::npos) << r.status.message();
  const MoveResult s = arm.MoveToJoints(Eigen::VectorXd::Zero(4));
  EXPECT_EQ(s.status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.status.message().find("4 entries"), std::string::npos) << s.status.message();
  EXPECT_EQ(arm.CurrentJoints(), before);
  EXPECT_EQ(arm.num_refused_moves(), 2);
}

TEST(SimArmTest, MovesCameraToReachablePose) {
  SimArm arm(DefaultArm());
  Rng rng(42);
  const Eigen::VectorXd q_goal = Deg({-20, -60, 70, 15, 40, 10});
  const RigidTransform X_WC = DefaultArm().CameraPose(q_goal);
  const MoveResult r = arm.MoveToCameraPose(X_WC, rng);
  ASSERT_TRUE(r.ok()) << r.status.ToString();
  EXPECT_TRUE(arm.CurrentCameraPose().IsNearlyEqualTo(X_WC, 2e-4, 1e-3));
  EXPECT_NEAR(r.joint_path_length, (r.q - DefaultArm().home_joints()).norm(), 1e-12);
  EXPECT_EQ(arm.num_moves(), 1);
}

TEST(SimArmTest, RefusesUnreachableCameraPose) {
  SimArm arm(DefaultArm());
  Rng rng(43);
  const Eigen::VectorXd before = arm.CurrentJoints();
  const MoveResult r = arm.MoveToCameraPose(RigidTransform(Eigen::Vector3d(3, 0, 0)), rng);
  EXPECT_EQ(r.status.code(), StatusCode::kUnreachable);
  EXPECT_NE(r.status.message().find("camera target"), std::string::npos) << r.status.message();
  EXPECT_EQ(arm.CurrentJoints(), before);
  EXPECT_EQ(arm.num_moves(), 0);
  EXPECT_EQ(arm.num_refused_moves(), 1);
}

TEST(SimArmTest, InvalidInitialJointsThrow) {
  try {
    SimArm arm(DefaultArm(), Deg({0, 0, 0, 0, 0, 200}));
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("joint6"), std::string::npos) << e.what();
  }
}

// Plays the reference's narrow zig-zag through the Arm interface: all moves succeed.
TEST(SimArmTest, PlaysReferenceZigZag) {
  SimArm arm(DefaultArm());
  const std::vector<std::vector<double>> waypoints_deg = {
      {-65, 19, 1, 66, 82, -18},    {64, -7, 50, -70, 73, 40},    {-65, -14, 66, 74, 70, -49},
      {64, -23, 87, -78, 68, 61},   {-65, -26, 96, 81, 66, -68},  {64, -31, 113, -86, 65, 81},
      {-65, -30, 118, 89, 65, -87}, {65, -30, 133, -96, 66, 105},
  };
  for (const auto& w : waypoints_deg) {
    const Eigen::VectorXd q =
        DefaultArm().FromReferenceJoints(Deg({w[0], w[1], w[2], w[3], w[4], w[5]}));
    const MoveResult r = arm.MoveToJoints(q);
    EXPECT_TRUE(r.ok()) << r.status.ToString();
  }
  EXPECT_EQ(arm.num_moves(), 8);
  EXPECT_GT(arm.total_joint_path_length(), 0.0);
}

}  // namespace
}  // namespace avp::robot

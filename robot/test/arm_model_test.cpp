#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <avp/core/rng.h>
#include <avp/robot/arm_model.h>

#include "test_util.h"

namespace avp::robot {
namespace {

using testing::DefaultArm;
using testing::Deg;
using testing::PosesNear;

constexpr double kTol = 1e-9;  // the hand formulas below are exact

Eigen::Matrix3d Ry(double rad) { return Eigen::AngleAxisd(rad, Eigen::Vector3d::UnitY()).matrix(); }
Eigen::Matrix3d Rz(double rad) { return Eigen::AngleAxisd(rad, Eigen::Vector3d::UnitZ()).matrix(); }

// The ReBeL by hand, from the joint table in docs/robot.md, for q4 = q6 = 0: joint1 turns about
// −z; joints 2, 3, 5 pitch about y with the baked offsets +30°, +30°, −7.5°; the link lengths
// between them are 0.249 (base → joint2), 0.2384, 0.289 (0.119 + 0.170) and 0.122 (0.1208 +
// 0.0012) m; the flange is pitched −90° from link_8.
RigidTransform HandFk(const Eigen::VectorXd& q) {
  const double t2 = DegToRad(30.0) + q[1];
  const double t3 = t2 + DegToRad(30.0) + q[2];
  const double t5 = t3 - DegToRad(7.5) + q[4];
  const Eigen::Vector3d p_planar(
      0.2384 * std::sin(t2) + 0.289 * std::sin(t3) + 0.122 * std::sin(t5), 0.0,
      0.249 + 0.2384 * std::cos(t2) + 0.289 * std::cos(t3) + 0.122 * std::cos(t5));
  const Eigen::Matrix3d R_yaw = Rz(-q[0]);
  return RigidTransform(R_yaw * Ry(t5 - DegToRad(90.0)), R_yaw * p_planar);
}

TEST(ArmModelTest, DefaultArmStructure) {
  const ArmModel& arm = DefaultArm();
  ASSERT_EQ(arm.num_joints(), 6);
  EXPECT_EQ(arm.joint_names(),
            (std::vector<std::string>{"joint1", "joint2", "joint3", "joint4", "joint5", "joint6"}));
  EXPECT_EQ(arm.base_link(), "base_link");
  EXPECT_EQ(arm.tip_link(), "flange");
  const Eigen::VectorXd lower = Deg({-179, -110, -110, -179, -87.5, -179});
  const Eigen::VectorXd upper = Deg({179, 110, 110, 179, 102.5, 179});
  EXPECT_TRUE(arm.lower_limits().isApprox(lower, 1e-12)) << arm.lower_limits().transpose();
  EXPECT_TRUE(arm.upper_limits().isApprox(upper, 1e-12)) << arm.upper_limits().transpose();
  for (const JointInfo& j : arm.joints()) {
    EXPECT_EQ(j.type, JointType::kRevolute) << j.name;
    EXPECT_NEAR(j.velocity_limit, EIGEN_PI / 4.0, 1e-12) << j.name;
  }
  EXPECT_TRUE(arm.home_joints().isApprox(Deg({0, -70, 60, 0, 47.5, 0}), 1e-12));
  // Stack height 0.8984 m: 0.100 above the base origin, 0.7984 m of links after joint1.
  EXPECT_NEAR(arm.max_reach_m(), 0.7984, 1e-9);
}

TEST(ArmModelTest, UrdfZeroPose) {
  const RigidTransform X_WF = DefaultArm().ForwardKinematics(Eigen::VectorXd::Zero(6));
  EXPECT_NEAR(X_WF.translation().x(), 0.466, 1e-3);
  EXPECT_NEAR(X_WF.translation().y(), 0.0, 1e-12);
  EXPECT_NEAR(X_WF.translation().z(), 0.674, 1e-3);
  // Pitched 52.5° towards +x: the flange x axis is 37.5° above the horizontal.
  const Eigen::Vector3d x_F = X_WF.rotation().col(0);
  EXPECT_TRUE(
      x_F.isApprox(Eigen::Vector3d(std::cos(DegToRad(37.5)), 0, std::sin(DegToRad(37.5))), 1e-12))
      << x_F.transpose();
  EXPECT_TRUE(PosesNear(X_WF, HandFk(Eigen::VectorXd::Zero(6)), kTol));
}

TEST(ArmModelTest, CandlePoseIsStraightUp) {
  const RigidTransform X_WF = DefaultArm().ForwardKinematics(Deg({0, -30, -30, 0, 7.5, 0}));
  EXPECT_NEAR((X_WF.translation() - Eigen::Vector3d(0, 0, 0.8984)).norm(), 0.0, 1e-12)
      << X_WF.translation().transpose();
  EXPECT_TRUE(X_WF.rotation().col(0).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));   // x up
  EXPECT_TRUE(X_WF.rotation().col(2).isApprox(-Eigen::Vector3d::UnitX(), 1e-12));  // z along −x
}

TEST(ArmModelTest, HandComputedPoses) {
  const ArmModel& arm = DefaultArm();
  struct Case {
    Eigen::VectorXd q;
    Eigen::Vector3d p_WF;
    Eigen::Matrix3d R_WF;
  };
  const std::vector<Case> cases = {
      // joint1 = +90° about −z swings the zero pose from +x to −y.
      {Deg({90, 0, 0, 0, 0, 0}),
       {0.0, -0.4662704, 0.6742294},
       Rz(-EIGEN_PI / 2) * Ry(DegToRad(-37.5))},
      // Upper arm, forearm and wrist horizontal along +x: 0.2384 + 0.289 + 0.122 at the shoulder
      // height 0.249; the flange frame is then aligned with the base.
      {Deg({0, 60, -30, 0, 7.5, 0}), {0.6494, 0.0, 0.249}, Eigen::Matrix3d::Identity()},
      // Candle with the wrist pitched 90°: the last 0.122 m point along +x.
      {Deg({0, -30, -30, 0, 97.5, 0}), {0.122, 0.0, 0.7764}, Eigen::Matrix3d::Identity()},
      // Candle with joint4 = 90° first: the same wrist pitch now points the last 0.122 m along +y.
      {Deg({0, -30, -30, 90, 97.5, 0}), {0.0, 0.122, 0.7764}, Rz(EIGEN_PI / 2)},
      // Candle with joint6 = 90°: flange x still up, flange z turned from −x to −y.
      {Deg({0, -30, -30, 0, 7.5, 90}), {0.0, 0.0, 0.8984}, Rz(EIGEN_PI / 2) * Ry(-EIGEN_PI / 2)},
  };
  for (const Case& c : cases) {
    const RigidTransform X_WF = arm.ForwardKinematics(c.q);
    EXPECT_LT((X_WF.translation() - c.p_WF).norm(), 1e-6)
        << "q = " << c.q.transpose() << ": " << X_WF.translation().transpose();
    EXPECT_LT(X_WF.AngleTo(RigidTransform(c.R_WF, c.p_WF)), 1e-9) << "q = " << c.q.transpose();
  }
}

TEST(ArmModelTest, MatchesHandModelOnRandomPlanarPoses) {
  const ArmModel& arm = DefaultArm();
  Rng rng(7);
  for (int k = 0; k < 200; ++k) {
    Eigen::VectorXd q = arm.RandomJoints(rng);
    q[3] = 0.0;
    q[5] = 0.0;
    const RigidTransform X_WF = arm.ForwardKinematics(q);
    const RigidTransform expected = HandFk(q);
    ASSERT_TRUE(PosesNear(X_WF, expected, 1e-12)) << "q = " << q.transpose();
  }
}

TEST(ArmModelTest, FkPreconditionsNameTheValues) {
  const ArmModel& arm = DefaultArm();
  try {
    (void)arm.ForwardKinematics(Eigen::VectorXd::Zero(5));
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("q.size() = 5"), std::string::npos) << e.what();
  }
  Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  q[2] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW((void)arm.ForwardKinematics(q), Error);
}

TEST(ArmModelTest, DefaultCameraMount) {
  const RigidTransform X_FC = DefaultArm().X_FC();
  EXPECT_TRUE(X_FC.IsNearlyEqualTo(CameraMount::DefaultX_FC(), 1e-12, 1e-9));
  const Eigen::Matrix3d& R_FC = X_FC.rotation();
  EXPECT_TRUE(R_FC.col(0).isApprox(-Eigen::Vector3d::UnitY(), 1e-12));  // x_C = −y_F
  EXPECT_TRUE(R_FC.col(1).isApprox(-Eigen::Vector3d::UnitZ(), 1e-12));  // y_C = −z_F
  EXPECT_TRUE(R_FC.col(2).isApprox(Eigen::Vector3d::UnitX(), 1e-12));   // z_C = x_F
  EXPECT_TRUE(X_FC.translation().isApprox(Eigen::Vector3d(0.03, 0, 0.06), 1e-12));
}

TEST(ArmModelTest, CameraPoseIsFlangeTimesMount) {
  const ArmModel& arm = DefaultArm();
  Rng rng(11);
  for (int k = 0; k < 20; ++k) {
    const Eigen::VectorXd q = arm.RandomJoints(rng);
    const RigidTransform expected = arm.ForwardKinematics(q) * arm.X_FC();
    EXPECT_TRUE(PosesNear(arm.CameraPose(q), expected, 1e-12));
  }
}

// The reference system's initial pose (0, −40, 90, 0, 40, 0)° is (0, −70, 60, 0, 47.5, 0)° in URDF
// joints: flange at (0.190, 0, 0.617) m aligned with the base, so the camera looks along +x with
// image right = −y and image down = −z.
TEST(ArmModelTest, ReferenceInitialPose) {
  const ArmModel& arm = DefaultArm();
  const Eigen::VectorXd q = arm.FromReferenceJoints(Deg({0, -40, 90, 0, 40, 0}));
  EXPECT_TRUE(q.isApprox(Deg({0, -70, 60, 0, 47.5, 0}), 1e-12)) << q.transpose();
  EXPECT_TRUE(arm.ToReferenceJoints(q).isApprox(Deg({0, -40, 90, 0, 40, 0}), 1e-12));

  const RigidTransform X_WF = arm.ForwardKinematics(q);
  EXPECT_NEAR(X_WF.translation().x(), 0.190, 1e-3);
  EXPECT_NEAR(X_WF.translation().y(), 0.0, 1e-12);
  EXPECT_NEAR(X_WF.translation().z(), 0.617, 1e-3);
  EXPECT_LT(X_WF.AngleTo(RigidTransform::Identity()), 1e-12);

  const RigidTransform X_WC = arm.CameraPose(q);
  // (0.2384 sin(−40°) + 0.289 sin 50° + 0.122 + 0.03, 0, 0.249 + 0.2384 cos 40° + 0.289 cos 50° +
  // 0.06)
  EXPECT_LT((X_WC.translation() - Eigen::Vector3d(0.2201462, 0.0, 0.6773906)).norm(), 1e-6)
      << X_WC.translation().transpose();
  EXPECT_TRUE(X_WC.rotation().col(2).isApprox(Eigen::Vector3d::UnitX(), 1e-12));
  EXPECT_TRUE(X_WC.rotation().col(0).isApprox(-Eigen::Vector3d::UnitY(), 1e-12));
  EXPECT_TRUE(X_WC.rotation().col(1).isApprox(-Eigen::Vector3d::UnitZ(), 1e-12));
}

// zig_zag_plane_narrow (reference-system.md §4.7), reference convention, degrees.
const std::vector<std::vector<double>> kZigZagNarrowDeg = {
    {-65, 19, 1, 66, 82, -18},    {64, -7, 50, -70, 73, 40},    {-65, -14, 66, 74, 70, -49},
    {64, -23, 87, -78, 68, 61},   {-65, -26, 96, 81, 66, -68},  {64, -31, 113, -86, 65, 81},
    {-65, -30, 118, 89, 65, -87}, {65, -30, 133, -96, 66, 105},
};

// Every narrow zig-zag waypoint, converted, is within the URDF limits and puts the camera on a
// vertical plane at x ≈ 0.22 m looking along +x with the image upright, alternating between
// y ≈ −0.16 and +0.15 m while descending from z ≈ 0.80 to 0.45 m. This is what pins down the
// convention's joint1 sign: without it the camera would look sideways and backwards.
TEST(ArmModelTest, ReferenceZigZagLooksAlongPlusX) {
  const ArmModel& arm = DefaultArm();
  double previous_z = 1.0;
  for (size_t i = 0; i < kZigZagNarrowDeg.size(); ++i) {
    const std::vector<double>& w = kZigZagNarrowDeg[i];
    const Eigen::VectorXd q_ref = Deg({w[0], w[1], w[2], w[3], w[4], w[5]});
    const Eigen::VectorXd q = arm.FromReferenceJoints(q_ref);
    ASSERT_TRUE(arm.WithinLimits(q)) << "p" << i + 1 << ": " << arm.CheckJoints(q).ToString();
    const RigidTransform X_WC = arm.CameraPose(q);
    const Eigen::Vector3d& p = X_WC.translation();
    std::printf("[ zig-zag ] p%zu camera xyz (%.3f, %.3f, %.3f) m, optical z (%.3f, %.3f, %.3f)\n",
                i + 1, p.x(), p.y(), p.z(), X_WC.rotation()(0, 2), X_WC.rotation()(1, 2),
                X_WC.rotation()(2, 2));
    EXPECT_GT(X_WC.rotation().col(2).x(), std::cos(DegToRad(3.0))) << "p" << i + 1;
    EXPECT_GT(-X_WC.rotation().col(0).y(), std::cos(DegToRad(3.0))) << "p" << i + 1;
    EXPECT_NEAR(p.x(), 0.224, 0.005) << "p" << i + 1;
    EXPECT_NEAR(std::abs(p.y()), 0.153, 0.01) << "p" << i + 1;
    EXPECT_EQ(p.y() < 0.0, i % 2 == 0) << "p" << i + 1;
    EXPECT_LT(p.z(), previous_z) << "p" << i + 1;
    previous_z = p.z();

    // Keeping the reference's joint1 sign instead looks ~130° away from +x.
    Eigen::VectorXd q_wrong_sign = q;
    q_wrong_sign[0] = -q[0];
    EXPECT_LT(arm.CameraPose(q_wrong_sign).rotation().col(2).x(), -0.5) << "p" << i + 1;
  }
  EXPECT_GT(previous_z, 0.4);
}

}  // namespace
}  // namespace avp::robot

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include <avp/robot/trajectory.h>

#include "test_util.h"

namespace avp::robot {
namespace {

using testing::DefaultArm;
using testing::Deg;

constexpr double kV = EIGEN_PI / 4.0;  // the ReBeL's URDF velocity limit, rad/s
constexpr double kA = 5.24;            // joint_acceleration_limit of the arm config, rad/s²

TEST(TimeParameterizeTest, OneJointTrapezoidMatchesTheClosedForm) {
  const ArmModel& arm = DefaultArm();
  const Eigen::VectorXd a = arm.home_joints();
  Eigen::VectorXd b = a;
  b[0] += 1.0;  // 1 rad on joint1
  const Result<JointTrajectory> t = TimeParameterize(arm, {a, b}, 0.5, 0.5, 0.1);
  ASSERT_TRUE(t.ok()) << t.status().ToString();
  // v = 0.3927 rad/s, a = 2.62 rad/s²: v²/a = 0.0589 <= 1, so a trapezoid of 1/v + v/a.
  const double v = 0.5 * kV;
  const double acc = 0.5 * kA;
  EXPECT_NEAR(t->duration_s(), 1.0 / v + v / acc, 1e-9);
  EXPECT_TRUE(t->points.front().q.isApprox(a));
  EXPECT_TRUE(t->points.back().q.isApprox(b));
  EXPECT_EQ(t->points.front().qd.norm(), 0.0);
  EXPECT_EQ(t->points.back().qd.norm(), 0.0);
  EXPECT_TRUE(t->Validate(arm).ok()) << t->Validate(arm).ToString();
}

TEST(TimeParameterizeTest, EveryJointStaysWithinItsScaledLimitsByFiniteDifferences) {
  const ArmModel& arm = DefaultArm();
  const std::vector<Eigen::VectorXd> path = {arm.home_joints(), Deg({30, -40, 70, 20, 30, -10}),
                                             Deg({-20, -60, 50, -40, 60, 45}),
                                             Deg({-20, -60, 50, -40, 60, 45.05})};
  const double vs = 0.7;
  const double as = 0.4;
  const Result<JointTrajectory> t = TimeParameterize(arm, path, vs, as, 0.02);
  ASSERT_TRUE(t.ok()) << t.status().ToString();
  ASSERT_TRUE(t->Validate(arm).ok()) << t->Validate(arm).ToString();
  const auto& p = t->points;
  for (size_t k = 1; k < p.size(); ++k) {
    const double dt = p[k].t_s - p[k - 1].t_s;
    ASSERT_GT(dt, 0.0);
    // Velocities: the recorded ones and the finite differences, within the scaled limit.
    EXPECT_LE(p[k].qd.cwiseAbs().maxCoeff(), vs * kV * (1 + 1e-9)) << k;
    EXPECT_LE(((p[k].q - p[k - 1].q) / dt).cwiseAbs().maxCoeff(), vs * kV * (1 + 1e-6)) << k;
    // Accelerations: the change of the recorded velocity over the interval.
    EXPECT_LE(((p[k].qd - p[k - 1].qd) / dt).cwiseAbs().maxCoeff(), as * kA * (1 + 1e-6)) << k;
  }
  // Every vertex of the path is a point, at rest.
  for (const Eigen::VectorXd& v : path) {
    bool found = false;
    for (const TrajectoryPoint& q : p) found = found || (q.q.isApprox(v, 1e-12) && q.qd.isZero());
    EXPECT_TRUE(found) << v.transpose();
  }
}

TEST(TimeParameterizeTest, APathThatDoesNotMoveGivesTwoPointsAtRest) {
  const ArmModel& arm = DefaultArm();
  const Result<JointTrajectory> t =
      TimeParameterize(arm, {arm.home_joints(), arm.home_joints()}, 0.5, 0.5, 0.1);
  ASSERT_TRUE(t.ok()) << t.status().ToString();
  ASSERT_EQ(t->points.size(), 2u);
  EXPECT_TRUE(t->Validate(arm).ok());
}

TEST(TimeParameterizeTest, BadInputIsNamed) {
  const ArmModel& arm = DefaultArm();
  const Eigen::VectorXd q = arm.home_joints();
  EXPECT_NE(TimeParameterize(arm, {}, 0.5, 0.5, 0.1).status().message().find("no vertex"),
            std::string::npos);
  EXPECT_NE(
      TimeParameterize(arm, {q, q}, 0.0, 0.5, 0.1).status().message().find("velocity_scaling (0)"),
      std::string::npos);
  EXPECT_NE(TimeParameterize(arm, {q, q}, 0.5, 1.5, 0.1)
                .status()
                .message()
                .find("acceleration_scaling (1.5)"),
            std::string::npos);
  EXPECT_NE(
      TimeParameterize(arm, {q, q}, 0.5, 0.5, -1).status().message().find("sample_period_s (-1)"),
      std::string::npos);
  EXPECT_NE(TimeParameterize(arm, {q, Eigen::VectorXd::Zero(3)}, 0.5, 0.5, 0.1)
                .status()
                .message()
                .find("vertex 1 has 3 entries"),
            std::string::npos);
}

TEST(JointTrajectoryTest, ValidateNamesTheBadPoint) {
  const ArmModel& arm = DefaultArm();
  Eigen::VectorXd b = arm.home_joints();
  b[1] += 0.5;
  JointTrajectory t = *TimeParameterize(arm, {arm.home_joints(), b}, 1.0, 1.0, 0.1);
  JointTrajectory late = t;
  late.points[2].t_s = late.points[1].t_s;
  EXPECT_NE(late.Validate(arm).message().find("trajectory point 2: time_from_start"),
            std::string::npos)
      << late.Validate(arm).ToString();
  JointTrajectory fast = t;
  fast.points[1].qd[1] = 2.0;
  EXPECT_NE(fast.Validate(arm).message().find("joint 'joint2' velocity 2 exceeds its limit"),
            std::string::npos)
      << fast.Validate(arm).ToString();
  JointTrajectory outside = t;
  outside.points[1].q[1] = 3.0;
  EXPECT_NE(outside.Validate(arm).message().find("trajectory point 1"), std::string::npos);
  JointTrajectory one = t;
  one.points.resize(1);
  EXPECT_NE(one.Validate(arm).message().find("at least 2"), std::string::npos);
  JointTrajectory names = t;
  names.joint_names[0] = "j1";
  EXPECT_NE(names.Validate(arm).message().find("are not the arm's"), std::string::npos);
}

}  // namespace
}  // namespace avp::robot

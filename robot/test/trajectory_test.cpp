#include <cmath>
#include <limits>
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

TEST(FramesAlongTest, FramesAtEveryPeriodStrictlyBetweenTheStartAndTheArrival) {
  const ArmModel& arm = DefaultArm();
  const Eigen::VectorXd a = arm.home_joints();
  Eigen::VectorXd b = a;
  b[0] += 1.0;
  const Result<JointTrajectory> t = TimeParameterize(arm, {a, b}, 0.5, 0.5, 0.1);
  ASSERT_TRUE(t.ok()) << t.status().ToString();
  const std::vector<FrameAlong> frames = FramesAlong(*t, 30.0);
  // 2.70 s at 30 Hz: frames 1 ... 81 (t = 2.7 s is at or past the arrival, not a moving frame).
  const int64_t duration_ns = TimeNs(t->points.back());
  ASSERT_FALSE(frames.empty());
  EXPECT_EQ(static_cast<int64_t>(frames.size()), (duration_ns * 30 - 1) / 1'000'000'000);
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].index, static_cast<int>(i) + 1);
    EXPECT_EQ(frames[i].t_ns, std::llround((static_cast<double>(i) + 1) * 1e9 / 30.0));
    EXPECT_LT(frames[i].t_ns, duration_ns);
    // Joint 1 moves monotonically from a to b; the others stay.
    EXPECT_GT(frames[i].q[0], a[0]);
    EXPECT_LT(frames[i].q[0], b[0]);
    if (i > 0) {
      EXPECT_GT(frames[i].q[0], frames[i - 1].q[0]);
    }
    EXPECT_NEAR((frames[i].q.tail(5) - a.tail(5)).norm(), 0.0, 1e-12);
  }
  // Half way in time, a symmetric profile is half way in joint space.
  const std::vector<int64_t> t_ns = t->times_ns();
  std::vector<Eigen::VectorXd> q;
  for (const TrajectoryPoint& p : t->points) q.push_back(p.q);
  EXPECT_NEAR(JointsAt(q, t_ns, duration_ns / 2)[0], a[0] + 0.5, 1e-3);
  EXPECT_TRUE(JointsAt(q, t_ns, -5).isApprox(a));
  EXPECT_TRUE(JointsAt(q, t_ns, duration_ns + 5).isApprox(b));
  // No frames without a rate or a move.
  EXPECT_TRUE(FramesAlong(*t, 0.0).empty());
  EXPECT_TRUE(FramesAlong(*t, std::nan("")).empty());
  EXPECT_TRUE(FramesAlong(JointTrajectory{}, 30.0).empty());
  // The one rule `avp sim ros2` publishes its frames by: the same times.
  const std::vector<int64_t> times = FrameTimesNs(duration_ns, 30.0);
  ASSERT_EQ(times.size(), frames.size());
  for (size_t i = 0; i < times.size(); ++i) EXPECT_EQ(times[i], frames[i].t_ns);
}

TEST(FramesAlongTest, FrameTimesAreStrictlyBeforeTheArrival) {
  // At 30 Hz the 30th frame falls on 1 s exactly: the arrival's own frame, not a moving one.
  EXPECT_EQ(FrameTimesNs(1'000'000'000, 30.0).size(), 29u);
  EXPECT_EQ(FrameTimesNs(1'000'000'001, 30.0).size(), 30u);
  EXPECT_EQ(FrameTimesNs(1'000'000'001, 30.0).back(), 1'000'000'000);
  // Rounded to whole nanoseconds: 1/3 s at 3 Hz.
  EXPECT_EQ(FrameTimesNs(2'000'000'000, 3.0),
            (std::vector<int64_t>{333'333'333, 666'666'667, 1'000'000'000, 1'333'333'333,
                                  1'666'666'667}));
  EXPECT_TRUE(FrameTimesNs(0, 30.0).empty());
  EXPECT_TRUE(FrameTimesNs(1'000'000'000, 0.0).empty());
  EXPECT_TRUE(FrameTimesNs(1'000'000'000, -30.0).empty());
  EXPECT_TRUE(FrameTimesNs(1'000'000'000, std::numeric_limits<double>::infinity()).empty());
  // A rate so low that k / rate overflows: no frame, and the loop ends.
  EXPECT_TRUE(FrameTimesNs(1'000'000'000, 1e-300).empty());
  EXPECT_TRUE(FrameTimesNs(std::numeric_limits<int64_t>::max(), 1e-300).empty());
}

TEST(FramesAlongTest, JointsAtInterpolatesLinearlyInWholeNanoseconds) {
  const std::vector<Eigen::VectorXd> q = {Eigen::Vector2d(0, 0), Eigen::Vector2d(1, 2),
                                          Eigen::Vector2d(1, 2), Eigen::Vector2d(3, 2)};
  const std::vector<int64_t> t = {0, 100, 100, 300};  // a repeated time: a jump, no division
  EXPECT_TRUE(JointsAt(q, t, 50).isApprox(Eigen::Vector2d(0.5, 1.0)));
  EXPECT_TRUE(JointsAt(q, t, 100).isApprox(Eigen::Vector2d(1, 2)));
  EXPECT_TRUE(JointsAt(q, t, 200).isApprox(Eigen::Vector2d(2, 2)));
  // A point's time as trajectory_msgs carries it: truncated to whole nanoseconds.
  EXPECT_EQ(TimeNs(TrajectoryPoint{.q = {}, .qd = {}, .t_s = 0.1234567899}), 123'456'789);
  EXPECT_EQ(TimeNs(TrajectoryPoint{.q = {}, .qd = {}, .t_s = 1.5}), 1'500'000'000);
}

}  // namespace
}  // namespace avp::robot

#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>
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

// FK of random in-limit joints gives reachable targets; IK from the home pose (a seed unrelated to
// the target) must find joints within the limits that reproduce them to 0.1 mm / 1 mrad.
TEST(IkTest, RoundTripOnRandomReachablePoses) {
  const ArmModel& arm = DefaultArm();
  const IkOptions& options = arm.config().ik;
  Rng target_rng(2024);
  Rng ik_rng(99);
  constexpr int kTargets = 600;
  int successes = 0;
  int total_restarts = 0;
  double total_ms = 0.0;
  for (int k = 0; k < kTargets; ++k) {
    const Eigen::VectorXd q_true = arm.RandomJoints(target_rng);
    const RigidTransform X_WF = arm.ForwardKinematics(q_true);
    const auto start = std::chrono::steady_clock::now();
    const IkResult ik = arm.SolveIk(X_WF, arm.home_joints(), ik_rng);
    total_ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (!ik.ok()) {
      EXPECT_EQ(ik.status.code(), StatusCode::kUnreachable);
      continue;
    }
    ++successes;
    total_restarts += ik.restarts;
    // Reported residuals are true residuals, within tolerance, with joints in the limits.
    ASSERT_TRUE(arm.WithinLimits(ik.q)) << ik.q.transpose();
    const RigidTransform X_reached = arm.ForwardKinematics(ik.q);
    ASSERT_LE(X_reached.TranslationDistanceTo(X_WF), options.position_tolerance_m);
    ASSERT_LE(X_reached.AngleTo(X_WF), options.orientation_tolerance_rad);
    EXPECT_NEAR(ik.position_error_m, X_reached.TranslationDistanceTo(X_WF), 1e-12);
    EXPECT_NEAR(ik.orientation_error_rad, X_reached.AngleTo(X_WF), 1e-9);
  }
  const double rate = static_cast<double>(successes) / kTargets;
  std::printf(
      "[ IK ] %d/%d random reachable poses solved (%.2f %%), mean %.3f ms, "
      "mean restarts %.2f\n",
      successes, kTargets, 100.0 * rate, total_ms / kTargets,
      static_cast<double>(total_restarts) / std::max(successes, 1));
  EXPECT_GE(rate, 0.99);
}

TEST(IkTest, SeedAtSolutionConvergesWithoutRestarts) {
  const ArmModel& arm = DefaultArm();
  Rng rng(1);
  const Eigen::VectorXd q = Deg({20, -50, 70, 10, 40, -30});
  const IkResult ik = arm.SolveIk(arm.ForwardKinematics(q), q, rng);
  ASSERT_TRUE(ik.ok()) << ik.status.ToString();
  EXPECT_EQ(ik.restarts, 0);
  EXPECT_LT((ik.q - q).norm(), 1e-3);
}

TEST(IkTest, FarTargetIsUnreachableWithMessage) {
  const ArmModel& arm = DefaultArm();
  Rng rng(3);
  const RigidTransform far(Eigen::Vector3d(3.0, 0.0, 0.5));
  const IkResult ik = arm.SolveIk(far, arm.home_joints(), rng);
  EXPECT_FALSE(ik.ok());
  EXPECT_EQ(ik.status.code(), StatusCode::kUnreachable);
  const std::string& msg = ik.status.message();
  EXPECT_NE(msg.find("xyz [3, 0, 0.5]"), std::string::npos) << msg;
  EXPECT_NE(msg.find("reach"), std::string::npos) << msg;
  EXPECT_GT(ik.position_error_m, 2.0);
  EXPECT_TRUE(arm.WithinLimits(ik.q));
  EXPECT_FALSE(arm.IsReachable(far));
}

TEST(IkTest, WristBeyondReachIsRejectedWithoutSolving) {
  const ArmModel& arm = DefaultArm();
  Rng rng(4);
  // 0.77 m above joint1 (inside the 0.7984 m reach bound) with the approach axis pointing down:
  // joint5 would sit 0.122 m higher, at z = 0.992, 0.743 m from joint2 (z = 0.249), but the links
  // between them span only 0.2384 + 0.119 + 0.170 = 0.5274 m.
  const RigidTransform X_WF(Eigen::AngleAxisd(EIGEN_PI / 2, Eigen::Vector3d::UnitY()).matrix(),
                            Eigen::Vector3d(0.0, 0.0, 0.87));
  const IkResult ik = arm.SolveIk(X_WF, arm.home_joints(), rng);
  ASSERT_FALSE(ik.ok());
  EXPECT_EQ(ik.status.code(), StatusCode::kUnreachable);
  EXPECT_EQ(ik.iterations, 0);
  EXPECT_NE(ik.status.message().find("puts joint 'joint5' 0.743 m from joint 'joint2'"),
            std::string::npos)
      << ik.status.message();
  EXPECT_NE(ik.status.message().find("(0.527 m)"), std::string::npos) << ik.status.message();
  // The bound is necessary, never wrong: no reachable target trips it.
  Rng target_rng(77);
  for (int k = 0; k < 300; ++k) {
    const RigidTransform X = arm.ForwardKinematics(arm.RandomJoints(target_rng));
    const IkResult r = arm.SolveIk(X, arm.home_joints(), rng);
    EXPECT_EQ(r.status.message().find("farther than the links"), std::string::npos)
        << r.status.message();
  }
}

TEST(IkTest, SolutionsOutsideTheLimitsAreRejectedAndReported) {
  const ArmModel& arm = DefaultArm();
  Rng rng(4);
  // The flange 5 cm above the base origin, pointing down, inside the robot's own column: LMA finds
  // joints for it, but only outside the limits.
  const RigidTransform X_WF(Eigen::AngleAxisd(EIGEN_PI / 2, Eigen::Vector3d::UnitY()).matrix(),
                            Eigen::Vector3d(0.0, 0.0, 0.05));
  IkOptions options = arm.config().ik;
  options.max_restarts = 5;
  const IkResult ik = arm.SolveIk(X_WF, arm.home_joints(), rng, options);
  ASSERT_FALSE(ik.ok());
  EXPECT_EQ(ik.status.code(), StatusCode::kUnreachable);
  EXPECT_EQ(ik.restarts, 5);
  EXPECT_GT(ik.iterations, 0);
  const std::string& msg = ik.status.message();
  EXPECT_NE(msg.find("xyz [0, 0, 0.05]"), std::string::npos) << msg;
  EXPECT_NE(msg.find("6 attempts"), std::string::npos) << msg;
  EXPECT_NE(msg.find("best residual"), std::string::npos) << msg;
  EXPECT_NE(msg.find("reached it outside the limits"), std::string::npos) << msg;
}

TEST(IkTest, SameSeedSameSolution) {
  const ArmModel& arm = DefaultArm();
  Rng target_rng(5);
  for (int k = 0; k < 20; ++k) {
    const RigidTransform X_WF = arm.ForwardKinematics(arm.RandomJoints(target_rng));
    Rng a(1234);
    Rng b(1234);
    const IkResult ia = arm.SolveIk(X_WF, arm.home_joints(), a);
    const IkResult ib = arm.SolveIk(X_WF, arm.home_joints(), b);
    EXPECT_EQ(ia.status, ib.status);
    EXPECT_EQ(ia.q, ib.q);  // bit for bit
    EXPECT_EQ(ia.restarts, ib.restarts);
    EXPECT_EQ(ia.iterations, ib.iterations);
  }
}

TEST(IkTest, SolutionsRespectNarrowedLimits) {
  // Narrow joint2 to [−40, 40]° through the config; every solution must honour it.
  ArmConfig config = DefaultArm().config();
  config.joint_limit_overrides.push_back({"joint2", DegToRad(-40), DegToRad(40)});
  config.home_joints.clear();  // the default home (joint2 = −70°) lies outside the new limits
  const ArmModel arm = ArmModel::Create(config).value();
  EXPECT_NEAR(arm.upper_limits()[1], DegToRad(40), 1e-12);
  Rng target_rng(8);
  Rng rng(9);
  int solved = 0;
  for (int k = 0; k < 50; ++k) {
    const Eigen::VectorXd q_true = arm.RandomJoints(target_rng);
    ASSERT_TRUE(arm.WithinLimits(q_true));
    const IkResult ik = arm.SolveIk(arm.ForwardKinematics(q_true), arm.home_joints(), rng);
    if (!ik.ok()) continue;
    ++solved;
    EXPECT_TRUE(arm.WithinLimits(ik.q)) << ik.q.transpose();
    EXPECT_GE(ik.q[1], DegToRad(-40) - 1e-12);
    EXPECT_LE(ik.q[1], DegToRad(40) + 1e-12);
  }
  EXPECT_GE(solved, 45);
}

TEST(IkTest, OutOfLimitSeedIsClamped) {
  const ArmModel& arm = DefaultArm();
  Rng rng(10);
  const Eigen::VectorXd q = Deg({10, -20, 30, 40, 50, 60});
  Eigen::VectorXd seed = q;
  seed[1] = DegToRad(300);  // far outside ±110°
  const IkResult ik = arm.SolveIk(arm.ForwardKinematics(q), seed, rng);
  ASSERT_TRUE(ik.ok()) << ik.status.ToString();
  EXPECT_TRUE(arm.WithinLimits(ik.q));
}

TEST(IkTest, WrongSeedSizeThrows) {
  const ArmModel& arm = DefaultArm();
  Rng rng(1);
  EXPECT_THROW((void)arm.SolveIk(RigidTransform(), Eigen::VectorXd::Zero(3), rng), Error);
}

TEST(IkTest, CameraIkRoundTrip) {
  const ArmModel& arm = DefaultArm();
  Rng target_rng(12);
  Rng rng(13);
  int solved = 0;
  for (int k = 0; k < 50; ++k) {
    const RigidTransform X_WC = arm.CameraPose(arm.RandomJoints(target_rng));
    const IkResult ik = arm.SolveCameraIk(X_WC, arm.home_joints(), rng);
    if (!ik.ok()) continue;
    ++solved;
    const RigidTransform reached = arm.CameraPose(ik.q);
    // The mount is rigid: camera residuals equal flange residuals in angle, and differ by at most
    // the lever arm (|p_FC| · angle) in position.
    EXPECT_LE(reached.AngleTo(X_WC), 1e-3);
    EXPECT_LE(reached.TranslationDistanceTo(X_WC), 1e-4 + 0.068 * 1e-3);
  }
  EXPECT_GE(solved, 49);
}

TEST(IkTest, ReachabilityOfCameraPoses) {
  const ArmModel& arm = DefaultArm();
  // The home camera pose is reachable, and IsReachable is a pure function of the pose.
  const RigidTransform X_WC_home = arm.CameraPose(arm.home_joints());
  EXPECT_TRUE(arm.IsReachable(X_WC_home));
  // 40 cm ahead of the home view, looking at the same plant: a typical NBV candidate.
  const RigidTransform ahead(X_WC_home.rotation(),
                             X_WC_home.translation() + Eigen::Vector3d(0.2, 0.1, -0.1));
  EXPECT_EQ(arm.IsReachable(ahead), arm.IsReachable(ahead));
  EXPECT_TRUE(arm.IsReachable(ahead));
  // Looking back at the robot from 0.75 m in front of it, at the base height: out of reach.
  const RigidTransform behind =
      RigidTransform::LookAt(Eigen::Vector3d(0.75, 0, 0.0), Eigen::Vector3d(0, 0, 0.0));
  EXPECT_FALSE(arm.IsReachable(behind));
}

// The model is shared between copies and threads: concurrent solves give the sequential answers.
TEST(IkTest, ConcurrentSolvesMatchSequentialOnes) {
  const ArmModel arm = DefaultArm();  // a copy shares the immutable chain
  Rng target_rng(31);
  std::vector<RigidTransform> targets;
  for (int k = 0; k < 40; ++k)
    targets.push_back(arm.ForwardKinematics(arm.RandomJoints(target_rng)));
  auto solve_all = [&](uint64_t seed) {
    Rng rng(seed);
    std::vector<Eigen::VectorXd> out;
    for (const RigidTransform& X : targets) out.push_back(arm.SolveIk(X, arm.home_joints(), rng).q);
    return out;
  };
  const std::vector<Eigen::VectorXd> expected_a = solve_all(1);
  const std::vector<Eigen::VectorXd> expected_b = solve_all(2);
  std::vector<Eigen::VectorXd> got_a, got_b;
  std::thread ta([&] { got_a = solve_all(1); });
  std::thread tb([&] { got_b = solve_all(2); });
  ta.join();
  tb.join();
  EXPECT_EQ(got_a, expected_a);
  EXPECT_EQ(got_b, expected_b);
}

TEST(IkTest, OtherArmFromItsOwnUrdf) {
  const std::filesystem::path dir = testing::TestDir();
  testing::WriteFile(dir / "planar3.urdf", testing::ThreeLinkUrdf());
  ArmConfig config;
  config.urdf_path = dir / "planar3.urdf";
  config.base_link = "world_base";
  config.tip_link = "tool";
  config.camera_mount.X_FC = RigidTransform();
  const ArmModel arm = ArmModel::Create(config).value();
  ASSERT_EQ(arm.num_joints(), 3);
  EXPECT_EQ(arm.joints()[2].type, JointType::kContinuous);
  EXPECT_TRUE(std::isinf(arm.upper_limits()[2]));
  // Straight up: 0.1 + 0.2 + 0.5 + 0.4 + 0.1, turned 90° about z by the pedestal.
  const Eigen::Matrix3d R_yaw = Eigen::AngleAxisd(EIGEN_PI / 2, Eigen::Vector3d::UnitZ()).matrix();
  EXPECT_TRUE(testing::PosesNear(arm.ForwardKinematics(Eigen::Vector3d::Zero()),
                                 RigidTransform(R_yaw, Eigen::Vector3d(0, 0, 1.3)), 1e-12));
  // Shoulder +90° about the turned y axis (world −x): everything lies along +y at z = 0.3.
  const RigidTransform X = arm.ForwardKinematics(Eigen::Vector3d(EIGEN_PI / 2, 0, 0));
  EXPECT_LT((X.translation() - Eigen::Vector3d(0, 1.0, 0.3)).norm(), 1e-12) << X;

  // A planar arm reaches only poses in its plane: a round trip works from FK targets.
  Rng rng(21);
  for (int k = 0; k < 20; ++k) {
    const Eigen::VectorXd q = arm.RandomJoints(rng);
    const IkResult ik = arm.SolveIk(arm.ForwardKinematics(q), Eigen::Vector3d::Zero(), rng);
    ASSERT_TRUE(ik.ok()) << ik.status.ToString();
    EXPECT_TRUE(arm.WithinLimits(ik.q));
    // The continuous wrist is wrapped to the angle nearest its start, so it stays within ±π of it.
    EXPECT_LE(std::abs(ik.q[2]), 2.0 * EIGEN_PI);
  }
  // Out of the plane: unreachable.
  const IkResult off =
      arm.SolveIk(RigidTransform(Eigen::Vector3d(0.3, 0.3, 0.5)), Eigen::Vector3d::Zero(), rng);
  EXPECT_EQ(off.status.code(), StatusCode::kUnreachable);
}

}  // namespace
}  // namespace avp::robot

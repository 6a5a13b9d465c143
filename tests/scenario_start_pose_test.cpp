// Cross-checks sim and robot: every scenario's start joints are within the arm's limits, and the
// camera pose the arm reaches with them (FK + mount) is the nominal start pose the scenario states.
#include <gtest/gtest.h>

#include <avp/robot/arm_model.h>
#include <avp/sim/scenario.h>

namespace avp {
namespace {

TEST(ScenarioStartPoseTest, StartJointsReachTheNominalStartCameraPose) {
  const Result<robot::ArmModel> arm = robot::LoadDefaultArm();
  ASSERT_TRUE(arm.ok()) << arm.status().ToString();
  const sim::ScenarioRegistry scenarios = sim::BuiltinScenarios();
  for (const sim::ScenarioEntry& info : scenarios.entries()) {
    for (uint64_t seed : {0u, 1u}) {
      const sim::Scene scene = sim::MakeScenario(info.name, seed).value();
      ASSERT_EQ(static_cast<int>(scene.start_joints_rad.size()), arm->num_joints()) << info.name;
      const Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(
          scene.start_joints_rad.data(), static_cast<Eigen::Index>(scene.start_joints_rad.size()));
      EXPECT_TRUE(arm->CheckJoints(q).ok()) << info.name << ": " << arm->CheckJoints(q).ToString();
      const RigidTransform X_WC = arm->CameraPose(q);
      EXPECT_LT(X_WC.TranslationDistanceTo(scene.X_WC_start), 1e-3)
          << info.name << ": FK " << X_WC << " vs nominal " << scene.X_WC_start;
      EXPECT_LT(X_WC.AngleTo(scene.X_WC_start), 1e-3)
          << info.name << ": FK " << X_WC << " vs nominal " << scene.X_WC_start;
    }
  }
}

}  // namespace
}  // namespace avp

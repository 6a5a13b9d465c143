#include <cmath>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include <avp/robot/arm_config.h>
#include <avp/robot/arm_model.h>

#include "test_util.h"

namespace avp::robot {
namespace {

using testing::TestDir;
using testing::WriteFile;

std::filesystem::path DefaultYaml() {
  return std::filesystem::path(AVP_CONFIG_DIR) / "arms" / "igus_rebel_d435.yaml";
}

// Writes `yaml` next to a copy of the planar test URDF and returns the YAML path.
std::filesystem::path WriteArmYaml(const std::string& yaml) {
  const std::filesystem::path dir = TestDir();
  WriteFile(dir / "planar3.urdf", testing::ThreeLinkUrdf());
  WriteFile(dir / "arm.yaml", yaml);
  return dir / "arm.yaml";
}

::testing::AssertionResult HasError(const Status& status, StatusCode code,
                                    const std::string& fragment) {
  if (status.code() == code && status.message().find(fragment) != std::string::npos) {
    return ::testing::AssertionSuccess();
  }
  return ::testing::AssertionFailure() << "expected " << ToString(code) << " containing '"
                                       << fragment << "', got " << status.ToString();
}

TEST(ArmConfigTest, DefaultsAreValid) {
  EXPECT_TRUE(IkOptions{}.Validate().ok());
  ArmConfig config;
  config.urdf_path = "x.urdf";
  EXPECT_TRUE(config.Validate().ok()) << config.Validate().ToString();
  EXPECT_EQ(IkOptions{}.max_restarts, 20);
  EXPECT_EQ(IkOptions{}.position_tolerance_m, 1e-4);
  EXPECT_EQ(IkOptions{}.orientation_tolerance_rad, 1e-3);
}

TEST(ArmConfigTest, LoadsTheDefaultArmYaml) {
  const ArmConfig config = ArmConfig::LoadYaml(DefaultYaml()).value();
  EXPECT_EQ(config.urdf_path.filename(), "igus_rebel_6dof.urdf");
  EXPECT_TRUE(config.urdf_path.is_absolute());
  EXPECT_EQ(config.base_link, "base_link");
  EXPECT_EQ(config.tip_link, "flange");
  EXPECT_EQ(config.camera_mount.frame_name, "camera_color_optical_frame");
  // The YAML's mount (rpy_deg [-90, 0, -90]) is the documented default.
  EXPECT_TRUE(config.camera_mount.X_FC.IsNearlyEqualTo(CameraMount::DefaultX_FC(), 1e-12, 1e-12));
  EXPECT_EQ(config.ik.max_restarts, 20);
  ASSERT_EQ(config.reference_convention.sign.size(), 6u);
  EXPECT_EQ(config.reference_convention.sign[0], -1.0);
  EXPECT_NEAR(config.reference_convention.offset_rad[4], DegToRad(7.5), 1e-15);
  ASSERT_EQ(config.home_joints.size(), 6u);
  EXPECT_NEAR(config.home_joints[1], DegToRad(-70), 1e-15);
}

TEST(ArmConfigTest, ValidateReportsEveryBadField) {
  ArmConfig config;
  config.urdf_path = "arm.urdf";
  config.tip_link = "";
  config.ik.max_restarts = -1;
  config.ik.position_tolerance_m = std::numeric_limits<double>::quiet_NaN();
  config.joint_limit_overrides.push_back({"joint2", 1.0, -1.0});
  config.reference_convention.sign = {1.0, 2.0};
  config.reference_convention.offset_rad = {0.0, 0.0};
  const Status s = config.Validate();
  ASSERT_EQ(s.code(), StatusCode::kInvalidArgument);
  const std::string& m = s.message();
  EXPECT_NE(m.find("tip_link ('') must not be empty"), std::string::npos) << m;
  EXPECT_NE(m.find("ik.max_restarts (-1) must be >= 0"), std::string::npos) << m;
  EXPECT_NE(m.find("ik.position_tolerance_m (nan)"), std::string::npos) << m;
  EXPECT_NE(m.find("joint_limit_overrides[0] (joint2): lower (1) must be < upper (-1)"),
            std::string::npos)
      << m;
  EXPECT_NE(m.find("reference_convention.sign[1] (2) must be +1 or -1"), std::string::npos) << m;
}

TEST(ArmConfigTest, RejectsUnknownKeys) {
  const auto path = WriteArmYaml(
      "urdf: planar3.urdf\nbase_link: world_base\ntip_link: tool\n"
      "tip_lnk: tool\n");
  EXPECT_TRUE(HasError(ArmConfig::LoadYaml(path).status(), StatusCode::kInvalidArgument,
                       "unknown key 'tip_lnk'"));
  const auto nested = WriteArmYaml("urdf: planar3.urdf\nik: {max_restart: 3}\n");
  EXPECT_TRUE(HasError(ArmConfig::LoadYaml(nested).status(), StatusCode::kInvalidArgument,
                       "unknown key 'max_restart'"));
}

TEST(ArmConfigTest, MissingUrdfNamesThePath) {
  const auto path = WriteArmYaml("urdf: no_such_robot.urdf\n");
  const Status s = ArmConfig::LoadYaml(path).status();
  EXPECT_TRUE(HasError(s, StatusCode::kNotFound, "no_such_robot.urdf"));
  EXPECT_NE(s.message().find(path.parent_path().string()), std::string::npos) << s.message();
}

TEST(ArmConfigTest, MissingYamlIsNotFound) {
  EXPECT_EQ(ArmConfig::LoadYaml("/nonexistent/arm.yaml").status().code(), StatusCode::kNotFound);
}

TEST(ArmConfigTest, BadValuesAreNamed) {
  const auto path = WriteArmYaml("urdf: planar3.urdf\nik: {max_iterations: lots}\n");
  EXPECT_TRUE(HasError(ArmConfig::LoadYaml(path).status(), StatusCode::kInvalidArgument,
                       "'max_iterations' must be an integer, got 'lots'"));
  const auto negative = WriteArmYaml("urdf: planar3.urdf\nik: {position_tolerance_m: -0.5}\n");
  EXPECT_TRUE(HasError(ArmConfig::LoadYaml(negative).status(), StatusCode::kInvalidArgument,
                       "ik.position_tolerance_m (-0.5) must be finite and > 0"));
  const auto both = WriteArmYaml(
      "urdf: planar3.urdf\nhome_joints: [0, 0, 0]\n"
      "home_joints_deg: [0, 0, 0]\n");
  EXPECT_TRUE(HasError(ArmConfig::LoadYaml(both).status(), StatusCode::kInvalidArgument,
                       "either 'home_joints' or 'home_joints_deg'"));
}

TEST(ArmConfigTest, UnknownLinkNamesAreReportedWithTheLinksThatExist) {
  const auto path = WriteArmYaml("urdf: planar3.urdf\nbase_link: world_base\ntip_link: flange\n");
  const Status s = LoadArm(path).status();
  EXPECT_TRUE(HasError(s, StatusCode::kNotFound, "unknown link 'flange'"));
  EXPECT_NE(s.message().find("links: a, b, c, pedestal, tool, world_base"), std::string::npos)
      << s.message();
  EXPECT_NE(s.message().find("arm.yaml"), std::string::npos) << s.message();
}

TEST(ArmConfigTest, TipNotBelowBase) {
  const auto path = WriteArmYaml("urdf: planar3.urdf\nbase_link: b\ntip_link: a\n");
  EXPECT_TRUE(HasError(LoadArm(path).status(), StatusCode::kInvalidArgument,
                       "tip_link 'a' is not below base_link 'b'"));
}

TEST(ArmConfigTest, UnknownOverrideJointIsNamed) {
  const auto path = WriteArmYaml(
      "urdf: planar3.urdf\nbase_link: world_base\ntip_link: tool\n"
      "joint_limit_overrides:\n  - {joint: knee, lower_deg: -10, upper_deg: 10}\n");
  EXPECT_TRUE(HasError(LoadArm(path).status(), StatusCode::kNotFound,
                       "unknown joint 'knee' (movable joints from 'world_base' to 'tool': "
                       "shoulder, elbow, wrist)"));
}

TEST(ArmConfigTest, OtherArmFromYaml) {
  const auto path = WriteArmYaml(
      "urdf: planar3.urdf\n"
      "base_link: world_base\n"
      "tip_link: tool\n"
      "home_joints_deg: [10, 20, 30]\n"
      "joint_limit_overrides:\n"
      "  - {joint: wrist, lower_deg: -90, upper_deg: 90}\n"
      "  - {joint: elbow, lower: -1.0, upper: 1.0}\n"
      "camera_mount: {frame: cam, pose: {xyz: [0, 0, 0.05], rpy: [0, 0, 0]}}\n"
      "ik: {max_restarts: 5, max_iterations: 50}\n");
  const ArmModel arm = LoadArm(path).value();
  ASSERT_EQ(arm.num_joints(), 3);
  EXPECT_EQ(arm.joint_names(), (std::vector<std::string>{"shoulder", "elbow", "wrist"}));
  EXPECT_EQ(arm.joints()[2].type, JointType::kRevolute);  // continuous, now limited
  EXPECT_NEAR(arm.upper_limits()[2], DegToRad(90), 1e-12);
  EXPECT_NEAR(arm.lower_limits()[1], -1.0, 1e-12);
  EXPECT_NEAR(arm.home_joints()[2], DegToRad(30), 1e-12);
  EXPECT_EQ(arm.config().ik.max_restarts, 5);
  // Straight up, camera 5 cm above the tool.
  EXPECT_LT(
      (arm.CameraPose(Eigen::Vector3d::Zero()).translation() - Eigen::Vector3d(0, 0, 1.35)).norm(),
      1e-12);
}

TEST(ArmConfigTest, HomeOutsideLimitsIsRejected) {
  const auto path = WriteArmYaml(
      "urdf: planar3.urdf\nbase_link: world_base\ntip_link: tool\nhome_joints_deg: [100, 0, 0]\n");
  EXPECT_TRUE(HasError(LoadArm(path).status(), StatusCode::kInvalidArgument,
                       "home_joints: joint 'shoulder' = 1.74533 rad (100.000 deg)"));
}

TEST(ArmConfigTest, MalformedUrdfIsAParseError) {
  const std::filesystem::path dir = TestDir();
  WriteFile(dir / "bad.urdf",
            "<robot name='x'><link name='a'/><joint name='j' type='revolute'>"
            "<parent link='a'/><child link='missing'/></joint></robot>");
  ArmConfig config;
  config.urdf_path = dir / "bad.urdf";
  const Status s = ArmModel::Create(config).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError) << s.ToString();
  EXPECT_NE(s.message().find("bad.urdf"), std::string::npos) << s.message();
}

TEST(ArmConfigTest, LoadDefaultArmHonoursExplicitDir) {
  EXPECT_TRUE(LoadDefaultArm(AVP_CONFIG_DIR).ok());
  EXPECT_EQ(LoadDefaultArm("/nonexistent").status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace avp::robot

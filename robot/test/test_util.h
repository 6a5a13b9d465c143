#pragma once

#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <string>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/transform.h>
#include <avp/robot/arm_model.h>

namespace avp::robot::testing {

/// Joint vector from degrees.
inline Eigen::VectorXd Deg(std::initializer_list<double> degrees) {
  Eigen::VectorXd q(static_cast<Eigen::Index>(degrees.size()));
  Eigen::Index i = 0;
  for (double d : degrees) q[i++] = DegToRad(d);
  return q;
}

/// Poses equal to `tolerance` in every translation (metres) and rotation-matrix entry.
inline ::testing::AssertionResult PosesNear(const RigidTransform& a, const RigidTransform& b,
                                            double tolerance) {
  const double dp = (a.translation() - b.translation()).cwiseAbs().maxCoeff();
  const double dr = (a.rotation() - b.rotation()).cwiseAbs().maxCoeff();
  if (dp <= tolerance && dr <= tolerance) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "poses differ by " << dp << " m, " << dr
                                       << " (rotation entries):\n  " << a << "\n  " << b;
}

/// The default arm (configs/arms/igus_rebel_d435.yaml), loaded once.
inline const ArmModel& DefaultArm() {
  static const ArmModel model = LoadDefaultArm(AVP_CONFIG_DIR).value();
  return model;
}

/// A fresh folder under the gtest temp dir, named after the running test.
inline std::filesystem::path TestDir() {
  const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "avp_robot_test" /
                                    (std::string(info->test_suite_name()) + "." + info->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

inline void WriteFile(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

/// A planar arm on a pedestal: a fixed joint lifts it 0.1 m and turns it 90° about z; then three
/// joints about the (turned) y axis, i.e. about world −x, with links 0.2 / 0.5 / 0.4 m along z and
/// a fixed 0.1 m tool link. The arm moves in the world y-z plane. Used to check that other URDFs
/// work (fixed joints before and after the movable ones, a continuous joint).
inline std::string ThreeLinkUrdf() {
  return R"(<?xml version="1.0"?>
<robot name="planar3">
  <link name="world_base"/>
  <link name="pedestal"/>
  <link name="a"/>
  <link name="b"/>
  <link name="c"/>
  <link name="tool"/>
  <joint name="pedestal_joint" type="fixed">
    <parent link="world_base"/><child link="pedestal"/>
    <origin xyz="0 0 0.1" rpy="0 0 1.5707963267948966"/>
  </joint>
  <joint name="shoulder" type="revolute">
    <parent link="pedestal"/><child link="a"/>
    <origin xyz="0 0 0.2" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="a"/><child link="b"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="1"/>
  </joint>
  <joint name="wrist" type="continuous">
    <parent link="b"/><child link="c"/>
    <origin xyz="0 0 0.4" rpy="0 0 0"/><axis xyz="0 1 0"/>
  </joint>
  <joint name="tool_joint" type="fixed">
    <parent link="c"/><child link="tool"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/>
  </joint>
</robot>
)";
}

}  // namespace avp::robot::testing

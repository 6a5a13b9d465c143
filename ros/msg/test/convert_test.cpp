#include "avp/ros/msg/convert.h"

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace avp::ros::msg {
namespace {

TEST(RosmsgConvertTest, RigidTransformRoundTripsThroughPoseAndTransform) {
  const RigidTransform X_WC =
      RigidTransform::FromRpy(0.3, -1.2, 2.9, Eigen::Vector3d(0.1, -0.2, 0.75));
  const Pose pose = ToPoseMsg(X_WC);
  const Quaternion& q = pose.orientation;
  EXPECT_NEAR(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w, 1.0, 1e-12);
  EXPECT_GE(q.w, 0.0);
  EXPECT_EQ(pose.position, (Point{0.1, -0.2, 0.75}));
  EXPECT_TRUE(FromPoseMsg(pose).value().IsNearlyEqualTo(X_WC, 1e-12, 1e-9));
  const Transform t = ToTransformMsg(X_WC);
  EXPECT_TRUE(FromTransformMsg(t).value().IsNearlyEqualTo(X_WC, 1e-12, 1e-9));
  EXPECT_EQ(ToPoseMsg(RigidTransform()).orientation, (Quaternion{0, 0, 0, 1}));
}

TEST(RosmsgConvertTest, QuaternionIsNormalisedAndZeroRefused) {
  Pose pose;
  pose.orientation = Quaternion{0, 0, 0, 2};
  EXPECT_TRUE(FromPoseMsg(pose).value().IsNearlyEqualTo(RigidTransform(), 0, 1e-12));
  pose.orientation = Quaternion{0, 0, 0, 0};
  const Status zero = FromPoseMsg(pose).status();
  EXPECT_EQ(zero.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(zero.message(), ::testing::HasSubstr("quaternion of norm 0"));
  pose.orientation = Quaternion{};
  pose.position.y = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(FromPoseMsg(pose).status().message(), ::testing::HasSubstr("non-finite"));
}

TEST(RosmsgConvertTest, Stamps) {
  EXPECT_EQ(ToTimeMsg(1'700'000'000'123'456'789), (Time{1'700'000'000, 123'456'789}));
  EXPECT_EQ(FromTimeMsg(Time{1, 2}), 1'000'000'002);
  EXPECT_EQ(FromPointMsg(ToPointMsg(Eigen::Vector3d(1, 2, 3))), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(FromVector3Msg(ToVector3Msg(Eigen::Vector3d(4, 5, 6))), Eigen::Vector3d(4, 5, 6));
}

TEST(RosmsgConvertTest, ViridisRunsFromItsFirstToItsLastStop) {
  EXPECT_EQ(Viridis(0.0), Rgba(0.267, 0.005, 0.329));
  EXPECT_EQ(Viridis(1.0), Rgba(0.993, 0.906, 0.144));
  EXPECT_EQ(Viridis(0.25), Rgba(0.229, 0.322, 0.546));
  EXPECT_EQ(Viridis(-3.0), Viridis(0.0));  // clamped
  EXPECT_EQ(Viridis(7.0), Viridis(1.0));
  EXPECT_EQ(Viridis(std::nan("")), Viridis(0.0));
  const ColorRGBA mid = Viridis(0.125);  // halfway between the first two stops
  EXPECT_FLOAT_EQ(mid.r, static_cast<float>(0.5 * (0.267 + 0.229)));
  EXPECT_FLOAT_EQ(mid.b, static_cast<float>(0.5 * (0.329 + 0.546)));
  EXPECT_FLOAT_EQ(mid.a, 1.0f);
}

}  // namespace
}  // namespace avp::ros::msg

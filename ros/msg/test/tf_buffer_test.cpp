// The TF buffer of avp live and avp replay: chains, interpolation, statics, TransformStamped as
// tf2 takes it, a whole bag kept, and refusals (loops, two parents, late and old stamps, unknown
// frames, denormalised quaternions).
#include <cmath>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/tf_buffer.h>

namespace avp::ros::msg {
namespace {

using ::testing::HasSubstr;
constexpr int64_t kSec = 1'000'000'000;

RigidTransform Yaw(double yaw, const Eigen::Vector3d& p) {
  return RigidTransform::FromRpy(0, 0, yaw, p);
}

TEST(TfBufferTest, ComposesAChainThroughStaticAndDynamicEdges) {
  TfBuffer tf;
  ASSERT_TRUE(tf.Add("base", "flange", Yaw(0.0, {1, 0, 0}), 10 * kSec, false).ok());
  ASSERT_TRUE(
      tf.Add("base", "flange", Yaw(std::numbers::pi / 2, {1, 0, 0}), 12 * kSec, false).ok());
  ASSERT_TRUE(tf.Add("flange", "camera", RigidTransform(Eigen::Vector3d(0, 0, 0.1)), 0, true).ok());
  // At 11 s: halfway, yaw pi/4; the camera 0.1 m above the flange.
  auto X = tf.Lookup("base", "camera", 11 * kSec);
  ASSERT_TRUE(X.ok()) << X.status().ToString();
  EXPECT_NEAR(X->translation().x(), 1.0, 1e-12);
  EXPECT_NEAR(X->translation().z(), 0.1, 1e-12);
  EXPECT_NEAR(X->rpy().z(), std::numbers::pi / 4, 1e-9);
  // The inverse direction is the inverse transform.
  auto Y = tf.Lookup("camera", "base", 11 * kSec);
  ASSERT_TRUE(Y.ok());
  EXPECT_TRUE((*X * *Y).IsNearlyEqualTo(RigidTransform::Identity(), 1e-12, 1e-12));
  // Siblings: flange in camera through the common parent.
  auto Z = tf.Lookup("camera", "flange", 11 * kSec);
  ASSERT_TRUE(Z.ok());
  EXPECT_NEAR(Z->translation().z(), -0.1, 1e-12);
  EXPECT_EQ(*tf.LatestCommonTime("base", "camera"), 12 * kSec);
}

TEST(TfBufferTest, ChainsComposeParentToChildInOrder) {
  // base -> flange (yaw 90°, 1 m along x) -> camera (0.1 m along the flange's x, pitched): the
  // camera is at base (1, 0.1, 0), which a product in the wrong order would not give.
  TfBuffer tf;
  const RigidTransform X_BF = Yaw(std::numbers::pi / 2, {1, 0, 0});
  const RigidTransform X_FC = RigidTransform::FromRpy(0, 0.3, 0, {0.1, 0, 0});
  ASSERT_TRUE(tf.Add("base", "flange", X_BF, 0, true).ok());
  ASSERT_TRUE(tf.Add("flange", "camera", X_FC, 0, true).ok());
  ASSERT_TRUE(tf.Add("base", "table", RigidTransform(Eigen::Vector3d(0, 0, -0.5)), 0, true).ok());
  auto X = tf.Lookup("base", "camera", 0);
  ASSERT_TRUE(X.ok());
  EXPECT_TRUE(X->IsNearlyEqualTo(X_BF * X_FC, 1e-12, 1e-12));
  EXPECT_NEAR(X->translation().y(), 0.1, 1e-12);
  // Across branches: the camera in the table's frame.
  auto Y = tf.Lookup("table", "camera", 0);
  ASSERT_TRUE(Y.ok());
  EXPECT_TRUE(
      Y->IsNearlyEqualTo(RigidTransform(Eigen::Vector3d(0, 0, 0.5)) * X_BF * X_FC, 1e-12, 1e-12));
}

TEST(TfBufferTest, AStampNewerThanTheLatestIsNotYetAndOlderThanTheCacheIsOutOfRange) {
  TfBuffer tf(TfBuffer::Options{.cache_s = 2.0, .extrapolation_s = 0.0});
  for (int i = 0; i <= 10; ++i) {
    ASSERT_TRUE(tf.Add("base", "flange", Yaw(0, {0.1 * i, 0, 0}), i * kSec, false).ok());
  }
  auto late = tf.Lookup("base", "flange", 11 * kSec);
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_THAT(late.status().message(), HasSubstr("not available yet"));
  auto old = tf.Lookup("base", "flange", 5 * kSec);
  ASSERT_FALSE(old.ok());
  EXPECT_EQ(old.status().code(), StatusCode::kOutOfRange);
  EXPECT_TRUE(tf.Lookup("base", "flange", 9 * kSec + kSec / 2).ok());
  // A sample older than the history is refused.
  EXPECT_EQ(tf.Add("base", "flange", Yaw(0, {0, 0, 0}), 1 * kSec, false).code(),
            StatusCode::kOutOfRange);
}

TEST(TfBufferTest, OutOfOrderSamplesAreSortedIn) {
  TfBuffer tf;
  ASSERT_TRUE(tf.Add("a", "b", Yaw(0, {0, 0, 0}), 0, false).ok());
  ASSERT_TRUE(tf.Add("a", "b", Yaw(0, {2, 0, 0}), 2 * kSec, false).ok());
  ASSERT_TRUE(tf.Add("a", "b", Yaw(0, {10, 0, 0}), 1 * kSec, false).ok());  // late arrival
  EXPECT_NEAR(tf.Lookup("a", "b", 1 * kSec)->translation().x(), 10.0, 1e-12);
  EXPECT_NEAR(tf.Lookup("a", "b", kSec / 2)->translation().x(), 5.0, 1e-12);
}

TEST(TfBufferTest, ExtrapolationToleranceHoldsTheNewestSample) {
  TfBuffer tf(TfBuffer::Options{.cache_s = 10.0, .extrapolation_s = 0.5});
  ASSERT_TRUE(tf.Add("a", "b", Yaw(0, {1, 0, 0}), kSec, false).ok());
  EXPECT_TRUE(tf.Lookup("a", "b", kSec + kSec / 4).ok());
  EXPECT_FALSE(tf.Lookup("a", "b", 2 * kSec).ok());
}

TEST(TfBufferTest, ToleranceHoldsTheNearestSampleOnBothSidesAndABagIsKeptWhole) {
  // As ros::bag::ReadBag reads a bag: every sample kept, its tolerance on both sides.
  TfBuffer tf(TfBuffer::Options{.cache_s = 0.0, .extrapolation_s = 20e-9});
  ASSERT_TRUE(tf.Add("a", "b", Yaw(0, {0, 0, 0}), 100 * kSec, false).ok());
  ASSERT_TRUE(tf.Add("a", "b", Yaw(0, {1, 0, 0}), 100 * kSec + 10, false).ok());
  ASSERT_TRUE(tf.Add("a", "b", Yaw(0, {5, 0, 0}), 0, false).ok());  // 100 s older: still kept
  EXPECT_NEAR(tf.Lookup("a", "b", 50 * kSec)->translation().x(), 2.5, 1e-9);
  EXPECT_NEAR(tf.Lookup("a", "b", -20)->translation().x(), 5.0, 1e-12);  // before the oldest
  EXPECT_NEAR(tf.Lookup("a", "b", 100 * kSec + 30)->translation().x(), 1.0, 1e-12);
  Result<RigidTransform> late = tf.Lookup("a", "b", 100 * kSec + 40'000'010);
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_THAT(late.status().message(),
              HasSubstr("the newest is 100.000000010 (40.0 ms earlier, beyond the tolerance of "
                        "0.0 ms)"));
  Result<RigidTransform> early = tf.Lookup("a", "b", -21);
  ASSERT_FALSE(early.ok());
  EXPECT_EQ(early.status().code(), StatusCode::kOutOfRange);
  EXPECT_THAT(early.status().message(), HasSubstr("at -1.999999979 is older than the oldest"));
}

TEST(TfBufferTest, TransformStampedAsTf2TakesIt) {
  TfBuffer tf;
  TransformStamped t;
  t.header.stamp = ToTimeMsg(3 * kSec);
  t.header.frame_id = "/base";  // a leading '/' (ROS 1 bags, old drivers): dropped, as tf2 does
  t.child_frame_id = "camera";
  t.transform = ToTransformMsg(Yaw(0.5, {1, 2, 3}));
  ASSERT_TRUE(tf.Add(t, true).ok());
  EXPECT_EQ(tf.Frames(), (std::vector<std::string>{"base", "camera"}));
  Result<RigidTransform> X = tf.Lookup("base", "/camera", 0);
  ASSERT_TRUE(X.ok()) << X.status().ToString();
  EXPECT_TRUE(X->IsNearlyEqualTo(Yaw(0.5, {1, 2, 3}), 1e-12, 1e-12));
  t.child_frame_id = "other";
  t.transform.rotation = {0, 0, 0, 0};
  EXPECT_THAT(tf.Add(t, false).message(),
              HasSubstr("/tf 'base' -> 'other' at 3.000000000: the quaternion (0, 0, 0, 0) has "
                        "norm 0, not 1"));
  t.transform.rotation = {0, 0, 0, 1.01};  // tf2's "denormalized quaternion"
  EXPECT_THAT(tf.Add(t, false).message(), HasSubstr("the quaternion (0, 0, 0, 1.01) has norm 1.0"));
  t.transform.rotation = {0, 0, 0, 1.0005};  // within 1e-3: normalised
  EXPECT_TRUE(tf.Add(t, false).ok());
  EXPECT_FALSE(tf.empty());
  EXPECT_TRUE(TfBuffer().empty());
}

TEST(TfBufferTest, RefusesLoopsSecondParentsAndEmptyNames) {
  TfBuffer tf;
  ASSERT_TRUE(tf.Add("a", "b", RigidTransform(), 0, true).ok());
  ASSERT_TRUE(tf.Add("b", "c", RigidTransform(), 0, true).ok());
  EXPECT_THAT(tf.Add("c", "a", RigidTransform(), 0, true).message(), HasSubstr("loop"));
  EXPECT_THAT(tf.Add("x", "c", RigidTransform(), 0, true).message(),
              HasSubstr("already has parent 'b'"));
  EXPECT_THAT(tf.Add("", "d", RigidTransform(), 0, true).message(), HasSubstr("empty"));
  EXPECT_THAT(tf.Add("d", "d", RigidTransform(), 0, true).message(), HasSubstr("own parent"));
}

TEST(TfBufferTest, UnknownAndDisconnectedFramesAreNamed) {
  TfBuffer tf;
  ASSERT_TRUE(tf.Add("a", "b", RigidTransform(), 0, true).ok());
  ASSERT_TRUE(tf.Add("x", "y", RigidTransform(), 0, true).ok());
  auto unknown = tf.Lookup("a", "camera", 0);
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(unknown.status().message(), HasSubstr("'camera' is not in the transform tree"));
  auto apart = tf.Lookup("b", "y", 0);
  ASSERT_FALSE(apart.ok());
  EXPECT_THAT(apart.status().message(), HasSubstr("not connected"));
  EXPECT_EQ(tf.Frames(), (std::vector<std::string>{"a", "b", "x", "y"}));
}

}  // namespace
}  // namespace avp::ros::msg

// avp live reads a camera as avp replay does: the shared fixtures (ros/msg/test/camera_fixtures.h:
// every colour encoding, 16UC1 and 32FC1 depth in both byte orders, NaN / inf / 0 depth, a
// negative depth) published over DDS on loopback and captured by Ros2RgbdSource give exactly the
// frames the fixtures name, which recording's bag reader test asserts for the same fixtures read
// from an MCAP file.
#include <chrono>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/ros/live/ros2_rgbd_source.h>
#include <avp/ros/live/tf_listener.h>
#include <avp/ros/msg/convert.h>

#include "camera_fixtures.h"
#include "ros2_test_support.h"

namespace avp::ros::live {
namespace {

using ros::dds::testing::LoopbackNode;
using ros::dds::testing::TestDomainId;
using ros::dds::testing::WaitFor;
using ::testing::HasSubstr;

TEST(LiveSameFramesTest, EveryFixtureIsCapturedAsTheBagReaderReadsIt) {
  const int domain = TestDomainId();
  auto cam = ros::dds::Node::Create(LoopbackNode("fake_camera", domain));
  auto avp = ros::dds::Node::Create(LoopbackNode("avp", domain));
  ASSERT_TRUE(cam.ok() && avp.ok());
  const ros::dds::QosProfile qos = ros::dds::QosProfile::SensorData();
  CameraTopicsOptions options;
  options.frame_timeout_s = 1.5;
  auto color = (*cam)->CreatePublisher<ros::msg::Image>(options.color_topic, qos);
  auto depth = (*cam)->CreatePublisher<ros::msg::Image>(options.depth_topic, qos);
  auto info = (*cam)->CreatePublisher<ros::msg::CameraInfo>(options.camera_info_topic, qos);
  auto tf_pub = TfBroadcaster::Create(**cam);
  ASSERT_TRUE(color.ok() && depth.ok() && info.ok() && tf_pub.ok());
  ros::msg::TfBuffer tf;
  auto listener = TfListener::Create(**avp, tf);
  ASSERT_TRUE(listener.ok());
  const RigidTransform X_WC = RigidTransform::FromRpy(0.1, -0.2, 0.3, {0.4, 0.0, 0.6});
  ros::msg::TransformStamped mount;
  mount.header.frame_id = options.base_frame;
  mount.child_frame_id = options.camera_frame;
  mount.transform = ros::msg::ToTransformMsg(X_WC);
  ASSERT_TRUE((*tf_pub)->SendStatic({mount}).ok());
  std::jthread info_thread([&](std::stop_token stop) {
    while (!stop.stop_requested()) {
      ros::msg::CameraInfo m = ros::msg::testing::FixtureCameraInfo();
      m.header.stamp = ros::msg::ToTimeMsg(NowNs());
      (void)(*info)->Publish(m);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
  auto source = Ros2RgbdSource::Create(**avp, tf, options, CameraIntrinsics{});
  ASSERT_TRUE(source.ok()) << source.status().ToString();
  ASSERT_TRUE(WaitFor([&] {
    return (*color)->matched_subscriptions() > 0 && (*depth)->matched_subscriptions() > 0 &&
           !tf.Frames().empty();
  }));
  const RigidTransform X_expected = tf.Lookup(options.base_frame, options.camera_frame, 0).value();

  uint64_t refused = 0;
  for (const ros::msg::testing::CameraFixture& f : ros::msg::testing::CameraFixtures()) {
    SCOPED_TRACE(f.name);
    // Published after the capture is asked for (frames stamped before it are never used).
    std::jthread camera([&](std::stop_token) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      const ros::msg::Time t = ros::msg::ToTimeMsg(NowNs());
      ros::msg::Image c = f.color;
      ros::msg::Image d = f.depth;
      c.header.stamp = d.header.stamp = t;
      (void)(*depth)->Publish(d);
      (void)(*color)->Publish(c);
    });
    if (!f.depth_error.empty()) {
      // Refused on arrival: the capture never sees a pair, and says why.
      Result<robot::Observation> obs = (*source)->Capture(RigidTransform(), 0);
      ASSERT_FALSE(obs.ok());
      EXPECT_EQ(obs.status().code(), StatusCode::kDeadlineExceeded);
      EXPECT_THAT(obs.status().message(), HasSubstr(options.depth_topic + ": " + f.depth_error));
      EXPECT_EQ((*source)->counters().refused, ++refused);
      continue;
    }
    Result<robot::Observation> obs = (*source)->Capture(RigidTransform(), 0);
    ASSERT_TRUE(obs.ok()) << obs.status().ToString();
    EXPECT_EQ(obs->frame.rgb, f.rgb);
    EXPECT_EQ(obs->frame.depth_m, f.depth_m);  // bit for bit: 0 for every no-return pixel
    EXPECT_EQ(obs->frame.K.width, ros::msg::testing::kFixtureWidth);
    EXPECT_EQ(obs->frame.K.fx, 50.0);
    EXPECT_EQ(obs->frame.frame_id, options.camera_frame);
    EXPECT_TRUE(obs->frame.X_WC.IsNearlyEqualTo(X_expected, 0.0, 0.0));
  }
  EXPECT_EQ(refused, 1u);
}

}  // namespace
}  // namespace avp::ros::live

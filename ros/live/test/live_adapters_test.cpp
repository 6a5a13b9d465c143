// The live adapters over DDS on loopback, against a fake camera and a fake arm in the same
// process (the image conversions are ros/msg's: ros/msg/test/images_test.cpp, and
// same_frames_test.cpp for every encoding through this source): refusals, pairing by stamp, frames
// stamped before the capture, a camera that stops, missing TF, a malformed sample, an arm that
// arrives, one that never does, a stop request, a planned trajectory sent whole (both joint
// conventions) and an invalid one refused before anything is published.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stop_token>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/robot/arm_model.h>
#include <avp/robot/trajectory.h>
#include <avp/ros/live/ros2_arm.h>
#include <avp/ros/live/ros2_rgbd_source.h>
#include <avp/ros/live/rviz_publisher.h>
#include <avp/ros/live/tf_listener.h>
#include <avp/ros/msg/convert.h>

#include "ros2_test_support.h"

namespace avp::ros::live {
namespace {

using ros::dds::testing::LoopbackNode;
using ros::dds::testing::TestDomainId;
using ros::dds::testing::WaitFor;
using ::testing::HasSubstr;

/// The value of a Result that must be OK (the test fails and aborts otherwise).
template <class T>
T Take(Result<T> r) {
  if (!r.ok()) throw Error(r.status().ToString());
  return std::move(r).value();
}

ros::msg::Image ColorImage(int w, int h, const std::string& encoding, int64_t stamp_ns) {
  ros::msg::Image m;
  m.header.stamp = ros::msg::Time::FromNanoseconds(stamp_ns);
  m.header.frame_id = "camera_color_optical_frame";
  m.width = static_cast<uint32_t>(w);
  m.height = static_cast<uint32_t>(h);
  m.encoding = encoding;
  m.step = static_cast<uint32_t>(3 * w);
  m.data.resize(static_cast<size_t>(3 * w * h));
  for (size_t i = 0; i < m.data.size(); i += 3) {
    m.data[i] = 10;
    m.data[i + 1] = 20;
    m.data[i + 2] = 30;
  }
  return m;
}

ros::msg::Image DepthMm(int w, int h, uint16_t mm, int64_t stamp_ns) {
  ros::msg::Image m;
  m.header.stamp = ros::msg::Time::FromNanoseconds(stamp_ns);
  m.header.frame_id = "camera_color_optical_frame";
  m.width = static_cast<uint32_t>(w);
  m.height = static_cast<uint32_t>(h);
  m.encoding = "16UC1";
  m.step = static_cast<uint32_t>(2 * w);
  m.data.resize(static_cast<size_t>(2 * w * h));
  for (size_t i = 0; i < m.data.size(); i += 2) {
    m.data[i] = static_cast<uint8_t>(mm & 0xff);
    m.data[i + 1] = static_cast<uint8_t>(mm >> 8);
  }
  return m;
}

ros::msg::CameraInfo Info(int w, int h) {
  ros::msg::CameraInfo info;
  info.header.frame_id = "camera_color_optical_frame";
  info.width = static_cast<uint32_t>(w);
  info.height = static_cast<uint32_t>(h);
  info.distortion_model = "plumb_bob";
  info.k = {50.0, 0, (w - 1) / 2.0, 0, 50.0, (h - 1) / 2.0, 0, 0, 1};
  return info;
}

/// A fake RealSense + robot_state_publisher on one node, avp's live side on another.
class LiveSourceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const int domain = TestDomainId();
    auto cam = ros::dds::Node::Create(LoopbackNode("fake_camera", domain));
    auto avp = ros::dds::Node::Create(LoopbackNode("avp", domain));
    ASSERT_TRUE(cam.ok() && avp.ok());
    cam_ = std::move(*cam);
    avp_ = std::move(*avp);
    color_ = Take(cam_->CreatePublisher<ros::msg::Image>(options_.color_topic,
                                                         ros::dds::QosProfile::Default()));
    depth_ = Take(cam_->CreatePublisher<ros::msg::Image>(options_.depth_topic,
                                                         ros::dds::QosProfile::Default()));
    info_ = Take(cam_->CreatePublisher<ros::msg::CameraInfo>(options_.camera_info_topic,
                                                             ros::dds::QosProfile::Default()));
    auto tf = TfBroadcaster::Create(*cam_);
    ASSERT_TRUE(tf.ok());
    tf_pub_ = std::move(*tf);
    auto listener = TfListener::Create(*avp_, tf_);
    ASSERT_TRUE(listener.ok());
    listener_ = std::move(*listener);
    options_.best_effort = false;
    options_.frame_timeout_s = 2.0;
    options_.tf_timeout_s = 0.3;
  }

  /// CameraInfo at 20 Hz from a thread until the test ends (drivers publish it with every frame).
  void StartInfo(const ros::msg::CameraInfo& info = Info(8, 6)) {
    info_thread_ = std::jthread([this, info](std::stop_token stop) {
      while (!stop.stop_requested()) {
        (void)info_->Publish(info);
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
    });
  }

  void SendCameraTf(int64_t stamp_ns, double x) {
    ros::msg::TFMessage msg;
    ros::msg::TransformStamped t;
    t.header.stamp = ros::msg::Time::FromNanoseconds(stamp_ns);
    t.header.frame_id = "igus_rebel_base_link";
    t.child_frame_id = "camera_color_optical_frame";
    t.transform = ros::msg::ToTransformMsg(RigidTransform(Eigen::Vector3d(x, 0, 0)));
    msg.transforms.push_back(t);
    ASSERT_TRUE(tf_pub_->Send(msg).ok());
  }

  Result<std::unique_ptr<Ros2RgbdSource>> MakeSource(std::stop_token stop = {}) {
    // Wait until the readers see the writers, so nothing published next is lost.
    CameraIntrinsics range;
    range.min_depth_m = 0.1;
    range.max_depth_m = 3.0;
    return Ros2RgbdSource::Create(*avp_, tf_, options_, range, stop);
  }

  /// Waits until the image readers see the writers and /tf reaches the listener (a probe frame),
  /// so that nothing the test publishes next is lost to discovery.
  void WaitMatched() {
    ASSERT_TRUE(WaitFor([&] {
      return color_->matched_subscriptions() > 0 && depth_->matched_subscriptions() > 0;
    }));
    ASSERT_TRUE(WaitFor([&] {
      ros::msg::TFMessage msg;
      ros::msg::TransformStamped t;
      t.header.stamp = ros::msg::Time::FromNanoseconds(NowNs());
      t.header.frame_id = "igus_rebel_base_link";
      t.child_frame_id = "probe";
      t.transform.rotation.w = 1.0;
      msg.transforms.push_back(t);
      (void)tf_pub_->Send(msg);
      const std::vector<std::string> frames = tf_.Frames();
      return std::find(frames.begin(), frames.end(), "probe") != frames.end();
    }));
  }

  CameraTopicsOptions options_;
  std::unique_ptr<ros::dds::Node> cam_, avp_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::Image>> color_, depth_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::CameraInfo>> info_;
  std::unique_ptr<TfBroadcaster> tf_pub_;
  ros::msg::TfBuffer tf_;
  std::unique_ptr<TfListener> listener_;
  std::jthread info_thread_;
};

TEST_F(LiveSourceTest, CapturesThePairStampedAfterTheCallWithItsTransform) {
  StartInfo();
  auto source = MakeSource();
  ASSERT_TRUE(source.ok()) << source.status().ToString();
  WaitMatched();
  EXPECT_EQ((*source)->intrinsics().width, 8);
  EXPECT_DOUBLE_EQ((*source)->intrinsics().fx, 50.0);
  // An old pair, stamped before the capture is asked for: never used.
  const int64_t old = NowNs() - 1'000'000'000;
  ASSERT_TRUE(color_->Publish(ColorImage(8, 6, "rgb8", old)).ok());
  ASSERT_TRUE(depth_->Publish(DepthMm(8, 6, 500, old)).ok());
  std::jthread camera([&](std::stop_token) {
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    const int64_t t = NowNs();
    SendCameraTf(t - 10'000'000, 1.0);
    SendCameraTf(t + 10'000'000, 3.0);
    // An unpaired colour (6 ms before the depth), the depth, then its colour 4 ms later: paired
    // within the 5 ms skew.
    (void)color_->Publish(ColorImage(8, 6, "bgr8", t - 4'000'000));
    (void)depth_->Publish(DepthMm(8, 6, 1500, t + 2'000'000));
    (void)color_->Publish(ColorImage(8, 6, "rgb8", t + 4'000'000 + 2'000'000));
  });
  auto obs = (*source)->Capture(RigidTransform(), 0);
  ASSERT_TRUE(obs.ok()) << obs.status().ToString();
  EXPECT_FLOAT_EQ(obs->frame.depth_m.at(3, 3), 1.5f);
  EXPECT_EQ(obs->frame.rgb.at(0, 0, 0), 10);  // the rgb8 frame
  // X_WC interpolated at the colour stamp between x = 1 (t - 10 ms) and x = 3 (t + 10 ms).
  EXPECT_NEAR(obs->frame.X_WC.translation().x(), 2.0 + 2.0 * 6.0 / 20.0, 1e-6);
  EXPECT_FALSE(obs->labels.has_value());
  EXPECT_EQ((*source)->counters().pairs_used, 1u);
}

TEST_F(LiveSourceTest, ADistortedCameraIsRectifiedToItsProjectionMatrix) {
  // A plumb_bob lens and a P whose focal length differs from K's: the frames avp fuses are the
  // rectified camera's (ros/msg/lens.h, as avp replay's), depth taken from the nearest raw pixel.
  ros::msg::CameraInfo info = Info(8, 6);
  info.d = {-0.2, 0.05, 0.0, 0.0, 0.0};
  info.p = {40.0, 0, 3.5, 0, 0, 40.0, 2.5, 0, 0, 0, 1, 0};
  StartInfo(info);
  auto source = MakeSource();
  ASSERT_TRUE(source.ok()) << source.status().ToString();
  WaitMatched();
  std::jthread camera([&](std::stop_token) {
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    const int64_t t = NowNs();
    SendCameraTf(t - 10'000'000, 1.0);
    SendCameraTf(t + 10'000'000, 1.0);
    (void)depth_->Publish(DepthMm(8, 6, 1500, t));
    (void)color_->Publish(ColorImage(8, 6, "rgb8", t));
  });
  auto obs = (*source)->Capture(RigidTransform(), 0);
  ASSERT_TRUE(obs.ok()) << obs.status().ToString();
  EXPECT_DOUBLE_EQ(obs->frame.K.fx, 40.0);  // P's, not K's 50
  EXPECT_DOUBLE_EQ(obs->frame.K.cx, 3.5);
  // Every rectified depth is a raw pixel's (1500 mm as metres) or 0 where the raw image has none.
  const float raw = obs->frame.depth_m.at(3, 3);
  EXPECT_FLOAT_EQ(raw, 1.5f);
  // The rectified camera (f 40) sees wider than the raw one (f 50): its border pixels look
  // outside the raw image (column 0 at -0.87 px, row 0 at -0.63 px) and have no depth; the
  // interior has the raw depth.
  for (int v = 0; v < 6; ++v) {
    for (int u = 0; u < 8; ++u) {
      const bool border = u == 0 || u == 7 || v == 0 || v == 5;
      EXPECT_EQ(obs->frame.depth_m.at(u, v), border ? 0.0f : raw) << u << ", " << v;
    }
  }
}

TEST_F(LiveSourceTest, FramesArrivingOutOfOrderArePairedByStamp) {
  StartInfo();
  auto source = MakeSource();
  ASSERT_TRUE(source.ok()) << source.status().ToString();
  WaitMatched();
  std::jthread camera([&](std::stop_token) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const int64_t t = NowNs();
    SendCameraTf(t, 1.0);
    SendCameraTf(t + 100'000'000, 1.0);
    // Colour t + 50 ms, then colour t + 20 ms, then the depth of t + 20 ms only.
    (void)color_->Publish(ColorImage(8, 6, "bgr8", t + 50'000'000));
    (void)color_->Publish(ColorImage(8, 6, "rgb8", t + 20'000'000));
    (void)depth_->Publish(DepthMm(8, 6, 800, t + 20'000'000));
  });
  auto obs = (*source)->Capture(RigidTransform(), 0);
  ASSERT_TRUE(obs.ok()) << obs.status().ToString();
  EXPECT_EQ(obs->frame.rgb.at(0, 0, 0), 10);  // the rgb8 frame, paired with its depth
  EXPECT_FLOAT_EQ(obs->frame.depth_m.at(0, 0), 0.8f);
}

TEST_F(LiveSourceTest, ACameraThatStopsIsADeadlineThatNamesTheTopics) {
  StartInfo();
  options_.frame_timeout_s = 0.3;
  auto source = MakeSource();
  ASSERT_TRUE(source.ok()) << source.status().ToString();
  const auto t0 = std::chrono::steady_clock::now();
  auto obs = (*source)->Capture(RigidTransform(), 0);
  ASSERT_FALSE(obs.ok());
  EXPECT_EQ(obs.status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_THAT(obs.status().message(), HasSubstr("/camera/camera/color/image_raw"));
  EXPECT_THAT(obs.status().message(), HasSubstr("received 0 colour, 0 depth"));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(2));
}

TEST_F(LiveSourceTest, NoCameraInfoIsAClearError) {
  options_.frame_timeout_s = 0.3;
  auto source = MakeSource();
  ASSERT_FALSE(source.ok());
  EXPECT_EQ(source.status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_THAT(source.status().message(),
              HasSubstr("no usable CameraInfo on /camera/camera/color/camera_info"));
}

TEST_F(LiveSourceTest, UnsupportedEncodingsAndMalformedSamplesAreReportedAndSkipped) {
  StartInfo();
  options_.frame_timeout_s = 1.0;
  auto source = MakeSource();
  ASSERT_TRUE(source.ok()) << source.status().ToString();
  WaitMatched();
  // Garbage bytes on the colour topic with the Image type: the subscription counts and goes on.
  auto raw =
      cam_->CreateRawPublisher(options_.color_topic, ros::dds::TypeInfo::Of<ros::msg::Image>(),
                               ros::dds::QosProfile::Default());
  ASSERT_TRUE(raw.ok());
  std::jthread camera([&](std::stop_token) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const uint8_t garbage[] = {0, 1, 0, 0, 0xff, 0xff, 0xff, 0x7f, 1, 2, 3};
    (void)(*raw)->Publish(garbage);
    const int64_t t = NowNs();
    SendCameraTf(t, 1.0);
    (void)color_->Publish(ColorImage(8, 6, "yuv422", t));
    (void)depth_->Publish(DepthMm(8, 6, 1000, t));
  });
  auto obs = (*source)->Capture(RigidTransform(), 0);
  ASSERT_FALSE(obs.ok());
  EXPECT_EQ(obs.status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_THAT(obs.status().message(), HasSubstr("colour encoding 'yuv422' is not supported"));
  EXPECT_EQ((*source)->counters().refused, 1u);
  // A good pair afterwards is captured.
  std::jthread again([&](std::stop_token) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const int64_t t = NowNs();
    SendCameraTf(t, 1.0);
    (void)color_->Publish(ColorImage(8, 6, "rgb8", t));
    (void)depth_->Publish(DepthMm(8, 6, 1000, t));
  });
  auto good = (*source)->Capture(RigidTransform(), 0);
  EXPECT_TRUE(good.ok()) << good.status().ToString();
}

TEST_F(LiveSourceTest, MissingOrLateTransformIsAnErrorNamingTheFrames) {
  StartInfo();
  auto source = MakeSource();
  ASSERT_TRUE(source.ok());
  WaitMatched();
  std::jthread camera([&](std::stop_token) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const int64_t t = NowNs();
    (void)color_->Publish(ColorImage(8, 6, "rgb8", t));
    (void)depth_->Publish(DepthMm(8, 6, 1000, t));
  });
  auto obs = (*source)->Capture(RigidTransform(), 0);
  ASSERT_FALSE(obs.ok());
  EXPECT_THAT(obs.status().message(),
              HasSubstr("no transform igus_rebel_base_link -> camera_color_optical_frame"));
  // TF that stops before the frame's stamp: "not available yet" after the TF timeout.
  SendCameraTf(NowNs(), 1.0);
  std::jthread late([&](std::stop_token) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const int64_t t = NowNs();
    (void)color_->Publish(ColorImage(8, 6, "rgb8", t));
    (void)depth_->Publish(DepthMm(8, 6, 1000, t));
  });
  auto late_obs = (*source)->Capture(RigidTransform(), 0);
  ASSERT_FALSE(late_obs.ok());
  EXPECT_EQ(late_obs.status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_THAT(late_obs.status().message(), HasSubstr("not available yet"));
}

TEST_F(LiveSourceTest, AStopRequestEndsTheWaitAsCancelled) {
  StartInfo();
  std::stop_source stop;
  options_.frame_timeout_s = 30.0;
  auto source = MakeSource(stop.get_token());
  ASSERT_TRUE(source.ok());
  std::jthread stopper([&](std::stop_token) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    stop.request_stop();
  });
  const auto t0 = std::chrono::steady_clock::now();
  auto obs = (*source)->Capture(RigidTransform(), 0);
  EXPECT_EQ(obs.status().code(), StatusCode::kCancelled);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(2));
}

/// A fake arm: publishes joint states; follows trajectory goals when `follow` is set.
class LiveArmTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto model = robot::LoadDefaultArm();
    ASSERT_TRUE(model.ok());
    model_ = std::make_unique<robot::ArmModel>(*model);
    q_ = model_->home_joints();
    const int domain = TestDomainId();
    robot_ = Take(ros::dds::Node::Create(LoopbackNode("fake_arm", domain)));
    avp_ = Take(ros::dds::Node::Create(LoopbackNode("avp", domain)));
    joints_ = Take(robot_->CreatePublisher<ros::msg::JointState>(
        "/joint_states", ros::dds::QosProfile::SensorData()));
    goals_ = Take(robot_->CreateSubscription<ros::msg::JointTrajectory>(
        options_.trajectory_topic, ros::dds::QosProfile::Default(),
        [this](ros::msg::JointTrajectory&& t, const ros::dds::SampleInfo&) {
          std::lock_guard lock(mutex_);
          last_goal_ = t;
          ++goals_received_;
          if (follow_) {
            for (size_t i = 0; i < t.joint_names.size(); ++i) {
              q_[static_cast<Eigen::Index>(i)] = t.points.back().positions[i];
            }
          }
        }));
    options_.min_duration_s = 0.0;
    options_.arrival_timeout_s = 0.5;
    publisher_ = std::jthread([this](std::stop_token stop) {
      while (!stop.stop_requested()) {
        ros::msg::JointState js;
        js.header.stamp = ros::msg::Time::FromNanoseconds(NowNs());
        {
          std::lock_guard lock(mutex_);
          js.name = names_.empty() ? model_->joint_names() : names_;
          js.position.assign(q_.data(), q_.data() + q_.size());
        }
        (void)joints_->Publish(js);
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
    });
  }
  void TearDown() override { publisher_ = {}; }

  /// Sends a planned trajectory (3 vertices, TimeParameterize at half the limits, 0.1 s samples)
  /// through Ros2Arm and checks the message the fake arm received against it: the joint names,
  /// every point in the robot's convention (the reference one with options_.reference_joints),
  /// times strictly increasing and equal to the trajectory's, speeds and finite-difference
  /// accelerations within the scaled limits; then that the arm arrived at the last point.
  void SendAPlannedTrajectoryAndCheckTheMessage() {
    const robot::ArmModel& model = *model_;
    if (options_.reference_joints) {
      std::lock_guard lock(mutex_);
      q_ = model.ToReferenceJoints(model.home_joints());  // the robot speaks the reference's
    }
    auto arm = Ros2Arm::Create(*avp_, tf_, model, options_);
    ASSERT_TRUE(arm.ok()) << arm.status().ToString();
    ASSERT_TRUE(WaitFor([&] { return goals_->matched_publishers() > 0; }));
    ASSERT_NEAR(((*arm)->CurrentJoints() - model.home_joints()).norm(), 0.0, 1e-9);

    const Eigen::VectorXd a = model.home_joints();
    Eigen::VectorXd b = a;
    b[0] += 0.3;
    b[2] -= 0.2;
    Eigen::VectorXd c = b;
    c[1] += 0.25;
    c[4] -= 0.15;
    constexpr double kScaling = 0.5;
    const robot::JointTrajectory t =
        Take(robot::TimeParameterize(model, {a, b, c}, kScaling, kScaling, 0.1));
    ASSERT_TRUE(t.Validate(model).ok()) << t.Validate(model).ToString();
    ASSERT_GT(t.points.size(), 3u);  // samples between the vertices, not only the vertices

    const robot::MoveResult r = (*arm)->FollowTrajectory(t);
    ASSERT_TRUE(r.ok()) << r.status.ToString();
    EXPECT_NEAR((r.q - c).norm(), 0.0, 1e-9);
    EXPECT_NEAR((r.q - t.points.back().q).norm(), 0.0, 1e-9);
    EXPECT_NEAR(r.execution_s, t.duration_s(), 1e-12);

    std::lock_guard lock(mutex_);
    ASSERT_EQ(goals_received_, 1);
    const ros::msg::JointTrajectory& m = last_goal_;
    EXPECT_EQ(m.joint_names, model.joint_names());
    ASSERT_EQ(m.points.size(), t.points.size());
    const auto n = static_cast<size_t>(model.num_joints());
    // The reference convention flips signs and shifts: velocities take the signs only.
    const std::vector<double>& sign = model.config().reference_convention.sign;
    const double a_max = kScaling * model.config().joint_acceleration_limit;
    for (size_t k = 0; k < m.points.size(); ++k) {
      const ros::msg::JointTrajectoryPoint& p = m.points[k];
      const robot::TrajectoryPoint& tp = t.points[k];
      const Eigen::VectorXd q = options_.reference_joints ? model.ToReferenceJoints(tp.q) : tp.q;
      ASSERT_EQ(p.positions.size(), n) << k;
      ASSERT_EQ(p.velocities.size(), n) << k;
      for (size_t j = 0; j < n; ++j) {
        const auto jj = static_cast<Eigen::Index>(j);
        const double s = options_.reference_joints && !sign.empty() ? sign[j] : 1.0;
        EXPECT_NEAR(p.positions[j], q[jj], 1e-9) << "point " << k << " joint " << j;
        EXPECT_NEAR(p.velocities[j], s * tp.qd[jj], 1e-9) << "point " << k << " joint " << j;
        EXPECT_LE(std::abs(p.velocities[j]),
                  kScaling * model.joints()[j].velocity_limit * (1 + 1e-9))
            << "point " << k << " joint " << j;
      }
      // Nanoseconds: the trajectory's time, to the nanosecond.
      const int64_t ns = p.time_from_start.ToNanoseconds();
      EXPECT_LE(std::abs(static_cast<double>(ns) - tp.t_s * 1e9), 1.0) << k;
      if (k == 0) {
        EXPECT_EQ(ns, 0);
        continue;
      }
      const int64_t ns_before = m.points[k - 1].time_from_start.ToNanoseconds();
      ASSERT_GT(ns, ns_before) << k;
      const double dt = static_cast<double>(ns - ns_before) * 1e-9;
      for (size_t j = 0; j < n; ++j) {
        const double acc = (p.velocities[j] - m.points[k - 1].velocities[j]) / dt;
        EXPECT_LE(std::abs(acc), a_max * (1 + 1e-6)) << "point " << k << " joint " << j;
      }
    }
    // At rest at both ends; the last point is the last vertex.
    for (size_t j = 0; j < n; ++j) {
      EXPECT_EQ(m.points.front().velocities[j], 0.0) << j;
      EXPECT_EQ(m.points.back().velocities[j], 0.0) << j;
    }
    const Eigen::VectorXd last = options_.reference_joints ? model.ToReferenceJoints(c) : c;
    for (size_t j = 0; j < n; ++j) {
      EXPECT_NEAR(m.points.back().positions[j], last[static_cast<Eigen::Index>(j)], 1e-9) << j;
    }
  }

  std::unique_ptr<robot::ArmModel> model_;
  ArmTopicsOptions options_;
  std::unique_ptr<ros::dds::Node> robot_, avp_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::JointState>> joints_;
  std::unique_ptr<ros::dds::Subscription<ros::msg::JointTrajectory>> goals_;
  ros::msg::TfBuffer tf_;
  std::mutex mutex_;
  Eigen::VectorXd q_;
  std::vector<std::string> names_;
  bool follow_ = true;
  ros::msg::JointTrajectory last_goal_;
  int goals_received_ = 0;
  std::jthread publisher_;
};

TEST_F(LiveArmTest, ArrivesWhenTheJointStatesReachTheGoal) {
  auto arm = Ros2Arm::Create(*avp_, tf_, *model_, options_);
  ASSERT_TRUE(arm.ok()) << arm.status().ToString();
  ASSERT_TRUE(WaitFor([&] { return (*arm)->CurrentJoints().size() == 6; }));
  EXPECT_NEAR(((*arm)->CurrentJoints() - model_->home_joints()).norm(), 0.0, 1e-12);
  ASSERT_TRUE(WaitFor([&] { return goals_->matched_publishers() > 0; }));
  Eigen::VectorXd goal = model_->home_joints();
  goal[0] += 0.2;
  const robot::MoveResult r = (*arm)->MoveToJoints(goal);
  ASSERT_TRUE(r.ok()) << r.status.ToString();
  EXPECT_NEAR((r.q - goal).norm(), 0.0, 1e-12);
  EXPECT_NEAR(r.joint_path_length, 0.2, 1e-9);
  std::lock_guard lock(mutex_);
  EXPECT_EQ(goals_received_, 1);
  EXPECT_EQ(last_goal_.joint_names, model_->joint_names());
  ASSERT_EQ(last_goal_.points.size(), 1u);
  // 0.2 rad at 0.5 rad/s.
  EXPECT_EQ(last_goal_.points[0].time_from_start.ToNanoseconds(), 400'000'000);
}

TEST_F(LiveArmTest, AnArmThatNeverArrivesIsADeadlineNamingTheJoint) {
  follow_ = false;
  auto arm = Ros2Arm::Create(*avp_, tf_, *model_, options_);
  ASSERT_TRUE(arm.ok());
  Eigen::VectorXd goal = model_->home_joints();
  goal[2] += 0.3;
  const auto t0 = std::chrono::steady_clock::now();
  const robot::MoveResult r = (*arm)->MoveToJoints(goal);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status.code(), StatusCode::kDeadlineExceeded);
  EXPECT_THAT(r.status.message(), HasSubstr("did not arrive"));
  EXPECT_THAT(r.status.message(), HasSubstr("joint 'joint3'"));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(3));
}

TEST_F(LiveArmTest, JointStatesWithoutTheArmsJointsAreRefusedByName) {
  {
    std::lock_guard lock(mutex_);
    names_ = {"a", "b", "c", "d", "e", "f"};
  }
  options_.state_timeout_s = 0.3;
  auto arm = Ros2Arm::Create(*avp_, tf_, *model_, options_);
  ASSERT_FALSE(arm.ok());
  EXPECT_EQ(arm.status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(arm.status().message(), HasSubstr("joint 'joint1' is missing"));
}

TEST_F(LiveArmTest, AStopRequestWhileMovingIsCancelled) {
  follow_ = false;
  options_.arrival_timeout_s = 30.0;
  std::stop_source stop;
  auto arm = Ros2Arm::Create(*avp_, tf_, *model_, options_, stop.get_token());
  ASSERT_TRUE(arm.ok());
  std::jthread stopper([&](std::stop_token) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    stop.request_stop();
  });
  Eigen::VectorXd goal = model_->home_joints();
  goal[0] += 0.3;
  const robot::MoveResult r = (*arm)->MoveToJoints(goal);
  EXPECT_EQ(r.status.code(), StatusCode::kCancelled);
}

TEST_F(LiveArmTest, APlannedTrajectoryIsSentWholeWithMonotonicTimesWithinTheLimits) {
  SendAPlannedTrajectoryAndCheckTheMessage();
}

TEST_F(LiveArmTest, APlannedTrajectoryIsSentInTheReferenceConventionWhenAsked) {
  options_.reference_joints = true;
  SendAPlannedTrajectoryAndCheckTheMessage();
}

TEST_F(LiveArmTest, AnInvalidTrajectoryIsRefusedByPointAndNothingIsPublished) {
  auto arm = Ros2Arm::Create(*avp_, tf_, *model_, options_);
  ASSERT_TRUE(arm.ok()) << arm.status().ToString();
  ASSERT_TRUE(WaitFor([&] { return goals_->matched_publishers() > 0; }));
  Eigen::VectorXd b = model_->home_joints();
  b[0] += 0.3;
  robot::JointTrajectory t =
      Take(robot::TimeParameterize(*model_, {model_->home_joints(), b}, 0.5, 0.5, 0.1));
  ASSERT_GE(t.points.size(), 3u);
  t.points[2].t_s = t.points[1].t_s;  // not strictly increasing
  const robot::MoveResult r = (*arm)->FollowTrajectory(t);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status.message(), HasSubstr("FollowTrajectory refused"));
  EXPECT_THAT(r.status.message(), HasSubstr("trajectory point 2: time_from_start"));
  EXPECT_NEAR((r.q - model_->home_joints()).norm(), 0.0, 1e-12);
  EXPECT_EQ((*arm)->goals_sent(), 0u);
  EXPECT_EQ((*arm)->num_refused_moves(), 1);
  // Give a wrongly published goal time to arrive before checking that none did.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  std::lock_guard lock(mutex_);
  EXPECT_EQ(goals_received_, 0);
}

TEST(RvizMarkersTest, CandidatesAreColouredByUtilityAndTheChosenViewIsLabelled) {
  pipeline::StepRecord step;
  step.view = 2;
  for (int i = 0; i < 3; ++i) {
    planning::ViewCandidate c;
    c.X_WC = RigidTransform(Eigen::Vector3d(0.1 * i, 0, 0));
    c.utility = 3.0 - i;
    c.reachable = true;
    step.top_candidates.push_back(c);
  }
  step.chosen = step.top_candidates[0];
  step.chosen_rank = 0;
  ros::msg::Header h;
  h.frame_id = "igus_rebel_base_link";
  const ros::msg::MarkerArray cands = CandidateMarkers(step, h);
  ASSERT_EQ(cands.markers.size(), 4u);  // DELETEALL + 3 arrows
  EXPECT_EQ(cands.markers[0].action, ros::msg::Marker::kDeleteAll);
  // Best utility: viridis yellow; worst: viridis purple.
  EXPECT_GT(cands.markers[1].color.r, 0.9f);
  EXPECT_LT(cands.markers[3].color.r, 0.3f);
  EXPECT_EQ(cands.markers[1].points.size(), 2u);
  const ros::msg::MarkerArray chosen = ChosenMarkers(step, h);
  ASSERT_EQ(chosen.markers.size(), 3u);
  EXPECT_THAT(chosen.markers[2].text, HasSubstr("view 3 (rank 0): utility 3"));
}

}  // namespace
}  // namespace avp::ros::live

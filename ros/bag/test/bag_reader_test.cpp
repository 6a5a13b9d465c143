// Reading a real robot's bag: a synthetic rosbag2 MCAP as the RealSense driver and a robot write
// it (30 Hz bgr8 colour and 16UC1 millimetre depth on the driver's topics, CameraInfo, a /tf arm
// joint moving under a /tf_static chain), thinned to 1 frame per second by default, the camera
// pose from TF at the image stamp; topics and frames by option; damaged files and bad messages.
#include "avp/ros/bag/bag_reader.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/robot/arm_model.h>
#include <avp/ros/mcap/mcap.h>
#include <avp/ros/msg/convert.h>
#include <avp/test/temp_dir_test.h>

#include "camera_fixtures.h"
#include "robot_bag_writer.h"

namespace avp::ros::bag {
namespace {

namespace fs = std::filesystem;

using ::testing::HasSubstr;

constexpr int kW = 8;
constexpr int kH = 6;
constexpr int64_t kT0 = 1'700'000'000'000'000'000;  // the bag's first stamp, ns
constexpr int64_t kFrameNs = 33'333'333;            // 30 Hz

/// The arm joint: link1 in base, translating along x at 0.1 m/s and turning about z at 0.2 rad/s.
RigidTransform Link1At(int64_t t_ns) {
  const double t = static_cast<double>(t_ns - kT0) * 1e-9;
  return RigidTransform::FromRpy(0.0, 0.0, 0.2 * t, Eigen::Vector3d(0.1 * t, 0.0, 0.3));
}
const RigidTransform kBaseToArm = RigidTransform::FromRpy(0.0, 0.0, 0.0, {0.0, 0.0, 0.1});
const RigidTransform kLinkToOptical =
    RigidTransform::FromRpy(-M_PI / 2, 0.0, -M_PI / 2, {0.05, 0.0, 0.02});

/// X_WC at `t_ns`: base -> arm (static) -> link1 (dynamic) -> optical (static).
RigidTransform ExpectedPose(int64_t t_ns) { return kBaseToArm * Link1At(t_ns) * kLinkToOptical; }

ros::msg::TransformStamped Tf(const std::string& parent, const std::string& child,
                              const RigidTransform& X, int64_t t_ns) {
  ros::msg::TransformStamped t;
  t.header = {ros::msg::ToTimeMsg(t_ns), parent};
  t.child_frame_id = child;
  t.transform = ros::msg::ToTransformMsg(X);
  return t;
}

struct BagSpec {
  double seconds = 3.0;
  std::string color_encoding = "bgr8";
  std::string depth_encoding = "16UC1";
  int64_t depth_offset_ns = 1'000'000;  // depth stamped 1 ms after colour
  bool with_tf = true;
  /// /tf runs from 20 ms before the first image to this long after the bag's last 1/30 s.
  int64_t tf_tail_ns = 20'000'000;
  bool with_camera_info = true;
  /// Frame index whose colour image is broken (its data one byte short), or -1.
  int broken_color = -1;
};

/// Colour of pixel (u, v) of frame i, as RGB.
std::array<uint8_t, 3> Rgb(int i, int u, int v) {
  return {static_cast<uint8_t>(10 * u + i), static_cast<uint8_t>(20 * v), static_cast<uint8_t>(i)};
}
uint16_t DepthMm(int i, int u, int v) { return static_cast<uint16_t>(500 + 10 * i + u + 3 * v); }

class BagReaderTest : public test::TempDirTest {
 protected:
  template <class T>
  void Put(ros::mcap::Writer& w, uint16_t channel, int64_t t, const T& msg) {
    const std::vector<uint8_t> bytes = ros::msg::Encode(msg);
    ASSERT_TRUE(
        w.Write(channel, seq_++, static_cast<uint64_t>(t), static_cast<uint64_t>(t), bytes).ok());
  }

  template <class T>
  uint16_t Channel(ros::mcap::Writer& w, const std::string& topic) {
    const uint16_t schema =
        w.AddSchema(ros::msg::MessageTraits<T>::kRosName, "ros2msg", ros::msg::Definition<T>())
            .value();
    return w
        .AddChannel(schema, topic, "cdr",
                    {{"offered_qos_profiles", ros::mcap::OfferedQosProfiles()}})
        .value();
  }

  std::filesystem::path WriteBag(const BagSpec& spec, const std::string& name = "robot.mcap") {
    const std::filesystem::path path = dir_ / name;
    auto w = ros::mcap::Writer::Open(path, {.chunk_size = 64 * 1024, .compression = ""}).value();
    const uint16_t color = Channel<ros::msg::Image>(*w, "/camera/camera/color/image_raw");
    const uint16_t depth =
        Channel<ros::msg::Image>(*w, "/camera/camera/aligned_depth_to_color/image_raw");
    const uint16_t info = Channel<ros::msg::CameraInfo>(*w, "/camera/camera/color/camera_info");
    const uint16_t tf = Channel<ros::msg::TFMessage>(*w, "/tf");
    const uint16_t tf_static = Channel<ros::msg::TFMessage>(*w, "/tf_static");
    if (spec.with_tf) {
      ros::msg::TFMessage s;
      s.transforms.push_back(Tf("igus_rebel_base_link", "arm_mount", kBaseToArm, kT0));
      s.transforms.push_back(Tf("link1", "camera_color_optical_frame", kLinkToOptical, kT0));
      Put(*w, tf_static, kT0, s);
    }
    const auto frames = static_cast<int>(std::lround(spec.seconds * 30));
    // /tf at 100 Hz from 20 ms before the first image to 20 ms after the last.
    for (int64_t t = kT0 - 20'000'000;
         spec.with_tf && t <= kT0 + frames * kFrameNs + spec.tf_tail_ns; t += 10'000'000) {
      Put(*w, tf, t, ros::msg::TFMessage{{Tf("arm_mount", "link1", Link1At(t), t)}});
    }
    for (int i = 0; i < frames; ++i) {
      const int64_t t = kT0 + i * kFrameNs;
      ros::msg::Image c;
      c.header = {ros::msg::ToTimeMsg(t), "camera_color_optical_frame"};
      c.width = kW;
      c.height = kH;
      c.encoding = spec.color_encoding;
      c.step = 3 * kW;
      for (int v = 0; v < kH; ++v) {
        for (int u = 0; u < kW; ++u) {
          const auto rgb = Rgb(i, u, v);
          if (spec.color_encoding == "bgr8") {
            c.data.insert(c.data.end(), {rgb[2], rgb[1], rgb[0]});
          } else {
            c.data.insert(c.data.end(), {rgb[0], rgb[1], rgb[2]});
          }
        }
      }
      if (i == spec.broken_color) c.data.pop_back();
      ros::msg::Image d;
      d.header = {ros::msg::ToTimeMsg(t + spec.depth_offset_ns), "camera_color_optical_frame"};
      d.width = kW;
      d.height = kH;
      d.encoding = spec.depth_encoding;
      d.step = 2 * kW;
      for (int v = 0; v < kH; ++v) {
        for (int u = 0; u < kW; ++u) {
          const uint16_t mm = DepthMm(i, u, v);
          d.data.insert(d.data.end(),
                        {static_cast<uint8_t>(mm & 0xff), static_cast<uint8_t>(mm >> 8)});
        }
      }
      ros::msg::CameraInfo k;
      k.header = c.header;
      k.width = kW;
      k.height = kH;
      k.distortion_model = "plumb_bob";
      k.d = {0, 0, 0, 0, 0};
      k.k = {6.0, 0, 3.5, 0, 6.5, 2.5, 0, 0, 1};
      Put(*w, color, t, c);
      Put(*w, depth, t + spec.depth_offset_ns, d);
      if (spec.with_camera_info) Put(*w, info, t, k);
    }
    EXPECT_TRUE(w->Close().ok());
    return path;
  }

  uint32_t seq_ = 0;
};

void ExpectView(const BagView& view, int frame) {
  const RgbdFrame& f = view.observation.frame;
  EXPECT_EQ(view.index, frame);
  EXPECT_EQ(f.stamp_ns, kT0 + frame * kFrameNs);
  EXPECT_EQ(f.frame_id, "camera_color_optical_frame");
  ASSERT_EQ(f.rgb.width(), kW);
  ASSERT_EQ(f.rgb.height(), kH);
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      const auto rgb = Rgb(frame, u, v);
      for (int ch = 0; ch < 3; ++ch) ASSERT_EQ(f.rgb.at(u, v, ch), rgb[ch]) << u << "," << v;
      ASSERT_EQ(f.depth_m.at(u, v), static_cast<float>(DepthMm(frame, u, v)) * 0.001f);
    }
  }
  EXPECT_EQ(f.K.width, kW);
  EXPECT_EQ(f.K.fx, 6.0);
  EXPECT_EQ(f.K.fy, 6.5);
  EXPECT_EQ(f.K.cx, 3.5);
  EXPECT_EQ(f.K.cy, 2.5);
  // The stamp falls between two 100 Hz /tf samples: interpolated, so within rounding of the
  // analytic pose.
  const RigidTransform expected = ExpectedPose(f.stamp_ns);
  EXPECT_LT(f.X_WC.TranslationDistanceTo(expected), 1e-9) << f.X_WC << " vs " << expected;
  EXPECT_LT(f.X_WC.AngleTo(expected), 1e-9);
  EXPECT_FALSE(view.observation.labels.has_value());
  EXPECT_FALSE(view.segmentation.has_value());
}

TEST_F(BagReaderTest, RealSenseBagAtOneFramePerSecondWithPoseFromTf) {
  const auto path = WriteBag({});
  Result<Bag> bag = ReadBag(path);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  EXPECT_FALSE(bag->avp_recording);
  EXPECT_TRUE(bag->damage.ok());
  EXPECT_EQ(bag->account.pairs, 90u);
  EXPECT_EQ(bag->account.left_out_count(), 87u);
  EXPECT_EQ(bag->account.skipped_count(), 0u)
      << (bag->account.skipped.empty() ? "" : bag->account.skipped[0]);
  ASSERT_EQ(bag->views.size(), 3u);  // t = 0, 1, 2 s: frames 0, 30, 60
  ExpectView(bag->views[0], 0);
  ExpectView(bag->views[1], 30);
  ExpectView(bag->views[2], 60);
  EXPECT_EQ(bag->topic_messages.at("/camera/camera/color/image_raw"), 90u);
}

TEST_F(BagReaderTest, FrameRateAndMaxViews) {
  const auto path = WriteBag({.seconds = 1.0});
  FrameSelection every;
  every.fps = 0.0;
  Result<Bag> all = ReadBag(path, {}, every);
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  ASSERT_EQ(all->views.size(), 30u);
  ExpectView(all->views[17], 17);
  FrameSelection ten;
  ten.fps = 10.0;  // every 100 ms: frames 0, 3, 6, ... (a frame is 33.3 ms)
  Result<Bag> tenth = ReadBag(path, {}, ten);
  ASSERT_TRUE(tenth.ok());
  ASSERT_EQ(tenth->views.size(), 10u);
  EXPECT_EQ(tenth->views[1].index, 3);
  FrameSelection five = every;
  five.max_views = 5;
  Result<Bag> first5 = ReadBag(path, {}, five);
  ASSERT_TRUE(first5.ok());
  ASSERT_EQ(first5->views.size(), 5u);
  // Reading stops at the fifth view: the pairs after it are not even read.
  EXPECT_LT(first5->account.pairs, 30u);
  EXPECT_EQ(first5->account.fused, 5u);
}

TEST_F(BagReaderTest, TopicAndFrameNamesAreOptions) {
  const auto path = WriteBag({.seconds = 1.0});
  BagReadOptions o;
  o.camera_frame = "link1";  // the pose of link1 instead of the optical frame
  Result<Bag> bag = ReadBag(path, o);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  EXPECT_LT(bag->views[0].observation.frame.X_WC.TranslationDistanceTo(kBaseToArm * Link1At(kT0)),
            1e-12);
  o = {};
  o.base_frame = "arm_mount";
  bag = ReadBag(path, o);
  ASSERT_TRUE(bag.ok());
  EXPECT_LT(
      bag->views[0].observation.frame.X_WC.TranslationDistanceTo(Link1At(kT0) * kLinkToOptical),
      1e-12);
  o = {};
  o.color_topic = "/color";
  bag = ReadBag(path, o);
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(), HasSubstr("no messages on '/color' (the bag's topics: "));
  EXPECT_THAT(bag.status().message(),
              HasSubstr("/camera/camera/color/image_raw (sensor_msgs/msg/Image, 30)"));
  o = {};
  o.depth_topic = "/camera/camera/color/camera_info";
  bag = ReadBag(path, o);
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(),
              HasSubstr("carries 'sensor_msgs/msg/CameraInfo', not sensor_msgs/msg/Image"));
}

TEST_F(BagReaderTest, MissingTransformsAndCameraInfoAreErrorsNamingThem) {
  Result<Bag> bag = ReadBag(WriteBag({.seconds = 1.0, .with_tf = false}, "notf.mcap"));
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(), HasSubstr("no view could be read"));
  EXPECT_THAT(bag.status().message(), HasSubstr("no transforms on '/tf' or '/tf_static'"));

  BagReadOptions o;
  o.base_frame = "world";
  bag = ReadBag(WriteBag({.seconds = 1.0}), o);
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(),
              HasSubstr("frame 'world' is not in the transform tree (known: arm_mount, "
                        "camera_color_optical_frame, igus_rebel_base_link, link1)"));

  bag = ReadBag(WriteBag({.seconds = 1.0, .with_camera_info = false}, "noinfo.mcap"));
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(),
              HasSubstr("no messages on '/camera/camera/color/camera_info'"));
}

TEST_F(BagReaderTest, TransformOutsideItsSamplesBeyondTheToleranceIsAnError) {
  const auto path = WriteBag({.seconds = 1.0});
  BagReadOptions o;
  o.tf_tolerance_ms = 0.0;
  FrameSelection every;
  every.fps = 0.0;
  Result<Bag> bag = ReadBag(path, o, every);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  EXPECT_EQ(bag->views.size(), 30u);  // /tf covers every image
  // /tf ending at 920 ms: the last image (966.7 ms) is 46.7 ms past it, beyond 20 ms; the one
  // before (933.3 ms) is within.
  o.tf_tolerance_ms = 20.0;
  bag = ReadBag(WriteBag({.seconds = 1.0, .tf_tail_ns = -75'000'000}, "short_tf.mcap"), o, every);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  EXPECT_EQ(bag->views.size(), 29u);
  ASSERT_EQ(bag->account.skipped_count(), 1u) << ::testing::PrintToString(bag->account.skipped);
  EXPECT_THAT(bag->account.skipped[0],
              HasSubstr("transform 'arm_mount' -> 'link1' at 1700000000.966666657 is not "
                        "available yet: the newest is 1700000000.920000000 (46.7 ms earlier, "
                        "beyond the tolerance of 20.0 ms)"));
}

TEST_F(BagReaderTest, BadImagesAreSkippedNamingTheValue) {
  Result<Bag> bag = ReadBag(WriteBag({.seconds = 1.0, .broken_color = 0}));
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  // Frame 0 is broken: the first usable pair is frame 1, then frames >= 1 s later (none in 1 s).
  ASSERT_EQ(bag->views.size(), 1u);
  EXPECT_EQ(bag->views[0].index, 1);
  ASSERT_EQ(bag->account.skipped_count(), 1u) << ::testing::PrintToString(bag->account.skipped);
  EXPECT_THAT(bag->account.skipped[0],
              HasSubstr("/camera/camera/color/image_raw: data holds 143 bytes, "
                        "but step 24 x height 6 = 144"));

  bag = ReadBag(WriteBag({.seconds = 0.2, .color_encoding = "yuv422"}, "yuv.mcap"));
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(),
              HasSubstr("colour encoding 'yuv422' is not supported (rgb8, bgr8, rgba8, bgra8, "
                        "mono8)"));

  bag = ReadBag(WriteBag({.seconds = 0.2, .depth_offset_ns = 20'000'000}, "skew.mcap"));
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(),
              HasSubstr("no colour image on '/camera/camera/color/image_raw' has a depth image "
                        "on '/camera/camera/aligned_depth_to_color/image_raw' within 5 ms (6 "
                        "colour, 6 depth images)"));
}

TEST_F(BagReaderTest, EveryCameraFixtureReadsAsLiveCapturesIt) {
  // The fixtures of live/test/same_frames_test.cpp, one frame a second, in a rosbag2 MCAP: each
  // reads back exactly as the fixture (and so as Ros2RgbdSource captures it); the frame with a
  // negative depth is skipped, naming the pixel.
  const std::vector<ros::msg::testing::CameraFixture> fixtures =
      ros::msg::testing::CameraFixtures();
  const fs::path path = dir_ / "fixtures.mcap";
  {
    auto w = ros::mcap::Writer::Open(path).value();
    const uint16_t color = Channel<ros::msg::Image>(*w, "/camera/camera/color/image_raw");
    const uint16_t depth =
        Channel<ros::msg::Image>(*w, "/camera/camera/aligned_depth_to_color/image_raw");
    const uint16_t info = Channel<ros::msg::CameraInfo>(*w, "/camera/camera/color/camera_info");
    const uint16_t tf_static = Channel<ros::msg::TFMessage>(*w, "/tf_static");
    Put(*w, tf_static, kT0,
        ros::msg::TFMessage{{Tf("igus_rebel_base_link", "camera_color_optical_frame",
                                kBaseToArm * kLinkToOptical, kT0)}});
    for (size_t i = 0; i < fixtures.size(); ++i) {
      const int64_t t = kT0 + static_cast<int64_t>(i) * 1'000'000'000;
      ros::msg::Image c = fixtures[i].color;
      ros::msg::Image d = fixtures[i].depth;
      ros::msg::CameraInfo k = ros::msg::testing::FixtureCameraInfo();
      c.header.stamp = d.header.stamp = k.header.stamp = ros::msg::ToTimeMsg(t);
      Put(*w, info, t, k);
      Put(*w, depth, t, d);
      Put(*w, color, t, c);
    }
    ASSERT_TRUE(w->Close().ok());
  }
  FrameSelection every;
  every.fps = 0.0;
  Result<Bag> bag = ReadBag(path, {}, every);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  EXPECT_EQ(bag->account.pairs, fixtures.size());
  size_t view = 0;
  for (size_t i = 0; i < fixtures.size(); ++i) {
    const ros::msg::testing::CameraFixture& f = fixtures[i];
    SCOPED_TRACE(f.name);
    if (!f.depth_error.empty()) {
      ASSERT_EQ(bag->account.skipped_count(), 1u);
      EXPECT_THAT(bag->account.skipped[0],
                  HasSubstr("/camera/camera/aligned_depth_to_color/image_raw: " + f.depth_error));
      continue;
    }
    ASSERT_LT(view, bag->views.size());
    const RgbdFrame& frame = bag->views[view++].observation.frame;
    EXPECT_EQ(frame.stamp_ns, kT0 + static_cast<int64_t>(i) * 1'000'000'000);
    EXPECT_EQ(frame.rgb, f.rgb);
    EXPECT_EQ(frame.depth_m, f.depth_m);  // bit for bit: 0 for every no-return pixel
    EXPECT_EQ(frame.K.width, ros::msg::testing::kFixtureWidth);
    EXPECT_EQ(frame.K.fx, 50.0);
    EXPECT_EQ(frame.frame_id, "camera_color_optical_frame");
    EXPECT_TRUE(frame.X_WC.IsNearlyEqualTo(kBaseToArm * kLinkToOptical, 1e-12, 1e-12));
  }
  EXPECT_EQ(view, bag->views.size());
}

TEST_F(BagReaderTest, GarbledPayloadsAreErrorsOrSkipsNeverCrashes) {
  // Every message of a 0.2 s bag in turn, its CDR payload cut short, grown, or with bytes
  // changed (the chunks' CRCs are right: the damage is in the messages themselves).
  const ros::mcap::File file = ros::mcap::ReadIndexed(WriteBag({.seconds = 0.2})).value();
  size_t ok = 0, failed = 0;
  for (size_t victim = 0; victim < file.messages.size(); ++victim) {
    for (int mode = 0; mode < 4; ++mode) {
      const fs::path path = dir_ / "garbled.mcap";
      auto w = ros::mcap::Writer::Open(path).value();
      for (const ros::mcap::Schema& s : file.schemas) {
        ASSERT_TRUE(w->AddSchema(s.name, s.encoding, s.data).ok());
      }
      for (const ros::mcap::Channel& c : file.channels) {
        ASSERT_TRUE(w->AddChannel(c.schema_id, c.topic, c.message_encoding, c.metadata).ok());
      }
      for (size_t i = 0; i < file.messages.size(); ++i) {
        ros::mcap::Message m = file.messages[i];
        if (i == victim) {
          std::vector<uint8_t>& d = m.data;
          if (mode == 0) d.resize(d.size() / 2);
          if (mode == 1) d.resize(d.size() + 7, 0xff);
          if (mode == 2) {
            for (size_t k = 4; k < d.size(); k += 5) d[k] ^= static_cast<uint8_t>(0x5a + k);
          }
          if (mode == 3 && d.size() > 12) {  // a length field made huge
            d[8] = d[9] = d[10] = 0xff;
          }
        }
        ASSERT_TRUE(w->Write(m).ok());
      }
      ASSERT_TRUE(w->Close().ok());
      FrameSelection every;
      every.fps = 0.0;
      Result<Bag> bag = ReadBag(path, {}, every);
      if (bag.ok()) {
        ++ok;
        EXPECT_LE(bag->views.size(), 6u);
        EXPECT_EQ(bag->views.size() + bag->account.skipped_count() >= 5, true);
      } else {
        ++failed;
        EXPECT_FALSE(bag.status().message().empty());
      }
    }
  }
  EXPECT_GT(ok, 0u);
  std::printf("[ garbled ] %zu messages x 4 damages: %zu read (damaged ones skipped), %zu errors\n",
              file.messages.size(), ok, failed);
}

TEST_F(BagReaderTest, JointStatesGiveTheCameraPoseAndTheFramesAreChosenByTimeRestAndCount) {
  // No TF at all: the arm's /joint_states through avp's default arm (its URDF and camera mount).
  // The arm holds still for 1 s, moves for 1 s, holds still again; 30 Hz frames for 3 s.
  const robot::ArmModel arm = robot::LoadDefaultArm().value();
  const Eigen::VectorXd home = arm.home_joints();
  auto q_at = [&](double s) {
    Eigen::VectorXd q = home;
    q[0] += 0.3 * std::clamp(s - 1.0, 0.0, 1.0);
    q[2] += 0.2 * std::clamp(s - 1.0, 0.0, 1.0);
    return q;
  };
  const fs::path path = dir_ / "joints.mcap";
  {
    auto w = testing::RobotBagWriter::Open(path).value();
    CameraIntrinsics K;
    K.width = 8;
    K.height = 6;
    K.fx = K.fy = 10.0;
    K.cx = 3.5;
    K.cy = 2.5;
    ImageRgb8 rgb(8, 6);
    DepthImage depth(8, 6);
    for (float& d : depth.data()) d = 0.5f;
    int64_t next_joints = kT0 - 300'000'000;
    for (int i = 0; i < 90; ++i) {
      const int64_t t = kT0 + i * int64_t{33'333'333};
      for (; next_joints <= t + 20'000'000; next_joints += 10'000'000) {
        ASSERT_TRUE(w->Joints(arm.joint_names(),
                              q_at(static_cast<double>(next_joints - kT0) * 1e-9), next_joints)
                        .ok());
      }
      ASSERT_TRUE(
          w->Frame(t, rgb, depth, ros::msg::ToCameraInfo(K, {}), "camera_color_optical_frame")
              .ok());
    }
    ASSERT_TRUE(w->Close().ok());
  }
  FrameSelection all;
  all.fps = 0.0;
  Result<Bag> bag = ReadBag(path, {}, all);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  ASSERT_EQ(bag->views.size(), 90u);
  EXPECT_LT(bag->views[0].observation.frame.X_WC.TranslationDistanceTo(arm.CameraPose(home)), 1e-9);
  // 1.5 s: halfway through the move, the joints interpolated between their samples.
  const RgbdFrame& mid = bag->views[45].observation.frame;
  EXPECT_LT(mid.X_WC.TranslationDistanceTo(
                arm.CameraPose(q_at(static_cast<double>(mid.stamp_ns - kT0) * 1e-9))),
            1e-6);

  FrameSelection rest = all;
  rest.at_rest_only = true;  // moved less than 1 cm/s and 2 deg/s over the 0.2 s before
  bag = ReadBag(path, {}, rest);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  for (const BagView& v : bag->views) {
    const double s = static_cast<double>(v.observation.frame.stamp_ns - kT0) * 1e-9;
    EXPECT_TRUE(s < 1.0 + 1e-6 || s >= 2.2 - 1e-6) << "a frame at " << s << " s, while moving";
  }
  EXPECT_GE(bag->views.size(), 50u);
  EXPECT_EQ(bag->account.left_out.at("moving") + bag->views.size(), 90u);

  FrameSelection window = all;
  window.start_s = 1.0;
  window.end_s = 2.0;
  window.every_nth = 5;
  bag = ReadBag(path, {}, window);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  // Frames 30 .. 60 (1 s to 2 s), every 5th: 30, 35, ..., 60; reading stops after frame 61.
  ASSERT_EQ(bag->views.size(), 7u);
  EXPECT_EQ(bag->views[0].index, 30);
  EXPECT_EQ(bag->views[6].index, 60);
  EXPECT_EQ(bag->account.left_out.at("before start_s"), 30u);
  EXPECT_EQ(bag->account.left_out.at("every_nth"), 24u);
  EXPECT_EQ(bag->account.left_out.at("after end_s"), 1u);

  // Joint names the arm does not have: the pose cannot be known, and the error says why.
  BagReadOptions other;
  other.joint_states_topic = "/joint_states";
  other.arm = "/no/such/arm.yaml";
  bag = ReadBag(path, other, all);
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(), HasSubstr("arm.yaml"));
}

TEST_F(BagReaderTest, TruncatedBagKeepsTheIntactFramesAndNamesTheOffset) {
  const auto path = WriteBag({});
  const auto size = std::filesystem::file_size(path);
  std::filesystem::resize_file(path, size * 6 / 10);
  Result<Bag> bag = ReadBag(path);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  EXPECT_FALSE(bag->damage.ok());
  EXPECT_THAT(bag->damage.message(), HasSubstr("at offset"));
  EXPECT_THAT(bag->damage.message(), HasSubstr(path.string()));
  // 1.8 s of 3 s survive at most: frames 0 and 30.
  ASSERT_GE(bag->views.size(), 1u);
  ASSERT_LE(bag->views.size(), 2u);
  ExpectView(bag->views[0], 0);

  std::filesystem::resize_file(path, 40);  // inside the first records
  bag = ReadBag(path);
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(), HasSubstr("offset"));
}

}  // namespace
}  // namespace avp::ros::bag

// The one reading of sensor_msgs/Image and CameraInfo (avp live and avp replay): every encoding
// of the shared fixtures, the depth rule, the errors naming the value, and the writers of the
// recorder and avp sim ros2 read back.
#include "avp/ros/msg/images.h"

#include <cmath>
#include <cstring>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "camera_fixtures.h"

namespace avp::ros::msg {
namespace {

using ::testing::HasSubstr;

TEST(RosmsgImagesTest, EveryFixtureReadsAsExpected) {
  for (const testing::CameraFixture& f : testing::CameraFixtures()) {
    SCOPED_TRACE(f.name);
    EXPECT_TRUE(CheckColorImage(f.color, "/c").ok());
    Result<ImageRgb8> rgb = ColorFromImage(f.color, "/c");
    ASSERT_TRUE(rgb.ok()) << rgb.status().ToString();
    EXPECT_EQ(*rgb, f.rgb);
    Result<DepthImage> depth = DepthFromImage(f.depth, "/d");
    const Status checked = CheckDepthImage(f.depth, "/d");
    if (!f.depth_error.empty()) {
      ASSERT_FALSE(depth.ok());
      EXPECT_EQ(depth.status().code(), StatusCode::kInvalidArgument);
      EXPECT_THAT(depth.status().message(), HasSubstr("/d: " + f.depth_error));
      EXPECT_EQ(checked, depth.status());  // refused on arrival alike
      continue;
    }
    ASSERT_TRUE(depth.ok()) << depth.status().ToString();
    EXPECT_TRUE(checked.ok()) << checked.ToString();
    EXPECT_EQ(*depth, f.depth_m);
    for (const float z : depth->data()) EXPECT_TRUE(std::isfinite(z) && z >= 0.0f);
  }
}

TEST(RosmsgImagesTest, TheDepthRule) {
  Image d;
  d.width = 4;
  d.height = 1;
  d.encoding = "32FC1";
  d.step = 16;
  d.header.stamp = Time{7, 5};
  const float values[4] = {1.25f, std::numeric_limits<float>::quiet_NaN(), 0.0f,
                           std::numeric_limits<float>::infinity()};
  d.data.resize(16);
  std::memcpy(d.data.data(), values, 16);
  Result<DepthImage> depth = DepthFromImage(d, "/d");
  ASSERT_TRUE(depth.ok());
  EXPECT_EQ(depth->at(0, 0), 1.25f);  // bit for bit
  EXPECT_EQ(depth->at(1, 0), 0.0f);   // NaN: no return
  EXPECT_EQ(depth->at(2, 0), 0.0f);
  EXPECT_EQ(depth->at(3, 0), 0.0f);  // +inf ("too far"): no return
  const float negative = -0.5f;
  std::memcpy(d.data.data() + 8, &negative, 4);
  EXPECT_THAT(DepthFromImage(d, "/d").status().message(),
              HasSubstr("/d: depth -0.5 m at pixel (2, 0) (stamp 7.000000005): a 32FC1 depth "
                        "must be positive, or NaN, inf or 0 for no return"));
  const float subnormal = std::numeric_limits<float>::denorm_min();
  std::memcpy(d.data.data() + 8, &subnormal, 4);
  EXPECT_THAT(DepthFromImage(d, "/d").status().message(), HasSubstr("at pixel (2, 0)"));
  // 16UC1: millimetres, 0 = no return; mono16 is the same.
  d.encoding = "16UC1";
  d.step = 8;
  d.data = {0x01, 0x02, 0, 0, 0xff, 0xff, 0xe8, 0x03};
  depth = DepthFromImage(d, "/d");
  ASSERT_TRUE(depth.ok());
  EXPECT_EQ(depth->at(0, 0), 513 * 0.001f);
  EXPECT_EQ(depth->at(1, 0), 0.0f);
  EXPECT_EQ(depth->at(2, 0), 65535 * 0.001f);
  EXPECT_EQ(depth->at(3, 0), 1000 * 0.001f);
  d.is_bigendian = 1;
  EXPECT_EQ(DepthFromImage(d, "/d")->at(0, 0), 258 * 0.001f);
}

TEST(RosmsgImagesTest, BadImagesAreRefusedNamingTheValue) {
  auto [color, rgb] = testing::detail::Color("rgb8", 0);
  Image bad = color;
  bad.encoding = "yuv422";
  EXPECT_THAT(ColorFromImage(bad, "/cam/color").status().message(),
              HasSubstr("/cam/color: colour encoding 'yuv422' is not supported (rgb8, bgr8, "
                        "rgba8, bgra8, mono8)"));
  EXPECT_EQ(CheckColorImage(bad, "/cam/color"), ColorFromImage(bad, "/cam/color").status());
  bad = color;
  bad.step = 10;
  EXPECT_THAT(ColorFromImage(bad, "/c").status().message(),
              HasSubstr("/c: step 10 is shorter than a row of 8 'rgb8' pixels (24 bytes)"));
  bad = color;
  bad.data.pop_back();
  EXPECT_THAT(ColorFromImage(bad, "/c").status().message(),
              HasSubstr("/c: data holds 143 bytes, but step 24 x height 6 = 144"));
  bad = color;
  bad.width = 0;
  EXPECT_THAT(ColorFromImage(bad, "/c").status().message(),
              HasSubstr("image size 0x6 is out of range (1..16384)"));
  bad = color;
  bad.height = 20000;
  EXPECT_THAT(DepthFromImage(bad, "/d").status().message(),
              HasSubstr("/d: depth encoding 'rgb8' is not supported (16UC1 in millimetres, 32FC1 "
                        "in metres)"));
  bad.encoding = "16UC1";
  EXPECT_THAT(CheckDepthImage(bad, "/d").message(), HasSubstr("image size 8x20000"));

  CameraInfo info = testing::FixtureCameraInfo();
  info.k[0] = 0.0;
  EXPECT_THAT(
      FromCameraInfo(info, 0.1, 3.0).status().message(),
      HasSubstr("CameraInfo (frame 'camera_color_optical_frame') gives invalid intrinsics"));
  info = testing::FixtureCameraInfo();
  info.binning_x = 2;
  EXPECT_THAT(FromCameraInfo(info, 0.1, 3.0).status().message(),
              HasSubstr("binning 2x0 or a region of interest 0x0 is not supported"));
  info.binning_x = 0;
  info.width = 0;
  EXPECT_THAT(FromCameraInfo(info, 0.1, 3.0).status().message(),
              HasSubstr("size 0x6 is out of range"));
}

TEST(RosmsgImagesTest, WritersReadBack) {
  const Header header{Time{3, 5}, "camera_color_optical_frame"};
  ImageRgb8 rgb(5, 3);
  for (size_t i = 0; i < rgb.data().size(); ++i) rgb.data()[i] = static_cast<uint8_t>(i * 7);
  const Image c = ToColorImage(rgb, header);
  EXPECT_EQ(c.encoding, "rgb8");
  EXPECT_EQ(c.step, 15u);
  EXPECT_EQ(c.header, header);
  EXPECT_EQ(ColorFromImage(c, "/c").value(), rgb);

  DepthImage depth(3, 2, 0.0f);
  depth.at(0, 0) = 0.123456789f;
  depth.at(1, 0) = std::nextafter(1.0f, 2.0f);
  depth.at(2, 1) = 2.5f;
  depth.at(1, 1) = 70.0f;  // beyond 16UC1: clamped
  const Image d32 = ToDepthImage(depth, header);
  EXPECT_EQ(d32.encoding, "32FC1");
  EXPECT_EQ(d32.step, 12u);
  EXPECT_EQ(DepthFromImage(d32, "/d").value(), depth);  // bit for bit
  const Image d16 = ToDepthImage(depth, header, DepthEncoding::k16UC1);
  EXPECT_EQ(d16.encoding, "16UC1");
  EXPECT_EQ(d16.step, 6u);
  const DepthImage mm = DepthFromImage(d16, "/d").value();
  EXPECT_EQ(mm.at(0, 0), 123 * 0.001f);
  EXPECT_EQ(mm.at(1, 0), 1000 * 0.001f);
  EXPECT_EQ(mm.at(1, 1), 65535 * 0.001f);
  EXPECT_EQ(mm.at(0, 1), 0.0f);

  InstanceImage ids(3, 2, 0);
  ids.at(2, 1) = 65535;
  ids.at(0, 0) = 258;
  const Image i = ToInstanceIdImage(ids, "mono16", header);
  EXPECT_EQ(i.encoding, "mono16");
  EXPECT_EQ(i.data[0], 2);  // little-endian 258
  EXPECT_EQ(i.data[1], 1);
  ClassImage classes(3, 2, 2);
  const Image k = ToClassIdImage(classes, header);
  EXPECT_EQ(k.encoding, "mono8");
  Result<SimulatorLabels> labels = LabelsFromImages(i, k, 3, 2, "/sim");
  ASSERT_TRUE(labels.ok()) << labels.status().ToString();
  EXPECT_EQ(labels->instance_ids, ids);
  EXPECT_EQ(labels->class_ids, classes);
  EXPECT_THAT(LabelsFromImages(i, k, 4, 2, "/sim").status().message(),
              HasSubstr("/sim: label images 3x2 and 3x2 do not match the 4x2 colour image"));
  EXPECT_THAT(LabelsFromImages(k, k, 3, 2, "/sim").status().message(),
              HasSubstr("/sim/instance: encoding 'mono8' (16UC1 or mono16 instance ids)"));

  const CameraIntrinsics K = CameraIntrinsics::FromHorizontalFov(64, 48, 60.0);
  const CameraInfo info = ToCameraInfo(K, header);
  EXPECT_EQ(info.width, 64u);
  EXPECT_EQ(info.distortion_model, "plumb_bob");
  EXPECT_EQ(info.p[0], K.fx);
  EXPECT_EQ(info.p[10], 1.0);
  const CameraIntrinsics back = FromCameraInfo(info, K.min_depth_m, K.max_depth_m).value();
  EXPECT_EQ(back.width, K.width);
  EXPECT_EQ(back.height, K.height);
  EXPECT_EQ(back.fx, K.fx);
  EXPECT_EQ(back.fy, K.fy);
  EXPECT_EQ(back.cx, K.cx);
  EXPECT_EQ(back.cy, K.cy);
}

}  // namespace
}  // namespace avp::ros::msg

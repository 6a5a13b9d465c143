#include "avp/ros/msg/cdr.h"

#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/ros/msg/messages.h>

namespace avp::ros::msg {
namespace {

using ::testing::HasSubstr;

std::vector<uint8_t> Concat(std::initializer_list<std::vector<uint8_t>> parts) {
  std::vector<uint8_t> out;
  for (const auto& p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

TEST(RosmsgCdrTest, HeaderBytesByHand) {
  const Header header{Time{1, 2}, "ab"};
  const std::vector<uint8_t> expected = {0x00, 0x01, 0x00, 0x00,  // encapsulation: CDR_LE
                                         0x01, 0x00, 0x00, 0x00,  // stamp.sec
                                         0x02, 0x00, 0x00, 0x00,  // stamp.nanosec
                                         0x03, 0x00, 0x00, 0x00,  // frame_id length incl. NUL
                                         'a',  'b',  0x00};       // no padding at the end
  EXPECT_EQ(Encode(header), expected);
}

// ros2-interop.md §1.2: "00 01 00 00, then stamp, then frame_id as uint32 length (including NUL)
// plus bytes", then the Image fields, each aligned relative to the end of the header.
TEST(RosmsgCdrTest, ImageBytesByHand) {
  Image image;
  image.header = Header{Time{0x11223344, 5}, "cam"};
  image.height = 1;
  image.width = 2;
  image.encoding = "mono8";
  image.is_bigendian = 0;
  image.step = 2;
  image.data = {0xaa, 0xbb};
  const std::vector<uint8_t> expected = Concat({
      {0x00, 0x01, 0x00, 0x00},
      {0x44, 0x33, 0x22, 0x11, 0x05, 0x00, 0x00, 0x00},  // stamp
      {0x04, 0x00, 0x00, 0x00, 'c', 'a', 'm', 0x00},     // frame_id: 4 = "cam" + NUL
      {0x01, 0x00, 0x00, 0x00},                          // height
      {0x02, 0x00, 0x00, 0x00},                          // width
      {0x06, 0x00, 0x00, 0x00, 'm', 'o', 'n', 'o', '8', 0x00},
      {0x00},                                // is_bigendian
      {0x00},                                // padding to 4 for step
      {0x02, 0x00, 0x00, 0x00},              // step
      {0x02, 0x00, 0x00, 0x00, 0xaa, 0xbb},  // data
  });
  EXPECT_EQ(Encode(image), expected);
}

TEST(RosmsgCdrTest, DoublesAlignToEightFromTheEndOfTheEncapsulationHeader) {
  // Header of 8 + 4 + 2 bytes ("a" + NUL): the Pose's first double needs 2 bytes of padding.
  PoseStamped pose;
  pose.header.frame_id = "a";
  pose.pose.position.x = 1.0;
  const std::vector<uint8_t> bytes = Encode(pose);
  ASSERT_EQ(bytes.size(), 4u + 16u + 7u * 8u);
  EXPECT_EQ(bytes[4 + 14], 0);
  EXPECT_EQ(bytes[4 + 15], 0);
  EXPECT_EQ(bytes[4 + 16 + 7], 0x3f);  // 1.0 = 00 .. f0 3f
  EXPECT_EQ(bytes[4 + 16 + 6], 0xf0);
}

TEST(RosmsgCdrTest, EmptySequencesOfDoublesAreNotAligned) {
  JointState js;
  js.header.frame_id = "";  // 8 + 4 + 1 = 13 bytes of header
  const std::vector<uint8_t> bytes = Encode(js);
  // header (13) + pad 3 + four empty sequences of 4 bytes: no alignment for empty float64[].
  EXPECT_EQ(bytes.size(), 4u + 13u + 3u + 16u);
}

TEST(RosmsgCdrTest, BigEndianSamplesDecode) {
  CameraInfo info;
  info.header = Header{Time{-7, 8}, "x"};
  info.d = {1.5, -2.5};
  info.k[0] = 600;
  info.roi.do_rectify = true;
  const std::vector<uint8_t> be = Encode(info, RosDistro::kJazzy, Endianness::kBig);
  EXPECT_EQ(be[1], 0x00);
  EXPECT_NE(be, Encode(info));
  const Result<CameraInfo> back = Decode<CameraInfo>(be);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, info);
}

TEST(RosmsgCdrTest, RefusesShortAndUnknownEncapsulations) {
  const std::vector<uint8_t> tiny = {0x00, 0x01};
  EXPECT_THAT(Decode<Time>(tiny).status().message(),
              HasSubstr("builtin_interfaces/msg/Time: sample of 2 bytes is shorter"));
  const std::vector<uint8_t> xcdr2 = {0x00, 0x07, 0x00, 0x00, 1, 0, 0, 0, 2, 0, 0, 0};
  EXPECT_THAT(Decode<Time>(xcdr2).status().message(), HasSubstr("XCDR2"));
  const std::vector<uint8_t> pl = {0x00, 0x03, 0x00, 0x00, 1, 0, 0, 0, 2, 0, 0, 0};
  EXPECT_THAT(Decode<Time>(pl).status().message(), HasSubstr("PL_CDR"));
}

TEST(RosmsgCdrTest, RefusesSamplesOverTheCap) {
  std::vector<uint8_t> huge(kMaxSampleBytes + 1, 0);
  huge[1] = 0x01;
  const Status status = Decode<Image>(huge).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("exceeds the cap of 268435456 bytes (kMaxSampleBytes)"));
}

TEST(RosmsgCdrTest, SequenceLengthPastTheEndNamesTypeFieldAndOffset) {
  Image image;
  image.header.frame_id = "camera_color_optical_frame";  // 27 bytes + NUL
  image.encoding = "rgb8";
  image.data = std::vector<uint8_t>(120, 7);
  std::vector<uint8_t> bytes = Encode(image);
  // data's length is the uint32 just before the last 120 bytes.
  const size_t length_at = bytes.size() - 120 - 4;
  const uint32_t lie = 4'000'000;
  std::memcpy(bytes.data() + length_at, &lie, 4);
  const Status status = Decode<Image>(bytes).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(), "sensor_msgs/msg/Image: data: sequence of 4000000 bytes at offset " +
                                  std::to_string(length_at) + " exceeds the 120 remaining");
}

TEST(RosmsgCdrTest, NestedFieldPathsAndBadValues) {
  MarkerArray array;
  array.markers.resize(2);
  const std::vector<uint8_t> unlocked = Encode(array);
  array.markers[1].frame_locked = true;
  std::vector<uint8_t> bytes = Encode(array);
  ASSERT_EQ(bytes.size(), unlocked.size());
  size_t pos = 0;
  while (pos < bytes.size() && bytes[pos] == unlocked[pos]) ++pos;
  ASSERT_LT(pos, bytes.size());
  bytes[pos] = 2;
  EXPECT_EQ(Decode<MarkerArray>(bytes).status().message(),
            "visualization_msgs/msg/MarkerArray: markers[1].frame_locked: bool at offset " +
                std::to_string(pos) + " is 2, not 0 or 1");
  // Truncated inside the second marker's points.
  array.markers[1].points.resize(3);
  std::vector<uint8_t> cut = Encode(array);
  cut.resize(cut.size() - 200);
  EXPECT_THAT(Decode<MarkerArray>(cut).status().message(),
              HasSubstr("visualization_msgs/msg/MarkerArray: markers[1]."));
}

TEST(RosmsgCdrTest, StringsMustEndInNulAndRespectBounds) {
  std::vector<uint8_t> bytes = Encode(Header{Time{}, "abc"});
  bytes.back() = 'd';
  EXPECT_THAT(Decode<Header>(bytes).status().message(),
              HasSubstr("std_msgs/msg/Header: frame_id: string of 4 bytes at offset 12 does not "
                        "end in a NUL byte"));
  NodeEntitiesInfo node;
  node.node_name = std::string(257, 'x');
  EXPECT_THAT(
      Decode<NodeEntitiesInfo>(Encode(node, RosDistro::kJazzy), RosDistro::kJazzy)
          .status()
          .message(),
      HasSubstr("node_name: string of 257 characters at offset 12 exceeds its bound of 256"));
}

TEST(RosmsgCdrTest, ZeroLengthStringReadsAsEmpty) {
  const std::vector<uint8_t> bytes = {0x00, 0x01, 0x00, 0x00, 1, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0};
  const Result<Header> header = Decode<Header>(bytes);
  ASSERT_TRUE(header.ok()) << header.status().ToString();
  EXPECT_EQ(header->frame_id, "");
  EXPECT_EQ(header->stamp, (Time{1, 2}));
}

}  // namespace
}  // namespace avp::ros::msg

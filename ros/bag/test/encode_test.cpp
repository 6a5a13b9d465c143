// The messages and JSON of a recorded view round-trip exactly: images (bit-exact floats), the
// segmentation (COCO RLE masks, float scores and boxes), poses (12 doubles), and the instance id
// image's overlap rule.
#include "avp/ros/bag/encode.h"

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/rng.h>
#include <avp/mapping/octomap_io.h>
#include <avp/ros/bag/layout.h>
#include <avp/ros/msg/images.h>

namespace avp::ros::bag {
namespace {

using ::testing::HasSubstr;

const ros::msg::Header kHeader{ros::msg::Time{3, 5}, "camera_color_optical_frame"};

TEST(RecordingEncodeTest, TheLayoutsImagesRoundTrip) {
  // The recorder writes ros/msg's images (ros/msg/test/images_test.cpp); the layout's readers read
  // them back by the same rules as avp live and avp replay, naming the layout's topics.
  ImageRgb8 rgb(5, 3);
  for (size_t i = 0; i < rgb.data().size(); ++i) rgb.data()[i] = static_cast<uint8_t>(i * 7);
  const ros::msg::Image c = ros::msg::ToColorImage(rgb, kHeader);
  EXPECT_EQ(c.encoding, kColorEncoding);
  EXPECT_EQ(ros::msg::ColorFromImage(ros::msg::Decode<ros::msg::Image>(ros::msg::Encode(c)).value(),
                                     kColorTopic)
                .value(),
            rgb);

  DepthImage depth(4, 2, 0.0f);
  depth.at(0, 0) = 0.123456789f;
  depth.at(1, 0) = std::nextafter(1.0f, 2.0f);
  depth.at(3, 1) = 2.5f;
  const ros::msg::Image d = ros::msg::ToDepthImage(depth, kHeader);
  EXPECT_EQ(d.encoding, kDepthEncoding);
  EXPECT_EQ(ros::msg::DepthFromImage(d, kDepthTopic).value(), depth);  // bit for bit
  // NaN in a recorded depth reads as no return (0), as live and replay read it.
  depth.at(2, 1) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(ros::msg::DepthFromImage(ros::msg::ToDepthImage(depth, kHeader), kDepthTopic)
                .value()
                .at(2, 1),
            0.0f);
  // RealSense 16UC1 millimetres.
  const ros::msg::Image mm =
      ros::msg::ToInstanceIdImage(InstanceImage(2, 1, 1500), "16UC1", kHeader);
  EXPECT_FLOAT_EQ(ros::msg::DepthFromImage(mm, kDepthTopic).value().at(1, 0), 1.5f);

  InstanceImage ids(3, 2, 0);
  ids.at(2, 1) = 65535;
  ids.at(0, 0) = 258;
  const ros::msg::Image i = ros::msg::ToInstanceIdImage(ids, kInstanceImageEncoding, kHeader);
  EXPECT_EQ(i.encoding, "mono16");
  EXPECT_EQ(ros::msg::InstanceIdsFromImage(i, kInstanceImageTopic).value(), ids);
  ClassImage classes(3, 1, 2);
  EXPECT_EQ(ros::msg::ClassIdsFromImage(ros::msg::ToClassIdImage(classes, kHeader), kSimClassTopic)
                .value(),
            classes);

  ros::msg::Image bad = c;
  bad.data.pop_back();
  EXPECT_THAT(ros::msg::ColorFromImage(bad, kColorTopic).status().message(),
              HasSubstr("/camera/camera/color/image_raw: data holds 44 bytes, but step 15 x "
                        "height 3 = 45"));
  bad.encoding = "yuv422";
  EXPECT_THAT(ros::msg::ColorFromImage(bad, kColorTopic).status().message(),
              HasSubstr("'yuv422' is not supported"));
}

Segmentation TwoOverlapping() {
  Segmentation s;
  s.width = 6;
  s.height = 4;
  InstanceMask a;
  a.mask = MaskImage(6, 4, 0);
  for (int u = 0; u < 4; ++u) a.mask.at(u, 1) = 1;
  a.confidence = 0.3f;
  a.label = "tomato";
  a.box = PixelBox{0.25f, 1.0f, 4.0f, 2.0f};
  InstanceMask b;
  b.mask = MaskImage(6, 4, 0);
  for (int u = 2; u < 6; ++u) b.mask.at(u, 1) = 255;
  b.mask.at(5, 3) = 1;
  b.confidence = 0.7000001f;
  b.semantic_class = SemanticClass::kLeaf;
  b.label = "leaf \u00e9";
  b.mask_score = 0.91f;
  InstanceMask c;  // same score as a: a (earlier) keeps the overlap
  c.mask = MaskImage(6, 4, 0);
  c.mask.at(0, 1) = 1;
  c.mask.at(0, 0) = 1;
  c.confidence = 0.3f;
  s.instances = {a, b, c};
  s.timings = {{"detector", 12.5}};
  return s;
}

TEST(RecordingEncodeTest, InstanceIdImageHigherScoreWins) {
  const InstanceImage ids = InstanceIdImage(TwoOverlapping());
  EXPECT_EQ(ids.at(0, 1), 1);  // a and c (equal scores): a
  EXPECT_EQ(ids.at(0, 0), 3);
  EXPECT_EQ(ids.at(1, 1), 1);
  EXPECT_EQ(ids.at(2, 1), 2);  // a and b: b (0.7 > 0.3)
  EXPECT_EQ(ids.at(5, 1), 2);
  EXPECT_EQ(ids.at(5, 3), 2);
  EXPECT_EQ(ids.at(4, 3), 0);
}

TEST(RecordingEncodeTest, InstancesJsonRoundTripsExactly) {
  const Segmentation s = TwoOverlapping();
  const std::string text = InstancesToJson(s).dump();
  const Segmentation back = InstancesFromJson(nlohmann::json::parse(text)).value();
  EXPECT_EQ(back.width, 6);
  EXPECT_EQ(back.height, 4);
  ASSERT_EQ(back.instances.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const InstanceMask& a = s.instances[i];
    const InstanceMask& b = back.instances[i];
    EXPECT_EQ(b.semantic_class, a.semantic_class);
    EXPECT_EQ(b.confidence, a.confidence);  // exact
    EXPECT_EQ(b.mask_score, a.mask_score);
    EXPECT_EQ(b.label, a.label);
    EXPECT_EQ(b.box, a.box);
    for (int v = 0; v < 4; ++v) {
      for (int u = 0; u < 6; ++u) EXPECT_EQ(b.mask.at(u, v) != 0, a.mask.at(u, v) != 0);
    }
  }
  ASSERT_EQ(back.timings.size(), 1u);
  EXPECT_EQ(back.timings[0].ms, 12.5);
  // COCO RLE, column-major: column 0 of a is rows 0..3 = [0, 1, 0, 0] -> counts start 1, 1.
  const auto j = InstancesToJson(s);
  EXPECT_EQ(j["instances"][0]["mask"]["size"], nlohmann::json::array({4, 6}));
  EXPECT_EQ(j["instances"][0]["mask"]["counts"][0], 1);
  EXPECT_EQ(j["instances"][0]["mask"]["counts"][1], 1);

  nlohmann::json broken = j;
  broken["instances"][1]["class"] = "banana";
  EXPECT_THAT(InstancesFromJson(broken).status().message(),
              HasSubstr("instance 1: unknown class 'banana'"));
  broken = j;
  broken["instances"][0]["mask"]["counts"] = {1, 2};
  EXPECT_THAT(InstancesFromJson(broken).status().message(), HasSubstr("instance 0"));
}

TEST(RecordingEncodeTest, PoseJsonIsExact) {
  const RigidTransform X =
      RigidTransform::FromRpy(0.1234567890123, -1.1, 2.9, Eigen::Vector3d(0.1 + 0.2, -1e-17, 3.0));
  const nlohmann::json j = PoseToJson(X);
  ASSERT_EQ(j.size(), 12u);
  const RigidTransform back = PoseFromJson(nlohmann::json::parse(j.dump())).value();
  EXPECT_EQ(back.rotation(), X.rotation());  // bit-exact
  EXPECT_EQ(back.translation(), X.translation());
  EXPECT_THAT(PoseFromJson(nlohmann::json::array({1, 2})).status().message(),
              HasSubstr("expected 12 numbers"));
  nlohmann::json skew = j;
  skew[0] = 2.0;
  EXPECT_THAT(PoseFromJson(skew).status().message(), HasSubstr("is not a rotation"));
}

TEST(RecordingEncodeTest, CandidateMarkersMarkTheChosenOne) {
  std::vector<planning::ViewCandidate> ranked(3);
  for (int i = 0; i < 3; ++i) {
    ranked[i].X_WC = RigidTransform(Eigen::Vector3d(0.1 * i, 0.0, 0.5));
    ranked[i].utility = 3.0 - i;
    ranked[i].reachable = true;
    ranked[i].source = "frontier";
  }
  const ros::msg::MarkerArray m = CandidateMarkers(ranked, 1, 2, {{}, "base"});
  ASSERT_EQ(m.markers.size(), 5u);  // DELETEALL, 3 arrows, the chosen one's text
  EXPECT_EQ(m.markers[0].action, ros::msg::Marker::kDeleteAll);
  EXPECT_EQ(m.markers[1].ns, "candidates");
  EXPECT_EQ(m.markers[2].ns, "chosen");
  EXPECT_EQ(m.markers[2].points.size(), 2u);
  EXPECT_DOUBLE_EQ(m.markers[2].points[1].z, 0.65);  // 0.15 along +z of the optical frame
  EXPECT_THAT(m.markers[4].text, HasSubstr("after view 3: rank 1 of 3, utility 2"));
  // Best utility is viridis' yellow end, the worst its purple end.
  EXPECT_GT(m.markers[1].color.r, 0.9f);
  EXPECT_LT(m.markers[3].color.r, 0.3f);
}

/// OctomapBinaryTree equals liboctomap's bytes (mapping::OctomapBinaryMessageData).
void ExpectSameAsLiboctomap(const mapping::OccupancyGrid& grid) {
  const std::string ours = OctomapBinaryTree(grid).value();
  const mapping::OctomapBinaryData theirs = mapping::OctomapBinaryMessageData(grid).value();
  EXPECT_EQ(ours.size(), theirs.data.size());
  EXPECT_TRUE(ours == theirs.data);
}

TEST(RecordingOctomapTest, BinaryTreeEqualsLiboctomapByteForByte) {
  mapping::OccupancyGrid grid;
  ExpectSameAsLiboctomap(grid);  // empty: no root, no bytes
  const float occ = grid.sensor_model().clamp_max_log_odds();
  const float fre = grid.sensor_model().clamp_min_log_odds();
  // One voxel, then a full 8^3 block of occupied voxels (pruned to one depth-13 leaf), a full
  // 16^3 region of free voxels (pruned to a depth-12 leaf), voxels either side of 0 (keys
  // 32767 / 32768 in OctoMap's terms), values beyond the clamps and exactly at the threshold.
  ASSERT_TRUE(grid.SetLogOdds({1, 2, 3}, 0.9f));
  ExpectSameAsLiboctomap(grid);
  for (int x = 16; x < 24; ++x)
    for (int y = 0; y < 8; ++y)
      for (int z = 8; z < 16; ++z) ASSERT_TRUE(grid.SetLogOdds({x, y, z}, occ));
  for (int x = -32; x < -16; ++x)
    for (int y = -16; y < 0; ++y)
      for (int z = 0; z < 16; ++z) ASSERT_TRUE(grid.SetLogOdds({x, y, z}, fre));
  ASSERT_TRUE(grid.SetLogOdds({-1, -1, -1}, 10.0f));
  ASSERT_TRUE(grid.SetLogOdds({0, -1, 0}, -10.0f));
  ASSERT_TRUE(grid.SetLogOdds({5, 5, 5}, grid.occupied_log_odds()));
  ExpectSameAsLiboctomap(grid);
  // A region that is all occupied but one free voxel does not collapse.
  for (int x = 40; x < 48; ++x)
    for (int y = 40; y < 48; ++y)
      for (int z = 40; z < 48; ++z) ASSERT_TRUE(grid.SetLogOdds({x, y, z}, occ));
  ASSERT_TRUE(grid.SetLogOdds({44, 41, 47}, fre));
  ExpectSameAsLiboctomap(grid);
  // Random voxels of random values in a 64^3 region around the origin.
  Rng rng(17);
  for (int i = 0; i < 20000; ++i) {
    const VoxelKey k{static_cast<int32_t>(rng.UniformInt(-32, 31)),
                     static_cast<int32_t>(rng.UniformInt(-32, 31)),
                     static_cast<int32_t>(rng.UniformInt(-32, 31))};
    ASSERT_TRUE(grid.SetLogOdds(k, static_cast<float>(rng.Uniform(-3.0, 3.0))));
  }
  ExpectSameAsLiboctomap(grid);
}

TEST(RecordingOctomapTest, KeysOutsideOctomapAreAnError) {
  mapping::OccupancyGrid grid;
  ASSERT_TRUE(grid.SetLogOdds({40000, 0, 0}, 1.0f));
  EXPECT_EQ(OctomapBinaryTree(grid).status().code(), StatusCode::kOutOfRange);
  EXPECT_THAT(OctomapBinaryTree(grid).status().message(),
              HasSubstr("outside OctoMap's 16-bit key range"));
}

}  // namespace
}  // namespace avp::ros::bag

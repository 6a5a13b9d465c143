#include "avp/ros/msg/markers.h"

#include <gtest/gtest.h>

#include <avp/ros/msg/convert.h>

namespace avp::ros::msg {
namespace {

const Header kHeader{Time::FromNanoseconds(5), "base"};

TEST(MarkersTest, ViewArrowPointsAlongTheOpticalAxis) {
  const RigidTransform X_WC =
      RigidTransform::LookAt(Eigen::Vector3d(1, 0, 0.5), Eigen::Vector3d(0, 0, 0.5));
  const Marker m =
      ViewArrowMarker(kHeader, "views", 3, X_WC, 0.2, {0.01, 0.02, 0.03}, Rgba(1, 0, 0));
  EXPECT_EQ(m.type, Marker::kArrow);
  EXPECT_EQ(m.action, Marker::kAdd);
  EXPECT_EQ(m.ns, "views");
  EXPECT_EQ(m.id, 3);
  EXPECT_EQ(m.header.frame_id, "base");
  EXPECT_EQ(m.pose.orientation.w, 1.0);  // arrows given by points: identity pose
  ASSERT_EQ(m.points.size(), 2u);
  EXPECT_NEAR(m.points[0].x, 1.0, 1e-12);
  EXPECT_NEAR(m.points[1].x, 0.8, 1e-12);  // 0.2 m towards the target
  EXPECT_NEAR(m.points[1].z, 0.5, 1e-12);
  EXPECT_EQ(m.scale, (Vector3{0.01, 0.02, 0.03}));
}

TEST(MarkersTest, TextSphereCubeListAndDeleteAll) {
  const Marker t = TextMarker(kHeader, "fruit", 1, {0, 0, 1}, "hello", 0.03, Rgba(1, 1, 1));
  EXPECT_EQ(t.type, Marker::kTextViewFacing);
  EXPECT_EQ(t.text, "hello");
  EXPECT_EQ(t.scale, (Vector3{0, 0, 0.03}));
  EXPECT_EQ(t.pose.position.z, 1.0);
  const Marker s = SphereMarker(kHeader, "fruit", 2, {1, 2, 3}, 0.05, Rgba(1, 0, 0, 0.5));
  EXPECT_EQ(s.type, Marker::kSphere);
  EXPECT_EQ(s.scale, (Vector3{0.05, 0.05, 0.05}));
  EXPECT_EQ(s.pose.position.y, 2.0);
  const Marker c = CubeListMarker(kHeader, "class", 0.005);
  EXPECT_EQ(c.type, Marker::kCubeList);
  EXPECT_TRUE(c.points.empty());
  EXPECT_EQ(DeleteAllMarker(kHeader).action, Marker::kDeleteAll);
}

TEST(MarkersTest, FruitMarkersReadBack) {
  const std::vector<GroundTruthFruit> fruits = {{7, {0.1, 0.2, 0.3}, 0.025},
                                                {65535, {-1, 0, 2}, 0.04}};
  MarkerArray markers = FruitMarkers(fruits, kHeader);
  ASSERT_EQ(markers.markers.size(), 2u);
  EXPECT_EQ(markers.markers[0].id, 7);
  EXPECT_EQ(markers.markers[0].scale.x, 0.05);
  // A marker that is not a fruit id (0, or past 16 bits) is skipped.
  markers.markers.push_back(DeleteAllMarker(kHeader));
  const std::vector<GroundTruthFruit> back = FruitsFromMarkers(markers);
  ASSERT_EQ(back.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(back[i].instance_id, fruits[i].instance_id);
    EXPECT_EQ(back[i].center_W, fruits[i].center_W);
    EXPECT_DOUBLE_EQ(back[i].radius_m, fruits[i].radius_m);
  }
}

}  // namespace
}  // namespace avp::ros::msg

#pragma once

// Reference messages shared by the unit tests and rosmsg_golden_dump: at least two per type, with
// empty strings and sequences, lengths that force padding, non-ASCII UTF-8, extreme values.

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <tuple>
#include <vector>

#include <avp/ros/msg/messages.h>

namespace avp::ros::msg::testing {

inline std::vector<uint8_t> Bytes(size_t n, uint8_t seed) {
  std::vector<uint8_t> out(n);
  for (size_t i = 0; i < n; ++i) out[i] = static_cast<uint8_t>(seed + 37 * i);
  return out;
}

inline Header H(int32_t sec, uint32_t nanosec, std::string frame) {
  return Header{Time{sec, nanosec}, std::move(frame)};
}

template <class T>
std::vector<T> References();

template <>
inline std::vector<Time> References() {
  return {Time{}, Time{std::numeric_limits<int32_t>::min(), 999'999'999},
          Time{std::numeric_limits<int32_t>::max(), 1}};
}
template <>
inline std::vector<Duration> References() {
  return {Duration{}, Duration{-2, 300'000'000}, Duration{3600, 5}};
}
template <>
inline std::vector<String> References() {
  return {String{}, String{"{\"view\": 3, \"X_WC\": [1, 0.5, -2e-17]}"},
          String{"tomate \u00e0 l'ancienne \u2014 \U0001F345"}, String{std::string(1001, 'x')}};
}
template <>
inline std::vector<Header> References() {
  return {Header{}, H(1'700'000'000, 123'456'789, "camera_color_optical_frame"), H(1, 2, "ü"),
          H(-5, 0, "frame/with/slashes_0123456789")};
}
template <>
inline std::vector<ColorRGBA> References() {
  return {ColorRGBA{}, ColorRGBA{1.0f, 0.5f, 0.25f, 0.125f},
          ColorRGBA{std::numeric_limits<float>::max(), std::numeric_limits<float>::denorm_min(),
                    -0.0f, 0.1f}};
}
template <>
inline std::vector<Point> References() {
  return {Point{}, Point{1.5, -2.25, 1e300},
          Point{std::numeric_limits<double>::denorm_min(), -0.0, 0.1}};
}
template <>
inline std::vector<Vector3> References() {
  return {Vector3{}, Vector3{0.005, 0.005, 0.005}, Vector3{-1e-300, 3.0, 1.0 / 3.0}};
}
template <>
inline std::vector<Quaternion> References() {
  return {Quaternion{}, Quaternion{0, 0, 0, 0}, Quaternion{0.5, -0.5, 0.5, 0.5}};
}
template <>
inline std::vector<Pose> References() {
  return {Pose{},
          Pose{Point{0.3, 0.0, 0.75}, Quaternion{0, 0.7071067811865476, 0, 0.7071067811865476}}};
}
template <>
inline std::vector<PoseStamped> References() {
  return {PoseStamped{},
          PoseStamped{H(12, 34, "igus_rebel_base_link"),
                      Pose{Point{1, 2, 3}, Quaternion{0.1, 0.2, 0.3, 0.9}}},
          // frame_id of 3 bytes: the Pose's doubles need 4 bytes of padding.
          PoseStamped{H(0, 0, "abc"), Pose{Point{-1, -2, -3}, Quaternion{}}}};
}
template <>
inline std::vector<PoseArray> References() {
  return {PoseArray{},
          PoseArray{H(7, 8, "w"), {Pose{}, Pose{Point{1, 1, 1}, Quaternion{0, 0, 1, 0}}}}};
}
template <>
inline std::vector<Transform> References() {
  return {Transform{}, Transform{Vector3{0.1, 0.2, 0.3},
                                 Quaternion{0, 0, 0.3826834323650898, 0.9238795325112867}}};
}
template <>
inline std::vector<TransformStamped> References() {
  return {TransformStamped{},
          TransformStamped{H(100, 200, "world"), "igus_rebel_link_6",
                           Transform{Vector3{0, 0, 0.5}, Quaternion{}}},
          TransformStamped{H(1, 1, "a"), "bé", Transform{}}};
}
template <>
inline std::vector<TFMessage> References() {
  TFMessage two;
  two.transforms = {References<TransformStamped>()[1], References<TransformStamped>()[2]};
  return {TFMessage{}, two};
}
template <>
inline std::vector<Image> References() {
  Image rgb;
  rgb.header = H(1'700'000'000, 5, "camera_color_optical_frame");
  rgb.height = 2;
  rgb.width = 3;
  rgb.encoding = "rgb8";
  rgb.step = 9;
  rgb.data = Bytes(18, 1);
  Image depth;  // 16UC1 big-endian flag set, odd lengths everywhere
  depth.header = H(3, 4, "d");
  depth.height = 1;
  depth.width = 1;
  depth.encoding = "16UC1";
  depth.is_bigendian = 1;
  depth.step = 2;
  depth.data = {0x12, 0x34};
  Image large;
  large.header = H(0, 0, "");
  large.height = std::numeric_limits<uint32_t>::max();
  large.width = 7;
  large.encoding = "32FC1";
  large.step = 28;
  large.data = Bytes(4099, 200);
  return {Image{}, rgb, depth, large};
}
template <>
inline std::vector<CompressedImage> References() {
  return {CompressedImage{}, CompressedImage{H(9, 9, "camera"), "jpeg", Bytes(5, 0xff)},
          CompressedImage{H(9, 9, "cam"), "png; 16UC1 compressedDepth", Bytes(3, 7)}};
}
template <>
inline std::vector<RegionOfInterest> References() {
  return {RegionOfInterest{}, RegionOfInterest{1, 2, 480, 640, true}};
}
template <>
inline std::vector<CameraInfo> References() {
  CameraInfo info;
  info.header = H(42, 43, "camera_color_optical_frame");
  info.height = 480;
  info.width = 640;
  info.distortion_model = "plumb_bob";
  info.d = {0.1, -0.2, 0.001, 0.002, 0.0};
  info.k = {615.0, 0, 320.5, 0, 615.5, 240.25, 0, 0, 1};
  info.r = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info.p = {615.0, 0, 320.5, 0, 0, 615.5, 240.25, 0, 0, 0, 1, 0};
  info.binning_x = 1;
  info.binning_y = 2;
  info.roi = RegionOfInterest{0, 0, 0, 0, true};
  CameraInfo odd;  // a 2-character model: k needs padding after an empty d
  odd.distortion_model = "eq";
  return {CameraInfo{}, info, odd};
}
template <>
inline std::vector<JointState> References() {
  JointState js;
  js.header = H(5, 6, "");
  js.name = {"joint1", "joint2", "", "gelenk_ä"};
  js.position = {0.0, -1.2217304763960306, 1.0471975511965976, 0.5};
  js.velocity = {};
  js.effort = {1e-3};
  return {JointState{}, js};
}
template <>
inline std::vector<PointField> References() {
  return {PointField{}, PointField{"x", 0, PointField::kFloat32, 1},
          PointField{"rgb", 16, PointField::kUint32, 1}};
}
template <>
inline std::vector<PointCloud2> References() {
  PointCloud2 cloud;
  cloud.header = H(10, 11, "world");
  cloud.height = 1;
  cloud.width = 2;
  cloud.fields = {PointField{"x", 0, PointField::kFloat32, 1},
                  PointField{"y", 4, PointField::kFloat32, 1},
                  PointField{"z", 8, PointField::kFloat32, 1},
                  PointField{"intensity", 12, PointField::kUint8, 1}};
  cloud.is_bigendian = false;
  cloud.point_step = 13;
  cloud.row_step = 26;
  cloud.data = Bytes(26, 3);
  cloud.is_dense = true;
  return {PointCloud2{}, cloud};
}
template <>
inline std::vector<JointTrajectoryPoint> References() {
  JointTrajectoryPoint p;
  p.positions = {0, 0.1, 0.2, 0.3, 0.4, 0.5};
  p.velocities = {};
  p.accelerations = {1};
  p.effort = {};
  p.time_from_start = Duration{2, 500'000'000};
  return {JointTrajectoryPoint{}, p};
}
template <>
inline std::vector<JointTrajectory> References() {
  JointTrajectory t;
  t.header = H(1, 0, "igus_rebel_base_link");
  t.joint_names = {"joint1", "joint2", "joint3", "joint4", "joint5", "joint6"};
  t.points = References<JointTrajectoryPoint>();
  return {JointTrajectory{}, t};
}
template <>
inline std::vector<UVCoordinate> References() {
  return {UVCoordinate{}, UVCoordinate{0.25f, 1.0f}};
}
template <>
inline std::vector<MeshFile> References() {
  return {MeshFile{}, MeshFile{"plant.dae", Bytes(11, 9)}};
}
template <>
inline std::vector<Marker> References() {
  Marker cubes;
  cubes.header = H(77, 88, "world");
  cubes.ns = "voxels/fruit";
  cubes.id = -3;
  cubes.type = Marker::kCubeList;
  cubes.action = Marker::kAdd;
  cubes.pose = Pose{};
  cubes.scale = Vector3{0.005, 0.005, 0.005};
  cubes.color = ColorRGBA{1, 0, 0, 1};
  cubes.lifetime = Duration{0, 0};
  cubes.frame_locked = true;
  cubes.points = {Point{0, 0, 0}, Point{0.005, 0, 0}, Point{0, 0.005, 0.01}};
  cubes.colors = {ColorRGBA{1, 0, 0, 1}, ColorRGBA{0, 1, 0, 1}, ColorRGBA{0, 0, 1, 0.5f}};
  Marker textured;
  textured.header = H(1, 2, "c");
  textured.ns = "";
  textured.id = std::numeric_limits<int32_t>::max();
  textured.type = Marker::kTriangleList;
  textured.action = Marker::kDeleteAll;
  textured.lifetime = Duration{-1, 999'999'999};
  textured.points = {Point{1, 2, 3}};
  textured.texture_resource = "embedded://texture";
  textured.texture = CompressedImage{H(3, 4, "tex"), "png", Bytes(7, 1)};
  textured.uv_coordinates = {UVCoordinate{0, 0}, UVCoordinate{1, 0.5f}, UVCoordinate{0.5f, 1}};
  textured.text = "Tomate – 12 Früchte";
  textured.mesh_resource = "package://avp/plant.stl";
  textured.mesh_file = MeshFile{"plant.stl", Bytes(3, 2)};
  textured.mesh_use_embedded_materials = true;
  return {Marker{}, cubes, textured};
}
template <>
inline std::vector<MarkerArray> References() {
  MarkerArray a;
  a.markers = References<Marker>();
  return {MarkerArray{}, a};
}
template <>
inline std::vector<Octomap> References() {
  Octomap map;
  map.header = H(1, 1, "world");
  map.binary = true;
  map.id = "OcTree";
  map.resolution = 0.005;
  map.data = {-128, -1, 0, 1, 127};
  Octomap color;
  color.header = H(2, 2, "map");
  color.id = "ColorOcTree";
  color.resolution = 0.1;
  color.data = {};
  return {Octomap{}, map, color};
}
template <>
inline std::vector<Gid> References() {
  Gid gid;
  for (size_t i = 0; i < 16; ++i) gid.data[i] = static_cast<uint8_t>(0xf0 + i);
  return {Gid{}, gid};
}
/// Humble keeps all 24 bytes of a GID; Jazzy only the first 16.
inline Gid Gid24() {
  Gid gid;
  for (size_t i = 0; i < 24; ++i) gid.data[i] = static_cast<uint8_t>(i + 1);
  return gid;
}
template <>
inline std::vector<NodeEntitiesInfo> References() {
  NodeEntitiesInfo node;
  node.node_namespace = "/";
  node.node_name = "avp_live";
  node.reader_gid_seq = References<Gid>();
  node.writer_gid_seq = {References<Gid>()[1]};
  NodeEntitiesInfo long_name;
  long_name.node_namespace = "/robots/rebel_1";
  long_name.node_name = std::string(256, 'n');
  return {NodeEntitiesInfo{}, node, long_name};
}
template <>
inline std::vector<ParticipantEntitiesInfo> References() {
  ParticipantEntitiesInfo p;
  p.gid = References<Gid>()[1];
  p.node_entities_info_seq = References<NodeEntitiesInfo>();
  return {ParticipantEntitiesInfo{}, p};
}

/// Every type, for typed tests.
#define AVP_ROSMSG_TYPE_COMMA(T) T,
using AllTypes = std::tuple<AVP_ROSMSG_FOR_EACH_TYPE(AVP_ROSMSG_TYPE_COMMA) void>;
#undef AVP_ROSMSG_TYPE_COMMA

}  // namespace avp::ros::msg::testing

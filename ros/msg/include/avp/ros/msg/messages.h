#pragma once

// ROS 2 messages as plain structs, with their ROS names, wire layout and schema, for talking to
// ROS 2 Humble / Jazzy peers without a ROS install (docs: ../shared/design/ros2-interop.md
// §1.2–1.6).
//
// Every type has a MessageTraits<T> specialisation naming it (`kRosName`, `kDdsName`), holding its
// own .msg text (`kMsg`, constants included; `kMsgHumble` where Humble's differs) and listing its
// fields in wire order (`VisitFields`). From those come:
//   Encode / Decode   XCDR1 bytes as rmw_cyclonedds and rmw_fastrtps write them (cdr.h);
//   Definition        the ros2msg schema text MCAP's ros2 profile and rosbag2 store;
//   TypeHash          the Jazzy type hash "RIHS01_<sha256 hex>" (REP-2011).
// Field names are the ROS names, so that code reads like a ROS callback.

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>
#include <avp/ros/msg/cdr.h>

namespace avp::ros::msg {

/// The ROS 2 distributions whose wire formats differ for some types (rmw_dds_common's Gid: 24 bytes
/// in Humble, 16 from Iron on). Jazzy also stands for Iron and later.
enum class RosDistro { kHumble, kJazzy };

/// "humble" or "jazzy".
std::string_view ToString(RosDistro distro);

// ---- builtin_interfaces -------------------------------------------------------------------------

/// A time stamp: seconds and nanoseconds since the epoch, nanosec in [0, 1e9).
struct Time {
  int32_t sec = 0;
  uint32_t nanosec = 0;
  /// Floor division, so -1 ns is {-1 s, 999999999 ns}; beyond the int32 seconds range
  /// (1901..2038) the result saturates at the nearest representable time.
  static Time FromNanoseconds(int64_t ns);
  int64_t ToNanoseconds() const;
  friend bool operator==(const Time&, const Time&) = default;
};

/// A signed duration, the same fields and rules as Time.
struct Duration {
  int32_t sec = 0;
  uint32_t nanosec = 0;
  static Duration FromNanoseconds(int64_t ns);
  int64_t ToNanoseconds() const;
  friend bool operator==(const Duration&, const Duration&) = default;
};

// ---- std_msgs -----------------------------------------------------------------------------------

struct Header {
  Time stamp;
  std::string frame_id;
  friend bool operator==(const Header&, const Header&) = default;
};

/// std_msgs/String: one UTF-8 string (avp's recordings carry JSON in it).
struct String {
  std::string data;
  friend bool operator==(const String&, const String&) = default;
};

struct ColorRGBA {
  float r = 0, g = 0, b = 0, a = 0;
  friend bool operator==(const ColorRGBA&, const ColorRGBA&) = default;
};

// ---- geometry_msgs ------------------------------------------------------------------------------

struct Point {
  double x = 0, y = 0, z = 0;
  friend bool operator==(const Point&, const Point&) = default;
};

struct Vector3 {
  double x = 0, y = 0, z = 0;
  friend bool operator==(const Vector3&, const Vector3&) = default;
};

/// w defaults to 1 (the identity), as in ROS; the wire carries all four values.
struct Quaternion {
  double x = 0, y = 0, z = 0, w = 1;
  friend bool operator==(const Quaternion&, const Quaternion&) = default;
};

struct Pose {
  Point position;
  Quaternion orientation;
  friend bool operator==(const Pose&, const Pose&) = default;
};

struct PoseStamped {
  Header header;
  Pose pose;
  friend bool operator==(const PoseStamped&, const PoseStamped&) = default;
};

struct PoseArray {
  Header header;
  std::vector<Pose> poses;
  friend bool operator==(const PoseArray&, const PoseArray&) = default;
};

struct Transform {
  Vector3 translation;
  Quaternion rotation;
  friend bool operator==(const Transform&, const Transform&) = default;
};

struct TransformStamped {
  Header header;  ///< header.frame_id is the parent frame
  std::string child_frame_id;
  Transform transform;
  friend bool operator==(const TransformStamped&, const TransformStamped&) = default;
};

// ---- tf2_msgs -----------------------------------------------------------------------------------

struct TFMessage {
  std::vector<TransformStamped> transforms;
  friend bool operator==(const TFMessage&, const TFMessage&) = default;
};

// ---- sensor_msgs --------------------------------------------------------------------------------

struct Image {
  Header header;
  uint32_t height = 0;
  uint32_t width = 0;
  std::string encoding;  ///< "rgb8", "bgr8", "mono8", "16UC1", "32FC1", ...
  uint8_t is_bigendian = 0;
  uint32_t step = 0;  ///< bytes per row
  std::vector<uint8_t> data;
  friend bool operator==(const Image&, const Image&) = default;
};

struct CompressedImage {
  Header header;
  std::string format;  ///< "jpeg", "png", ...
  std::vector<uint8_t> data;
  friend bool operator==(const CompressedImage&, const CompressedImage&) = default;
};

struct RegionOfInterest {
  uint32_t x_offset = 0;
  uint32_t y_offset = 0;
  uint32_t height = 0;
  uint32_t width = 0;
  bool do_rectify = false;
  friend bool operator==(const RegionOfInterest&, const RegionOfInterest&) = default;
};

struct CameraInfo {
  Header header;
  uint32_t height = 0;
  uint32_t width = 0;
  std::string distortion_model;  ///< "plumb_bob", "rational_polynomial", "equidistant"
  std::vector<double> d;
  std::array<double, 9> k{};   ///< row-major 3x3 intrinsics
  std::array<double, 9> r{};   ///< row-major 3x3 rectification
  std::array<double, 12> p{};  ///< row-major 3x4 projection
  uint32_t binning_x = 0;
  uint32_t binning_y = 0;
  RegionOfInterest roi;
  friend bool operator==(const CameraInfo&, const CameraInfo&) = default;
};

struct JointState {
  Header header;
  std::vector<std::string> name;
  std::vector<double> position;  ///< rad or m
  std::vector<double> velocity;
  std::vector<double> effort;
  friend bool operator==(const JointState&, const JointState&) = default;
};

struct PointField {
  static constexpr uint8_t kInt8 = 1;
  static constexpr uint8_t kUint8 = 2;
  static constexpr uint8_t kInt16 = 3;
  static constexpr uint8_t kUint16 = 4;
  static constexpr uint8_t kInt32 = 5;
  static constexpr uint8_t kUint32 = 6;
  static constexpr uint8_t kFloat32 = 7;
  static constexpr uint8_t kFloat64 = 8;
  std::string name;
  uint32_t offset = 0;
  uint8_t datatype = 0;
  uint32_t count = 0;
  friend bool operator==(const PointField&, const PointField&) = default;
};

struct PointCloud2 {
  Header header;
  uint32_t height = 0;
  uint32_t width = 0;
  std::vector<PointField> fields;
  bool is_bigendian = false;
  uint32_t point_step = 0;
  uint32_t row_step = 0;
  std::vector<uint8_t> data;
  bool is_dense = false;
  friend bool operator==(const PointCloud2&, const PointCloud2&) = default;
};

// ---- trajectory_msgs ----------------------------------------------------------------------------

struct JointTrajectoryPoint {
  std::vector<double> positions;
  std::vector<double> velocities;
  std::vector<double> accelerations;
  std::vector<double> effort;
  Duration time_from_start;
  friend bool operator==(const JointTrajectoryPoint&, const JointTrajectoryPoint&) = default;
};

struct JointTrajectory {
  Header header;
  std::vector<std::string> joint_names;
  std::vector<JointTrajectoryPoint> points;
  friend bool operator==(const JointTrajectory&, const JointTrajectory&) = default;
};

// ---- visualization_msgs -------------------------------------------------------------------------

struct UVCoordinate {
  float u = 0;
  float v = 0;
  friend bool operator==(const UVCoordinate&, const UVCoordinate&) = default;
};

struct MeshFile {
  std::string filename;
  std::vector<uint8_t> data;
  friend bool operator==(const MeshFile&, const MeshFile&) = default;
};

struct Marker {
  // type
  static constexpr int32_t kArrow = 0;
  static constexpr int32_t kCube = 1;
  static constexpr int32_t kSphere = 2;
  static constexpr int32_t kCylinder = 3;
  static constexpr int32_t kLineStrip = 4;
  static constexpr int32_t kLineList = 5;
  static constexpr int32_t kCubeList = 6;
  static constexpr int32_t kSphereList = 7;
  static constexpr int32_t kPoints = 8;
  static constexpr int32_t kTextViewFacing = 9;
  static constexpr int32_t kMeshResource = 10;
  static constexpr int32_t kTriangleList = 11;
  static constexpr int32_t kArrowStrip = 12;  ///< Jazzy and later only
  // action
  static constexpr int32_t kAdd = 0;
  static constexpr int32_t kModify = 0;
  static constexpr int32_t kDelete = 2;
  static constexpr int32_t kDeleteAll = 3;

  Header header;
  std::string ns;
  int32_t id = 0;
  int32_t type = 0;
  int32_t action = 0;
  Pose pose;
  Vector3 scale;
  ColorRGBA color;
  Duration lifetime;  ///< 0 = forever
  bool frame_locked = false;
  std::vector<Point> points;
  std::vector<ColorRGBA> colors;
  std::string texture_resource;
  CompressedImage texture;
  std::vector<UVCoordinate> uv_coordinates;
  std::string text;
  std::string mesh_resource;
  MeshFile mesh_file;
  bool mesh_use_embedded_materials = false;
  friend bool operator==(const Marker&, const Marker&) = default;
};

struct MarkerArray {
  std::vector<Marker> markers;
  friend bool operator==(const MarkerArray&, const MarkerArray&) = default;
};

// ---- octomap_msgs -------------------------------------------------------------------------------

/// data is OcTree::writeBinaryData() (binary = true, id "OcTree") or AbstractOcTree::writeData()
/// (id "OcTree" or "ColorOcTree"), without the file header.
struct Octomap {
  Header header;
  bool binary = false;
  std::string id;
  double resolution = 0;  ///< m
  std::vector<int8_t> data;
  friend bool operator==(const Octomap&, const Octomap&) = default;
};

// ---- rmw_dds_common (the ros_discovery_info topic that `ros2 node list` reads) ------------------

/// A DDS entity GID: 24 bytes on the wire in Humble, 16 from Iron on (the last 8 bytes are then
/// not sent, and read back as 0). The .msg type is char[N], which ROS maps to uint8.
struct Gid {
  std::array<uint8_t, 24> data{};
  friend bool operator==(const Gid&, const Gid&) = default;
};

struct NodeEntitiesInfo {
  static constexpr size_t kMaxNameChars = 256;  ///< string<=256
  std::string node_namespace;
  std::string node_name;
  std::vector<Gid> reader_gid_seq;
  std::vector<Gid> writer_gid_seq;
  friend bool operator==(const NodeEntitiesInfo&, const NodeEntitiesInfo&) = default;
};

struct ParticipantEntitiesInfo {
  Gid gid;
  std::vector<NodeEntitiesInfo> node_entities_info_seq;
  friend bool operator==(const ParticipantEntitiesInfo&, const ParticipantEntitiesInfo&) = default;
};

// ---- Traits -------------------------------------------------------------------------------------

/// Specialised below for every message type. Members:
///   kRosName  "sensor_msgs/msg/Image"
///   kDdsName  "sensor_msgs::msg::dds_::Image_" (the DDS type name rmw implementations register)
///   kMsg      the type's own .msg text (fields and constants, ROS spelling), Jazzy's
///   kMsgHumble  (some types only) Humble's .msg text where it differs
///   kDistroDependent  true when the wire format differs between distributions
///   VisitFields(visitor, msg)  calls `visitor("field", msg.field)` for every field in wire order;
///     visitors also offer FixedBytes(name, array, n), BoundedString(name, s, bound) and distro().
template <class T>
struct MessageTraits;

/// True for the message types of this header.
template <class T>
concept RosMessage = requires {
  { MessageTraits<T>::kRosName } -> std::convertible_to<std::string_view>;
};

template <class T>
inline constexpr bool kDistroDependent = MessageTraits<T>::kDistroDependent;

#define AVP_ROSMSG_NAMES(pkg, type)                                            \
  static constexpr std::string_view kRosName = #pkg "/msg/" #type;             \
  static constexpr std::string_view kDdsName = #pkg "::msg::dds_::" #type "_"; \
  static constexpr bool kDistroDependent = false

template <>
struct MessageTraits<Time> {
  AVP_ROSMSG_NAMES(builtin_interfaces, Time);
  static constexpr std::string_view kMsg = "int32 sec\nuint32 nanosec\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("sec", m.sec);
    v("nanosec", m.nanosec);
  }
};

template <>
struct MessageTraits<Duration> {
  AVP_ROSMSG_NAMES(builtin_interfaces, Duration);
  static constexpr std::string_view kMsg = "int32 sec\nuint32 nanosec\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("sec", m.sec);
    v("nanosec", m.nanosec);
  }
};

template <>
struct MessageTraits<Header> {
  AVP_ROSMSG_NAMES(std_msgs, Header);
  static constexpr std::string_view kMsg = "builtin_interfaces/Time stamp\nstring frame_id\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("stamp", m.stamp);
    v("frame_id", m.frame_id);
  }
};

template <>
struct MessageTraits<String> {
  AVP_ROSMSG_NAMES(std_msgs, String);
  static constexpr std::string_view kMsg = "string data\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("data", m.data);
  }
};

template <>
struct MessageTraits<ColorRGBA> {
  AVP_ROSMSG_NAMES(std_msgs, ColorRGBA);
  static constexpr std::string_view kMsg = "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("r", m.r);
    v("g", m.g);
    v("b", m.b);
    v("a", m.a);
  }
};

template <>
struct MessageTraits<Point> {
  AVP_ROSMSG_NAMES(geometry_msgs, Point);
  static constexpr std::string_view kMsg = "float64 x\nfloat64 y\nfloat64 z\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("x", m.x);
    v("y", m.y);
    v("z", m.z);
  }
};

template <>
struct MessageTraits<Vector3> {
  AVP_ROSMSG_NAMES(geometry_msgs, Vector3);
  static constexpr std::string_view kMsg = "float64 x\nfloat64 y\nfloat64 z\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("x", m.x);
    v("y", m.y);
    v("z", m.z);
  }
};

template <>
struct MessageTraits<Quaternion> {
  AVP_ROSMSG_NAMES(geometry_msgs, Quaternion);
  static constexpr std::string_view kMsg = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("x", m.x);
    v("y", m.y);
    v("z", m.z);
    v("w", m.w);
  }
};

template <>
struct MessageTraits<Pose> {
  AVP_ROSMSG_NAMES(geometry_msgs, Pose);
  static constexpr std::string_view kMsg = "Point position\nQuaternion orientation\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("position", m.position);
    v("orientation", m.orientation);
  }
};

template <>
struct MessageTraits<PoseStamped> {
  AVP_ROSMSG_NAMES(geometry_msgs, PoseStamped);
  static constexpr std::string_view kMsg = "std_msgs/Header header\nPose pose\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("pose", m.pose);
  }
};

template <>
struct MessageTraits<PoseArray> {
  AVP_ROSMSG_NAMES(geometry_msgs, PoseArray);
  static constexpr std::string_view kMsg = "std_msgs/Header header\nPose[] poses\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("poses", m.poses);
  }
};

template <>
struct MessageTraits<Transform> {
  AVP_ROSMSG_NAMES(geometry_msgs, Transform);
  static constexpr std::string_view kMsg = "Vector3 translation\nQuaternion rotation\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("translation", m.translation);
    v("rotation", m.rotation);
  }
};

template <>
struct MessageTraits<TransformStamped> {
  AVP_ROSMSG_NAMES(geometry_msgs, TransformStamped);
  static constexpr std::string_view kMsg =
      "std_msgs/Header header\nstring child_frame_id\nTransform transform\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("child_frame_id", m.child_frame_id);
    v("transform", m.transform);
  }
};

template <>
struct MessageTraits<TFMessage> {
  AVP_ROSMSG_NAMES(tf2_msgs, TFMessage);
  static constexpr std::string_view kMsg = "geometry_msgs/TransformStamped[] transforms\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("transforms", m.transforms);
  }
};

template <>
struct MessageTraits<Image> {
  AVP_ROSMSG_NAMES(sensor_msgs, Image);
  static constexpr std::string_view kMsg =
      "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n"
      "uint32 step\nuint8[] data\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("height", m.height);
    v("width", m.width);
    v("encoding", m.encoding);
    v("is_bigendian", m.is_bigendian);
    v("step", m.step);
    v("data", m.data);
  }
};

template <>
struct MessageTraits<CompressedImage> {
  AVP_ROSMSG_NAMES(sensor_msgs, CompressedImage);
  static constexpr std::string_view kMsg = "std_msgs/Header header\nstring format\nuint8[] data\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("format", m.format);
    v("data", m.data);
  }
};

template <>
struct MessageTraits<RegionOfInterest> {
  AVP_ROSMSG_NAMES(sensor_msgs, RegionOfInterest);
  static constexpr std::string_view kMsg =
      "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("x_offset", m.x_offset);
    v("y_offset", m.y_offset);
    v("height", m.height);
    v("width", m.width);
    v("do_rectify", m.do_rectify);
  }
};

template <>
struct MessageTraits<CameraInfo> {
  AVP_ROSMSG_NAMES(sensor_msgs, CameraInfo);
  static constexpr std::string_view kMsg =
      "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n"
      "float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n"
      "uint32 binning_y\nRegionOfInterest roi\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("height", m.height);
    v("width", m.width);
    v("distortion_model", m.distortion_model);
    v("d", m.d);
    v("k", m.k);
    v("r", m.r);
    v("p", m.p);
    v("binning_x", m.binning_x);
    v("binning_y", m.binning_y);
    v("roi", m.roi);
  }
};

template <>
struct MessageTraits<JointState> {
  AVP_ROSMSG_NAMES(sensor_msgs, JointState);
  static constexpr std::string_view kMsg =
      "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
      "float64[] effort\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("name", m.name);
    v("position", m.position);
    v("velocity", m.velocity);
    v("effort", m.effort);
  }
};

template <>
struct MessageTraits<PointField> {
  AVP_ROSMSG_NAMES(sensor_msgs, PointField);
  static constexpr std::string_view kMsg =
      "uint8 INT8 = 1\nuint8 UINT8 = 2\nuint8 INT16 = 3\nuint8 UINT16 = 4\nuint8 INT32 = 5\n"
      "uint8 UINT32 = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\n"
      "string name\nuint32 offset\nuint8 datatype\nuint32 count\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("name", m.name);
    v("offset", m.offset);
    v("datatype", m.datatype);
    v("count", m.count);
  }
};

template <>
struct MessageTraits<PointCloud2> {
  AVP_ROSMSG_NAMES(sensor_msgs, PointCloud2);
  static constexpr std::string_view kMsg =
      "std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\n"
      "bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("height", m.height);
    v("width", m.width);
    v("fields", m.fields);
    v("is_bigendian", m.is_bigendian);
    v("point_step", m.point_step);
    v("row_step", m.row_step);
    v("data", m.data);
    v("is_dense", m.is_dense);
  }
};

template <>
struct MessageTraits<JointTrajectoryPoint> {
  AVP_ROSMSG_NAMES(trajectory_msgs, JointTrajectoryPoint);
  static constexpr std::string_view kMsg =
      "float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\nfloat64[] effort\n"
      "builtin_interfaces/Duration time_from_start\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("positions", m.positions);
    v("velocities", m.velocities);
    v("accelerations", m.accelerations);
    v("effort", m.effort);
    v("time_from_start", m.time_from_start);
  }
};

template <>
struct MessageTraits<JointTrajectory> {
  AVP_ROSMSG_NAMES(trajectory_msgs, JointTrajectory);
  static constexpr std::string_view kMsg =
      "std_msgs/Header header\nstring[] joint_names\nJointTrajectoryPoint[] points\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("joint_names", m.joint_names);
    v("points", m.points);
  }
};

template <>
struct MessageTraits<UVCoordinate> {
  AVP_ROSMSG_NAMES(visualization_msgs, UVCoordinate);
  static constexpr std::string_view kMsg = "float32 u\nfloat32 v\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("u", m.u);
    v("v", m.v);
  }
};

template <>
struct MessageTraits<MeshFile> {
  AVP_ROSMSG_NAMES(visualization_msgs, MeshFile);
  static constexpr std::string_view kMsg = "string filename\nuint8[] data\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("filename", m.filename);
    v("data", m.data);
  }
};

#define AVP_ROSMSG_MARKER_CONSTANTS(extra)                                                  \
  "int32 ARROW = 0\nint32 CUBE = 1\nint32 SPHERE = 2\nint32 CYLINDER = 3\n"                 \
  "int32 LINE_STRIP = 4\nint32 LINE_LIST = 5\nint32 CUBE_LIST = 6\nint32 SPHERE_LIST = 7\n" \
  "int32 POINTS = 8\nint32 TEXT_VIEW_FACING = 9\nint32 MESH_RESOURCE = 10\n"                \
  "int32 TRIANGLE_LIST = 11\n" extra                                                        \
  "\nint32 ADD = 0\nint32 MODIFY = 0\nint32 DELETE = 2\nint32 DELETEALL = 3\n\n"
#define AVP_ROSMSG_MARKER_FIELDS                                                                \
  "std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n"                     \
  "geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n"            \
  "builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n"     \
  "std_msgs/ColorRGBA[] colors\nstring texture_resource\nsensor_msgs/CompressedImage texture\n" \
  "UVCoordinate[] uv_coordinates\nstring text\nstring mesh_resource\nMeshFile mesh_file\n"      \
  "bool mesh_use_embedded_materials\n"

template <>
struct MessageTraits<Marker> {
  AVP_ROSMSG_NAMES(visualization_msgs, Marker);
  static constexpr std::string_view kMsg =
      AVP_ROSMSG_MARKER_CONSTANTS("int32 ARROW_STRIP = 12\n") AVP_ROSMSG_MARKER_FIELDS;
  static constexpr std::string_view kMsgHumble =
      AVP_ROSMSG_MARKER_CONSTANTS("") AVP_ROSMSG_MARKER_FIELDS;
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("ns", m.ns);
    v("id", m.id);
    v("type", m.type);
    v("action", m.action);
    v("pose", m.pose);
    v("scale", m.scale);
    v("color", m.color);
    v("lifetime", m.lifetime);
    v("frame_locked", m.frame_locked);
    v("points", m.points);
    v("colors", m.colors);
    v("texture_resource", m.texture_resource);
    v("texture", m.texture);
    v("uv_coordinates", m.uv_coordinates);
    v("text", m.text);
    v("mesh_resource", m.mesh_resource);
    v("mesh_file", m.mesh_file);
    v("mesh_use_embedded_materials", m.mesh_use_embedded_materials);
  }
};
#undef AVP_ROSMSG_MARKER_CONSTANTS
#undef AVP_ROSMSG_MARKER_FIELDS

template <>
struct MessageTraits<MarkerArray> {
  AVP_ROSMSG_NAMES(visualization_msgs, MarkerArray);
  static constexpr std::string_view kMsg = "Marker[] markers\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("markers", m.markers);
  }
};

template <>
struct MessageTraits<Octomap> {
  AVP_ROSMSG_NAMES(octomap_msgs, Octomap);
  static constexpr std::string_view kMsg =
      "std_msgs/Header header\nbool binary\nstring id\nfloat64 resolution\nint8[] data\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("header", m.header);
    v("binary", m.binary);
    v("id", m.id);
    v("resolution", m.resolution);
    v("data", m.data);
  }
};

#undef AVP_ROSMSG_NAMES
#define AVP_ROSMSG_NAMES(pkg, type)                                            \
  static constexpr std::string_view kRosName = #pkg "/msg/" #type;             \
  static constexpr std::string_view kDdsName = #pkg "::msg::dds_::" #type "_"; \
  static constexpr bool kDistroDependent = true

template <>
struct MessageTraits<Gid> {
  AVP_ROSMSG_NAMES(rmw_dds_common, Gid);
  static constexpr std::string_view kMsg = "char[16] data\n";
  static constexpr std::string_view kMsgHumble = "char[24] data\n";
  /// Bytes on the wire.
  static constexpr size_t WireBytes(RosDistro distro) {
    return distro == RosDistro::kHumble ? 24 : 16;
  }
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v.FixedBytes("data", m.data, WireBytes(v.distro()));
  }
};

template <>
struct MessageTraits<NodeEntitiesInfo> {
  AVP_ROSMSG_NAMES(rmw_dds_common, NodeEntitiesInfo);
  static constexpr std::string_view kMsg =
      "string<=256 node_namespace\nstring<=256 node_name\nGid[] reader_gid_seq\n"
      "Gid[] writer_gid_seq\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v.BoundedString("node_namespace", m.node_namespace, NodeEntitiesInfo::kMaxNameChars);
    v.BoundedString("node_name", m.node_name, NodeEntitiesInfo::kMaxNameChars);
    v("reader_gid_seq", m.reader_gid_seq);
    v("writer_gid_seq", m.writer_gid_seq);
  }
};

template <>
struct MessageTraits<ParticipantEntitiesInfo> {
  AVP_ROSMSG_NAMES(rmw_dds_common, ParticipantEntitiesInfo);
  static constexpr std::string_view kMsg = "Gid gid\nNodeEntitiesInfo[] node_entities_info_seq\n";
  template <class V, class M>
  static void VisitFields(V& v, M& m) {
    v("gid", m.gid);
    v("node_entities_info_seq", m.node_entities_info_seq);
  }
};
#undef AVP_ROSMSG_NAMES

/// Calls X(Type) for every message type above (explicit instantiations, tests).
// clang-format off
#define AVP_ROSMSG_FOR_EACH_TYPE(X)                                                               \
  X(Time) X(Duration) X(Header) X(String) X(ColorRGBA) X(Point) X(Vector3) X(Quaternion) X(Pose)            \
  X(PoseStamped) X(PoseArray) X(Transform) X(TransformStamped) X(TFMessage) X(Image)              \
  X(CompressedImage) X(RegionOfInterest) X(CameraInfo) X(JointState) X(PointField)                \
  X(PointCloud2) X(JointTrajectoryPoint) X(JointTrajectory) X(UVCoordinate) X(MeshFile)           \
  X(Marker) X(MarkerArray) X(Octomap) X(Gid) X(NodeEntitiesInfo) X(ParticipantEntitiesInfo)
// clang-format on

// ---- Encoding -----------------------------------------------------------------------------------

/// XCDR1 bytes of `msg` as a ROS 2 `distro` peer expects them, with the encapsulation header
/// (`00 01 00 00` little-endian by default). Never fails for a message held in memory (a string or
/// sequence past 2^32 elements throws avp::Error). Note that bounded fields (NodeEntitiesInfo's
/// names) are written as they are; a peer refuses names past the bound.
template <RosMessage T>
std::vector<uint8_t> Encode(const T& msg, RosDistro distro,
                            Endianness endianness = Endianness::kLittle);

/// Encode for the types whose wire does not depend on the distribution.
template <RosMessage T>
requires(!kDistroDependent<T>) std::vector<uint8_t> Encode(const T& msg) {
  return Encode(msg, RosDistro::kJazzy);
}

/// Decodes a sample (encapsulation header included, either byte order). Bounded and safe against
/// any input: every length is checked against the remaining bytes before anything is allocated,
/// samples over kMaxSampleBytes are refused, strings must end in NUL, bools be 0 or 1. Errors are
/// InvalidArgument and name the type, the field path and the byte offset, e.g.
/// "sensor_msgs/msg/Image: data: sequence of 4000000 bytes at offset 48 exceeds the 120 remaining".
/// Trailing bytes after the last field are ignored (CDR permits padding there).
template <RosMessage T>
Result<T> Decode(std::span<const uint8_t> bytes, RosDistro distro);

template <RosMessage T>
requires(!kDistroDependent<T>) Result<T> Decode(std::span<const uint8_t> bytes) {
  return Decode<T>(bytes, RosDistro::kJazzy);
}

// ---- Schemas and type hashes --------------------------------------------------------------------

/// The ros2msg schema of `ros_name` ("sensor_msgs/msg/Image") as MCAP's ros2 profile and rosbag2
/// store it: the type's .msg text, then for each type it depends on (depth first, each once) a line
/// of 80 '=', a line "MSG: pkg/Type" (no "/msg/") and that type's text. NotFound for a type this
/// header does not define.
Result<std::string> DefinitionOf(std::string_view ros_name, RosDistro distro = RosDistro::kJazzy);

/// The REP-2011 type hash "RIHS01_<64 lowercase hex>" of `ros_name` as Jazzy computes it
/// (rosidl_generator_type_description): SHA-256 of the canonical JSON TypeDescription built from
/// the field names and types of the type and every type it references (sorted by name); default
/// values, constants and comments do not count.
Result<std::string> TypeHashOf(std::string_view ros_name);

/// The canonical JSON that TypeHashOf hashes (for tests and debugging).
Result<std::string> TypeDescriptionJsonOf(std::string_view ros_name);

template <RosMessage T>
std::string_view Definition(RosDistro distro = RosDistro::kJazzy);

template <RosMessage T>
std::string TypeHash() {
  return TypeHashOf(MessageTraits<T>::kRosName).value();
}

/// Every type of this header: ROS name, DDS name, own .msg text per distribution.
struct MessageInfo {
  std::string_view ros_name;
  std::string_view dds_name;
  std::string_view msg_jazzy;
  std::string_view msg_humble;
  bool distro_dependent = false;
};
std::span<const MessageInfo> AllMessages();

}  // namespace avp::ros::msg

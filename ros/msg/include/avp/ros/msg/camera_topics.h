#pragma once

// Where a camera's frames are on ROS 2: the topics and frames that `avp sim ros2` publishes
// (ros::simrobot::SimRobotOptions), `avp live` subscribes to (ros::live::CameraTopicsOptions, the
// `live.camera` section) and `avp replay` reads from a bag (ros::bag::BagReadOptions,
// `--bag-option`): one definition, one table of keys (docs/ros2.md).

#include <concepts>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/options.h>

namespace avp::ros::msg {

/// The simulator's labels on ROS 2: PREFIX/instance (16UC1 instance ids), PREFIX/class (mono8
/// SemanticClass ids), PREFIX/fruits (latched MarkerArray), stamped as the colour image. What `avp
/// sim ros2` publishes, what recordings hold (ros/bag/layout.h) and where `avp replay` and `avp
/// live` (when told: a real robot has none) look for them: the oracle segmenter's input.
inline constexpr std::string_view kSimLabelsPrefix = "/avp/sim";

/// Where a camera's frames are: the topics and frames the simulated robot publishes (`avp sim
/// ros2`), `avp live` subscribes to and `avp replay` reads. The defaults are the seed system's
/// RealSense D435 under realsense2_camera with align_depth.enable:=true, on an igus ReBeL.
struct CameraTopics {
  std::string color_topic = "/camera/camera/color/image_raw";
  std::string depth_topic = "/camera/camera/aligned_depth_to_color/image_raw";
  std::string camera_info_topic = "/camera/camera/color/camera_info";
  /// The map's frame (the arm's base) and the camera's optical frame; empty camera_frame: the
  /// colour image's header.frame_id (readers only).
  std::string base_frame = "igus_rebel_base_link";
  std::string camera_frame = "camera_color_optical_frame";
  /// The transforms (tf2_msgs/TFMessage), as tf2_ros names them.
  std::string tf_topic = "/tf";
  std::string tf_static_topic = "/tf_static";
  /// Readers: a colour and a depth image form a pair when their stamps differ by at most this.
  double max_pair_skew_ms = 5.0;
};

/// Adds the names of CameraTopics (color_topic, depth_topic, camera_info_topic, base_frame,
/// camera_frame, tf_topic, tf_static_topic) to the table of an options struct that derives from
/// it, and the rule that the topics and the base frame are not empty.
template <std::derived_from<CameraTopics> O>
void AddCameraTopicNames(OptionTable<O>& t) {
  t.Text("color_topic", &O::color_topic,
         "colour image (read: rgb8, bgr8, rgba8, bgra8, mono8; avp sim ros2 writes rgb8)");
  t.Text("depth_topic", &O::depth_topic, "depth aligned to colour (16UC1 mm, 32FC1 m)");
  t.Text("camera_info_topic", &O::camera_info_topic, "the colour camera's CameraInfo");
  t.Text("base_frame", &O::base_frame, "the map's frame: the arm's base");
  t.Text("camera_frame", &O::camera_frame,
         "the camera's optical frame (readers: empty is the colour image's frame_id)");
  t.Text("tf_topic", &O::tf_topic, "dynamic transforms (tf2_msgs/TFMessage)");
  t.Text("tf_static_topic", &O::tf_static_topic, "static transforms (tf2_msgs/TFMessage)");
  t.AddRule([](const O& o, std::vector<std::string>& errors) {
    for (const auto& [key, value] : {std::pair{"color_topic", &o.color_topic},
                                     {"depth_topic", &o.depth_topic},
                                     {"camera_info_topic", &o.camera_info_topic},
                                     {"base_frame", &o.base_frame},
                                     {"tf_topic", &o.tf_topic},
                                     {"tf_static_topic", &o.tf_static_topic}}) {
      if (value->empty()) errors.push_back(std::string(key) + " is empty");
    }
  });
}

/// The readers' table (`avp live`'s camera, `avp replay`'s bag): the names and max_pair_skew_ms.
template <std::derived_from<CameraTopics> O>
void AddCameraTopicOptions(OptionTable<O>& t) {
  AddCameraTopicNames(t);
  t.Real("max_pair_skew_ms", &O::max_pair_skew_ms, "ms", ValueRange::Closed(0, 1000),
         "colour and depth stamps may differ by this much");
}

}  // namespace avp::ros::msg

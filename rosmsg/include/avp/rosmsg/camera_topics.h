#pragma once

// Where a camera's frames are on ROS 2: the topics and frames that `avp live` subscribes to
// (live::CameraTopicsOptions, the `live.camera` section) and that `avp replay` reads from a bag
// (recording::BagReadOptions, `--bag-option`): one definition, one table of keys (docs/ros2.md).

#include <concepts>
#include <string>
#include <vector>

#include <avp/core/options.h>

namespace avp::rosmsg {

/// The defaults are the seed system's RealSense D435 under realsense2_camera with
/// align_depth.enable:=true, on an igus ReBeL.
struct CameraTopics {
  std::string color_topic = "/camera/camera/color/image_raw";
  std::string depth_topic = "/camera/camera/aligned_depth_to_color/image_raw";
  std::string camera_info_topic = "/camera/camera/color/camera_info";
  /// The map's frame (the arm's base) and the camera's optical frame; empty camera_frame: the
  /// colour image's header.frame_id.
  std::string base_frame = "igus_rebel_base_link";
  std::string camera_frame = "camera_color_optical_frame";
  /// A colour and a depth image form a pair when their stamps differ by at most this.
  double max_pair_skew_ms = 5.0;
};

/// Adds the keys of CameraTopics (color_topic, depth_topic, camera_info_topic, base_frame,
/// camera_frame, max_pair_skew_ms) to the table of an options struct that derives from it, and
/// the rule that the three topics and the base frame are not empty.
template <std::derived_from<CameraTopics> O>
void AddCameraTopicOptions(OptionTable<O>& t) {
  t.Text("color_topic", &O::color_topic, "colour image (rgb8, bgr8, rgba8, bgra8, mono8)");
  t.Text("depth_topic", &O::depth_topic, "depth aligned to colour (16UC1 mm, 32FC1 m)");
  t.Text("camera_info_topic", &O::camera_info_topic, "the colour camera's CameraInfo");
  t.Text("base_frame", &O::base_frame, "the map's frame: the arm's base");
  t.Text("camera_frame", &O::camera_frame,
         "the camera's optical frame (empty: the colour image's frame_id)");
  t.Real("max_pair_skew_ms", &O::max_pair_skew_ms, "ms", ValueRange::Closed(0, 1000),
         "colour and depth stamps may differ by this much");
  t.AddRule([](const O& o, std::vector<std::string>& errors) {
    for (const auto& [key, value] : {std::pair{"color_topic", &o.color_topic},
                                     {"depth_topic", &o.depth_topic},
                                     {"camera_info_topic", &o.camera_info_topic},
                                     {"base_frame", &o.base_frame}}) {
      if (value->empty()) errors.push_back(std::string(key) + " is empty");
    }
  });
}

}  // namespace avp::rosmsg

#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>
#include <vector>

#include <avp/core/camera.h>
#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/live/clock.h>
#include <avp/live/tf_buffer.h>
#include <avp/robot/rgbd_source.h>
#include <avp/ros2/node.h>
#include <avp/rosmsg/messages.h>

namespace avp::live {

/// Where a live camera's frames come from (docs/ros2.md). The defaults are the seed system's
/// RealSense D435 under realsense2_camera with align_depth.enable:=true, on an igus ReBeL.
struct CameraTopicsOptions {
  std::string color_topic = "/camera/camera/color/image_raw";
  std::string depth_topic = "/camera/camera/aligned_depth_to_color/image_raw";
  std::string camera_info_topic = "/camera/camera/color/camera_info";
  /// The map's frame (the arm's base) and the camera's optical frame; empty camera_frame: the
  /// colour image's header.frame_id.
  std::string base_frame = "igus_rebel_base_link";
  std::string camera_frame = "camera_color_optical_frame";
  /// Images with the sensor-data QoS (best effort, as camera drivers publish); false: reliable.
  bool best_effort = true;
  /// A colour and a depth image form a pair when their stamps differ by at most this.
  double max_pair_skew_ms = 5.0;
  /// A capture waits at most this long for a pair stamped after it was asked for.
  double frame_timeout_s = 5.0;
  /// ... and then at most this long for the transform at the pair's stamp.
  double tf_timeout_s = 1.0;
  /// Frames are used only when stamped at least this long after the capture was asked for
  /// (after the arm arrived): motion blur and rolling shutters settle.
  double settle_s = 0.0;
  /// Simulator labels for the oracle segmenter (avp sim ros2 publishes them): PREFIX/instance
  /// (16UC1 instance ids), PREFIX/class (mono8 classes), PREFIX/fruits (MarkerArray); empty: none.
  std::string labels_prefix;
  /// Frames of each topic kept while waiting for their partner.
  int queue = 30;
};
const OptionTable<CameraTopicsOptions>& CameraTopicsOptionTable();

/// Counts of what a live source received and refused (record.json's "live").
struct SourceCounters {
  uint64_t color = 0;
  uint64_t depth = 0;
  uint64_t camera_info = 0;
  uint64_t refused = 0;  ///< images refused on arrival (encoding, size, step)
  uint64_t pairs_used = 0;
  std::string last_problem;
};

/// A robot::RgbdSource on ROS 2 topics: colour (rgb8, bgr8) and aligned depth (16UC1 mm, 32FC1
/// m) paired by stamp, the intrinsics from CameraInfo (the depth range from `camera`), and X_WC
/// from the TF buffer at the pair's stamp, base_frame → camera_frame. Capture(X_WC, stamp) waits
/// (bounded, and ended by the stop token) for the first pair stamped after it was called.
/// Non-finite, zero or negative depth becomes "no return" (0). Every problem is a status naming
/// the topic and the value: an unsupported encoding, a size or step that does not match, a
/// camera that stops (DeadlineExceeded), TF missing or late.
class Ros2RgbdSource final : public robot::RgbdSource {
 public:
  /// Subscribes and waits (frame_timeout_s) for the first CameraInfo. `tf` is shared with the
  /// arm; `camera` gives the depth range (and a warning when the CameraInfo's size differs).
  static Result<std::unique_ptr<Ros2RgbdSource>> Create(ros2::Node& node, TfBuffer& tf,
                                                        const CameraTopicsOptions& options,
                                                        const CameraIntrinsics& camera,
                                                        std::stop_token stop = {});
  ~Ros2RgbdSource() override;

  Result<robot::Observation> Capture(const RigidTransform& X_WC, int64_t stamp_ns) override;
  CameraIntrinsics intrinsics() const override;
  SourceCounters counters() const;

  /// Converts one image, checking encoding, sizes and step (exposed for tests).
  static Result<ImageRgb8> ColorFromMessage(const rosmsg::Image& msg, std::string_view topic);
  static Result<DepthImage> DepthFromMessage(const rosmsg::Image& msg, std::string_view topic);
  /// Intrinsics from a CameraInfo (k), with the depth range of `range`.
  static Result<CameraIntrinsics> IntrinsicsFromCameraInfo(const rosmsg::CameraInfo& info,
                                                           const CameraIntrinsics& range);

 private:
  Ros2RgbdSource(ros2::Node& node, TfBuffer& tf, const CameraTopicsOptions& options,
                 const CameraIntrinsics& camera, std::stop_token stop);
  Status Subscribe();
  void OnImage(rosmsg::Image&& msg, bool is_color);
  void OnLabel(rosmsg::Image&& msg, bool is_instance);
  void OnCameraInfo(rosmsg::CameraInfo&& msg);
  void OnFruits(rosmsg::MarkerArray&& msg);
  /// The first pair stamped at or after `not_before_ns`; call with mutex_ held.
  std::optional<std::pair<size_t, size_t>> FindPair(int64_t not_before_ns) const;
  Result<robot::Observation> Assemble(const rosmsg::Image& color, const rosmsg::Image& depth,
                                      std::unique_lock<std::mutex>& lock);

  ros2::Node& node_;
  TfBuffer& tf_;
  CameraTopicsOptions options_;
  CameraIntrinsics camera_;
  std::stop_token stop_;

  mutable std::mutex mutex_;
  std::condition_variable_any cv_;
  std::deque<rosmsg::Image> color_, depth_, instance_, class_;
  std::optional<CameraIntrinsics> K_;
  std::vector<GroundTruthFruit> fruits_;
  bool have_fruits_ = false;
  SourceCounters counters_;
  bool warned_distortion_ = false;

  std::unique_ptr<ros2::Subscription<rosmsg::Image>> color_sub_, depth_sub_, instance_sub_,
      class_sub_;
  std::unique_ptr<ros2::Subscription<rosmsg::CameraInfo>> info_sub_;
  std::unique_ptr<ros2::Subscription<rosmsg::MarkerArray>> fruits_sub_;
};

/// Transform message → RigidTransform as tf2 takes it: rosmsg::FromTransformMsg, refusing also a
/// quaternion whose norm is not within 1e-3 of 1 (tf2's "denormalized quaternion"); the message
/// names `what`.
Result<RigidTransform> ToRigidTransform(const rosmsg::Transform& t, std::string_view what);

}  // namespace avp::live

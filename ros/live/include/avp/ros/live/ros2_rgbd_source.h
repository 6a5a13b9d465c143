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
#include <avp/robot/rgbd_source.h>
#include <avp/ros/dds/node.h>
#include <avp/ros/live/clock.h>
#include <avp/ros/live/tf_listener.h>
#include <avp/ros/msg/camera_topics.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/lens.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::live {

class LiveMoveStream;

/// Where a live camera's frames come from (docs/ros2.md): the topics and frames shared with
/// `avp replay` (ros::msg::CameraTopics: color_topic, depth_topic, camera_info_topic, base_frame,
/// camera_frame, max_pair_skew_ms) and what only a live source needs.
struct CameraTopicsOptions : ros::msg::CameraTopics {
  /// Images with the sensor-data QoS (best effort, as camera drivers publish); false: reliable.
  bool best_effort = true;
  /// A capture waits at most this long for a pair stamped after it was asked for.
  double frame_timeout_s = 5.0;
  /// ... and then at most this long for the transform at the pair's stamp.
  double tf_timeout_s = 1.0;
  /// Frames are used only when stamped at least this long after the capture was asked for
  /// (after the arm arrived): motion blur and rolling shutters settle.
  double settle_s = 0.0;
  /// Simulator labels for the oracle segmenter: PREFIX/instance (16UC1 instance ids),
  /// PREFIX/class (mono8 classes), PREFIX/fruits (MarkerArray); `avp sim ros2` publishes them at
  /// ros::msg::kSimLabelsPrefix ("/avp/sim"). Empty (the default: a real robot has none): not
  /// waited for.
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
  uint64_t refused = 0;     ///< images refused on arrival (encoding, size, step, a bad depth)
  uint64_t pairs_used = 0;  ///< frames captured at rest (the views)
  /// Fusion during motion (StreamMove): frames handed over while the arm moved, dropped because
  /// the map fell behind (more than max_pending waiting, or gone from the queue), and thinned
  /// above the rate.
  uint64_t moving_pairs = 0;
  uint64_t moving_dropped = 0;
  uint64_t moving_skipped = 0;
  std::string last_problem;
};

/// A robot::RgbdSource on ROS 2 topics: colour and aligned depth paired by stamp, the intrinsics
/// from CameraInfo (the depth range from `camera`), and X_WC from the TF buffer at the pair's
/// stamp, base_frame → camera_frame. Images are read as `avp replay` reads them
/// (ros/msg/images.h): colour rgb8, bgr8, rgba8, bgra8, mono8; depth 16UC1 mm, 32FC1 m, with
/// NaN, inf and 0 as "no return" (0) and an image with a negative depth refused.
/// Capture(X_WC, stamp) waits (bounded, and ended by the stop token) for the first pair stamped
/// after it was called. Images are checked on arrival; one refused is counted and named in the
/// errors. Every problem is a status naming the topic and the value: an unsupported encoding, a
/// size or step that does not match, a camera that stops (DeadlineExceeded), TF missing or late.
class Ros2RgbdSource final : public robot::RgbdSource {
 public:
  /// Subscribes and waits (frame_timeout_s) for the first CameraInfo. `tf` is shared with the
  /// arm; `camera` gives the depth range (and a warning when the CameraInfo's size differs).
  static Result<std::unique_ptr<Ros2RgbdSource>> Create(ros::dds::Node& node,
                                                        ros::msg::TfBuffer& tf,
                                                        const CameraTopicsOptions& options,
                                                        const CameraIntrinsics& camera,
                                                        std::stop_token stop = {});
  ~Ros2RgbdSource() override;

  Result<robot::Observation> Capture(const RigidTransform& X_WC, int64_t stamp_ns) override;
  CameraIntrinsics intrinsics() const override;
  /// The pairs stamped from now until End() (the arm arrived), oldest first, at most
  /// request.rate_hz a second; when more than request.max_pending wait, the oldest are dropped
  /// (counted, logged once per move). The poses come from TF at each pair's stamp.
  std::unique_ptr<robot::MoveStream> StreamMove(const robot::MoveStreamRequest& request) override;
  SourceCounters counters() const;

 private:
  friend class LiveMoveStream;
  Ros2RgbdSource(ros::dds::Node& node, ros::msg::TfBuffer& tf, const CameraTopicsOptions& options,
                 const CameraIntrinsics& camera, std::stop_token stop);
  Status Subscribe();
  void OnImage(ros::msg::Image&& msg, bool is_color);
  void OnLabel(ros::msg::Image&& msg, bool is_instance);
  void OnCameraInfo(ros::msg::CameraInfo&& msg);
  void OnFruits(ros::msg::MarkerArray&& msg);
  /// The first pair stamped at or after `not_before_ns`, and with `with_labels` the first whose
  /// colour stamp also has both simulator label images (a frame whose labels were dropped is
  /// passed over, not waited for); call with mutex_ held.
  std::optional<std::pair<size_t, size_t>> FindPair(int64_t not_before_ns, bool with_labels) const;
  /// A colour frame stamped `stamp_ns` leaves the queue while a move is streamed (mutex held).
  void TellTrimmed(int64_t stamp_ns);
  Result<robot::Observation> Assemble(const ros::msg::Image& color, const ros::msg::Image& depth,
                                      std::unique_lock<std::mutex>& lock);

  ros::dds::Node& node_;
  ros::msg::TfBuffer& tf_;
  CameraTopicsOptions options_;
  CameraIntrinsics camera_;
  std::stop_token stop_;

  mutable std::mutex mutex_;
  std::condition_variable_any cv_;
  std::deque<ros::msg::Image> color_, depth_, instance_, class_;
  std::optional<CameraIntrinsics> K_;
  std::vector<GroundTruthFruit> fruits_;
  bool have_fruits_ = false;
  SourceCounters counters_;
  /// Bumped by every image that arrives and every move that ends (wakes a stream's wait).
  uint64_t generation_ = 0;
  /// The move being streamed, told about colour frames that leave the queue unconsumed.
  LiveMoveStream* active_stream_ = nullptr;
  /// The lens of the latest CameraInfo (identity for a rectified camera).
  std::shared_ptr<const ros::msg::Rectifier> rectifier_;

  std::unique_ptr<ros::dds::Subscription<ros::msg::Image>> color_sub_, depth_sub_, instance_sub_,
      class_sub_;
  std::unique_ptr<ros::dds::Subscription<ros::msg::CameraInfo>> info_sub_;
  std::unique_ptr<ros::dds::Subscription<ros::msg::MarkerArray>> fruits_sub_;
};

}  // namespace avp::ros::live

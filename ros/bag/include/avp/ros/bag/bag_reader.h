#pragma once

// Reading an MCAP recording back as a sequence of views to fuse (`avp replay`, docs/recording.md
// "Replay"): avp's own recordings (`avp run --record`: one view per /avp/step with its exact pose,
// masks, simulator labels, run configuration and ground truth) and rosbag2 MCAP files from a real
// robot (sensor_msgs/Image colour + aligned depth, CameraInfo, /tf and /tf_static), its images
// read as `avp live` reads them (ros/msg/images.h) and its transforms in ros::msg::TfBuffer.

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <avp/core/camera.h>
#include <avp/core/options.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/robot/rgbd_source.h>
#include <avp/ros/msg/camera_topics.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::bag {

/// Which topics and frames a bag is read with, and which frames of a real bag are fused. The
/// camera's topics and frames are those `avp live` subscribes to (ros::msg::CameraTopics:
/// color_topic, depth_topic, camera_info_topic, base_frame, camera_frame, tf_topic,
/// tf_static_topic, max_pair_skew_ms, the same keys and defaults).
struct BagReadOptions : ros::msg::CameraTopics {
  /// Simulator label images PREFIX/instance (16UC1 / mono16 ids) and PREFIX/class (mono8
  /// classes), as avp records them and `avp sim ros2` publishes them; empty: none.
  std::string labels_prefix{ros::msg::kSimLabelsPrefix};
  /// TF: the transform at the colour image's stamp is interpolated between the samples of each
  /// /tf edge that bracket it; outside an edge's samples, the nearest one is used when it is at
  /// most this far from the stamp.
  double tf_tolerance_ms = 50.0;
  /// Real bags: fuse at most this many frames per second of bag time (the first pair, then each
  /// first pair at least 1 / rate later); 0 = every pair. avp's own recordings fuse every step.
  double frame_rate_hz = 1.0;
  /// At most this many views (0 = all).
  int max_views = 0;
  /// The views to fuse are decoded in memory (colour, depth, labels, masks: about 3.7 MB per
  /// 640 x 480 view): at most this many megabytes, else ResourceExhausted (a long 30 Hz bag with
  /// frame_rate_hz = 0 would fill the memory).
  double max_decoded_mb = 4096.0;
  /// Ignore the bag's /avp/step messages and read it like a real robot's bag (colour, depth,
  /// CameraInfo and TF only).
  bool as_robot_bag = false;
  /// The depth range of the views' intrinsics (CameraInfo carries none): min and max depth, metres.
  double min_depth_m = CameraIntrinsics{}.min_depth_m;
  double max_depth_m = CameraIntrinsics{}.max_depth_m;
};

/// The fields of BagReadOptions (`avp replay --bag-option KEY=VALUE`; min/max depth come from the
/// run configuration's camera).
const OptionTable<BagReadOptions>& BagReadOptionTable();

/// One view to fuse.
struct BagView {
  /// avp recordings: the step's view number; real bags: the index of the colour/depth pair.
  int index = 0;
  /// The frame (colour, depth in metres, intrinsics, X_WC in the base frame, stamp, frame id)
  /// and, when the bag has them, the simulator labels (without fruits: the replay adds the
  /// ground truth's).
  robot::Observation observation;
  /// The masks the recording's segmenter produced (avp recordings), exactly.
  std::optional<Segmentation> segmentation;
  /// The arm's joints when recorded (avp recordings: the step's q), else empty.
  Eigen::VectorXd q;
  /// avp recordings: the /avp/step JSON as recorded (metrics, candidates, ...); null otherwise.
  nlohmann::json step;
};

/// A bag read for replay.
struct Bag {
  std::filesystem::path path;
  /// True for an avp recording (it has /avp/step messages and was not read as_robot_bag).
  bool avp_recording = false;
  /// The MCAP metadata record "avp" (command, scene, seed, planner, segmenter, run_config ...);
  /// empty when absent.
  std::map<std::string, std::string> avp_metadata;
  /// The ground_truth.json attachment (eval::GroundTruthToJson's form, read with
  /// eval::GroundTruthFromJson), when the bag has one.
  std::optional<nlohmann::json> ground_truth;
  std::vector<BagView> views;
  /// OK, or the damage the streaming reader found (naming the byte offset): `views` then holds
  /// what came before it.
  Status damage;
  uint64_t intact_bytes = 0;
  uint64_t file_bytes = 0;
  /// Real bags: colour/depth pairs found, and those left out by frame_rate_hz / max_views.
  size_t pairs = 0;
  size_t pairs_thinned = 0;
  /// Pairs or steps that could not be used (no transform, no CameraInfo, a bad image), each
  /// "stamp S: why"; the first few are kept, `skipped_count` counts them all.
  std::vector<std::string> skipped;
  size_t skipped_count = 0;
  /// Messages per topic in the intact part.
  std::map<std::string, uint64_t> topic_messages;
};

/// Reads `path` (ros::mcap::ReadStreaming: a damaged file gives the views before the damage, and
/// `damage` says where). Errors: the file cannot be read at all or holds no usable view (the
/// error names why: a missing topic, listing the bag's topics; no transform between the frames,
/// listing the TF frames; ...), invalid options, a ground_truth.json that is not JSON.
Result<Bag> ReadBag(const std::filesystem::path& path, const BagReadOptions& options = {});

}  // namespace avp::ros::bag

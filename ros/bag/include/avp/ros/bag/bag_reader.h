#pragma once

// Reading a bag back as a sequence of views to fuse (`avp replay`, docs/recording.md "Replay" and
// "Replaying a real robot's bag"): avp's own recordings (`avp run --record`: one view per
// /avp/step with its exact pose, masks, simulator labels, run configuration and ground truth) and
// a robot's rosbag2 bags, MCAP or SQLite 3, a file or a (split) bag folder (message_source.h):
// sensor_msgs/Image colour + aligned depth, CameraInfo (its lens rectified: ros/msg/lens.h), /tf
// and /tf_static (or /joint_states through the arm's URDF), read as `avp live` reads them
// (ros/msg/images.h), message by message in bounded memory.

#include <concepts>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <avp/core/camera.h>
#include <avp/core/options.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/robot/rgbd_source.h>
#include <avp/ros/bag/frame_selection.h>
#include <avp/ros/bag/message_source.h>
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
  /// When the bag's TF has no transform from the base to the camera frame: the arm's joints
  /// (sensor_msgs/JointState, interpolated at the image's stamp) through the arm's URDF give the
  /// camera pose (robot::ArmModel::CameraPose; the base frame is then the arm's base link).
  std::string joint_states_topic = "/joint_states";
  /// The arm (its YAML: URDF, base and tip links, camera mount); empty: avp's default arm.
  std::string arm;
  /// Lens distortion (CameraInfo's distortion_model and D): "rectify" the images (colour
  /// bilinear, depth nearest: ros::msg::Rectifier) or "ignore" it (fuse raw images as if
  /// rectified: for comparisons only).
  std::string distortion = "rectify";
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
  /// avp recordings: a frame fused while the arm moved (kMovingFrameTopic, whose JSON is `step`),
  /// not a view: `index` is the view the move left (0-based), `moving_k` its number along the move.
  bool moving = false;
  int moving_k = 0;
};

/// What became of a bag's frames: each colour/depth pair (robot bags) or step (avp recordings)
/// is fused, left out by the FrameSelection (counted by reason), or skipped because it could not
/// be used (no transform, no CameraInfo, a bad image: counted by reason, and named).
struct FrameAccount {
  /// Colour/depth pairs found (robot bags), or steps (avp recordings).
  size_t pairs = 0;
  size_t fused = 0;
  /// avp recordings: frames fused while the arm moved (kMovingFrameTopic), returned between the
  /// views (not in `pairs` or `fused`).
  size_t moving_frames = 0;
  /// Reason -> pairs: "before start_s", "after end_s", "moving", "every_nth", "fps",
  /// "max_views".
  std::map<std::string, size_t> left_out;
  /// Reason -> frames: "no transform", "no CameraInfo", "bad image", "no depth within
  /// max_pair_skew_ms", ...
  std::map<std::string, size_t> skipped_by_reason;
  /// The first skipped frames, each "stamp S: why"; skipped_count() counts them all.
  std::vector<std::string> skipped;
  /// One entry per fused or skipped frame (the first kMaxFrames): index, stamp, what became of
  /// it ("fused" or the reason it was skipped).
  struct Frame {
    int index = 0;
    int64_t stamp_ns = 0;
    std::string what;
  };
  std::vector<Frame> frames;
  static constexpr size_t kMaxFrames = 10000;

  size_t left_out_count() const;
  size_t skipped_count() const;
};

/// A bag opened for replay, read view by view in bounded memory (its messages streamed in
/// log-time order: ros::bag::OpenBag). Robot bags: colour and depth paired by stamp (within
/// max_pair_skew_ms), the camera pose from TF interpolated at the colour image's stamp (or the
/// arm's joints through its URDF), the intrinsics from the CameraInfo nearest in time, the lens
/// distortion rectified; the pairs chosen by the FrameSelection. avp recordings: every /avp/step
/// with its images, masks, labels and exact pose.
class BagReader {
 public:
  /// Opens `path` (a file or a bag folder) and reads what is known before the first message.
  /// Errors: invalid options, a path that is no bag (saying what it is), a bag whose index
  /// lists no colour topic (listing its topics), a ground_truth.json that is not JSON.
  static Result<std::unique_ptr<BagReader>> Open(const std::filesystem::path& path,
                                                 const BagReadOptions& options = {});
  ~BagReader();
  BagReader(const BagReader&) = delete;
  BagReader& operator=(const BagReader&) = delete;

  /// Which frames to fuse; before the first Next. InvalidArgument naming a bad value.
  Status SetSelection(const FrameSelection& selection);

  /// The next view; nullopt at the end of the bag (or of its intact part: damage()). Errors: a
  /// topic of the wrong type or encoding, and, at the end, a bag that gave no view at all (why:
  /// a missing topic, listing the bag's topics; no transform, listing the TF frames; ...).
  Result<std::optional<BagView>> Next();

  const std::filesystem::path& path() const;
  /// Format ("MCAP (indexed, zstd chunks)", "rosbag2 SQLite 3", ...), files, sizes.
  const BagInfo& info() const;
  /// True for an avp recording (its "avp" metadata or /avp/step topic; not read as_robot_bag).
  bool avp_recording() const;
  /// The MCAP metadata record "avp" (command, scene, seed, planner, segmenter, run_config ...);
  /// empty when absent.
  const std::map<std::string, std::string>& avp_metadata() const;
  /// The ground_truth.json attachment (eval::GroundTruthToJson's form), when the bag has one.
  const std::optional<nlohmann::json>& ground_truth() const;
  /// Whether the bag's topics (as far as known) include `topic`.
  bool HasTopic(std::string_view topic) const;
  /// Whether the views carry the simulator's labels: labels_prefix is set and the bag has
  /// PREFIX/instance (as far as known).
  bool HasSimulatorLabels() const;
  /// OK, or the damage met (naming the file and offset): the views before it were returned.
  const Status& damage() const;
  uint64_t bytes_read() const;
  const FrameAccount& account() const;
  /// Messages per topic read so far.
  const std::map<std::string, uint64_t>& topic_messages() const;

  struct Impl;

 private:
  explicit BagReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// A whole bag read at once (tests and small bags: every view is kept in memory).
struct Bag {
  std::filesystem::path path;
  BagInfo info;
  bool avp_recording = false;
  std::map<std::string, std::string> avp_metadata;
  std::optional<nlohmann::json> ground_truth;
  std::vector<BagView> views;
  Status damage;
  FrameAccount account;
  std::map<std::string, uint64_t> topic_messages;
};

/// Every view of `path` (BagReader). Errors: those of Open and Next.
Result<Bag> ReadBag(const std::filesystem::path& path, const BagReadOptions& options = {},
                    const FrameSelection& selection = {});

}  // namespace avp::ros::bag

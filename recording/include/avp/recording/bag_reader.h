#pragma once

// Reading an MCAP recording back as a sequence of views to fuse (`avp replay`, docs/recording.md
// "Replay"): avp's own recordings (`avp run --record`: one view per /avp/step with its exact pose,
// masks, simulator labels, run configuration and ground truth) and rosbag2 MCAP files from a real
// robot (sensor_msgs/Image colour + aligned depth, CameraInfo, /tf and /tf_static).

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
#include <avp/rosmsg/messages.h>

namespace avp::recording {

/// Which topics and frames a bag is read with, and which frames of a real bag are fused.
/// The topic and frame defaults are the seed's RealSense names (as live::CameraTopicsOptions).
struct BagReadOptions {
  std::string color_topic = "/camera/camera/color/image_raw";
  std::string depth_topic = "/camera/camera/aligned_depth_to_color/image_raw";
  std::string camera_info_topic = "/camera/camera/color/camera_info";
  std::string tf_topic = "/tf";
  std::string tf_static_topic = "/tf_static";
  /// The map's frame (the arm's base) and the camera's optical frame (empty: the colour image's
  /// header.frame_id).
  std::string base_frame = "igus_rebel_base_link";
  std::string camera_frame = "camera_color_optical_frame";
  /// Simulator label images PREFIX/instance (16UC1 / mono16 ids) and PREFIX/class (mono8
  /// classes), as avp records them and `avp sim ros2` publishes them; empty: none.
  std::string labels_prefix = "/avp/sim";
  /// A colour and a depth image form a pair when their stamps differ by at most this.
  double max_pair_skew_ms = 5.0;
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

/// Reads `path` (mcap::ReadStreaming: a damaged file gives the views before the damage, and
/// `damage` says where). Errors: the file cannot be read at all or holds no usable view (the
/// error names why: a missing topic, listing the bag's topics; no transform between the frames,
/// listing the TF frames; ...), invalid options, a ground_truth.json that is not JSON.
Result<Bag> ReadBag(const std::filesystem::path& path, const BagReadOptions& options = {});

// ---- The pieces, for tests and other readers --------------------------------------------------

/// Colour from a sensor_msgs/Image: rgb8, bgr8, rgba8, bgra8 or mono8 (alpha dropped, grey
/// copied to the three channels). InvalidArgument naming the topic and the value: an unknown
/// encoding, a size outside 1..16384, a step shorter than a row, data whose length is not step x
/// height.
Result<ImageRgb8> ColorFromImageMsg(const rosmsg::Image& msg, std::string_view topic);

/// Depth in metres from a sensor_msgs/Image: 32FC1 (metres, copied bit for bit; NaN / +-inf are
/// "no return" as REP 118 has it and stay so) or 16UC1 / mono16 (millimetres, 0 = no return);
/// either byte order. InvalidArgument as ColorFromImageMsg, and for a negative or subnormal
/// 32FC1 depth (naming the pixel and the value).
Result<DepthImage> DepthFromImageMsg(const rosmsg::Image& msg, std::string_view topic);

/// Intrinsics from a CameraInfo (K's fx, fy, cx, cy; the size), with the given depth range.
/// InvalidArgument naming the values: a size outside 1..16384, invalid intrinsics, binning or a
/// region of interest.
Result<CameraIntrinsics> IntrinsicsFromCameraInfoMsg(const rosmsg::CameraInfo& info,
                                                     double min_depth_m, double max_depth_m);

/// The transform tree of a whole bag (/tf and /tf_static), for lookups at any stamp: each edge
/// parent -> child keeps all its samples; a static edge holds at every time.
class TfTree {
 public:
  /// Frame names are kept without a leading '/' (as tf2 does), in Add and in Lookup.
  /// Adds one TransformStamped. InvalidArgument naming the frames and values: an empty frame,
  /// parent == child, a non-finite value, a quaternion whose norm is not 1 (within 1e-3), a child
  /// that already has another parent.
  Status Add(const rosmsg::TransformStamped& t, bool is_static);
  /// X_TS, the pose of frame `source` in frame `target` at `stamp_ns`: each dynamic edge of the
  /// chain interpolated between the samples that bracket the stamp (linear in translation, slerp
  /// in rotation), or its nearest sample when that is within `tolerance_ns`. NotFound naming the
  /// frame (and the known frames) when a frame is unknown or the two are not connected;
  /// OutOfRange naming the edge and the gap when the stamp is too far from an edge's samples.
  Result<RigidTransform> Lookup(const std::string& target, const std::string& source,
                                int64_t stamp_ns, int64_t tolerance_ns) const;
  /// Known frames, sorted.
  std::vector<std::string> Frames() const;
  bool empty() const { return edges_.empty(); }

 private:
  struct Sample {
    int64_t stamp_ns;
    RigidTransform X_PC;
  };
  struct Edge {
    std::string parent;
    bool is_static = false;
    std::vector<Sample> samples;  ///< by stamp
  };
  Result<RigidTransform> EdgeAt(const std::string& child, const Edge& edge, int64_t stamp_ns,
                                int64_t tolerance_ns) const;
  std::vector<std::string> ChainToRoot(const std::string& frame) const;

  std::map<std::string, Edge, std::less<>> edges_;  ///< by child frame
};

}  // namespace avp::recording

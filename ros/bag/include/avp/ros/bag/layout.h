#pragma once

// The topics, types and records of avp's own MCAP recordings (`avp run --record`, `avp live
// --record`, `avp bench --record`): what ros::bag::McapRecorder writes and what the replay reads.
// Profile `ros2`: `ros2msg` schemas, `cdr` payloads, `offered_qos_profiles` and `topic_type_hash`
// (Jazzy's RIHS01 type hash) per channel, as rosbag2 writes them. Every
// message of a fused view has log_time = publish_time = header stamp = the capture's stamp_ns.
// docs/recording.md has the table.

#include <string_view>

namespace avp::ros::bag {

// ---- Per fused view -----------------------------------------------------------------------------

/// sensor_msgs/msg/Image, rgb8: the colour image (the RealSense driver's topic).
inline constexpr std::string_view kColorTopic = "/camera/camera/color/image_raw";
/// sensor_msgs/msg/Image, 32FC1: the aligned z-depth in metres, the frame's floats bit-exact
/// (a replay also reads a RealSense bag's 16UC1 millimetres).
inline constexpr std::string_view kDepthTopic = "/camera/camera/aligned_depth_to_color/image_raw";
/// sensor_msgs/msg/CameraInfo: K (no distortion; plumb_bob with zero coefficients).
inline constexpr std::string_view kCameraInfoTopic = "/camera/camera/color/camera_info";
/// tf2_msgs/msg/TFMessage: base frame -> the frame's frame_id (the camera optical frame) = X_WC.
/// The quaternion does not round-trip bit-exactly: the exact pose is the step's "X_WC".
inline constexpr std::string_view kTfTopic = "/tf";
/// sensor_msgs/msg/JointState: the arm's joints at the view (the arm model's joint names).
inline constexpr std::string_view kJointStatesTopic = "/joint_states";
/// sensor_msgs/msg/Image, mono16: 0 = no instance, i + 1 = instance i of the segmentation
/// (where masks overlap, the higher score wins; equal scores: the earlier instance).
inline constexpr std::string_view kInstanceImageTopic = "/avp/segmentation/instance_image";
/// std_msgs/msg/String: the segmentation as JSON, exact (InstancesToJson): width, height and per
/// instance its class, label, score, mask score, box and mask as COCO RLE.
inline constexpr std::string_view kInstancesTopic = "/avp/segmentation/instances";
/// sensor_msgs/msg/Image 16UC1 (instance ids) and mono8 (SemanticClass ids): the simulator's
/// labels, when the source has them (so a replay can rerun the oracle segmenter).
inline constexpr std::string_view kSimInstanceTopic = "/avp/sim/instance";
inline constexpr std::string_view kSimClassTopic = "/avp/sim/class";
/// visualization_msgs/msg/MarkerArray: every ranked candidate of the plan after the view (an
/// arrow along its optical axis coloured by utility, viridis), the chosen one magenta and
/// longer with a text of its utility, gain and cost.
inline constexpr std::string_view kCandidatesTopic = "/avp/planning/candidates";
/// octomap_msgs/msg/Octomap: the map after integrating the view (binary, id "OcTree").
inline constexpr std::string_view kMapTopic = "/avp/map";
/// std_msgs/msg/String: the step as JSON (StepToJson): view, X_WC exact, q, statuses, counts,
/// metrics, every ranked candidate, the chosen rank, times.
inline constexpr std::string_view kStepTopic = "/avp/step";

// ---- Per frame fused while the arm moved (fusion during motion) ---------------------------------

/// std_msgs/msg/String at the frame's stamp, beside its colour, depth, CameraInfo, TF, simulator
/// labels and (when it was segmented) masks: {"view": the view the move left (1-based), "k": the
/// frame's number along the move, "stamp_ns", "segmented", "X_WC": exact}. No /avp/step, map or
/// candidates: a replay fuses it as a moving frame between the two views.
inline constexpr std::string_view kMovingFrameTopic = "/avp/moving_frame";

// ---- Encodings ----------------------------------------------------------------------------------

inline constexpr std::string_view kColorEncoding = "rgb8";
inline constexpr std::string_view kDepthEncoding = "32FC1";
inline constexpr std::string_view kInstanceImageEncoding = "mono16";
inline constexpr std::string_view kSimInstanceEncoding = "16UC1";
inline constexpr std::string_view kSimClassEncoding = "mono8";

// ---- Records outside the topics -----------------------------------------------------------------

/// The MCAP Metadata record of the run. Keys: command, revision, scene, seed, planner,
/// segmenter, prompt, base_frame, run_config (the resolved run configuration YAML, as `avp run
/// --print-config` prints it), views (the episode's budget).
inline constexpr std::string_view kMetadataName = "avp";
/// The MCAP Attachment holding the ground truth (eval::GroundTruthToJson), when the run has one.
inline constexpr std::string_view kGroundTruthAttachment = "ground_truth.json";
inline constexpr std::string_view kGroundTruthMediaType = "application/json";

/// The frame the TF and the markers are in (as `avp live`'s default base frame).
inline constexpr std::string_view kDefaultBaseFrame = "igus_rebel_base_link";

}  // namespace avp::ros::bag

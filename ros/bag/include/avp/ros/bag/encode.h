#pragma once

// What McapRecorder writes for one fused view, as functions: the ROS 2 messages of the layout
// (layout.h) built from avp's segmentations and plans, and the exact JSON of the segmentation and
// of the step, with their inverses for the replay.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include <avp/core/image.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/mapping/voxel_grid.h>
#include <avp/pipeline/episode.h>
#include <avp/planning/view_planner.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::bag {

// The images and CameraInfo of a view are written and read by ros/msg's conversions
// (ros/msg/images.h: ToColorImage, ToDepthImage with 32FC1, ToInstanceIdImage, ToClassIdImage,
// ToCameraInfo and ColorFromImage, DepthFromImage, ...), as `avp sim ros2` publishes them and
// `avp live` reads them.

/// 0 = no instance, i + 1 = instance i; where masks overlap the higher confidence wins (equal:
/// the earlier instance).
InstanceImage InstanceIdImage(const Segmentation& segmentation);

/// {"width", "height", "instances": [{"class", "label", "score", "mask_score", "box": [x0, y0, x1,
/// y1] | null, "mask": {"size": [height, width], "counts": [COCO RLE, column-major]}}], "timings":
/// [{"stage", "ms"}]}; floats exact (they round-trip through JSON's doubles).
nlohmann::json InstancesToJson(const Segmentation& segmentation);
/// The inverse: masks are 255 where set. Errors name the field and the instance.
Result<Segmentation> InstancesFromJson(const nlohmann::json& j);

/// A pose as 12 numbers, the 3x4 [R | p] row-major (doubles exact in JSON).
nlohmann::json PoseToJson(const RigidTransform& X);
/// The inverse; InvalidArgument unless 12 finite numbers with R a rotation (1e-6).
Result<RigidTransform> PoseFromJson(const nlohmann::json& j);

/// The step as /avp/step carries it: {"view", "views_total", "stamp_ns", "X_WC" (PoseToJson), "q",
/// "capture_status", "segment_status", "integrate_status", "plan_status", "move_status" ("" when
/// OK), "masks", "integration": {...}, "known_voxels", "occupied_voxels", "target_voxels",
/// "instances", "known_delta", "target_delta", "metrics": [[name, value|null]], "planned",
/// "candidates_generated", "candidates_reachable", "candidates": every ranked candidate of `plan`
/// (the step's top candidates when there is no plan) [{"rank", "X_WC", "q", "reachable", "gain",
/// "cost", "utility", "source"}], "chosen_rank", "refused_moves", "joint_path_length", "times":
/// {stage: ms}}.
nlohmann::json StepToJson(const pipeline::StepRecord& step, const planning::PlanResult* plan,
                          int64_t stamp_ns);

/// The grid as octomap_msgs/Octomap's binary data: byte for byte what liboctomap writes for it
/// (mapping::OctomapBinaryMessageData: an OcTree of every known voxel, maximum likelihood,
/// pruned, OcTree::writeBinaryData), built straight from the grid's 8^3 blocks without a tree,
/// several times faster. OutOfRange naming the first voxel outside OctoMap's 16-bit keys.
Result<std::string> OctomapBinaryTree(const mapping::OccupancyGrid& grid);

/// The candidates as markers in `header`'s frame: a DELETEALL, then one arrow per candidate along
/// its optical axis coloured by utility (viridis from the lowest to the highest), the chosen one
/// (rank `chosen_rank`, -1: none) magenta and longer with a text (rank, utility, gain, cost).
ros::msg::MarkerArray CandidateMarkers(const std::vector<planning::ViewCandidate>& ranked,
                                       int chosen_rank, int view, const ros::msg::Header& header);

}  // namespace avp::ros::bag

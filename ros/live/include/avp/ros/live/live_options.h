#pragma once

#include <string>
#include <vector>

#include <avp/core/box.h>
#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/ros/dds/node.h>
#include <avp/ros/live/ros2_arm.h>
#include <avp/ros/live/ros2_rgbd_source.h>
#include <avp/ros/live/rviz_publisher.h>

namespace avp::ros::live {

/// The `live:` section of `avp live --config live.yaml` (docs/ros2.md): the node, the camera and
/// arm topics, RViz, the region of interest and the time limits. The rest of the file is the run
/// configuration of `avp run` (planner, segmenter, map, episode).
struct LiveOptions {
  std::string node_name = "avp";
  std::string node_namespace = "/";
  /// -1: ROS_DOMAIN_ID (else 0).
  int domain_id = -1;
  /// The peers' ROS 2 distribution: the GID size in ros_discovery_info (`ros2 node list`).
  ros::msg::RosDistro distro = ros::msg::RosDistro::kHumble;
  CameraTopicsOptions camera;
  ArmTopicsOptions arm;
  RvizOptions rviz;
  /// The plant's region of interest in the base frame (min and max corners, metres); required
  /// unless the run configuration names a scenario or scene (then its plant bounds, inflated by
  /// roi_margin_m, as in avp run).
  std::vector<double> roi_min_m;
  std::vector<double> roi_max_m;
  /// The whole episode may take at most this long (0: no limit); then it stops as interrupted
  /// and its results are written.
  double timeout_s = 0.0;

  /// The ROI as a box when both corners are given.
  Result<Box3> Roi() const;
};
const OptionTable<LiveOptions>& LiveOptionTable();

ros::dds::NodeOptions NodeOptionsOf(const LiveOptions& options);

}  // namespace avp::ros::live

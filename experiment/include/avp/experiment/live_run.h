#pragma once

// `avp live`: one episode of the active-vision loop on a ROS 2 robot into a run folder, beside
// `avp run`'s RunToFolder (docs/ros2.md). Built with AVP_WITH_ROS2.

#include <functional>
#include <stop_token>
#include <string>

#include <avp/core/status.h>
#include <avp/experiment/registries.h>
#include <avp/experiment/run_config.h>
#include <avp/experiment/run_folder.h>
#include <avp/ros/live/live_options.h>

namespace avp::experiment {

/// What a live run reports before the robot has answered: the node's name and domain, and the
/// topics it waits for.
struct LiveWaiting {
  std::string node;
  int domain_id = 0;
  std::string camera_info_topic;
  std::string joint_states_topic;
};

/// Runs one episode of `config` on the ROS 2 robot that `live` describes: frames from the
/// camera's topics (ros::live::Ros2RgbdSource), the arm through JointTrajectory goals and
/// /joint_states (ros::live::Ros2Arm), X_WC from /tf, the map and the planner's views for RViz
/// (ros::live::RvizPublisher, when live.rviz.enabled). The plant is config's scene when it names
/// one (its ROI, and the ground truth the steps are scored against), else live.roi without metrics.
/// The run folder is RunEpisodeToFolder's, checked before anything waits for the robot
/// (record.json's "live" section: the options, the node, the topics' counters). A stop requested
/// through `stop` (Ctrl-C, live.timeout_s, a result that cannot be written) ends the episode with
/// its results written; `on_waiting` is called once the node is up. Errors: a folder that holds
/// results (without folder.force), the scene's, the ground truth's, the node's and the topics'.
Result<RunSummary> RunLiveToFolder(const CheckedRunConfig& config,
                                   const ros::live::LiveOptions& live,
                                   const RunFolderOptions& folder, std::stop_source stop,
                                   const std::function<void(const LiveWaiting&)>& on_waiting = {});

}  // namespace avp::experiment

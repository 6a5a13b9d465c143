#include <chrono>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include <avp/experiment/episode_runner.h>
#include <avp/experiment/live_run.h>
#include <avp/experiment/output_folder.h>
#include <avp/io/options_yaml.h>
#include <avp/robot/arm_model.h>
#include <avp/ros/live/ros2_arm.h>
#include <avp/ros/live/ros2_rgbd_source.h>
#include <avp/ros/live/rviz_publisher.h>
#include <avp/ros/live/tf_listener.h>

namespace avp::experiment {

namespace {

/// The plant of a live run, when the configuration names one: the scene, its ground truth and
/// the seconds that took; the ROI either way.
struct LivePlant {
  std::optional<sim::Scene> scene;
  std::optional<eval::GroundTruth> gt;
  double gt_seconds = 0.0;
  Box3 roi;
};

Result<LivePlant> PlantOf(const RunConfig& config, const Registries& registries,
                          const ros::live::LiveOptions& live) {
  LivePlant plant;
  if (config.scenario.empty() && config.scene_file.empty()) {
    AVP_ASSIGN_OR_RETURN(plant.roi, live.Roi());
    return plant;
  }
  AVP_ASSIGN_OR_RETURN(plant.scene, LoadScene(config, registries));
  const auto t0 = std::chrono::steady_clock::now();
  AVP_ASSIGN_OR_RETURN(plant.gt, GroundTruthFor(config, *plant.scene));
  plant.gt_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  plant.roi = plant.scene->plant_bounds.Inflated(config.roi_margin_m);
  return plant;
}

/// The robot's side on ROS 2: the node, TF, the arm, the camera and the RViz publisher.
struct LiveRobot {
  std::unique_ptr<ros::dds::Node> node;
  ros::msg::TfBuffer tf;
  std::unique_ptr<ros::live::TfListener> listener;
  std::unique_ptr<ros::live::Ros2Arm> arm;
  std::unique_ptr<ros::live::Ros2RgbdSource> source;
  std::unique_ptr<ros::live::RvizPublisher> rviz;
};

Status Connect(const RunConfig& config, const ros::live::LiveOptions& live,
               const std::stop_token& stop,
               const std::function<void(const LiveWaiting&)>& on_waiting, LiveRobot& robot) {
  AVP_ASSIGN_OR_RETURN(robot.node, ros::dds::Node::Create(ros::live::NodeOptionsOf(live)));
  AVP_ASSIGN_OR_RETURN(robot.listener,
                       ros::live::TfListener::Create(*robot.node, robot.tf, live.camera.tf_topic,
                                                     live.camera.tf_static_topic));
  if (on_waiting) {
    on_waiting({robot.node->fully_qualified_name(), robot.node->domain_id(),
                live.camera.camera_info_topic, live.arm.joint_states_topic});
  }
  AVP_ASSIGN_OR_RETURN(const robot::ArmModel model, robot::LoadDefaultArm());
  AVP_ASSIGN_OR_RETURN(robot.arm,
                       ros::live::Ros2Arm::Create(*robot.node, robot.tf, model, live.arm, stop));
  AVP_ASSIGN_OR_RETURN(robot.source, ros::live::Ros2RgbdSource::Create(
                                         *robot.node, robot.tf, live.camera, config.camera, stop));
  if (live.rviz.enabled) {
    AVP_ASSIGN_OR_RETURN(robot.rviz, ros::live::RvizPublisher::Create(*robot.node, live.rviz,
                                                                      config.episode.target_class));
  }
  return Status::Ok();
}

/// record.json's "live" section: the options, the node, and what each topic delivered.
nlohmann::json LiveRecord(const ros::live::LiveOptions& o, const LiveRobot& robot) {
  const ros::live::SourceCounters c = robot.source->counters();
  return {
      {"options", io::OptionsToJson(ros::live::LiveOptionTable().Values(o),
                                    ros::live::LiveOptionTable().Info(o))},
      {"node", robot.node->fully_qualified_name()},
      {"domain_id", robot.node->domain_id()},
      {"camera",
       {{"color", c.color},
        {"depth", c.depth},
        {"camera_info", c.camera_info},
        {"refused", c.refused},
        {"pairs_used", c.pairs_used},
        {"moving_pairs", c.moving_pairs},
        {"moving_dropped", c.moving_dropped},
        {"moving_skipped", c.moving_skipped},
        {"last_problem", c.last_problem}}},
      {"arm",
       {{"joint_states", robot.arm->joint_states_received()},
        {"goals_sent", robot.arm->goals_sent()}}},
      {"tf", {{"received", robot.listener->received()}, {"refused", robot.listener->refused()}}},
      {"rviz_messages", robot.rviz != nullptr ? robot.rviz->published() : 0}};
}

}  // namespace

Result<RunSummary> RunLiveToFolder(const CheckedRunConfig& checked,
                                   const ros::live::LiveOptions& live,
                                   const RunFolderOptions& folder, std::stop_source stop,
                                   const std::function<void(const LiveWaiting&)>& on_waiting) {
  const RunConfig& config = *checked;
  // A run folder that holds results is refused before the robot is waited for.
  AVP_RETURN_IF_ERROR(CheckOutputFolder(folder.out_dir, RunFolderKind(), folder.force));
  AVP_ASSIGN_OR_RETURN(const LivePlant plant, PlantOf(config, checked.registries(), live));
  LiveRobot robot;
  AVP_RETURN_IF_ERROR(Connect(config, live, stop.get_token(), on_waiting, robot));

  FolderRun run;
  run.command = "avp live";
  run.scene_name = plant.scene ? plant.scene->name : "live";
  run.scene_description = plant.scene ? plant.scene->description : "a ROS 2 robot";
  run.gt = plant.gt ? &*plant.gt : nullptr;
  run.gt_seconds = plant.gt_seconds;
  run.extra = [&] { return nlohmann::json{{"live", LiveRecord(live, robot)}}; };
  const RobotSide side{robot.source.get(), robot.arm.get(), stop.get_token()};
  run.run = [&](const std::vector<pipeline::EpisodeObserver*>& observers,
                std::unique_ptr<mapping::SemanticMap>* map, std::stop_token write_failed) {
    // A result that cannot be written stops the robot's episode like Ctrl-C does.
    const std::stop_callback forward(write_failed, [&] { stop.request_stop(); });
    const EpisodeTruth truth{plant.scene ? &*plant.scene : nullptr,
                             plant.gt ? &*plant.gt : nullptr};
    return RunEpisodeWithRobot(checked, side, plant.roi, truth, observers, map);
  };
  RunFolderOptions options = folder;
  options.record_base_frame = live.camera.base_frame;
  std::vector<pipeline::EpisodeObserver*> observers;
  if (robot.rviz) observers.push_back(robot.rviz.get());
  return RunEpisodeToFolder(checked, options, run, observers);
}

}  // namespace avp::experiment

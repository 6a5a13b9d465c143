// avp live: the active-vision loop on a ROS 2 robot (docs/ros2.md): frames from the camera's
// topics, the arm through JointTrajectory goals and /joint_states, the map and the planner's
// views published for RViz; the same run folder as avp run. Ctrl-C or live.timeout_s stop it with
// its results written.
#include <chrono>
#include <cstdio>
#include <memory>
#include <stop_token>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/experiment/episode_runner.h>
#include <avp/experiment/output_folder.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/options_yaml.h>
#include <avp/live/live_options.h>
#include <avp/live/ros2_arm.h>
#include <avp/live/ros2_rgbd_source.h>
#include <avp/live/rviz_publisher.h>
#include <avp/live/tf_listener.h>
#include <avp/robot/arm_model.h>

#include "cli_common.h"
#include "ros2_cli.h"
#include "run_cli.h"

namespace avp::apps {

namespace {

struct LiveCli {
  RunCli run;
  std::vector<std::string> live_options;
};

nlohmann::json LiveRecord(const live::LiveOptions& o, const ros2::Node& node,
                          const live::Ros2RgbdSource& source, const live::Ros2Arm& arm,
                          const live::TfListener& tf, const live::RvizPublisher* rviz) {
  const live::SourceCounters c = source.counters();
  return {
      {"options",
       io::OptionsToJson(live::LiveOptionTable().Values(o), live::LiveOptionTable().Info(o))},
      {"node", node.fully_qualified_name()},
      {"domain_id", node.domain_id()},
      {"camera",
       {{"color", c.color},
        {"depth", c.depth},
        {"camera_info", c.camera_info},
        {"refused", c.refused},
        {"pairs_used", c.pairs_used},
        {"last_problem", c.last_problem}}},
      {"arm", {{"joint_states", arm.joint_states_received()}, {"goals_sent", arm.goals_sent()}}},
      {"tf", {{"received", tf.received()}, {"refused", tf.refused()}}},
      {"rviz_messages", rviz != nullptr ? rviz->published() : 0}};
}

int Live(const CLI::App& cmd, const LiveCli& cli, const experiment::Registries& registries) {
  YAML::Node section;
  const Result<experiment::RunConfig> config = ResolveConfig(
      cmd, cli.run, registries, {.name = "live", .node = &section, .default_scene = false});
  if (!config.ok()) return Failed("live", config.status());
  const Result<live::LiveOptions> options =
      ResolveSectionOptions(live::LiveOptionTable(), section, cli.live_options,
                            cli.run.config_file + ": live", "live option");
  if (!options.ok()) return Failed("live", options.status());
  if (cli.run.print_config) {
    Result<YAML::Node> yaml = experiment::RunConfigToYaml(*config, registries);
    if (!yaml.ok()) return Failed("live", yaml.status());
    (*yaml)["live"] = io::OptionsToYaml(live::LiveOptionTable().Values(*options),
                                        live::LiveOptionTable().Info(*options));
    std::fputs(io::YamlText(*yaml).c_str(), stdout);
    return 0;
  }

  // A run folder that holds results is refused before the robot is waited for.
  if (const Status s =
          experiment::CheckOutputFolder(cli.run.out, experiment::RunFolderKind(), cli.run.force);
      !s.ok()) {
    return Failed("live", s);
  }
  // The plant, when named: its ROI and the ground truth the steps are scored against.
  std::optional<sim::Scene> scene;
  std::optional<eval::GroundTruth> gt;
  double gt_s = 0.0;
  Box3 roi;
  if (!config->scenario.empty() || !config->scene_file.empty()) {
    Result<sim::Scene> s = experiment::LoadScene(*config, registries);
    if (!s.ok()) return Failed("live", s.status());
    scene = std::move(*s);
    const auto t0 = std::chrono::steady_clock::now();
    Result<eval::GroundTruth> g = experiment::GroundTruthFor(*config, *scene);
    if (!g.ok()) return Failed("live", g.status());
    gt = std::move(*g);
    gt_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    roi = scene->plant_bounds.Inflated(config->roi_margin_m);
  } else {
    Result<Box3> r = options->Roi();
    if (!r.ok()) return Failed("live", r.status());
    roi = *r;
  }

  std::stop_source stop;
  StopOnSignal stopper(stop, options->timeout_s,
                       "avp live: interrupted: finishing the step and saving results");
  Result<std::unique_ptr<ros2::Node>> node = ros2::Node::Create(live::NodeOptionsOf(*options));
  if (!node.ok()) return Failed("live", node.status());
  live::TfBuffer tf;
  Result<std::unique_ptr<live::TfListener>> listener = live::TfListener::Create(**node, tf);
  if (!listener.ok()) return Failed("live", listener.status());
  std::printf("avp live: node %s on ROS_DOMAIN_ID %d; waiting for %s and %s\n",
              (*node)->fully_qualified_name().c_str(), (*node)->domain_id(),
              options->camera.camera_info_topic.c_str(), options->arm.joint_states_topic.c_str());
  std::fflush(stdout);
  Result<robot::ArmModel> model = robot::LoadDefaultArm();
  if (!model.ok()) return Failed("live", model.status());
  Result<std::unique_ptr<live::Ros2Arm>> arm =
      live::Ros2Arm::Create(**node, tf, *model, options->arm, stop.get_token());
  if (!arm.ok()) return Failed("live", arm.status());
  Result<std::unique_ptr<live::Ros2RgbdSource>> source =
      live::Ros2RgbdSource::Create(**node, tf, options->camera, config->camera, stop.get_token());
  if (!source.ok()) return Failed("live", source.status());
  std::unique_ptr<live::RvizPublisher> rviz;
  if (options->rviz.enabled) {
    Result<std::unique_ptr<live::RvizPublisher>> r =
        live::RvizPublisher::Create(**node, options->rviz, config->episode.target_class);
    if (!r.ok()) return Failed("live", r.status());
    rviz = std::move(*r);
  }

  experiment::FolderRun run;
  run.command = "avp live";
  run.scene_name = scene ? scene->name : "live";
  run.scene_description = scene ? scene->description : "a ROS 2 robot";
  run.gt = gt ? &*gt : nullptr;
  run.gt_seconds = gt_s;
  run.extra = [&] {
    return nlohmann::json{
        {"live", LiveRecord(*options, **node, **source, **arm, **listener, rviz.get())}};
  };
  const experiment::RobotSide robot{source->get(), arm->get(), stop.get_token()};
  run.run = [&](const std::vector<pipeline::EpisodeObserver*>& observers,
                std::unique_ptr<mapping::SemanticMap>* map, std::stop_token write_failed) {
    // A result that cannot be written stops the robot's episode like Ctrl-C does.
    const std::stop_callback forward(write_failed, [&] { stop.request_stop(); });
    const experiment::EpisodeTruth truth{scene ? &*scene : nullptr, gt ? &*gt : nullptr};
    return experiment::RunEpisodeWithRobot(*config, registries, robot, roi, truth, observers, map);
  };
  experiment::RunFolderOptions folder;
  folder.out_dir = cli.run.out;
  folder.force = cli.run.force;
  folder.record = cmd.count("--record") > 0;
  folder.record_path = cli.run.record_file;
  folder.record_base_frame = options->camera.base_frame;
  if (!cli.run.config_file.empty()) {
    folder.inputs.emplace_back(cli.run.config_file, "configuration file");
  }
  folder.on_step = PrintStep;
  std::vector<pipeline::EpisodeObserver*> observers;
  if (rviz) observers.push_back(rviz.get());
  const Result<experiment::RunSummary> summary =
      experiment::RunEpisodeToFolder(*config, registries, folder, run, observers);
  if (!summary.ok()) return Failed("live", summary.status());
  const pipeline::EpisodeResult& e = summary->result.episode;
  std::printf("%s with %s / %s: %d views (%s%s%s) in %.1f s", run.scene_name.c_str(),
              config->planner.name.c_str(), config->segmenter.name.c_str(), e.views_fused(),
              std::string(pipeline::ToString(e.end)).c_str(), e.end_reason.empty() ? "" : ": ",
              e.end_reason.c_str(), summary->seconds);
  if (gt) {
    std::printf("; final F1 %.3f, fruits found %zu/%zu", summary->result.final_metrics.exact.f1,
                summary->result.final_metrics.fruits.found,
                summary->result.final_metrics.fruits.total);
  }
  std::printf("\nwrote %zu files to %s:\n", summary->files.size(), folder.out_dir.string().c_str());
  for (const auto& f : summary->files) std::printf("  %s\n", f.string().c_str());
  // An episode cut short by the robot or the segmenter is a failure of the command, its results
  // saved.
  if (e.end == pipeline::EpisodeEnd::kSegmenterFault) {
    return Failed("live", UnavailableError(fmt::format("segmenter fault: {}", e.end_reason)));
  }
  return e.end == pipeline::EpisodeEnd::kRobotFault ? 1 : 0;
}

}  // namespace

void AddLiveCommand(CLI::App& app, CommandContext& context) {
  auto cli = std::make_shared<LiveCli>();
  CLI::App* cmd = app.add_subcommand(
      "live",
      "The active-vision loop on a ROS 2 robot: camera and arm topics, RViz markers, a run folder "
      "(docs/ros2.md)");
  AddRunOptions(*cmd, cli->run);
  cmd->get_option("--out")->default_str("out/live");
  cli->run.out = "out/live";
  AddRecordOption(*cmd, cli->run);
  AddKeyValueOption(*cmd, "--live-option", cli->live_options,
                    "A key of the config's live: section (repeatable), e.g. "
                    "camera.color_topic=/cam/color/image_raw, arm.trajectory_topic=, distro=jazzy");
  cmd->callback([cli, cmd, &context] {
    RunGuarded(context, [&] { return Live(*cmd, *cli, *context.registries); });
  });
}

}  // namespace avp::apps

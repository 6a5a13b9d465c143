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

#include <avp/experiment/live_run.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/options_yaml.h>
#include <avp/ros/live/live_options.h>

#include "cli_common.h"
#include "ros2_cli.h"
#include "run_cli.h"

namespace avp::apps {

namespace {

struct LiveCli {
  RunCli run;
  std::vector<std::string> live_options;
};

int Live(const CLI::App& cmd, const LiveCli& cli, const experiment::Registries& registries) {
  YAML::Node section;
  const Result<experiment::CheckedRunConfig> config = ResolveConfig(
      cmd, cli.run, registries,
      {.name = "live", .node = &section, .default_scene = false, .plan_motion = true});
  if (!config.ok()) return Failed("live", config.status());
  const Result<ros::live::LiveOptions> options =
      ResolveSectionOptions(ros::live::LiveOptionTable(), section, cli.live_options,
                            cli.run.config_file + ": live", "live option");
  if (!options.ok()) return Failed("live", options.status());
  if (cli.run.print_config) {
    Result<YAML::Node> yaml = experiment::RunConfigToYaml(**config, registries);
    if (!yaml.ok()) return Failed("live", yaml.status());
    (*yaml)["live"] = io::OptionsToYaml(ros::live::LiveOptionTable().Values(*options),
                                        ros::live::LiveOptionTable().Info(*options));
    std::fputs(io::YamlText(*yaml).c_str(), stdout);
    return 0;
  }

  std::stop_source stop;
  StopOnSignal stopper(stop, options->timeout_s,
                       "avp live: interrupted: finishing the step and saving results");
  experiment::RunFolderOptions folder;
  folder.out_dir = cli.run.out;
  folder.force = cli.run.force;
  folder.record = cmd.count("--record") > 0;
  folder.record_path = cli.run.record_file;
  folder.record_compression = cli.run.record_compression;
  if (!cli.run.config_file.empty()) {
    folder.inputs.emplace_back(cli.run.config_file, "configuration file");
  }
  folder.on_step = PrintStep;
  const Result<experiment::RunSummary> summary = experiment::RunLiveToFolder(
      *config, *options, folder, stop, [](const experiment::LiveWaiting& w) {
        std::printf("avp live: node %s on ROS_DOMAIN_ID %d; waiting for %s and %s\n",
                    w.node.c_str(), w.domain_id, w.camera_info_topic.c_str(),
                    w.joint_states_topic.c_str());
        std::fflush(stdout);
      });
  if (!summary.ok()) return Failed("live", summary.status());
  const pipeline::EpisodeResult& e = summary->result.episode;
  std::printf("%s with %s / %s: %d views (%s%s%s) in %.1f s", summary->scene_name.c_str(),
              (*config)->planner.name.c_str(), (*config)->segmenter.name.c_str(), e.views_fused(),
              std::string(pipeline::ToString(e.end)).c_str(), e.end_reason.empty() ? "" : ": ",
              e.end_reason.c_str(), summary->seconds);
  if (!(*config)->scenario.empty() || !(*config)->scene_file.empty()) {  // scored against its truth
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

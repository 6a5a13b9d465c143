// avp replay BAG: segmentation, mapping and evaluation over a bag (avp's own recording or a
// robot's rosbag2: MCAP or SQLite 3, a file or a bag folder) into a run folder (docs/recording.md
// "Replay").
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/experiment/replay.h>
#include <avp/experiment/run_config.h>
#include <avp/io/yaml.h>
#include <avp/report/progress.h>
#include <avp/ros/bag/layout.h>

#include "cli_common.h"
#include "commands.h"

namespace avp::apps {

namespace {

struct ReplayCli {
  std::string bag;
  std::string out = "out/replay";
  bool force = false;
  std::string segmenter;
  std::string config_file;
  std::vector<std::string> set;
  ros::bag::BagReadOptions bag_options;
  std::vector<std::string> bag_option_items;
  // Shorthands for run configuration keys (given: they override --config and the recording's).
  double fps = 1.0;  ///< shown as the default; applied only when given (shorthand_keys)
  int max_views = 0;
  std::string prompt;
  std::vector<std::string> shorthand_keys;  ///< "replay.fps=2", ... in the order of the line
};

/// The bag's run configuration, then --config, then --set (ReplayToFolder validates it).
Result<experiment::RunConfig> ResolveReplayConfig(const ros::bag::BagReader& bag,
                                                  const ReplayCli& cli) {
  AVP_ASSIGN_OR_RETURN(experiment::RunConfig config, experiment::BagRunConfig(bag));
  if (!cli.config_file.empty()) {
    AVP_ASSIGN_OR_RETURN(const YAML::Node root, io::LoadYamlFile(cli.config_file));
    AVP_RETURN_IF_ERROR(experiment::ReadRunConfigYaml(root, cli.config_file, config));
  }
  AVP_ASSIGN_OR_RETURN(const OptionValues values, ParseKeyValues(cli.set, "--set item"));
  for (const auto& [key, value] : values) {
    AVP_RETURN_IF_ERROR(experiment::SetRunConfigKey(config, key, value));
  }
  AVP_ASSIGN_OR_RETURN(const OptionValues shorthands,
                       ParseKeyValues(cli.shorthand_keys, "shorthand"));
  for (const auto& [key, value] : shorthands) {
    AVP_RETURN_IF_ERROR(experiment::SetRunConfigKey(config, key, value));
  }
  return config;
}

/// "robot bag (rosbag2 SQLite 3, 2 files)" / "avp recording (MCAP ...)".
std::string BagLine(const ros::bag::BagReader& bag) {
  const ros::bag::BagInfo& info = bag.info();
  return fmt::format("{}: {} ({}, {:.1f} MB)", bag.path().string(),
                     bag.avp_recording() ? "avp recording" : "robot bag", info.format,
                     static_cast<double>(info.file_bytes) / 1e6);
}

/// What became of the bag's frames, for the console.
void PrintAccount(const ros::bag::BagReader& bag, const experiment::ReplaySummary& summary) {
  const ros::bag::FrameAccount& a = bag.account();
  std::vector<std::string> left_out;
  for (const auto& [reason, n] : a.left_out) left_out.push_back(fmt::format("{} {}", n, reason));
  std::vector<std::string> skipped;
  for (const auto& [reason, n] : a.skipped_by_reason) {
    skipped.push_back(fmt::format("{} {}", n, reason));
  }
  std::printf(
      "frames: %zu %s, %zu fused, %zu left out%s, %zu skipped%s; masks: %zu, %zu with no "
      "valid depth\n",
      a.pairs, bag.avp_recording() ? "steps" : "colour/depth pairs", a.fused, a.left_out_count(),
      left_out.empty() ? "" : fmt::format(" ({})", fmt::join(left_out, ", ")).c_str(),
      a.skipped_count(),
      skipped.empty() ? "" : fmt::format(" ({})", fmt::join(skipped, ", ")).c_str(),
      summary.masks(), summary.masks_without_depth());
  for (const std::string& s : a.skipped) spdlog::warn("skipped: {}", s);
  if (a.skipped_count() > a.skipped.size()) {
    spdlog::warn("... {} more skipped (record.json lists each frame)",
                 a.skipped_count() - a.skipped.size());
  }
}

void PrintOutcome(const ReplayCli& cli, const experiment::ReplaySummary& summary) {
  const experiment::RunResult& r = summary.run.result;
  std::printf("replayed %d view(s) with %s masks in %.1f s (%s%s%s)", r.episode.views_fused(),
              summary.segmenter.c_str(), summary.run.seconds,
              std::string(pipeline::ToString(r.episode.end)).c_str(),
              r.episode.end_reason.empty() ? "" : ": ", r.episode.end_reason.c_str());
  if (summary.run.result.gt_voxels > 0 || !r.fruits.empty()) {
    std::printf("; final F1 %.3f, fruits found %zu/%zu", r.final_metrics.exact.f1,
                r.final_metrics.fruits.found, r.final_metrics.fruits.total);
  }
  std::printf("\n");
  if (summary.metrics_compared > 0) {
    if (summary.metrics_differ == 0) {
      std::printf("metrics identical to the recording's at all %zu views\n",
                  summary.metrics_compared);
    } else {
      std::printf("metrics differ from the recording's at %zu of %zu views (first: %s)\n",
                  summary.metrics_differ, summary.metrics_compared,
                  summary.first_difference.c_str());
    }
  }
  std::printf("wrote %zu files to %s:\n", summary.run.files.size(), cli.out.c_str());
  for (const auto& f : summary.run.files) std::printf("  %s\n", f.string().c_str());
}

/// The views the progress counts to: an avp recording's steps, or --max-views; else unknown.
size_t ExpectedViews(const ros::bag::BagReader& bag, const experiment::RunConfig& config) {
  size_t n = 0;
  if (bag.avp_recording()) {
    auto it = bag.info().topic_counts.find(std::string(ros::bag::kStepTopic));
    if (it != bag.info().topic_counts.end()) n = it->second;
  }
  if (config.replay.max_views > 0 && (n == 0 || n > static_cast<size_t>(config.replay.max_views))) {
    n = static_cast<size_t>(config.replay.max_views);
  }
  return n;
}

int Replay(const ReplayCli& cli_in, const experiment::Registries& registries) {
  ReplayCli cli = cli_in;
  {
    Result<OptionValues> items = ParseKeyValues(cli.bag_option_items, "--bag-option item");
    if (!items.ok()) return Failed("replay", items.status());
    if (Status s = ros::bag::BagReadOptionTable().SetAll(cli.bag_options, *items); !s.ok()) {
      return Failed("replay", s);
    }
  }
  Result<std::unique_ptr<ros::bag::BagReader>> opened =
      ros::bag::BagReader::Open(cli.bag, cli.bag_options);
  if (!opened.ok()) return Failed("replay", opened.status());
  ros::bag::BagReader& bag = **opened;
  std::printf("%s\n", BagLine(bag).c_str());
  std::fflush(stdout);  // before the progress lines on stderr
  const Result<experiment::RunConfig> config = ResolveReplayConfig(bag, cli);
  if (!config.ok()) return Failed("replay", config.status());

  experiment::ReplayOptions options;
  options.segmenter = cli.segmenter;
  options.folder.out_dir = cli.out;
  options.folder.force = cli.force;
  if (!cli.config_file.empty()) {
    options.folder.inputs.emplace_back(cli.config_file, "configuration file");
  }
  report::Progress progress(report::ProgressOn(stderr, "views", ExpectedViews(bag, *config)));
  options.folder.on_step = [&progress, &bag](const pipeline::StepRecord& s) {
    const double f1 = s.Metric("f1");
    const double read = bag.info().file_bytes == 0 ? 100.0
                                                   : 100.0 * static_cast<double>(bag.bytes_read()) /
                                                         static_cast<double>(bag.info().file_bytes);
    progress.Done(
        std::isnan(f1)
            ? fmt::format("view {}: {} masks ({} without depth), {} occupied voxels; {:.0f} % of "
                          "the bag read",
                          s.view + 1, s.masks, s.masks_without_depth, s.occupied_voxels,
                          std::min(read, 100.0))
            : fmt::format("view {}: F1 {:.3f}, fruits {:.0f}/{:.0f}", s.view + 1, f1,
                          s.Metric("fruits_found"), s.Metric("fruits_total")));
  };
  const Result<experiment::ReplaySummary> summary =
      experiment::ReplayToFolder(bag, *config, registries, options);
  progress.Finish();
  if (!summary.ok()) return Failed("replay", summary.status());
  for (const std::string& n : summary->notes) spdlog::warn("{}", n);
  PrintAccount(bag, *summary);
  PrintOutcome(cli, *summary);
  if (!bag.damage().ok()) {
    spdlog::error("{}", bag.damage().ToString());
    return Failed("replay", bag.damage().WithContext(fmt::format(
                                "the recording is damaged; its {} intact view(s) were replayed "
                                "into {}",
                                summary->views, cli.out)));
  }
  return 0;
}

}  // namespace

void AddReplayCommand(CLI::App& app, CommandContext& context) {
  auto cli = std::make_shared<ReplayCli>();
  CLI::App* cmd = app.add_subcommand(
      "replay",
      "Segmentation, mapping and evaluation over a bag: avp's own recording (avp run --record) or "
      "a robot's rosbag2 (MCAP or Humble's SQLite 3 .db3, a file or a bag folder; "
      "docs/recording.md)");
  cmd->add_option("bag", cli->bag,
                  "The bag: an MCAP file (uncompressed, zstd or lz4), a rosbag2 .db3, or a bag "
                  "folder (metadata.yaml and its .db3 / .mcap files)")
      ->required();
  cmd->add_option("--out", cli->out, "Run folder")->default_str(cli->out);
  cmd->add_flag("--force", cli->force,
                "Replace the results an earlier run left in --out (only an avp run folder)");
  cmd->add_option("--segmenter", cli->segmenter,
                  "'recorded' (the recording's masks: the default when the bag has them) or a "
                  "segmenter (`avp run --segmenter help`); the oracle needs the simulator labels "
                  "an avp recording carries");
  cmd->add_option("--config", cli->config_file,
                  "Run configuration YAML over the recording's (map, integrator, camera range, "
                  "segmenter options)");
  AddKeyValueOption(*cmd, "--set", cli->set,
                    "Any key of the run configuration over the recording's (repeatable)");
  ros::bag::BagReadOptions& b = cli->bag_options;
  cmd->add_option("--color-topic", b.color_topic, "Colour images")->default_str(b.color_topic);
  cmd->add_option("--depth-topic", b.depth_topic, "Depth aligned to colour (32FC1 m, 16UC1 mm)")
      ->default_str(b.depth_topic);
  cmd->add_option("--camera-info-topic", b.camera_info_topic, "CameraInfo of the colour camera")
      ->default_str(b.camera_info_topic);
  cmd->add_option("--base-frame", b.base_frame, "The map's frame (the arm's base)")
      ->default_str(b.base_frame);
  cmd->add_option("--camera-frame", b.camera_frame,
                  "The camera's optical frame ('': the colour image's frame_id)")
      ->default_str(b.camera_frame);
  AddNumberOption(*cmd, "--fps", cli->fps, 0.0, 1000.0,
                  "Robot bags: fuse at most this many frames per second of bag time (0: all; "
                  "replay.fps, default 1)")
      ->each([cli](const std::string& v) { cli->shorthand_keys.push_back("replay.fps=" + v); });
  AddNumberOption(*cmd, "--max-views", cli->max_views, 0, 1000000,
                  "At most this many views (0: all; replay.max_views)")
      ->each(
          [cli](const std::string& v) { cli->shorthand_keys.push_back("replay.max_views=" + v); });
  cmd->add_option("--prompt", cli->prompt,
                  "What to find, for the segmenter (episode.prompt; the recording's otherwise)")
      ->each([cli](const std::string& v) { cli->shorthand_keys.push_back("episode.prompt=" + v); });
  AddKeyValueOption(*cmd, "--bag-option", cli->bag_option_items,
                    "Any bag option (repeatable): tf_topic, tf_static_topic, labels_prefix, "
                    "max_pair_skew_ms, tf_tolerance_ms, joint_states_topic, arm, distortion, "
                    "as_robot_bag, ...; the frames to fuse and the region of interest are the "
                    "run configuration's replay.* keys (--set replay.every_nth=5)");
  cmd->callback(
      [cli, &context] { RunGuarded(context, [&] { return Replay(*cli, *context.registries); }); });
}

}  // namespace avp::apps

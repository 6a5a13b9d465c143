#pragma once

// The flags `avp run`, `avp live` and `avp sim ros2` share: the run configuration (--config, the
// shorthands, --*-option, --set) and the per-step progress line.
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>
#include <yaml-cpp/yaml.h>

#include <avp/core/status.h>
#include <avp/experiment/registries.h>
#include <avp/experiment/run_config.h>
#include <avp/pipeline/episode.h>

#include "cli_common.h"

namespace avp::apps {

/// The flags of an episode's configuration that `avp run` and `avp bench` share (a bench applies
/// them to every episode), each applied only when given: --segmenter, --views, --prompt,
/// --voxel-size, --policy, --carving, --no-noise, --oracle-regret, --fuse-while-moving, then the
/// --segmenter-option,
/// --map-option and --set items, in that order.
struct EpisodeFlags {
  std::string segmenter, prompt, policy, carving;
  int views = 0;
  double voxel_size_m = 0.0;
  bool no_noise = false, oracle_regret = false, fuse_while_moving = false;
  std::vector<std::string> segmenter_options, map_options, set;
};

/// Adds EpisodeFlags' options to `cmd`.
void AddEpisodeFlags(CLI::App& cmd, EpisodeFlags& flags);

/// The given EpisodeFlags over `config` (a --segmenter naming another segmenter first drops the
/// options `config` gave the previous one: they were its).
Status ApplyEpisodeFlags(const CLI::App& cmd, const EpisodeFlags& flags,
                         experiment::RunConfig& config);

/// The flags of `avp run`. Shorthand flags apply only when given, over --config; then the
/// --*-option and --set items, in that order.
struct RunCli {
  std::string config_file;
  bool print_config = false;
  SceneFlags scene;
  EpisodeFlags episode;
  std::string planner, gt, out = "out/run";
  int threads = 0;
  bool force = false;
  std::vector<std::string> planner_options;
  /// --record [FILE] (avp run, avp live; given: the command's count("--record")): its file, empty
  /// for RUN_DIR/episode.mcap.
  std::string record_file;
  /// --record-compression: the recording's chunk compression ("" none, "zstd", "lz4").
  std::string record_compression;
};

/// Adds --record [FILE] (an MCAP recording of the episode, docs/recording.md) and
/// --record-compression to `cmd`.
void AddRecordOption(CLI::App& cmd, RunCli& cli);

/// Adds the run configuration's flags to `cmd`.
void AddRunOptions(CLI::App& cmd, RunCli& cli);

/// A section of the --config file that is not the run configuration's (`live:`), handed to the
/// command; whether the default scenario applies when none is named; and whether the arm's moves
/// are planned collision-free unless the configuration says otherwise (motion.enabled: a real
/// arm's default, docs/motion.md).
struct ConfigSection {
  std::string name;
  YAML::Node* node = nullptr;
  bool default_scene = true;
  bool plan_motion = false;
};

/// The configuration: the defaults, --config (without `section`), the shorthand flags, the
/// --*-option items, --set; the default scenario when none is named (section.default_scene);
/// validated (errors name the file).
Result<experiment::CheckedRunConfig> ResolveConfig(const CLI::App& cmd, const RunCli& cli,
                                                   const experiment::Registries& registries,
                                                   const ConfigSection& section = {});

/// One line per fused view: pose, masks, F1 and fruits (when there is ground truth), stage times.
void PrintStep(const pipeline::StepRecord& s);
/// PrintStep's line with `progress` before the problems (avp run: report::FormatProgressTimes, the
/// rate, the time elapsed and the time left).
void PrintStepWithProgress(const pipeline::StepRecord& s, std::string_view progress);

}  // namespace avp::apps

#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <stop_token>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include <avp/core/status.h>
#include <avp/experiment/episode_runner.h>
#include <avp/experiment/registries.h>
#include <avp/experiment/run_config.h>
#include <avp/pipeline/episode.h>

namespace avp::experiment {

/// Where `avp run` writes and what it reports while it runs.
struct RunFolderOptions {
  std::filesystem::path out_dir = "out/run";
  /// A folder that already holds results is refused unless `force`, which empties it first (only
  /// when it is an avp run folder holding nothing else: PrepareOutputFolder).
  bool force = false;
  /// Files the run reads besides the configuration's scene and ground truth (the --config file):
  /// no output may be one of them.
  std::vector<std::pair<std::filesystem::path, std::string>> inputs;
  /// Called after every step (progress printing); may be empty.
  std::function<void(const pipeline::StepRecord&)> on_step;
  /// Called once with the scene RunToFolder loaded, before its ground truth and episode (e.g. to
  /// print the scene file's warnings); may be empty.
  std::function<void(const sim::Scene&)> on_scene;
  /// Record the episode as MCAP (`--record`, docs/recording.md): every fused view's topics into
  /// `record_path`, or out_dir/episode.mcap when it is empty. A write error stops the episode and
  /// is the run's error, naming the file.
  bool record = false;
  std::filesystem::path record_path;
  /// The recording's chunk compression: "" (none), "zstd" or "lz4" (`--record-compression`).
  std::string record_compression;
  /// The frame the recording's TF and markers are in (`avp live`: its base frame).
  std::string record_base_frame = "igus_rebel_base_link";
  /// Asks the episode to stop (the user's interrupt: Ctrl-C in Python): it ends as interrupted
  /// after the step under way, and its results are written as for any early end.
  std::stop_token stop;
};

struct RunSummary {
  RunResult result;
  std::string scene_name;
  /// record.json first, then metrics.csv, map.avpmap, map.ot, fruit_voxels.ply, metrics.svg,
  /// report.html.
  std::vector<std::filesystem::path> files;
  double seconds = 0.0;
};

/// `avp run`: one episode of `config` into a run folder (docs/experiments.md):
///   avp-state.json    the folder's lifecycle: "in-progress" from the start, "complete" after
///                     the last result (output_folder.h); a killed run stays "in-progress"
///   record.json       the effective configuration, seed, git revision, host, timings, how it
///                     ended, the ground truth, final metrics and every step
///   metrics.csv       one row per fused view, written as the episode goes
///   map.avpmap        the final map as avp's map file (all of it: avp map info / compare)
///   map.ot            the final map as an OctoMap ColorOcTree (octovis)
///   fruit_voxels.ply  the final fruit voxels with class, confidence, instance
///   metrics.svg       F1 (exact and one-voxel tolerance) and fruits found per view
///   report.html       the episode in 3D, step by step: the map, the ground-truth fruit, each
///                     view's frustum, masks and candidates, the curves (one file, offline;
///                     docs/report.md)
Result<RunSummary> RunToFolder(const CheckedRunConfig& config, const RunFolderOptions& options);

/// What a run folder records besides the configuration: how the episode is run, on what, and
/// what it is scored against. RunToFolder fills it for the simulator; `avp live` for a robot.
struct FolderRun {
  /// record.json's "avp": the command ("avp run", "avp live").
  std::string command = "avp run";
  /// The plant: a scene's name and description, or what the user calls the live one.
  std::string scene_name;
  std::string scene_description;
  /// The ground truth, when known (null: no metrics), and the seconds it took.
  const eval::GroundTruth* gt = nullptr;
  double gt_seconds = 0.0;
  /// More record.json keys (e.g. "live": topics, frames, counters), asked for after the episode.
  std::function<nlohmann::json()> extra;
  /// Runs the episode with these observers (the CSV writer, the progress callback) and hands
  /// over the final map.
  /// The stop token asks the episode to stop (a result could not be written).
  std::function<Result<RunResult>(const std::vector<pipeline::EpisodeObserver*>&,
                                  std::unique_ptr<mapping::SemanticMap>*, std::stop_token)>
      run;
};

/// Runs `run` into options.out_dir and writes the folder RunToFolder describes. The episode's
/// results are written even when it ended early (interrupted, robot fault). The folder is
/// prepared first (PrepareOutputFolder: a folder holding results is refused without `force`) and
/// no output may be an input (the scene, the ground truth, options.inputs). A write error stops
/// the episode (through the stop token handed to run.run) and is the error, naming the file; the
/// folder is then marked "failed".
Result<RunSummary> RunEpisodeToFolder(
    const CheckedRunConfig& config, const RunFolderOptions& options, const FolderRun& run,
    const std::vector<pipeline::EpisodeObserver*>& observers = {});

/// record.json's "config": the effective configuration (RunConfigToYaml's tree) as JSON, numbers
/// and flags typed.
nlohmann::json RunConfigJson(const CheckedRunConfig& config);

}  // namespace avp::experiment

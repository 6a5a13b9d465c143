#pragma once

#include <filesystem>
#include <functional>
#include <string>
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
  /// Called after every step (progress printing); may be empty.
  std::function<void(const pipeline::StepRecord&)> on_step;
};

struct RunSummary {
  RunResult result;
  std::string scene_name;
  /// record.json first, then metrics.csv, map.ot, fruit_voxels.ply, metrics.svg.
  std::vector<std::filesystem::path> files;
  double seconds = 0.0;
};

/// `avp run`: one episode of `config` into a run folder (docs/experiments.md):
///   record.json       the effective configuration, seed, git revision, host, timings, how it
///                     ended, the ground truth, final metrics and every step
///   metrics.csv       one row per fused view, written as the episode goes
///   map.ot            the final map as an OctoMap ColorOcTree (octovis)
///   fruit_voxels.ply  the final fruit voxels with class, confidence, instance
///   metrics.svg       F1 (exact and one-voxel tolerance) and fruits found per view
Result<RunSummary> RunToFolder(const RunConfig& config, const Registries& registries,
                               const RunFolderOptions& options);

/// record.json's "config": the effective configuration (RunConfigToYaml's tree) as JSON, numbers
/// and flags typed.
Result<nlohmann::json> RunConfigJson(const RunConfig& config, const Registries& registries);

}  // namespace avp::experiment

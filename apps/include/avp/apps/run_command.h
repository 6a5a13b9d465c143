#pragma once

#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/eval/experiment.h>
#include <avp/pipeline/episode.h>

namespace avp::apps {

/// The build's identity for run records: git revision (with "-dirty" when the tree had changes),
/// or "unknown" when the source tree is not a git checkout.
std::string SourceRevision();
/// "hostname (OS release, N hardware threads)".
std::string HostDescription();

// ---- avp run ------------------------------------------------------------------------------------

/// `avp run`: one episode into a run directory (docs/experiments.md):
///   record.json       resolved config, seed, git revision, host, timings, how it ended, final
///   metrics metrics.csv       one row per fused view, written as the episode goes map.ot final map
///   as an OctoMap ColorOcTree (octovis) fruit_voxels.ply  final fruit voxels with class,
///   confidence, instance metrics.svg       F1 (exact and one-voxel tolerance) and fruits found per
///   view
struct RunOptions {
  eval::RunConfig config;
  std::filesystem::path out_dir = "out/run";
  /// Called after every step (progress printing).
  std::function<void(const pipeline::StepRecord&)> on_step;
};

struct RunSummary {
  eval::RunResult result;
  std::string scene_name;
  std::vector<std::filesystem::path> files;
  double seconds = 0.0;
};

Result<RunSummary> RunRun(const RunOptions& options);

/// "KEY=VALUE" items (--planner-option) into `out` (later ones win); InvalidArgument naming an
/// item without '=' or with an empty key. The keys and values are checked by
/// eval::RunConfig::Validate (planning::SetAvpNbvOption).
Status ParsePlannerOptions(const std::vector<std::string>& items,
                           std::map<std::string, std::string>& out);

// ---- avp bench ----------------------------------------------------------------------------------

/// `avp bench`: scenarios x planners x seeds, episodes in parallel; per-run metrics.csv and
/// record.json under runs/, and the summary: summary.csv (long format: scenario, planner,
/// segmenter, view, metric, mean, ci95, n), summary.md, and per-scenario plots f1_<s>.svg and
/// fruits_<s>.svg in the style of the paper's Fig. 3.
struct BenchOptions {
  std::vector<std::string> scenarios;
  std::vector<std::string> planners;
  std::vector<uint64_t> seeds;
  /// Everything else of each episode (its scenario, planner and seed are overridden).
  eval::RunConfig base;
  std::filesystem::path out_dir = "out/bench";
  /// Episodes run at once (0 = hardware threads).
  int jobs = 0;
  /// Progress bar on stderr.
  bool progress = true;
  Status Validate() const;
};

/// Reads an experiment YAML (configs/experiments/paper.yaml): keys scenarios, planners, seeds
/// (a list, or {first, count}), views, segmenter, prompt, voxel_size_m, policy, carving,
/// depth_noise. Unknown keys are errors naming them.
Result<BenchOptions> LoadBenchConfig(const std::filesystem::path& yaml);

struct BenchCell {
  std::string scenario, planner;
  size_t runs = 0;
  double final_f1_mean = 0.0, final_f1_ci95 = 0.0;
  double final_found_mean = 0.0, final_found_ci95 = 0.0;
  double fruits_total_mean = 0.0;
  double plan_ms_mean = 0.0, episode_s_mean = 0.0;
  size_t failed = 0;
};

struct BenchSummary {
  std::vector<BenchCell> cells;
  std::vector<std::filesystem::path> files;
  size_t episodes = 0, failed = 0;
  double seconds = 0.0;
};

Result<BenchSummary> RunBench(const BenchOptions& options);

}  // namespace avp::apps

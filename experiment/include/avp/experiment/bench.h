#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <avp/core/limits.h>
#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/experiment/registries.h>
#include <avp/experiment/run_config.h>
#include <avp/report/bench_summary.h>

namespace avp::experiment {

/// The most seeds a bench takes (per scenario and planner): checked before any list is allocated.
inline constexpr uint64_t kMaxBenchSeeds = 100000;

/// InvalidArgument "<what> (n) must be at most 100000 seeds" above kMaxBenchSeeds.
Status CheckSeedCount(uint64_t count, std::string_view what);

/// The most episodes (scenarios x planners x seeds) one bench runs: max_bench_episodes, 100000 by
/// default (`avp --limit max_bench_episodes=N bench ...`). Checked before any job is listed.
const Limit& MaxBenchEpisodes();

/// `avp bench`: scenarios x planners x seeds, episodes in parallel (docs/experiments.md).
struct BenchConfig {
  /// One line for the summary.
  std::string description;
  std::vector<std::string> scenarios;
  std::vector<std::string> planners;
  std::vector<uint64_t> seeds;
  /// Per planner of `planners`, options over its registered defaults.
  std::map<std::string, OptionValues> planner_options;
  /// Everything else of each episode (its scenario, planner and seed are the job's; its threads
  /// 1, episodes run in parallel instead).
  RunConfig base;
  std::filesystem::path out_dir = "out/bench";
  /// Episodes run at once (0 = hardware threads), at most kMaxThreads.
  int jobs = 0;
  /// A non-empty out_dir is refused unless `force`, which empties it first when it is an avp
  /// bench folder holding nothing else (PrepareOutputFolder).
  bool force = false;
  /// Files the bench reads (its --config): no output may be one of them.
  std::vector<std::pair<std::filesystem::path, std::string>> inputs;
  /// Progress bars on stderr.
  bool progress = true;

  /// Every problem at once: empty or unknown scenarios and planners, empty names, repeated
  /// seeds, too many seeds or episodes (max_bench_episodes), jobs out of [0, kMaxThreads], options
  /// of a planner that is not in the bench or that it does not have, a bad base configuration.
  Status Validate(const Registries& registries) const;
};

/// Reads an experiment YAML (configs/experiments/paper.yaml): keys description, scenarios,
/// planners (lists), seeds (a list, or {first, count}), planner_options ({planner: {key:
/// value}}), run (a run configuration tree over the defaults, as `avp run --print-config` prints
/// it). Unknown keys are errors naming them and the known ones.
Result<BenchConfig> LoadBenchConfig(const std::filesystem::path& yaml);

struct BenchSummary {
  std::vector<report::BenchCell> cells;
  /// summary.md first, then summary.csv and the plots.
  std::vector<std::filesystem::path> files;
  size_t episodes = 0, failed = 0;
  double seconds = 0.0;
};

/// Runs the bench: each (scenario, seed) scene and ground truth once, shared by the planners;
/// per-run metrics.csv and record.json under runs/<scenario>/<planner>/seed-<n>/, then the
/// summary (report::WriteBenchSummary). The bench folder and each per-run folder have the run
/// folder's lifecycle (avp-state.json, output_folder.h): a folder holding results is refused
/// unless config.force. A result that cannot be written stops the bench (the running episodes
/// are asked to stop, no new one starts) with IoError naming the file.
Result<BenchSummary> RunBench(const BenchConfig& config, const Registries& registries);

}  // namespace avp::experiment

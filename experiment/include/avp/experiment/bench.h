#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

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
  /// Episodes run at once (0 = hardware threads).
  int jobs = 0;
  /// Progress bars on stderr.
  bool progress = true;

  /// Every problem at once: empty or unknown scenarios and planners, repeated seeds, options of a
  /// planner that is not in the bench or that it does not have, a bad base configuration.
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
/// summary (report::WriteBenchSummary).
Result<BenchSummary> RunBench(const BenchConfig& config, const Registries& registries);

}  // namespace avp::experiment

#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <stop_token>
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
#include <avp/report/conditions.h>
#include <avp/sim/scenario.h>

namespace avp::experiment {

/// The most seeds a bench takes (per scenario and planner): checked before any list is allocated.
inline constexpr uint64_t kMaxBenchSeeds = 100000;

/// InvalidArgument "<what> (n) must be at most 100000 seeds" above kMaxBenchSeeds.
Status CheckSeedCount(uint64_t count, std::string_view what);

/// The most episodes (scenarios x planners x seeds) one bench runs: max_bench_episodes, 100000 by
/// default (`avp --limit max_bench_episodes=N bench ...`). Checked before any job is listed.
const Limit& MaxBenchEpisodes();

/// One entry of a bench's scenario list, resolved: a registered scenario or a scene file, with
/// its arrangement (docs/experiments.md, "Your own plant").
struct BenchScenario {
  std::string entry;     ///< the list entry it comes from, as given
  std::string scenario;  ///< a registered scenario; empty for a scene file
  std::filesystem::path scene_file;
  std::string arrangement;  ///< sim::ParseArrangement's text; empty: none
  /// Its name in summaries and run folders: the scenario's name or the scene's (the file's
  /// `name:` or stem), "@<arrangement>" appended when one is given. Empty for a scene file until
  /// the file is read.
  std::string display_name;
};

/// True when a scenario list entry names a scene file: its part before the last '@' ends in
/// .yaml or .yml, or contains a '/'.
bool IsSceneFileEntry(std::string_view entry);

/// The entries of a scenario list, each "NAME", "NAME@ARRANGEMENT", "FILE" or "FILE@ARRANGEMENT";
/// "FILE@paper" stands for the four paper arrangements (reference, full-occlusion,
/// single-cluster, unoriented-start). Errors (InvalidArgument naming the entry): an empty entry or
/// arrangement, a bad arrangement (sim::ParseArrangement), an unknown scenario, an arrangement
/// other than reference for a scenario. Files are not read here.
Result<std::vector<BenchScenario>> ExpandScenarioList(const std::vector<std::string>& entries,
                                                      const sim::ScenarioRegistry& scenarios);

/// One condition of a bench (detector misses x2, 10 mm voxels, ...): its episodes' run
/// configuration and planner options over the bench's (docs/experiments.md, "Conditions").
struct BenchCondition {
  /// Its bench folder under the bench's out_dir: letters, digits, '.', '-', '_'.
  std::string name;
  std::string description;  ///< one line, may be empty
  /// Run configuration keys over the bench's, as `--set` takes them ("map.grid.voxel_size_m").
  OptionValues run;
  /// Per planner of the bench, options over the bench's planner_options.
  std::map<std::string, OptionValues> planner_options;
};

/// `avp bench`: scenarios x planners x seeds, episodes in parallel (docs/experiments.md).
struct BenchConfig {
  /// One line for the summary.
  std::string description;
  /// Registered scenarios and scene files, each optionally "@ARRANGEMENT" (ExpandScenarioList).
  /// A scene file path is relative to the current directory (LoadBenchConfig makes a config's
  /// relative to the config file).
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
  /// Progress on stderr (report::Progress): a bar on a terminal, one line per finished job in a
  /// log or under CI.
  bool progress = true;
  /// `--record`: each episode also as MCAP, runs/<scenario>/<planner>/seed-<n>/episode.mcap
  /// (docs/recording.md).
  bool record = false;
  /// The recordings' chunk compression: "" (none), "zstd" or "lz4" (`--record-compression`).
  std::string record_compression;
  /// `--shard K/N`: run only the K-th (1-based) of N slices of the job list (scenario x seed x
  /// planner). The (scenario, seed)s are dealt, each with all its planners (its ground truth is
  /// computed once), round-robin in a fixed shuffled order (the same on every machine), so that
  /// every slice gets a share of every scenario. A shard's folder holds its runs and bench.json
  /// but no summary: `avp bench merge` makes it. 1/1: the whole bench.
  uint64_t shard_index = 1, shard_count = 1;
  /// `--resume`: out_dir may hold an earlier, interrupted run of this very bench (its bench.json
  /// names the same configuration, job list, shard and revision): the jobs whose run folders are
  /// complete are read back, not run again; the others are emptied and run. Not with `force`.
  bool resume = false;
  /// When not empty, the bench runs once per condition, each into out_dir/<name>/, and compares
  /// them (RunBenchConditions); the first planner is the one compared with the others.
  std::vector<BenchCondition> conditions;
  /// Asks the bench to stop (the user's interrupt: Ctrl-C in Python): running episodes end after
  /// the step under way and are marked failed ("interrupted"), no new one starts, and RunBench
  /// returns Cancelled. The folder can be resumed (`resume`).
  std::stop_token stop;

  /// Every problem at once: empty or unknown scenarios and planners, empty names, bad
  /// arrangements, missing scene files (naming the entry and the file), repeated seeds, too many
  /// seeds or episodes (max_bench_episodes), jobs out of [0, kMaxThreads], options of a planner
  /// that is not in the bench or that it does not have, a bad base configuration. Scene files are
  /// read by RunBench (their errors, and two entries with the same display name, fail it there).
  Status Validate(const Registries& registries) const;
};

/// Reads an experiment YAML (configs/experiments/paper.yaml): keys description, scenarios (scene
/// files among them relative to the YAML file),
/// planners (lists), seeds (a list, or {first, count}), planner_options ({planner: {key:
/// value}}), run (a run configuration tree over the defaults, as `avp run --print-config` prints
/// it), conditions (a list of {name, description, run, planner_options}, each over the bench's).
/// Unknown keys are errors naming them and the known ones.
Result<BenchConfig> LoadBenchConfig(const std::filesystem::path& yaml);
/// The same from a YAML tree already parsed (`context` names it in errors; scene files of the
/// list are relative to `base_dir`).
Result<BenchConfig> ReadBenchConfigYaml(const YAML::Node& root, std::string_view context,
                                        const std::filesystem::path& base_dir);

/// What a bench without a configuration file runs, for each list it does not give: every
/// registered scenario, the planners avp-nbv, predefined and reference-nbv, seeds 0..9.
void FillBenchDefaults(BenchConfig& config, const Registries& registries);

struct BenchSummary {
  std::vector<report::BenchCell> cells;
  /// Per scenario, the first planner's paired difference over each other one (summary.md).
  std::vector<report::PairedLead> leads;
  /// summary.md first, then summary.csv, the plots and report.html.
  std::vector<std::filesystem::path> files;
  /// The bench's report.html (docs/report.md, "Bench report").
  std::filesystem::path report_html;
  size_t episodes = 0, failed = 0;
  /// Of `episodes`, those a resumed bench read back instead of running.
  size_t resumed = 0;
  double seconds = 0.0;
};

/// Runs the bench: each scene file read once (and arranged once per arrangement), each
/// (scenario, seed) scene and ground truth once, shared by the planners;
/// per-run metrics.csv and record.json under runs/<scenario>/<planner>/seed-<n>/, then the
/// summary (report::WriteBenchSummary) and report.html beside it (report::WriteBenchReportHtml).
/// The bench folder and each per-run folder have the run folder's lifecycle (avp-state.json,
/// output_folder.h): a folder holding results is refused unless config.force. A result that cannot
/// be written stops the bench (the running episodes are asked to stop, no new one starts) with
/// IoError naming the file.
///
/// Every bench folder also gets bench.json (written before the first episode, rewritten at the
/// end): what was run (the description of the summary, the whole job list, the shard, the
/// revision) and each (scenario, seed)'s ground-truth fruit visibility, so that shards can be
/// merged and an interrupted bench resumed (docs/experiments.md, "Shards, merging, resuming").
/// The summary is made from the run folders as written (report::ReadBenchEpisode): a bench run
/// whole, merged from shards or resumed gives the same summary.csv. With shard_count > 1 no
/// summary is written (files empty). Errors besides the above: InvalidArgument for a shard out
/// of range, `resume` with `force`; FailedPrecondition when `resume` finds another bench (naming
/// what differs) or a folder without bench.json.
Result<BenchSummary> RunBench(const BenchConfig& config, const Registries& registries);

/// `avp bench merge`: the shard folders `shards` (each a complete `avp bench --shard K/N`, or a
/// whole bench) into one bench folder `out_dir`: their run folders copied under runs/, then
/// bench.json, summary.md, summary.csv, plots and report.html as RunBench writes them. `out_dir`
/// has the bench folder's lifecycle (refused when it holds results unless `force`). Errors:
/// InvalidArgument for no shard, a shard given twice, shards of different benches (naming the
/// two folders and what differs: configuration, job list, shard count, revision), a job missing
/// from every shard or present in two (naming it and how many more), `out_dir` inside a shard or
/// a shard inside it; FailedPrecondition for a shard that is not complete (resume it first) or
/// has no bench.json; IoError naming a file that cannot be copied or written.
Result<BenchSummary> MergeBenches(const std::vector<std::filesystem::path>& shards,
                                  const std::filesystem::path& out_dir, bool force,
                                  bool progress = true);

/// The bench of one condition: out_dir/<name>, the condition's run keys applied over the base
/// (after the bench's own), its planner options after the bench's, its description appended, no
/// conditions. InvalidArgument naming the condition and the key for a bad run key.
Result<BenchConfig> ConditionBenchConfig(const BenchConfig& config, const BenchCondition& c);

struct ConditionsSummary {
  /// Per condition, in order: its name and its bench's summary.
  std::vector<std::pair<std::string, BenchSummary>> benches;
  report::ConditionTables tables;
  size_t episodes = 0, failed = 0;
  double seconds = 0.0;
};

/// Runs the bench once per condition (config.conditions, in order), each a complete bench folder
/// out_dir/<name>/ (RunBench), then writes conditions.md and conditions.csv into out_dir
/// (report::WriteConditionTables, the first planner as the lead). out_dir has the output folder
/// lifecycle (kind "bench-conditions"): refused when it holds results unless config.force.
/// Every condition is validated before the first episode runs. A condition whose bench fails
/// stops the run with its error, naming it.
Result<ConditionsSummary> RunBenchConditions(const BenchConfig& config,
                                             const Registries& registries);

}  // namespace avp::experiment

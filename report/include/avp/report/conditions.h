#pragma once
// Benches under conditions (detector misses, depth noise, voxel size, ...) side by side: the
// final F1 and fruits found of each planner per condition and scenario, and how far the lead
// planner is ahead of each other one, paired by seed (docs/experiments.md, "Conditions").

#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/eval/statistics.h>
#include <avp/report/bench_summary.h>

namespace avp::report {

/// One episode of a bench folder as read back from runs/<scenario>/<planner>/seed-<n>/
/// (record.json, metrics.csv, avp-state.json).
struct BenchRunResult {
  std::string scenario, planner;
  uint64_t seed = 0;
  /// Complete and not ended by a segmenter fault (the bench's own rule for its statistics).
  bool ok = false;
  std::string error;  ///< why not, when !ok
  int views = 0;      ///< fused views (rows of metrics.csv)
  /// At the final view.
  double f1 = std::numeric_limits<double>::quiet_NaN();
  double found_fraction = std::numeric_limits<double>::quiet_NaN();
};

/// Every run folder of the bench folder `bench_dir`, in path order. Errors: NotFound when it has
/// no runs/ folder; InvalidArgument naming a folder under runs/<scenario>/<planner>/ that is not
/// seed-<n>; ParseError naming the file for a record.json or metrics.csv that is not one avp
/// wrote (a missing column, a bad number). A run that failed or never finished is returned
/// with ok = false and its state as the error.
Result<std::vector<BenchRunResult>> ReadBenchRuns(const std::filesystem::path& bench_dir);

/// One run folder of a bench (`run_dir`, runs/<scenario>/<planner>/seed-<n>) read back whole, as
/// the bench's summary needs it: the metrics of every view (metrics.csv's columns from the first
/// metric up to known_voxels, at its 9 significant digits), the plan times, the episode's seconds,
/// its fruits and its regret (record.json). The summary of `avp bench`, of `avp bench merge` and
/// of a resumed bench are all made from these, so they agree to the digit. A run that is not
/// complete (its avp-state.json says so, or there is none) comes back with a failed status naming
/// its state and error; so does one its record says ended by a segmenter fault (the bench's rule).
/// Errors: ParseError naming the file for a record.json or metrics.csv that avp did not write, or
/// whose scenario, planner or seed is not the expected one.
Result<BenchEpisode> ReadBenchEpisode(const std::filesystem::path& run_dir,
                                      const std::string& scenario, const std::string& planner,
                                      uint64_t seed);

/// A bench folder and the condition it ran under.
struct ConditionBench {
  std::string name;
  std::string description;  ///< may be empty
  std::filesystem::path dir;
};

/// One planner under one condition in one scenario: over its successful seeds.
struct ConditionCell {
  std::string condition, scenario, planner;
  size_t failed = 0;
  eval::Summary f1, found, views;
};

/// The lead planner minus another one, seed by seed (the seeds both finished).
struct ConditionLead {
  std::string condition, scenario, planner, versus;
  eval::Summary f1, found;
  /// eval::PairedVerdict of the F1 difference: "ahead", "behind", "tied" or "n/a".
  std::string verdict;
};

struct ConditionTables {
  std::vector<ConditionCell> cells;
  std::vector<ConditionLead> leads;
  /// conditions.md, conditions.csv.
  std::vector<std::filesystem::path> files;
};

/// Reads each condition's bench folder (ReadBenchRuns) and writes into `out_dir`:
///   conditions.csv  condition,scenario,planner,versus,metric,mean,ci95,n — per planner the
///                   metrics f1, fruits_found_fraction and views (versus empty), and per other
///                   planner the lead's paired differences f1_lead and found_lead (versus = it);
///   conditions.md   per scenario a table: conditions as rows, each planner's F1 and fruits
///                   found, the lead's difference over each other planner with its verdict, and
///                   the views the lead planner used; then every comparison the lead does not win.
/// `lead` is the planner compared with the others (it must have run in every condition).
/// Errors: InvalidArgument for no condition, repeated names, a condition, scenario or planner
/// name with a comma, a quote or a line break (conditions.csv's names are unquoted), `out_dir`
/// inside one of the bench folders, or a lead planner missing from a condition; ReadBenchRuns'
/// errors; IoError naming a file that cannot be written.
Result<ConditionTables> WriteConditionTables(const std::filesystem::path& out_dir,
                                             const std::vector<ConditionBench>& conditions,
                                             const std::string& lead);

}  // namespace avp::report

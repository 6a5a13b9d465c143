#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/eval/ground_truth.h>
#include <avp/eval/statistics.h>

namespace avp::report {

/// One ground-truth fruit of a bench episode (eval::FruitResult, at the final view).
struct BenchFruit {
  /// eval::GroundTruth::best_visible_fraction; NaN for a ground truth without it (a file).
  double best_visible_fraction = std::numeric_limits<double>::quiet_NaN();
  /// How visible it was in the episode's fused views (NaN: unknown).
  double episode_visible_fraction = std::numeric_limits<double>::quiet_NaN();
  bool found = false;  ///< at the final view
};

/// One plan step of a bench episode measured with the truth (eval::StepRegret, `avp bench
/// --oracle-regret`).
struct BenchRegret {
  int step = 0;  ///< plan call, from 0: it chose fused view step + 2 (1-based)
  size_t candidates = 0;
  double regret = std::numeric_limits<double>::quiet_NaN();
  size_t chosen_true_rank = 1;
  /// Spearman's correlation of the planner's gain with the true gain; NaN when undefined.
  double rank_correlation = std::numeric_limits<double>::quiet_NaN();
};

/// One episode of a bench as its summary needs it.
struct BenchEpisode {
  std::string scenario, planner;
  uint64_t seed = 0;
  /// Not OK: the episode failed (counted, left out of the statistics).
  Status status;
  /// Per fused view: the metrics (name, value) in MetricsRow's order.
  std::vector<std::vector<std::pair<std::string, double>>> metrics;
  std::vector<double> plan_ms;
  double episode_s = 0.0;
  /// The episode's contacts with the true world (pipeline::SumMotion: every move, the return
  /// home included) and what the straight joint lines would have hit; NaN when unknown.
  double contacts = std::numeric_limits<double>::quiet_NaN();
  double straight_line_contacts = std::numeric_limits<double>::quiet_NaN();
  /// The episode's motion time (the trajectories' durations, s; NaN when unknown) and each
  /// move's planning time.
  double motion_s = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> move_planning_ms;
  /// 1 when the simulator found an object inside the free space assumed around the arm at its
  /// start (record.json motion.start_clearance.broken), 0 when it checked and found none, NaN
  /// when it did not check (straight moves, a real robot, an older record).
  double start_clearance_broken = std::numeric_limits<double>::quiet_NaN();
  /// Every ground-truth fruit of the episode (empty for a ground truth without fruits).
  std::vector<BenchFruit> fruits;
  /// Per plan step with the run configuration's oracle_regret (empty otherwise).
  std::vector<BenchRegret> regret;
};

/// The regret of one (scenario, planner) over every plan step of its successful episodes, all
/// seeds pooled (`avp bench --oracle-regret`; docs/experiments.md).
struct RegretSummary {
  size_t plans = 0;
  /// The median number of ranked candidates a plan had (1 for the predefined planner: its
  /// regret is 0 by definition, and its rank correlation undefined).
  double candidates_median = std::numeric_limits<double>::quiet_NaN();
  /// The mean regret and its 95 % interval (eval::Summary's bootstrap; NaN below two plans).
  double regret_mean = std::numeric_limits<double>::quiet_NaN();
  double regret_lo = std::numeric_limits<double>::quiet_NaN();
  double regret_hi = std::numeric_limits<double>::quiet_NaN();
  /// Plans whose choice was the truly best candidate (chosen_true_rank 1).
  size_t best_chosen = 0;
  double chosen_rank_median = std::numeric_limits<double>::quiet_NaN();
  /// Over the plans where the correlation is defined (`correlated` of them).
  size_t correlated = 0;
  double rank_correlation_median = std::numeric_limits<double>::quiet_NaN();
  double rank_correlation_mean = std::numeric_limits<double>::quiet_NaN();
  double rank_correlation_lo = std::numeric_limits<double>::quiet_NaN();
  double rank_correlation_hi = std::numeric_limits<double>::quiet_NaN();
};

/// RegretSummary of (scenario, planner); plans = 0 when no episode measured its regret.
RegretSummary SummarizeRegret(const std::vector<BenchEpisode>& episodes,
                              const std::string& scenario, const std::string& planner);

/// Fruits of one visibility bin, [lo, hi) (the last bin includes hi = 1): the bins' edges are
/// 0, eval::kVisibleFractionLevels and 1.
struct VisibilityBin {
  double lo = 0.0, hi = 0.0;
  size_t fruits = 0;  ///< over the successful episodes (seeds), pooled
  size_t found = 0;
  /// found / fruits and its Wilson score 95 % interval; NaN when the bin is empty.
  double fraction = std::numeric_limits<double>::quiet_NaN();
  double ci_lo = std::numeric_limits<double>::quiet_NaN();
  double ci_hi = std::numeric_limits<double>::quiet_NaN();
};

/// The fraction of fruits found at the final view per bin of best visible fraction, for the
/// successful episodes of (scenario, planner), every seed's fruits pooled (docs/evaluation.md,
/// "Per-fruit results"). Fruits without a best visible fraction (a file's ground truth) are in
/// no bin. Four bins: [0, 0.05), [0.05, 0.25), [0.25, 0.5), [0.5, 1].
std::vector<VisibilityBin> FoundByVisibility(const std::vector<BenchEpisode>& episodes,
                                             const std::string& scenario,
                                             const std::string& planner);

/// Wilson's score interval of a proportion k / n at 95 % (z = 1.96): {lo, hi}; NaN for n = 0.
std::pair<double, double> WilsonInterval95(size_t k, size_t n);

/// How hidden a scenario's fruits are, over its seeds (eval::GroundTruth::best_visible_fraction):
/// fruits in all, and those whose best visible fraction reaches each of
/// eval::kVisibleFractionLevels. Empty (0 fruits) for ground truths read from files.
struct FruitVisibility {
  double fruits = 0.0;
  std::array<double, eval::kVisibleFractionLevels.size()> visible{};
  /// Adds one ground truth's fruits.
  void Add(const eval::GroundTruth& gt);
};

/// What the summary says about the bench besides its episodes.
struct BenchDescription {
  std::vector<std::string> scenarios, planners;
  size_t seeds = 0;
  int views = 0;
  std::string segmenter;
  double voxel_size_m = 0.0;
  std::string revision;
  /// Per planner, its options over the registered defaults (none: not listed).
  std::map<std::string, OptionValues> planner_options;
  /// The bench's one-line description (may be empty).
  std::string description;
  /// The episodes' run configuration where it differs from the defaults (KEY = VALUE).
  OptionValues run_options;
  std::map<std::string, FruitVisibility> visibility;  ///< by scenario
};

/// The final view of one (scenario, planner): the mean over seeds and its 95 % interval
/// (eval::Summary's bootstrap, within [0, 1]; NaN below two seeds).
struct BenchCell {
  std::string scenario, planner;
  size_t runs = 0;
  double final_f1_mean = 0.0;
  double final_f1_lo = std::numeric_limits<double>::quiet_NaN();
  double final_f1_hi = std::numeric_limits<double>::quiet_NaN();
  double final_found_mean = 0.0;
  double final_found_lo = std::numeric_limits<double>::quiet_NaN();
  double final_found_hi = std::numeric_limits<double>::quiet_NaN();
  double fruits_total_mean = 0.0;
  double plan_ms_mean = 0.0, episode_s_mean = 0.0;
  size_t failed = 0;
};

/// The lead planner (the bench's first) minus another one at the final view, seed by seed over
/// the seeds both finished: F1 and the fraction of fruits found, each a mean with its 95 %
/// interval (within [-1, 1]), and eval::PairedVerdict of the F1 difference.
struct PairedLead {
  std::string scenario, planner, versus;
  eval::Summary f1, found;
  /// "ahead", "tied", "behind" or "n/a" (below two paired seeds).
  std::string verdict;
};

/// The lead's PairedLead over each other planner of `planners` in `scenario` (none with fewer than
/// two planners); `planners.front()` leads.
std::vector<PairedLead> PairedLeads(const std::vector<BenchEpisode>& episodes,
                                    const std::string& scenario,
                                    const std::vector<std::string>& planners);

struct BenchTables {
  std::vector<BenchCell> cells;
  /// Per scenario, the lead's paired difference over each other planner (two planners or more).
  std::vector<PairedLead> leads;
  /// summary.md, summary.csv, fruits_by_visibility.csv, then the plots.
  std::vector<std::filesystem::path> files;
  size_t failed = 0;
};

/// Writes the bench's summary into `out_dir` (docs/experiments.md): summary.csv (long format:
/// scenario, planner, versus, segmenter, view, metric, mean, ci_lo, ci_hi, n, the interval
/// eval::Summary's bootstrap, nan below two seeds; with two planners or more, the lead's paired
/// differences at the final view as rows with `versus` set: metrics f1 and
/// fruits_found_fraction; an episode that ended early keeps
/// its last metrics for the remaining views; with regret measured, also the metrics
/// oracle_regret, oracle_rank_correlation and oracle_chosen_rank at the view each plan chose, and
/// per (scenario, planner) the same three pooled over every plan at view 0),
/// fruits_by_visibility.csv (FoundByVisibility per scenario, planner and bin), summary.md (the
/// final view per planner, how hidden the fruits are, the fraction found per visibility bin, F1
/// per view, the regret table when measured), and per scenario f1_<s>.svg and
/// fruits_<s>.svg (mean and 95 % interval per planner, the paper's Fig. 3; small n marked), and
/// the paired leads in summary.md. `seconds` is the bench's wall
/// time so far.
Result<BenchTables> WriteBenchSummary(const std::filesystem::path& out_dir,
                                      const BenchDescription& bench,
                                      const std::vector<BenchEpisode>& episodes, double seconds);

/// `s` with every character other than letters, digits, '-', '_' and '.' replaced by '_' (file
/// and folder names from scenario and planner names).
std::string SafeFileName(std::string s);

}  // namespace avp::report

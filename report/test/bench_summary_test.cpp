// The bench summary's per-fruit results: fruits binned by best visible fraction (the edges of
// eval::kVisibleFractionLevels), the fraction found per bin with Wilson's interval, and the
// fruits_by_visibility.csv / summary.md table WriteBenchSummary writes from them.
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/report/bench_summary.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::report {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

std::string ReadAll(const fs::path& p) { return test::ReadWholeFile(p); }

/// A successful episode of one view with fruits (best visible fraction, found).
BenchEpisode Episode(const std::string& planner, uint64_t seed,
                     const std::vector<std::pair<double, bool>>& fruits) {
  BenchEpisode e;
  e.scenario = "s";
  e.planner = planner;
  e.seed = seed;
  e.metrics = {{{"f1", 0.5}, {"fruits_found_fraction", 0.5}}};
  for (const auto& [v, found] : fruits)
    e.fruits.push_back({.best_visible_fraction = v, .found = found});
  return e;
}

TEST(BenchSummaryTest, WilsonIntervalMatchesHandComputedValues) {
  // k = 0, n = 10: [0, z^2 / (n + z^2)] = [0, 0.27753].
  auto [lo, hi] = WilsonInterval95(0, 10);
  EXPECT_DOUBLE_EQ(lo, 0.0);
  EXPECT_NEAR(hi, 1.96 * 1.96 / (10 + 1.96 * 1.96), 1e-12);
  // k = 5, n = 10: 0.5 +- 1.96 sqrt(0.025 + 0.0009604) / 1.38416 = [0.23659, 0.76341].
  std::tie(lo, hi) = WilsonInterval95(5, 10);
  EXPECT_NEAR(lo, 0.2365896, 1e-6);
  EXPECT_NEAR(hi, 0.7634104, 1e-6);
  // k = n = 4: [n / (n + z^2), 1] = [0.51007, 1].
  std::tie(lo, hi) = WilsonInterval95(4, 4);
  EXPECT_NEAR(lo, 4.0 / (4.0 + 1.96 * 1.96), 1e-12);
  EXPECT_DOUBLE_EQ(hi, 1.0);
  std::tie(lo, hi) = WilsonInterval95(0, 0);
  EXPECT_TRUE(std::isnan(lo) && std::isnan(hi));
}

TEST(BenchSummaryTest, FruitsAreBinnedByBestVisibleFractionOverSeeds) {
  const std::vector<BenchEpisode> episodes = {
      // Bin edges: 0.05 and 0.25 and 0.5 open the next bin; 1.0 is in the last one.
      Episode("a", 0, {{0.0, false}, {0.049, true}, {0.05, false}, {0.25, true}, {0.5, true}}),
      Episode("a", 1, {{0.2, true}, {0.49, false}, {1.0, true}, {NAN, true}}),
      Episode("b", 0, {{0.9, false}}),
  };
  BenchEpisode failed = Episode("a", 2, {{0.9, true}, {0.9, true}});
  failed.status = InternalError("it failed");  // left out, as from every other statistic
  std::vector<BenchEpisode> all = episodes;
  all.push_back(failed);
  const std::vector<VisibilityBin> a = FoundByVisibility(all, "s", "a");
  ASSERT_EQ(a.size(), 4u);
  EXPECT_DOUBLE_EQ(a[0].lo, 0.0);
  EXPECT_DOUBLE_EQ(a[0].hi, 0.05);
  EXPECT_DOUBLE_EQ(a[3].lo, 0.5);
  EXPECT_DOUBLE_EQ(a[3].hi, 1.0);
  // [0, 0.05): 0.0, 0.049; [0.05, 0.25): 0.05, 0.2; [0.25, 0.5): 0.25, 0.49; [0.5, 1]: 0.5, 1.0.
  // The NaN fruit (a file's ground truth) is in no bin.
  const size_t fruits[] = {2, 2, 2, 2};
  const size_t found[] = {1, 1, 1, 2};
  size_t total = 0;
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(a[i].fruits, fruits[i]) << i;
    EXPECT_EQ(a[i].found, found[i]) << i;
    EXPECT_DOUBLE_EQ(a[i].fraction, static_cast<double>(found[i]) / 2.0) << i;
    const auto [lo, hi] = WilsonInterval95(found[i], fruits[i]);
    EXPECT_DOUBLE_EQ(a[i].ci_lo, lo);
    EXPECT_DOUBLE_EQ(a[i].ci_hi, hi);
    total += a[i].fruits;
  }
  EXPECT_EQ(total, 8u);  // 9 fruits of the two successful episodes, less the NaN one
  const std::vector<VisibilityBin> b = FoundByVisibility(all, "s", "b");
  EXPECT_EQ(b[3].fruits, 1u);
  EXPECT_EQ(b[3].found, 0u);
  EXPECT_EQ(b[0].fruits, 0u);
  EXPECT_TRUE(std::isnan(b[0].fraction));
}

/// Scenario "s", planners "a" and "b", two seeds, the oracle, 5 mm voxels, `views` views.
BenchDescription TwoPlannerBench(int views) {
  BenchDescription d;
  d.scenarios = {"s"};
  d.planners = {"a", "b"};
  d.seeds = 2;
  d.views = views;
  d.segmenter = "oracle";
  d.voxel_size_m = 0.005;
  return d;
}

class BenchSummaryFilesTest : public test::TempDirTest {};

TEST_F(BenchSummaryFilesTest, WritesTheVisibilityCsvAndTable) {
  const BenchDescription d = TwoPlannerBench(1);
  const std::vector<BenchEpisode> episodes = {
      Episode("a", 0, {{0.01, false}, {0.3, true}, {0.7, true}}),
      Episode("a", 1, {{0.02, false}, {0.6, false}}),
      Episode("b", 0, {{0.7, true}}),
  };
  auto t = WriteBenchSummary(dir_, d, episodes, 1.0);
  ASSERT_TRUE(t.ok()) << t.status().ToString();
  const std::string csv = ReadAll(dir_ / "fruits_by_visibility.csv");
  EXPECT_EQ(csv,
            "scenario,planner,segmenter,visible_from,visible_to,fruits,found,fraction,wilson_lo,"
            "wilson_hi\n"
            "s,a,oracle,0,0.05,2,0,0,0,0.657628047\n"
            "s,a,oracle,0.05,0.25,0,0,nan,nan,nan\n"
            "s,a,oracle,0.25,0.5,1,1,1,0.206543291,1\n"
            "s,a,oracle,0.5,1,2,1,0.5,0.0945286548,0.905471345\n"
            "s,b,oracle,0,0.05,0,0,nan,nan,nan\n"
            "s,b,oracle,0.05,0.25,0,0,nan,nan,nan\n"
            "s,b,oracle,0.25,0.5,0,0,nan,nan,nan\n"
            "s,b,oracle,0.5,1,1,1,1,0.206543291,1\n");
  const std::string md = ReadAll(dir_ / "summary.md");
  EXPECT_THAT(md,
              HasSubstr("| planner | [0.00, 0.05) | [0.05, 0.25) | [0.25, 0.50) | [0.50, 1.00] |"));
  EXPECT_THAT(md, HasSubstr("| a | 0 / 2 = 0.00 [0.00, 0.66] | – | 1 / 1 = 1.00 [0.21, 1.00] | "
                            "1 / 2 = 0.50 [0.09, 0.91] |"));
  EXPECT_THAT(md, HasSubstr("| b | – | – | – | 1 / 1 = 1.00 [0.21, 1.00] |"));
  ASSERT_GE(t->files.size(), 3u);
  EXPECT_EQ(t->files[2], dir_ / "fruits_by_visibility.csv");
}

/// Motion per episode (docs/motion.md): contacts and the straight line's, motion time, each
/// move's planning time, in summary.md's table and summary.csv on the last view's line; an
/// episode whose record has no motion (an older one) adds nothing.
TEST_F(BenchSummaryFilesTest, WritesContactsAndMotionTimePerEpisode) {
  const BenchDescription d = TwoPlannerBench(1);
  BenchEpisode a0 = Episode("a", 0, {{0.5, true}});
  a0.contacts = 0;
  a0.straight_line_contacts = 5;
  a0.motion_s = 10;
  a0.move_planning_ms = {1, 3};
  a0.start_clearance_broken = 1;
  BenchEpisode a1 = Episode("a", 1, {{0.5, true}});
  a1.contacts = 2;
  a1.straight_line_contacts = 3;
  a1.motion_s = 20;
  a1.move_planning_ms = {2};
  a1.start_clearance_broken = 0;
  const std::vector<BenchEpisode> episodes = {a0, a1, Episode("b", 0, {{0.5, true}})};
  ASSERT_TRUE(WriteBenchSummary(dir_, d, episodes, 1.0).ok());
  const std::string md = ReadAll(dir_ / "summary.md");
  EXPECT_THAT(md, HasSubstr("contacts/episode (straight line) | motion s |"));
  EXPECT_THAT(md, HasSubstr("| 1.00, at most 2 (4.00); start clearance broken in 1 | 15.0 |"))
      << md;
  EXPECT_THAT(md, HasSubstr("| – | – |")) << md;  // b: no motion recorded
  const std::string csv = ReadAll(dir_ / "summary.csv");
  EXPECT_THAT(csv, HasSubstr("s,a,oracle,1,contacts,1,"));
  EXPECT_THAT(csv, HasSubstr("s,a,oracle,1,straight_line_contacts,4,"));
  EXPECT_THAT(csv, HasSubstr("s,a,oracle,1,motion_s,15,"));
  EXPECT_THAT(csv, HasSubstr("s,a,oracle,1,start_clearance_broken,0.5,"));
  EXPECT_THAT(csv, Not(HasSubstr("planning_ms")));  // wall times: not reproducible
  EXPECT_THAT(csv, Not(HasSubstr("s,b,oracle,1,contacts")));
}

/// Regret per plan step: pooled per (scenario, planner), per view in summary.csv, a table in
/// summary.md; planners without measurements have no rows.
TEST_F(BenchSummaryFilesTest, WritesTheRegretOfEachPlanStep) {
  const BenchDescription d = TwoPlannerBench(3);
  const auto nan = std::nan("");
  auto episode = [&](const std::string& planner, uint64_t seed, std::vector<BenchRegret> regret) {
    BenchEpisode e = Episode(planner, seed, {});
    e.metrics.resize(3, e.metrics.front());
    e.regret = std::move(regret);
    return e;
  };
  const std::vector<BenchEpisode> episodes = {
      episode("a", 0,
              {{.step = 0, .regret = 0.0, .chosen_true_rank = 1, .rank_correlation = 0.5},
               {.step = 1, .regret = 0.5, .chosen_true_rank = 4, .rank_correlation = 0.1}}),
      episode("a", 1,
              {{.step = 0, .regret = 0.2, .chosen_true_rank = 2, .rank_correlation = nan},
               {.step = 1, .regret = 0.1, .chosen_true_rank = 3, .rank_correlation = 0.3}}),
      episode("b", 0, {}),
  };
  const RegretSummary r = SummarizeRegret(episodes, "s", "a");
  EXPECT_EQ(r.plans, 4u);
  EXPECT_DOUBLE_EQ(r.regret_mean, 0.2);
  EXPECT_EQ(r.best_chosen, 1u);
  EXPECT_DOUBLE_EQ(r.chosen_rank_median, 2.5);
  EXPECT_EQ(r.correlated, 3u);  // the NaN left out
  EXPECT_DOUBLE_EQ(r.rank_correlation_median, 0.3);
  EXPECT_NEAR(r.rank_correlation_mean, 0.3, 1e-12);
  EXPECT_EQ(SummarizeRegret(episodes, "s", "b").plans, 0u);

  auto t = WriteBenchSummary(dir_, d, episodes, 1.0);
  ASSERT_TRUE(t.ok()) << t.status().ToString();
  const std::string csv = ReadAll(dir_ / "summary.csv");
  // view 0: every plan pooled; views 2 and 3: the plans that chose them.
  EXPECT_THAT(csv, HasSubstr("s,a,oracle,0,oracle_regret,0.2,"));
  // Two plans: the interval is theirs; one: none (nan).
  EXPECT_THAT(csv, HasSubstr("s,a,oracle,2,oracle_regret,0.1,0,0.2,2,\n"));
  EXPECT_THAT(csv, HasSubstr("s,a,oracle,3,oracle_regret,0.3,0.1,0.5,2,\n"));
  EXPECT_THAT(csv, HasSubstr("s,a,oracle,2,oracle_rank_correlation,0.5,nan,nan,1,\n"));
  EXPECT_THAT(csv, HasSubstr("s,a,oracle,0,oracle_chosen_rank,2.5,"));
  EXPECT_THAT(csv, Not(HasSubstr("s,b,oracle,0,oracle_regret")));
  EXPECT_THAT(csv, Not(HasSubstr(",1,oracle_regret")));
  const std::string md = ReadAll(dir_ / "summary.md");
  EXPECT_DOUBLE_EQ(r.candidates_median, 0.0);  // the hand-made plans say none
  EXPECT_THAT(md, HasSubstr("| a | 4 | 0 | 0.200 ["));
  EXPECT_THAT(md, HasSubstr(" | 1 / 4 | 2 | 0.300 | 0.300 ["));
  EXPECT_THAT(md, Not(HasSubstr("| b | 0 |")));
}

}  // namespace
}  // namespace avp::report

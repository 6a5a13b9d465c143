// Benches under conditions side by side: runs read back from bench folders, paired leads.
#include "avp/report/conditions.h"

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::report {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

class ConditionTablesTest : public test::TempDirTest {
 protected:
  /// One run folder as avp bench writes it: record.json and metrics.csv with the F1 of each view
  /// (the found fraction is F1 / 2).
  void Run(const std::string& bench, const std::string& scenario, const std::string& planner,
           uint64_t seed, const std::vector<double>& f1) {
    const fs::path d = dir_ / bench / "runs" / scenario / planner / fmt::format("seed-{}", seed);
    fs::create_directories(d);
    std::ofstream(d / "record.json") << fmt::format(
        R"({{"scenario": "{}", "planner": "{}", "seed": {}, "end": "budget-reached"}})", scenario,
        planner, seed);
    std::ofstream csv(d / "metrics.csv");
    csv << "view,f1,precision,fruits_found_fraction,status\n";
    for (size_t v = 0; v < f1.size(); ++v) {
      csv << fmt::format("{},{},0.5,{},ok\n", v + 1, f1[v], f1[v] / 2);
    }
  }
};

TEST_F(ConditionTablesTest, PairsTheLeadWithEachPlannerSeedBySeed) {
  // easy: avp-nbv 0.30 above "other" on average (0.30, 0.32, 0.28, 0.30), 3 views;
  // hard: differences 0.1, -0.1, 0.05 (seed 3 of "other" failed), 2 views.
  const double easy_lead[] = {0.30, 0.32, 0.28, 0.30};
  const double hard_lead[] = {0.1, -0.1, 0.05};
  for (uint64_t s = 0; s < 4; ++s) {
    const double base = 0.2 + 0.05 * s;
    Run("easy", "plant", "avp-nbv", s, {0.0, 0.1, base + easy_lead[s]});
    Run("easy", "plant", "other", s, {0.0, 0.1, base});
    Run("easy", "plant", "worse", s, {0.0, base + 0.2 + 0.01 * s});
    Run("hard", "plant", "avp-nbv", s, {0.0, base + (s < 3 ? hard_lead[s] : 0.0)});
    if (s < 3) Run("hard", "plant", "other", s, {0.0, base});
    Run("hard", "plant", "worse", s, {0.0, base});
  }
  const fs::path failed = dir_ / "hard/runs/plant/other/seed-3";
  fs::create_directories(failed);
  std::ofstream(failed / "avp-state.json") << R"({"state": "failed", "error": "boom"})";

  const auto runs = ReadBenchRuns(dir_ / "hard");
  ASSERT_TRUE(runs.ok()) << runs.status().ToString();
  ASSERT_EQ(runs->size(), 12u);
  EXPECT_EQ(runs->at(4).planner, "other");
  EXPECT_EQ(runs->at(7).seed, 3u);
  EXPECT_FALSE(runs->at(7).ok);
  EXPECT_EQ(runs->at(7).error, "state failed: boom");
  EXPECT_EQ(runs->at(0).views, 2);
  EXPECT_DOUBLE_EQ(runs->at(0).f1, 0.3);
  EXPECT_DOUBLE_EQ(runs->at(0).found_fraction, 0.15);

  const auto t = WriteConditionTables(
      dir_, {{"easy", "nothing changed", dir_ / "easy"}, {"hard", "", dir_ / "hard"}}, "avp-nbv");
  ASSERT_TRUE(t.ok()) << t.status().ToString();
  ASSERT_EQ(t->cells.size(), 6u);
  ASSERT_EQ(t->leads.size(), 4u);
  const ConditionLead& easy_other = t->leads[0];
  EXPECT_EQ(easy_other.condition, "easy");
  EXPECT_EQ(easy_other.versus, "other");
  EXPECT_EQ(easy_other.f1.n, 4u);
  EXPECT_NEAR(easy_other.f1.mean, 0.30, 1e-12);
  EXPECT_NEAR(easy_other.found.mean, 0.15, 1e-12);
  EXPECT_EQ(easy_other.verdict, "ahead");
  // vs "worse": 0.30 + d - (0.2 + 0.01 s) with d = 0.30, 0.32, 0.28, 0.30 minus 0.2: ~0.09.
  EXPECT_EQ(t->leads[1].versus, "worse");
  EXPECT_NEAR(t->leads[1].f1.mean, (0.10 + 0.11 + 0.06 + 0.07) / 4, 1e-12);
  const ConditionLead& hard_other = t->leads[2];
  EXPECT_EQ(hard_other.f1.n, 3u);  // seed 3 failed for "other"
  EXPECT_NEAR(hard_other.f1.mean, 0.05 / 3, 1e-12);
  EXPECT_EQ(hard_other.verdict, "tied");
  // The lead's cells: views and the failed run.
  EXPECT_EQ(t->cells[0].planner, "avp-nbv");
  EXPECT_DOUBLE_EQ(t->cells[0].views.mean, 3.0);
  EXPECT_EQ(t->cells[4].condition, "hard");
  EXPECT_EQ(t->cells[4].planner, "other");
  EXPECT_EQ(t->cells[4].failed, 1u);
  EXPECT_EQ(t->cells[4].f1.n, 3u);

  const std::string md = test::ReadWholeFile(dir_ / "conditions.md");
  EXPECT_THAT(md, HasSubstr("| easy | `"));
  EXPECT_THAT(md, HasSubstr("| nothing changed |"));
  // Paired interval of 0.30, 0.32, 0.28, 0.30: within [0.28, 0.32], above 0.
  EXPECT_THAT(md, HasSubstr("| +0.300 [+0.2"));
  EXPECT_THAT(md, HasSubstr("] **ahead** |"));
  EXPECT_GE(easy_other.f1.ci_lo, 0.28);
  EXPECT_LE(easy_other.f1.ci_hi, 0.32);
  EXPECT_THAT(md, HasSubstr("(1 failed)"));
  EXPECT_THAT(md, HasSubstr("`avp-nbv` is ahead in 2 of 4 comparisons"));
  EXPECT_THAT(md, HasSubstr("- hard, plant, vs other: F1 +0.017"));
  const std::string csv = test::ReadWholeFile(dir_ / "conditions.csv");
  EXPECT_THAT(csv, HasSubstr("condition,scenario,planner,versus,metric,mean,ci_lo,ci_hi,n\n"));
  EXPECT_THAT(csv, HasSubstr("\neasy,plant,avp-nbv,,views,3,3,3,4\n"));
  EXPECT_THAT(csv, HasSubstr("\neasy,plant,avp-nbv,other,f1_lead,0.3,"));
  EXPECT_THAT(csv, HasSubstr("\nhard,plant,other,,f1,"));
}

TEST(LeadVerdictTest, NeedsTheWholeIntervalOnOneSide) {
  eval::Summary d;
  d.n = 5;
  d.mean = 0.1;
  d.ci_lo = 0.05;
  d.ci_hi = 0.15;
  EXPECT_EQ(eval::PairedVerdict(d), "ahead");
  d.ci_lo = -0.05;
  EXPECT_EQ(eval::PairedVerdict(d), "tied");
  d.mean = -0.2;
  d.ci_lo = -0.3;
  d.ci_hi = -0.1;
  EXPECT_EQ(eval::PairedVerdict(d), "behind");
  d.n = 1;
  EXPECT_EQ(eval::PairedVerdict(d), "n/a");
}

TEST_F(ConditionTablesTest, BadFoldersAreErrorsNamingThem) {
  const auto none = ReadBenchRuns(dir_ / "nothing");
  ASSERT_FALSE(none.ok());
  EXPECT_THAT(none.status().message(), HasSubstr("nothing' is not an avp bench folder"));

  Run("a", "plant", "avp-nbv", 0, {0.1});
  std::ofstream(dir_ / "a/runs/plant/avp-nbv/seed-0/metrics.csv")
      << "view,f1,fruits_found_fraction\n1,0.1,0.2\n2,x,0.3\n";
  const auto bad = ReadBenchRuns(dir_ / "a");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("metrics.csv: row 3: column f1 ('x')"));
  std::ofstream(dir_ / "a/runs/plant/avp-nbv/seed-0/metrics.csv") << "view,f1\n1,0.1\n";
  EXPECT_THAT(ReadBenchRuns(dir_ / "a").status().message(),
              HasSubstr("no column 'fruits_found_fraction'"));

  Run("b", "plant", "other", 0, {0.1});
  EXPECT_THAT(WriteConditionTables(dir_, {{"b", "", dir_ / "b"}}, "avp-nbv").status().message(),
              HasSubstr("the lead planner 'avp-nbv' has no run in condition 'b'"));
  EXPECT_THAT(WriteConditionTables(dir_, {{"b", "", dir_ / "b"}, {"b", "", dir_ / "b"}}, "other")
                  .status()
                  .message(),
              HasSubstr("the condition 'b' is given twice"));
  EXPECT_FALSE(WriteConditionTables(dir_, {}, "other").ok());

  // conditions.csv writes names unquoted: a comma in a name is refused, naming it.
  const fs::path out = dir_ / "tables";
  EXPECT_THAT(WriteConditionTables(out, {{"b,c", "", dir_ / "b"}}, "other").status().message(),
              HasSubstr("the condition name 'b,c' holds a comma"));
  Run("q", "plant,x", "other", 0, {0.1});
  EXPECT_THAT(WriteConditionTables(out, {{"q", "", dir_ / "q"}}, "other").status().message(),
              HasSubstr("the scenario name 'plant,x' holds a comma"));
  // The tables never go into a bench folder they read (nor into one of its subfolders).
  for (const fs::path& inside : {dir_ / "b", dir_ / "b" / "runs", dir_ / "b" / "." / "new"}) {
    EXPECT_THAT(WriteConditionTables(inside, {{"b", "", dir_ / "b"}}, "other").status().message(),
                HasSubstr("is inside the bench folder"))
        << inside;
  }
  EXPECT_TRUE(WriteConditionTables(dir_ / "b-tables", {{"b", "", dir_ / "b"}}, "other").ok());
  EXPECT_TRUE(fs::exists(dir_ / "b-tables" / "conditions.csv"));

  // A folder among the seeds that is not seed-<n> is an error naming it, not seed 0.
  for (const std::string name : {"seed-", "seed-x", "seed-1a", "notes"}) {
    fs::create_directories(dir_ / "b/runs/plant/other" / name);
    const auto stray = ReadBenchRuns(dir_ / "b");
    ASSERT_FALSE(stray.ok()) << name;
    EXPECT_THAT(stray.status().message(), HasSubstr(name + "' is not a run folder")) << name;
    fs::remove(dir_ / "b/runs/plant/other" / name);
  }
  Run("b", "plant", "other", 17, {0.3});
  const auto two = ReadBenchRuns(dir_ / "b");
  ASSERT_TRUE(two.ok()) << two.status().message();
  ASSERT_EQ(two->size(), 2u);
  EXPECT_EQ((*two)[1].seed, 17u);
}

}  // namespace
}  // namespace avp::report

// `avp bench` writes report.html beside summary.md (experiment::RunBench): a tiny real bench, 2
// scenarios x 2 planners x 2 seeds x 3 views, whose page data carries exactly summary.csv's and
// fruits_by_visibility.csv's numbers and links every episode's run folder.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/experiment/bench.h>
#include <avp/report/bench_html.h>
#include <avp/test/temp_dir_test.h>

namespace avp::experiment {
namespace {

namespace fs = std::filesystem;
using ::testing::Contains;

std::vector<std::vector<std::string>> CsvRows(const fs::path& p) {
  std::vector<std::vector<std::string>> rows;
  std::ifstream in(p);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    rows.push_back(cells);
  }
  return rows;
}

/// summary.csv's number format.
std::string G9(const nlohmann::json& v) {
  if (v.is_null()) return "nan";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v.get<double>());
  return buf;
}

/// Every row of summary.csv (scenario,planner,segmenter,view,metric,mean,ci_lo,ci_hi,n,versus)
/// is in the page: the per-view rows in its planners, the lead's rows (versus set) in its leads.
void ExpectSummaryCsvEqualsPage(
    const fs::path& csv, const nlohmann::json& data,
    const std::map<std::pair<std::string, std::string>, const nlohmann::json*>& planners) {
  // The lead's paired differences, by (scenario, versus).
  std::map<std::pair<std::string, std::string>, const nlohmann::json*> leads;
  for (const nlohmann::json& s : data["scenarios"]) {
    ASSERT_EQ(s["leads"].size(), 1u);
    for (const nlohmann::json& l : s["leads"]) {
      leads[{s["name"].get<std::string>(), l["versus"].get<std::string>()}] = &l;
    }
  }
  // summary.csv: scenario,planner,segmenter,view,metric,mean,ci_lo,ci_hi,n,versus; every row is in
  // the page, the lead's rows (versus set) too.
  size_t rows = 0, lead_rows = 0;
  for (std::vector<std::string> c : CsvRows(csv)) {
    if (c.size() == 9) c.emplace_back();  // CsvRows drops a trailing empty field (no `versus`)
    ASSERT_EQ(c.size(), 10u);
    const std::string where = c[0] + " " + c[1] + " " + c[4] + " " + c[3];
    if (!c[9].empty()) {
      const nlohmann::json& l = *leads.at({c[0], c[9]});
      const nlohmann::json& d = c[4] == "f1_lead" ? l["f1"] : l["found"];
      EXPECT_EQ(c[3], "3") << where;
      EXPECT_EQ(G9(d["mean"]), c[5]) << where;
      EXPECT_EQ(G9(d["ci_lo"]), c[6]) << where;
      EXPECT_EQ(G9(d["ci_hi"]), c[7]) << where;
      EXPECT_EQ(std::to_string(d["n"].get<size_t>()), c[8]) << where;
      ++lead_rows;
      continue;
    }
    // The episode's motion rows (contacts, motion time: per episode, docs/motion.md) are in
    // summary.md, not in the page's per-view data.
    if (c[4] == "contacts" || c[4] == "straight_line_contacts" || c[4] == "motion_s") continue;
    const nlohmann::json& pv = (*planners.at({c[0], c[1]}))["per_view"];
    ASSERT_TRUE(pv.contains(c[4])) << c[4];
    const size_t v = std::stoul(c[3]) - 1;
    EXPECT_EQ(G9(pv[c[4]]["mean"][v]), c[5]) << where;
    EXPECT_EQ(G9(pv[c[4]]["ci_lo"][v]), c[6]) << where;
    EXPECT_EQ(G9(pv[c[4]]["ci_hi"][v]), c[7]) << where;
    EXPECT_EQ(std::to_string(pv[c[4]]["n"][v].get<size_t>()), c[8]);
    // A fraction's interval stays within [0, 1].
    if (c[4] == "f1" || c[4] == "fruits_found_fraction") {
      EXPECT_GE(std::stod(c[6]), 0.0) << where;
      EXPECT_LE(std::stod(c[7]), 1.0) << where;
    }
    ++rows;
  }
  // 4 (scenario, planner) x the metrics x 3 views; per scenario the lead's F1 and found rows.
  EXPECT_EQ(rows, 4u * data["metrics"].size() * 3u);
  EXPECT_EQ(lead_rows, 2u * 2u);
  EXPECT_GT(rows, 4u * 3u * 10u);
}

class BenchReportTest : public test::TempDirTest {
 protected:
  const Registries registries_ = BuiltinRegistries();
};

TEST_F(BenchReportTest, ReportDataEqualsTheSummaryAndLinksEveryRun) {
  BenchConfig o;
  o.scenarios = {"tomato-single-cluster", "tomato-full-occlusion"};
  o.planners = {"random", "predefined"};
  o.seeds = {0, 1};
  o.base.episode.views = 3;
  o.out_dir = dir_ / "bench";
  o.progress = false;
  const Result<BenchSummary> r = RunBench(o, registries_);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->failed, 0u);
  EXPECT_EQ(r->report_html, o.out_dir / "report.html");
  EXPECT_THAT(r->files, Contains(o.out_dir / "report.html"));
  const Result<nlohmann::json> data = report::ReadBenchReportData(r->report_html);
  ASSERT_TRUE(data.ok()) << data.status().ToString();
  EXPECT_EQ((*data)["bench"]["views"], 3);
  EXPECT_EQ((*data)["bench"]["seeds"], 2);
  EXPECT_EQ((*data)["bench"]["episodes"], 8);
  ASSERT_EQ((*data)["scenarios"].size(), 2u);

  std::map<std::pair<std::string, std::string>, const nlohmann::json*> planners;
  for (const nlohmann::json& s : (*data)["scenarios"]) {
    ASSERT_EQ(s["planners"].size(), 2u);
    for (const nlohmann::json& p : s["planners"]) {
      planners[{s["name"].get<std::string>(), p["name"].get<std::string>()}] = &p;
      EXPECT_EQ(p["n"], 2);
      // Every episode links its run folder, which holds its record and metrics.
      ASSERT_EQ(p["runs"].size(), 2u);
      for (const nlohmann::json& run : p["runs"]) {
        EXPECT_TRUE(run["ok"].get<bool>());
        const fs::path folder = o.out_dir / run["folder"].get<std::string>();
        EXPECT_TRUE(fs::is_regular_file(folder / "record.json")) << folder;
        EXPECT_THAT(run["files"], Contains("record.json"));
        EXPECT_THAT(run["files"], Contains("metrics.csv"));
      }
    }
  }

  ASSERT_NO_FATAL_FAILURE(ExpectSummaryCsvEqualsPage(o.out_dir / "summary.csv", *data, planners));
  ASSERT_EQ(r->leads.size(), 2u);
  EXPECT_EQ(r->leads[0].f1.n, 2u);
  EXPECT_THAT(r->leads[0].verdict, testing::AnyOf("ahead", "tied", "behind"));

  // fruits_by_visibility.csv, bin by bin.
  std::map<std::pair<std::string, std::string>, size_t> next_bin;
  size_t bins = 0;
  for (const std::vector<std::string>& c : CsvRows(o.out_dir / "fruits_by_visibility.csv")) {
    ASSERT_EQ(c.size(), 10u);
    const nlohmann::json& b =
        (*planners.at({c[0], c[1]}))["visibility_bins"][next_bin[{c[0], c[1]}]++];
    EXPECT_EQ(G9(b["lo"]), c[3]);
    EXPECT_EQ(G9(b["hi"]), c[4]);
    EXPECT_EQ(std::to_string(b["fruits"].get<size_t>()), c[5]);
    EXPECT_EQ(std::to_string(b["found"].get<size_t>()), c[6]);
    EXPECT_EQ(G9(b["fraction"]), c[7]);
    EXPECT_EQ(G9(b["ci_lo"]), c[8]);
    EXPECT_EQ(G9(b["ci_hi"]), c[9]);
    ++bins;
  }
  EXPECT_EQ(bins, 16u);

  // The final-view table (summary.md and the console) from the same numbers.
  ASSERT_EQ(r->cells.size(), 4u);
  for (const report::BenchCell& cell : r->cells) {
    const nlohmann::json& f = (*planners.at({cell.scenario, cell.planner}))["final"];
    EXPECT_DOUBLE_EQ(f["f1"]["mean"].get<double>(), cell.final_f1_mean);
    EXPECT_EQ(G9(f["f1"]["ci_lo"]), G9(cell.final_f1_lo));
    EXPECT_EQ(G9(f["f1"]["ci_hi"]), G9(cell.final_f1_hi));
    EXPECT_DOUBLE_EQ(f["fruits_found_fraction"]["mean"].get<double>(), cell.final_found_mean);
    EXPECT_EQ(G9(f["fruits_found_fraction"]["ci_lo"]), G9(cell.final_found_lo));
    EXPECT_EQ(G9(f["fruits_found_fraction"]["ci_hi"]), G9(cell.final_found_hi));
    EXPECT_DOUBLE_EQ(f["plan_ms_mean"].get<double>(), cell.plan_ms_mean);
  }
}

}  // namespace
}  // namespace avp::experiment

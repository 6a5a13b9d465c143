// The bench report page's data (report.html of a bench folder): the same numbers as summary.csv,
// fruits_by_visibility.csv and summary.md's final-view table, each episode's run folder, and the
// page's escaping of names that would end its script elements.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/io/file.h>
#include <avp/report/bench_html.h>
#include <avp/report/bench_summary.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::report {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

std::string ReadAll(const fs::path& p) { return test::ReadWholeFile(p); }

std::vector<std::string> Split(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string cell;
  while (std::getline(ss, cell, ',')) out.push_back(cell);
  if (!line.empty() && line.back() == ',') out.emplace_back();  // a trailing empty field
  return out;
}

/// summary.csv's number format.
std::string G9(const nlohmann::json& v) {
  if (v.is_null()) return "nan";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v.get<double>());
  return buf;
}

/// An episode of `views` views whose metrics vary with the planner, the seed and the view.
BenchEpisode Episode(const std::string& scenario, const std::string& planner, uint64_t seed,
                     int views) {
  BenchEpisode e;
  e.scenario = scenario;
  e.planner = planner;
  e.seed = seed;
  const double p = planner == "b" ? 0.1 : 0.0;
  const double s = static_cast<double>(seed);
  for (int v = 0; v < views; ++v) {
    const double f1 = 0.2 + 0.15 * v + p + 0.037 * s + (scenario == "t" ? 0.01 : 0.0);
    const double found = std::floor(1.0 + v + s);
    e.metrics.push_back(
        {{"f1", f1},
         {"f1_tol", f1 + 0.05},
         {"fruits_found", found},
         {"fruits_total", 5.0},
         {"fruits_found_fraction", found / 5.0},
         // Undefined at the first view of seed 0: left out of its statistics.
         {"center_error_m", v == 0 && seed == 0 ? NAN : 0.01 * (v + 1) + 0.003 * s}});
    e.plan_ms.push_back(10.0 + s + v);
  }
  e.episode_s = 1.5 + s;
  for (int f = 0; f < 5; ++f) {
    e.fruits.push_back({.best_visible_fraction = 0.1 * f + 0.02 * s,
                        .episode_visible_fraction = 0.1,
                        .found = f < static_cast<int>(e.metrics.back()[2].second)});
  }
  return e;
}

class BenchHtmlTest : public test::TempDirTest {
 protected:
  /// 2 scenarios x 2 planners x 2 seeds, 3 views; s/b seed 1 ended after 2 views (its last
  /// metrics carry on), t/a seed 2 failed (out of the statistics).
  void SetUp() override {
    test::TempDirTest::SetUp();
    bench_.scenarios = {"s", "t"};
    bench_.planners = {"a", "b"};
    bench_.seeds = 2;
    bench_.views = 3;
    bench_.segmenter = "oracle";
    bench_.voxel_size_m = 0.004;
    bench_.revision = "abc";
    bench_.description = "tiny";
    for (const std::string& s : bench_.scenarios) {
      for (const std::string& p : bench_.planners) {
        for (uint64_t seed : {0, 1}) {
          episodes_.push_back(Episode(s, p, seed, s == "s" && p == "b" && seed == 1 ? 2 : 3));
        }
      }
    }
    BenchEpisode failed = Episode("t", "a", 2, 3);
    failed.status = InternalError("planner crashed");
    episodes_.push_back(failed);
  }

  BenchDescription bench_;
  std::vector<BenchEpisode> episodes_;
};

/// The report's planners by (scenario, planner).
using PlannerData = std::map<std::pair<std::string, std::string>, const nlohmann::json*>;

/// Every row of summary.csv (scenario,planner,segmenter,view,metric,mean,ci_lo,ci_hi,n,versus)
/// equals the report's per-view numbers: 4 (scenario, planner) x 6 metrics x 3 views; the lead's
/// paired rows (versus set) are counted.
void ExpectSummaryCsvEqualsReport(const fs::path& file, const PlannerData& planners) {
  std::istringstream csv(ReadAll(file));
  std::string line;
  std::getline(csv, line);
  ASSERT_EQ(line, "scenario,planner,segmenter,view,metric,mean,ci_lo,ci_hi,n,versus");
  size_t rows = 0, lead_rows = 0;
  while (std::getline(csv, line)) {
    const std::vector<std::string> c = Split(line);
    ASSERT_EQ(c.size(), 10u) << line;
    if (!c[9].empty()) {
      EXPECT_THAT(c[4], testing::AnyOf("f1_lead", "found_lead")) << line;
      ++lead_rows;
      continue;
    }
    // The episode's motion rows (contacts, motion time: per episode, docs/motion.md) are in
    // summary.md, not in the page's per-view data.
    if (c[4] == "contacts" || c[4] == "straight_line_contacts" || c[4] == "motion_s" ||
        c[4] == "start_clearance_broken") {
      continue;
    }
    const nlohmann::json& pv = (*planners.at({c[0], c[1]}))["per_view"];
    ASSERT_TRUE(pv.contains(c[4])) << line;
    const size_t v = std::stoul(c[3]) - 1;
    EXPECT_EQ(G9(pv[c[4]]["mean"][v]), c[5]) << line;
    EXPECT_EQ(G9(pv[c[4]]["ci_lo"][v]), c[6]) << line;
    EXPECT_EQ(G9(pv[c[4]]["ci_hi"][v]), c[7]) << line;
    EXPECT_EQ(std::to_string(pv[c[4]]["n"][v].get<size_t>()), c[8]) << line;
    ++rows;
  }
  EXPECT_EQ(rows, 72u);
  EXPECT_EQ(lead_rows, 4u);  // 2 scenarios x (F1, found) of the lead over the other planner
}

/// fruits_by_visibility.csv (scenario,planner,segmenter,visible_from,visible_to,fruits,found,
/// fraction,wilson_lo,wilson_hi) equals the report's visibility bins.
void ExpectVisibilityCsvEqualsReport(const fs::path& file, const PlannerData& planners) {
  std::istringstream vis(ReadAll(file));
  std::string line;
  std::getline(vis, line);
  size_t bins = 0;
  std::map<std::pair<std::string, std::string>, size_t> bin_index;
  while (std::getline(vis, line)) {
    const std::vector<std::string> c = Split(line);
    ASSERT_EQ(c.size(), 10u) << line;
    const size_t i = bin_index[{c[0], c[1]}]++;
    const nlohmann::json& b = (*planners.at({c[0], c[1]}))["visibility_bins"][i];
    EXPECT_EQ(G9(b["lo"]), c[3]) << line;
    EXPECT_EQ(G9(b["hi"]), c[4]) << line;
    EXPECT_EQ(std::to_string(b["fruits"].get<size_t>()), c[5]) << line;
    EXPECT_EQ(std::to_string(b["found"].get<size_t>()), c[6]) << line;
    EXPECT_EQ(G9(b["fraction"]), c[7]) << line;
    EXPECT_EQ(G9(b["ci_lo"]), c[8]) << line;
    EXPECT_EQ(G9(b["ci_hi"]), c[9]) << line;
    ++bins;
  }
  EXPECT_EQ(bins, 16u);
}

/// summary.md's final-view table: the cells WriteBenchSummary returns equal the report's.
void ExpectCellsEqualReport(const std::vector<BenchCell>& cells, const PlannerData& planners) {
  ASSERT_EQ(cells.size(), 4u);
  for (const BenchCell& cell : cells) {
    const nlohmann::json& p = *planners.at({cell.scenario, cell.planner});
    EXPECT_EQ(p["n"].get<size_t>(), cell.runs);
    EXPECT_EQ(p["failed"].get<size_t>(), cell.failed);
    EXPECT_DOUBLE_EQ(p["final"]["f1"]["mean"].get<double>(), cell.final_f1_mean);
    EXPECT_EQ(G9(p["final"]["f1"]["ci_lo"]), G9(cell.final_f1_lo));
    EXPECT_EQ(G9(p["final"]["f1"]["ci_hi"]), G9(cell.final_f1_hi));
    EXPECT_DOUBLE_EQ(p["final"]["fruits_found_fraction"]["mean"].get<double>(),
                     cell.final_found_mean);
    EXPECT_EQ(G9(p["final"]["fruits_found_fraction"]["ci_lo"]), G9(cell.final_found_lo));
    EXPECT_EQ(G9(p["final"]["fruits_found_fraction"]["ci_hi"]), G9(cell.final_found_hi));
    EXPECT_DOUBLE_EQ(p["final"]["fruits_total"]["mean"].get<double>(), cell.fruits_total_mean);
    EXPECT_DOUBLE_EQ(p["final"]["plan_ms_mean"].get<double>(), cell.plan_ms_mean);
    EXPECT_DOUBLE_EQ(p["final"]["episode_s_mean"].get<double>(), cell.episode_s_mean);
  }
}

TEST_F(BenchHtmlTest, EmbeddedNumbersEqualSummaryCsv) {
  const fs::path dir = dir_ / "bench";
  const Result<BenchTables> tables = WriteBenchSummary(dir, bench_, episodes_, 12.0);
  ASSERT_TRUE(tables.ok()) << tables.status().ToString();
  // A run folder with a report (links are listed with the files each folder holds).
  const fs::path run = dir / BenchRunFolder("s", "a", 1);
  EXPECT_EQ(BenchRunFolder("s", "a", 1).generic_string(), "runs/s/a/seed-1");
  ASSERT_TRUE(io::WriteFileAtomic(run / "report.html", "<html></html>").ok());
  ASSERT_TRUE(io::WriteFileAtomic(run / "record.json", "{}").ok());
  const fs::path html = dir / "report.html";
  ASSERT_TRUE(WriteBenchReportHtml(html, BenchReportJson(bench_, episodes_, 12.0, dir)).ok());
  const Result<nlohmann::json> data = ReadBenchReportData(html);
  ASSERT_TRUE(data.ok()) << data.status().ToString();
  EXPECT_EQ((*data)["format"], "avp-bench-report");
  EXPECT_EQ((*data)["bench"]["views"], 3);
  EXPECT_EQ((*data)["bench"]["episodes"], 9);
  EXPECT_EQ((*data)["bench"]["failed"], 1);
  ASSERT_EQ((*data)["scenarios"].size(), 2u);

  PlannerData planners;
  for (const nlohmann::json& s : (*data)["scenarios"]) {
    for (const nlohmann::json& p : s["planners"]) {
      planners[{s["name"].get<std::string>(), p["name"].get<std::string>()}] = &p;
    }
  }
  ASSERT_EQ(planners.size(), 4u);

  ASSERT_NO_FATAL_FAILURE(ExpectSummaryCsvEqualsReport(dir / "summary.csv", planners));
  // Spot checks by hand: s/a view 2 f1 = 0.35 + 0.037 s over seeds 0, 1 -> mean 0.3685; with two
  // values the bootstrap interval is theirs, [0.35, 0.387] (never past them, as t's was).
  const nlohmann::json& sa = (*planners.at({"s", "a"}))["per_view"]["f1"];
  EXPECT_NEAR(sa["mean"][1].get<double>(), 0.3685, 1e-12);
  EXPECT_NEAR(sa["ci_lo"][1].get<double>(), 0.35, 1e-12);
  EXPECT_NEAR(sa["ci_hi"][1].get<double>(), 0.387, 1e-12);
  // s/b seed 1 ended after 2 views: its view-2 metrics count again at view 3.
  const nlohmann::json& sb = (*planners.at({"s", "b"}))["per_view"]["f1"];
  EXPECT_NEAR(sb["mean"][2].get<double>(), (0.2 + 0.3 + 0.1 + 0.2 + 0.15 + 0.1 + 0.037) / 2.0,
              1e-12);
  // center_error_m is NaN at view 1 of seed 0: one sample, no interval (null; nan in summary.csv).
  const nlohmann::json& ce = (*planners.at({"s", "a"}))["per_view"]["center_error_m"];
  EXPECT_EQ(ce["n"][0], 1);
  EXPECT_TRUE(ce["ci_lo"][0].is_null());
  EXPECT_TRUE(ce["ci_hi"][0].is_null());
  // t/a: two successful seeds, the failed third counted apart.
  EXPECT_EQ((*planners.at({"t", "a"}))["n"], 2);
  EXPECT_EQ((*planners.at({"t", "a"}))["failed"], 1);

  ASSERT_NO_FATAL_FAILURE(
      ExpectVisibilityCsvEqualsReport(dir / "fruits_by_visibility.csv", planners));
  ASSERT_NO_FATAL_FAILURE(ExpectCellsEqualReport(tables->cells, planners));

  // Runs: every episode with its folder and the files there.
  const nlohmann::json& runs = (*planners.at({"s", "a"}))["runs"];
  ASSERT_EQ(runs.size(), 2u);
  EXPECT_EQ(runs[1]["folder"], "runs/s/a/seed-1");
  EXPECT_EQ(runs[1]["files"], nlohmann::json::array({"record.json", "report.html"}));
  EXPECT_EQ(runs[0]["files"], nlohmann::json::array());
  const nlohmann::json& ta = (*planners.at({"t", "a"}))["runs"];
  ASSERT_EQ(ta.size(), 3u);
  EXPECT_FALSE(ta[2]["ok"].get<bool>());
  EXPECT_THAT(ta[2]["status"].get<std::string>(), HasSubstr("planner crashed"));
}

TEST_F(BenchHtmlTest, PageIsSelfContainedAndNamesCannotEndItsScripts) {
  bench_.scenarios = {"</script><script>alert(1)</script>", "t"};
  for (BenchEpisode& e : episodes_) {
    if (e.scenario == "s") e.scenario = bench_.scenarios[0];
  }
  bench_.description = "a <b>bold</b> & \"quoted\" bench";
  const nlohmann::json data = BenchReportJson(bench_, episodes_, 1.0, dir_);
  const std::string html = BenchReportHtml(data);
  // One data script, one page script, nothing fetched from elsewhere.
  EXPECT_THAT(html, HasSubstr("<meta charset=\"utf-8\">"));
  EXPECT_THAT(html,
              HasSubstr("<title>avp bench: a &lt;b&gt;bold&lt;/b&gt; &amp; &quot;quoted&quot; "
                        "bench</title>"));
  EXPECT_THAT(html, Not(HasSubstr("<script src")));
  EXPECT_THAT(html, Not(HasSubstr("<link")));
  EXPECT_THAT(html, Not(HasSubstr("https://")));
  size_t scripts = 0;
  for (size_t at = html.find("</script"); at != std::string::npos;
       at = html.find("</script", at + 1)) {
    ++scripts;
  }
  EXPECT_EQ(scripts, 2u);
  const fs::path path = dir_ / "report.html";
  ASSERT_TRUE(io::WriteFileAtomic(path, html).ok());
  const Result<nlohmann::json> back = ReadBenchReportData(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, data);
  EXPECT_EQ((*back)["scenarios"][0]["name"], "</script><script>alert(1)</script>");
  EXPECT_EQ((*back)["scenarios"][0]["file_name"], "__script__script_alert_1___script_");
}

TEST(BenchHtmlEscapeTest, ScriptEndsAreEscapedCaseInsensitively) {
  EXPECT_EQ(JsForHtmlScript("a=\"</script>\";b='</SCRIPT'"), "a=\"<\\/script>\";b='<\\/SCRIPT'");
  EXPECT_EQ(JsForHtmlScript("x</scrip"), "x</scrip");
  EXPECT_EQ(JsonForHtmlScript(nlohmann::json{{"k", "<!--</script>"}}),
            "{\"k\":\"\\u003c!--\\u003c/script>\"}");
  // Invalid UTF-8 in a name is replaced, not an exception.
  EXPECT_NO_THROW(JsonForHtmlScript(nlohmann::json("\xff")));
}

TEST_F(BenchHtmlTest, MissingOrBrokenDataNamesTheFile) {
  const fs::path dir = dir_;
  ASSERT_TRUE(io::WriteFileAtomic(dir / "none.html", "<html></html>").ok());
  const Result<nlohmann::json> none = ReadBenchReportData(dir / "none.html");
  EXPECT_EQ(none.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(none.status().message(), HasSubstr("none.html"));
  ASSERT_TRUE(io::WriteFileAtomic(dir / "bad.html",
                                  "<script type=\"application/json\" id=\"avp-bench-data\">{x"
                                  "</script>")
                  .ok());
  const Result<nlohmann::json> bad = ReadBenchReportData(dir / "bad.html");
  EXPECT_EQ(bad.status().code(), StatusCode::kParseError);
  EXPECT_THAT(bad.status().message(), HasSubstr("bad.html"));
  // The data starts after the 52 characters of its <script> tag.
  EXPECT_THAT(bad.status().message(), HasSubstr("offset 52"));
}

}  // namespace
}  // namespace avp::report

// `avp run` and `avp bench` as library calls (experiment::RunToFolder, RunBench): the run folder's
// files and their content, the bench's long-format summary CSV, Markdown and plots, the experiment
// YAML, and bad input.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/experiment/bench.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/json.h>
#include <avp/test/temp_dir_test.h>

namespace avp::experiment {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<std::string> Lines(const fs::path& p) {
  std::vector<std::string> out;
  std::ifstream in(p);
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

class RunCommandTest : public test::TempDirTest {
 protected:
  const Registries registries_ = BuiltinRegistries();
};

TEST_F(RunCommandTest, RunWritesTheRunFolder) {
  RunConfig c;
  c.scenario = "tomato-single-cluster";
  c.seed = 2;
  c.episode.views = 3;
  c.threads = 2;
  RunFolderOptions o;
  o.out_dir = dir_ / "run";
  int steps = 0;
  o.on_step = [&](const pipeline::StepRecord&) { ++steps; };
  auto r = RunToFolder(c, registries_, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(steps, 3);
  for (const char* f :
       {"record.json", "metrics.csv", "map.ot", "fruit_voxels.ply", "metrics.svg"}) {
    EXPECT_TRUE(fs::exists(o.out_dir / f)) << f;
  }
  const auto lines = Lines(o.out_dir / "metrics.csv");
  ASSERT_EQ(lines.size(), 4u);  // header + 3 views
  EXPECT_THAT(lines[0], HasSubstr("view,f1,precision,recall,tp,fp,fn,f1_tol"));
  EXPECT_THAT(lines[0], HasSubstr("fruits_found"));
  EXPECT_EQ(lines[1].substr(0, 2), "1,");
  EXPECT_EQ(lines[3].substr(0, 2), "3,");

  auto record = io::ReadJsonFile(o.out_dir / "record.json");
  ASSERT_TRUE(record.ok());
  EXPECT_EQ((*record)["config"]["seed"], 2);
  EXPECT_EQ((*record)["config"]["planner"]["name"], "avp-nbv");
  EXPECT_EQ((*record)["config"]["planner"]["options"]["p_unknown"], 0.05);
  EXPECT_EQ((*record)["config"]["map"]["grid"]["voxel_size_m"], 0.005);
  EXPECT_EQ((*record)["config"]["episode"]["integrator"]["carving"], "projective");
  EXPECT_EQ((*record)["config"]["scenario"], "tomato-single-cluster");
  EXPECT_EQ((*record)["views_fused"], 3);
  EXPECT_EQ((*record)["steps"].size(), 3u);
  EXPECT_TRUE((*record).contains("git_revision"));
  EXPECT_TRUE((*record).contains("host"));
  EXPECT_GT((*record)["ground_truth"]["voxels"].get<int>(), 100);
  EXPECT_EQ((*record)["config"]["oracle_regret"], false);
  EXPECT_TRUE((*record)["oracle_regret"].empty());  // measured only with --oracle-regret
  // Each fruit with its best visible fraction, and the counts at the levels (non-increasing).
  const auto& gt_json = (*record)["ground_truth"];
  ASSERT_EQ(gt_json["fruits"].size(), (*record)["scene"]["fruits"].get<size_t>());
  for (const auto& f : gt_json["fruits"]) {
    EXPECT_GE(f["best_visible_fraction"].get<double>(), 0.0);
    EXPECT_LE(f["best_visible_fraction"].get<double>(), 1.0);
  }
  const auto& at_least = gt_json["fruits_visible_at_least"];
  ASSERT_EQ(at_least.size(), 3u);
  EXPECT_GE(at_least["0.05"].get<int>(), at_least["0.25"].get<int>());
  EXPECT_GE(at_least["0.25"].get<int>(), at_least["0.50"].get<int>());
  EXPECT_GE(at_least["0.50"].get<int>(), 1);
  const double f1 = (*record)["final_metrics"]["f1"].get<double>();
  EXPECT_EQ(f1, r->result.final_metrics.exact.f1);
  EXPECT_THAT(ReadAll(o.out_dir / "metrics.svg"), HasSubstr("voxel F1 (exact)"));
}

TEST_F(RunCommandTest, RunRejectsBadInput) {
  RunConfig c;
  c.scenario = "tomato-nowhere";
  c.episode.views = 2;
  RunFolderOptions o;
  o.out_dir = dir_ / "bad";
  auto r = RunToFolder(c, registries_, o);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("unknown scenario 'tomato-nowhere' (known: "));
  c.scenario = "tomato-single-cluster";
  c.planner.name = "best";
  r = RunToFolder(c, registries_, o);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("unknown planner 'best'"));
}

TEST_F(RunCommandTest, PlannerOptionsReachThePlannerAndTheRecord) {
  const Result<OptionValues> parsed = ParseKeyValues(
      {"p_unknown=0.1", "candidates.max_candidates=40", "p_unknown=0.2"}, "planner option");
  ASSERT_TRUE(parsed.ok());
  EXPECT_THAT(ParseKeyValues({"p_unknown"}, "planner option").status().message(),
              HasSubstr("'p_unknown' must be KEY=VALUE"));

  RunConfig c;
  c.scenario = "tomato-single-cluster";
  c.episode.views = 2;
  c.planner.options = *parsed;  // later ones win
  RunFolderOptions o;
  o.out_dir = dir_ / "opts";
  auto r = RunToFolder(c, registries_, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  auto record = io::ReadJsonFile(o.out_dir / "record.json");
  ASSERT_TRUE(record.ok());
  EXPECT_EQ((*record)["config"]["planner"]["options"]["p_unknown"], 0.2);
  EXPECT_EQ((*record)["config"]["planner"]["options"]["candidates"]["max_candidates"], 40);
  // The planner generated at most the 40 candidates asked for (720 by default).
  const std::vector<std::string> lines = Lines(o.out_dir / "metrics.csv");
  ASSERT_GE(lines.size(), 2u);
  std::vector<std::string> header, row;
  for (auto [line, out] : {std::pair{&lines[0], &header}, {&lines[1], &row}}) {
    std::stringstream ss(*line);
    for (std::string cell; std::getline(ss, cell, ',');) out->push_back(cell);
  }
  const auto col = std::find(header.begin(), header.end(), "candidates") - header.begin();
  ASSERT_LT(static_cast<size_t>(col), row.size());
  EXPECT_GT(std::stoi(row[static_cast<size_t>(col)]), 0);
  EXPECT_LE(std::stoi(row[static_cast<size_t>(col)]), 40);

  c.planner.options = {{"p_unknown", "1.5"}};
  r = RunToFolder(c, registries_, o);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("p_unknown (1.5) must be in [0, 1)"));
  c.planner.options = {{"w_motoin", "0.1"}};
  EXPECT_THAT(RunToFolder(c, registries_, o).status().message(),
              HasSubstr("unknown avp-nbv option 'w_motoin'"));
  c.planner.options = {{"p_unknown", "0.1"}};
  c.planner.name = "predefined";
  EXPECT_THAT(RunToFolder(c, registries_, o).status().message(),
              HasSubstr("unknown predefined planner option 'p_unknown' (known: generic_"));

  // In an experiment file, under planner_options; only for planners of the bench.
  const fs::path yaml = dir_ / "opts.yaml";
  std::ofstream(yaml) << "scenarios: [tomato-single-cluster]\nplanners: [avp-nbv, predefined]\n"
                         "seeds: [0]\nplanner_options: {avp-nbv: {p_unknown: 0.1, refine_top: 16, "
                         "candidates: {radii_m: [0.3, 0.5]}}}\n";
  auto bench = LoadBenchConfig(yaml);
  ASSERT_TRUE(bench.ok()) << bench.status().ToString();
  EXPECT_EQ(bench->planner_options.at("avp-nbv"),
            (OptionValues{
                {"p_unknown", "0.1"}, {"refine_top", "16"}, {"candidates.radii_m", "0.3,0.5"}}));
  EXPECT_TRUE(bench->Validate(registries_).ok()) << bench->Validate(registries_).ToString();
  bench->planners = {"predefined"};
  EXPECT_THAT(
      bench->Validate(registries_).message(),
      HasSubstr("options are given for planner 'avp-nbv', which is not among the planners"));
  bench->planners = {"avp-nbv"};
  bench->planner_options["avp-nbv"].emplace_back("refine_top", "0");
  EXPECT_THAT(bench->Validate(registries_).message(), HasSubstr("refine_top (0) must be >= 1"));
}

TEST_F(RunCommandTest, BenchWritesLongFormatSummaryAndPlots) {
  BenchConfig o;
  o.scenarios = {"tomato-single-cluster"};
  o.planners = {"avp-nbv", "predefined"};
  o.seeds = {0, 1};
  o.base.episode.views = 2;
  o.out_dir = dir_ / "bench";
  o.progress = false;
  auto r = RunBench(o, registries_);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->episodes, 4u);
  EXPECT_EQ(r->failed, 0u);
  const auto lines = Lines(o.out_dir / "summary.csv");
  ASSERT_GT(lines.size(), 1u);
  EXPECT_EQ(lines[0], "scenario,planner,segmenter,view,metric,mean,ci95,n");
  int f1_rows = 0;
  for (const std::string& l : lines) {
    if (l.find(",f1,") != std::string::npos) {
      ++f1_rows;
      EXPECT_EQ(l.substr(l.rfind(',') + 1), "2") << l;  // two seeds
      EXPECT_THAT(l, HasSubstr("tomato-single-cluster,"));
      EXPECT_THAT(l, HasSubstr(",oracle,"));
    }
  }
  EXPECT_EQ(f1_rows, 4);  // 2 planners x 2 views
  EXPECT_THAT(ReadAll(o.out_dir / "summary.md"), HasSubstr("| avp-nbv | 2 |"));
  EXPECT_THAT(ReadAll(o.out_dir / "summary.md"),
              HasSubstr("Run configuration over its defaults: `episode.views = 2`."));
  EXPECT_THAT(ReadAll(o.out_dir / "summary.md"),
              HasSubstr("Fruits by their best visible fraction from a reachable observation view "
                        "(all seeds): ≥ 5 %: "));
  EXPECT_TRUE(fs::exists(o.out_dir / "f1_tomato-single-cluster.svg"));
  EXPECT_TRUE(fs::exists(o.out_dir / "fruits_tomato-single-cluster.svg"));
  EXPECT_TRUE(fs::exists(o.out_dir / "runs" / "tomato-single-cluster" / "predefined" / "seed-1" /
                         "metrics.csv"));
  ASSERT_EQ(r->cells.size(), 2u);
  EXPECT_EQ(r->cells[0].runs, 2u);
}

TEST_F(RunCommandTest, BenchConfigFileAndErrors) {
  auto paper = LoadBenchConfig(fs::path(AVP_CONFIG_DIR) / "experiments" / "paper.yaml");
  ASSERT_TRUE(paper.ok()) << paper.status().ToString();
  EXPECT_EQ(paper->scenarios.size(), 5u);
  EXPECT_EQ(paper->seeds.size(), 10u);
  EXPECT_EQ(paper->base.episode.views, 8);
  EXPECT_EQ(paper->base.segmenter.name, "oracle");
  EXPECT_EQ(paper->base.map.semantics.policy, mapping::FusionPolicy::kBayesian);
  EXPECT_TRUE(paper->Validate(registries_).ok()) << paper->Validate(registries_).ToString();
  auto bounds =
      LoadBenchConfig(fs::path(AVP_CONFIG_DIR) / "experiments" / "full-occlusion-bounds.yaml");
  ASSERT_TRUE(bounds.ok()) << bounds.status().ToString();
  EXPECT_EQ(bounds->planners, (std::vector<std::string>{"avp-nbv", "oracle-nbv", "oracle-detect"}));
  EXPECT_EQ(bounds->seeds.size(), 10u);
  EXPECT_TRUE(bounds->Validate(registries_).ok()) << bounds->Validate(registries_).ToString();

  const fs::path bad = dir_ / "bad.yaml";
  std::ofstream(bad) << "scenarios: [tomato-single-cluster]\nplanners: [avp-nbv]\nseeds: [0]\n"
                        "colour: red\n";
  auto r = LoadBenchConfig(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("colour"));
  std::ofstream(bad) << "scenarios: [tomato-single-cluster]\nplanners: [avp-nbv]\nseeds: [0]\n"
                        "run: {episode: {viewz: 3}}\n";
  r = LoadBenchConfig(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("unknown run configuration key 'episode.viewz'"));
  std::ofstream(bad) << "scenarios: [tomato-single-cluster]\nplanners: [avp-nbv]\nseeds: [0]\n"
                        "run: {seed: 3}\n";
  r = LoadBenchConfig(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("run.seed is set by each job"));
  // Seed lists are bounded before they are allocated, and never wrap from a negative number.
  std::ofstream(bad) << "scenarios: [tomato-single-cluster]\nplanners: [avp-nbv]\n"
                        "seeds: {first: 0, count: 18446744073709551615}\n";
  r = LoadBenchConfig(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(),
              HasSubstr("seeds.count (18446744073709551615) must be at most 100000 seeds"));
  std::ofstream(bad) << "scenarios: [tomato-single-cluster]\nplanners: [avp-nbv]\nseeds: [0, -1]\n";
  r = LoadBenchConfig(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("a seed ('-1') must be a whole number >= 0"));

  BenchConfig o;
  o.scenarios = {"tomato-nowhere"};
  o.planners = {"avp-nbv"};
  o.seeds = {0, 0};
  EXPECT_THAT(o.Validate(registries_).message(), HasSubstr("unknown scenario 'tomato-nowhere'"));
  EXPECT_THAT(o.Validate(registries_).message(), HasSubstr("seeds repeat"));
}

}  // namespace
}  // namespace avp::experiment

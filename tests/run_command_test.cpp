// `avp run` and `avp bench` as library calls (experiment::RunToFolder, RunBench): the run folder's
// files and their content, the bench's long-format summary CSV, Markdown and plots, the experiment
// YAML, and bad input.
#include <algorithm>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <avp/core/semantic_class.h>
#include <avp/experiment/bench.h>
#include <avp/experiment/episode_runner.h>
#include <avp/experiment/output_folder.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/json.h>
#include <avp/report/run_html.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::experiment {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

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

/// record.json's per-fruit list against the record's own counts: one entry per scene fruit with
/// the ground truth's best visible fraction; the found flags are final_metrics' fruits_found;
/// found_view (1-based, like steps[].view) agrees with fruits_found after every view of
/// metrics.csv (`csv`, header + one line per view); the errors average to the aggregates.
void ExpectFruitListMatchesTheRecord(const nlohmann::json& record,
                                     const std::vector<std::string>& csv) {
  const auto& fruits = record["fruits"];
  ASSERT_TRUE(fruits.is_array());
  ASSERT_EQ(fruits.size(), record["scene"]["fruits"].get<size_t>());
  const auto& gt_fruits = record["ground_truth"]["fruits"];
  ASSERT_EQ(gt_fruits.size(), fruits.size());
  int found = 0;
  double center_sum = 0.0;
  double radius_sum = 0.0;
  int estimated = 0;
  for (size_t i = 0; i < fruits.size(); ++i) {
    const auto& f = fruits[i];
    EXPECT_EQ(f["fruit"], gt_fruits[i]["fruit"]);
    EXPECT_EQ(f["best_visible_fraction"], gt_fruits[i]["best_visible_fraction"]);
    EXPECT_EQ(f["center_m"].size(), 3u);
    EXPECT_GT(f["radius_m"].get<double>(), 0.01);
    if (f["found"].get<bool>()) {
      ++found;
      EXPECT_FALSE(f["found_view"].is_null());
      EXPECT_FALSE(f["found_since_view"].is_null());
      EXPECT_LE(f["found_view"].get<int>(), f["found_since_view"].get<int>());
    } else {
      EXPECT_TRUE(f["found_since_view"].is_null());
      EXPECT_TRUE(f["estimate"].is_null());
    }
    if (!f["center_error_m"].is_null()) {
      ++estimated;
      center_sum += f["center_error_m"].get<double>();
      radius_sum += f["radius_error_m"].get<double>();
      EXPECT_LT(f["center_error_m"].get<double>(), 0.05);
    }
  }
  const auto& final_metrics = record["final_metrics"];
  EXPECT_EQ(found, final_metrics["fruits_found"].get<int>());
  ASSERT_GT(found, 0);
  ASSERT_GT(estimated, 0);
  EXPECT_NEAR(center_sum / estimated, final_metrics["center_error_m"].get<double>(), 1e-12);
  EXPECT_NEAR(radius_sum / estimated, final_metrics["radius_error_m"].get<double>(), 1e-12);
  // After view k: the fruits whose found_view <= k, less those lost again, are fruits_found.
  const auto& steps = record["steps"];
  ASSERT_EQ(csv.size(), steps.size() + 1);
  for (size_t k = 1; k <= steps.size(); ++k) {
    int first_found = 0;
    int found_now_lower_bound = 0;
    for (const auto& f : fruits) {
      if (!f["found_view"].is_null() && f["found_view"].get<size_t>() <= k) ++first_found;
      if (!f["found_since_view"].is_null() && f["found_since_view"].get<size_t>() <= k) {
        ++found_now_lower_bound;
      }
    }
    const int found_k = steps[k - 1]["metrics"]["fruits_found"].get<int>();
    EXPECT_EQ(steps[k - 1]["view"].get<size_t>(), k);
    EXPECT_LE(found_now_lower_bound, found_k) << "view " << k;
    EXPECT_GE(first_found, found_k) << "view " << k;
    // metrics.csv's fruits_found of the same view (its column from the header).
    std::vector<std::string> header, row;
    for (std::stringstream h(csv[0]); std::getline(h, header.emplace_back(), ',');) {
    }
    for (std::stringstream l(csv[k]); std::getline(l, row.emplace_back(), ',');) {
    }
    const size_t col = static_cast<size_t>(std::find(header.begin(), header.end(), "fruits_found") -
                                           header.begin());
    ASSERT_LT(col, row.size());
    EXPECT_EQ(std::stoi(row[col]), found_k) << "view " << k;
  }
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
  auto r = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o);
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
  ExpectFruitListMatchesTheRecord(*record, lines);
}

TEST_F(RunCommandTest, EpisodeVisibilityOfEachFruitIsWhatTheRendererShows) {
  // Render every fused view again, independently, and count each fruit's pixels (class fruit,
  // depth within the integrator's range) over the unoccluded area pi (f r / z)^2: the largest
  // fraction over the views is the record's episode_visible_fraction, at the view it names.
  RunConfig c;
  c.scenario = "tomato-single-cluster";
  c.seed = 3;
  c.episode.views = 3;
  c.threads = 2;
  c.depth_noise.enabled = false;  // the render below has no noise either
  auto scene = LoadScene(c, registries_);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  auto gt = GroundTruthFor(c, *scene);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  auto r = RunEpisodeOnScene(CheckedRunConfig::Check(c, registries_).value(), *scene, *gt);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->episode.views_fused(), 3);
  ASSERT_EQ(r->fruits.size(), scene->Fruits().size());
  const sim::RgbdRenderer renderer(*scene);
  const double max_range = c.episode.integrator.max_range_m;
  struct Best {
    double fraction = 0.0;
    int view = -1;
  };
  const auto rendered_best = [&](const RunResult& run) {
    std::map<uint16_t, Best> best;
    for (const pipeline::StepRecord& step : run.episode.steps) {
      const sim::RenderedFrame frame = renderer.Render(c.camera, step.X_WC);
      const CameraIntrinsics& K = frame.rgbd.K;
      std::map<uint16_t, int> pixels;
      for (int v = 0; v < K.height; ++v) {
        for (int u = 0; u < K.width; ++u) {
          if (frame.class_ids.at(u, v) != static_cast<uint8_t>(SemanticClass::kFruit)) continue;
          const double d = frame.rgbd.depth_m.at(u, v);
          const Eigen::Vector3d p((u - K.cx) / K.fx * d, (v - K.cy) / K.fy * d, d);
          if (d > 0.0 && p.norm() <= max_range) ++pixels[frame.instance_ids.at(u, v)];
        }
      }
      for (const sim::FruitTruth& f : scene->Fruits()) {
        const double z = (step.X_WC.inverse() * f.center_W).z();
        const double fr = std::sqrt(K.fx * K.fy) * f.mean_radius_m();
        const double area = M_PI * (fr / z) * (fr / z);
        const double fraction = std::min(1.0, pixels[f.instance_id] / area);
        Best& b = best[f.instance_id];
        if (b.view < 0 || fraction > b.fraction) b = {fraction, step.view};
      }
    }
    return best;
  };
  std::map<uint16_t, Best> best = rendered_best(*r);
  int seen = 0;
  for (const eval::FruitResult& f : r->fruits) {
    EXPECT_NEAR(f.episode_visible_fraction, best[f.instance_id].fraction, 1e-9) << f.name;
    if (best[f.instance_id].fraction > 0.0) {
      EXPECT_EQ(f.episode_best_view, best[f.instance_id].view) << f.name;
      ++seen;
    }
  }
  EXPECT_GE(seen, 3);  // the single cluster: several fruits in view
  // The default depth noise drops or moves depths: a dropped fruit pixel still counts (the
  // labels are ground truth), so the fractions stay within a few percent of the clean render.
  c.depth_noise.enabled = true;
  auto noisy = RunEpisodeOnScene(CheckedRunConfig::Check(c, registries_).value(), *scene, *gt);
  ASSERT_TRUE(noisy.ok()) << noisy.status().ToString();
  best = rendered_best(*noisy);
  for (const eval::FruitResult& f : noisy->fruits) {
    EXPECT_NEAR(f.episode_visible_fraction, best[f.instance_id].fraction, 0.02) << f.name;
  }
}

TEST_F(RunCommandTest, ARunThatFindsNothingSaysWhy) {
  // The README's example of the paper's planner: from an unoriented start it sees no fruit, its
  // gains are all zero and it finds nothing; record.json says why (issue 32).
  RunConfig c;
  c.scenario = "tomato-unoriented-start";
  c.planner.name = "reference-nbv";
  c.episode.views = 3;
  RunFolderOptions o;
  o.out_dir = dir_ / "ref";
  const auto r = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->result.final_metrics.fruits.found, 0u);
  const auto record = io::ReadJsonFile(o.out_dir / "record.json");
  ASSERT_TRUE(record.ok());
  const nlohmann::json& why = (*record)["nothing_found"];
  ASSERT_TRUE(why.is_array()) << why.dump();
  ASSERT_GE(why.size(), 2u) << why.dump();
  EXPECT_THAT(why.dump(), HasSubstr("no view returned a mask"));
  EXPECT_THAT(why.dump(), HasSubstr("zero gain"));
  // The page says it too, among its facts.
  const auto page = report::ReadRunReportData(o.out_dir / "report.html");
  ASSERT_TRUE(page.ok()) << page.status().ToString();
  EXPECT_THAT(page->dump(), HasSubstr("why no fruit was found"));
  EXPECT_THAT(page->dump(), HasSubstr("no view returned a mask"));
}

TEST(SegmenterFailedEveryViewTest, OnlyWhenNoViewWasSegmented) {
  RunResult r;
  EXPECT_TRUE(SegmenterFailedEveryView(r).ok());  // no views
  for (int v = 0; v < 3; ++v) {
    pipeline::StepRecord s;
    s.view = v;
    s.segment_status = InvalidArgumentError(fmt::format("degenerate fruit at view {}", v + 1));
    r.episode.steps.push_back(s);
  }
  const Status all = SegmenterFailedEveryView(r);
  EXPECT_EQ(all.code(), StatusCode::kUnavailable);
  EXPECT_THAT(all.message(), HasSubstr("the segmenter failed at every one of the 3 views"));
  EXPECT_THAT(all.message(), HasSubstr("degenerate fruit at view 1"));
  r.episode.steps[1].segment_status = Status::Ok();
  EXPECT_TRUE(SegmenterFailedEveryView(r).ok());
}

TEST_F(RunCommandTest, RunRejectsBadInput) {
  RunConfig c;
  c.scenario = "tomato-nowhere";
  c.episode.views = 2;
  // Refused at the door: no CheckedRunConfig, so nothing that runs an episode is reached.
  Result<CheckedRunConfig> r = CheckedRunConfig::Check(c, registries_);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("unknown scenario 'tomato-nowhere' (known: "));
  c.scenario = "tomato-single-cluster";
  c.planner.name = "best";
  r = CheckedRunConfig::Check(c, registries_);
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
  auto r = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o);
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

  // Bad options are refused at the door (CheckedRunConfig::Check), before any episode.
  c.planner.options = {{"p_unknown", "1.5"}};
  EXPECT_THAT(CheckedRunConfig::Check(c, registries_).status().message(),
              HasSubstr("p_unknown (1.5) must be in [0, 1)"));
  c.planner.options = {{"w_motoin", "0.1"}};
  EXPECT_THAT(CheckedRunConfig::Check(c, registries_).status().message(),
              HasSubstr("unknown avp-nbv option 'w_motoin'"));
  c.planner.options = {{"p_unknown", "0.1"}};
  c.planner.name = "predefined";
  EXPECT_THAT(CheckedRunConfig::Check(c, registries_).status().message(),
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

TEST_F(RunCommandTest, BenchProgressOffATerminalIsOneLinePerJob) {
  BenchConfig o;
  o.scenarios = {"tomato-single-cluster"};
  o.planners = {"predefined"};
  o.seeds = {0, 1};
  o.base.episode.views = 2;
  o.jobs = 1;
  o.out_dir = dir_ / "bench-progress";
  testing::internal::CaptureStderr();  // a file: not a terminal, so lines
  const auto r = RunBench(o, registries_);
  const std::string err = testing::internal::GetCapturedStderr();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_THAT(err, HasSubstr("ground truth 1/2 (50 %) "));
  EXPECT_THAT(err, HasSubstr(": tomato-single-cluster seed 0 ok\n"));
  EXPECT_THAT(err, HasSubstr("episodes 1/2 (50 %) "));
  EXPECT_THAT(err, HasSubstr("episodes 2/2 (100 %) "));
  EXPECT_THAT(err, HasSubstr(": tomato-single-cluster predefined seed 1 ok\n"));
  EXPECT_EQ(err.find('\r'), std::string::npos);
  EXPECT_EQ(err.find('\x1b'), std::string::npos);
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
  EXPECT_EQ(lines[0], "scenario,planner,segmenter,view,metric,mean,ci_lo,ci_hi,n,versus");
  int f1_rows = 0;
  for (const std::string& l : lines) {
    if (l.find(",f1,") != std::string::npos) {
      ++f1_rows;
      EXPECT_TRUE(l.ends_with(",2,")) << l;  // two seeds, no `versus`
      EXPECT_THAT(l, HasSubstr("tomato-single-cluster,"));
      EXPECT_THAT(l, HasSubstr(",oracle,"));
    }
  }
  EXPECT_EQ(f1_rows, 4);  // 2 planners x 2 views
  EXPECT_THAT(ReadAll(o.out_dir / "summary.md"), HasSubstr("| avp-nbv | 2 (small) |"));
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

  // Per-fruit results: each run's record.json lists its fruits; fruits_by_visibility.csv bins
  // them by best visible fraction, per planner every fruit of both seeds once, and the found
  // counts are the runs' found flags.
  std::map<std::string, int> fruits_of, found_of;
  for (const char* planner : {"avp-nbv", "predefined"}) {
    for (const char* seed : {"seed-0", "seed-1"}) {
      auto rec = io::ReadJsonFile(o.out_dir / "runs" / "tomato-single-cluster" / planner / seed /
                                  "record.json");
      ASSERT_TRUE(rec.ok()) << rec.status().ToString();
      ASSERT_TRUE((*rec)["fruits"].is_array());
      ASSERT_GT((*rec)["fruits"].size(), 0u);
      for (const auto& f : (*rec)["fruits"]) {
        ++fruits_of[planner];
        found_of[planner] += f["found"].get<bool>() ? 1 : 0;
        EXPECT_TRUE(f.contains("found_view"));
        EXPECT_TRUE(f.contains("episode_visible_fraction"));
      }
    }
  }
  const auto bins = Lines(o.out_dir / "fruits_by_visibility.csv");
  ASSERT_EQ(bins.size(), 1u + 2u * 4u);  // header + 2 planners x 4 bins
  EXPECT_EQ(bins[0],
            "scenario,planner,segmenter,visible_from,visible_to,fruits,found,fraction,wilson_lo,"
            "wilson_hi");
  EXPECT_THAT(bins[1], HasSubstr("tomato-single-cluster,avp-nbv,oracle,0,0.05,"));
  EXPECT_THAT(bins[8], HasSubstr("tomato-single-cluster,predefined,oracle,0.5,1,"));
  std::map<std::string, int> binned, binned_found;
  for (size_t i = 1; i < bins.size(); ++i) {
    std::vector<std::string> cells;
    for (std::stringstream l(bins[i]); std::getline(l, cells.emplace_back(), ',');) {
    }
    binned[cells[1]] += std::stoi(cells[5]);
    binned_found[cells[1]] += std::stoi(cells[6]);
  }
  EXPECT_EQ(binned, fruits_of);
  EXPECT_EQ(binned_found, found_of);
  EXPECT_THAT(ReadAll(o.out_dir / "summary.md"),
              HasSubstr("Fruits found at the final view by best visible fraction"));
}

// `avp bench --oracle-regret`: each run's record.json holds its plans' regret, and summary.csv /
// summary.md carry exactly those numbers per view and pooled.
TEST_F(RunCommandTest, BenchOracleRegretIsSummarisedPerScenario) {
  BenchConfig o;
  o.scenarios = {"tomato-single-cluster"};
  o.planners = {"avp-nbv"};
  o.seeds = {0};
  o.base.episode.views = 3;
  o.base.oracle_regret = true;
  o.out_dir = dir_ / "bench-regret";
  o.progress = false;
  auto r = RunBench(o, registries_);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->failed, 0u);
  auto rec = io::ReadJsonFile(o.out_dir / "runs" / "tomato-single-cluster" / "avp-nbv" / "seed-0" /
                              "record.json");
  ASSERT_TRUE(rec.ok()) << rec.status().ToString();
  const auto& steps = (*rec)["oracle_regret"];
  ASSERT_EQ(steps.size(), 2u);  // two plans choose views 2 and 3
  double sum = 0.0;
  for (const auto& step : steps) {
    const double regret = step["regret"].get<double>();
    EXPECT_GE(regret, 0.0);
    EXPECT_LE(regret, 1.0);
    EXPECT_GE(step["chosen_true_rank"].get<int>(), 1);
    EXPECT_GT(step["candidates"].get<int>(), 10);
    sum += regret;
  }
  const std::string csv = ReadAll(o.out_dir / "summary.csv");
  EXPECT_THAT(csv, HasSubstr(fmt::format(
                       "tomato-single-cluster,avp-nbv,oracle,2,oracle_regret,{:.9g},nan,nan,1,\n",
                       steps[0]["regret"].get<double>())));
  EXPECT_THAT(csv, HasSubstr(fmt::format(
                       "tomato-single-cluster,avp-nbv,oracle,0,oracle_regret,{:.9g},", sum / 2.0)));
  EXPECT_THAT(csv, HasSubstr(fmt::format(
                       "tomato-single-cluster,avp-nbv,oracle,3,oracle_chosen_rank,{},nan,nan,1,\n",
                       steps[1]["chosen_true_rank"].get<int>())));
  EXPECT_THAT(ReadAll(o.out_dir / "summary.md"),
              HasSubstr(fmt::format("| avp-nbv | 2 | {:.0f} | {:.3f} [",
                                    0.5 * (steps[0]["candidates"].get<double>() +
                                           steps[1]["candidates"].get<double>()),
                                    sum / 2.0)));
}

TEST_F(RunCommandTest, BenchConfigFileAndErrors) {
  auto paper = LoadBenchConfig(fs::path(AVP_CONFIG_DIR) / "experiments" / "paper.yaml");
  ASSERT_TRUE(paper.ok()) << paper.status().ToString();
  EXPECT_EQ(paper->scenarios.size(), 7u);  // four tomato, three espalier
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

// ---- Results that survive: the run folder's lifecycle, reruns, write errors ------------------

/// A quick episode: the predefined planner on 1 cm voxels.
RunConfig SmallRun(int views = 2) {
  RunConfig c;
  c.scenario = "tomato-single-cluster";
  c.seed = 1;
  c.episode.views = views;
  c.threads = 2;
  c.planner.name = "predefined";
  c.map.grid.voxel_size_m = 0.01;
  return c;
}

TEST_F(RunCommandTest, RunFolderIsInProgressWhileItRunsAndCompleteAfter) {
  const RunConfig c = SmallRun(3);
  RunFolderOptions o;
  o.out_dir = dir_ / "run";
  // A kill after the second step is this snapshot of the folder: it says "in-progress", has two
  // rows of metrics.csv and no record.json.
  const fs::path killed = dir_ / "killed";
  std::string state_while_running;
  o.on_step = [&](const pipeline::StepRecord& s) {
    if (s.view != 1) return;
    const Result<FolderState> st = ReadFolderState(o.out_dir);
    state_while_running = st.ok() ? st->state : st.status().ToString();
    fs::copy(o.out_dir, killed, fs::copy_options::recursive);
  };
  const auto r = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(state_while_running, "in-progress");
  const Result<FolderState> done = ReadFolderState(o.out_dir);
  ASSERT_TRUE(done.ok()) << done.status().ToString();
  EXPECT_EQ(done->state, "complete");
  EXPECT_EQ(done->kind, "run");
  EXPECT_EQ(done->command, "avp run");
  EXPECT_FALSE(done->finished.empty());

  EXPECT_EQ(ReadFolderState(killed).value().state, "in-progress");
  EXPECT_FALSE(fs::exists(killed / "record.json"));
  EXPECT_EQ(Lines(killed / "metrics.csv").size(), 3u);  // header + 2 views

  // A rerun into the killed folder refuses, saying what it holds; --force starts clean.
  o.on_step = nullptr;
  o.out_dir = killed;
  const Status refused = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).status();
  EXPECT_EQ(refused.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(refused.message(), HasSubstr("output folder '" + killed.string() + "'"));
  EXPECT_THAT(refused.message(), HasSubstr("an avp run that did not finish"));
  EXPECT_THAT(refused.message(), HasSubstr("--force"));
  o.force = true;
  const auto again = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(ReadFolderState(killed).value().state, "complete");
  EXPECT_EQ(Lines(killed / "metrics.csv").size(), 4u);  // header + 3 views, none of the old run
}

TEST_F(RunCommandTest, RerunIntoACompleteFolderRefusesAndForceReplacesIt) {
  RunConfig c = SmallRun();
  RunFolderOptions o;
  o.out_dir = dir_ / "run";
  ASSERT_TRUE(RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).ok());
  const std::string first_record = ReadAll(o.out_dir / "record.json");
  c.seed = 5;
  const Status refused = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).status();
  EXPECT_EQ(refused.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(refused.message(), HasSubstr("the results of a complete avp run"));
  EXPECT_EQ(ReadAll(o.out_dir / "record.json"), first_record);  // untouched
  o.force = true;
  ASSERT_TRUE(RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).ok());
  EXPECT_EQ(io::ReadJsonFile(o.out_dir / "record.json").value()["config"]["seed"], 5);
}

TEST_F(RunCommandTest, ForceNeverEmptiesAFolderThatIsNotARunFolder) {
  const RunConfig c = SmallRun();
  RunFolderOptions o;
  o.out_dir = dir_ / "thesis";
  fs::create_directories(o.out_dir);
  std::ofstream(o.out_dir / "chapter1.tex") << "precious";
  o.force = true;
  const Status s = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).status();
  EXPECT_EQ(s.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(s.message(), HasSubstr("'chapter1.tex'"));
  EXPECT_THAT(s.message(), HasSubstr("not an avp run folder, so --force does not empty it"));
  EXPECT_EQ(ReadAll(o.out_dir / "chapter1.tex"), "precious");
  // Nor a run folder with something else in it.
  o.out_dir = dir_ / "run";
  o.force = false;
  ASSERT_TRUE(RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).ok());
  std::ofstream(o.out_dir / "notes.txt") << "mine";
  o.force = true;
  EXPECT_THAT(RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).status().message(),
              HasSubstr("'notes.txt'"));
  EXPECT_TRUE(fs::exists(o.out_dir / "notes.txt"));
  EXPECT_TRUE(fs::exists(o.out_dir / "record.json"));
}

TEST_F(RunCommandTest, OutputsNeverOverwriteInputs) {
  // The ground truth given as the run folder's own map.ot: --force would replace it.
  RunConfig c = SmallRun();
  RunFolderOptions o;
  o.out_dir = dir_ / "run";
  ASSERT_TRUE(RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).ok());
  c.ground_truth_file = o.out_dir / "map.ot";
  o.force = true;
  const std::string before = ReadAll(c.ground_truth_file);
  const Status s = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).status();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("is the ground truth file"));
  EXPECT_THAT(s.message(), HasSubstr("outputs never overwrite inputs"));
  EXPECT_EQ(ReadAll(c.ground_truth_file), before);
  // A configuration file the run read, reached through another spelling of the path.
  c.ground_truth_file.clear();
  o.inputs = {{o.out_dir / "." / "record.json", "configuration file"}};
  EXPECT_THAT(RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).status().message(),
              HasSubstr("is the configuration file"));
}

TEST_F(RunCommandTest, AWriteErrorStopsTheRunNamingTheFile) {
  // The run folder's parent is a regular file: nothing can be written, and the error says where.
  std::ofstream(dir_ / "file") << "x";
  RunFolderOptions o;
  o.out_dir = dir_ / "file" / "run";
  const Status s =
      RunToFolder(CheckedRunConfig::Check(SmallRun(), registries_).value(), o).status();
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr(o.out_dir.string()));
  EXPECT_THAT(s.message(), HasSubstr("Not a directory"));
  EXPECT_THAT(s.message(), Not(HasSubstr("Success")));
}

/// Files of this process may grow to `bytes` at most while it lives (a full disk, as the writers
/// see it: writes past it fail with EFBIG); SIGXFSZ is ignored meanwhile.
class ScopedFileSizeLimit {
 public:
  explicit ScopedFileSizeLimit(rlim_t bytes) {
    getrlimit(RLIMIT_FSIZE, &saved_);
    old_handler_ = std::signal(SIGXFSZ, SIG_IGN);
    rlimit r = saved_;
    r.rlim_cur = bytes;
    setrlimit(RLIMIT_FSIZE, &r);
  }
  ~ScopedFileSizeLimit() {
    setrlimit(RLIMIT_FSIZE, &saved_);
    std::signal(SIGXFSZ, old_handler_);
  }

 private:
  rlimit saved_{};
  void (*old_handler_)(int) = nullptr;
};

TEST_F(RunCommandTest, AFullDiskStopsTheRunAtTheStepNamingTheFile) {
  const RunConfig c = SmallRun(8);
  RunFolderOptions o;
  o.out_dir = dir_ / "run";
  int steps = 0;
  o.on_step = [&](const pipeline::StepRecord&) { ++steps; };
  Status s;
  {
    const ScopedFileSizeLimit full(1500);  // metrics.csv's header and a few rows
    s = RunToFolder(CheckedRunConfig::Check(c, registries_).value(), o).status();
  }
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr((o.out_dir / "metrics.csv").string()));
  EXPECT_THAT(s.message(), HasSubstr("File too large"));
  EXPECT_LT(steps, 8) << "the episode went on after metrics.csv could not be written";
  EXPECT_FALSE(fs::exists(o.out_dir / "record.json"));
  const Result<FolderState> state = ReadFolderState(o.out_dir);
  ASSERT_TRUE(state.ok()) << state.status().ToString();
  EXPECT_EQ(state->state, "failed");
  EXPECT_THAT(state->error, HasSubstr("metrics.csv"));
}

TEST_F(RunCommandTest, BenchFolderHasTheLifecycleAndRefusesReruns) {
  BenchConfig o;
  o.scenarios = {"tomato-single-cluster"};
  o.planners = {"predefined"};
  o.seeds = {0};
  o.base.episode.views = 2;
  o.base.map.grid.voxel_size_m = 0.01;
  o.out_dir = dir_ / "bench";
  o.progress = false;
  ASSERT_TRUE(RunBench(o, registries_).ok());
  EXPECT_EQ(ReadFolderState(o.out_dir).value().state, "complete");
  EXPECT_EQ(ReadFolderState(o.out_dir).value().kind, "bench");
  const fs::path run = o.out_dir / "runs" / "tomato-single-cluster" / "predefined" / "seed-0";
  EXPECT_EQ(ReadFolderState(run).value().state, "complete");
  EXPECT_TRUE(fs::exists(run / "record.json"));

  const Status refused = RunBench(o, registries_).status();
  EXPECT_EQ(refused.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(refused.message(), HasSubstr("the results of a complete avp bench"));
  o.force = true;
  o.seeds = {3};
  ASSERT_TRUE(RunBench(o, registries_).ok());
  EXPECT_FALSE(fs::exists(run)) << "--force left the earlier bench's runs";
  EXPECT_TRUE(fs::exists(o.out_dir / "runs" / "tomato-single-cluster" / "predefined" / "seed-3"));
  // A run folder is not a bench folder.
  RunFolderOptions ro;
  ro.out_dir = dir_ / "run";
  ASSERT_TRUE(RunToFolder(CheckedRunConfig::Check(SmallRun(), registries_).value(), ro).ok());
  o.out_dir = ro.out_dir;
  EXPECT_THAT(RunBench(o, registries_).status().message(),
              HasSubstr("not an avp bench folder, so --force does not empty it"));
  EXPECT_TRUE(fs::exists(ro.out_dir / "record.json"));
}

/// A bench of two conditions: as it is, and with avp-nbv stopping early and smaller masks.
constexpr const char* kTwoConditions = R"(description: two conditions
scenarios: [tomato-single-cluster]
planners: [avp-nbv, predefined]
seeds: [0, 1]
run: {episode: {views: 3}, map: {grid: {voxel_size_m: 0.01}}}
conditions:
  - name: plain
  - name: stop-early
    description: avp-nbv stops at its second plan, masks 1 px smaller
    run: {segmenter: {options: {boundary_offset_px: -1}}}
    planner_options: {avp-nbv: {min_gain_fraction: 0.99}}
)";

TEST_F(RunCommandTest, BenchConditionsRunOneBenchEachAndCompareThem) {
  const fs::path yaml = dir_ / "conditions.yaml";
  std::ofstream(yaml) << kTwoConditions;
  auto config = LoadBenchConfig(yaml);
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  ASSERT_EQ(config->conditions.size(), 2u);
  EXPECT_EQ(config->conditions[1].run,
            (OptionValues{{"segmenter.options.boundary_offset_px", "-1"}}));
  config->out_dir = dir_ / "out";
  config->progress = false;
  auto derived = ConditionBenchConfig(*config, config->conditions[1]);
  ASSERT_TRUE(derived.ok()) << derived.status().ToString();
  EXPECT_EQ(derived->out_dir, dir_ / "out" / "stop-early");
  EXPECT_EQ(derived->base.segmenter.options, (OptionValues{{"boundary_offset_px", "-1"}}));
  EXPECT_EQ(derived->base.episode.views, 3);
  EXPECT_DOUBLE_EQ(derived->base.map.grid.voxel_size_m, 0.01);  // the bench's run stays
  EXPECT_EQ(derived->planner_options.at("avp-nbv"), (OptionValues{{"min_gain_fraction", "0.99"}}));
  EXPECT_EQ(derived->description,
            "two conditions; condition stop-early: avp-nbv stops at its second plan, masks 1 px "
            "smaller");
  EXPECT_TRUE(derived->conditions.empty());

  const auto r = RunBenchConditions(*config, registries_);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->episodes, 8u);
  EXPECT_EQ(r->failed, 0u);
  EXPECT_EQ(ReadFolderState(config->out_dir).value().kind, "bench-conditions");
  EXPECT_EQ(ReadFolderState(config->out_dir).value().state, "complete");
  EXPECT_EQ(ReadFolderState(config->out_dir / "plain").value().kind, "bench");
  EXPECT_TRUE(fs::exists(config->out_dir / "stop-early" / "summary.md"));
  // Each condition's bench is the bench it stands for: the same episodes as run alone.
  BenchConfig alone = *derived;
  alone.out_dir = dir_ / "alone";
  const auto a = RunBench(alone, registries_);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_EQ(r->benches[1].second.cells.size(), a->cells.size());
  for (size_t i = 0; i < a->cells.size(); ++i) {
    EXPECT_EQ(r->benches[1].second.cells[i].final_f1_mean, a->cells[i].final_f1_mean);
  }
  // avp-nbv stops where its second plan expects less than 0.99 x its first's (seeds differ).
  const report::ConditionTables& t = r->tables;
  ASSERT_EQ(t.cells.size(), 4u);
  EXPECT_EQ(t.cells[0].condition, "plain");
  EXPECT_DOUBLE_EQ(t.cells[0].views.mean, 3.0);
  EXPECT_EQ(t.cells[2].condition, "stop-early");
  EXPECT_EQ(t.cells[2].planner, "avp-nbv");
  EXPECT_GE(t.cells[2].views.mean, 2.0);
  EXPECT_LT(t.cells[2].views.mean, 3.0);
  EXPECT_DOUBLE_EQ(t.cells[3].views.mean, 3.0);
  ASSERT_EQ(t.leads.size(), 2u);
  EXPECT_EQ(t.leads[0].versus, "predefined");
  EXPECT_EQ(t.leads[0].f1.n, 2u);
  EXPECT_NEAR(t.leads[0].f1.mean, t.cells[0].f1.mean - t.cells[1].f1.mean, 1e-12);
  const std::string text = test::ReadWholeFile(config->out_dir / "conditions.md");
  EXPECT_THAT(text, HasSubstr("| stop-early | `"));
  EXPECT_THAT(text, HasSubstr("## tomato-single-cluster"));

  // A rerun is refused, --force replaces it; its folder is not a bench folder.
  EXPECT_THAT(RunBenchConditions(*config, registries_).status().message(),
              HasSubstr("the results of a complete avp bench (bench-conditions"));
  BenchConfig plain_bench = *config;
  plain_bench.conditions.clear();
  plain_bench.force = true;
  EXPECT_THAT(RunBench(plain_bench, registries_).status().message(),
              HasSubstr("not an avp bench folder"));
}

TEST_F(RunCommandTest, BadBenchConditionsAreNamedBeforeAnythingRuns) {
  const fs::path yaml = dir_ / "conditions.yaml";
  std::ofstream(yaml) << kTwoConditions;
  auto config = LoadBenchConfig(yaml);
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  config->out_dir = dir_ / "out";
  config->progress = false;
  BenchConfig bad = *config;
  bad.out_dir = dir_ / "bad";
  bad.conditions[0].name = "../up";
  bad.conditions[1].run.emplace_back("episode.viewz", "3");
  bad.conditions.push_back(bad.conditions[1]);
  bad.conditions.push_back({.name = "other",
                            .description = "",
                            .run = {},
                            .planner_options = {{"random", {{"x", "1"}}}}});
  const std::string m = RunBenchConditions(bad, registries_).status().message();
  EXPECT_THAT(m, HasSubstr("condition name '../up' must be a folder name"));
  EXPECT_THAT(m, HasSubstr("condition 'stop-early': run: "));
  EXPECT_THAT(m, HasSubstr("episode.viewz"));
  EXPECT_THAT(m, HasSubstr("condition 'stop-early' is given twice"));
  EXPECT_THAT(m, HasSubstr("condition 'other': invalid bench configuration: options are given "
                           "for planner 'random'"));
  EXPECT_FALSE(fs::exists(bad.out_dir));
  std::ofstream(yaml) << "scenarios: [tomato-single-cluster]\nplanners: [avp-nbv]\nseeds: [0]\n"
                         "conditions: [{name: a, run: {seed: 3}}]\n";
  EXPECT_THAT(LoadBenchConfig(yaml).status().message(),
              HasSubstr("conditions[0]: run.seed is set by each job"));
  std::ofstream(yaml) << "scenarios: [tomato-single-cluster]\nplanners: [avp-nbv]\nseeds: [0]\n"
                         "conditions: [{name: a, colour: red}]\n";
  EXPECT_THAT(LoadBenchConfig(yaml).status().message(), HasSubstr("colour"));
}

TEST_F(RunCommandTest, RobustnessConfigIsValid) {
  auto r = LoadBenchConfig(fs::path(AVP_CONFIG_DIR) / "experiments" / "robustness.yaml");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->conditions.size(), 12u);
  EXPECT_EQ(r->planners.front(), "avp-nbv");
  EXPECT_TRUE(r->Validate(registries_).ok()) << r->Validate(registries_).ToString();
}

TEST_F(RunCommandTest, BenchLimitsEpisodesSeedsAndJobs) {
  BenchConfig o;
  o.scenarios = {"tomato-single-cluster", "tomato-full-occlusion"};
  o.planners = {"predefined", "avp-nbv"};
  o.seeds = {0, 1, 2};
  {
    const ScopedLimit limit(MaxBenchEpisodes(), 11);
    const Status s = o.Validate(registries_);
    EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
    EXPECT_THAT(s.message(), HasSubstr("2 scenarios x 2 planners x 3 seeds (12) exceeds the "
                                       "limit max_bench_episodes = 11"));
  }
  EXPECT_TRUE(o.Validate(registries_).ok());
  {
    // Each condition runs the whole bench again: 3 conditions x 12 episodes.
    BenchConfig c = o;
    c.conditions = {{"a", "", {}, {}}, {"b", "", {}, {}}, {"c", "", {}, {}}};
    const ScopedLimit limit(MaxBenchEpisodes(), 35);
    const Status s = c.Validate(registries_);
    EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
    EXPECT_THAT(s.message(), HasSubstr("2 scenarios x 2 planners x 3 seeds x 3 conditions (36) "
                                       "exceeds the limit max_bench_episodes = 35"));
    const ScopedLimit enough(MaxBenchEpisodes(), 36);
    EXPECT_TRUE(c.Validate(registries_).ok()) << c.Validate(registries_).ToString();
  }
  o.jobs = 5000;
  EXPECT_THAT(o.Validate(registries_).message(), HasSubstr("jobs (5000) must be in [0, 1024]"));
  o.jobs = 0;
  o.planners = {"predefined", ""};
  EXPECT_THAT(o.Validate(registries_).message(), HasSubstr("a planner name is empty"));
}

}  // namespace
}  // namespace avp::experiment

// report.html of a run folder (report/run_html.h): the data the page embeds against the run's
// own record (voxels per step, frustums, candidates, fruit found and missed) and the final map
// file, the page's size on the demo's episode, base64 and the page's escaping.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <tuple>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/experiment/episode_runner.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/file.h>
#include <avp/io/json.h>
#include <avp/mapping/map_file.h>
#include <avp/report/run_html.h>
#include <avp/report/run_report.h>
#include <avp/test/temp_dir_test.h>

namespace avp::report {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using ::testing::HasSubstr;

using Key = std::tuple<int, int, int>;
struct Cell {
  int cls = 0;
  int confidence = 0;
  int instance = 0;
};

int U16(const std::string& b, size_t o) {
  return static_cast<uint8_t>(b[o]) | static_cast<uint8_t>(b[o + 1]) << 8;
}

/// Applies one step's voxel changes (the page's binary records) to `state`.
void Apply(const json& voxels, const json& origin, std::map<Key, Cell>& state) {
  auto set = Base64Decode(voxels["set_b64"].get<std::string>());
  auto removed = Base64Decode(voxels["removed_b64"].get<std::string>());
  ASSERT_TRUE(set.ok() && removed.ok());
  ASSERT_EQ(set->size(), voxels["set"].get<size_t>() * 10);
  ASSERT_EQ(removed->size(), voxels["removed"].get<size_t>() * 6);
  const int ox = origin[0], oy = origin[1], oz = origin[2];
  for (size_t o = 0; o < removed->size(); o += 6) {
    const Key k{ox + U16(*removed, o), oy + U16(*removed, o + 2), oz + U16(*removed, o + 4)};
    ASSERT_EQ(state.erase(k), 1u) << "a removed voxel was not there";
  }
  for (size_t o = 0; o < set->size(); o += 10) {
    const Key k{ox + U16(*set, o), oy + U16(*set, o + 2), oz + U16(*set, o + 4)};
    state[k] = Cell{static_cast<uint8_t>((*set)[o + 6]), static_cast<uint8_t>((*set)[o + 7]),
                    U16(*set, o + 8)};
  }
}

class RunReportTest : public test::TempDirTest {
 protected:
  const experiment::Registries registries_ = experiment::BuiltinRegistries();
};

/// One step of the page against record.json's step and the episode's: the frustum (pose and
/// intrinsics), the masks picture with one row per instance, and (but after the last view) every
/// ranked candidate, the chosen one as the record has it.
void ExpectStepMatchesRecord(const json& step, const json& rstep, const RigidTransform& X_WC,
                             bool last, size_t view) {
  const json& cam = step["camera"];
  ASSERT_EQ(cam["X_WC"].size(), 12u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(cam["X_WC"][i * 4 + 3].get<double>(), X_WC.translation()(i), 1e-5);
  }
  EXPECT_EQ(cam["K"]["width"], 640);
  EXPECT_GT(cam["median_depth_m"].get<double>(), 0.1);
  const json& img = step["image"];
  EXPECT_EQ(img["width"], 320);
  EXPECT_EQ(img["instances"].size(), rstep["masks"].get<size_t>());
  auto jpeg = Base64Decode(img["jpeg"].get<std::string>());
  ASSERT_TRUE(jpeg.ok());
  ASSERT_GT(jpeg->size(), 1000u);
  EXPECT_EQ(static_cast<uint8_t>((*jpeg)[0]), 0xff);  // JPEG SOI
  EXPECT_EQ(static_cast<uint8_t>((*jpeg)[1]), 0xd8);
  if (last) {
    EXPECT_TRUE(step["plan"].is_null());  // no plan after the last view
    return;
  }
  const json& plan = step["plan"];
  ASSERT_TRUE(plan.is_object()) << "view " << view;
  EXPECT_EQ(plan["generated"], rstep["plan"]["generated"]);
  EXPECT_EQ(plan["ranked"], rstep["plan"]["reachable"]);
  EXPECT_EQ(plan["kept"], plan["ranked"]);
  EXPECT_EQ(plan["chosen_rank"], rstep["plan"]["chosen_rank"]);
  EXPECT_EQ(plan["candidates"]["utility"].size(), plan["kept"].get<size_t>());
  EXPECT_EQ(plan["candidates"]["eye"].size(), 3 * plan["kept"].get<size_t>());
  const json& top = rstep["plan"]["top_candidates"];
  ASSERT_GE(top.size(), 1u);
  for (size_t i = 0; i < top.size(); ++i) {
    const double u = top[i]["utility"].get<double>();
    EXPECT_NEAR(plan["candidates"]["utility"][i].get<double>(), u, 1e-5 * std::abs(u) + 1e-12);
  }
}

/// The final state is the final map's occupied voxels, with their class and instance.
void ExpectStateIsTheMap(const fs::path& map_file, const std::map<Key, Cell>& state) {
  auto map = mapping::LoadMap(map_file);
  ASSERT_TRUE(map.ok()) << map.status().ToString();
  size_t checked = 0;
  const float occupied = map->grid().occupied_log_odds();
  map->grid().ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    if (log_odds < occupied) return;
    const auto it = state.find({k.x, k.y, k.z});
    ASSERT_NE(it, state.end());
    const mapping::SemanticCell* cell = map->Semantic(k);
    const bool labelled = cell != nullptr && cell->has_label();
    EXPECT_EQ(it->second.cls, labelled ? cell->semantic_class : 0);
    EXPECT_EQ(it->second.instance, labelled ? cell->instance_id : 0);
    if (labelled) {
      EXPECT_NEAR(it->second.confidence / 255.0, cell->confidence, 0.5 / 255 + 1e-6);
    }
    ++checked;
  });
  EXPECT_EQ(checked, state.size());
  const size_t fruit_voxels =
      static_cast<size_t>(std::count_if(state.begin(), state.end(), [](const auto& kv) {
        return kv.second.cls == static_cast<int>(SemanticClass::kFruit);
      }));
  EXPECT_GT(fruit_voxels, 50u);
}

/// The ground-truth fruit, found and missed, as record.json has them.
void ExpectFruitsMatchRecord(const json& data, const json& record) {
  const json& fruits = data["fruits"];
  ASSERT_EQ(fruits.size(), record["fruits"].size());
  size_t found = 0;
  for (size_t i = 0; i < fruits.size(); ++i) {
    EXPECT_EQ(fruits[i]["found"], record["fruits"][i]["found"]);
    EXPECT_EQ(fruits[i]["center_m"], record["fruits"][i]["center_m"]);
    EXPECT_EQ(fruits[i]["radius_m"], record["fruits"][i]["radius_m"]);
    found += fruits[i]["found"].get<bool>() ? 1 : 0;
  }
  EXPECT_EQ(data["expected"]["fruit_found"], found);
  EXPECT_EQ(data["expected"]["fruit_missed"], fruits.size() - found);
  EXPECT_EQ(found, record["final_metrics"]["fruits_found"].get<size_t>());
}

TEST_F(RunReportTest, ThePageHoldsWhatTheRunRecorded) {
  experiment::RunConfig c;
  c.scenario = "tomato-single-cluster";
  c.seed = 2;
  c.episode.views = 4;
  c.threads = 2;
  experiment::RunFolderOptions o;
  o.out_dir = dir_ / "run";
  auto r = experiment::RunToFolder(experiment::CheckedRunConfig::Check(c, registries_).value(), o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const fs::path html = o.out_dir / "report.html";
  ASSERT_TRUE(fs::exists(html));
  EXPECT_EQ(r->files.back(), html);
  auto record = io::ReadJsonFile(o.out_dir / "record.json");
  ASSERT_TRUE(record.ok());
  auto data = ReadRunReportData(html);
  ASSERT_TRUE(data.ok()) << data.status().ToString();
  EXPECT_EQ((*data)["format"], "avp-run-report");
  EXPECT_EQ((*data)["version"], 1);
  EXPECT_THAT((*data)["title"].get<std::string>(), HasSubstr("avp-nbv"));

  // One step per fused view; replaying the voxel changes gives each step's occupied voxels.
  const json& steps = (*data)["steps"];
  const json& rsteps = (*record)["steps"];
  ASSERT_EQ(steps.size(), 4u);
  ASSERT_EQ(steps.size(), rsteps.size());
  std::map<Key, Cell> state;
  for (size_t k = 0; k < steps.size(); ++k) {
    Apply(steps[k]["voxels"], (*data)["origin_key"], state);
    const size_t occupied = rsteps[k]["occupied_voxels"].get<size_t>();
    EXPECT_GT(occupied, 1000u) << "view " << k + 1;
    EXPECT_EQ(state.size(), occupied) << "view " << k + 1;
    EXPECT_EQ(steps[k]["voxels"]["occupied"].get<size_t>(), occupied);
    EXPECT_EQ(steps[k]["view"], rsteps[k]["view"]);
    ASSERT_NO_FATAL_FAILURE(ExpectStepMatchesRecord(
        steps[k], rsteps[k], r->result.episode.steps[k].X_WC, k + 1 == steps.size(), k + 1));
  }
  EXPECT_EQ((*data)["expected"]["voxels"], rsteps.back()["occupied_voxels"]);
  EXPECT_EQ((*data)["expected"]["frustums"], (*record)["views_fused"]);

  ASSERT_NO_FATAL_FAILURE(ExpectStateIsTheMap(o.out_dir / "map.avpmap", state));

  ASSERT_NO_FATAL_FAILURE(ExpectFruitsMatchRecord(*data, *record));
  // The curves' numbers are the record's metrics.
  EXPECT_NEAR(steps.back()["metrics"]["f1"].get<double>(),
              rsteps.back()["metrics"]["f1"].get<double>(), 1e-6);

  // The page: one data element, the viewer inline, nothing fetched from elsewhere.
  const std::string page = *io::ReadFileBounded(html, "report");
  EXPECT_THAT(page, HasSubstr("<script type=\"application/json\" id=\"avp-report-data\">"));
  EXPECT_EQ(page.find("<script src"), std::string::npos);
  EXPECT_EQ(page.find("<link"), std::string::npos);
}

/// Times the collector's OnView (what the report adds to each step).
class TimedCollector final : public pipeline::EpisodeObserver {
 public:
  void OnView(const pipeline::StepRecord& step, const pipeline::StepData& data,
              const mapping::SemanticMap& map) override {
    const auto t0 = std::chrono::steady_clock::now();
    collector.OnView(step, data, map);
    ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  void OnStep(const pipeline::StepRecord&, const mapping::SemanticMap&) override {}
  RunReportCollector collector;
  std::vector<double> ms;
};

TEST_F(RunReportTest, TheDemosEpisodeFitsInTenMegabytes) {
  // make demo's first run: tomato-full-occlusion, avp-nbv, oracle masks, 8 views, seed 0.
  experiment::RunConfig c;
  c.scenario = "tomato-full-occlusion";
  c.seed = 0;
  c.episode.views = 8;
  c.threads = 2;
  auto scene = experiment::LoadScene(c, registries_);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  auto gt = experiment::GroundTruthFor(c, *scene);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  TimedCollector timed;
  auto r = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(c, registries_).value(), *scene, *gt, {&timed});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  RunReportInfo info;
  info.title = "demo";
  info.fruits = FruitsJson(r->fruits);
  const fs::path html = dir_ / "report.html";
  ASSERT_TRUE(WriteRunReportHtml(html, timed.collector, info).ok());
  const uintmax_t bytes = fs::file_size(html);
  auto data = ReadRunReportData(html);
  ASSERT_TRUE(data.ok());
  size_t voxel_b64 = 0, image_b64 = 0, candidates = 0;
  for (const json& s : (*data)["steps"]) {
    voxel_b64 += s["voxels"]["set_b64"].get<std::string>().size() +
                 s["voxels"]["removed_b64"].get<std::string>().size();
    if (s["image"].is_object()) image_b64 += s["image"]["jpeg"].get<std::string>().size();
    if (s["plan"].is_object()) candidates += s["plan"]["kept"].get<size_t>();
  }
  double step_ms = 0.0, report_ms = 0.0;
  for (const auto& s : r->episode.steps) step_ms += s.times.total_ms;
  for (const double ms : timed.ms) report_ms += ms;
  std::printf(
      "report.html of the demo episode: %ju bytes (%zu views, %ju final occupied voxels; voxel "
      "changes %zu bytes base64, mask pictures %zu bytes base64, %zu candidates); collecting: "
      "%.1f ms per view (%.1f %% of the step's %.1f ms)\n",
      bytes, (*data)["steps"].size(), (*data)["expected"]["voxels"].get<uintmax_t>(), voxel_b64,
      image_b64, candidates, report_ms / timed.ms.size(), 100.0 * report_ms / step_ms,
      step_ms / timed.ms.size());
  EXPECT_EQ((*data)["steps"].size(), 8u);
  EXPECT_EQ((*data)["expected"]["voxels"].get<size_t>(), r->episode.steps.back().occupied_voxels);
  EXPECT_GT((*data)["expected"]["voxels"].get<size_t>(), 10000u);
  EXPECT_LE(bytes, 10u * 1000 * 1000);
}

TEST(RunReportCollector, KeepsEachViewsChangesAndAViewWithoutACapture) {
  // Two views on a hand-made map: what was added, relabelled and freed, with no capture, no
  // segmentation and no plan (a live view whose camera failed).
  mapping::SemanticMap map;
  mapping::OccupancyGrid& grid = map.grid();
  const float hit = grid.clamp_max_log_odds();
  const float free = grid.clamp_min_log_odds();
  for (int x = 0; x < 3; ++x) ASSERT_TRUE(grid.SetLogOdds({x - 1, 2, 100}, hit));
  ASSERT_TRUE(grid.SetLogOdds({5, 5, 5}, free));  // known, not occupied
  mapping::SemanticCell* fruit = grid.MutableSemantic({0, 2, 100});
  ASSERT_NE(fruit, nullptr);
  fruit->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
  fruit->instance_id = 7;
  fruit->confidence = 0.5f;
  RunReportCollector collector;
  pipeline::StepRecord step;
  step.X_WC = RigidTransform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.1, 0.2, 0.3));
  step.capture_status = UnavailableError("camera gone");
  collector.OnView(step, pipeline::StepData{}, map);
  // View 2: one voxel freed, one added, the fruit voxel's confidence changed.
  ASSERT_TRUE(grid.SetLogOdds({-1, 2, 100}, free));
  ASSERT_TRUE(grid.SetLogOdds({1, 3, 101}, hit));
  fruit = grid.MutableSemantic({0, 2, 100});
  fruit->confidence = 1.0f;
  step.view = 1;
  collector.OnView(step, pipeline::StepData{}, map);
  EXPECT_EQ(collector.OccupiedVoxelsPerStep(), (std::vector<size_t>{3, 3}));

  auto data = collector.Data(RunReportInfo{});
  ASSERT_TRUE(data.ok()) << data.status().ToString();
  EXPECT_EQ((*data)["origin_key"], json::array({-1, 2, 100}));
  EXPECT_TRUE((*data)["fruits"].is_null());
  const json& steps = (*data)["steps"];
  ASSERT_EQ(steps.size(), 2u);
  EXPECT_TRUE(steps[0]["camera"]["K"].is_null());
  EXPECT_TRUE(steps[0]["image"].is_null());
  EXPECT_TRUE(steps[0]["plan"].is_null());
  EXPECT_EQ(steps[0]["errors"]["capture"], "Unavailable: camera gone");
  EXPECT_EQ(steps[0]["camera"]["X_WC"],
            json::array({1.0, 0.0, 0.0, 0.1, 0.0, 1.0, 0.0, 0.2, 0.0, 0.0, 1.0, 0.3}));
  EXPECT_EQ(steps[0]["voxels"]["set"], 3);
  EXPECT_EQ(steps[0]["voxels"]["removed"], 0);
  EXPECT_EQ(steps[1]["voxels"]["set"], 2);  // the new voxel and the fruit's confidence
  EXPECT_EQ(steps[1]["voxels"]["removed"], 1);
  std::map<Key, Cell> state;
  Apply(steps[0]["voxels"], (*data)["origin_key"], state);
  ASSERT_EQ(state.size(), 3u);
  EXPECT_EQ(state[Key(0, 2, 100)].cls, static_cast<int>(SemanticClass::kFruit));
  EXPECT_EQ(state[Key(0, 2, 100)].instance, 7);
  EXPECT_EQ(state[Key(0, 2, 100)].confidence, 128);  // round(0.5 * 255)
  EXPECT_EQ(state[Key(1, 2, 100)].cls, 0);
  Apply(steps[1]["voxels"], (*data)["origin_key"], state);
  ASSERT_EQ(state.size(), 3u);
  EXPECT_EQ(state.count(Key(-1, 2, 100)), 0u);
  EXPECT_EQ(state.count(Key(1, 3, 101)), 1u);
  EXPECT_EQ(state[Key(0, 2, 100)].confidence, 255);
  EXPECT_EQ((*data)["expected"]["voxels"], 3);
  EXPECT_EQ((*data)["expected"]["frustums"], 2);
}

TEST(RunReportHtml, Base64RoundTripsAndNamesABadCharacter) {
  std::string all;
  for (int i = 0; i < 256; ++i) all.push_back(static_cast<char>(i));
  for (size_t n : {0u, 1u, 2u, 3u, 4u, 5u, 256u}) {
    const std::string in = all.substr(0, n);
    const std::string enc = Base64Encode(in);
    EXPECT_EQ(enc.size() % 4, 0u);
    auto dec = Base64Decode(enc);
    ASSERT_TRUE(dec.ok()) << dec.status().ToString();
    EXPECT_EQ(*dec, in) << n;
  }
  EXPECT_EQ(Base64Encode("Man"), "TWFu");
  EXPECT_EQ(Base64Encode("Ma"), "TWE=");
  EXPECT_EQ(Base64Encode("M"), "TQ==");
  const auto bad = Base64Decode("TW*u");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("offset 2"));
  EXPECT_FALSE(Base64Decode("TWF").ok());
}

TEST_F(RunReportTest, ThePageEscapesWhatCouldEndItsScripts) {
  RunReportCollector empty;
  RunReportInfo info;
  info.title = "a </script><b>title";
  info.facts = {{"scene", "</script>"}};
  auto data = empty.Data(info);
  ASSERT_TRUE(data.ok());
  EXPECT_EQ((*data)["steps"].size(), 0u);
  EXPECT_EQ((*data)["expected"]["voxels"], 0);
  const std::string page = RunReportHtml(*data, "var s = '</script>';", info.title);
  // Only the page's own two script elements end.
  size_t ends = 0;
  for (size_t p = page.find("</script"); p != std::string::npos; p = page.find("</script", p + 1)) {
    ++ends;
  }
  EXPECT_EQ(ends, 2u);
  EXPECT_THAT(page, HasSubstr("<title>a &lt;/script&gt;&lt;b&gt;title"));
  const fs::path path = dir_ / "report.html";
  ASSERT_TRUE(io::WriteFileAtomic(path, page).ok());
  auto back = ReadRunReportData(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ((*back)["title"], info.title);
  EXPECT_EQ((*back)["facts"][0][1], "</script>");
  // A page without data.
  ASSERT_TRUE(io::WriteFileAtomic(path, "<html></html>").ok());
  EXPECT_EQ(ReadRunReportData(path).status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace avp::report

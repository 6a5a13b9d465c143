// A user's own plant end to end: scene files of each supported mesh format (OBJ + MTL, PLY, STL,
// COLLADA, glTF 2 .gltf and .glb) through `avp bench` (seeds, ground truth, run folders,
// summaries), `avp map build`, `avp map gt` and `avp map compare`; the paper's arrangements of one
// plant (`@paper`), and the errors of bad entries. Library calls, plus the built `avp` once.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/experiment/bench.h>
#include <avp/experiment/map_build.h>
#include <avp/io/json.h>
#include <avp/mapping/map_tools.h>
#include <avp/sim/scene_file.h>
#include <avp/test/plant_mesh_files.h>
#include <avp/test/read_file.h>
#include <avp/test/run_command.h>
#include <avp/test/temp_dir_test.h>

namespace avp {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

std::vector<std::string> Lines(const fs::path& p) {
  std::vector<std::string> out;
  std::ifstream in(p);
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

/// The value of `column` in line `row` of a CSV file (NaN when absent).
double Cell(const fs::path& csv, size_t row, const std::string& column) {
  const std::vector<std::string> lines = Lines(csv);
  if (lines.size() <= row) return std::nan("");
  const auto split = [](const std::string& text) {
    std::vector<std::string> cells;
    std::string cell;
    for (std::istringstream in(text); std::getline(in, cell, ',');) cells.push_back(cell);
    return cells;
  };
  const std::vector<std::string> header = split(lines.front()), values = split(lines[row]);
  for (size_t i = 0; i < header.size() && i < values.size(); ++i) {
    if (header[i] == column) return std::stod(values[i]);
  }
  return std::nan("");
}

/// A bench of one fast planner, `seeds` seeds and 2 views on `scenarios`.
experiment::BenchConfig SmallBench(std::vector<std::string> scenarios, const fs::path& out,
                                   std::vector<uint64_t> seeds = {0, 1}) {
  experiment::BenchConfig b;
  b.scenarios = std::move(scenarios);
  b.planners = {"predefined"};
  b.seeds = std::move(seeds);
  b.base.episode.views = 2;
  b.out_dir = out;
  b.progress = false;
  return b;
}

class SceneFileFormatTest : public test::TempDirTest,
                            public ::testing::WithParamInterface<test::MeshFormat> {
 protected:
  const experiment::Registries registries_ = experiment::BuiltinRegistries();
};

TEST_P(SceneFileFormatTest, BenchMapBuildGtAndCompare) {
  const test::MeshFormat format = GetParam();
  const std::string name = "plant_" + format.ext;
  const fs::path yaml = test::WriteTestPlantScene(format, dir_ / "plant", name);

  // The file reads back as the plant: 7 fruit where they were placed.
  const Result<sim::Scene> scene = sim::LoadSceneFile(yaml);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  const std::vector<sim::FruitTruth> fruits = scene->Fruits();
  const test::TestPlant plant;
  ASSERT_EQ(fruits.size(), plant.fruit_centres.size());
  for (const Eigen::Vector3d& c : plant.fruit_centres) {
    double nearest = 1e9;
    for (const sim::FruitTruth& f : fruits) nearest = std::min(nearest, (f.center_W - c).norm());
    EXPECT_LT(nearest, 0.002) << format.ext << ": no fruit at " << c.transpose();
  }

  // avp bench: two seeds of the same scene (one file read), ground truth, run folders, summary.
  const experiment::BenchConfig bench = SmallBench({yaml.string()}, dir_ / "bench");
  const Result<experiment::BenchSummary> r = experiment::RunBench(bench, registries_);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->episodes, 2u);
  EXPECT_EQ(r->failed, 0u);
  ASSERT_EQ(r->cells.size(), 1u);
  EXPECT_EQ(r->cells[0].scenario, name);
  EXPECT_GT(r->cells[0].final_f1_mean, 0.05);
  int f1_rows = 0;
  for (const std::string& l : Lines(bench.out_dir / "summary.csv")) {
    if (l.find(",f1,") == std::string::npos) continue;
    ++f1_rows;
    EXPECT_EQ(l.substr(0, name.size() + 1), name + ",") << l;
    EXPECT_TRUE(l.ends_with(",2,")) << l;  // two seeds, no `versus`
  }
  EXPECT_EQ(f1_rows, 2);  // two views
  EXPECT_THAT(test::ReadWholeFile(bench.out_dir / "summary.md"), HasSubstr(name));
  for (int seed : {0, 1}) {
    const fs::path run =
        bench.out_dir / "runs" / name / "predefined" / ("seed-" + std::to_string(seed));
    const Result<nlohmann::json> record = io::ReadJsonFile(run / "record.json");
    ASSERT_TRUE(record.ok()) << record.status().ToString();
    EXPECT_EQ((*record)["scenario"], name);
    EXPECT_EQ((*record)["scene_file"], yaml.string());
    EXPECT_FALSE(record->contains("arrangement"));
    EXPECT_EQ((*record)["seed"], seed);
    EXPECT_EQ(Lines(run / "metrics.csv").size(), 3u);  // header + 2 views
  }

  // avp map build / gt / compare on the same file.
  experiment::MapBuildOptions build;
  build.scene.scene_file = yaml;
  build.views = 3;
  build.map.grid.voxel_size_m = 0.008;
  build.out = dir_ / "maps" / "plant.avpmap";
  const Result<experiment::MapBuildSummary> built =
      experiment::BuildMap(build, registries_.scenarios);
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  EXPECT_EQ(built->scene_name, name);
  EXPECT_EQ(built->total_fruits, 7u);
  EXPECT_GT(built->fruit_voxels, 100u);
  experiment::MapGtOptions gt;
  gt.scene.scene_file = yaml;
  gt.voxel_size_m = 0.008;
  gt.out = dir_ / "maps" / "gt.bt";
  const Result<experiment::MapGtSummary> written =
      experiment::WriteGroundTruthOctree(gt, registries_.scenarios);
  ASSERT_TRUE(written.ok()) << written.status().ToString();
  EXPECT_EQ(written->fruits, 7u);
  EXPECT_GT(written->voxels, 300u);
  mapping::MapCompareOptions compare;
  compare.map = build.out;
  compare.gt = gt.out;
  const Result<mapping::MapCompareSummary> c = mapping::CompareMapFiles(compare);
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  ASSERT_GE(c->results.size(), 2u);
  // The map sees the fruit's near halves from a 120-degree arc: precise, half the surface found.
  const mapping::GroundTruthComparison& tolerant = c->results[1];
  EXPECT_GT(tolerant.precision, 0.8) << format.ext;
  EXPECT_GT(tolerant.recall, 0.3) << format.ext;
  EXPECT_GT(c->results[0].f1, 0.2) << format.ext;
}

INSTANTIATE_TEST_SUITE_P(AllFormats, SceneFileFormatTest,
                         ::testing::ValuesIn(test::AllMeshFormats()),
                         [](const ::testing::TestParamInfo<test::MeshFormat>& p) {
                           return p.param.ext;
                         });

class SceneFileBenchTest : public test::TempDirTest {
 protected:
  const experiment::Registries registries_ = experiment::BuiltinRegistries();
  fs::path Plant(const std::string& name = "plant") {
    return test::WriteTestPlantScene({"obj", "obj"}, dir_ / "scenes", name);
  }
};

TEST_F(SceneFileBenchTest, PaperExpandsToTheFourArrangements) {
  const fs::path yaml = Plant();
  const Result<std::vector<experiment::BenchScenario>> list = experiment::ExpandScenarioList(
      {"tomato-single-cluster", yaml.string() + "@paper"}, registries_.scenarios);
  ASSERT_TRUE(list.ok()) << list.status().ToString();
  ASSERT_EQ(list->size(), 5u);
  EXPECT_EQ((*list)[0].display_name, "tomato-single-cluster");
  const std::vector<std::string> names = {"reference", "full-occlusion", "single-cluster",
                                          "unoriented-start"};
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ((*list)[i + 1].arrangement, names[i]);
    EXPECT_EQ((*list)[i + 1].scene_file, yaml);
    EXPECT_EQ((*list)[i + 1].entry, yaml.string() + "@paper");
  }

  // One seed of each arrangement: names, ground truth and the start views differ as arranged.
  const experiment::BenchConfig bench = SmallBench({yaml.string() + "@paper"}, dir_ / "bench", {3});
  const Result<experiment::BenchSummary> r = experiment::RunBench(bench, registries_);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->episodes, 4u);
  EXPECT_EQ(r->failed, 0u);
  std::map<std::string, const report::BenchCell*> cells;
  for (const report::BenchCell& c : r->cells) cells[c.scenario] = &c;
  for (const std::string& n : names) {
    ASSERT_EQ(cells.count("plant@" + n), 1u) << n;
    const fs::path run = bench.out_dir / "runs" / ("plant_" + n) / "predefined" / "seed-3";
    const Result<nlohmann::json> record = io::ReadJsonFile(run / "record.json");
    ASSERT_TRUE(record.ok()) << record.status().ToString();
    EXPECT_EQ((*record)["scenario"], "plant@" + n);
    EXPECT_EQ((*record)["arrangement"], n);
  }
  // single-cluster keeps the 4 fruit of the upper row (of 7); the others keep all 7. In the
  // first view (the start view), unoriented-start sees no fruit, full-occlusion fewer than the
  // reference.
  const auto metrics = [&](const std::string& n) {
    return bench.out_dir / "runs" / ("plant_" + n) / "predefined" / "seed-3" / "metrics.csv";
  };
  EXPECT_EQ(Cell(metrics("reference"), 2, "fruits_total"), 7.0);
  EXPECT_EQ(Cell(metrics("single-cluster"), 2, "fruits_total"), 4.0);
  EXPECT_EQ(Cell(metrics("unoriented-start"), 2, "fruits_total"), 7.0);
  EXPECT_EQ(Cell(metrics("full-occlusion"), 2, "fruits_total"), 7.0);
  const auto first_found = [&](const std::string& n) {
    return Cell(metrics(n), 1, "fruits_found");
  };
  // The reference start view holds the upper row (4 fruit); the lower row is below its field.
  EXPECT_EQ(first_found("reference"), 4.0);
  EXPECT_EQ(first_found("unoriented-start"), 0.0);
  EXPECT_LT(first_found("full-occlusion"), first_found("reference"));
}

TEST_F(SceneFileBenchTest, BadEntriesNameTheEntryAndTheFile) {
  const fs::path yaml = Plant();
  int run = 0;  // a failed bench leaves its folder marked failed: each try gets its own
  const auto message = [&](std::vector<std::string> scenarios) {
    const Result<experiment::BenchSummary> r = experiment::RunBench(
        SmallBench(std::move(scenarios), dir_ / ("bench" + std::to_string(++run)), {0}),
        registries_);
    EXPECT_FALSE(r.ok());
    return r.ok() ? std::string() : r.status().message();
  };
  const std::string missing = (dir_ / "nowhere" / "plant.yaml").string();
  EXPECT_THAT(message({missing}), HasSubstr("scenarios entry '" + missing + "': scene file '" +
                                            missing + "' does not exist"));
  EXPECT_THAT(message({yaml.string() + "@sideways"}), HasSubstr("unknown arrangement 'sideways'"));
  EXPECT_THAT(message({yaml.string() + "@"}), HasSubstr("no arrangement after '@'"));
  EXPECT_THAT(message({"tomato-single-cluster@full-occlusion"}),
              HasSubstr("arrangement 'full-occlusion' is for scene files"));
  EXPECT_THAT(message({"tomato-single-cluster@paper"}), HasSubstr("'paper' arranges a scene file"));
  EXPECT_THAT(message({"my_plant"}), HasSubstr("unknown scenario 'my_plant'"));
  // A file that does not parse: the entry, the file and the parser's message.
  std::ofstream(dir_ / "scenes" / "broken.yaml") << "version: 1\nmeshes: [{file: none.obj}]\n";
  const std::string broken = (dir_ / "scenes" / "broken.yaml").string();
  const std::string m = message({broken});
  EXPECT_THAT(m, HasSubstr("scenarios entry '" + broken + "' (scene file '" + broken + "')"));
  EXPECT_THAT(m, HasSubstr("none.obj"));
  // Two files whose scenes have the same name: both entries named.
  const fs::path twin = test::WriteTestPlantScene({"ply", "ply"}, dir_ / "twin", "plant");
  const std::string dup = message({yaml.string(), twin.string()});
  EXPECT_THAT(dup, HasSubstr("have the same name 'plant'"));
  EXPECT_THAT(dup, HasSubstr(yaml.string()));
  EXPECT_THAT(dup, HasSubstr(twin.string()));
  // A scene file inside the bench folder is refused (--force would remove it).
  const fs::path inside = test::WriteTestPlantScene(
      {"obj", "obj"}, dir_ / ("bench" + std::to_string(run + 1)) / "in", "x");
  EXPECT_THAT(message({inside.string()}), HasSubstr("is inside the bench folder"));
}

TEST_F(SceneFileBenchTest, ConfigPathsAreRelativeToTheConfig) {
  Plant();
  fs::create_directories(dir_ / "experiments");
  std::ofstream(dir_ / "experiments" / "own.yaml")
      << "scenarios: [tomato-single-cluster, ../scenes/plant.yaml@unoriented-start, "
         "../scenes/plant.yaml]\nplanners: [predefined]\nseeds: [0]\n";
  const Result<experiment::BenchConfig> b =
      experiment::LoadBenchConfig(dir_ / "experiments" / "own.yaml");
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->scenarios, (std::vector<std::string>{
                              "tomato-single-cluster",
                              (dir_ / "scenes" / "plant.yaml").string() + "@unoriented-start",
                              (dir_ / "scenes" / "plant.yaml").string()}));
  EXPECT_TRUE(b->Validate(registries_).ok()) << b->Validate(registries_).ToString();
  // The shipped example: the example plant arranged the paper's four ways.
  const Result<experiment::BenchConfig> own =
      experiment::LoadBenchConfig(fs::path(AVP_CONFIG_DIR) / "experiments" / "own-plant.yaml");
  ASSERT_TRUE(own.ok()) << own.status().ToString();
  EXPECT_TRUE(own->Validate(registries_).ok()) << own->Validate(registries_).ToString();
  const Result<std::vector<experiment::BenchScenario>> list =
      experiment::ExpandScenarioList(own->scenarios, registries_.scenarios);
  ASSERT_TRUE(list.ok());
  EXPECT_EQ(list->size(), 4u);
}

#ifdef AVP_BINARY
using test::Ran;

/// Runs the built avp with `args` through the shell, stdout and stderr together.
Ran Avp(const std::string& args) { return test::RunShell("'" AVP_BINARY "' " + args + " 2>&1"); }

TEST_F(SceneFileBenchTest, TheCommandLineTakesSceneFilesAndArrangements) {
  const fs::path yaml = Plant();
  const std::string d = dir_.string();
  Ran r = Avp("bench --scenarios '" + yaml.string() +
              "@unoriented-start' --planners predefined --seeds 1 --views 2 --jobs 2 --out '" + d +
              "/bench'");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("plant@unoriented-start"));
  r = Avp("map build --scene '" + yaml.string() +
          "' --arrangement single-cluster --views 2 --out '" + d + "/m.avpmap'");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("map of 'plant@single-cluster'"));
  EXPECT_THAT(r.output, HasSubstr("(4 fruits in the scene)"));
  r = Avp("map gt --scene '" + yaml.string() + "' --out '" + d + "/gt.bt'");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("of 7 fruits of 'plant'"));
  r = Avp("map gt --scene '" + yaml.string() + "' --arrangement paper --out '" + d + "/gt2.bt'");
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("only in an avp bench scenario list"));
  r = Avp("run --scenario tomato-single-cluster --arrangement full-occlusion --print-config");
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("arrangement 'full-occlusion' needs a scene file"));
  r = Avp("run --scene '" + yaml.string() + "' --arrangement unoriented-start --print-config");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("arrangement: unoriented-start"));
}
#endif

}  // namespace
}  // namespace avp

// End-to-end: `avp map build | gt | info | export | compare` as library calls (experiment's
// BuildMap and WriteGroundTruthOctree, mapping's map tools): a map of a simulated
// plant is built, described, exported to OctoMap and PLY, and scored against the scene's fruit
// ground truth; bad input gives messages that name the bad value.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <string>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/experiment/map_build.h>
#include <avp/experiment/registries.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/json.h>
#include <avp/mapping/map_tools.h>
#include <avp/mapping/octomap_io.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp {
namespace {

using experiment::MapBuildOptions;
using experiment::MapBuildSummary;
using experiment::MapBuildView;
using experiment::MapGtOptions;
using experiment::MapGtSummary;
using mapping::FormatMapCompare;
using mapping::FormatMapInfo;
using mapping::MapCompareOptions;
using mapping::MapCompareSummary;
using mapping::MapExportFormat;
using mapping::MapExportOptions;
using mapping::MapExportSummary;
using mapping::MapInfo;

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

class MapCommandTest : public test::TempDirTest {
 protected:
  const sim::ScenarioRegistry scenarios_ = sim::BuiltinScenarios();
  MapBuildOptions SmallBuild() const {
    MapBuildOptions o;
    o.scene.scenario = "tomato-single-cluster";
    o.scene.seed = 1;
    o.views = 3;
    o.map.grid.voxel_size_m = 0.008;
    // The reference system's fusion and ray-cast carving (the defaults are bayesian, projective).
    o.map.semantics.policy = mapping::FusionPolicy::kReferenceMax;
    o.integrator.carving = mapping::FreeSpaceCarving::kRayCast;
    o.out = dir_ / "maps" / "plant.avpmap";
    return o;
  }
};

/// `map info` of a built map: the build's counts, its options and its provenance note.
MapInfo ExpectInfoOfBuiltMap(const MapBuildOptions& build, const MapBuildSummary& built) {
  const Result<MapInfo> info = mapping::ReadMapInfo(build.out);
  EXPECT_TRUE(info.ok()) << info.status().ToString();
  if (!info.ok()) return {};
  EXPECT_EQ(info->known_voxels, built.known_voxels);
  EXPECT_EQ(info->occupied_voxels, built.occupied_voxels);
  EXPECT_EQ(info->free_voxels + info->occupied_voxels, info->known_voxels);
  EXPECT_EQ(info->labelled_voxels, built.labelled_voxels);
  EXPECT_EQ(info->occupied_by_class[static_cast<size_t>(SemanticClass::kFruit)],
            built.fruit_voxels);
  EXPECT_EQ(info->instances.size(), built.instances.size());
  EXPECT_EQ(info->options.semantics.policy, mapping::FusionPolicy::kReferenceMax);
  EXPECT_TRUE(info->options.grid.roi.has_value());
  const std::string text = FormatMapInfo(*info);
  EXPECT_THAT(text, HasSubstr("format version 2"));
  EXPECT_THAT(text, HasSubstr("voxel size   8 mm"));
  EXPECT_THAT(text, HasSubstr("reference-max"));
  EXPECT_THAT(text, HasSubstr("--scenario tomato-single-cluster --seed 1 --views 3"));
  EXPECT_THAT(text, HasSubstr("fruit"));
  if (!info->instances.empty()) {
    EXPECT_THAT(text, HasSubstr(fmt::format("instances    {} (segments of the fused masks",
                                            info->instances.size())));
  }

  return *info;
}

/// `map export` to bt, ot (format from the extension) and ply.
void ExpectExports(const MapBuildOptions& build, const MapBuildSummary& built, const MapInfo& info,
                   const fs::path& dir_) {
  MapExportOptions exp;
  exp.map = build.out;
  exp.format = "bt";
  exp.out = dir_ / "plant.bt";
  Result<MapExportSummary> exported = mapping::ExportMapFile(exp);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_EQ(exported->occupied_voxels, built.occupied_voxels);
  const auto back = mapping::ImportOctomapOccupied(exp.out);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->keys.size(), built.occupied_voxels);
  exp.format.clear();
  exp.out = dir_ / "plant.ot";
  exported = mapping::ExportMapFile(exp);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_EQ(exported->format, MapExportFormat::kOt);
  EXPECT_GT(exported->labelled_voxels, 0u);
  exp.format = "ply";
  exp.out = dir_ / "plant.ply";
  exported = mapping::ExportMapFile(exp);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  const size_t occupied_labelled = info.occupied_by_class[1] + info.occupied_by_class[2] +
                                   info.occupied_by_class[3] + info.occupied_by_class[4] +
                                   info.occupied_by_class[5] + info.occupied_by_class[6];
  EXPECT_EQ(exported->labelled_voxels, occupied_labelled);
  EXPECT_EQ(exported->ply_voxels, mapping::PlyVoxels::kLabelled);
  EXPECT_EQ(exported->unlabelled_voxels, 0u);
  // --voxels all-labelled: every labelled voxel; --voxels occupied: the whole plant.
  exp.ply_voxels = mapping::PlyVoxels::kAllLabelled;
  exported = mapping::ExportMapFile(exp);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_EQ(exported->labelled_voxels, info.labelled_voxels);
  EXPECT_EQ(exported->not_occupied_voxels, info.labelled_voxels - occupied_labelled);
  exp.ply_voxels = mapping::PlyVoxels::kOccupied;
  exported = mapping::ExportMapFile(exp);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_EQ(exported->ply_voxels, mapping::PlyVoxels::kOccupied);
  EXPECT_EQ(exported->occupied_voxels, built.occupied_voxels);
  EXPECT_EQ(exported->labelled_voxels, occupied_labelled);
  EXPECT_EQ(exported->unlabelled_voxels, built.occupied_voxels - occupied_labelled);
  EXPECT_GT(exported->unlabelled_voxels, 0u);  // leaves and stem the masks did not cover
  EXPECT_EQ(exported->file_bytes, fs::file_size(exp.out));
  // Other formats have no choice of voxels: refused, naming the format.
  exp.format = "bt";
  exp.out = dir_ / "plant2.bt";
  const Status refused = mapping::ExportMapFile(exp).status();
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.message(), HasSubstr("--voxels occupied applies to PLY only"));
  EXPECT_THAT(refused.message(), HasSubstr("'bt' (from --format)"));
  EXPECT_FALSE(fs::exists(exp.out));
}

/// `map gt` + `map compare`: at 6 mm the GT is resampled onto the 8 mm map; at 8 mm it is not.
void ExpectComparisons(const MapBuildOptions& build, const MapBuildSummary& built,
                       const sim::ScenarioRegistry& scenarios_, const fs::path& dir_) {
  MapGtOptions gt;
  gt.scene = build.scene;
  gt.voxel_size_m = 0.006;
  gt.out = dir_ / "gt6.bt";
  const Result<MapGtSummary> gt_summary = experiment::WriteGroundTruthOctree(gt, scenarios_);
  ASSERT_TRUE(gt_summary.ok()) << gt_summary.status().ToString();
  EXPECT_GT(gt_summary->voxels, 100u);

  MapCompareOptions cmp;
  cmp.map = build.out;
  cmp.gt = gt.out;
  cmp.tolerance_voxels = 1;
  cmp.json_out = dir_ / "compare.json";
  const Result<MapCompareSummary> compared = mapping::CompareMapFiles(cmp);
  ASSERT_TRUE(compared.ok()) << compared.status().ToString();
  ASSERT_EQ(compared->results.size(), 2u);
  const auto& exact = compared->results[0];
  const auto& tol = compared->results[1];
  EXPECT_TRUE(exact.resampled);
  EXPECT_EQ(exact.gt_voxels_original, gt_summary->voxels);
  EXPECT_EQ(exact.predicted, built.fruit_voxels);
  EXPECT_EQ(exact.tp + exact.fp, exact.predicted);
  EXPECT_EQ(exact.gt_found + exact.fn, exact.ground_truth);
  EXPECT_EQ(exact.tp, exact.gt_found);
  EXPECT_GE(tol.tp, exact.tp);
  EXPECT_GE(tol.gt_found, exact.gt_found);
  // Ground-truth masks: what the map calls fruit lies on (or next to) a fruit surface.
  EXPECT_GT(tol.precision, 0.8);
  EXPECT_GT(tol.recall, 0.1);
  const std::string report = FormatMapCompare(*compared);
  EXPECT_THAT(report, HasSubstr("resolutions differ"));
  EXPECT_THAT(report, HasSubstr("+-1 voxel"));
  const auto json = io::ReadJsonFile(cmp.json_out);
  ASSERT_TRUE(json.ok()) << json.status().ToString();
  EXPECT_EQ((*json)["results"][1]["tp"].get<size_t>(), tol.tp);
  EXPECT_EQ((*json)["results"][0]["fn"].get<size_t>(), exact.fn);
  EXPECT_TRUE((*json)["resampled"].get<bool>());

  gt.voxel_size_m = 0.008;
  gt.out = dir_ / "gt8.bt";
  ASSERT_TRUE(experiment::WriteGroundTruthOctree(gt, scenarios_).ok());
  cmp.gt = gt.out;
  cmp.tolerance_voxels = 0;
  cmp.json_out.clear();
  const Result<MapCompareSummary> same = mapping::CompareMapFiles(cmp);
  ASSERT_TRUE(same.ok()) << same.status().ToString();
  ASSERT_EQ(same->results.size(), 1u);
  EXPECT_FALSE(same->results[0].resampled);
  EXPECT_THAT(FormatMapCompare(*same), Not(HasSubstr("resolutions differ")));
}

TEST_F(MapCommandTest, BuildInfoExportCompareEndToEnd) {
  MapBuildOptions build = SmallBuild();
  std::vector<MapBuildView> progress;
  build.on_view = [&](const MapBuildView& v) { progress.push_back(v); };
  const Result<MapBuildSummary> built = experiment::BuildMap(build, scenarios_);
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  ASSERT_EQ(progress.size(), 3u);
  for (size_t i = 0; i < progress.size(); ++i) {
    EXPECT_EQ(progress[i].index, static_cast<int>(i));
    EXPECT_GT(progress[i].stats.endpoints, 1000u) << "view " << i;
    if (i > 0) {
      EXPECT_GE(progress[i].known_voxels, progress[i - 1].known_voxels);
    }
  }
  EXPECT_GT(built->fruit_voxels, 50u);
  EXPECT_GE(built->instances.size(), 1u);
  EXPECT_TRUE(fs::exists(build.out));
  EXPECT_EQ(built->file_bytes, fs::file_size(build.out));

  const MapInfo info = ExpectInfoOfBuiltMap(build, *built);
  ExpectExports(build, *built, info, dir_);
  ExpectComparisons(build, *built, scenarios_, dir_);
}

TEST_F(MapCommandTest, BayesianProjectiveSingleViewIsRecorded) {
  MapBuildOptions build = SmallBuild();
  build.views = 1;
  build.map.semantics.policy = mapping::FusionPolicy::kBayesian;
  build.integrator.carving = mapping::FreeSpaceCarving::kProjective;
  ASSERT_TRUE(experiment::BuildMap(build, scenarios_).ok());
  const Result<MapInfo> info = mapping::ReadMapInfo(build.out);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_EQ(info->options.semantics.policy, mapping::FusionPolicy::kBayesian);
  EXPECT_THAT(FormatMapInfo(*info), HasSubstr("bayesian"));
  EXPECT_THAT(info->file.note, HasSubstr("--carving projective"));
}

TEST_F(MapCommandTest, BadInputsNameTheBadValue) {
  MapBuildOptions build = SmallBuild();
  build.views = 0;
  auto r = experiment::BuildMap(build, scenarios_);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("views (0)"));

  build = SmallBuild();
  build.scene.scenario = "tomato-upside-down";
  r = experiment::BuildMap(build, scenarios_);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("tomato-upside-down"));

  build = SmallBuild();
  build.map.grid.voxel_size_m = 0.5;
  r = experiment::BuildMap(build, scenarios_);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("0.5"));

  const auto info = mapping::ReadMapInfo(dir_ / "none.avpmap");
  ASSERT_FALSE(info.ok());
  EXPECT_THAT(info.status().message(), HasSubstr("none.avpmap"));

  MapExportOptions exp;
  exp.map = dir_ / "none.avpmap";
  exp.out = dir_ / "out.xyz";
  auto e = mapping::ExportMapFile(exp);
  ASSERT_FALSE(e.ok());
  EXPECT_THAT(e.status().message(), HasSubstr("'xyz'"));

  MapCompareOptions cmp;
  cmp.map = dir_ / "none.avpmap";
  cmp.gt = dir_ / "none.bt";
  cmp.tolerance_voxels = -1;
  auto c = mapping::CompareMapFiles(cmp);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c.status().message(), HasSubstr("tolerance_voxels (-1)"));
  cmp.tolerance_voxels = 1;
  c = mapping::CompareMapFiles(cmp);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c.status().message(), HasSubstr("none.avpmap"));
}

TEST_F(MapCommandTest, ExportNeverOverwritesItsInput) {
  // Refused before the map is read: X is left byte for byte as it was.
  const fs::path map = dir_ / "plant.ply";
  const std::string bytes = "AVPMAP\x01 not really a map";
  std::ofstream(map, std::ios::binary) << bytes;
  MapExportOptions exp;
  exp.map = map;
  for (const fs::path& out : {map, dir_ / "." / "plant.ply", dir_ / "link.ply"}) {
    if (out.filename() == "link.ply") fs::create_symlink(map, out);
    exp.out = out;
    const Status s = mapping::ExportMapFile(exp).status();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << out;
    EXPECT_THAT(s.message(), HasSubstr("is the map file '" + map.string() + "' it reads"));
    EXPECT_THAT(s.message(), HasSubstr("outputs never overwrite inputs"));
    EXPECT_EQ(test::ReadWholeFile(map), bytes) << out;
  }
  // compare --json is an output too.
  MapCompareOptions cmp;
  cmp.map = map;
  cmp.gt = dir_ / "gt.bt";
  std::ofstream(cmp.gt) << "gt";
  cmp.json_out = cmp.gt;
  EXPECT_THAT(mapping::CompareMapFiles(cmp).status().message(),
              HasSubstr("is the ground truth file '" + cmp.gt.string() + "'"));
}

TEST_F(MapCommandTest, AFolderGivenForAMapIsNotSaidToBeMissing) {
  const fs::path folder = dir_ / "maps";
  fs::create_directories(folder);
  MapExportOptions exp;
  exp.map = folder;
  exp.out = dir_ / "x.ply";
  MapCompareOptions cmp;
  cmp.map = folder;
  cmp.gt = folder;
  // Built once with append: GCC 12 at -O3 warns (-Wrestrict, a false positive) on
  // "'" + std::string&& inside this loop.
  std::string expected = "'";
  expected.append(folder.string()).append("' is a folder, not a map file");
  for (const Status& s :
       {mapping::ReadMapInfo(folder).status(), mapping::ExportMapFile(exp).status(),
        mapping::CompareMapFiles(cmp).status()}) {
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(s.message(), HasSubstr(expected));
    EXPECT_THAT(s.message(), Not(HasSubstr("does not exist")));
  }
}

/// The exact and tolerant scores of two comparisons are the same.
void ExpectSameScores(const MapCompareSummary& a, const MapCompareSummary& b) {
  ASSERT_EQ(a.results.size(), b.results.size());
  for (size_t i = 0; i < a.results.size(); ++i) {
    EXPECT_EQ(a.results[i].predicted, b.results[i].predicted) << i;
    EXPECT_EQ(a.results[i].ground_truth, b.results[i].ground_truth) << i;
    EXPECT_EQ(a.results[i].tp, b.results[i].tp) << i;
    EXPECT_EQ(a.results[i].gt_found, b.results[i].gt_found) << i;
    EXPECT_DOUBLE_EQ(a.results[i].f1, b.results[i].f1) << i;
  }
  EXPECT_DOUBLE_EQ(a.best_shift_f1, b.best_shift_f1);
}

TEST_F(MapCommandTest, ARunsMapFilesScoreTheSameAgainstABtGroundTruth) {
  // avp run writes map.avpmap and map.ot; both compare against `avp map gt`'s .bt alike.
  experiment::RunConfig c;
  c.scenario = "tomato-single-cluster";
  c.seed = 2;
  c.episode.views = 3;
  c.threads = 2;
  experiment::RunFolderOptions o;
  o.out_dir = dir_ / "run";
  const auto run = experiment::RunToFolder(
      experiment::CheckedRunConfig::Check(c, experiment::BuiltinRegistries()).value(), o);
  ASSERT_TRUE(run.ok()) << run.status().ToString();
  ASSERT_TRUE(fs::exists(o.out_dir / "map.avpmap"));
  ASSERT_TRUE(fs::exists(o.out_dir / "map.ot"));
  EXPECT_NE(std::find(run->files.begin(), run->files.end(), o.out_dir / "map.avpmap"),
            run->files.end());

  MapGtOptions gt;
  gt.scene.scenario = c.scenario;
  gt.scene.seed = c.seed;
  gt.voxel_size_m = 0.005;  // the run's map voxel size
  gt.out = dir_ / "gt.bt";
  ASSERT_TRUE(experiment::WriteGroundTruthOctree(gt, scenarios_).ok());

  MapCompareOptions cmp;
  cmp.gt = gt.out;
  cmp.map = o.out_dir / "map.avpmap";
  const Result<MapCompareSummary> from_avpmap = mapping::CompareMapFiles(cmp);
  ASSERT_TRUE(from_avpmap.ok()) << from_avpmap.status().ToString();
  cmp.map = o.out_dir / "map.ot";
  const Result<MapCompareSummary> from_ot = mapping::CompareMapFiles(cmp);
  ASSERT_TRUE(from_ot.ok()) << from_ot.status().ToString();
  ExpectSameScores(*from_avpmap, *from_ot);
  const auto& exact = from_avpmap->results[0];
  EXPECT_FALSE(exact.resampled);
  EXPECT_GT(exact.predicted, 100u);
  EXPECT_GT(exact.tp, exact.predicted / 2);
  EXPECT_GE(from_avpmap->results[1].f1, exact.f1);
  EXPECT_EQ(from_ot->map_source.tree_type, "ColorOcTree");
  EXPECT_FALSE(from_ot->gt_used_labels);
  const std::string report = FormatMapCompare(*from_ot);
  EXPECT_THAT(report, HasSubstr("(ot ColorOcTree, 5 mm voxels)"));
  EXPECT_THAT(report, HasSubstr("(bt OcTree, 5 mm voxels"));
  EXPECT_THAT(report, HasSubstr("lattice check"));
  EXPECT_THAT(report, Not(HasSubstr("resolutions differ")));

  // The run's map.avpmap is the whole map: info says what made it.
  const Result<MapInfo> info = mapping::ReadMapInfo(o.out_dir / "map.avpmap");
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_THAT(info->file.note, HasSubstr("avp run of tomato-single-cluster"));
  EXPECT_EQ(info->occupied_by_class[static_cast<size_t>(SemanticClass::kFruit)], exact.predicted);
}

TEST_F(MapCommandTest, InfoExportCompareReadEveryMapFormat) {
  const MapBuildOptions build = SmallBuild();
  const Result<MapBuildSummary> built = experiment::BuildMap(build, scenarios_);
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  MapExportOptions exp;
  exp.map = build.out;
  exp.out = dir_ / "plant.ot";
  ASSERT_TRUE(mapping::ExportMapFile(exp).ok());
  exp.out = dir_ / "plant.bt";
  ASSERT_TRUE(mapping::ExportMapFile(exp).ok());

  // info on .ot / .bt: the same voxels; classes from the colours of the .ot, none in the .bt.
  const Result<MapInfo> ot = mapping::ReadMapInfo(dir_ / "plant.ot");
  ASSERT_TRUE(ot.ok()) << ot.status().ToString();
  EXPECT_EQ(ot->occupied_voxels, built->occupied_voxels);
  EXPECT_EQ(ot->known_voxels, built->known_voxels);
  EXPECT_EQ(ot->occupied_by_class[static_cast<size_t>(SemanticClass::kFruit)], built->fruit_voxels);
  const std::string ot_text = FormatMapInfo(*ot);
  EXPECT_THAT(ot_text, HasSubstr("OctoMap ColorOcTree .ot"));
  EXPECT_THAT(ot_text, HasSubstr("in a class colour (read as that class)"));
  EXPECT_THAT(ot_text, HasSubstr("not kept"));
  EXPECT_THAT(ot_text, HasSubstr("voxel size   8 mm"));
  const Result<MapInfo> bt = mapping::ReadMapInfo(dir_ / "plant.bt");
  ASSERT_TRUE(bt.ok()) << bt.status().ToString();
  EXPECT_EQ(bt->occupied_voxels, built->occupied_voxels);
  EXPECT_EQ(bt->known_voxels, built->known_voxels);
  EXPECT_EQ(bt->labelled_voxels, 0u);
  EXPECT_THAT(FormatMapInfo(*bt), HasSubstr("a .bt file holds occupancy only"));

  // export .ot -> .avpmap (the format from the extension) and .bt -> .ot.
  exp.map = dir_ / "plant.ot";
  exp.out = dir_ / "from_ot.avpmap";
  const Result<MapExportSummary> to_avpmap = mapping::ExportMapFile(exp);
  ASSERT_TRUE(to_avpmap.ok()) << to_avpmap.status().ToString();
  EXPECT_EQ(to_avpmap->format, MapExportFormat::kAvpMap);
  EXPECT_EQ(to_avpmap->occupied_voxels, built->occupied_voxels);
  EXPECT_FALSE(to_avpmap->source.lost.empty());
  mapping::MapFileInfo file;
  const auto reread = mapping::LoadMap(exp.out, &file);
  ASSERT_TRUE(reread.ok()) << reread.status().ToString();
  EXPECT_EQ(reread->grid().CountOccupiedVoxels(), built->occupied_voxels);
  EXPECT_THAT(file.note, HasSubstr("plant.ot (ot, ColorOcTree)"));
  exp.map = dir_ / "plant.bt";
  exp.out = dir_ / "from_bt.ot";
  const Result<MapExportSummary> to_ot = mapping::ExportMapFile(exp);
  ASSERT_TRUE(to_ot.ok()) << to_ot.status().ToString();
  EXPECT_EQ(to_ot->occupied_voxels, built->occupied_voxels);
  EXPECT_EQ(to_ot->labelled_voxels, 0u);

  // compare: the map against its own files as ground truth. A labelled GT (.avpmap, ColorOcTree
  // in class colours) gives its fruit voxels: F1 1; a .bt gives every occupied voxel.
  MapCompareOptions cmp;
  cmp.map = build.out;
  for (const fs::path& gt_path : {build.out, dir_ / "plant.ot", dir_ / "from_ot.avpmap"}) {
    cmp.gt = gt_path;
    const Result<MapCompareSummary> self = mapping::CompareMapFiles(cmp);
    ASSERT_TRUE(self.ok()) << self.status().ToString();
    EXPECT_TRUE(self->gt_used_labels) << gt_path;
    EXPECT_DOUBLE_EQ(self->results[0].f1, 1.0) << gt_path;
    EXPECT_LT(self->best_shift_f1, 1.0) << gt_path;
  }
  cmp.gt = dir_ / "plant.bt";
  const Result<MapCompareSummary> vs_bt = mapping::CompareMapFiles(cmp);
  ASSERT_TRUE(vs_bt.ok()) << vs_bt.status().ToString();
  EXPECT_FALSE(vs_bt->gt_used_labels);
  EXPECT_EQ(vs_bt->results[0].ground_truth, built->occupied_voxels);
  EXPECT_DOUBLE_EQ(vs_bt->results[0].precision, 1.0);  // every fruit voxel is occupied
  // A ground truth one voxel off (another frame): exact F1 collapses, the lattice check finds the
  // shift and warns.
  {
    const auto map = mapping::LoadMap(build.out);
    ASSERT_TRUE(map.ok());
    mapping::GridOptions g;
    g.voxel_size_m = map->voxel_size_m();
    mapping::OccupancyGrid shifted(g);
    for (const VoxelKey& k : mapping::OccupiedVoxelsOfClass(map->grid(), SemanticClass::kFruit)) {
      shifted.SetLogOdds({k.x, k.y, k.z - 1}, shifted.clamp_max_log_odds());
    }
    ASSERT_TRUE(mapping::ExportOctomapBinary(shifted, dir_ / "shifted.bt").ok());
    cmp.gt = dir_ / "shifted.bt";
    const Result<MapCompareSummary> off = mapping::CompareMapFiles(cmp);
    ASSERT_TRUE(off.ok()) << off.status().ToString();
    EXPECT_LT(off->results[0].f1, 0.8);
    EXPECT_EQ(off->best_shift, (VoxelKey{0, 0, -1}));
    EXPECT_DOUBLE_EQ(off->best_shift_f1, 1.0);
    const std::string text = FormatMapCompare(*off);
    EXPECT_THAT(text, HasSubstr("(+0, +0, -1), gives exact F1 1.0000"));
    EXPECT_THAT(text, HasSubstr("a one-voxel shift raises exact F1 by 0.1 or more"));
  }
  // The .bt as the map: no labels, nothing predicted.
  cmp.map = dir_ / "plant.bt";
  const Result<MapCompareSummary> bt_map = mapping::CompareMapFiles(cmp);
  ASSERT_TRUE(bt_map.ok()) << bt_map.status().ToString();
  EXPECT_EQ(bt_map->results[0].predicted, 0u);
}

TEST_F(MapCommandTest, CompareNamesResolutionMismatchesAndBrokenFiles) {
  const MapBuildOptions build = SmallBuild();  // 8 mm
  ASSERT_TRUE(experiment::BuildMap(build, scenarios_).ok());
  MapGtOptions gt;
  gt.scene = build.scene;
  gt.voxel_size_m = 0.006;
  gt.out = dir_ / "gt6.bt";
  ASSERT_TRUE(experiment::WriteGroundTruthOctree(gt, scenarios_).ok());
  MapCompareOptions cmp;
  cmp.map = build.out;
  cmp.gt = gt.out;
  cmp.json_out = dir_ / "cmp.json";
  const Result<MapCompareSummary> r = mapping::CompareMapFiles(cmp);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->results[0].resampled);
  const std::string text = FormatMapCompare(*r);
  EXPECT_THAT(text, HasSubstr("resolutions differ (map 8 mm, ground truth 6 mm)"));
  EXPECT_THAT(text, HasSubstr("--voxel-size 0.006"));
  const auto json = io::ReadJsonFile(cmp.json_out);
  ASSERT_TRUE(json.ok());
  EXPECT_EQ((*json)["gt_format"], "bt");
  EXPECT_EQ((*json)["map_format"], "avpmap");
  EXPECT_EQ((*json)["best_one_voxel_shift"].size(), 3u);

  // A truncated ground truth: the file and the byte are named.
  const std::string bytes = test::ReadWholeFile(gt.out);
  const fs::path cut = dir_ / "cut.bt";
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() - 5);
  cmp.gt = cut;
  cmp.json_out.clear();
  Status s = mapping::CompareMapFiles(cmp).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), HasSubstr("cut.bt"));
  EXPECT_THAT(s.message(), HasSubstr("byte"));
  // Neither format: the first bytes are quoted.
  const fs::path text_file = dir_ / "gt.ot";
  std::ofstream(text_file) << "x y z\n1 2 3\n";
  cmp.gt = text_file;
  s = mapping::CompareMapFiles(cmp).status();
  EXPECT_THAT(s.message(), HasSubstr("gt.ot"));
  EXPECT_THAT(s.message(), HasSubstr("'x y z"));
  cmp.gt = gt.out;
  cmp.map = cut;
  s = mapping::ReadMapInfo(cut).status();
  EXPECT_THAT(s.message(), HasSubstr("cut.bt"));
}

TEST(ArcViewPosesTest, ViewsLookAtTheTargetFromTheArc) {
  const Eigen::Vector3d target(0.6, 0.05, 0.8);
  const Eigen::Vector3d start(0.2, 0.05, 0.7);  // azimuth 180 deg, 0.4 m away
  std::vector<double> azimuths;
  const auto poses = experiment::ArcViewPoses(target, start, 5, 120.0, 0.4, &azimuths);
  ASSERT_EQ(poses.size(), 5u);
  EXPECT_NEAR(azimuths[0], 120.0, 1e-9);
  EXPECT_NEAR(azimuths[2], 180.0, 1e-9);
  EXPECT_NEAR(azimuths[4], 240.0, 1e-9);
  EXPECT_TRUE(poses[2].translation().isApprox(start, 1e-12));
  for (const RigidTransform& X_WC : poses) {
    const Eigen::Vector3d eye = X_WC.translation();
    EXPECT_NEAR((eye - target).head<2>().norm(), 0.4, 1e-12);
    EXPECT_NEAR(eye.z(), 0.7, 1e-12);
    // Optical z points at the target; image up (-y) has a positive world z component.
    EXPECT_TRUE(X_WC.rotation().col(2).isApprox((target - eye).normalized(), 1e-12));
    EXPECT_LT(X_WC.rotation().col(1).z(), 0.0);
  }
  azimuths.clear();
  const auto ring = experiment::ArcViewPoses(target, start, 4, 360.0, 0.5, &azimuths);
  ASSERT_EQ(ring.size(), 4u);
  EXPECT_NEAR(azimuths[1] - azimuths[0], 90.0, 1e-9);
  EXPECT_NEAR(azimuths[3] - azimuths[0], 270.0, 1e-9);
}

}  // namespace
}  // namespace avp

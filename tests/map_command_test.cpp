// End-to-end: `avp map build | gt | info | export | compare` as library calls: a map of a simulated
// plant is built, described, exported to OctoMap and PLY, and scored against the scene's fruit
// ground truth; bad input gives messages that name the bad value.
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/apps/map_command.h>
#include <avp/io/json.h>
#include <avp/mapping/octomap_io.h>
#include <avp/test/temp_dir_test.h>

namespace avp::apps {
namespace {

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

TEST_F(MapCommandTest, BuildInfoExportCompareEndToEnd) {
  MapBuildOptions build = SmallBuild();
  std::vector<MapBuildView> progress;
  build.on_view = [&](const MapBuildView& v) { progress.push_back(v); };
  const Result<MapBuildSummary> built = RunMapBuild(build, scenarios_);
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

  // info
  const Result<MapInfo> info = RunMapInfo(build.out);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_EQ(info->known_voxels, built->known_voxels);
  EXPECT_EQ(info->occupied_voxels, built->occupied_voxels);
  EXPECT_EQ(info->free_voxels + info->occupied_voxels, info->known_voxels);
  EXPECT_EQ(info->labelled_voxels, built->labelled_voxels);
  EXPECT_EQ(info->occupied_by_class[static_cast<size_t>(SemanticClass::kFruit)],
            built->fruit_voxels);
  EXPECT_EQ(info->instances.size(), built->instances.size());
  EXPECT_EQ(info->options.semantics.policy, mapping::FusionPolicy::kReferenceMax);
  ASSERT_TRUE(info->options.grid.roi.has_value());
  const std::string text = FormatMapInfo(*info);
  EXPECT_THAT(text, HasSubstr("format version 2"));
  EXPECT_THAT(text, HasSubstr("voxel size   8 mm"));
  EXPECT_THAT(text, HasSubstr("reference-max"));
  EXPECT_THAT(text, HasSubstr("--scenario tomato-single-cluster --seed 1 --views 3"));
  EXPECT_THAT(text, HasSubstr("fruit"));

  // export: bt, ot (format from the extension) and ply
  MapExportOptions exp;
  exp.map = build.out;
  exp.format = "bt";
  exp.out = dir_ / "plant.bt";
  Result<MapExportSummary> exported = RunMapExport(exp);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_EQ(exported->occupied_voxels, built->occupied_voxels);
  const auto back = mapping::ImportOctomapOccupied(exp.out);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->keys.size(), built->occupied_voxels);
  exp.format.clear();
  exp.out = dir_ / "plant.ot";
  exported = RunMapExport(exp);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_EQ(exported->format, MapExportFormat::kOt);
  EXPECT_GT(exported->labelled_voxels, 0u);
  exp.format = "ply";
  exp.out = dir_ / "plant.ply";
  exported = RunMapExport(exp);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_EQ(exported->labelled_voxels, info->occupied_by_class[1] + info->occupied_by_class[2] +
                                           info->occupied_by_class[3] + info->occupied_by_class[4] +
                                           info->occupied_by_class[5] + info->occupied_by_class[6]);

  // gt + compare: at 6 mm the GT is resampled onto the 8 mm map; at 8 mm it is not.
  MapGtOptions gt;
  gt.scene = build.scene;
  gt.voxel_size_m = 0.006;
  gt.out = dir_ / "gt6.bt";
  const Result<MapGtSummary> gt_summary = RunMapGt(gt, scenarios_);
  ASSERT_TRUE(gt_summary.ok()) << gt_summary.status().ToString();
  EXPECT_GT(gt_summary->voxels, 100u);

  MapCompareOptions cmp;
  cmp.map = build.out;
  cmp.gt = gt.out;
  cmp.tolerance_voxels = 1;
  cmp.json_out = dir_ / "compare.json";
  const Result<MapCompareSummary> compared = RunMapCompare(cmp);
  ASSERT_TRUE(compared.ok()) << compared.status().ToString();
  ASSERT_EQ(compared->results.size(), 2u);
  const auto& exact = compared->results[0];
  const auto& tol = compared->results[1];
  EXPECT_TRUE(exact.resampled);
  EXPECT_EQ(exact.gt_voxels_original, gt_summary->voxels);
  EXPECT_EQ(exact.predicted, built->fruit_voxels);
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
  ASSERT_TRUE(RunMapGt(gt, scenarios_).ok());
  cmp.gt = gt.out;
  cmp.tolerance_voxels = 0;
  cmp.json_out.clear();
  const Result<MapCompareSummary> same = RunMapCompare(cmp);
  ASSERT_TRUE(same.ok()) << same.status().ToString();
  ASSERT_EQ(same->results.size(), 1u);
  EXPECT_FALSE(same->results[0].resampled);
  EXPECT_THAT(FormatMapCompare(*same), Not(HasSubstr("resolutions differ")));
}

TEST_F(MapCommandTest, BayesianProjectiveSingleViewIsRecorded) {
  MapBuildOptions build = SmallBuild();
  build.views = 1;
  build.map.semantics.policy = mapping::FusionPolicy::kBayesian;
  build.integrator.carving = mapping::FreeSpaceCarving::kProjective;
  ASSERT_TRUE(RunMapBuild(build, scenarios_).ok());
  const Result<MapInfo> info = RunMapInfo(build.out);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_EQ(info->options.semantics.policy, mapping::FusionPolicy::kBayesian);
  EXPECT_THAT(FormatMapInfo(*info), HasSubstr("bayesian"));
  EXPECT_THAT(info->file.note, HasSubstr("--carving projective"));
}

TEST_F(MapCommandTest, BadInputsNameTheBadValue) {
  MapBuildOptions build = SmallBuild();
  build.views = 0;
  auto r = RunMapBuild(build, scenarios_);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("views (0)"));

  build = SmallBuild();
  build.scene.scenario = "tomato-upside-down";
  r = RunMapBuild(build, scenarios_);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("tomato-upside-down"));

  build = SmallBuild();
  build.map.grid.voxel_size_m = 0.5;
  r = RunMapBuild(build, scenarios_);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("0.5"));

  const auto info = RunMapInfo(dir_ / "none.avpmap");
  ASSERT_FALSE(info.ok());
  EXPECT_THAT(info.status().message(), HasSubstr("none.avpmap"));

  MapExportOptions exp;
  exp.map = dir_ / "none.avpmap";
  exp.out = dir_ / "out.xyz";
  auto e = RunMapExport(exp);
  ASSERT_FALSE(e.ok());
  EXPECT_THAT(e.status().message(), HasSubstr("'xyz'"));

  MapCompareOptions cmp;
  cmp.map = dir_ / "none.avpmap";
  cmp.gt = dir_ / "none.bt";
  cmp.tolerance_voxels = -1;
  auto c = RunMapCompare(cmp);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c.status().message(), HasSubstr("tolerance_voxels (-1)"));
  cmp.tolerance_voxels = 1;
  c = RunMapCompare(cmp);
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
    const Status s = RunMapExport(exp).status();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << out;
    EXPECT_THAT(s.message(), HasSubstr("is the map file '" + map.string() + "' it reads"));
    EXPECT_THAT(s.message(), HasSubstr("outputs never overwrite inputs"));
    std::ifstream in(map, std::ios::binary);
    EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), bytes) << out;
  }
  // compare --json is an output too.
  MapCompareOptions cmp;
  cmp.map = map;
  cmp.gt = dir_ / "gt.bt";
  std::ofstream(cmp.gt) << "gt";
  cmp.json_out = cmp.gt;
  EXPECT_THAT(RunMapCompare(cmp).status().message(),
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
  for (const Status& s :
       {RunMapInfo(folder).status(), RunMapExport(exp).status(), RunMapCompare(cmp).status()}) {
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(s.message(), HasSubstr("'" + folder.string() + "' is a folder, not a map file"));
    EXPECT_THAT(s.message(), Not(HasSubstr("does not exist")));
  }
}

TEST(ArcViewPosesTest, ViewsLookAtTheTargetFromTheArc) {
  const Eigen::Vector3d target(0.6, 0.05, 0.8);
  const Eigen::Vector3d start(0.2, 0.05, 0.7);  // azimuth 180 deg, 0.4 m away
  std::vector<double> azimuths;
  const auto poses = ArcViewPoses(target, start, 5, 120.0, 0.4, &azimuths);
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
  const auto ring = ArcViewPoses(target, start, 4, 360.0, 0.5, &azimuths);
  ASSERT_EQ(ring.size(), 4u);
  EXPECT_NEAR(azimuths[1] - azimuths[0], 90.0, 1e-9);
  EXPECT_NEAR(azimuths[3] - azimuths[0], 270.0, 1e-9);
}

}  // namespace
}  // namespace avp::apps

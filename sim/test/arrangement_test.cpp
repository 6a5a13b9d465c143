// Arrangements (docs/scene-format.md, "Arrangements"): a plant of a scene file placed like the
// paper's tomato scenarios, checked with real numbers on a small hand-built asymmetric plant.
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <avp/core/camera.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>

namespace avp::sim {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr double kFruitRadius = 0.025;

/// A stem at (0.7, 0) with two fruit clusters on the arm's side (-x): `upper` fruit in a row at
/// z = 0.75 and `lower` at z = 0.45, and a leaf screen 9 cm behind the stem (+x side) that hides
/// whatever is behind it from the reference start camera. The reference start.
Scene TestPlant(int upper = 4, int lower = 3, double lower_x = 0.62) {
  Scene s;
  s.name = "test_plant";
  s.description = "a test plant";
  s.Add("stem", SemanticClass::kStem, Eigen::Vector3f(0.2f, 0.5f, 0.1f),
        MakeCylinder(Eigen::Vector3d(0.7, 0, 0.0), Eigen::Vector3d(0.7, 0, 1.0), 0.01, 8));
  TriangleMesh screen = MakeBox(Eigen::Vector3d(0.004, 0.2, 0.3));
  screen.Transform(RigidTransform(Eigen::Vector3d(0.79, 0.0, 0.6)));
  s.Add("screen_leaf", SemanticClass::kLeaf, Eigen::Vector3f(0.1f, 0.4f, 0.1f), std::move(screen));
  const auto row = [&](int n, double x, double z, const std::string& prefix) {
    for (int i = 0; i < n; ++i) {
      Ellipsoid e;
      e.center_W = Eigen::Vector3d(x, (i - 0.5 * (n - 1)) * 0.055, z);
      e.radii = Eigen::Vector3d::Constant(kFruitRadius);
      s.Add(prefix + std::to_string(i), SemanticClass::kFruit, Eigen::Vector3f(0.8f, 0.1f, 0.05f),
            e);
    }
  };
  row(upper, 0.62, 0.75, "upper_");
  row(lower, lower_x, 0.45, "lower_");
  s.start_joints_rad = ReferenceStartJointsRad(0.0);
  s.X_WC_start = ReferenceStartCameraPose(0.0);
  s.UpdatePlantBounds();
  return s;
}

Arrangement Parse(std::string_view spec) {
  Result<Arrangement> a = ParseArrangement(spec);
  EXPECT_TRUE(a.ok()) << a.status().ToString();
  return a.ok() ? *a : Arrangement{};
}

TEST(ArrangementTest, NamesAndCustomItemsParse) {
  EXPECT_EQ(ArrangementNames(), (std::vector<std::string>{"reference", "full-occlusion",
                                                          "single-cluster", "unoriented-start"}));
  EXPECT_TRUE(Parse("").IsIdentity());
  EXPECT_TRUE(Parse("reference").IsIdentity());
  EXPECT_TRUE(Parse("full-occlusion").occluding_yaw);
  EXPECT_TRUE(Parse("single-cluster").single_cluster);
  const Arrangement u = Parse("unoriented-start");
  EXPECT_EQ(u.plant_offset_m, Eigen::Vector3d(0.0, 0.4, 0.0));
  EXPECT_EQ(u.start_yaw_deg, 20.0);
  const Arrangement c = Parse("plant-x=0.1+plant-y=-0.2+plant-z=0.05+plant-yaw=30+start-yaw=-10");
  EXPECT_EQ(c.plant_offset_m, Eigen::Vector3d(0.1, -0.2, 0.05));
  EXPECT_EQ(c.plant_yaw_deg, 30.0);
  EXPECT_EQ(c.start_yaw_deg, -10.0);
  EXPECT_EQ(c.spec, "plant-x=0.1+plant-y=-0.2+plant-z=0.05+plant-yaw=30+start-yaw=-10");
  const Arrangement sc = Parse("single-cluster+cluster-gap=0.1+full-occlusion");
  EXPECT_TRUE(sc.single_cluster && sc.occluding_yaw);
  EXPECT_EQ(sc.cluster_gap_m, 0.1);
}

TEST(ArrangementTest, BadSpecsNameTheValue) {
  const auto message = [](std::string_view spec) {
    const Result<Arrangement> a = ParseArrangement(spec);
    EXPECT_FALSE(a.ok()) << spec;
    return a.ok() ? std::string() : a.status().message();
  };
  EXPECT_THAT(message("full-oclusion"), HasSubstr("unknown arrangement 'full-oclusion'"));
  EXPECT_THAT(message("full-oclusion"), HasSubstr("known: reference, full-occlusion"));
  EXPECT_THAT(message("paper"), HasSubstr("only in an avp bench scenario list"));
  EXPECT_THAT(message("plant-yaw=abc"), HasSubstr("plant-yaw ('abc') must be a number"));
  EXPECT_THAT(message("start-yaw=400"), HasSubstr("start-yaw ('400') must be a number in [-180"));
  EXPECT_THAT(message("plant-q=1"), HasSubstr("unknown key 'plant-q'"));
  EXPECT_THAT(message("full-occlusion+plant-yaw=30"),
              HasSubstr("plant-yaw is set twice (by 'full-occlusion' and by 'plant-yaw=30')"));
  EXPECT_THAT(message("unoriented-start+plant-y=1"), HasSubstr("plant-y is set twice"));
  EXPECT_THAT(message("reference++single-cluster"), HasSubstr("empty item"));
  EXPECT_THAT(message("cluster-gap=0.1"), HasSubstr("only with single-cluster"));
}

TEST(ArrangementTest, UnorientedStartMovesThePlantAndTurnsTheStart) {
  const Scene before = TestPlant();
  Scene after = before;
  const Result<ArrangementReport> r = ApplyArrangement(after, Parse("unoriented-start"));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(after.name, "test_plant@unoriented-start");
  EXPECT_THAT(after.description, HasSubstr("plant moved by (0, 0.4, 0) m"));
  const std::vector<FruitTruth> f0 = before.Fruits(), f1 = after.Fruits();
  ASSERT_EQ(f0.size(), 7u);
  ASSERT_EQ(f1.size(), 7u);
  for (size_t i = 0; i < f0.size(); ++i) {
    EXPECT_EQ(f1[i].instance_id, f0[i].instance_id);
    EXPECT_NEAR((f1[i].center_W - f0[i].center_W - Eigen::Vector3d(0, 0.4, 0)).norm(), 0.0, 1e-12)
        << f0[i].name;
  }
  EXPECT_NEAR((after.plant_bounds.min() - before.plant_bounds.min()).y(), 0.4, 1e-6);
  EXPECT_NEAR((after.plant_bounds.max() - before.plant_bounds.max()).y(), 0.4, 1e-6);
  // Joint 1 +20 deg; the start camera turned by 20 deg about the world z axis through the base,
  // towards -y (away from the plant), as ReferenceStartCameraPose(20) places it.
  EXPECT_NEAR(after.start_joints_rad[0] - before.start_joints_rad[0], 20.0 * EIGEN_PI / 180.0,
              1e-12);
  for (size_t j = 1; j < 6; ++j) EXPECT_EQ(after.start_joints_rad[j], before.start_joints_rad[j]);
  const Eigen::AngleAxisd turn(after.X_WC_start.rotation() *
                               before.X_WC_start.rotation().transpose());
  EXPECT_NEAR(turn.angle() * 180.0 / EIGEN_PI, 20.0, 1e-9);
  EXPECT_NEAR(turn.axis().z(), -1.0, 1e-9);
  EXPECT_NEAR(
      (after.X_WC_start.translation() - ReferenceStartCameraPose(20.0).translation()).norm(), 0.0,
      1e-12);
  EXPECT_LT(after.X_WC_start.rotation().col(2).y(), -0.3);  // looks towards -y
  // No fruit left in the start view.
  EXPECT_GT(CountFruitPixels(before, CameraIntrinsics::RealSenseD435(), before.X_WC_start), 5000u);
  EXPECT_EQ(CountFruitPixels(after, CameraIntrinsics::RealSenseD435(), after.X_WC_start), 0u);
}

TEST(ArrangementTest, FullOcclusionPicksTheYawThatHidesTheFruit) {
  const Scene before = TestPlant();
  Scene after = before;
  const Result<ArrangementReport> r = ApplyArrangement(after, Parse("full-occlusion"));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->fruit_pixels_by_yaw.size(), 24u);
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  const size_t reference_pixels = CountFruitPixels(before, K, before.X_WC_start);
  EXPECT_EQ(r->fruit_pixels_by_yaw[0], reference_pixels);
  // The chosen yaw is the first minimum of the 24 candidates, and the plant turned by it shows
  // that many fruit pixels: the screen leaf is now between the camera and the fruit.
  size_t best = 0;
  for (size_t k = 1; k < 24; ++k) {
    if (r->fruit_pixels_by_yaw[k] < r->fruit_pixels_by_yaw[best]) best = k;
  }
  EXPECT_EQ(r->plant_yaw_deg, 15.0 * static_cast<double>(best));
  EXPECT_GE(r->plant_yaw_deg, 120.0);
  EXPECT_LE(r->plant_yaw_deg, 240.0);
  const size_t arranged_pixels = CountFruitPixels(after, K, after.X_WC_start);
  EXPECT_NEAR(static_cast<double>(arranged_pixels),
              static_cast<double>(r->fruit_pixels_by_yaw[best]),
              20.0 + 0.01 * static_cast<double>(r->fruit_pixels_by_yaw[best]));
  EXPECT_GT(reference_pixels, 5000u);
  EXPECT_LT(arranged_pixels * 20, reference_pixels)
      << arranged_pixels << " vs " << reference_pixels;
  // The turn is about the vertical through the plant's centre: the bounds' centre stays (x, y),
  // the fruit keep their heights and distances to that axis.
  const Eigen::Vector3d c0 = before.plant_bounds.center();
  const std::vector<FruitTruth> f0 = before.Fruits(), f1 = after.Fruits();
  ASSERT_EQ(f1.size(), f0.size());
  for (size_t i = 0; i < f0.size(); ++i) {
    EXPECT_NEAR(f1[i].center_W.z(), f0[i].center_W.z(), 1e-12);
    EXPECT_NEAR((f1[i].center_W - c0).head<2>().norm(), (f0[i].center_W - c0).head<2>().norm(),
                1e-9);
  }
  EXPECT_EQ(after.X_WC_start.translation(), before.X_WC_start.translation());
  EXPECT_THAT(after.description, HasSubstr("fewest fruit pixels"));
  // Deterministic.
  Scene again = before;
  const Result<ArrangementReport> r2 = ApplyArrangement(again, Parse("full-occlusion"));
  ASSERT_TRUE(r2.ok());
  EXPECT_EQ(r2->fruit_pixels_by_yaw, r->fruit_pixels_by_yaw);
  EXPECT_EQ(DescribeDifference(again, after), "");
}

TEST(ArrangementTest, SingleClusterKeepsTheLargestCluster) {
  const Scene before = TestPlant(4, 3);
  EXPECT_EQ(FruitClusters(before, 0.04),
            (std::vector<std::vector<uint16_t>>{{3, 4, 5, 6}, {7, 8, 9}}));
  // A gap wider than the 0.25 m between the rows joins them.
  EXPECT_EQ(FruitClusters(before, 0.3).size(), 1u);
  Scene after = before;
  const Result<ArrangementReport> r = ApplyArrangement(after, Parse("single-cluster"));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->fruits_kept, 4u);
  EXPECT_EQ(r->fruits_removed, 3u);
  const std::vector<FruitTruth> fruits = after.Fruits();
  ASSERT_EQ(fruits.size(), 4u);
  for (const FruitTruth& f : fruits) EXPECT_THAT(f.name, HasSubstr("upper_"));
  EXPECT_EQ(FruitClusters(after, 0.04).size(), 1u);
  EXPECT_EQ(after.objects.size(), before.objects.size() - 3);  // stem and leaf stay
  EXPECT_EQ(after.name, "test_plant@single-cluster");
  // Ties (3 and 3): the cluster nearer the start camera (eye at z 0.677) wins: the upper row
  // (z 0.75) unless the lower row is brought much closer to the arm.
  Scene tie = TestPlant(3, 3);
  ASSERT_TRUE(ApplyArrangement(tie, Parse("single-cluster")).ok());
  for (const FruitTruth& f : tie.Fruits()) EXPECT_THAT(f.name, HasSubstr("upper_"));
  Scene near = TestPlant(3, 3, 0.35);
  ASSERT_TRUE(ApplyArrangement(near, Parse("single-cluster")).ok());
  for (const FruitTruth& f : near.Fruits()) EXPECT_THAT(f.name, HasSubstr("lower_"));
  // No fruit: an error naming the scene.
  Scene bare = TestPlant(0, 0);
  const Result<ArrangementReport> none = ApplyArrangement(bare, Parse("single-cluster"));
  ASSERT_FALSE(none.ok());
  EXPECT_THAT(none.status().message(), HasSubstr("scene 'test_plant' has no fruit"));
}

TEST(ArrangementTest, CustomYawAndOffset) {
  const Scene before = TestPlant();
  Scene after = before;
  ASSERT_TRUE(ApplyArrangement(after, Parse("plant-yaw=90+plant-x=0.1")).ok());
  const Eigen::Vector3d c = before.plant_bounds.center();
  const std::vector<FruitTruth> f0 = before.Fruits(), f1 = after.Fruits();
  for (size_t i = 0; i < f0.size(); ++i) {
    const Eigen::Vector3d d = f0[i].center_W - c;
    const Eigen::Vector3d expected(c.x() - d.y() + 0.1, c.y() + d.x(), f0[i].center_W.z());
    EXPECT_NEAR((f1[i].center_W - expected).norm(), 0.0, 1e-12) << f0[i].name;
  }
}

class ArrangementFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) /
           ("avp_arrangement_file_test_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    ASSERT_TRUE(SaveSceneFiles(TestPlant(), dir_).ok());
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(ArrangementFileTest, LoadSceneArrangesFilesAndRefusesArrangedScenarios) {
  const ScenarioRegistry registry = BuiltinScenarios();
  SceneSource source;
  source.scene_file = dir_ / "test_plant.yaml";
  const Result<Scene> plain = LoadScene(source, registry);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_EQ(plain->name, "test_plant");
  source.arrangement = "unoriented-start";
  const Result<Scene> moved = LoadScene(source, registry);
  ASSERT_TRUE(moved.ok()) << moved.status().ToString();
  EXPECT_EQ(moved->name, "test_plant@unoriented-start");
  ASSERT_EQ(moved->Fruits().size(), plain->Fruits().size());
  for (size_t i = 0; i < plain->Fruits().size(); ++i) {
    EXPECT_NEAR(moved->Fruits()[i].center_W.y() - plain->Fruits()[i].center_W.y(), 0.4, 1e-6);
  }
  source.arrangement = "sideways";
  Result<Scene> bad = LoadScene(source, registry);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("unknown arrangement 'sideways'"));

  SceneSource scenario;
  scenario.scenario = "tomato-single-cluster";
  scenario.arrangement = "full-occlusion";
  bad = LoadScene(scenario, registry);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("arrangement 'full-occlusion' is for scene files"));
  EXPECT_THAT(bad.status().message(), HasSubstr("tomato-single-cluster"));
  scenario.arrangement = "reference";
  const Result<Scene> reference = LoadScene(scenario, registry);
  ASSERT_TRUE(reference.ok()) << reference.status().ToString();
  EXPECT_EQ(reference->name, "tomato-single-cluster@reference");
}

}  // namespace
}  // namespace avp::sim

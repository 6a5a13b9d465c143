#include <cmath>
#include <set>
#include <string>
#include <variant>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/camera.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;

constexpr double kPi = 3.14159265358979323846;

Scene Make(std::string_view name, uint64_t seed) {
  Result<Scene> r = MakeScenario(name, seed);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  return std::move(r).value();
}

::testing::AssertionResult SameScene(const Scene& a, const Scene& b) {
  const std::string difference = DescribeDifference(a, b);
  if (difference.empty()) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << difference;
}

/// Fruit centres that project into a D435 image from the scene's start camera.
int FruitCentresInStartView(const Scene& scene) {
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  const RigidTransform X_CW = scene.X_WC_start.inverse();
  int n = 0;
  for (const FruitTruth& f : scene.Fruits()) {
    const std::optional<Eigen::Vector2d> uv = K.Project(X_CW * f.center_W);
    if (uv && K.IsInImage(*uv)) ++n;
  }
  return n;
}

int FruitPixels(const RgbdRenderer& renderer, const RigidTransform& X_WC) {
  const RenderedFrame frame = renderer.Render(CameraIntrinsics::RealSenseD435(), X_WC);
  int n = 0;
  for (const uint8_t c : frame.class_ids.data())
    n += c == static_cast<uint8_t>(SemanticClass::kFruit);
  return n;
}

/// A camera 0.55 m behind the plant (+x side) looking back at it, at the height of the fruit.
RigidTransform BackView(const Scene& scene) {
  Eigen::Vector3d fruit_centre = Eigen::Vector3d::Zero();
  const std::vector<FruitTruth> fruits = scene.Fruits();
  for (const FruitTruth& f : fruits)
    fruit_centre += f.center_W / static_cast<double>(fruits.size());
  return RigidTransform::LookAt(fruit_centre + Eigen::Vector3d(0.55, 0.0, 0.0), fruit_centre);
}

TEST(ScenarioTest, ListIsStableAndStartsWithTheDefault) {
  const ScenarioRegistry registry = BuiltinScenarios();
  const std::vector<ScenarioEntry>& list = registry.entries();
  const std::vector<std::string> expected = {"tomato-multiple-clusters",  "tomato-full-occlusion",
                                             "tomato-single-cluster",     "tomato-unoriented-start",
                                             "espalier-multiple-fruits",  "espalier-full-occlusion",
                                             "espalier-unoriented-start", "generic-training"};
  ASSERT_EQ(list.size(), expected.size());
  for (size_t i = 0; i < list.size(); ++i) {
    EXPECT_EQ(list[i].name, expected[i]);
    EXPECT_FALSE(list[i].description.empty());
    EXPECT_EQ(list[i].description.find('\n'), std::string::npos);
    EXPECT_LT(list[i].description.size(), 120u) << list[i].name;
  }
  EXPECT_EQ(DefaultScenarioName(), list.front().name);
  // The training family is registered but never evaluated by default.
  std::vector<std::string> evaluation(expected.begin(), expected.end() - 1);
  EXPECT_EQ(registry.EvaluationNames(), evaluation);
  EXPECT_TRUE(registry.Find(kGenericTrainingScenario)->training_only);
  ScenarioRegistry again = BuiltinScenarios();
  EXPECT_THROW(RegisterBuiltinScenarios(again), Error);
}

TEST(ScenarioTest, RegisteredScenariosAreBuiltWithTheirNameAndSeed) {
  ScenarioRegistry registry;
  ScenarioEntry e;
  e.name = "one-sphere";
  e.description = "a lone fruit";
  e.build = [](uint64_t seed) -> Result<Scene> {
    Scene scene;
    SceneObject fruit;
    fruit.name = "fruit";
    fruit.semantic_class = SemanticClass::kFruit;
    Ellipsoid sphere;
    sphere.center_W = Eigen::Vector3d(0.6, 0.0, 0.5);
    sphere.radii = Eigen::Vector3d::Constant(0.03 + 0.001 * static_cast<double>(seed % 3));
    fruit.shape = sphere;
    scene.Add(std::move(fruit));
    scene.UpdatePlantBounds();
    return scene;
  };
  ASSERT_TRUE(registry.Add(e).ok());
  EXPECT_THAT(registry.Add(e).message(), HasSubstr("'one-sphere' is already registered"));
  const Result<Scene> scene = registry.Make("one-sphere", 4);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  EXPECT_EQ(scene->name, "one-sphere");
  EXPECT_EQ(scene->description, "a lone fruit");
  EXPECT_EQ(scene->seed, 4u);
  EXPECT_EQ(scene->Fruits().size(), 1u);
  EXPECT_EQ(registry.Make("tomato-full-occlusion", 0).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(LoadScene({"one-sphere", "", 2, ""}, registry)->seed, 2u);
  EXPECT_THAT(LoadScene({"one-sphere", "x.yaml", 2, ""}, registry).status().message(),
              HasSubstr("not both"));
}

TEST(ScenarioTest, UnknownNameIsNotFoundAndListsTheKnownOnes) {
  const Result<Scene> r = MakeScenario("tomato-full-oclusion", 0);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(r.status().message(), HasSubstr("'tomato-full-oclusion'"));
  for (const std::string& name : BuiltinScenarios().Names()) {
    EXPECT_THAT(r.status().message(), HasSubstr(name));
  }
  EXPECT_EQ(MakeScenario("", 0).status().code(), StatusCode::kNotFound);
}

TEST(ScenarioTest, ReferenceStartMatchesTheUrdfConventionMath) {
  const std::vector<double> q = ReferenceStartJointsRad();
  const std::vector<double> deg = {0.0, -70.0, 60.0, 0.0, 47.5, 0.0};
  ASSERT_EQ(q.size(), 6u);
  for (size_t i = 0; i < 6; ++i) EXPECT_NEAR(q[i], deg[i] * kPi / 180.0, 1e-15);
  const RigidTransform X_WC = ReferenceStartCameraPose();
  EXPECT_TRUE(X_WC.translation().isApprox(Eigen::Vector3d(0.22, 0.0, 0.677), 1e-12));
  // Optical z along +x, image up (-y) = world +z, image right (x) = world -y.
  EXPECT_TRUE(X_WC.rotation().col(2).isApprox(Eigen::Vector3d::UnitX(), 1e-12));
  EXPECT_TRUE((-X_WC.rotation().col(1)).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
  EXPECT_TRUE(X_WC.rotation().col(0).isApprox(-Eigen::Vector3d::UnitY(), 1e-12));
  EXPECT_TRUE(X_WC.IsNearlyEqualTo(
      RigidTransform::LookAt(X_WC.translation(), X_WC.translation() + Eigen::Vector3d::UnitX()),
      1e-12, 1e-12));
}

TEST(ScenarioTest, JointOneYawRotatesTheCameraAboutTheBase) {
  for (const double yaw_deg : {-65.0, 20.0, 65.0}) {
    const RigidTransform X = ReferenceStartCameraPose(yaw_deg);
    EXPECT_DOUBLE_EQ(ReferenceStartJointsRad(yaw_deg)[0], yaw_deg * kPi / 180.0);
    // q1 = +theta turns the view by -theta about z (towards -y for theta > 0).
    const double a = -yaw_deg * kPi / 180.0;
    EXPECT_TRUE(X.rotation().col(2).isApprox(Eigen::Vector3d(std::cos(a), std::sin(a), 0), 1e-12));
    EXPECT_TRUE(X.translation().isApprox(
        Eigen::Vector3d(0.22 * std::cos(a), 0.22 * std::sin(a), 0.677), 1e-12));
    EXPECT_TRUE((-X.rotation().col(1)).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
  }
}

TEST(ScenarioTest, EveryScenarioBuildsValidScenesForSeveralSeeds) {
  const ScenarioRegistry scenarios = BuiltinScenarios();
  for (const ScenarioEntry& info : scenarios.entries()) {
    for (const uint64_t seed : {0u, 1u, 17u}) {
      SCOPED_TRACE(info.name + " seed " + std::to_string(seed));
      const Scene s = Make(info.name, seed);
      ASSERT_TRUE(s.Validate().ok()) << s.Validate().ToString();
      EXPECT_EQ(s.name, info.name);
      EXPECT_EQ(s.description, info.description);
      EXPECT_EQ(s.seed, seed);
      int ground = 0;
      for (const SceneObject& o : s.objects) {
        if (o.semantic_class == SemanticClass::kGround) {
          ++ground;
          EXPECT_NEAR(o.Bounds().max().z(), 0.0, 1e-9);
        }
      }
      EXPECT_EQ(ground, 1);
      EXPECT_FALSE(s.Fruits().empty());
      // The plant's bounds exclude the 4 x 4 m ground and contain every fruit.
      ASSERT_FALSE(s.plant_bounds.IsEmpty());
      EXPECT_LT(s.plant_bounds.size().x(), 1.5);
      // The training family draws plants from 0.5 m up (generic_plant.h).
      EXPECT_GT(s.plant_bounds.max().z(), info.training_only ? 0.45 : 1.0);
      for (const FruitTruth& f : s.Fruits()) EXPECT_TRUE(s.plant_bounds.Contains(f.center_W));
      // Start: 6 URDF joints, camera consistent with the joint-1 yaw.
      ASSERT_EQ(s.start_joints_rad.size(), 6u);
      const double yaw_deg = s.start_joints_rad[0] * 180.0 / kPi;
      EXPECT_TRUE(s.X_WC_start.IsNearlyEqualTo(ReferenceStartCameraPose(yaw_deg), 1e-12, 1e-12));
      for (size_t i = 1; i < 6; ++i) {
        EXPECT_DOUBLE_EQ(s.start_joints_rad[i], ReferenceStartJointsRad()[i]);
      }
      EXPECT_LT(s.num_triangles(), 150000u);
    }
  }
}

TEST(ScenarioTest, SameSeedSameSceneDifferentSeedDifferentPlant) {
  const ScenarioRegistry scenarios = BuiltinScenarios();
  for (const ScenarioEntry& info : scenarios.entries()) {
    SCOPED_TRACE(info.name);
    const Scene a = Make(info.name, 5);
    EXPECT_TRUE(SameScene(a, Make(info.name, 5)));
    const Scene b = Make(info.name, 6);
    EXPECT_FALSE(SameScene(a, b));
    EXPECT_GT((a.Fruits()[0].center_W - b.Fruits()[0].center_W).norm(), 1e-3);
  }
}

TEST(ScenarioTest, TomatoScenariosHaveTheirFruitCountsAndSizes) {
  struct Expect {
    const char* name;
    int min_fruits, max_fruits;
  };
  for (const Expect& e :
       {Expect{"tomato-multiple-clusters", 12, 42}, Expect{"tomato-full-occlusion", 9, 35},
        Expect{"tomato-single-cluster", 5, 8}}) {
    for (uint64_t seed = 0; seed < 6; ++seed) {
      SCOPED_TRACE(std::string(e.name) + " seed " + std::to_string(seed));
      const Scene s = Make(e.name, seed);
      const std::vector<FruitTruth> fruits = s.Fruits();
      EXPECT_GE(static_cast<int>(fruits.size()), e.min_fruits);
      EXPECT_LE(static_cast<int>(fruits.size()), e.max_fruits);
      for (const FruitTruth& f : fruits) {
        EXPECT_GE(f.radii.minCoeff(), 0.015);
        EXPECT_LE(f.radii.maxCoeff(), 0.035);
        // The reference plant's fruit region (x 0.57-0.86, y -0.16-0.11, z 0.50-1.08), widened
        // for the random layout.
        EXPECT_GT(f.center_W.x(), 0.35);
        EXPECT_LT(f.center_W.x(), 1.05);
        EXPECT_LT(std::abs(f.center_W.y()), 0.35);
        EXPECT_GT(f.center_W.z(), 0.2);
        EXPECT_LT(f.center_W.z(), 1.3);
      }
      // Main stem height 1.0-1.4 m.
      for (const SceneObject& o : s.objects) {
        if (o.name == "tomato/stem") {
          EXPECT_GE(o.Bounds().max().z(), 1.0 - 1e-6);
          EXPECT_LE(o.Bounds().max().z(), 1.4 + 0.01);
        }
      }
    }
  }
  // One truss in the single-cluster scene.
  int trusses = 0;
  for (const SceneObject& o : Make("tomato-single-cluster", 3).objects) {
    trusses += o.name.find("/truss_") != std::string::npos;
  }
  EXPECT_EQ(trusses, 1);
}

TEST(ScenarioTest, EspalierScenariosHaveTheirApples) {
  for (const char* name : {"espalier-multiple-fruits", "espalier-full-occlusion"}) {
    for (uint64_t seed = 0; seed < 4; ++seed) {
      SCOPED_TRACE(std::string(name) + " seed " + std::to_string(seed));
      const Scene s = Make(name, seed);
      EXPECT_GE(s.Fruits().size(), 12u);
      EXPECT_LE(s.Fruits().size(), 24u);
      for (const FruitTruth& f : s.Fruits()) {
        EXPECT_GE(f.radii.minCoeff(), 0.030);
        EXPECT_LE(f.radii.maxCoeff(), 0.045);
      }
      EXPECT_NEAR(s.plant_bounds.size().y(), 1.7, 0.1);  // posts at +-0.85 m
    }
  }
}

TEST(ScenarioTest, UnorientedScenariosReuseTheirTwinsPlant) {
  for (const uint64_t seed : {0u, 9u}) {
    const Scene oriented = Make("tomato-multiple-clusters", seed);
    const Scene moved = Make("tomato-unoriented-start", seed);
    const std::vector<FruitTruth> a = oriented.Fruits();
    const std::vector<FruitTruth> b = moved.Fruits();
    ASSERT_EQ(a.size(), b.size());
    for (size_t i = 0; i < a.size(); ++i) {
      EXPECT_LT((b[i].center_W - a[i].center_W - Eigen::Vector3d(0, 0.4, 0)).norm(), 1e-9);
    }
    EXPECT_NEAR(moved.start_joints_rad[0], 20.0 * kPi / 180.0, 1e-15);

    const Scene espalier = Make("espalier-multiple-fruits", seed);
    const Scene turned = Make("espalier-unoriented-start", seed);
    ASSERT_EQ(espalier.objects.size(), turned.objects.size());
    for (size_t i = 0; i < espalier.Fruits().size(); ++i) {
      EXPECT_EQ(espalier.Fruits()[i].center_W, turned.Fruits()[i].center_W);
    }
    EXPECT_NEAR(turned.start_joints_rad[0], 65.0 * kPi / 180.0, 1e-15);
  }
}

TEST(ScenarioTest, StartViewsSeeFruitOnlyWhereTheyShould) {
  // Geometry only (fruit centres inside the start image), over several seeds.
  for (uint64_t seed = 0; seed < 6; ++seed) {
    SCOPED_TRACE(seed);
    EXPECT_GE(FruitCentresInStartView(Make("tomato-multiple-clusters", seed)), 3);
    EXPECT_EQ(FruitCentresInStartView(Make("tomato-unoriented-start", seed)), 0);
    EXPECT_EQ(FruitCentresInStartView(Make("espalier-unoriented-start", seed)), 0);
  }
}

// Rendered checks with the Embree camera: count fruit-class pixels at 640x480.
TEST(ScenarioRenderTest, FullOcclusionHidesTheFruitOnlyFromTheStart) {
  for (const char* name : {"tomato-full-occlusion", "espalier-full-occlusion"}) {
    for (const uint64_t seed : {0u, 1u}) {
      SCOPED_TRACE(std::string(name) + " seed " + std::to_string(seed));
      const Scene s = Make(name, seed);
      const RgbdRenderer renderer(s);
      const int start = FruitPixels(renderer, s.X_WC_start);
      const int back = FruitPixels(renderer, BackView(s));
      // From behind the plant the fruit are plain to see; from the start at most 0.5 % of that
      // (slivers between leaves the surface sampling of the occlusion screen can miss).
      EXPECT_GT(back, 5000);
      EXPECT_LE(start, back / 200);
      // Several fruit centres do lie inside the start image: it is the leaves that hide them.
      EXPECT_GE(FruitCentresInStartView(s), 1);
    }
  }
}

TEST(ScenarioRenderTest, MultipleClustersShowFruitAndUnorientedStartsShowNone) {
  for (const uint64_t seed : {0u, 1u}) {
    SCOPED_TRACE(seed);
    const Scene typical = Make("tomato-multiple-clusters", seed);
    const int typical_pixels = FruitPixels(RgbdRenderer(typical), typical.X_WC_start);
    EXPECT_GT(typical_pixels, 3000);
    const Scene moved = Make("tomato-unoriented-start", seed);
    EXPECT_LE(FruitPixels(RgbdRenderer(moved), moved.X_WC_start), typical_pixels / 100);
    const Scene single = Make("tomato-single-cluster", seed);
    EXPECT_GT(FruitPixels(RgbdRenderer(single), BackView(single)), 1000);
    const Scene turned = Make("espalier-unoriented-start", seed);
    const Scene espalier = Make("espalier-multiple-fruits", seed);
    const RgbdRenderer espalier_renderer(espalier);
    EXPECT_LE(FruitPixels(espalier_renderer, turned.X_WC_start), 500);
    // From 1.3 m in front of the espalier nearly every apple is in view.
    const RigidTransform wide = RigidTransform::LookAt({-0.6, 0.0, 0.8}, {0.7, 0.0, 0.75});
    EXPECT_GT(FruitPixels(espalier_renderer, wide), 3000);
  }
}

}  // namespace
}  // namespace avp::sim

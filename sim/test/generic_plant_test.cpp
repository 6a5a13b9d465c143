#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <avp/core/camera.h>
#include <avp/core/rng.h>
#include <avp/sim/generic_plant.h>
#include <avp/sim/scenario.h>

namespace avp::sim {
namespace {

using Layout = GenericPlantDraw::Layout;

TEST(GenericPlantTest, SeedsCoverEveryLayoutOcclusionAndStart) {
  std::set<std::string> layouts;
  int occluded = 0, yawed = 0, far_side = 0, supported = 0;
  for (uint64_t seed = 0; seed < 40; ++seed) {
    Rng rng(seed);
    const GenericPlantDraw d = DrawGenericLayout(rng);
    layouts.insert(GenericLayoutName(d.layout));
    occluded += d.occluded ? 1 : 0;
    far_side += d.far_side_fruit ? 1 : 0;
    if (d.start_yaw_deg != 0.0) {
      ++yawed;
      EXPECT_GE(std::abs(d.start_yaw_deg), 15.0);
      EXPECT_LE(std::abs(d.start_yaw_deg), 55.0);
    }
    EXPECT_EQ(d.plants > 1, d.layout == Layout::kRow);
    EXPECT_TRUE(!d.supports || d.layout == Layout::kWall || d.layout == Layout::kTrellis);
    supported += d.supports ? 1 : 0;
  }
  EXPECT_EQ(layouts, (std::set<std::string>{"row", "single", "trellis", "wall"}));
  EXPECT_GT(supported, 0);
  // Each is drawn with probability 0.3: between 4 and 20 of 40 (binomial, p > 0.999).
  for (const int n : {occluded, yawed, far_side}) {
    EXPECT_GE(n, 4);
    EXPECT_LE(n, 20);
  }
}

TEST(GenericPlantTest, PlantsHaveSeparateFruitInsideTheirBoundsAndAreDeterministic) {
  for (const Layout layout : {Layout::kSingle, Layout::kRow, Layout::kWall, Layout::kTrellis}) {
    for (uint64_t seed = 0; seed < 4; ++seed) {
      SCOPED_TRACE(std::string(GenericLayoutName(layout)) + " seed " + std::to_string(seed));
      GenericPlantDraw draw;
      draw.layout = layout;
      draw.plants = layout == Layout::kRow ? 3 : 1;
      draw.supports = layout == Layout::kTrellis;
      Scene scene, again;
      Rng rng(seed), rng_again(seed);
      const GenericPlantInfo info = AddGenericPlants(draw, ReferenceStartCameraPose(), rng, scene);
      AddGenericPlants(draw, ReferenceStartCameraPose(), rng_again, again);
      scene.UpdatePlantBounds();
      ASSERT_TRUE(scene.Validate().ok()) << scene.Validate().ToString();
      const std::vector<FruitTruth> fruits = scene.Fruits();
      ASSERT_FALSE(fruits.empty());
      EXPECT_EQ(fruits.size(), info.fruit_ids.size());
      EXPECT_GT(info.num_branches, draw.plants);
      EXPECT_GT(info.num_leaves, 0);
      EXPECT_LT(info.num_triangles, 150000u);
      for (size_t i = 0; i < fruits.size(); ++i) {
        EXPECT_TRUE(scene.plant_bounds.Contains(fruits[i].center_W));
        EXPECT_GT(fruits[i].center_W.z() - fruits[i].radii.z(), 0.05);
        EXPECT_GE(fruits[i].mean_radius_m(), 0.015 * 0.8);
        EXPECT_LE(fruits[i].mean_radius_m(), 0.045 * 1.2);
        for (size_t j = 0; j < i; ++j) {
          EXPECT_GT((fruits[i].center_W - fruits[j].center_W).norm(),
                    0.8 * (fruits[i].mean_radius_m() + fruits[j].mean_radius_m()));
        }
      }
      ASSERT_EQ(again.Fruits().size(), fruits.size());
      for (size_t i = 0; i < fruits.size(); ++i) {
        EXPECT_EQ(again.Fruits()[i].center_W, fruits[i].center_W);
      }
      if (layout == Layout::kWall || layout == Layout::kTrellis) {
        // A wall or a trellis is wide along y and thin along x.
        EXPECT_GT(scene.plant_bounds.size().y(), 1.5 * scene.plant_bounds.size().x());
      }
      size_t supports = 0;
      for (const SceneObject& o : scene.objects) {
        supports += o.semantic_class == SemanticClass::kSupport ? 1 : 0;
      }
      // Two stakes and 1-4 wires.
      if (draw.supports) {
        EXPECT_GE(supports, 3u);
        EXPECT_LE(supports, 6u);
      } else {
        EXPECT_EQ(supports, 0u);
      }
    }
  }
}

TEST(GenericPlantTest, AnOccludedPlantHidesItsFruitFromTheStartView) {
  const CameraIntrinsics camera = CameraIntrinsics::RealSenseD435();
  for (uint64_t seed = 0; seed < 3; ++seed) {
    GenericPlantDraw draw;
    Scene open, hidden;
    Rng a(seed), b(seed);
    AddGenericPlants(draw, ReferenceStartCameraPose(), a, open);
    draw.occluded = true;
    const GenericPlantInfo info = AddGenericPlants(draw, ReferenceStartCameraPose(), b, hidden);
    const size_t before = CountFruitPixels(open, camera, ReferenceStartCameraPose());
    const size_t after = CountFruitPixels(hidden, camera, ReferenceStartCameraPose());
    SCOPED_TRACE("seed " + std::to_string(seed));
    if (before > 0) {
      EXPECT_GT(info.num_screen_leaves, 0);
    }
    EXPECT_LE(after, before / 10 + 20) << before << " fruit pixels before the screen";
  }
}

TEST(GenericPlantTest, TheTrainingScenarioFollowsItsDraw) {
  for (uint64_t seed = 0; seed < 6; ++seed) {
    const Result<Scene> scene = MakeScenario(kGenericTrainingScenario, seed);
    ASSERT_TRUE(scene.ok()) << scene.status().ToString();
    Rng rng = Rng(seed).Fork("generic-training");
    const GenericPlantDraw draw = DrawGenericLayout(rng);
    EXPECT_TRUE(scene->X_WC_start.IsNearlyEqualTo(ReferenceStartCameraPose(draw.start_yaw_deg),
                                                  1e-12, 1e-12));
  }
}

}  // namespace
}  // namespace avp::sim

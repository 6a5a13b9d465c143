#include <algorithm>
#include <set>
#include <string>
#include <variant>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/tomato_plant.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;

struct Grown {
  Scene scene;
  TomatoPlantInfo info;
};

Grown Grow(const TomatoPlantParams& params, uint64_t seed) {
  Grown g;
  Rng rng(seed);
  g.info = AddTomatoPlant(params, rng, g.scene);
  return g;
}

const SceneObject& Find(const Scene& scene, const std::string& name) {
  for (const SceneObject& o : scene.objects) {
    if (o.name == name) return o;
  }
  throw Error("no object named " + name);
}

/// True when both scenes hold the same objects with bit-identical geometry.
::testing::AssertionResult SameScene(const Scene& a, const Scene& b) {
  const std::string difference = DescribeDifference(a, b);
  if (difference.empty()) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << difference;
}

std::vector<Ellipsoid> FruitShapes(const Scene& scene) {
  std::vector<Ellipsoid> out;
  for (const SceneObject& o : scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) out.push_back(std::get<Ellipsoid>(o.shape));
  }
  return out;
}

TEST(TomatoPlantTest, DefaultsAreValidAndValidateNamesEveryBadField) {
  EXPECT_TRUE(TomatoPlantParams{}.Validate().ok());
  TomatoPlantParams p;
  p.height_min_m = 2.0;
  p.height_max_m = 1.4;
  p.leaflets_min = 4;
  p.fruit_radius_max_m = 0.01;
  p.leaf_density = -1.0;
  p.occlusion.enabled = true;
  p.occlusion.samples_per_fruit = 2;
  const Status s = p.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("invalid tomato plant"));
  EXPECT_THAT(s.message(), HasSubstr("height_max_m (1.4) must be in [height_min_m (2), 3]"));
  EXPECT_THAT(s.message(), HasSubstr("leaflets_min (4) must be odd"));
  EXPECT_THAT(s.message(), HasSubstr("fruit_radius_max_m (0.01)"));
  EXPECT_THAT(s.message(), HasSubstr("leaf_density (-1)"));
  EXPECT_THAT(s.message(), HasSubstr("samples_per_fruit (2)"));
  Scene scene;
  Rng rng(0);
  try {
    AddTomatoPlant(p, rng, scene);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("leaflets_min (4)"));
  }
  EXPECT_TRUE(scene.objects.empty());
}

TEST(TomatoPlantTest, SameSeedGivesTheSamePlantAndOtherSeedsDiffer) {
  const TomatoPlantParams p;
  const Grown a = Grow(p, 42);
  const Grown b = Grow(p, 42);
  EXPECT_TRUE(SameScene(a.scene, b.scene));
  const Grown c = Grow(p, 43);
  EXPECT_FALSE(SameScene(a.scene, c.scene));
  EXPECT_NE(a.info.height_m, c.info.height_m);
  const std::vector<Ellipsoid> fa = FruitShapes(a.scene);
  const std::vector<Ellipsoid> fc = FruitShapes(c.scene);
  ASSERT_FALSE(fa.empty());
  ASSERT_FALSE(fc.empty());
  EXPECT_GT((fa[0].center_W - fc[0].center_W).norm(), 1e-3);
}

TEST(TomatoPlantTest, TwoPlantsFromOneGeneratorDiffer) {
  // Each call draws its own seed from the generator it is given.
  Scene scene;
  Rng rng(5);
  TomatoPlantParams p;
  const TomatoPlantInfo first = AddTomatoPlant(p, rng, scene);
  p.name_prefix = "second";
  p.stem_base_W.y() = 0.6;
  const TomatoPlantInfo second = AddTomatoPlant(p, rng, scene);
  EXPECT_NE(first.height_m, second.height_m);
  EXPECT_TRUE(scene.Validate().ok());
  EXPECT_EQ(scene.objects.size(), first.num_objects + second.num_objects);
}

TEST(TomatoPlantTest, StemTrussesAndFruitsStayWithinTheirRanges) {
  const TomatoPlantParams p;
  for (uint64_t seed = 0; seed < 12; ++seed) {
    SCOPED_TRACE(seed);
    const Grown g = Grow(p, seed);
    ASSERT_TRUE(g.scene.Validate().ok());
    // Stem height (the tube's top) within [1.0, 1.4] m; the top may lean a few centimetres.
    EXPECT_GE(g.info.height_m, p.height_min_m);
    EXPECT_LE(g.info.height_m, p.height_max_m);
    const Box3 stem = Find(g.scene, "tomato/stem").Bounds();
    EXPECT_NEAR(stem.max().z(), g.info.height_m, 0.012);
    EXPECT_NEAR(stem.min().z(), 0.0, 0.002);
    EXPECT_LT((g.info.stem_top_W - p.stem_base_W).head<2>().norm(), p.stem_lean_max_m + 0.01);

    const int trusses = static_cast<int>(g.info.fruits_per_truss.size());
    EXPECT_GE(trusses, p.trusses_min);
    EXPECT_LE(trusses, p.trusses_max);
    for (const int n : g.info.fruits_per_truss) {
      EXPECT_GE(n, p.fruits_per_truss_min);
      EXPECT_LE(n, p.fruits_per_truss_max);
    }
    const std::vector<Ellipsoid> fruits = FruitShapes(g.scene);
    ASSERT_EQ(fruits.size(), g.info.fruit_ids.size());
    for (size_t i = 0; i < fruits.size(); ++i) {
      const Ellipsoid& f = fruits[i];
      EXPECT_GE(f.radii.minCoeff(), p.fruit_radius_min_m);
      EXPECT_LE(f.radii.maxCoeff(), p.fruit_radius_max_m);
      EXPECT_TRUE(IsRotationMatrix(f.R_WE, 1e-9));
      // Hanging from the plant: above the ground, around the stem, below its top.
      EXPECT_GT(f.center_W.z() - f.radii.maxCoeff(), 0.02);
      EXPECT_LT(f.center_W.z(), g.info.height_m);
      EXPECT_LT((f.center_W - p.stem_base_W).head<2>().norm(), 0.4);
      // No two fruits overlap by more than 5 % of their radii (touching is fine).
      for (size_t j = 0; j < i; ++j) {
        const double d = (f.center_W - fruits[j].center_W).norm();
        EXPECT_GE(d, 0.95 * (f.radii.maxCoeff() + fruits[j].radii.maxCoeff()) - 1e-9)
            << i << " and " << j;
      }
    }
    // Budget: a typical plant renders in well under the 40-150k triangle budget.
    EXPECT_GT(g.info.num_triangles, 8000u);
    EXPECT_LT(g.info.num_triangles, 150000u);
  }
}

TEST(TomatoPlantTest, ObjectsHaveTheDocumentedNamesAndClasses) {
  const Grown g = Grow(TomatoPlantParams{}, 3);
  std::set<std::string> names;
  int leaves = 0;
  for (const SceneObject& o : g.scene.objects) {
    EXPECT_TRUE(names.insert(o.name).second) << "duplicate name " << o.name;
    EXPECT_EQ(o.name.rfind("tomato/", 0), 0u) << o.name;
    EXPECT_TRUE((o.albedo.array() >= 0.0f).all() && (o.albedo.array() <= 1.0f).all());
    if (o.name.find("/fruit_") != std::string::npos) {
      EXPECT_EQ(o.semantic_class, SemanticClass::kFruit) << o.name;
    } else if (o.name.find("/rachis") != std::string::npos ||
               o.name.find("/truss_") != std::string::npos || o.name == "tomato/stem") {
      EXPECT_EQ(o.semantic_class, SemanticClass::kStem) << o.name;
    } else if (o.name.find("/leaf_") != std::string::npos) {
      EXPECT_EQ(o.semantic_class, SemanticClass::kLeaf) << o.name;
      ++leaves;
    } else {
      EXPECT_EQ(o.name, "tomato/stake");
      EXPECT_EQ(o.semantic_class, SemanticClass::kSupport);
    }
  }
  EXPECT_EQ(leaves, g.info.num_leaves);
  for (const uint16_t id : g.info.fruit_ids) {
    ASSERT_NE(g.scene.FindInstance(id), nullptr);
    EXPECT_EQ(g.scene.FindInstance(id)->semantic_class, SemanticClass::kFruit);
  }
}

TEST(TomatoPlantTest, CompoundLeavesHaveAnOddNumberOfLeaflets) {
  // Without the small intercalary leaflets, each leaflet is one connected component.
  TomatoPlantParams p;
  p.intercalary_leaflets = false;
  const Grown g = Grow(p, 8);
  ASSERT_GT(g.info.num_leaves, 8);
  std::set<size_t> counts;
  for (const SceneObject& o : g.scene.objects) {
    if (o.semantic_class != SemanticClass::kLeaf) continue;
    const size_t n = ConnectedComponents(std::get<TriangleMesh>(o.shape)).size();
    EXPECT_TRUE(n == 5 || n == 7 || n == 9) << o.name << ": " << n;
    counts.insert(n);
  }
  EXPECT_GE(counts.size(), 2u);  // the count varies from leaf to leaf
}

TEST(TomatoPlantTest, LeafDensityControlsLeafCountAndArea) {
  const auto leaf_area = [](const Scene& scene) {
    double area = 0.0;
    for (const SceneObject& o : scene.objects) {
      if (o.semantic_class == SemanticClass::kLeaf) {
        area += SurfaceArea(std::get<TriangleMesh>(o.shape));
      }
    }
    return area;
  };
  TomatoPlantParams p;
  p.leaf_density = 0.0;
  const Grown bare = Grow(p, 1);
  EXPECT_EQ(bare.info.num_leaves, 0);
  EXPECT_EQ(leaf_area(bare.scene), 0.0);
  p.leaf_density = 0.5;
  const Grown sparse = Grow(p, 1);
  p.leaf_density = 1.0;
  const Grown typical = Grow(p, 1);
  p.leaf_density = 2.0;
  const Grown dense = Grow(p, 1);
  EXPECT_LT(sparse.info.num_leaves, typical.info.num_leaves);
  EXPECT_LT(typical.info.num_leaves, dense.info.num_leaves);
  EXPECT_GT(leaf_area(typical.scene), 1.6 * leaf_area(sparse.scene));
  EXPECT_GT(leaf_area(dense.scene), 1.6 * leaf_area(typical.scene));
  // ~12 leaves per metre of leafy stem (from first_leaf_height_m to 4 cm below the top).
  const double leafy_m = typical.info.height_m - p.first_leaf_height_m - 0.04;
  EXPECT_NEAR(typical.info.num_leaves / leafy_m, 12.0, 2.0);
  // The fruit do not depend on the leaves (independent random streams).
  const std::vector<Ellipsoid> a = FruitShapes(sparse.scene);
  const std::vector<Ellipsoid> b = FruitShapes(dense.scene);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].center_W, b[i].center_W);
}

TEST(TomatoPlantTest, StemBasePositionMovesTheWholePlant) {
  TomatoPlantParams p;
  const Grown here = Grow(p, 9);
  p.stem_base_W = Eigen::Vector3d(0.5, -0.3, 0.0);
  const Grown there = Grow(p, 9);
  const Eigen::Vector3d shift(-0.2, -0.3, 0.0);
  const std::vector<Ellipsoid> a = FruitShapes(here.scene);
  const std::vector<Ellipsoid> b = FruitShapes(there.scene);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_LT((b[i].center_W - a[i].center_W - shift).norm(), 1e-9);
  }
  const Box3 stem_a = Find(here.scene, "tomato/stem").Bounds();
  const Box3 stem_b = Find(there.scene, "tomato/stem").Bounds();
  EXPECT_LT((stem_b.center() - stem_a.center() - shift).norm(), 1e-6);
}

TEST(TomatoPlantTest, TrussAzimuthPutsTheFruitOnOneSide) {
  TomatoPlantParams p;
  p.truss_azimuth_deg = 0.0;  // +x
  p.truss_azimuth_spread_deg = 60.0;
  for (uint64_t seed = 0; seed < 5; ++seed) {
    for (const Ellipsoid& f : FruitShapes(Grow(p, seed).scene)) {
      EXPECT_GT(f.center_W.x(), p.stem_base_W.x() + 0.02) << seed;
    }
  }
}

TEST(TomatoPlantTest, RipenessColoursRunFromGreenToRed) {
  const Eigen::Vector3f green = TomatoColor(0.0);
  const Eigen::Vector3f red = TomatoColor(1.0);
  EXPECT_GT(green.y(), green.x());
  EXPECT_GT(red.x(), 5.0f * red.y());
  EXPECT_EQ(TomatoColor(-3.0), green);  // clamped
  TomatoPlantParams p;
  p.ripeness_min = 1.0;
  p.ripeness_max = 1.0;
  const Grown ripe = Grow(p, 2);
  for (const SceneObject& o : ripe.scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) {
      EXPECT_GT(o.albedo.x(), 3.0f * o.albedo.y());
    }
  }
}

TEST(TomatoPlantTest, OcclusionScreenHidesEveryFruitFromTheEye) {
  TomatoPlantParams p;
  p.truss_azimuth_spread_deg = 120.0;
  p.occlusion.enabled = true;
  p.occlusion.eye_W = Eigen::Vector3d(0.22, 0.0, 0.677);
  p.occlusion.view_direction_W = Eigen::Vector3d::UnitX();
  const Grown g = Grow(p, 4);
  EXPECT_GT(g.info.num_screen_leaves, 0);
  EXPECT_LT(g.info.num_screen_leaves, p.occlusion.max_leaves);
  EXPECT_EQ(g.info.num_visible_samples, 0);
  ASSERT_TRUE(g.scene.Validate().ok());

  // An independent, four times denser sampling finds (almost) nothing either.
  OcclusionScreen check = p.occlusion;
  check.samples_per_fruit = 640;
  const std::vector<Ellipsoid> fruits = FruitShapes(g.scene);
  FruitVisibility visibility(check, fruits);
  for (const SceneObject& o : g.scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) continue;
    visibility.AddOccluder(std::get<TriangleMesh>(o.shape));
  }
  ASSERT_GT(visibility.num_samples(), 500u);
  EXPECT_LE(visibility.CountVisible(), static_cast<int>(visibility.num_samples() / 200));

  // Without the screen the same plant shows a good part of its fruit.
  p.occlusion.enabled = false;
  const Grown open = Grow(p, 4);
  FruitVisibility open_visibility(check, FruitShapes(open.scene));
  for (const SceneObject& o : open.scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) continue;
    open_visibility.AddOccluder(std::get<TriangleMesh>(o.shape));
  }
  EXPECT_GT(open_visibility.CountVisible(), static_cast<int>(open_visibility.num_samples() / 10));
}

}  // namespace
}  // namespace avp::sim

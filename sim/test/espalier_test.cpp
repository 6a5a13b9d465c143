#include <set>
#include <string>
#include <variant>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>
#include <avp/sim/espalier.h>
#include <avp/sim/mesh_builder.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;

struct Grown {
  Scene scene;
  EspalierInfo info;
};

Grown Grow(const EspalierParams& params, uint64_t seed) {
  Grown g;
  Rng rng(seed);
  g.info = AddEspalier(params, rng, g.scene);
  return g;
}

std::vector<Ellipsoid> Apples(const Scene& scene) {
  std::vector<Ellipsoid> out;
  for (const SceneObject& o : scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) out.push_back(std::get<Ellipsoid>(o.shape));
  }
  return out;
}

Box3 BoundsOf(const Scene& scene, const std::string& prefix) {
  Box3 b;
  for (const SceneObject& o : scene.objects) {
    if (o.name.rfind(prefix, 0) == 0) b.Extend(o.Bounds());
  }
  return b;
}

TEST(EspalierTest, DefaultsAreValidAndValidateNamesEveryBadField) {
  EXPECT_TRUE(EspalierParams{}.Validate().ok());
  EspalierParams p;
  p.tiers_min = 1;
  p.width_m = 0.1;
  p.fruit_radius_min_m = 0.05;
  p.fruit_radius_max_m = 0.04;
  p.red_fraction = 2.0;
  const Status s = p.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("invalid espalier"));
  EXPECT_THAT(s.message(), HasSubstr("tiers_min (1)"));
  EXPECT_THAT(s.message(), HasSubstr("width_m (0.1)"));
  EXPECT_THAT(s.message(), HasSubstr("fruit_radius_max_m (0.04)"));
  EXPECT_THAT(s.message(), HasSubstr("red_fraction (2)"));
  Scene scene;
  Rng rng(0);
  EXPECT_THROW(AddEspalier(p, rng, scene), Error);
}

TEST(EspalierTest, SameSeedSameTreeOtherSeedsDiffer) {
  const EspalierParams p;
  const Grown a = Grow(p, 7);
  const Grown b = Grow(p, 7);
  ASSERT_EQ(a.scene.objects.size(), b.scene.objects.size());
  for (size_t i = 0; i < a.scene.objects.size(); ++i) {
    const SceneObject& x = a.scene.objects[i];
    const SceneObject& y = b.scene.objects[i];
    ASSERT_EQ(x.name, y.name);
    ASSERT_EQ(x.albedo, y.albedo);
    if (const auto* m = std::get_if<TriangleMesh>(&x.shape)) {
      ASSERT_EQ(m->vertices, std::get<TriangleMesh>(y.shape).vertices) << x.name;
      ASSERT_EQ(m->triangles, std::get<TriangleMesh>(y.shape).triangles) << x.name;
    } else {
      ASSERT_EQ(std::get<Ellipsoid>(x.shape).center_W, std::get<Ellipsoid>(y.shape).center_W);
      ASSERT_EQ(std::get<Ellipsoid>(x.shape).radii, std::get<Ellipsoid>(y.shape).radii);
    }
  }
  const Grown c = Grow(p, 8);
  const std::vector<Ellipsoid> fa = Apples(a.scene);
  const std::vector<Ellipsoid> fc = Apples(c.scene);
  ASSERT_FALSE(fa.empty());
  ASSERT_FALSE(fc.empty());
  EXPECT_GT((fa[0].center_W - fc[0].center_W).norm(), 1e-3);
}

TEST(EspalierTest, ShapeFollowsTheParameters) {
  const EspalierParams p;
  for (uint64_t seed = 0; seed < 8; ++seed) {
    SCOPED_TRACE(seed);
    const Grown g = Grow(p, seed);
    ASSERT_TRUE(g.scene.Validate().ok());
    EXPECT_GE(g.info.num_tiers, p.tiers_min);
    EXPECT_LE(g.info.num_tiers, p.tiers_max);
    ASSERT_EQ(g.info.tier_heights_m.size(), static_cast<size_t>(g.info.num_tiers));
    EXPECT_NEAR(g.info.tier_heights_m.front(), p.first_tier_height_m, 0.021);
    EXPECT_DOUBLE_EQ(g.info.tier_heights_m.back(), p.height_m);
    // Planar: trunk and cordons stay within a few centimetres of the plane x = 0.7.
    const Box3 wood = BoundsOf(g.scene, "espalier/trunk");
    EXPECT_NEAR(wood.min().x(), 0.7 - p.trunk_radius_m, 0.015);
    EXPECT_NEAR(wood.max().x(), 0.7 + p.trunk_radius_m, 0.015);
    EXPECT_NEAR(wood.max().z(), p.height_m - 0.07, 0.03);
    const Box3 cordons = BoundsOf(g.scene, "espalier/cordon_");
    // About 1.5 m wide (each side reaches 92-100 % of 0.75 m, spurs and leaves add a little).
    EXPECT_GT(cordons.size().y(), 0.92 * p.width_m);
    EXPECT_LT(cordons.size().y(), p.width_m + 0.2);
    const Box3 canopy = BoundsOf(g.scene, "espalier/leaves_");
    EXPECT_LT(canopy.size().x(), 0.45);  // a thin wall of leaves
    EXPECT_GT(canopy.size().y(), 1.2);

    const std::vector<Ellipsoid> apples = Apples(g.scene);
    EXPECT_GE(static_cast<int>(apples.size()), p.fruits_min);
    EXPECT_LE(static_cast<int>(apples.size()), p.fruits_max);
    EXPECT_EQ(apples.size(), g.info.fruit_ids.size());
    for (size_t i = 0; i < apples.size(); ++i) {
      EXPECT_GE(apples[i].radii.minCoeff(), p.fruit_radius_min_m);
      EXPECT_LE(apples[i].radii.maxCoeff(), p.fruit_radius_max_m);
      EXPECT_LT(std::abs(apples[i].center_W.x() - 0.7), 0.15);
      EXPECT_LT(std::abs(apples[i].center_W.y()), 0.5 * p.width_m + 0.05);
      for (size_t j = 0; j < i; ++j) {
        EXPECT_GE((apples[i].center_W - apples[j].center_W).norm(),
                  0.97 * (apples[i].radii.maxCoeff() + apples[j].radii.maxCoeff()) - 1e-9);
      }
    }
    EXPECT_GT(g.info.num_leaves, 200);
    EXPECT_GT(g.info.num_triangles, 10000u);
    EXPECT_LT(g.info.num_triangles, 150000u);
  }
}

TEST(EspalierTest, SupportsArePostsAndOneWirePerTier) {
  const Grown g = Grow(EspalierParams{}, 2);
  int posts = 0;
  int wires = 0;
  for (const SceneObject& o : g.scene.objects) {
    if (o.semantic_class != SemanticClass::kSupport) continue;
    if (o.name.find("/post_") != std::string::npos) {
      ++posts;
      EXPECT_GT(std::abs(o.Bounds().center().y()), 0.75);  // beyond the cordon tips
      EXPECT_NEAR(o.Bounds().min().z(), 0.0, 1e-6);
    } else {
      EXPECT_NE(o.name.find("/wire_"), std::string::npos) << o.name;
      ++wires;
      EXPECT_GT(o.Bounds().size().y(), 1.5);
    }
  }
  EXPECT_EQ(posts, 2);
  EXPECT_EQ(wires, g.info.num_tiers);

  EspalierParams bare;
  bare.supports = false;
  bare.leaf_density = 0.0;
  const Grown b = Grow(bare, 2);
  for (const SceneObject& o : b.scene.objects) {
    EXPECT_NE(o.semantic_class, SemanticClass::kSupport) << o.name;
    EXPECT_NE(o.semantic_class, SemanticClass::kLeaf) << o.name;
  }
  EXPECT_EQ(b.info.num_leaves, 0);
}

TEST(EspalierTest, FruitSideChoosesFrontOrBack) {
  EspalierParams p;
  p.fruit_side = FruitSide::kBack;
  for (const Ellipsoid& a : Apples(Grow(p, 1).scene)) EXPECT_GT(a.center_W.x(), 0.7 + 0.01);
  p.fruit_side = FruitSide::kFront;
  for (const Ellipsoid& a : Apples(Grow(p, 1).scene)) EXPECT_LT(a.center_W.x(), 0.7 - 0.01);
}

TEST(EspalierTest, AppleColoursFollowTheRedFraction) {
  EXPECT_GT(AppleColor(1.0).x(), 5.0f * AppleColor(1.0).y());
  EXPECT_GT(AppleColor(0.0).y(), AppleColor(0.0).x());
  EspalierParams p;
  p.red_fraction = 1.0;
  const Grown red = Grow(p, 3);
  p.red_fraction = 0.0;
  const Grown green = Grow(p, 3);
  for (const SceneObject& o : red.scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) {
      EXPECT_GT(o.albedo.x(), 1.5f * o.albedo.y()) << o.name;
    }
  }
  for (const SceneObject& o : green.scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) {
      EXPECT_GT(o.albedo.y(), 0.6f * o.albedo.x()) << o.name;
    }
  }
}

TEST(EspalierTest, OcclusionScreenHidesTheApplesFromTheEye) {
  EspalierParams p;
  p.fruit_side = FruitSide::kBack;
  p.occlusion.enabled = true;
  p.occlusion.eye_W = Eigen::Vector3d(0.22, 0.0, 0.677);
  p.occlusion.view_direction_W = Eigen::Vector3d::UnitX();
  const Grown g = Grow(p, 5);
  EXPECT_EQ(g.info.num_visible_samples, 0);
  EXPECT_GT(g.info.num_screen_leaves, 0);
  std::set<std::string> names;
  for (const SceneObject& o : g.scene.objects) EXPECT_TRUE(names.insert(o.name).second) << o.name;
  EXPECT_TRUE(names.count("espalier/screen_leaves_00"));
  EXPECT_TRUE(names.count("espalier/screen_shoot_00"));
}

}  // namespace
}  // namespace avp::sim

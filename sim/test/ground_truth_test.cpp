#include <algorithm>
#include <cmath>
#include <string>
#include <unordered_set>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>
#include <avp/sim/ground_truth.h>
#include <avp/sim/mesh_builder.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;

SceneObject Fruit(const Eigen::Vector3d& centre, const Eigen::Vector3d& radii,
                  const Eigen::Matrix3d& R = Eigen::Matrix3d::Identity()) {
  SceneObject o;
  o.name = "fruit";
  o.semantic_class = SemanticClass::kFruit;
  Ellipsoid e;
  e.center_W = centre;
  e.radii = radii;
  e.R_WE = R;
  o.shape = e;
  return o;
}

SceneObject SphereFruit(const Eigen::Vector3d& centre, double r) {
  return Fruit(centre, Eigen::Vector3d::Constant(r));
}

/// Icosphere of radius r about `centre` (the mesh builder's tessellation, moved).
TriangleMesh Icosphere(const Eigen::Vector3d& centre, double r, int levels) {
  TriangleMesh mesh = MakeIcosphere(r, levels);
  mesh.Transform(RigidTransform(centre));
  return mesh;
}

/// An icosphere of radius 0.05 m about `centre`, of the given class.
SceneObject Ball(const std::string& name, SemanticClass semantic_class,
                 const Eigen::Vector3d& centre) {
  SceneObject o;
  o.name = name;
  o.semantic_class = semantic_class;
  o.shape = Icosphere(centre, 0.05, 1);
  return o;
}

Eigen::Vector3d RandomUnitVector(Rng& rng) {
  const double z = rng.Uniform(-1.0, 1.0);
  const double phi = rng.Uniform(0.0, 2.0 * M_PI);
  const double rho = std::sqrt(1.0 - z * z);
  return {rho * std::cos(phi), rho * std::sin(phi), z};
}

double IoU(const FruitVoxels& a, const FruitVoxels& b) {
  size_t common = 0;
  for (const auto& [key, id] : a.voxels) common += b.voxels.count(key);
  return static_cast<double>(common) / (a.voxels.size() + b.voxels.size() - common);
}

constexpr double kSqrt3Over2 = 0.8660254037844386;

TEST(GroundTruthTest, SphereVoxelsAreExactlyTheSurfaceVoxels) {
  const double s = 0.006;
  Rng rng(17);
  for (int trial = 0; trial < 4; ++trial) {
    const double r = 0.02 + 0.01 * trial;
    const Eigen::Vector3d c(rng.Uniform(-0.5, 0.5), rng.Uniform(-0.5, 0.5), rng.Uniform(0, 1));
    Scene scene;
    const uint16_t id = scene.Add(SphereFruit(c, r));
    const FruitVoxels gt = VoxelizeFruitSurfaces(scene, s);
    EXPECT_EQ(gt.voxel_size_m, s);
    ASSERT_FALSE(gt.voxels.empty());
    // (a) Every voxel centre lies within the half diagonal of the surface.
    for (const auto& [key, value] : gt.voxels) {
      EXPECT_EQ(value, id);
      const double dist = std::abs((key.Center(s) - c).norm() - r);
      EXPECT_LE(dist, s * kSqrt3Over2 + 1e-12) << key.x << "," << key.y << "," << key.z;
    }
    // (b) Dense random surface samples (about 60 per voxel) all fall in the set.
    const int samples = 60 * static_cast<int>(gt.voxels.size());
    for (int i = 0; i < samples; ++i) {
      const VoxelKey key = VoxelKey::FromPoint(c + r * RandomUnitVector(rng), s);
      ASSERT_TRUE(gt.voxels.count(key))
          << "sample " << i << " key " << key.x << "," << key.y << "," << key.z;
    }
    // (c) Count against the surface-area expectation: a surface element with unit normal n
    // crosses (|n_x| + |n_y| + |n_z|) / s^2 cells per unit area on average over grid offsets,
    // 3/2 averaged over the sphere, so E[N] = 1.5 * 4 pi r^2 / s^2 = 6 pi r^2 / s^2 (curvature
    // terms are small: measured means over 40 offsets are 1.007, 1.005, 1.003, 1.001 times this
    // for r / s = 3, 5, 6, 10; single offsets stay within 0.96 ... 1.06 for r / s >= 3).
    const double expected = 6.0 * M_PI * r * r / (s * s);
    EXPECT_GT(gt.voxels.size(), 0.95 * expected) << "r=" << r;
    EXPECT_LT(gt.voxels.size(), 1.06 * expected) << "r=" << r;
  }
}

TEST(GroundTruthTest, MeanSurfaceVoxelCountOverGridOffsetsIsSixPiRSquaredOverSSquared) {
  const double s = 0.005;
  const double r = 4 * s;
  Rng rng(5);
  double sum = 0;
  const int n = 24;
  for (int i = 0; i < n; ++i) {
    Scene scene;
    scene.Add(
        SphereFruit(Eigen::Vector3d(rng.Uniform(0, 1), rng.Uniform(0, 1), rng.Uniform(0, 1)), r));
    sum += VoxelizeFruitSurfaces(scene, s).voxels.size();
  }
  const double expected = 6.0 * M_PI * r * r / (s * s);  // 301.6
  EXPECT_NEAR(sum / n, expected, 0.02 * expected);
}

TEST(GroundTruthTest, EllipsoidMatchesABruteForceSignChangeReference) {
  // A rotated ellipsoid; reference: sign changes of the implicit function on a 7x7x7 sample grid
  // inside each cube. The reference can only miss thin crossings, never invent one, so it must be
  // a subset of our set, and the extra voxels must sit within the half diagonal of the surface.
  const double s = 0.005;
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(0.8, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  const SceneObject object = Fruit(Eigen::Vector3d(0.101, -0.052, 0.333), {0.035, 0.025, 0.02}, R);
  const Ellipsoid& e = std::get<Ellipsoid>(object.shape);
  Scene scene;
  scene.Add(object);
  const FruitVoxels gt = VoxelizeFruitSurfaces(scene, s);

  const Box3 box = e.Bounds();
  const VoxelKey lo = VoxelKey::FromPoint(box.min(), s);
  const VoxelKey hi = VoxelKey::FromPoint(box.max(), s);
  size_t reference_count = 0;
  for (int z = lo.z - 1; z <= hi.z + 1; ++z) {
    for (int y = lo.y - 1; y <= hi.y + 1; ++y) {
      for (int x = lo.x - 1; x <= hi.x + 1; ++x) {
        bool neg = false;
        bool pos = false;
        for (int k = 0; k < 343; ++k) {
          const Eigen::Vector3d p =
              Eigen::Vector3d(x + (k % 7) / 6.0, y + (k / 7 % 7) / 6.0, z + (k / 49) / 6.0) * s;
          const double f = e.Implicit(p);
          neg |= f <= 0;
          pos |= f >= 0;
        }
        if (neg && pos) {
          ++reference_count;
          EXPECT_TRUE(gt.voxels.count({x, y, z})) << x << "," << y << "," << z;
        }
      }
    }
  }
  EXPECT_GE(gt.voxels.size(), reference_count);
  EXPECT_LE(gt.voxels.size(), reference_count + reference_count / 20) << "only thin crossings";
  // Every voxel in the set touches the surface: sampling its cube finely (or, for a thin
  // crossing, the closest point of the unit-sphere image) finds f <= 0 somewhere.
  for (const auto& [key, id] : gt.voxels) {
    double fmin = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 1331; ++k) {
      const Eigen::Vector3d p =
          Eigen::Vector3d(key.x + (k % 11) / 10.0, key.y + (k / 11 % 11) / 10.0,
                          key.z + (k / 121) / 10.0) *
          s;
      fmin = std::min(fmin, e.Implicit(p));
    }
    // Within 0.1 voxel of touching: f grows by at most ~2 * 0.1 s / r_min near the surface.
    EXPECT_LT(fmin, 2.0 * 0.1 * s * kSqrt3Over2 / 0.02 + 1e-12);
  }
}

TEST(GroundTruthTest, ThinCrossingBetweenCornersIsFound) {
  // The top of a sphere pokes 0.01 voxel into voxel (0, 0, 0) through the middle of its bottom
  // face: all eight corners are outside, yet the surface passes through the voxel.
  const double s = 0.01;
  const double r = 0.05;
  Scene scene;
  scene.Add(SphereFruit(Eigen::Vector3d(0.5 * s, 0.5 * s, 0.01 * s - r), r));
  const FruitVoxels gt = VoxelizeFruitSurfaces(scene, s);
  EXPECT_TRUE(gt.voxels.count({0, 0, 0}));
  EXPECT_FALSE(gt.voxels.count({0, 0, 1}));
  // The same for an edge crossing: the sphere clips the voxel's lower x-y edge only.
  Scene edge_scene;
  const double d = 0.01 * s;  // penetration depth along the diagonal; corners stay outside
  const Eigen::Vector3d dir = Eigen::Vector3d(-1, -1, 0).normalized();
  edge_scene.Add(SphereFruit(Eigen::Vector3d(0, 0, 0.5 * s) + (r - d) * dir, r));
  EXPECT_TRUE(VoxelizeFruitSurfaces(edge_scene, s).voxels.count({0, 0, 0}));
}

TEST(GroundTruthTest, TriangulatedSphereGivesNearlyTheSameSet) {
  const double s = 0.006;
  const Eigen::Vector3d c(0.213, -0.118, 0.604);
  const double r = 0.032;
  Scene analytic;
  analytic.Add(SphereFruit(c, r));
  Scene meshed;
  SceneObject mesh_fruit;
  mesh_fruit.name = "mesh-fruit";
  mesh_fruit.semantic_class = SemanticClass::kFruit;
  mesh_fruit.shape = Icosphere(c, r, 4);  // 5120 triangles, max sagitta ~0.03 mm
  meshed.Add(mesh_fruit);
  const FruitVoxels a = VoxelizeFruitSurfaces(analytic, s);
  const FruitVoxels m = VoxelizeFruitSurfaces(meshed, s);
  const double iou = IoU(a, m);
  EXPECT_GT(iou, 0.9);
  EXPECT_GT(iou, 0.97) << "measured 0.99: only voxels the surface barely touches differ";
  // Every mesh voxel lies within the half diagonal (+ the mesh's float/sagitta error).
  for (const auto& [key, id] : m.voxels) {
    EXPECT_LE(std::abs((key.Center(s) - c).norm() - r), s * kSqrt3Over2 + 1e-4);
  }
}

TEST(GroundTruthTest, LargeTriangleCoversTheVoxelsItCrosses) {
  // One big triangle in the plane z = 0.5 s: exactly the voxels of layer 0 whose square meets
  // the triangle x >= 0, y >= 0, x + y <= L are found, though none contains a vertex.
  const double s = 0.01;
  const double L = 0.1;
  Scene scene;
  SceneObject o;
  o.name = "flat-fruit";
  o.semantic_class = SemanticClass::kFruit;
  TriangleMesh mesh;
  mesh.vertices = {Eigen::Vector3f(0.0f, 0.0f, 0.5f * s), Eigen::Vector3f(L, 0.0f, 0.5f * s),
                   Eigen::Vector3f(0.0f, L, 0.5f * s)};
  mesh.triangles = {Eigen::Vector3i(0, 1, 2)};
  o.shape = mesh;
  scene.Add(o);
  const FruitVoxels gt = VoxelizeFruitSurfaces(scene, s);
  for (int y = -2; y < 12; ++y) {
    for (int x = -2; x < 12; ++x) {
      // The closed square [x s, (x+1) s] x [y s, (y+1) s] meets the triangle iff x, y >= -1 and
      // its lower-left corner satisfies x s + y s <= L (up to float rounding of the vertices).
      const bool expected = x >= 0 && y >= 0 && (x + y) * s < L - 1e-6;
      const bool clear_miss = x < -1 || y < -1 || (x + y) * s > L + 1e-6;
      if (expected) {
        EXPECT_TRUE(gt.voxels.count({x, y, 0})) << x << "," << y;
      }
      if (clear_miss) {
        EXPECT_FALSE(gt.voxels.count({x, y, 0})) << x << "," << y;
      }
    }
  }
  for (const auto& [key, id] : gt.voxels) EXPECT_EQ(key.z, 0);
}

TEST(GroundTruthTest, InstanceIdsOfTwoFruits) {
  const double s = 0.005;
  Scene scene;
  // A leaf (not a fruit) must be ignored.
  const SceneObject leaf = Ball("leaf", SemanticClass::kLeaf, Eigen::Vector3d(0.5, 0.5, 0.5));
  scene.Add(leaf);
  const Eigen::Vector3d ca(0.0, 0.0, 0.3);
  const Eigen::Vector3d cb(0.0595, 0.0, 0.3);  // touching within a voxel: they share voxels
  const uint16_t a = scene.Add(SphereFruit(ca, 0.03));
  const uint16_t b = scene.Add(SphereFruit(cb, 0.03));
  const FruitVoxels gt = VoxelizeFruitSurfaces(scene, s);

  Scene only_a;
  only_a.Add(SphereFruit(ca, 0.03));
  Scene only_b;
  only_b.Add(SphereFruit(cb, 0.03));
  const FruitVoxels ga = VoxelizeFruitSurfaces(only_a, s);
  const FruitVoxels gb = VoxelizeFruitSurfaces(only_b, s);
  size_t shared = 0;
  for (const auto& [key, id] : gt.voxels) {
    const bool in_a = ga.voxels.count(key);
    const bool in_b = gb.voxels.count(key);
    ASSERT_TRUE(in_a || in_b);
    if (in_a && in_b) {
      ++shared;
      EXPECT_EQ(id, std::min(a, b));
    } else {
      EXPECT_EQ(id, in_a ? a : b);
    }
  }
  EXPECT_EQ(gt.voxels.size(), ga.voxels.size() + gb.voxels.size() - shared);
  EXPECT_GT(shared, 0u);
  // Sorted keys are ascending and complete.
  const std::vector<VoxelKey> keys = gt.SortedKeys();
  EXPECT_EQ(keys.size(), gt.voxels.size());
  EXPECT_TRUE(std::is_sorted(keys.begin(), keys.end()));
  // No fruit: no voxels.
  Scene no_fruit;
  no_fruit.Add(leaf);
  EXPECT_TRUE(VoxelizeFruitSurfaces(no_fruit, s).voxels.empty());
}

TEST(GroundTruthTest, ObstacleSurfacesAreEverySolidObjectButTheGround) {
  const double s = 0.005;
  Scene scene;
  SceneObject leaf = Ball("leaf", SemanticClass::kLeaf, Eigen::Vector3d(0.5, 0.5, 0.5));
  scene.Add(leaf);
  scene.Add(SphereFruit(Eigen::Vector3d(0.0, 0.0, 0.3), 0.03));
  scene.Add(Ball("ground", SemanticClass::kGround, Eigen::Vector3d(-0.5, 0.0, 0.0)));
  scene.Add(Ball("sky", SemanticClass::kBackground, Eigen::Vector3d(-0.5, 0.0, 0.0)));

  const std::vector<VoxelKey> keys = VoxelizeObstacleSurfaces(scene, s);
  EXPECT_TRUE(std::is_sorted(keys.begin(), keys.end()));
  EXPECT_EQ(std::adjacent_find(keys.begin(), keys.end()), keys.end());
  // Exactly the leaf's and the fruit's surface voxels, neither the ground nor the background.
  Scene only_leaf;
  only_leaf.Add(leaf);
  Scene leaf_as_fruit;
  leaf.semantic_class = SemanticClass::kFruit;
  leaf_as_fruit.Add(leaf);
  const FruitVoxels fruit = VoxelizeFruitSurfaces(scene, s);
  const FruitVoxels leaf_voxels = VoxelizeFruitSurfaces(leaf_as_fruit, s);
  std::unordered_set<VoxelKey, VoxelKeyHash> expected;
  for (const auto& [key, id] : fruit.voxels) expected.insert(key);
  for (const auto& [key, id] : leaf_voxels.voxels) expected.insert(key);
  using KeySet = std::unordered_set<VoxelKey, VoxelKeyHash>;
  EXPECT_EQ(KeySet(keys.begin(), keys.end()), expected);
  EXPECT_EQ(VoxelizeObstacleSurfaces(only_leaf, s).size(), leaf_voxels.voxels.size());
  EXPECT_THAT([&] { (void)VoxelizeObstacleSurfaces(scene, 0.0); },
              ::testing::ThrowsMessage<Error>(HasSubstr("voxel_size_m = 0")));
}

TEST(GroundTruthTest, BadInputThrowsNamingTheValue) {
  Scene scene;
  scene.Add(SphereFruit(Eigen::Vector3d(0, 0, 0.3), 0.03));
  EXPECT_THAT([&] { (void)VoxelizeFruitSurfaces(scene, -0.01); },
              ::testing::ThrowsMessage<Error>(HasSubstr("voxel_size_m = -0.01")));
  EXPECT_THROW((void)VoxelizeFruitSurfaces(scene, std::nan("")), Error);
  // An absurdly fine grid is refused instead of running for hours.
  EXPECT_THAT([&] { (void)VoxelizeFruitSurfaces(scene, 1e-7); },
              ::testing::ThrowsMessage<Error>(HasSubstr("count")));
  Scene sheared = scene;
  std::get<Ellipsoid>(sheared.objects[0].shape).R_WE(2, 0) = 0.3;
  EXPECT_THAT([&] { (void)VoxelizeFruitSurfaces(sheared, 0.005); },
              ::testing::ThrowsMessage<Error>(HasSubstr("IsRotationMatrix")));
  Scene bad = scene;
  std::get<Ellipsoid>(bad.objects[0].shape).radii.x() = 0.0;
  EXPECT_THAT([&] { (void)VoxelizeFruitSurfaces(bad, 0.005); },
              ::testing::ThrowsMessage<Error>(HasSubstr("radii > 0")));
}

}  // namespace
}  // namespace avp::sim

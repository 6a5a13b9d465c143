// GainGrid: At() against the slow ReadGainVoxel on random maps (inside and outside the grid's box),
// every brick size against the default, Walk() against TraverseRay, WalkSkippingFree() against
// Walk(), the near-target ball at its boundary, quantisation, the size guard,
// empty maps, and RayDirections.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/rng.h>
#include <avp/mapping/ray_traversal.h>
#include <avp/planning/gain_grid.h>

namespace avp::planning {
namespace {

using mapping::VoxelState;
using ::testing::HasSubstr;

mapping::SemanticMap MakeMap(double voxel_size_m) {
  mapping::MapOptions options;
  options.grid.voxel_size_m = voxel_size_m;
  return mapping::SemanticMap(options);
}

/// A 30^3 region with ~35 % known voxels (3 % of them occupied), labels with random
/// confidences (fruit, leaf, stem) on some known voxels and on a few unknown ones, and a fruit
/// voxel with confidence exactly 0 and one with exactly 1.
mapping::SemanticMap RandomMap(uint64_t seed, double voxel_size_m) {
  mapping::SemanticMap map = MakeMap(voxel_size_m);
  mapping::OccupancyGrid& grid = map.grid();
  Rng rng(seed);
  auto label = [&](const VoxelKey& k) {
    mapping::SemanticCell* c = grid.MutableSemantic(k);
    const double u = rng.Uniform01();
    const SemanticClass cls = u < 0.5    ? SemanticClass::kFruit
                              : u < 0.75 ? SemanticClass::kLeaf
                                         : SemanticClass::kStem;
    c->semantic_class = static_cast<uint8_t>(cls);
    c->confidence = static_cast<float>(rng.Uniform01());
  };
  for (int32_t z = -12; z < 18; ++z) {
    for (int32_t y = -15; y < 15; ++y) {
      for (int32_t x = -9; x < 21; ++x) {
        const VoxelKey k{x, y, z};
        if (rng.Bernoulli(0.35)) {
          const bool occupied = rng.Bernoulli(0.03);
          const float v = occupied ? static_cast<float>(rng.Uniform(0.0, 3.4))
                                   : static_cast<float>(rng.Uniform(-1.9, -0.01));
          EXPECT_TRUE(grid.SetLogOdds(k, v));
          if (rng.Bernoulli(0.2)) label(k);
        } else if (rng.Bernoulli(0.01)) {
          label(k);  // payload without occupancy
        }
      }
    }
  }
  grid.MutableSemantic({30, 0, 0})->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
  grid.MutableSemantic({30, 0, 0})->confidence = 0.0f;
  EXPECT_TRUE(grid.SetLogOdds({-20, 3, 4}, 3.4f));
  grid.MutableSemantic({-20, 3, 4})->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
  grid.MutableSemantic({-20, 3, 4})->confidence = 1.0f;
  return map;
}

std::string Describe(const GainVoxel& v) {
  return "state " + std::to_string(static_cast<int>(v.state)) + ", class " +
         std::to_string(static_cast<int>(v.cls)) + ", p_occ " + std::to_string(v.p_occ) +
         ", p_target " + std::to_string(v.p_target) + ", near " + std::to_string(v.near_target) +
         ", in_roi " + std::to_string(v.in_roi);
}

bool Same(const GainVoxel& a, const GainVoxel& b) {
  return a.state == b.state && a.cls == b.cls && a.p_occ == b.p_occ && a.p_target == b.p_target &&
         a.near_target == b.near_target && a.in_roi == b.in_roi;
}

TEST(GainGridTest, QuantizeProbabilityRoundsToMultiplesOf1Over255) {
  EXPECT_EQ(QuantizeProbability(0.0), 0.0f);
  EXPECT_EQ(QuantizeProbability(1.0), 1.0f);
  EXPECT_EQ(QuantizeProbability(-0.3), 0.0f);
  EXPECT_EQ(QuantizeProbability(1.7), 1.0f);
  EXPECT_EQ(QuantizeProbability(std::nan("")), 0.0f);
  EXPECT_EQ(QuantizeProbability(0.5), 128.0f / 255.0f);   // 127.5 rounds up
  EXPECT_EQ(QuantizeProbability(0.7), 179.0f / 255.0f);   // 178.5 rounds up
  EXPECT_EQ(QuantizeProbability(0.12), 31.0f / 255.0f);   // 30.6
  EXPECT_EQ(QuantizeProbability(0.97), 247.0f / 255.0f);  // 247.35
  for (int b = 0; b <= 255; ++b) EXPECT_EQ(QuantizeProbability(b / 255.0), b / 255.0f) << b;
}

TEST(GainGridTest, ReadGainVoxelReadsTheMap) {
  mapping::SemanticMap map = MakeMap(0.005);
  ASSERT_TRUE(map.grid().SetLogOdds({0, 0, 0}, 2.0f));
  ASSERT_TRUE(map.grid().SetLogOdds({1, 0, 0}, -0.4f));
  mapping::SemanticCell* c = map.grid().MutableSemantic({0, 0, 0});
  c->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
  c->confidence = 0.6f;
  map.grid().MutableSemantic({1, 0, 0})->semantic_class =
      static_cast<uint8_t>(SemanticClass::kLeaf);
  const Box3 roi(Eigen::Vector3d(0.0, 0.0, 0.0), Eigen::Vector3d(0.004, 0.01, 0.01));

  const GainVoxel a = ReadGainVoxel(map, {0, 0, 0}, SemanticClass::kFruit, roi, 0.005);
  EXPECT_EQ(a.state, VoxelState::kOccupied);
  EXPECT_EQ(a.cls, SemanticClass::kFruit);
  EXPECT_EQ(a.p_occ, QuantizeProbability(1.0 - 1.0 / (1.0 + std::exp(2.0))));  // 0.8808 -> 225
  EXPECT_EQ(a.p_occ, 225.0f / 255.0f);
  EXPECT_EQ(a.p_target, 153.0f / 255.0f);  // 0.6 * 255 = 153
  EXPECT_TRUE(a.near_target);
  EXPECT_TRUE(a.in_roi);

  const GainVoxel b = ReadGainVoxel(map, {1, 0, 0}, SemanticClass::kFruit, roi, 0.005);
  EXPECT_EQ(b.state, VoxelState::kFree);
  EXPECT_EQ(b.cls, SemanticClass::kLeaf);
  EXPECT_EQ(b.p_occ, 102.0f / 255.0f);  // sigmoid(-0.4) = 0.40131 -> 102.33
  EXPECT_EQ(b.p_target, 0.0f);          // labelled, but not with the target class
  EXPECT_TRUE(b.near_target);           // 1 voxel = 5 mm from the fruit voxel
  EXPECT_FALSE(b.in_roi);               // centre x = 7.5 mm > 4 mm

  // With the leaf as target, the fruit voxel has no target probability.
  const GainVoxel a_leaf = ReadGainVoxel(map, {0, 0, 0}, SemanticClass::kLeaf, roi, 0.0);
  EXPECT_EQ(a_leaf.p_target, 0.0f);
  EXPECT_FALSE(a_leaf.near_target);

  const GainVoxel u = ReadGainVoxel(map, {2, 0, 0}, SemanticClass::kFruit, roi, 0.005);
  EXPECT_EQ(u.state, VoxelState::kUnknown);
  EXPECT_EQ(u.cls, SemanticClass::kBackground);
  EXPECT_EQ(u.p_occ, 0.5f);     // unknown voxels read 0.5 exactly (not 128/255)
  EXPECT_FALSE(u.near_target);  // 2 voxels away
  EXPECT_THROW(ReadGainVoxel(map, {0, 0, 0}, SemanticClass::kFruit, roi, -1.0), Error);
}

void ExpectAtEqualsReadGainVoxel(const mapping::SemanticMap& map, SemanticClass target,
                                 const Box3& roi, double radius_m, uint64_t seed) {
  GainGridOptions options;
  options.near_target_radius_m = radius_m;
  const auto grid = GainGrid::Build(map, target, roi, options);
  ASSERT_TRUE(grid.ok()) << grid.status().ToString();
  EXPECT_EQ(grid->voxel_size_m(), map.voxel_size_m());
  EXPECT_EQ(grid->target(), target);
  size_t near = 0, in_roi = 0, labelled = 0, checked = 0;
  // Every key of the map's region and a margin beyond the grid's box on every side.
  for (int32_t z = -26; z < 32; ++z) {
    for (int32_t y = -26; y < 26; ++y) {
      for (int32_t x = -30; x < 40; ++x) {
        const VoxelKey k{x, y, z};
        const GainVoxel fast = grid->At(k);
        const GainVoxel slow = ReadGainVoxel(map, k, target, roi, radius_m);
        ASSERT_TRUE(Same(fast, slow)) << x << " " << y << " " << z << ": fast " << Describe(fast)
                                      << " / slow " << Describe(slow);
        near += fast.near_target;
        in_roi += fast.in_roi;
        labelled += fast.cls != SemanticClass::kBackground;
        ++checked;
      }
    }
  }
  EXPECT_GT(near, 1000u);
  if (roi.IsEmpty()) {
    EXPECT_EQ(in_roi, 0u);
  } else {
    EXPECT_GT(in_roi, 100u);
  }
  EXPECT_GT(labelled, 500u);
  // Far away keys (and extreme ones) read as unknown.
  Rng rng(seed);
  for (int i = 0; i < 2000; ++i) {
    const VoxelKey k{static_cast<int32_t>(rng.UniformInt(-8000000, 8000000)),
                     static_cast<int32_t>(rng.UniformInt(-8000000, 8000000)),
                     static_cast<int32_t>(rng.UniformInt(-8000000, 8000000))};
    ASSERT_TRUE(Same(grid->At(k), ReadGainVoxel(map, k, target, roi, radius_m)));
    EXPECT_EQ(grid->At(k).state, VoxelState::kUnknown);
  }
  EXPECT_GT(checked, 100000u);
}

TEST(GainGridTest, AtEqualsReadGainVoxelOnRandomMaps) {
  const mapping::SemanticMap map = RandomMap(1, 0.005);
  const Box3 roi(Eigen::Vector3d(-0.03, -0.04, -0.02), Eigen::Vector3d(0.06, 0.05, 0.07));
  ExpectAtEqualsReadGainVoxel(map, SemanticClass::kFruit, roi, 0.015, 11);
}

TEST(GainGridTest, AtEqualsReadGainVoxelWithAnotherVoxelSizeTargetAndRadius) {
  const mapping::SemanticMap map = RandomMap(2, 0.004);
  const Box3 roi(Eigen::Vector3d(-0.011, -0.033, 0.0), Eigen::Vector3d(0.04, 0.02, 0.03));
  ExpectAtEqualsReadGainVoxel(map, SemanticClass::kLeaf, roi, 0.0101, 12);
  ExpectAtEqualsReadGainVoxel(map, SemanticClass::kFruit, Box3(), 0.0, 13);  // empty ROI
}

TEST(GainGridTest, NearTargetBallIsExactAtItsBoundary) {
  mapping::SemanticMap map = MakeMap(0.005);
  map.grid().MutableSemantic({0, 0, 0})->semantic_class =
      static_cast<uint8_t>(SemanticClass::kFruit);
  GainGridOptions options;
  options.near_target_radius_m = 0.04;  // exactly 8 voxels: 0.04 / 0.005 is not exactly 8.0
  const auto grid = GainGrid::Build(map, SemanticClass::kFruit, Box3(), options);
  ASSERT_TRUE(grid.ok()) << grid.status().ToString();
  EXPECT_TRUE(grid->At({8, 0, 0}).near_target);
  EXPECT_TRUE(grid->At({-8, 0, 0}).near_target);
  EXPECT_TRUE(grid->At({0, 0, -8}).near_target);
  EXPECT_FALSE(grid->At({9, 0, 0}).near_target);
  EXPECT_FALSE(grid->At({0, -9, 0}).near_target);
  EXPECT_TRUE(grid->At({4, 4, 4}).near_target);   // 48 <= 64
  EXPECT_FALSE(grid->At({5, 5, 4}).near_target);  // 66 > 64
  EXPECT_TRUE(grid->At({0, 0, 0}).near_target);   // the labelled voxel itself
  EXPECT_FALSE(grid->At({6, 5, 2}).near_target);  // 65
  EXPECT_TRUE(grid->At({6, 5, 1}).near_target);   // 62
  // Count: the integer points of the ball of radius 8 (x^2 + y^2 + z^2 <= 64) is 2109.
  int count = 0;
  for (int z = -10; z <= 10; ++z) {
    for (int y = -10; y <= 10; ++y) {
      for (int x = -10; x <= 10; ++x) count += grid->At({x, y, z}).near_target;
    }
  }
  EXPECT_EQ(count, 2109);
  // The slow read agrees on the boundary.
  EXPECT_TRUE(ReadGainVoxel(map, {8, 0, 0}, SemanticClass::kFruit, Box3(), 0.04).near_target);
  EXPECT_FALSE(ReadGainVoxel(map, {9, 0, 0}, SemanticClass::kFruit, Box3(), 0.04).near_target);
  // A label-only voxel (unknown occupancy) is unknown but labelled.
  EXPECT_EQ(grid->At({0, 0, 0}).state, VoxelState::kUnknown);
  EXPECT_EQ(grid->At({0, 0, 0}).cls, SemanticClass::kFruit);
  EXPECT_EQ(grid->At({0, 0, 0}).p_occ, 0.5f);
  // Radius 0: only the labelled voxel itself.
  options.near_target_radius_m = 0.0;
  const auto tight = GainGrid::Build(map, SemanticClass::kFruit, Box3(), options);
  ASSERT_TRUE(tight.ok());
  EXPECT_TRUE(tight->At({0, 0, 0}).near_target);
  EXPECT_FALSE(tight->At({1, 0, 0}).near_target);
}

TEST(GainGridTest, EmptyMapReadsUnknownEverywhere) {
  const mapping::SemanticMap map = MakeMap(0.005);
  const Box3 roi(Eigen::Vector3d::Zero(), Eigen::Vector3d::Constant(0.1));
  const auto grid = GainGrid::Build(map, SemanticClass::kFruit, roi);
  ASSERT_TRUE(grid.ok()) << grid.status().ToString();
  const GainVoxel v = grid->At({3, 3, 3});
  EXPECT_EQ(v.state, VoxelState::kUnknown);
  EXPECT_EQ(v.cls, SemanticClass::kBackground);
  EXPECT_EQ(v.p_occ, 0.5f);
  EXPECT_EQ(v.p_target, 0.0f);
  EXPECT_FALSE(v.near_target);
  EXPECT_TRUE(v.in_roi);
  EXPECT_FALSE(grid->At({-1, 3, 3}).in_roi);
  int visited = 0;
  EXPECT_EQ(grid->Walk(Eigen::Vector3d(0.001, 0.001, 0.001), Eigen::Vector3d(0.0501, 0.001, 0.001),
                       [&](const VoxelKey&, const GainVoxel& g) {
                         visited += g.state == VoxelState::kUnknown;
                         return true;
                       }),
            10);
  EXPECT_EQ(visited, 10);
}

TEST(GainGridTest, RefusesGridsLargerThanMaxBytesAndBadOptions) {
  mapping::SemanticMap map = MakeMap(0.005);
  ASSERT_TRUE(map.grid().SetLogOdds({0, 0, 0}, 1.0f));
  ASSERT_TRUE(map.grid().SetLogOdds({99, 49, 9}, 1.0f));  // 100 x 50 x 10 voxels = 200 kB
  GainGridOptions options;
  options.near_target_radius_m = 0.0;
  options.max_bytes = 200000;
  EXPECT_TRUE(GainGrid::Build(map, SemanticClass::kFruit, Box3(), options).ok());
  options.max_bytes = 199999;
  const auto refused = GainGrid::Build(map, SemanticClass::kFruit, Box3(), options);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.status().message(), HasSubstr("100 x 50 x 10 voxels"));
  EXPECT_THAT(refused.status().message(), HasSubstr("max_bytes"));
  // The radius inflates the box: 1 voxel on each side -> 102 x 52 x 12.
  options.max_bytes = size_t{1} << 30;
  options.near_target_radius_m = 0.005;
  options.max_bytes = 254000;
  const auto inflated = GainGrid::Build(map, SemanticClass::kFruit, Box3(), options);
  ASSERT_FALSE(inflated.ok());
  EXPECT_THAT(inflated.status().message(), HasSubstr("102 x 52 x 12 voxels"));
  options.max_bytes = 254592;
  EXPECT_TRUE(GainGrid::Build(map, SemanticClass::kFruit, Box3(), options).ok());

  options.near_target_radius_m = -0.01;
  const auto bad = GainGrid::Build(map, SemanticClass::kFruit, Box3(), options);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("near_target_radius_m (-0.01)"));
  options.near_target_radius_m = std::nan("");
  EXPECT_FALSE(GainGrid::Build(map, SemanticClass::kFruit, Box3(), options).ok());
}

TEST(GainGridTest, WalkVisitsTraverseRayKeysWithoutTheEndVoxel) {
  const mapping::SemanticMap map = RandomMap(3, 0.005);
  const Box3 roi(Eigen::Vector3d(-0.03, -0.04, -0.02), Eigen::Vector3d(0.06, 0.05, 0.07));
  const auto grid = GainGrid::Build(map, SemanticClass::kFruit, roi);
  ASSERT_TRUE(grid.ok());
  Rng rng(4);
  int64_t total = 0;
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d from(rng.Uniform(-0.15, 0.2), rng.Uniform(-0.15, 0.15),
                               rng.Uniform(-0.15, 0.2));
    Eigen::Vector3d to(rng.Uniform(-0.15, 0.2), rng.Uniform(-0.15, 0.15), rng.Uniform(-0.15, 0.2));
    if (i % 10 == 0) to = (VoxelKey::FromPoint(to, 0.005).Center(0.005).array() + 0.0025).matrix();
    std::vector<VoxelKey> expected;
    mapping::TraverseRay(from, to, 0.005, [&](const VoxelKey& k) {
      expected.push_back(k);
      return true;
    });
    ASSERT_FALSE(expected.empty());
    expected.pop_back();
    std::vector<VoxelKey> walked;
    const int64_t n = grid->Walk(from, to, [&](const VoxelKey& k, const GainVoxel& v) {
      walked.push_back(k);
      EXPECT_TRUE(Same(v, grid->At(k)));
      return true;
    });
    ASSERT_EQ(walked, expected) << "ray " << i;
    ASSERT_EQ(n, static_cast<int64_t>(expected.size()));
    total += n;
    // Stopping early: the visitor's false ends the walk after that voxel.
    if (expected.size() > 3) {
      int calls = 0;
      EXPECT_EQ(
          grid->Walk(from, to, [&](const VoxelKey&, const GainVoxel&) { return ++calls < 3; }), 3);
    }
  }
  EXPECT_GT(total, 100000);
  // A segment inside one voxel visits nothing.
  EXPECT_EQ(grid->Walk(Eigen::Vector3d(0.001, 0.001, 0.001), Eigen::Vector3d(0.002, 0.003, 0.004),
                       [](const VoxelKey&, const GainVoxel&) { return true; }),
            0);
}

TEST(GainGridTest, EveryBrickSizeReadsTheSame) {
  // The default 8^3 bricks are checked against ReadGainVoxel above; the other layouts (dense,
  // 2^3, 4^3, 16^3) must read the same on every key of the box and a margin around it, with
  // dims that are no multiple of the brick edge and negative keys.
  const mapping::SemanticMap map = RandomMap(6, 0.005);
  const Box3 roi(Eigen::Vector3d(-0.03, -0.04, -0.02), Eigen::Vector3d(0.06, 0.05, 0.07));
  const auto ref = GainGrid::Build(map, SemanticClass::kFruit, roi);
  ASSERT_TRUE(ref.ok());
  EXPECT_EQ(ref->brick_edge(), 8);
  EXPECT_LT(ref->min_key().x, 0);
  EXPECT_NE(ref->dims().x() % 8, 0);
  EXPECT_NE(ref->dims().y() % 8, 0);
  for (int shift : {0, 1, 2, 4}) {
    GainGridOptions options;
    options.brick_shift = shift;
    const auto grid = GainGrid::Build(map, SemanticClass::kFruit, roi, options);
    ASSERT_TRUE(grid.ok()) << shift;
    EXPECT_EQ(grid->brick_edge(), 1 << shift);
    EXPECT_EQ(grid->dims(), ref->dims());
    EXPECT_EQ(grid->min_key(), ref->min_key());
    const VoxelKey lo = ref->min_key();
    const Eigen::Vector3i n = ref->dims();
    for (int32_t z = lo.z - 3; z < lo.z + n.z() + 3; ++z) {
      for (int32_t y = lo.y - 3; y < lo.y + n.y() + 3; ++y) {
        for (int32_t x = lo.x - 3; x < lo.x + n.x() + 3; ++x) {
          ASSERT_TRUE(Same(grid->At({x, y, z}), ref->At({x, y, z})))
              << shift << ": " << x << " " << y << " " << z;
        }
      }
    }
    EXPECT_LE(grid->free_bricks(), grid->bricks());
    if (shift == 0) {
      EXPECT_EQ(grid->free_bricks(), 0u);  // no flags in the dense layout
    }
  }
  GainGridOptions bad;
  bad.brick_shift = 5;
  EXPECT_FALSE(GainGrid::Build(map, SemanticClass::kFruit, roi, bad).ok());
  bad.brick_shift = -1;
  EXPECT_FALSE(GainGrid::Build(map, SemanticClass::kFruit, roi, bad).ok());
}

/// Mostly free space over 75 x 70 x 66 voxels (0.375 x 0.35 x 0.33 m, negative keys included):
/// three occupied fruit-labelled balls, an unknown slab, unknown holes and scattered occupied
/// voxels, so that some bricks are all free and others not.
mapping::SemanticMap SparseMap(uint64_t seed) {
  mapping::SemanticMap map = MakeMap(0.005);
  mapping::OccupancyGrid& grid = map.grid();
  Rng rng(seed);
  struct Ball {
    Eigen::Vector3d c;
    double r;
  };
  std::vector<Ball> balls;
  for (int i = 0; i < 3; ++i) {
    balls.push_back(
        {Eigen::Vector3d(rng.Uniform(-20, 40), rng.Uniform(-25, 30), rng.Uniform(-10, 40)),
         rng.Uniform(3.0, 7.0)});
  }
  for (int32_t z = -13; z < 53; ++z) {
    for (int32_t y = -31; y < 39; ++y) {
      for (int32_t x = -27; x < 48; ++x) {
        const VoxelKey k{x, y, z};
        const Eigen::Vector3d p(x, y, z);
        bool ball = false;
        for (const Ball& b : balls) ball = ball || (p - b.c).norm() <= b.r;
        if (ball) {
          EXPECT_TRUE(grid.SetLogOdds(k, static_cast<float>(rng.Uniform(0.5, 3.0))));
          mapping::SemanticCell* c = grid.MutableSemantic(k);
          c->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
          c->confidence = static_cast<float>(rng.Uniform01());
        } else if ((z >= 20 && z < 23) || rng.Bernoulli(0.0002)) {
          continue;  // unknown
        } else if (rng.Bernoulli(0.0001)) {
          EXPECT_TRUE(grid.SetLogOdds(k, 1.0f));
        } else {
          EXPECT_TRUE(grid.SetLogOdds(k, static_cast<float>(rng.Uniform(-2.0, -0.1))));
        }
      }
    }
  }
  return map;
}

TEST(GainGridTest, WalkSkippingFreeVisitsEveryNonFreeVoxelOfWalkInOrder) {
  const mapping::SemanticMap map = SparseMap(7);
  const Box3 roi(Eigen::Vector3d(-0.1, -0.12, -0.05), Eigen::Vector3d(0.2, 0.15, 0.2));
  for (int shift : {3, 2, 4}) {
    GainGridOptions options;
    options.brick_shift = shift;
    options.skip_free_bricks = true;
    const auto grid = GainGrid::Build(map, SemanticClass::kFruit, roi, options);
    ASSERT_TRUE(grid.ok());
    // The box's 8-voxel unknown margin and the slab leave few whole free bricks of 16^3.
    ASSERT_GT(grid->free_bricks(), shift == 4 ? 3 : grid->bricks() / 10) << shift;
    ASSERT_LT(grid->free_bricks(), grid->bricks()) << shift;
    Rng rng(8 + static_cast<uint64_t>(shift));
    int64_t walked = 0, skipped = 0, stops = 0;
    for (int i = 0; i < 3000; ++i) {
      // End points inside, around and far outside the grid's box (-0.135 .. 0.265 m).
      auto point = [&]() -> Eigen::Vector3d {
        const double m = i % 3 == 0 ? 0.6 : 0.2;
        return Eigen::Vector3d(rng.Uniform(-m, m), rng.Uniform(-m, m), rng.Uniform(-m, m)) +
               Eigen::Vector3d(0.05, 0.02, 0.1);
      };
      const Eigen::Vector3d from = point();
      Eigen::Vector3d to = point();
      if (i % 10 == 0)
        to = (VoxelKey::FromPoint(to, 0.005).Center(0.005).array() + 0.0025).matrix();
      struct Visit {
        VoxelKey k;
        GainVoxel v;
      };
      std::vector<Visit> all, fast;
      const int64_t n_all = grid->Walk(from, to, [&](const VoxelKey& k, const GainVoxel& v) {
        all.push_back({k, v});
        return true;
      });
      const int64_t n_fast =
          grid->WalkSkippingFree(from, to, [&](const VoxelKey& k, const GainVoxel& v) {
            fast.push_back({k, v});
            EXPECT_TRUE(Same(v, grid->At(k)));
            return true;
          });
      ASSERT_EQ(n_fast, n_all) << "ray " << i;
      // `fast` is `all` without some free voxels: a subsequence, every omission free.
      size_t j = 0;
      for (const Visit& a : all) {
        if (j < fast.size() && fast[j].k == a.k) {
          ASSERT_TRUE(Same(fast[j].v, a.v));
          ++j;
        } else {
          ASSERT_EQ(a.v.state, VoxelState::kFree) << "ray " << i << ": skipped a non-free voxel";
          ++skipped;
        }
      }
      ASSERT_EQ(j, fast.size()) << "ray " << i << ": visits not in Walk's order";
      walked += n_all;
      // Stopping at the m-th non-free voxel: both stop there and return the same count.
      std::vector<size_t> non_free;
      for (size_t a = 0; a < all.size(); ++a) {
        if (all[a].v.state != VoxelState::kFree) non_free.push_back(a);
      }
      if (!non_free.empty()) {
        const size_t m =
            static_cast<size_t>(rng.UniformInt(0, static_cast<int64_t>(non_free.size()) - 1));
        auto stopper = [&](size_t* seen) {
          return [&, seen](const VoxelKey&, const GainVoxel& v) {
            return v.state == VoxelState::kFree || (*seen)++ < m;
          };
        };
        size_t seen_all = 0, seen_fast = 0;
        const int64_t s_all = grid->Walk(from, to, stopper(&seen_all));
        const int64_t s_fast = grid->WalkSkippingFree(from, to, stopper(&seen_fast));
        ASSERT_EQ(s_all, static_cast<int64_t>(non_free[m]) + 1) << "ray " << i;
        ASSERT_EQ(s_fast, s_all) << "ray " << i;
        ASSERT_EQ(seen_fast, m + 1);
        ++stops;
      }
    }
    EXPECT_GT(walked, 200000) << shift;
    EXPECT_GT(skipped, shift == 4 ? walked / 100 : walked / 5) << shift;
    std::printf("brick edge %d: %.1f %% of %lld walked voxels skipped\n", 1 << shift,
                100.0 * static_cast<double>(skipped) / static_cast<double>(walked),
                static_cast<long long>(walked));
    EXPECT_GT(stops, 1000) << shift;
  }
}

TEST(GainGridTest, WalkSkippingFreeIsWalkWithoutFreeBricks) {
  // Without flags (dense, or skipping off) it is Walk.
  const mapping::SemanticMap map = SparseMap(7);
  const Box3 roi(Eigen::Vector3d(-0.1, -0.12, -0.05), Eigen::Vector3d(0.2, 0.15, 0.2));
  for (const auto& [shift, skip] : {std::pair{0, true}, {3, false}}) {
    GainGridOptions options;
    options.brick_shift = shift;
    options.skip_free_bricks = skip;
    const auto grid = GainGrid::Build(map, SemanticClass::kFruit, roi, options);
    ASSERT_TRUE(grid.ok());
    EXPECT_EQ(grid->free_bricks(), 0u);
    const Eigen::Vector3d from(-0.3, 0.01, 0.02), to(0.4, 0.05, 0.11);
    std::vector<VoxelKey> a, b;
    grid->Walk(from, to, [&](const VoxelKey& k, const GainVoxel&) {
      a.push_back(k);
      return true;
    });
    grid->WalkSkippingFree(from, to, [&](const VoxelKey& k, const GainVoxel&) {
      b.push_back(k);
      return true;
    });
    EXPECT_EQ(a, b);
    EXPECT_GT(a.size(), 100u);
  }
}

TEST(GainGridTest, RayDirectionsCoverThePixelGrid) {
  const CameraIntrinsics K = CameraIntrinsics::FromHorizontalFov(65, 49, 60.0);
  const std::vector<Eigen::Vector3d> all = RayDirections(K, 1);
  ASSERT_EQ(all.size(), 65u * 49u);
  for (const Eigen::Vector3d& d : all) EXPECT_NEAR(d.norm(), 1.0, 1e-12);
  // Pixel (32, 24) is the principal point: straight along the optical axis.
  const Eigen::Vector3d& centre = all[24 * 65 + 32];
  EXPECT_NEAR(centre.x(), 0.0, 1e-15);
  EXPECT_NEAR(centre.y(), 0.0, 1e-15);
  EXPECT_NEAR(centre.z(), 1.0, 1e-15);
  // Row by row from the top-left pixel centre.
  const Eigen::Vector3d first = K.RayDirection(Eigen::Vector2d(0, 0)).normalized();
  EXPECT_TRUE(all[0].isApprox(first, 1e-15));
  EXPECT_LT(all[0].x(), 0.0);
  EXPECT_LT(all[0].y(), 0.0);
  EXPECT_TRUE(all[1].isApprox(K.RayDirection(Eigen::Vector2d(1, 0)).normalized(), 1e-15));
  EXPECT_TRUE(all[65].isApprox(K.RayDirection(Eigen::Vector2d(0, 1)).normalized(), 1e-15));
  // The corner ray makes the half-diagonal field-of-view angle with the axis.
  const double half_diag = std::atan(std::hypot(32.0, 24.0) / K.fx);
  EXPECT_NEAR(std::acos(all.back().z()), half_diag, 1e-12);

  // Stride 8: u = 4, 12, ..., 60 (8 columns), v = 4, 12, ..., 44 (6 rows).
  const std::vector<Eigen::Vector3d> sparse = RayDirections(K, 8);
  ASSERT_EQ(sparse.size(), 48u);
  EXPECT_TRUE(sparse[0].isApprox(K.RayDirection(Eigen::Vector2d(4, 4)).normalized(), 1e-15));
  EXPECT_TRUE(sparse[9].isApprox(K.RayDirection(Eigen::Vector2d(12, 12)).normalized(), 1e-15));
  EXPECT_TRUE(sparse[47].isApprox(K.RayDirection(Eigen::Vector2d(60, 44)).normalized(), 1e-15));
  // Stride 20 on the D435 model: u = 10, 30, ..., 630 (32), v = 10, ..., 470 (24).
  EXPECT_EQ(RayDirections(CameraIntrinsics::RealSenseD435(), 20).size(), 32u * 24u);
  EXPECT_THROW(RayDirections(K, 0), Error);
  CameraIntrinsics bad = K;
  bad.fx = -1.0;
  EXPECT_THROW(RayDirections(bad, 4), Error);
}

}  // namespace
}  // namespace avp::planning

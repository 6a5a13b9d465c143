// OccupancyGrid: options, key arithmetic, OctoMap-exact log-odds updates, ROI, iteration, change
// tracking, semantics payload, memory, the block hash table and the parallel update path.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::mapping {
namespace {

using ::testing::HasSubstr;

VoxelKey RandomKey(Rng& rng, int32_t range) {
  return {static_cast<int32_t>(rng.UniformInt(-range, range)),
          static_cast<int32_t>(rng.UniformInt(-range, range)),
          static_cast<int32_t>(rng.UniformInt(-range, range))};
}

// ---- Options -----------------------------------------------------------------------------------

TEST(GridOptionsTest, DefaultsAndLimitsAreValid) {
  EXPECT_TRUE(GridOptions{}.Validate().ok());
  GridOptions o;
  o.voxel_size_m = GridOptions::kMinVoxelSize;
  EXPECT_TRUE(o.Validate().ok());
  o.voxel_size_m = GridOptions::kMaxVoxelSize;
  EXPECT_TRUE(o.Validate().ok());
  o.roi = Box3(Eigen::Vector3d(-0.1, -0.2, 0.0), Eigen::Vector3d(0.3, 0.2, 0.9));
  EXPECT_TRUE(o.Validate().ok());
}

TEST(GridOptionsTest, ErrorsNameTheBadValue) {
  const auto message = [](const GridOptions& o) {
    const Status s = o.Validate();
    EXPECT_FALSE(s.ok());
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    return s.message();
  };
  GridOptions o;
  o.voxel_size_m = 0.001;
  EXPECT_THAT(message(o), HasSubstr("voxel_size_m (0.001 m)"));
  o.voxel_size_m = 0.025;
  EXPECT_THAT(message(o), HasSubstr("voxel_size_m (0.025 m)"));
  o.voxel_size_m = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(message(o), HasSubstr("voxel_size_m (nan)"));
  o.voxel_size_m = -0.005;
  EXPECT_THAT(message(o), HasSubstr("voxel_size_m (-0.005 m)"));

  GridOptions bad_sensor;
  bad_sensor.sensor.hit = 0.45;  // below the occupancy threshold
  EXPECT_THAT(message(bad_sensor), HasSubstr("hit (0.45)"));
  bad_sensor.sensor.hit = 0.7;
  bad_sensor.sensor.clamp_max = 1.5;
  EXPECT_THAT(message(bad_sensor), HasSubstr("clamp_max (1.5)"));

  // Every bad value at once.
  GridOptions both;
  both.voxel_size_m = 0.03;
  both.sensor.miss = 0.6;
  const std::string m = message(both);
  EXPECT_THAT(m, HasSubstr("voxel_size_m (0.03 m)"));
  EXPECT_THAT(m, HasSubstr("miss (0.6)"));

  GridOptions empty_roi;
  empty_roi.roi = Box3();
  EXPECT_THAT(message(empty_roi), HasSubstr("roi"));
}

TEST(GridOptionsTest, ConstructorThrowsOnInvalidOptions) {
  GridOptions o;
  o.voxel_size_m = 0.001;
  try {
    OccupancyGrid grid(o);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("0.001"));
  }
  o.voxel_size_m = 0.005;
  o.sensor.occupied_threshold = 0.99;
  EXPECT_THROW(OccupancyGrid{o}, Error);
}

TEST(GridOptionsTest, GridExposesTheSensorModelInFloatLogOdds) {
  OccupancyGrid grid;
  EXPECT_EQ(grid.voxel_size_m(), 0.005);
  EXPECT_EQ(grid.hit_log_odds(), LogOdds(0.7));
  EXPECT_EQ(grid.miss_log_odds(), LogOdds(0.4));
  EXPECT_EQ(grid.clamp_min_log_odds(), LogOdds(0.12));
  EXPECT_EQ(grid.clamp_max_log_odds(), LogOdds(0.97));
  EXPECT_EQ(grid.occupied_log_odds(), 0.0f);
  EXPECT_NEAR(grid.hit_log_odds(), 0.847298, 1e-6);
  EXPECT_NEAR(grid.miss_log_odds(), -0.405465, 1e-6);
  EXPECT_NEAR(grid.clamp_min_log_odds(), -1.992430, 1e-6);
  EXPECT_NEAR(grid.clamp_max_log_odds(), 3.476099, 1e-6);
  EXPECT_EQ(ToString(VoxelState::kUnknown), "unknown");
  EXPECT_EQ(ToString(VoxelState::kFree), "free");
  EXPECT_EQ(ToString(VoxelState::kOccupied), "occupied");
}

// ---- Keys --------------------------------------------------------------------------------------

TEST(BlockKeyTest, BlockAndLocalIndexRoundTripIncludingNegativeKeys) {
  EXPECT_EQ(BlockOf({0, 7, 8}), (BlockKey{0, 0, 1}));
  EXPECT_EQ(BlockOf({-1, -8, -9}), (BlockKey{-1, -1, -2}));
  EXPECT_EQ(LocalIndex({1, 2, 3}), 1 + 2 * 8 + 3 * 64);
  EXPECT_EQ(LocalIndex({-1, -1, -1}), 511);
  EXPECT_EQ(LocalIndex({-8, -16, 8}), 0);
  EXPECT_EQ(KeyOf(BlockKey{-1, 0, 2}, 511), (VoxelKey{-1, 7, 23}));
  EXPECT_EQ(KeyOf(BlockKey{-3, 5, -1}, 0), (VoxelKey{-24, 40, -8}));

  for (const BlockKey b : {BlockKey{0, 0, 0}, BlockKey{-1, -1, -1}, BlockKey{5, -7, 123},
                           BlockKey{-(1 << 20), (1 << 20) - 1, -12345}}) {
    for (int i = 0; i < kBlockVoxels; ++i) {
      const VoxelKey k = KeyOf(b, i);
      ASSERT_EQ(BlockOf(k), b) << i;
      ASSERT_EQ(LocalIndex(k), i);
    }
  }
  Rng rng(5);
  for (int n = 0; n < 20000; ++n) {
    const VoxelKey k = RandomKey(rng, kMaxKeyMagnitude - 1);
    const int i = LocalIndex(k);
    ASSERT_GE(i, 0);
    ASSERT_LT(i, kBlockVoxels);
    ASSERT_EQ(KeyOf(BlockOf(k), i), k);
    // Floor division on every axis.
    const BlockKey b = BlockOf(k);
    ASSERT_EQ(b.x, static_cast<int32_t>(std::floor(k.x / 8.0)));
    ASSERT_EQ(b.y, static_cast<int32_t>(std::floor(k.y / 8.0)));
    ASSERT_EQ(b.z, static_cast<int32_t>(std::floor(k.z / 8.0)));
  }
}

TEST(BlockKeyTest, KeyRangeAndBits) {
  EXPECT_TRUE(KeyInRange({kMaxKeyMagnitude - 1, -(kMaxKeyMagnitude - 1), 0}));
  EXPECT_FALSE(KeyInRange({kMaxKeyMagnitude, 0, 0}));
  EXPECT_FALSE(KeyInRange({0, -kMaxKeyMagnitude, 0}));
  BlockBits bits;
  EXPECT_FALSE(bits.any());
  bits.set(0);
  bits.set(63);
  bits.set(64);
  bits.set(511);
  EXPECT_EQ(bits.count(), 4);
  EXPECT_TRUE(bits.atomic_test_and_set(100));
  EXPECT_FALSE(bits.atomic_test_and_set(100));
  std::vector<int> set;
  bits.ForEachSet([&](int i) { set.push_back(i); });
  EXPECT_EQ(set, (std::vector<int>{0, 63, 64, 100, 511}));
  bits.reset(63);
  EXPECT_FALSE(bits.test(63));
  bits.clear();
  EXPECT_FALSE(bits.any());
}

// ---- Queries and updates -----------------------------------------------------------------------

TEST(OccupancyGridTest, EverythingIsUnknownByDefaultAndQueriesDoNotAllocate) {
  OccupancyGrid grid;
  Rng rng(1);
  for (int i = 0; i < 100; ++i) {
    const VoxelKey k = RandomKey(rng, 1000);
    EXPECT_EQ(grid.State(k), VoxelState::kUnknown);
    EXPECT_FALSE(grid.LogOdds(k).has_value());
    EXPECT_EQ(grid.Semantic(k), nullptr);
  }
  EXPECT_EQ(grid.State({kMaxKeyMagnitude, 0, 0}), VoxelState::kUnknown);
  EXPECT_EQ(grid.num_blocks(), 0u);
  EXPECT_EQ(grid.CountKnownVoxels(), 0u);
  EXPECT_EQ(grid.CountOccupiedVoxels(), 0u);
  EXPECT_TRUE(grid.KnownBounds().IsEmpty());
  EXPECT_EQ(grid.frame(), 0u);
  // A voxel next to a known one (same block) stays unknown.
  ASSERT_TRUE(grid.SetLogOdds({3, 3, 3}, 1.0f));
  EXPECT_EQ(grid.State({3, 3, 4}), VoxelState::kUnknown);
  EXPECT_FALSE(grid.LogOdds({3, 3, 4}).has_value());
  EXPECT_EQ(grid.num_blocks(), 1u);
}

TEST(OccupancyGridTest, UpdateOnceAppliesOneUpdatePerVoxelPerFrame) {
  OccupancyGrid grid;
  const float hit = grid.hit_log_odds();
  const float miss = grid.miss_log_odds();
  const VoxelKey a{10, -20, 30}, b{11, -20, 30};
  EXPECT_EQ(grid.BeginFrame(), 1u);
  EXPECT_TRUE(grid.UpdateOnce(a, hit));
  EXPECT_FALSE(grid.UpdateOnce(a, hit));
  EXPECT_FALSE(grid.UpdateOnce(a, miss));  // occupied wins: the first update of the frame stays
  EXPECT_EQ(grid.LogOdds(a), hit);
  EXPECT_TRUE(grid.UpdateOnce(b, miss));
  EXPECT_EQ(grid.LogOdds(b), miss);
  EXPECT_EQ(grid.State(a), VoxelState::kOccupied);
  EXPECT_EQ(grid.State(b), VoxelState::kFree);

  EXPECT_EQ(grid.BeginFrame(), 2u);
  EXPECT_EQ(grid.frame(), 2u);
  EXPECT_TRUE(grid.UpdateOnce(a, hit));
  EXPECT_FALSE(grid.UpdateOnce(a, hit));
  EXPECT_EQ(grid.LogOdds(a), hit + hit);
  EXPECT_TRUE(grid.UpdateOnce(b, hit));
  EXPECT_EQ(grid.LogOdds(b), miss + hit);
  EXPECT_EQ(grid.State(b), VoxelState::kOccupied);  // 0.441833 >= 0

  // The accessor shares the frame bookkeeping.
  grid.BeginFrame();
  OccupancyGrid::Accessor acc(grid);
  EXPECT_FALSE(acc.TouchedThisFrame(a));
  EXPECT_TRUE(acc.UpdateOnce(a, miss));
  EXPECT_TRUE(acc.TouchedThisFrame(a));
  EXPECT_FALSE(grid.UpdateOnce(a, hit));
  EXPECT_FALSE(acc.TouchedThisFrame({100, 100, 100}));  // no block there
  EXPECT_FALSE(acc.UpdateOnce(a, hit));
  EXPECT_EQ(grid.LogOdds(a), hit + hit + miss);
}

/// OctoMap with the same sensor model as the grid's defaults.
octomap::OcTree MakeOctree(double resolution) {
  octomap::OcTree tree(resolution);
  tree.setProbHit(0.7);
  tree.setProbMiss(0.4);
  tree.setClampingThresMin(0.12);
  tree.setClampingThresMax(0.97);
  tree.setOccupancyThres(0.5);
  return tree;
}

TEST(OccupancyGridTest, ClampsExactlyLikeOctomap) {
  OccupancyGrid grid;
  const VoxelKey k{1, 2, 3};
  // Hits: 0.847298, 1.694596, 2.541894, 3.389192, then the clamp 3.476099.
  const double expected_hits[] = {0.847298, 1.694596, 2.541894, 3.389192, 3.476099, 3.476099};
  for (double e : expected_hits) {
    grid.BeginFrame();
    ASSERT_TRUE(grid.UpdateOnce(k, grid.hit_log_odds()));
    EXPECT_NEAR(*grid.LogOdds(k), e, 1e-6);
  }
  EXPECT_EQ(*grid.LogOdds(k), LogOdds(0.97));
  EXPECT_EQ(*grid.LogOdds(k), grid.clamp_max_log_odds());
  // Misses from the clamp down to the lower clamp (float sums, as OctoMap).
  float v = grid.clamp_max_log_odds();
  for (int i = 0; i < 20; ++i) {
    grid.BeginFrame();
    ASSERT_TRUE(grid.UpdateOnce(k, grid.miss_log_odds()));
    v = std::max(v + grid.miss_log_odds(), grid.clamp_min_log_odds());
    EXPECT_EQ(*grid.LogOdds(k), v) << i;
  }
  EXPECT_EQ(*grid.LogOdds(k), LogOdds(0.12));
  EXPECT_NEAR(*grid.LogOdds(k), -1.992430, 1e-6);
  EXPECT_EQ(grid.State(k), VoxelState::kFree);

  // Misses on a fresh voxel: -0.405465, -0.810930, -1.216395, -1.621860, clamp -1.992430.
  const VoxelKey m{-5, -5, -5};
  const double expected_misses[] = {-0.405465, -0.810930, -1.216395, -1.621860, -1.992430};
  for (double e : expected_misses) {
    grid.BeginFrame();
    ASSERT_TRUE(grid.UpdateOnce(m, grid.miss_log_odds()));
    EXPECT_NEAR(*grid.LogOdds(m), e, 1e-6);
  }
}

TEST(OccupancyGridTest, RandomUpdateSequencesAreBitIdenticalToOctomap) {
  const double s = 0.005;
  OccupancyGrid grid;
  octomap::OcTree tree = MakeOctree(s);
  Rng rng(99);
  std::vector<VoxelKey> keys;
  for (int i = 0; i < 50; ++i) keys.push_back(RandomKey(rng, 200));
  for (int frame = 0; frame < 60; ++frame) {
    grid.BeginFrame();
    for (const VoxelKey& k : keys) {
      if (!rng.Bernoulli(0.7)) continue;
      const bool occupied = rng.Bernoulli(0.4);
      ASSERT_TRUE(grid.UpdateOnce(k, occupied ? grid.hit_log_odds() : grid.miss_log_odds()));
      const octomap::OcTreeKey ok(static_cast<octomap::key_type>(k.x + 32768),
                                  static_cast<octomap::key_type>(k.y + 32768),
                                  static_cast<octomap::key_type>(k.z + 32768));
      tree.updateNode(ok, occupied, /*lazy_eval=*/true);
    }
  }
  int compared = 0;
  for (const VoxelKey& k : keys) {
    const octomap::OcTreeKey ok(static_cast<octomap::key_type>(k.x + 32768),
                                static_cast<octomap::key_type>(k.y + 32768),
                                static_cast<octomap::key_type>(k.z + 32768));
    const octomap::OcTreeNode* node = tree.search(ok);
    ASSERT_NE(node, nullptr);
    ASSERT_TRUE(grid.LogOdds(k).has_value());
    EXPECT_EQ(*grid.LogOdds(k), node->getLogOdds()) << "voxel " << k.x << " " << k.y << " " << k.z;
    EXPECT_EQ(grid.State(k) == VoxelState::kOccupied, tree.isNodeOccupied(node));
    ++compared;
  }
  EXPECT_EQ(compared, 50);
}

TEST(OccupancyGridTest, OccupiedThresholdIsInclusive) {
  OccupancyGrid grid;
  ASSERT_TRUE(grid.SetLogOdds({0, 0, 0}, 0.0f));
  EXPECT_EQ(grid.State({0, 0, 0}), VoxelState::kOccupied);
  ASSERT_TRUE(grid.SetLogOdds({1, 0, 0}, -1e-7f));
  EXPECT_EQ(grid.State({1, 0, 0}), VoxelState::kFree);
  // Hit then two misses is still occupied (0.036368), a third miss makes it free.
  const VoxelKey k{5, 5, 5};
  float expected = 0.0f;
  const float updates[] = {grid.hit_log_odds(), grid.miss_log_odds(), grid.miss_log_odds()};
  for (float u : updates) {
    grid.BeginFrame();
    ASSERT_TRUE(grid.UpdateOnce(k, u));
    expected += u;
  }
  EXPECT_NEAR(*grid.LogOdds(k), 0.036368, 1e-6);
  EXPECT_EQ(*grid.LogOdds(k), expected);
  EXPECT_EQ(grid.State(k), VoxelState::kOccupied);
  grid.BeginFrame();
  ASSERT_TRUE(grid.UpdateOnce(k, grid.miss_log_odds()));
  EXPECT_EQ(grid.State(k), VoxelState::kFree);

  // A higher threshold.
  GridOptions o;
  o.sensor.occupied_threshold = 0.6;
  OccupancyGrid strict(o);
  const float thr = strict.occupied_log_odds();
  EXPECT_EQ(thr, LogOdds(0.6));
  ASSERT_TRUE(strict.SetLogOdds({0, 0, 0}, thr));
  ASSERT_TRUE(strict.SetLogOdds({1, 0, 0}, std::nextafter(thr, -1.0f)));
  ASSERT_TRUE(strict.SetLogOdds({2, 0, 0}, 0.2f));
  EXPECT_EQ(strict.State({0, 0, 0}), VoxelState::kOccupied);
  EXPECT_EQ(strict.State({1, 0, 0}), VoxelState::kFree);
  EXPECT_EQ(strict.State({2, 0, 0}), VoxelState::kFree);
  EXPECT_EQ(strict.CountOccupiedVoxels(), 1u);
}

TEST(OccupancyGridTest, SetLogOddsClampsAndRejectsNonFinite) {
  OccupancyGrid grid;
  ASSERT_TRUE(grid.SetLogOdds({0, 0, 0}, 10.0f));
  EXPECT_EQ(grid.LogOdds({0, 0, 0}), grid.clamp_max_log_odds());
  ASSERT_TRUE(grid.SetLogOdds({0, 0, 1}, -10.0f));
  EXPECT_EQ(grid.LogOdds({0, 0, 1}), grid.clamp_min_log_odds());
  ASSERT_TRUE(grid.SetLogOdds({0, 0, 2}, 1.25f));
  EXPECT_EQ(grid.LogOdds({0, 0, 2}), 1.25f);
  EXPECT_FALSE(grid.SetLogOdds({0, 0, 3}, std::numeric_limits<float>::quiet_NaN()));
  EXPECT_EQ(grid.State({0, 0, 3}), VoxelState::kUnknown);
  EXPECT_FALSE(grid.SetLogOdds({kMaxKeyMagnitude, 0, 0}, 1.0f));
  EXPECT_FALSE(grid.UpdateOnce({0, -kMaxKeyMagnitude, 0}, 1.0f));
  EXPECT_EQ(grid.CountKnownVoxels(), 3u);
}

TEST(OccupancyGridTest, RoiAdmitsExactlyTheVoxelsWhoseCentreLiesInside) {
  // 2^-7 m voxels: centres and box faces are exact binary fractions, so the closed-box rule is
  // tested exactly on the boundary.
  const double s = 0.0078125;
  GridOptions o;
  o.voxel_size_m = s;
  o.roi = Box3(Eigen::Vector3d(0.5 * s, -3.5 * s, -10 * s), Eigen::Vector3d(4.5 * s, 2.0 * s, 0.0));
  OccupancyGrid grid(o);
  EXPECT_TRUE(grid.Admits({0, -4, -9}));   // centre exactly on the min x and y faces
  EXPECT_TRUE(grid.Admits({4, 1, -1}));    // centre exactly on the max x face
  EXPECT_TRUE(grid.Admits({2, 0, -10}));   // centre -9.5 s
  EXPECT_FALSE(grid.Admits({-1, 0, -5}));  // centre -0.5 s < 0.5 s
  EXPECT_FALSE(grid.Admits({5, 0, -5}));   // centre 5.5 s > 4.5 s
  EXPECT_FALSE(grid.Admits({2, -5, -5}));  // centre -4.5 s < -3.5 s
  EXPECT_FALSE(grid.Admits({2, 2, -5}));   // centre 2.5 s > 2.0 s
  EXPECT_FALSE(grid.Admits({2, 0, -11}));  // centre -10.5 s < -10 s
  EXPECT_FALSE(grid.Admits({2, 0, 0}));    // centre 0.5 s > 0
  for (int32_t x = -3; x <= 7; ++x) {
    for (int32_t y = -6; y <= 4; ++y) {
      for (int32_t z = -13; z <= 2; ++z) {
        const VoxelKey k{x, y, z};
        ASSERT_EQ(grid.Admits(k), o.roi->Contains(grid.CenterOf(k))) << x << " " << y << " " << z;
      }
    }
  }
  // Rejected updates allocate nothing and leave the voxel unknown.
  grid.BeginFrame();
  EXPECT_FALSE(grid.UpdateOnce({5, 0, -5}, 1.0f));
  EXPECT_FALSE(grid.SetLogOdds({-1, 0, -5}, 1.0f));
  EXPECT_EQ(grid.MutableSemantic({2, 2, -5}), nullptr);
  EXPECT_EQ(grid.num_blocks(), 0u);
  EXPECT_TRUE(grid.UpdateOnce({4, 1, -1}, 1.0f));
  EXPECT_EQ(grid.State({4, 1, -1}), VoxelState::kOccupied);
  EXPECT_EQ(grid.State({5, 0, -5}), VoxelState::kUnknown);
}

TEST(OccupancyGridTest, RoiMatchesBoxContainsOnRandomBoxes) {
  Rng rng(12);
  for (int trial = 0; trial < 20; ++trial) {
    GridOptions o;
    o.voxel_size_m = trial % 2 ? 0.005 : 0.013;
    const Eigen::Vector3d lo(rng.Uniform(-0.2, 0.1), rng.Uniform(-0.2, 0.1),
                             rng.Uniform(-0.2, 0.1));
    const Eigen::Vector3d hi =
        lo +
        Eigen::Vector3d(rng.Uniform(0.001, 0.1), rng.Uniform(0.001, 0.1), rng.Uniform(0.001, 0.1));
    o.roi = Box3(lo, hi);
    const OccupancyGrid grid(o);
    const VoxelKey a = grid.KeyOf(lo), b = grid.KeyOf(hi);
    for (int32_t x = a.x - 2; x <= b.x + 2; ++x) {
      for (int32_t y = a.y - 2; y <= b.y + 2; ++y) {
        for (int32_t z = a.z - 2; z <= b.z + 2; ++z) {
          const VoxelKey k{x, y, z};
          ASSERT_EQ(grid.Admits(k), o.roi->Contains(grid.CenterOf(k)))
              << trial << ": " << x << " " << y << " " << z;
        }
      }
    }
  }
}

TEST(OccupancyGridTest, IterationAndCountsMatchAReferenceMap) {
  OccupancyGrid grid;
  Rng rng(3);
  std::map<VoxelKey, float> reference;
  for (int i = 0; i < 3000; ++i) {
    const VoxelKey k = RandomKey(rng, 60);
    const float v = static_cast<float>(rng.Uniform(-1.9, 3.4));
    ASSERT_TRUE(grid.SetLogOdds(k, v));
    reference[k] = v;
  }
  std::map<VoxelKey, float> seen;
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float v) {
    EXPECT_TRUE(seen.emplace(k, v).second) << "visited twice";
  });
  EXPECT_EQ(seen, reference);
  size_t occupied = 0;
  for (const auto& [k, v] : reference) {
    occupied += v >= 0.0f;
    ASSERT_EQ(grid.LogOdds(k), v);
    ASSERT_EQ(grid.State(k), v >= 0.0f ? VoxelState::kOccupied : VoxelState::kFree);
  }
  EXPECT_EQ(grid.CountKnownVoxels(), reference.size());
  EXPECT_EQ(grid.CountOccupiedVoxels(), occupied);
  // Block iteration: each block once, in allocation order, with its voxels.
  std::set<BlockKey> blocks;
  size_t known = 0;
  grid.ForEachBlock([&](const OccupancyBlock& b) {
    EXPECT_TRUE(blocks.insert(b.key).second);
    known += static_cast<size_t>(b.known.count());
  });
  EXPECT_EQ(blocks.size(), grid.num_blocks());
  EXPECT_EQ(known, reference.size());
}

TEST(OccupancyGridTest, KnownBoundsCoverExactlyTheKnownVoxels) {
  const double s = 0.005;
  OccupancyGrid grid;
  EXPECT_TRUE(grid.KnownBounds().IsEmpty());
  ASSERT_NE(grid.MutableSemantic({100, 100, 100}), nullptr);  // payload only: not known
  EXPECT_TRUE(grid.KnownBounds().IsEmpty());
  ASSERT_TRUE(grid.SetLogOdds({-3, 2, 5}, 1.0f));
  ASSERT_TRUE(grid.SetLogOdds({4, -1, 7}, -1.0f));
  ASSERT_TRUE(grid.SetLogOdds({0, 0, 6}, -1.0f));
  const Box3 b = grid.KnownBounds();
  EXPECT_NEAR(b.min().x(), -3 * s, 1e-12);
  EXPECT_NEAR(b.min().y(), -1 * s, 1e-12);
  EXPECT_NEAR(b.min().z(), 5 * s, 1e-12);
  EXPECT_NEAR(b.max().x(), 5 * s, 1e-12);
  EXPECT_NEAR(b.max().y(), 3 * s, 1e-12);
  EXPECT_NEAR(b.max().z(), 8 * s, 1e-12);
}

TEST(OccupancyGridTest, ChangeTrackingReportsUpdatedVoxelsUntilCleared) {
  OccupancyGrid grid;
  const VoxelKey a{0, 0, 0}, b{1, 0, 0}, c{-9, 40, 3}, d{100, 0, 0};
  EXPECT_TRUE(grid.DirtyBlocks().empty());
  grid.BeginFrame();
  ASSERT_TRUE(grid.UpdateOnce(a, grid.hit_log_odds()));
  ASSERT_TRUE(grid.UpdateOnce(c, grid.miss_log_odds()));
  ASSERT_TRUE(grid.UpdateOnce(b, grid.miss_log_odds()));
  EXPECT_EQ(grid.DirtyBlocks(), (std::vector<BlockKey>{BlockOf(a), BlockOf(c)}));
  std::map<VoxelKey, float> changed;
  grid.ForEachChangedVoxel([&](const VoxelKey& k, float v) { changed[k] = v; });
  EXPECT_EQ(changed,
            (std::map<VoxelKey, float>{
                {a, grid.hit_log_odds()}, {b, grid.miss_log_odds()}, {c, grid.miss_log_odds()}}));
  grid.ClearChanges();
  EXPECT_TRUE(grid.DirtyBlocks().empty());
  int n = 0;
  grid.ForEachChangedVoxel([&](const VoxelKey&, float) { ++n; });
  EXPECT_EQ(n, 0);
  // Known voxels are unaffected by ClearChanges.
  EXPECT_EQ(grid.CountKnownVoxels(), 3u);
  // A rejected (second) update in the same frame is no change.
  EXPECT_FALSE(grid.UpdateOnce(a, grid.hit_log_odds()));
  EXPECT_TRUE(grid.DirtyBlocks().empty());
  grid.BeginFrame();
  ASSERT_TRUE(grid.UpdateOnce(b, grid.hit_log_odds()));
  ASSERT_TRUE(grid.SetLogOdds(d, 2.0f));
  EXPECT_EQ(grid.DirtyBlocks(), (std::vector<BlockKey>{BlockOf(a), BlockOf(d)}));
  changed.clear();
  grid.ForEachChangedVoxel([&](const VoxelKey& k, float v) { changed[k] = v; });
  EXPECT_EQ(changed, (std::map<VoxelKey, float>{{b, grid.miss_log_odds() + grid.hit_log_odds()},
                                                {d, 2.0f}}));
}

TEST(OccupancyGridTest, SemanticPayloadIsLazyAndCounted) {
  OccupancyGrid grid;
  const VoxelKey a{3, 4, 5}, b{3, 4, 6}, far{-100, 7, 2};
  EXPECT_EQ(grid.Semantic(a), nullptr);
  EXPECT_EQ(grid.num_semantic_blocks(), 0u);
  ASSERT_TRUE(grid.SetLogOdds(a, 1.0f));
  EXPECT_EQ(grid.Semantic(a), nullptr);  // a block without payload
  EXPECT_EQ(grid.num_semantic_blocks(), 0u);

  SemanticCell* cell = grid.MutableSemantic(a);
  ASSERT_NE(cell, nullptr);
  EXPECT_EQ(grid.num_semantic_blocks(), 1u);
  EXPECT_EQ(*cell, SemanticCell{});
  EXPECT_EQ(grid.CountSemanticVoxels(), 0u);
  cell->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
  cell->instance_id = 7;
  cell->confidence = 0.8f;
  cell->observations = 1;
  EXPECT_EQ(grid.CountSemanticVoxels(), 1u);
  const SemanticCell* read = grid.Semantic(a);
  ASSERT_NE(read, nullptr);
  EXPECT_EQ(read->cls(), SemanticClass::kFruit);
  EXPECT_EQ(read->instance_id, 7);
  EXPECT_EQ(grid.Semantic(b), nullptr);      // same block, no evidence
  EXPECT_EQ(grid.MutableSemantic(a), cell);  // stable address

  // A second block gets its own payload; the voxel itself stays unknown.
  const size_t blocks_before = grid.num_blocks();
  SemanticCell* c2 = grid.MutableSemantic(far);
  ASSERT_NE(c2, nullptr);
  EXPECT_EQ(grid.num_blocks(), blocks_before + 1);
  EXPECT_EQ(grid.num_semantic_blocks(), 2u);
  EXPECT_EQ(grid.State(far), VoxelState::kUnknown);
  c2->semantic_class = static_cast<uint8_t>(SemanticClass::kLeaf);
  std::map<VoxelKey, uint8_t> labelled;
  grid.ForEachSemanticVoxel(
      [&](const VoxelKey& k, const SemanticCell& c) { labelled[k] = c.semantic_class; });
  EXPECT_EQ(labelled, (std::map<VoxelKey, uint8_t>{{a, 1}, {far, 2}}));
  EXPECT_EQ(grid.CountSemanticVoxels(), 2u);

  // Back to background: no longer counted.
  cell->semantic_class = static_cast<uint8_t>(SemanticClass::kBackground);
  EXPECT_EQ(grid.CountSemanticVoxels(), 1u);
  // Semantic() never inserts.
  const size_t n = grid.num_blocks();
  EXPECT_EQ(grid.Semantic({5000, 5000, 5000}), nullptr);
  EXPECT_EQ(grid.num_blocks(), n);
}

TEST(OccupancyGridTest, ClearRemovesEverythingAndTheGridStaysUsable) {
  OccupancyGrid grid;
  Rng rng(8);
  grid.BeginFrame();
  for (int i = 0; i < 500; ++i) grid.UpdateOnce(RandomKey(rng, 300), grid.hit_log_odds());
  ASSERT_NE(grid.MutableSemantic({1, 1, 1}), nullptr);
  const size_t full_bytes = grid.MemoryBytes();
  ASSERT_GT(grid.num_blocks(), 100u);
  grid.Clear();
  EXPECT_EQ(grid.num_blocks(), 0u);
  EXPECT_EQ(grid.num_semantic_blocks(), 0u);
  EXPECT_EQ(grid.CountKnownVoxels(), 0u);
  EXPECT_TRUE(grid.KnownBounds().IsEmpty());
  EXPECT_TRUE(grid.DirtyBlocks().empty());
  EXPECT_LT(grid.MemoryBytes(), full_bytes);
  EXPECT_EQ(grid.State({1, 1, 1}), VoxelState::kUnknown);
  EXPECT_EQ(grid.Semantic({1, 1, 1}), nullptr);
  grid.BeginFrame();
  EXPECT_TRUE(grid.UpdateOnce({1, 1, 1}, grid.hit_log_odds()));
  EXPECT_EQ(grid.LogOdds({1, 1, 1}), grid.hit_log_odds());
  EXPECT_EQ(grid.num_blocks(), 1u);
}

TEST(OccupancyGridTest, ReleaseEmptyBlocksKeepsKnownAndSemanticBlocks) {
  OccupancyGrid grid;
  grid.BeginFrame();
  std::vector<BlockKey> keys = {{5, 5, 5}, {0, 0, 0}, {-1, 2, 3}, {9, 9, 9}, {-4, -4, -4}};
  grid.PrepareFrameBlocks(keys);
  ASSERT_EQ(grid.num_blocks(), 5u);
  const VoxelKey known1 = KeyOf(BlockKey{9, 9, 9}, 17);
  const VoxelKey known2 = KeyOf(BlockKey{-4, -4, -4}, 300);
  const VoxelKey labelled = KeyOf(BlockKey{5, 5, 5}, 42);
  ASSERT_TRUE(grid.UpdateOnce(known1, grid.hit_log_odds()));
  ASSERT_TRUE(grid.UpdateOnce(known2, grid.miss_log_odds()));
  SemanticCell* cell = grid.MutableSemantic(labelled);
  ASSERT_NE(cell, nullptr);
  cell->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
  cell->observations = 2;
  const size_t bytes_before = grid.MemoryBytes();

  EXPECT_EQ(grid.ReleaseEmptyBlocks(), 2u);  // {0,0,0} and {-1,2,3}
  EXPECT_EQ(grid.num_blocks(), 3u);
  EXPECT_EQ(grid.FindBlock({0, 0, 0}), nullptr);
  EXPECT_EQ(grid.FindBlock({-1, 2, 3}), nullptr);
  for (const BlockKey b : {BlockKey{5, 5, 5}, BlockKey{9, 9, 9}, BlockKey{-4, -4, -4}}) {
    const OccupancyBlock* found = grid.FindBlock(b);
    ASSERT_NE(found, nullptr);
    EXPECT_EQ(found->key, b);
  }
  EXPECT_EQ(grid.LogOdds(known1), grid.hit_log_odds());
  EXPECT_EQ(grid.LogOdds(known2), grid.miss_log_odds());
  ASSERT_NE(grid.Semantic(labelled), nullptr);
  EXPECT_EQ(grid.Semantic(labelled)->cls(), SemanticClass::kFruit);
  std::vector<VoxelKey> sem;
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const SemanticCell&) { sem.push_back(k); });
  EXPECT_EQ(sem, std::vector<VoxelKey>{labelled});
  EXPECT_EQ(grid.num_semantic_blocks(), 1u);
  EXPECT_LT(grid.MemoryBytes(), bytes_before);
  EXPECT_EQ(grid.ReleaseEmptyBlocks(), 0u);
  // Still fully usable: new blocks and existing ones.
  EXPECT_TRUE(grid.SetLogOdds({0, 0, 0}, 1.0f));
  EXPECT_EQ(grid.num_blocks(), 4u);
  EXPECT_EQ(grid.MutableSemantic(labelled), grid.MutableSemantic(labelled));
  EXPECT_EQ(grid.num_semantic_blocks(), 1u);
}

TEST(OccupancyGridTest, MemoryGrowsWithBlocksAndSemanticPayload) {
  OccupancyGrid grid;
  const size_t empty = grid.MemoryBytes();
  size_t prev = empty;
  for (int i = 0; i < 50; ++i) {
    ASSERT_TRUE(grid.SetLogOdds({i * 8, 0, 0}, 1.0f));
    const size_t now = grid.MemoryBytes();
    EXPECT_GE(now, prev + sizeof(OccupancyBlock)) << i;
    prev = now;
  }
  EXPECT_GE(grid.MemoryBytes(), empty + 50 * sizeof(OccupancyBlock));
  ASSERT_TRUE(grid.SetLogOdds({1, 0, 0}, 1.0f));  // same block: no growth
  EXPECT_EQ(grid.MemoryBytes(), prev);
  ASSERT_NE(grid.MutableSemantic({1, 0, 0}), nullptr);
  EXPECT_GE(grid.MemoryBytes(), prev + sizeof(SemanticBlock));
  // About 2.3 KB per occupancy block, as documented.
  EXPECT_GT(sizeof(OccupancyBlock), 2048u);
  EXPECT_LT(sizeof(OccupancyBlock), 2600u);
}

TEST(OccupancyGridTest, HashTableFindsOneHundredThousandRandomBlocks) {
  Rng rng(2024);
  constexpr int32_t kMaxBlock = (kMaxKeyMagnitude >> kBlockShift) - 1;  // 2^20 - 1
  std::vector<BlockKey> keys;
  std::set<BlockKey> unique;
  // Extremes first, then random blocks (some clustered, some spread over the whole range).
  for (const BlockKey b : {BlockKey{-kMaxBlock - 1, -kMaxBlock - 1, -kMaxBlock - 1},
                           BlockKey{kMaxBlock, kMaxBlock, kMaxBlock}, BlockKey{0, 0, 0},
                           BlockKey{-1, -1, -1}, BlockKey{kMaxBlock, -kMaxBlock - 1, 0}}) {
    unique.insert(b);
    keys.push_back(b);
  }
  while (keys.size() < 100000) {
    const int32_t r = keys.size() % 2 ? kMaxBlock : 40;
    const BlockKey b{static_cast<int32_t>(rng.UniformInt(-r - 1, r)),
                     static_cast<int32_t>(rng.UniformInt(-r - 1, r)),
                     static_cast<int32_t>(rng.UniformInt(-r - 1, r))};
    if (unique.insert(b).second) keys.push_back(b);
  }
  OccupancyGrid grid;
  for (const BlockKey& b : keys) ASSERT_NE(grid.GetOrCreateBlock(b), nullptr);
  ASSERT_EQ(grid.num_blocks(), keys.size());
  for (size_t i = 0; i < keys.size(); ++i) {
    ASSERT_EQ(grid.Lookup(keys[i]), static_cast<int32_t>(i));
    const OccupancyBlock* b = grid.FindBlock(keys[i]);
    ASSERT_NE(b, nullptr);
    ASSERT_EQ(b->key, keys[i]);
    ASSERT_EQ(grid.GetOrCreateBlock(keys[i]), b);  // no second allocation
  }
  EXPECT_EQ(grid.num_blocks(), keys.size());
  // Absent keys are not found.
  int absent = 0;
  for (int i = 0; i < 20000; ++i) {
    const BlockKey b{static_cast<int32_t>(rng.UniformInt(-41, 40)),
                     static_cast<int32_t>(rng.UniformInt(-41, 40)),
                     static_cast<int32_t>(rng.UniformInt(-41, 40))};
    if (unique.count(b) == 0) {
      ++absent;
      ASSERT_EQ(grid.FindBlock(b), nullptr);
    }
  }
  EXPECT_GT(absent, 1000);
  // Iteration follows allocation order.
  size_t i = 0;
  grid.ForEachBlock([&](const OccupancyBlock& b) {
    ASSERT_EQ(b.key, keys[i]);
    ++i;
  });
  EXPECT_EQ(i, keys.size());
  // The voxel at the extreme corners is reachable through the normal API.
  const VoxelKey corner{kMaxKeyMagnitude - 1, kMaxKeyMagnitude - 1, kMaxKeyMagnitude - 1};
  ASSERT_TRUE(grid.SetLogOdds(corner, 1.0f));
  EXPECT_EQ(grid.State(corner), VoxelState::kOccupied);
  EXPECT_EQ(grid.num_blocks(), keys.size());  // that block existed already
}

TEST(OccupancyGridTest, PrepareFrameBlocksAllocatesInSortedOrder) {
  OccupancyGrid grid;
  grid.BeginFrame();
  std::vector<BlockKey> keys = {{3, 0, 0}, {-2, 5, 1}, {3, 0, 0}, {0, 0, -7}, {-2, 5, 0}};
  grid.PrepareFrameBlocks(keys);
  std::vector<BlockKey> order;
  grid.ForEachBlock([&](const OccupancyBlock& b) { order.push_back(b.key); });
  std::vector<BlockKey> expected = {{-2, 5, 0}, {-2, 5, 1}, {0, 0, -7}, {3, 0, 0}};
  EXPECT_EQ(order, expected);
  // Same blocks in another order: same layout.
  OccupancyGrid other;
  other.BeginFrame();
  std::vector<BlockKey> shuffled = {{0, 0, -7}, {3, 0, 0}, {-2, 5, 1}, {-2, 5, 0}};
  other.PrepareFrameBlocks(shuffled);
  std::vector<BlockKey> order2;
  other.ForEachBlock([&](const OccupancyBlock& b) { order2.push_back(b.key); });
  EXPECT_EQ(order2, expected);
}

TEST(OccupancyGridTest, NoAllocAccessorReportsMissingAndUnpreparedBlocks) {
  GridOptions o;
  o.roi = Box3(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1));
  OccupancyGrid grid(o);
  grid.BeginFrame();
  std::vector<BlockKey> keys = {{0, 0, 0}};
  grid.PrepareFrameBlocks(keys);
  OccupancyGrid::NoAllocAccessor acc(grid);
  EXPECT_TRUE(acc.UpdateOnce({1, 2, 3}, grid.miss_log_odds()));
  EXPECT_FALSE(acc.last_missing());
  EXPECT_FALSE(acc.UpdateOnce({1, 2, 3}, grid.miss_log_odds()));  // already updated
  EXPECT_FALSE(acc.last_missing());
  EXPECT_FALSE(acc.UpdateOnce({20, 0, 0}, grid.miss_log_odds()));  // no block
  EXPECT_TRUE(acc.last_missing());
  EXPECT_EQ(acc.missing_blocks(), 1u);
  EXPECT_FALSE(acc.UpdateOnce({1000, 0, 0}, grid.miss_log_odds()));  // outside the ROI
  EXPECT_FALSE(acc.last_missing());
  EXPECT_EQ(acc.missing_blocks(), 1u);
  // A block from an older frame that was not prepared again is not touched.
  ASSERT_TRUE(grid.SetLogOdds({-8, 0, 0}, 0.5f));  // allocates block {-1, 0, 0}
  grid.BeginFrame();
  std::vector<BlockKey> only_origin = {{0, 0, 0}};
  grid.PrepareFrameBlocks(only_origin);
  OccupancyGrid::NoAllocAccessor acc2(grid);
  EXPECT_FALSE(acc2.UpdateOnce({-7, 0, 0}, grid.miss_log_odds()));
  EXPECT_TRUE(acc2.last_missing());
  EXPECT_EQ(grid.State({-7, 0, 0}), VoxelState::kUnknown);
  EXPECT_TRUE(acc2.UpdateOnce({1, 2, 3}, grid.miss_log_odds()));  // new frame: applies again
  EXPECT_EQ(grid.LogOdds({1, 2, 3}), grid.miss_log_odds() + grid.miss_log_odds());
  EXPECT_EQ(grid.num_blocks(), 2u);
}

TEST(OccupancyGridTest, TwoThreadsUpdateEachVoxelExactlyOncePerFrame) {
  OccupancyGrid grid;
  Rng rng(17);
  // 40k voxel updates per thread over ~15k distinct voxels in a few dozen blocks.
  std::vector<VoxelKey> keys;
  for (int i = 0; i < 40000; ++i) keys.push_back(RandomKey(rng, 12));
  std::set<VoxelKey> distinct(keys.begin(), keys.end());
  std::vector<VoxelKey> reversed(keys.rbegin(), keys.rend());
  const float miss = grid.miss_log_odds();
  for (int frame = 1; frame <= 3; ++frame) {
    grid.BeginFrame();
    std::vector<BlockKey> blocks;
    for (const VoxelKey& k : keys) blocks.push_back(BlockOf(k));
    grid.PrepareFrameBlocks(blocks);
    std::atomic<size_t> applied{0};
    std::atomic<size_t> missing{0};
    const auto work = [&](const std::vector<VoxelKey>& list) {
      OccupancyGrid::NoAllocAccessor acc(grid);
      size_t n = 0;
      for (int pass = 0; pass < 2; ++pass) {
        for (const VoxelKey& k : list) n += acc.UpdateOnce(k, miss) ? 1 : 0;
      }
      applied += n;
      missing += acc.missing_blocks();
    };
    std::thread t1(work, std::cref(keys));
    std::thread t2(work, std::cref(reversed));
    t1.join();
    t2.join();
    EXPECT_EQ(applied.load(), distinct.size()) << "frame " << frame;
    EXPECT_EQ(missing.load(), 0u);
    float expected = 0.0f;
    for (int f = 0; f < frame; ++f) expected = std::max(expected + miss, grid.clamp_min_log_odds());
    size_t wrong = 0;
    for (const VoxelKey& k : distinct) wrong += grid.LogOdds(k) != expected;
    EXPECT_EQ(wrong, 0u) << "frame " << frame;
    EXPECT_EQ(grid.CountKnownVoxels(), distinct.size());
    size_t changed = 0;
    grid.ForEachChangedVoxel([&](const VoxelKey&, float) { ++changed; });
    EXPECT_EQ(changed, distinct.size());
  }
}

TEST(OccupancyGridTest, MoveKeepsTheContents) {
  OccupancyGrid a;
  ASSERT_TRUE(a.SetLogOdds({1, 2, 3}, 1.5f));
  a.MutableSemantic({1, 2, 3})->semantic_class = 1;
  OccupancyGrid b(std::move(a));
  EXPECT_EQ(b.LogOdds({1, 2, 3}), 1.5f);
  EXPECT_EQ(b.CountSemanticVoxels(), 1u);
  OccupancyGrid c;
  c = std::move(b);
  EXPECT_EQ(c.State({1, 2, 3}), VoxelState::kOccupied);
  EXPECT_EQ(c.num_blocks(), 1u);
}

}  // namespace
}  // namespace avp::mapping

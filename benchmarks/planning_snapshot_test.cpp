// PlanningSnapshot: exact copies of the grid over a box, class bits, size limits, and CastRay
// against a brute-force walk (TraverseRay + grid.State).
#include "planning_snapshot.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/rng.h>
#include <avp/mapping/ray_traversal.h>

namespace avp::mapping {
namespace {

using ::testing::HasSubstr;

constexpr double kVoxel = 0.005;

/// A 40^3-voxel region around (-20 .. 19) with ~35 % known voxels, 3 % of them occupied, and
/// labels (fruit, leaf, support) on some known voxels (occupied and free) and on a few unknown
/// ones (payload without occupancy).
OccupancyGrid RandomGrid(uint64_t seed, double voxel_size_m = kVoxel) {
  GridOptions options;
  options.voxel_size_m = voxel_size_m;
  OccupancyGrid grid(options);
  Rng rng(seed);
  for (int32_t z = -20; z < 20; ++z) {
    for (int32_t y = -20; y < 20; ++y) {
      for (int32_t x = -20; x < 20; ++x) {
        const VoxelKey k{x, y, z};
        if (rng.Bernoulli(0.35)) {
          const bool occupied = rng.Bernoulli(0.03);
          const float v = occupied ? static_cast<float>(rng.Uniform(0.0, 3.4))
                                   : static_cast<float>(rng.Uniform(-1.9, -0.01));
          EXPECT_TRUE(grid.SetLogOdds(k, v));
          if (rng.Bernoulli(0.3)) {
            const SemanticClass cls = rng.Bernoulli(0.5)   ? SemanticClass::kFruit
                                      : rng.Bernoulli(0.5) ? SemanticClass::kLeaf
                                                           : SemanticClass::kSupport;
            grid.MutableSemantic(k)->semantic_class = static_cast<uint8_t>(cls);
          }
        } else if (rng.Bernoulli(0.02)) {
          grid.MutableSemantic(k)->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
        }
      }
    }
  }
  return grid;
}

uint8_t ClassOf(const OccupancyGrid& grid, const VoxelKey& k) {
  const SemanticCell* c = grid.Semantic(k);
  return c == nullptr ? 0 : c->semantic_class;
}

/// The expected byte of a voxel: state bits, plus class bits for known labelled voxels.
uint8_t ExpectedCell(const OccupancyGrid& grid, const VoxelKey& k) {
  const VoxelState s = grid.State(k);
  if (s == VoxelState::kUnknown) return 0;
  return static_cast<uint8_t>(static_cast<uint8_t>(s) |
                              (ClassOf(grid, k) << PlanningSnapshot::kClassShift));
}

bool InSnapshot(const PlanningSnapshot& snap, const VoxelKey& k) {
  const VoxelKey m = snap.min_key();
  return k.x >= m.x && k.y >= m.y && k.z >= m.z && k.x < m.x + snap.dims().x() &&
         k.y < m.y + snap.dims().y() && k.z < m.z + snap.dims().z();
}

/// Brute force: the voxels of [from, to) by TraverseRay (dropping the end voxel), states from
/// `state_of`, stopping at (and counting) the first occupied one.
template <typename StateOf>
PlanningSnapshot::RayCounts ReferenceCast(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                                          StateOf&& state_of, double voxel_size_m = kVoxel) {
  std::vector<VoxelKey> keys;
  TraverseRay(from, to, voxel_size_m, [&](const VoxelKey& k) {
    keys.push_back(k);
    return true;
  });
  PlanningSnapshot::RayCounts c;
  if (keys.empty()) return c;
  keys.pop_back();
  for (const VoxelKey& k : keys) {
    const auto [state, cls] = state_of(k);
    ++c.visited;
    if (state == VoxelState::kOccupied) {
      c.hit = true;
      c.hit_class = cls;
      break;
    }
    if (state == VoxelState::kFree) ++c.free;
    if (state == VoxelState::kUnknown) ++c.unknown;
  }
  return c;
}

std::string Describe(const PlanningSnapshot::RayCounts& c) {
  return "unknown " + std::to_string(c.unknown) + ", free " + std::to_string(c.free) +
         ", visited " + std::to_string(c.visited) + ", hit " + std::to_string(c.hit) + ", class " +
         std::to_string(c.hit_class);
}

bool Same(const PlanningSnapshot::RayCounts& a, const PlanningSnapshot::RayCounts& b) {
  return a.unknown == b.unknown && a.free == b.free && a.visited == b.visited && a.hit == b.hit &&
         a.hit_class == b.hit_class;
}

// ---- Build -------------------------------------------------------------------------------------

TEST(PlanningSnapshotTest, BuildOverKnownCopiesEveryVoxelExactly) {
  const OccupancyGrid grid = RandomGrid(1);
  const auto snap = PlanningSnapshot::BuildOverKnown(grid);
  ASSERT_TRUE(snap.ok()) << snap.status().ToString();
  EXPECT_EQ(snap->voxel_size_m(), kVoxel);
  // The box is the bounding box of the known voxels.
  VoxelKey lo{1 << 30, 1 << 30, 1 << 30}, hi{-(1 << 30), -(1 << 30), -(1 << 30)};
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float) {
    lo = {std::min(lo.x, k.x), std::min(lo.y, k.y), std::min(lo.z, k.z)};
    hi = {std::max(hi.x, k.x), std::max(hi.y, k.y), std::max(hi.z, k.z)};
  });
  EXPECT_EQ(snap->min_key(), lo);
  EXPECT_EQ(snap->dims(), Eigen::Vector3i(hi.x - lo.x + 1, hi.y - lo.y + 1, hi.z - lo.z + 1));
  // Stored in whole 8^3 bricks.
  const Eigen::Vector3i bricks = (snap->dims().array() + 7) / 8;
  EXPECT_EQ(snap->bytes(), static_cast<size_t>(bricks.prod()) * 512u);
  EXPECT_TRUE(snap->box().min().isApprox(grid.KnownBounds().min(), 1e-12));
  EXPECT_TRUE(snap->box().max().isApprox(grid.KnownBounds().max(), 1e-12));

  size_t occupied = 0, free = 0, labelled = 0;
  for (int32_t z = lo.z - 2; z <= hi.z + 2; ++z) {
    for (int32_t y = lo.y - 2; y <= hi.y + 2; ++y) {
      for (int32_t x = lo.x - 2; x <= hi.x + 2; ++x) {
        const VoxelKey k{x, y, z};
        ASSERT_EQ(snap->State(k), grid.State(k)) << x << " " << y << " " << z;
        ASSERT_EQ(snap->Cell(k), ExpectedCell(grid, k)) << x << " " << y << " " << z;
        occupied += snap->State(k) == VoxelState::kOccupied;
        free += snap->State(k) == VoxelState::kFree;
        labelled += (snap->Cell(k) >> PlanningSnapshot::kClassShift) != 0;
      }
    }
  }
  EXPECT_EQ(occupied, grid.CountOccupiedVoxels());
  EXPECT_EQ(occupied + free, grid.CountKnownVoxels());
  EXPECT_GT(occupied, 100u);
  EXPECT_GT(labelled, 1000u);
  // Unlabelled payload on unknown voxels does not show up.
  EXPECT_LT(labelled, grid.CountSemanticVoxels());
}

TEST(PlanningSnapshotTest, ClassBitsHoldTheSemanticClass) {
  OccupancyGrid grid;
  ASSERT_TRUE(grid.SetLogOdds({0, 0, 0}, 2.0f));
  ASSERT_TRUE(grid.SetLogOdds({1, 0, 0}, -1.0f));
  ASSERT_TRUE(grid.SetLogOdds({2, 0, 0}, 1.0f));
  ASSERT_TRUE(grid.SetLogOdds({3, 0, 0}, 1.0f));
  grid.MutableSemantic({0, 0, 0})->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
  grid.MutableSemantic({1, 0, 0})->semantic_class = static_cast<uint8_t>(SemanticClass::kOther);
  grid.MutableSemantic({2, 0, 0})->semantic_class = static_cast<uint8_t>(SemanticClass::kStem);
  const auto snap = PlanningSnapshot::BuildOverKnown(grid);
  ASSERT_TRUE(snap.ok());
  EXPECT_EQ(snap->Cell({0, 0, 0}), 2 | (1 << 2));
  EXPECT_EQ(snap->Cell({1, 0, 0}), 1 | (6 << 2));
  EXPECT_EQ(snap->Cell({2, 0, 0}), 2 | (3 << 2));
  EXPECT_EQ(snap->Cell({3, 0, 0}), 2);
  EXPECT_EQ(snap->dims(), Eigen::Vector3i(4, 1, 1));
  EXPECT_EQ(snap->Cell({4, 0, 0}), 0);
  EXPECT_EQ(snap->Cell({-1, 0, 0}), 0);
  EXPECT_EQ(snap->Cell({0, 1, 0}), 0);
}

TEST(PlanningSnapshotTest, BuildOverASubBoxCopiesOnlyVoxelsWithCentresInside) {
  const OccupancyGrid grid = RandomGrid(2);
  const Box3 box(Eigen::Vector3d(-0.0312, -0.0051, 0.0149),
                 Eigen::Vector3d(0.0203, 0.0377, 0.0601));
  const auto snap = PlanningSnapshot::Build(grid, box);
  ASSERT_TRUE(snap.ok()) << snap.status().ToString();
  int inside = 0;
  for (int32_t z = -22; z < 22; ++z) {
    for (int32_t y = -22; y < 22; ++y) {
      for (int32_t x = -22; x < 22; ++x) {
        const VoxelKey k{x, y, z};
        const bool in_box = box.Contains(k.Center(kVoxel));
        ASSERT_EQ(InSnapshot(*snap, k), in_box) << x << " " << y << " " << z;
        inside += in_box;
        ASSERT_EQ(snap->Cell(k), in_box ? ExpectedCell(grid, k) : uint8_t{0})
            << x << " " << y << " " << z;
      }
    }
  }
  EXPECT_EQ(inside, snap->dims().prod());
  EXPECT_EQ(snap->bytes(), static_cast<size_t>(((snap->dims().array() + 7) / 8).prod()) * 512u);
  // A box larger than the map: everything known is copied, the rest reads unknown.
  const Box3 big(Eigen::Vector3d::Constant(-0.2), Eigen::Vector3d::Constant(0.2));
  const auto all = PlanningSnapshot::Build(grid, big);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->dims(), Eigen::Vector3i(80, 80, 80));
  size_t known = 0;
  for (int32_t z = -40; z < 40; ++z) {
    for (int32_t y = -40; y < 40; ++y) {
      for (int32_t x = -40; x < 40; ++x) {
        ASSERT_EQ(all->Cell({x, y, z}), ExpectedCell(grid, {x, y, z}));
        known += all->State({x, y, z}) != VoxelState::kUnknown;
      }
    }
  }
  EXPECT_EQ(known, grid.CountKnownVoxels());
}

TEST(PlanningSnapshotTest, ErrorsForEmptyBoxesAndSizeLimits) {
  OccupancyGrid grid;
  const auto empty_map = PlanningSnapshot::BuildOverKnown(grid);
  EXPECT_FALSE(empty_map.ok());
  EXPECT_FALSE(PlanningSnapshot::Build(grid, Box3()).ok());
  // A box thinner than a voxel between two centres holds no voxel.
  EXPECT_FALSE(PlanningSnapshot::Build(
                   grid, Box3(Eigen::Vector3d(0.0001, 0, 0), Eigen::Vector3d(0.002, 0.1, 0.1)))
                   .ok());

  // 100 x 100 x 100 voxels = 13 x 13 x 13 bricks of 512 bytes = 1,124,864 bytes.
  ASSERT_TRUE(grid.SetLogOdds({0, 0, 0}, 1.0f));
  ASSERT_TRUE(grid.SetLogOdds({99, 99, 99}, 1.0f));
  const auto too_big = PlanningSnapshot::BuildOverKnown(grid, 1124863);
  ASSERT_FALSE(too_big.ok());
  EXPECT_THAT(too_big.status().message(), HasSubstr("max_bytes"));
  EXPECT_THAT(too_big.status().message(), HasSubstr("100 x 100 x 100"));
  const auto fits = PlanningSnapshot::BuildOverKnown(grid, 1124864);
  ASSERT_TRUE(fits.ok()) << fits.status().ToString();
  EXPECT_EQ(fits->bytes(), 1124864u);
  EXPECT_EQ(fits->State({99, 99, 99}), VoxelState::kOccupied);
  EXPECT_EQ(fits->State({50, 50, 50}), VoxelState::kUnknown);
  // Absurd boxes fail cleanly instead of allocating.
  const auto huge = PlanningSnapshot::Build(
      grid, Box3(Eigen::Vector3d::Constant(-50.0), Eigen::Vector3d::Constant(50.0)));
  EXPECT_FALSE(huge.ok());
}

// ---- CastRay -----------------------------------------------------------------------------------

TEST(PlanningSnapshotTest, CastRayCountsUpToAndIncludingTheFirstOccupiedVoxel) {
  OccupancyGrid grid;
  // Along +x through voxel centres: free, unknown, free, free, occupied (fruit), free.
  ASSERT_TRUE(grid.SetLogOdds({0, 0, 0}, -1.0f));
  ASSERT_TRUE(grid.SetLogOdds({2, 0, 0}, -1.0f));
  ASSERT_TRUE(grid.SetLogOdds({3, 0, 0}, -1.0f));
  ASSERT_TRUE(grid.SetLogOdds({4, 0, 0}, 1.0f));
  ASSERT_TRUE(grid.SetLogOdds({5, 0, 0}, -1.0f));
  grid.MutableSemantic({4, 0, 0})->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
  const auto snap = PlanningSnapshot::BuildOverKnown(grid);
  ASSERT_TRUE(snap.ok());
  const auto c = [&](double x0, double x1) {
    return snap->CastRay(Eigen::Vector3d(x0, 0.5, 0.5) * kVoxel,
                         Eigen::Vector3d(x1, 0.5, 0.5) * kVoxel);
  };
  // Hits the occupied voxel: visited counts it.
  auto r = c(0.5, 7.5);
  EXPECT_TRUE(r.hit);
  EXPECT_EQ(r.hit_class, 1);
  EXPECT_EQ(r.free, 3u);
  EXPECT_EQ(r.unknown, 1u);
  EXPECT_EQ(r.visited, 5u);
  // Ending inside the occupied voxel: the end voxel is not visited, no hit.
  r = c(0.5, 4.5);
  EXPECT_FALSE(r.hit);
  EXPECT_EQ(r.hit_class, 0);
  EXPECT_EQ(r.free, 3u);
  EXPECT_EQ(r.unknown, 1u);
  EXPECT_EQ(r.visited, 4u);
  // Starting in the occupied voxel: it is the first visited voxel.
  r = c(4.5, 5.5);
  EXPECT_TRUE(r.hit);
  EXPECT_EQ(r.visited, 1u);
  EXPECT_EQ(r.free + r.unknown, 0u);
  // Same voxel: nothing visited.
  r = c(4.2, 4.8);
  EXPECT_EQ(r.visited, 0u);
  EXPECT_FALSE(r.hit);
  // Backwards from outside the box: unknown (outside) voxels are counted too.
  r = c(9.5, 3.5);  // 9, 8, 7, 6 unknown (outside the box), 5 free, 4 hit
  EXPECT_TRUE(r.hit);
  EXPECT_EQ(r.unknown, 4u);
  EXPECT_EQ(r.free, 1u);
  EXPECT_EQ(r.visited, 6u);
  // Entirely outside the box.
  r = snap->CastRay(Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1.05, 1, 1));
  EXPECT_FALSE(r.hit);
  EXPECT_EQ(r.unknown, 10u);
  EXPECT_EQ(r.visited, 10u);
  // A default snapshot sees nothing.
  const PlanningSnapshot none;
  EXPECT_EQ(none.CastRay(Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones()).visited, 0u);
  EXPECT_EQ(none.Cell({0, 0, 0}), 0);
}

TEST(PlanningSnapshotTest, CastRayMatchesBruteForceOnRandomRays) {
  const OccupancyGrid grid = RandomGrid(3);
  const auto over_known = PlanningSnapshot::BuildOverKnown(grid);
  ASSERT_TRUE(over_known.ok());
  const Box3 sub(Eigen::Vector3d(-0.05, -0.03, -0.06), Eigen::Vector3d(0.04, 0.06, 0.02));
  const auto partial = PlanningSnapshot::Build(grid, sub);
  ASSERT_TRUE(partial.ok());
  const auto grid_state = [&](const VoxelKey& k) {
    return std::pair<VoxelState, uint8_t>(grid.State(k), ClassOf(grid, k));
  };
  const auto partial_state = [&](const VoxelKey& k) {
    if (!sub.Contains(k.Center(kVoxel)))
      return std::pair<VoxelState, uint8_t>(VoxelState::kUnknown, 0);
    return std::pair<VoxelState, uint8_t>(grid.State(k), ClassOf(grid, k));
  };
  Rng rng(33);
  int hits = 0, misses = 0, outside_starts = 0;
  for (int i = 0; i < 6000; ++i) {
    Eigen::Vector3d from, to;
    const int mode = i % 4;
    if (mode == 0) {  // inside to inside
      from =
          Eigen::Vector3d(rng.Uniform(-0.1, 0.1), rng.Uniform(-0.1, 0.1), rng.Uniform(-0.1, 0.1));
      to = Eigen::Vector3d(rng.Uniform(-0.1, 0.1), rng.Uniform(-0.1, 0.1), rng.Uniform(-0.1, 0.1));
    } else if (mode == 1) {  // from far outside through the box
      Eigen::Vector3d dir(rng.Normal(), rng.Normal(), rng.Normal());
      dir.normalize();
      from = -0.25 * dir + Eigen::Vector3d(rng.Uniform(-0.03, 0.03), rng.Uniform(-0.03, 0.03), 0);
      to = from + 0.5 * dir;
    } else if (mode == 2) {  // short rays
      from =
          Eigen::Vector3d(rng.Uniform(-0.1, 0.1), rng.Uniform(-0.1, 0.1), rng.Uniform(-0.1, 0.1));
      to = from + Eigen::Vector3d(rng.Uniform(-0.01, 0.01), rng.Uniform(-0.01, 0.01),
                                  rng.Uniform(-0.01, 0.01));
    } else {  // axis-aligned through voxel centres (exact ties at edges)
      const VoxelKey a{static_cast<int32_t>(rng.UniformInt(-25, 25)),
                       static_cast<int32_t>(rng.UniformInt(-25, 25)),
                       static_cast<int32_t>(rng.UniformInt(-25, 25))};
      from = a.Center(kVoxel);
      to = from;
      to[rng.UniformInt(0, 2)] += kVoxel * static_cast<double>(rng.UniformInt(-30, 30));
    }
    outside_starts += !InSnapshot(*over_known, VoxelKey::FromPoint(from, kVoxel));
    const auto got = over_known->CastRay(from, to);
    const auto want = ReferenceCast(from, to, grid_state);
    ASSERT_TRUE(Same(got, want)) << "ray " << i << ": got " << Describe(got) << ", want "
                                 << Describe(want);
    hits += got.hit;
    misses += !got.hit;
    const auto got_partial = partial->CastRay(from, to);
    const auto want_partial = ReferenceCast(from, to, partial_state);
    ASSERT_TRUE(Same(got_partial, want_partial))
        << "ray " << i << " (sub-box): got " << Describe(got_partial) << ", want "
        << Describe(want_partial);
  }
  // The rays exercise both outcomes and start outside the box often.
  EXPECT_GT(hits, 1000);
  EXPECT_GT(misses, 1000);
  EXPECT_GT(outside_starts, 1000);
}

// End points exactly on voxel faces, edges and corners (a power-of-two voxel makes the lattice
// exact): rays whose exhausted axis would cross exactly at the end point go through the guarded
// loop, every other ray through the fast one; both must equal the brute-force walk.
TEST(PlanningSnapshotTest, CastRayMatchesBruteForceWithEndPointsOnVoxelFaces) {
  constexpr double kPow2Voxel = 1.0 / 128.0;  // 7.8125 mm, exact in binary
  const OccupancyGrid grid = RandomGrid(5, kPow2Voxel);
  const auto snap = PlanningSnapshot::BuildOverKnown(grid);
  ASSERT_TRUE(snap.ok());
  const auto grid_state = [&](const VoxelKey& k) {
    return std::pair<VoxelState, uint8_t>(grid.State(k), ClassOf(grid, k));
  };
  Rng rng(71);
  int hits = 0, negative_face_ends = 0;
  for (int i = 0; i < 6000; ++i) {
    Eigen::Vector3d from, to;
    for (int a = 0; a < 3; ++a) {
      // Half the coordinates on a face (an integer multiple of the voxel), half in between.
      const auto coord = [&] {
        const double k = static_cast<double>(rng.UniformInt(-24, 24));
        return rng.Bernoulli(0.5) ? k * kPow2Voxel : (k + rng.Uniform(0.0, 1.0)) * kPow2Voxel;
      };
      from[a] = coord();
      to[a] = coord();
      negative_face_ends += to[a] < from[a] && std::floor(to[a] / kPow2Voxel) * kPow2Voxel == to[a];
    }
    const auto got = snap->CastRay(from, to);
    const auto want = ReferenceCast(from, to, grid_state, kPow2Voxel);
    ASSERT_TRUE(Same(got, want)) << "ray " << i << ": got " << Describe(got) << ", want "
                                 << Describe(want);
    hits += got.hit;
  }
  EXPECT_GT(hits, 500);
  EXPECT_GT(negative_face_ends, 3000);
}

}  // namespace
}  // namespace avp::mapping

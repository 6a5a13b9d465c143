// ObstacleField: options and bounds validation, the max_cells limit, the empty field, the lower
// bound property and accuracy against brute force over the obstacle voxels, the exact EDT against
// a brute-force transform over the cells, unknown voxels in the region of interest and free-space
// spheres.
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/rng.h>
#include <avp/motion/obstacle_field.h>

namespace avp::motion {
namespace {

using mapping::OccupancyGrid;
using mapping::VoxelState;
using ::testing::HasSubstr;

constexpr float kOccupied = 2.0f;
constexpr float kFree = -2.0f;
const double kSqrt3 = std::sqrt(3.0);

/// Distance from p to the cube of voxel k (edge s); 0 inside.
double VoxelDistance(const Eigen::Vector3d& p, const VoxelKey& k, double s) {
  const Eigen::Vector3d lo = Eigen::Vector3d(k.x, k.y, k.z) * s;
  const Eigen::Vector3d hi = lo + Eigen::Vector3d::Constant(s);
  return (lo - p).cwiseMax(p - hi).cwiseMax(0.0).norm();
}

/// Brute force: the distance from p to the nearest of `voxels`; infinity when there is none.
double TrueDistance(const Eigen::Vector3d& p, const std::vector<VoxelKey>& voxels, double s) {
  double d = std::numeric_limits<double>::infinity();
  for (const VoxelKey& k : voxels) d = std::min(d, VoxelDistance(p, k, s));
  return d;
}

Eigen::Vector3d RandomPoint(Rng& rng, const Box3& box) {
  return {rng.Uniform(box.min().x(), box.max().x()), rng.Uniform(box.min().y(), box.max().y()),
          rng.Uniform(box.min().z(), box.max().z())};
}

/// A grid with `count` occupied voxels: half scattered, half in small clusters (leaf-like
/// patches), all with their centre in `region`. Returns the keys set.
std::vector<VoxelKey> AddOccupied(OccupancyGrid& grid, const Box3& region, int count, Rng& rng) {
  std::vector<VoxelKey> keys;
  const double s = grid.voxel_size_m();
  while (static_cast<int>(keys.size()) < count) {
    const VoxelKey k = grid.KeyOf(RandomPoint(rng, region));
    const int patch = keys.size() % 2 == 0 ? 1 : 3;
    for (int dy = 0; dy < patch; ++dy) {
      for (int dx = 0; dx < patch; ++dx) {
        const VoxelKey p{k.x + dx, k.y + dy, k.z};
        if (!region.Contains(p.Center(s)) || grid.State(p) == VoxelState::kOccupied) continue;
        EXPECT_TRUE(grid.SetLogOdds(p, kOccupied));
        keys.push_back(p);
      }
    }
  }
  return keys;
}

// ---- Options, bounds, limits -------------------------------------------------------------------

TEST(ObstacleFieldOptionsTest, DefaultsAndLimitsAreValid) {
  EXPECT_TRUE(ObstacleFieldOptions{}.Validate().ok());
  ObstacleFieldOptions o;
  o.resolution_m = 0.002;
  EXPECT_TRUE(o.Validate().ok());
  o.resolution_m = 0.1;
  o.max_cells = 1;
  EXPECT_TRUE(o.Validate().ok());
}

TEST(ObstacleFieldOptionsTest, ErrorsNameEveryBadValue) {
  ObstacleFieldOptions o;
  o.resolution_m = 0.0;
  Status s = o.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(),
            "invalid obstacle field options: resolution_m (0) must be in [0.002, 0.1]");

  o.resolution_m = std::numeric_limits<double>::quiet_NaN();
  o.max_distance_m = -0.5;
  o.max_cells = 0;
  o.start_clearance_m = -0.01;
  s = o.Validate();
  EXPECT_THAT(s.message(), HasSubstr("resolution_m (nan) must be in [0.002, 0.1]"));
  EXPECT_THAT(s.message(), HasSubstr("start_clearance_m (-0.01) must be finite and >= 0"));
  EXPECT_THAT(s.message(), HasSubstr("max_distance_m (-0.5) must be finite and > 0"));
  EXPECT_THAT(s.message(), HasSubstr("max_cells (0) must be >= 1"));

  o = {};
  o.resolution_m = 0.2;
  o.max_distance_m = std::numeric_limits<double>::infinity();
  o.start_clearance_m = std::numeric_limits<double>::quiet_NaN();
  s = o.Validate();
  EXPECT_THAT(s.message(), HasSubstr("resolution_m (0.2) must be in [0.002, 0.1]"));
  EXPECT_THAT(s.message(), HasSubstr("max_distance_m (inf) must be finite and > 0"));
  EXPECT_THAT(s.message(), HasSubstr("start_clearance_m (nan) must be finite and >= 0"));
}

TEST(ObstacleFieldTest, BuildRefusesBadOptionsBoundsAndFreeSpace) {
  const OccupancyGrid grid;
  const Box3 bounds({-0.1, -0.1, 0.0}, {0.1, 0.1, 0.2});
  ObstacleFieldOptions bad;
  bad.max_distance_m = 0.0;
  auto r = ObstacleField::Build(grid, bounds, bounds, bad);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("max_distance_m (0) must be finite and > 0"));

  r = ObstacleField::Build(grid, bounds, Box3(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(r.status().message(),
            "invalid obstacle field bounds: [empty box] must be a finite, non-empty box");

  r = ObstacleField::Build(grid, bounds, bounds, {},
                           {Sphere{{0.0, 0.0, 0.1}, 0.05}, Sphere{{0.0, 0.0, 0.1}, -1.0}});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("sphere 1 (centre (0, 0, 0.1), radius -1)"));
}

TEST(ObstacleFieldTest, RefusesMoreCellsThanMaxCells) {
  const OccupancyGrid grid;  // 5 mm voxels
  // 0.0012 .. 0.1988 m: 40 whole voxels (0 .. 0.2 m), 20 cells of 1 cm per axis.
  const Box3 bounds(Eigen::Vector3d::Constant(0.0012), Eigen::Vector3d::Constant(0.1988));
  ObstacleFieldOptions o;
  o.max_cells = 7999;
  const auto r = ObstacleField::Build(grid, bounds, bounds, o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(r.status().message(), HasSubstr("needs 8000 cells (20 x 20 x 20)"));
  EXPECT_THAT(r.status().message(), HasSubstr("more than max_cells (7999)"));
  EXPECT_THAT(r.status().message(), HasSubstr(bounds.ToString()));

  o.max_cells = 8000;
  const auto ok = ObstacleField::Build(grid, bounds, bounds, o);
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(ok->dims(), Eigen::Vector3i(20, 20, 20));
  EXPECT_TRUE(ok->origin() == Eigen::Vector3d::Zero());
  EXPECT_TRUE(ok->bounds().min().isApprox(bounds.min()));
  EXPECT_GE(ok->build_ms(), 0.0);
}

TEST(ObstacleFieldTest, EmptyFieldsReportMaxDistance) {
  const ObstacleField none;
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(none.Distance({0.0, 0.0, 0.0}), ObstacleFieldOptions{}.max_distance_m);
  EXPECT_EQ(none.obstacle_cells(), 0);

  // A map with free voxels only and no unknown obstacles: nothing to avoid.
  OccupancyGrid grid;
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(grid.SetLogOdds({i, 0, 0}, kFree));
  const Box3 bounds({-0.05, -0.05, -0.05}, {0.1, 0.05, 0.05});
  ObstacleFieldOptions o;
  o.unknown_is_obstacle = false;
  o.max_distance_m = 0.25;
  const auto field = ObstacleField::Build(grid, bounds, bounds, o);
  ASSERT_TRUE(field.ok()) << field.status().ToString();
  EXPECT_FALSE(field->empty());
  EXPECT_EQ(field->obstacle_cells(), 0);
  EXPECT_EQ(field->unknown_cells(), 0);
  EXPECT_EQ(field->Distance({0.0, 0.0, 0.0}), 0.25);
  EXPECT_EQ(field->Distance({5.0, 0.0, 0.0}), 0.25);
}

// ---- Occupied voxels
// -----------------------------------------------------------------------------

TEST(ObstacleFieldTest, OneVoxelInOneCell) {
  OccupancyGrid grid;          // 5 mm voxels
  const VoxelKey k{4, 7, 10};  // [0.02, 0.025] x [0.035, 0.04] x [0.05, 0.055]
  ASSERT_TRUE(grid.SetLogOdds(k, kOccupied));
  const Box3 bounds({0.001, 0.001, 0.001}, {0.099, 0.099, 0.099});
  ObstacleFieldOptions o;
  o.unknown_is_obstacle = false;
  const auto field = ObstacleField::Build(grid, bounds, bounds, o);
  ASSERT_TRUE(field.ok()) << field.status().ToString();
  EXPECT_EQ(field->dims(), Eigen::Vector3i(10, 10, 10));
  EXPECT_EQ(field->obstacle_cells(), 1);  // cell (2, 3, 5) holds the whole voxel
  EXPECT_EQ(field->Distance(k.Center(0.005)), 0.0);
  // 5 cells along x from the obstacle cell's centre: 5 cm − half a diagonal.
  const Eigen::Vector3d p(0.075, 0.035, 0.055);
  EXPECT_NEAR(field->Distance(p), 0.05 - 0.005 * kSqrt3, 1e-6);
  EXPECT_LE(field->Distance(p), VoxelDistance(p, k, 0.005));

  // At 7.5 mm cells the voxel, [4, 5] x [7, 8] x [10, 11] voxels from the origin, is
  // [2.67, 3.33] x [4.67, 5.33] x [6.67, 7.33] cells: it overlaps two cells on every axis.
  o.resolution_m = 0.0075;
  const auto finer = ObstacleField::Build(grid, bounds, bounds, o);
  ASSERT_TRUE(finer.ok());
  EXPECT_EQ(finer->obstacle_cells(), 8);
}

TEST(ObstacleFieldTest, OccupiedVoxelsOutsideTheBoundsAreIgnored) {
  OccupancyGrid grid;
  const Box3 bounds({-0.1013, -0.1013, 0.0007}, {0.1013, 0.1013, 0.2007});
  ASSERT_TRUE(grid.SetLogOdds(grid.KeyOf({0.12, 0.0, 0.1}), kOccupied));  // 2 cm outside
  ASSERT_TRUE(grid.SetLogOdds(grid.KeyOf({-0.05, 0.0, 0.1}), kOccupied));
  ObstacleFieldOptions o;
  o.unknown_is_obstacle = false;
  const auto field = ObstacleField::Build(grid, bounds, bounds, o);
  ASSERT_TRUE(field.ok());
  EXPECT_EQ(field->obstacle_cells(), 1);
  EXPECT_GT(field->Distance({0.1, 0.0, 0.1}), 0.09);  // 2 cm from the ignored voxel
}

/// The lower bound property and the accuracy against brute force, for several resolutions
/// (coarser than, equal to, not a multiple of and finer than the 5 mm voxels).
class ObstacleFieldAccuracyTest : public ::testing::TestWithParam<double> {};

TEST_P(ObstacleFieldAccuracyTest, IsALowerBoundAndWithinTwoCellDiagonalsOfBruteForce) {
  const double res = GetParam();
  Rng rng(20261207);
  OccupancyGrid grid;
  const double s = grid.voxel_size_m();
  const Box3 bounds({-0.1013, -0.0987, 0.0031}, {0.1013, 0.1191, 0.2044});
  // Voxels inside and a little outside the bounds: those whose centre is outside are ignored.
  const std::vector<VoxelKey> all = AddOccupied(grid, bounds.Inflated(0.01), 100, rng);
  std::vector<VoxelKey> in;
  for (const VoxelKey& k : all)
    if (bounds.Contains(k.Center(s))) in.push_back(k);
  ASSERT_GT(in.size(), 50u);
  ASSERT_LT(in.size(), all.size());

  ObstacleFieldOptions o;
  o.resolution_m = res;
  o.unknown_is_obstacle = false;
  o.max_distance_m = 0.15;
  const auto built = ObstacleField::Build(grid, bounds, bounds, o);
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  const ObstacleField& field = *built;
  EXPECT_GT(field.obstacle_cells(), 0);
  EXPECT_EQ(field.unknown_cells(), 0);

  // Random points in and around the bounds (about half of them outside).
  const Box3 grid_box(field.origin(), field.origin() + field.dims().cast<double>() * res);
  int inside = 0;
  double error_sum = 0.0;
  for (int i = 0; i < 4000; ++i) {
    const Eigen::Vector3d p = RandomPoint(rng, bounds.Inflated(0.03));
    const double truth = TrueDistance(p, in, s);
    const double d = field.Distance(p);
    ASSERT_LE(d, truth + 1e-9) << "p = " << p.transpose() << " res " << res;
    ASSERT_GE(d, 0.0);
    ASSERT_LE(d, o.max_distance_m);
    if (grid_box.Contains(p)) {
      ++inside;
      const double error = std::min(truth, o.max_distance_m) - d;
      ASSERT_LE(error, 2.0 * kSqrt3 * res + 1e-6) << "p = " << p.transpose() << " res " << res;
      error_sum += error;
    }
  }
  EXPECT_GT(inside, 1500);
  EXPECT_LT(error_sum / inside, 1.5 * res);  // measured 0.6 - 1.3 cells
  // At cell centres the error is at most one cell diagonal.
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3i c(static_cast<int>(rng.UniformInt(0, field.dims().x() - 1)),
                            static_cast<int>(rng.UniformInt(0, field.dims().y() - 1)),
                            static_cast<int>(rng.UniformInt(0, field.dims().z() - 1)));
    const Eigen::Vector3d p = field.origin() + (c.cast<double>().array() + 0.5).matrix() * res;
    const double truth = TrueDistance(p, in, s);
    const double d = field.Distance(p);
    ASSERT_LE(d, truth + 1e-9);
    ASSERT_LE(std::min(truth, o.max_distance_m) - d, kSqrt3 * res + 1e-6) << c.transpose();
  }
  // Far outside: still a lower bound, and not a trivial one.
  const Eigen::Vector3d far(0.5, 0.0, 0.1);
  EXPECT_LE(field.Distance(far), TrueDistance(far, in, s));
  EXPECT_EQ(field.Distance(far), o.max_distance_m);
  EXPECT_EQ(field.Distance({std::nan(""), 0.0, 0.0}), 0.0);
}

INSTANTIATE_TEST_SUITE_P(Resolutions, ObstacleFieldAccuracyTest,
                         ::testing::Values(0.01, 0.005, 0.0075, 0.003, 0.02));

TEST(ObstacleFieldTest, CellValuesMatchABruteForceTransformOverTheCells) {
  // The separable EDT against min over obstacle cells of |centre − centre'| − half a diagonal,
  // on a grid with distances beyond the cap and lines without any obstacle.
  Rng rng(5);
  OccupancyGrid grid;
  const Box3 bounds({-0.0613, -0.0513, 0.0012}, {0.0913, 0.0513, 0.1412});
  AddOccupied(grid, Box3({-0.06, -0.05, 0.0}, {0.0, 0.05, 0.1}), 25, rng);
  ObstacleFieldOptions o;
  o.resolution_m = 0.01;
  o.unknown_is_obstacle = false;
  o.max_distance_m = 0.08;
  const auto field = ObstacleField::Build(grid, bounds, bounds, o);
  ASSERT_TRUE(field.ok());
  const Eigen::Vector3i dims = field->dims();
  std::vector<Eigen::Vector3d> centres, obstacles;
  for (int z = 0; z < dims.z(); ++z) {
    for (int y = 0; y < dims.y(); ++y) {
      for (int x = 0; x < dims.x(); ++x) {
        const Eigen::Vector3d c =
            field->origin() + (Eigen::Vector3d(x, y, z).array() + 0.5).matrix() * 0.01;
        centres.push_back(c);
        // Obstacle cells are exactly the zeros: a neighbour is >= (1 − √3/2) cells away.
        if (field->Distance(c) == 0.0) obstacles.push_back(c);
      }
    }
  }
  EXPECT_EQ(static_cast<int64_t>(obstacles.size()), field->obstacle_cells());
  for (const Eigen::Vector3d& c : centres) {
    double nearest = std::numeric_limits<double>::infinity();
    for (const Eigen::Vector3d& q : obstacles) nearest = std::min(nearest, (c - q).norm());
    const double expected = std::clamp(nearest - 0.005 * kSqrt3, 0.0, o.max_distance_m);
    ASSERT_NEAR(field->Distance(c), expected, 1e-6) << c.transpose();
  }
}

// ---- Unknown voxels and free space -----------------------------------------------------------

/// A map whose ROI is observed (free) for x < 0.02 and unknown beyond (partly allocated blocks
/// with unknown voxels, partly blocks never allocated), with one occupied voxel in the known part
/// and one in the unknown part.
struct UnknownScene {
  OccupancyGrid grid;
  // Grown to whole voxels: origin (-0.1, -0.1, 0), cells aligned with the ROI's faces.
  Box3 bounds{Eigen::Vector3d(-0.0987, -0.0987, 0.0013), Eigen::Vector3d(0.1013, 0.1013, 0.2013)};
  Box3 roi{Eigen::Vector3d(-0.06, -0.06, 0.04), Eigen::Vector3d(0.06, 0.06, 0.16)};
  VoxelKey known_occupied{-6, 0, 20};   // centre (-0.0275, 0.0025, 0.1025)
  VoxelKey unknown_occupied{8, 2, 20};  // centre (0.0425, 0.0125, 0.1025)
  std::vector<VoxelKey> unknown;        // unknown voxels with their centre in roi ∩ bounds

  UnknownScene() {
    const double s = grid.voxel_size_m();
    for (int z = 0; z < 44; ++z) {
      for (int y = -24; y < 24; ++y) {
        for (int x = -24; x < 24; ++x) {
          const VoxelKey k{x, y, z};
          const Eigen::Vector3d c = k.Center(s);
          if (!roi.Contains(c)) continue;
          if (c.x() < 0.02) {
            EXPECT_TRUE(grid.SetLogOdds(k, kFree));
          } else if (!(k == unknown_occupied)) {
            unknown.push_back(k);
          }
        }
      }
    }
    EXPECT_TRUE(grid.SetLogOdds(known_occupied, kOccupied));
    EXPECT_TRUE(grid.SetLogOdds(unknown_occupied, kOccupied));
  }
};

TEST(ObstacleFieldTest, UnknownVoxelsInTheRoiAreObstaclesWhenAsked) {
  UnknownScene scene;
  const double s = scene.grid.voxel_size_m();
  ObstacleFieldOptions off;
  off.unknown_is_obstacle = false;
  const auto known_only = ObstacleField::Build(scene.grid, scene.roi, scene.bounds, off);
  ASSERT_TRUE(known_only.ok());
  EXPECT_EQ(known_only->obstacle_cells(), 2);
  EXPECT_EQ(known_only->unknown_cells(), 0);
  const Eigen::Vector3d in_unknown(0.045, -0.03, 0.07);
  EXPECT_GT(known_only->Distance(in_unknown), 0.025);

  const auto built = ObstacleField::Build(scene.grid, scene.roi, scene.bounds, {});
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  const ObstacleField& field = *built;
  // The unknown slab x in [0.02, 0.06], |y| <= 0.06, z in [0.04, 0.16] at 1 cm: 4 x 12 x 12.
  EXPECT_EQ(field.unknown_cells(), 4 * 12 * 12 - 1);
  EXPECT_EQ(field.obstacle_cells(), 4 * 12 * 12 + 1);
  EXPECT_EQ(field.Distance(in_unknown), 0.0);
  EXPECT_EQ(field.Distance(scene.unknown_occupied.Center(s)), 0.0);
  // The observed part of the ROI is free; so is the unknown space outside the ROI.
  EXPECT_GT(field.Distance({-0.04, -0.04, 0.06}), 0.03);
  EXPECT_GT(field.Distance({0.09, 0.09, 0.01}), 0.03);
  EXPECT_GT(field.Distance({0.05, 0.05, 0.19}), 0.015);

  // Lower bound over every obstacle voxel, occupied or unknown.
  std::vector<VoxelKey> obstacles = scene.unknown;
  obstacles.push_back(scene.known_occupied);
  obstacles.push_back(scene.unknown_occupied);
  Rng rng(11);
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d p = RandomPoint(rng, scene.bounds.Inflated(0.03));
    ASSERT_LE(field.Distance(p), TrueDistance(p, obstacles, s) + 1e-9) << p.transpose();
  }
}

TEST(ObstacleFieldTest, FreeSpaceClearsUnknownCellsButNotOccupiedOnes) {
  UnknownScene scene;
  const double s = scene.grid.voxel_size_m();
  const auto before = ObstacleField::Build(scene.grid, scene.roi, scene.bounds, {});
  ASSERT_TRUE(before.ok());
  // The arm swept a 4 cm sphere around the unknown occupied voxel.
  const Sphere swept{scene.unknown_occupied.Center(s), 0.04};
  const auto after = ObstacleField::Build(scene.grid, scene.roi, scene.bounds, {}, {swept});
  ASSERT_TRUE(after.ok()) << after.status().ToString();
  EXPECT_LT(after->unknown_cells(), before->unknown_cells());
  EXPECT_EQ(before->obstacle_cells() - after->obstacle_cells(),
            before->unknown_cells() - after->unknown_cells());
  // The occupied voxel stays an obstacle; the swept unknown space around it does not.
  EXPECT_EQ(after->Distance(scene.unknown_occupied.Center(s)), 0.0);
  // Two cells above the occupied voxel's cell (14, 11, 10): the nearest obstacles are that cell
  // and the unknown cells beyond the sphere, both two cells away.
  const Eigen::Vector3d beside(0.045, 0.015, 0.125);
  EXPECT_EQ(before->Distance(beside), 0.0);
  EXPECT_NEAR(after->Distance(beside), 0.02 - 0.005 * kSqrt3, 1e-6);
  // Cells left unknown keep their place: a point in the unknown slab away from the sphere.
  EXPECT_EQ(after->Distance({0.045, -0.045, 0.05}), 0.0);
  // Free space does not clear anything when unknown voxels are not obstacles.
  ObstacleFieldOptions off;
  off.unknown_is_obstacle = false;
  const auto known_only = ObstacleField::Build(scene.grid, scene.roi, scene.bounds, off, {swept});
  ASSERT_TRUE(known_only.ok());
  EXPECT_EQ(known_only->obstacle_cells(), 2);
  EXPECT_EQ(known_only->Distance(scene.unknown_occupied.Center(s)), 0.0);
}

TEST(ObstacleFieldTest, AnRoiOutsideTheBoundsAddsNothing) {
  UnknownScene scene;
  const Box3 far_roi({1.0, 1.0, 1.0}, {1.2, 1.2, 1.2});
  const auto field = ObstacleField::Build(scene.grid, far_roi, scene.bounds, {});
  ASSERT_TRUE(field.ok());
  EXPECT_EQ(field->obstacle_cells(), 2);
  EXPECT_EQ(field->unknown_cells(), 0);
  const auto empty_roi = ObstacleField::Build(scene.grid, Box3(), scene.bounds, {});
  ASSERT_TRUE(empty_roi.ok());
  EXPECT_EQ(empty_roi->obstacle_cells(), 2);
}

}  // namespace
}  // namespace avp::motion

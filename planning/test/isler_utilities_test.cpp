// Isler et al. utilities: each utility on hand-computed rays, the exclusive visibility product,
// the proximity field against brute force, fast == slow evaluators on random rays and views over
// random maps, and the IslerPlanner's ranking.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/mapping/sensor_model.h>
#include <avp/planning/isler_utilities.h>
#include <avp/robot/arm_model.h>

namespace avp::planning {
namespace {

using ::testing::HasSubstr;
using U = IslerUtility;

mapping::SemanticMap MakeMap(double voxel_size_m) {
  mapping::MapOptions options;
  options.grid.voxel_size_m = voxel_size_m;
  return mapping::SemanticMap(options);
}

/// Sets a voxel to occupancy probability p (stored as log-odds).
void SetP(mapping::SemanticMap& map, const VoxelKey& k, double p) {
  ASSERT_TRUE(map.grid().SetLogOdds(k, mapping::LogOdds(p)));
}

struct HandRay {
  mapping::SemanticMap map = MakeMap(0.01);
  Eigen::Vector3d from = VoxelKey{0, 0, 0}.Center(0.01);
  Eigen::Vector3d to = VoxelKey{10, 0, 0}.Center(0.01);
};

/// The ray of the hand computations: x_0 free (p 0.2), x_1 and x_2 unknown (0.5), x_3 occupied
/// (0.8), then an unknown voxel and an occupied one that the ray never reaches.
HandRay MakeHandRay() {
  HandRay r;
  SetP(r.map, {0, 0, 0}, 0.2);
  SetP(r.map, {3, 0, 0}, 0.8);
  SetP(r.map, {6, 0, 0}, 0.9);
  return r;
}

IslerRayGain Fast(U u, const mapping::SemanticMap& map, const Eigen::Vector3d& from,
                  const Eigen::Vector3d& to, double d_max = 0.02) {
  const auto grid = GainGrid::Build(map, SemanticClass::kFruit, Box3());
  EXPECT_TRUE(grid.ok());
  const auto prox = ProximityField::Build(map, d_max);
  EXPECT_TRUE(prox.ok());
  return EvaluateIslerRay(u, *grid, &*prox, from, to);
}

IslerRayGain Slow(U u, const mapping::SemanticMap& map, const Eigen::Vector3d& from,
                  const Eigen::Vector3d& to, double d_max = 0.02) {
  return EvaluateIslerRayReference(u, map, SemanticClass::kFruit, Box3(), d_max, from, to);
}

TEST(IslerUtilitiesTest, BinaryEntropyInBits) {
  EXPECT_DOUBLE_EQ(BinaryEntropyBits(0.5), 1.0);
  EXPECT_NEAR(BinaryEntropyBits(0.2), 0.7219280948873623, 1e-15);
  EXPECT_NEAR(BinaryEntropyBits(0.8), 0.7219280948873623, 1e-15);
  EXPECT_EQ(BinaryEntropyBits(0.0), 0.0);
  EXPECT_EQ(BinaryEntropyBits(1.0), 0.0);
  EXPECT_EQ(BinaryEntropyBits(-0.1), 0.0);
  EXPECT_TRUE(std::isnan(BinaryEntropyBits(std::nan(""))));
}

// x_0 free 0.2, x_1 unknown, x_2 unknown, x_3 occupied 0.8 (the ray ends there).
// H_b: 0.7219281 (0.2 and 0.8), 1 (0.5). Exclusive visibility: 1, 0.8, 0.4, 0.2.
TEST(IslerUtilitiesTest, EachUtilityOnAHandComputedRay) {
  const HandRay r = MakeHandRay();
  struct Case {
    U u;
    double gain;
    int64_t voxels;
  };
  const Case cases[] = {
      // AE: (0.7219281 + 1 + 1 + 0.7219281) / 4 voxels, over the one hit ray.
      {U::kAverageEntropy, 3.4438561897747246, 4},
      // OA: 1 * 0.7219281 + 0.8 * 1 + 0.4 * 1 + 0.2 * 0.7219281.
      {U::kOcclusionAware, 2.0663137138648348, 0},
      // UV: the unknown ones only: 0.8 + 0.4.
      {U::kUnobservedVoxel, 1.2, 0},
      // RSV: the occupied x_3 comes right after the unknown x_2.
      {U::kRearSideVoxel, 1.0, 0},
      // RSE: the unknown run x_1, x_2 (0.8 + 0.4) plus the hit voxel's 0.2 * 0.7219281.
      {U::kRearSideEntropy, 1.3443856189774725, 0},
      // PC (d_max 0.02 m): x_2 is 0.01 m from x_3 (adds 0.01), x_1 0.02 m (adds 0).
      {U::kProximityCount, 0.01, 0},
  };
  for (const Case& c : cases) {
    for (const IslerRayGain& g : {Fast(c.u, r.map, r.from, r.to), Slow(c.u, r.map, r.from, r.to)}) {
      EXPECT_NEAR(g.gain, c.gain, 1e-7) << ToString(c.u);
      EXPECT_EQ(g.voxels, c.voxels) << ToString(c.u);
      EXPECT_TRUE(g.hit) << ToString(c.u);
    }
  }
  EXPECT_NEAR(CombineIslerRays(U::kAverageEntropy, {Fast(U::kAverageEntropy, r.map, r.from, r.to)}),
              0.8609640474436812, 1e-7);
  // With a larger d_max both unknown voxels count: (0.03 - 0.02) + (0.03 - 0.01).
  EXPECT_NEAR(Fast(U::kProximityCount, r.map, r.from, r.to, 0.03).gain, 0.03, 1e-12);
  EXPECT_NEAR(Slow(U::kProximityCount, r.map, r.from, r.to, 0.03).gain, 0.03, 1e-12);
}

TEST(IslerUtilitiesTest, VisibilityIsTheExclusiveProduct) {
  // The reference implementation's p_vis *= p_occ would give OA = 1 * 0.7219 + 0.2 + 0.1 +
  // 0.05 * 0.7219 = 1.058 and UV = 0.3 on the hand ray; the inclusive product (1 - p) would
  // give OA = 0.8 * 0.7219 + 0.4 + 0.2 + 0.04 * 0.7219 = 1.206.
  const HandRay r = MakeHandRay();
  EXPECT_GT(Fast(U::kOcclusionAware, r.map, r.from, r.to).gain, 2.06);
  EXPECT_GT(Fast(U::kUnobservedVoxel, r.map, r.from, r.to).gain, 1.19);
  // Ten unknown voxels in empty space: Σ_{i<10} 0.5^i = 2 - 2^-9; the first voxel counts fully.
  const mapping::SemanticMap empty = MakeMap(0.01);
  for (const U u : {U::kOcclusionAware, U::kUnobservedVoxel}) {
    const IslerRayGain f = Fast(u, empty, r.from, r.to);
    EXPECT_DOUBLE_EQ(f.gain, 1.998046875) << ToString(u);
    EXPECT_FALSE(f.hit);
    EXPECT_DOUBLE_EQ(Slow(u, empty, r.from, r.to).gain, 1.998046875) << ToString(u);
  }
  // A one-voxel ray: p_vis(x_0) = 1.
  const Eigen::Vector3d next = VoxelKey{1, 0, 0}.Center(0.01);
  EXPECT_DOUBLE_EQ(Fast(U::kUnobservedVoxel, empty, r.from, next).gain, 1.0);
}

TEST(IslerUtilitiesTest, RaysThatHitNothingAndRaysThatStartOnASurface) {
  mapping::SemanticMap map = MakeMap(0.01);
  SetP(map, {0, 0, 0}, 0.2);
  SetP(map, {1, 0, 0}, 0.3);
  const Eigen::Vector3d from = VoxelKey{0, 0, 0}.Center(0.01);
  const Eigen::Vector3d to = VoxelKey{4, 0, 0}.Center(0.01);
  // free 0.2, free 0.3, unknown, unknown; no hit: AE, RSV, RSE give nothing.
  for (const U u : {U::kAverageEntropy, U::kRearSideVoxel, U::kRearSideEntropy}) {
    const IslerRayGain g = Fast(u, map, from, to);
    EXPECT_EQ(g.gain, 0.0) << ToString(u);
    EXPECT_EQ(g.voxels, 0) << ToString(u);
    EXPECT_FALSE(g.hit);
  }
  // UV: the unknowns after two free voxels: 0.8 * 0.7 * (1 + 0.5).
  const double p0 = ReadGainVoxel(map, {0, 0, 0}, SemanticClass::kFruit, Box3(), 0.0).p_occ;
  const double p1 = ReadGainVoxel(map, {1, 0, 0}, SemanticClass::kFruit, Box3(), 0.0).p_occ;
  EXPECT_NEAR(Fast(U::kUnobservedVoxel, map, from, to).gain, (1 - p0) * (1 - p1) * 1.5, 1e-12);
  EXPECT_NEAR(Fast(U::kUnobservedVoxel, map, from, to).gain, 0.8 * 0.7 * 1.5, 3e-3);  // 1/255 steps
  // An occupied first voxel: no predecessor, so no rear side; RSE counts the hit voxel alone.
  mapping::SemanticMap wall = MakeMap(0.01);
  SetP(wall, {0, 0, 0}, 0.8);
  EXPECT_EQ(Fast(U::kRearSideVoxel, wall, from, to).gain, 0.0);
  EXPECT_NEAR(Fast(U::kRearSideEntropy, wall, from, to).gain, 0.7219280948873623, 1e-7);
  EXPECT_EQ(Fast(U::kRearSideEntropy, wall, from, to).voxels, 0);
  // A free voxel between the unknown run and the hit breaks the run.
  mapping::SemanticMap broken = MakeMap(0.01);
  SetP(broken, {2, 0, 0}, 0.2);
  SetP(broken, {3, 0, 0}, 0.8);
  const IslerRayGain rse = Fast(U::kRearSideEntropy, broken, from, VoxelKey{8, 0, 0}.Center(0.01));
  // p_vis at x_3: 0.5 * 0.5 * 0.8 = 0.2; only the hit voxel's term remains.
  EXPECT_NEAR(rse.gain, 0.2 * 0.7219280948873623, 1e-7);
  EXPECT_EQ(Fast(U::kRearSideVoxel, broken, from, VoxelKey{8, 0, 0}.Center(0.01)).gain, 0.0);
}

/// A random map: ~35 % known voxels over a 40^3 region, 4 % of them occupied.
mapping::SemanticMap RandomMap(uint64_t seed, double voxel_size_m) {
  mapping::SemanticMap map = MakeMap(voxel_size_m);
  Rng rng(seed);
  for (int32_t z = -20; z < 20; ++z) {
    for (int32_t y = -20; y < 20; ++y) {
      for (int32_t x = -20; x < 20; ++x) {
        if (!rng.Bernoulli(0.35)) continue;
        const bool occupied = rng.Bernoulli(0.04);
        const float v = occupied ? static_cast<float>(rng.Uniform(0.0, 3.4))
                                 : static_cast<float>(rng.Uniform(-1.9, -0.01));
        EXPECT_TRUE(map.grid().SetLogOdds({x, y, z}, v));
        if (occupied && rng.Bernoulli(0.3)) {
          mapping::SemanticCell* c = map.grid().MutableSemantic({x, y, z});
          c->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
          c->confidence = static_cast<float>(rng.Uniform01());
        }
      }
    }
  }
  return map;
}

TEST(IslerUtilitiesTest, ProximityFieldMatchesBruteForce) {
  const mapping::SemanticMap map = RandomMap(1, 0.005);
  const auto field = ProximityField::Build(map, 0.015);  // 3 voxels
  ASSERT_TRUE(field.ok()) << field.status().ToString();
  EXPECT_EQ(field->max_distance_m(), 0.015);
  size_t within = 0, checked = 0;
  for (int32_t z = -25; z < 25; z += 2) {
    for (int32_t y = -25; y < 25; ++y) {
      for (int32_t x = -25; x < 25; ++x) {
        const VoxelKey k{x, y, z};
        int64_t best = -1;
        for (int dz = -3; dz <= 3; ++dz) {
          for (int dy = -3; dy <= 3; ++dy) {
            for (int dx = -3; dx <= 3; ++dx) {
              const int64_t d2 = dx * dx + dy * dy + dz * dz;
              if (d2 > 9 || (best >= 0 && d2 >= best)) continue;
              if (map.State({x + dx, y + dy, z + dz}) == mapping::VoxelState::kOccupied) best = d2;
            }
          }
        }
        const std::optional<double> d = field->DistanceToOccupied(k);
        ASSERT_EQ(d.has_value(), best >= 0) << x << " " << y << " " << z;
        if (d) {
          EXPECT_EQ(*d, 0.005 * std::sqrt(static_cast<double>(best)));
          ++within;
        }
        ++checked;
      }
    }
  }
  EXPECT_GT(within, checked / 4);
  EXPECT_LT(within, checked);
  // Exactly at d_max (3 voxels along an axis) is within, beyond it is not.
  mapping::SemanticMap one = MakeMap(0.005);
  SetP(one, {0, 0, 0}, 0.9);
  const auto f1 = ProximityField::Build(one, 0.015);
  ASSERT_TRUE(f1.ok());
  EXPECT_NEAR(*f1->DistanceToOccupied({3, 0, 0}), 0.015, 1e-15);
  EXPECT_FALSE(f1->DistanceToOccupied({3, 1, 0}).has_value());
  EXPECT_EQ(*f1->DistanceToOccupied({0, 0, 0}), 0.0);
  EXPECT_FALSE(f1->DistanceToOccupied({100, 0, 0}).has_value());
  // Bad sizes.
  EXPECT_THAT(ProximityField::Build(one, -1.0).status().message(),
              HasSubstr("max_distance_m (-1)"));
  EXPECT_FALSE(ProximityField::Build(one, 0.015, 10).ok());
  EXPECT_TRUE(ProximityField::Build(MakeMap(0.005), 0.015).ok());  // empty: nothing near
}

TEST(IslerUtilitiesTest, AProximityFieldCroppedToARegionIsExactInsideIt) {
  const mapping::SemanticMap map = RandomMap(1, 0.005);
  // A region of 20 x 12 x 10 voxels inside the map; a voxel far outside it.
  const Box3 region(Eigen::Vector3d(-0.05, -0.03, -0.02), Eigen::Vector3d(0.05, 0.03, 0.03));
  const auto full = ProximityField::Build(map, 0.015);
  const auto cropped = ProximityField::Build(map, 0.015, size_t{1} << 30, region);
  ASSERT_TRUE(full.ok() && cropped.ok());
  size_t inside = 0, near = 0;
  for (int32_t z = -25; z < 25; ++z) {
    for (int32_t y = -25; y < 25; ++y) {
      for (int32_t x = -25; x < 25; ++x) {
        const VoxelKey k{x, y, z};
        if (!region.Contains(k.Center(0.005))) continue;
        ++inside;
        ASSERT_EQ(cropped->DistanceToOccupied(k), full->DistanceToOccupied(k))
            << x << " " << y << " " << z;
        near += full->DistanceToOccupied(k).has_value() ? 1 : 0;
      }
    }
  }
  EXPECT_GT(inside, 2000u);
  EXPECT_GT(near, inside / 4);
  // Far from the region the cropped field knows nothing: it was not built there.
  const VoxelKey far{-24, -24, -24};
  ASSERT_FALSE(region.Contains(far.Center(0.005)));
  size_t far_known = 0, far_known_full = 0;
  for (int32_t z = -25; z < -15; ++z) {
    for (int32_t y = -25; y < -15; ++y) {
      for (int32_t x = -25; x < -15; ++x) {
        far_known += cropped->DistanceToOccupied({x, y, z}).has_value() ? 1 : 0;
        far_known_full += full->DistanceToOccupied({x, y, z}).has_value() ? 1 : 0;
      }
    }
  }
  EXPECT_EQ(far_known, 0u);
  EXPECT_GT(far_known_full, 0u);
}

TEST(IslerUtilitiesTest, FastEqualsSlowOnRandomRays) {
  const mapping::SemanticMap map = RandomMap(2, 0.005);
  const auto grid = GainGrid::Build(map, SemanticClass::kFruit, Box3());
  ASSERT_TRUE(grid.ok());
  const double d_max = 0.015;
  const auto prox = ProximityField::Build(map, d_max);
  ASSERT_TRUE(prox.ok());
  Rng rng(3);
  for (const U u : AllIslerUtilities()) {
    int hits = 0, nonzero = 0;
    for (int i = 0; i < 300; ++i) {
      const Eigen::Vector3d from(rng.Uniform(-0.13, 0.13), rng.Uniform(-0.13, 0.13),
                                 rng.Uniform(-0.13, 0.13));
      const Eigen::Vector3d to(rng.Uniform(-0.13, 0.13), rng.Uniform(-0.13, 0.13),
                               rng.Uniform(-0.13, 0.13));
      const IslerRayGain f = EvaluateIslerRay(u, *grid, &*prox, from, to);
      const IslerRayGain s =
          EvaluateIslerRayReference(u, map, SemanticClass::kFruit, Box3(), d_max, from, to);
      ASSERT_NEAR(f.gain, s.gain, 1e-9 * std::max(1.0, std::abs(s.gain)))
          << ToString(u) << " ray " << i;
      ASSERT_EQ(f.voxels, s.voxels) << ToString(u) << " ray " << i;
      ASSERT_EQ(f.hit, s.hit) << ToString(u) << " ray " << i;
      hits += f.hit;
      nonzero += f.gain != 0.0;
    }
    EXPECT_GT(hits, 50) << ToString(u);
    EXPECT_GT(nonzero, 30) << ToString(u);
  }
}

TEST(IslerUtilitiesTest, FastEqualsSlowOnViews) {
  const mapping::SemanticMap map = RandomMap(4, 0.005);
  const auto grid = GainGrid::Build(map, SemanticClass::kFruit, Box3());
  ASSERT_TRUE(grid.ok());
  IslerRayOptions options;
  options.max_range_m = 0.3;
  options.ray_stride_px = 48;
  options.proximity_max_distance_m = 0.01;
  const auto prox = ProximityField::Build(map, options.proximity_max_distance_m);
  ASSERT_TRUE(prox.ok());
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  const RigidTransform views[] = {
      RigidTransform::LookAt(Eigen::Vector3d(-0.2, 0.01, 0.02), Eigen::Vector3d::Zero()),
      RigidTransform::LookAt(Eigen::Vector3d(0.05, -0.15, 0.12), Eigen::Vector3d(0, 0, 0.01)),
  };
  for (const RigidTransform& X_WC : views) {
    for (const U u : AllIslerUtilities()) {
      const double fast = IslerViewGain(u, *grid, &*prox, X_WC, K, options);
      const double slow =
          IslerViewGainReference(u, map, SemanticClass::kFruit, Box3(), X_WC, K, options);
      EXPECT_NEAR(fast, slow, 1e-9 * std::max(1.0, std::abs(slow))) << ToString(u);
      EXPECT_GT(fast, 0.0) << ToString(u);
    }
  }
  // PC without a proximity field is a precondition failure.
  EXPECT_THROW(IslerViewGain(U::kProximityCount, *grid, nullptr, views[0], K, options), Error);
}

TEST(IslerUtilitiesTest, NamesAndOptions) {
  EXPECT_EQ(AllIslerUtilities().size(), 6u);
  for (const U u : AllIslerUtilities()) EXPECT_EQ(IslerUtilityFromString(ToString(u)), u);
  EXPECT_EQ(IslerUtilityFromString("oa"), U::kOcclusionAware);
  EXPECT_EQ(IslerUtilityFromString("OA"), std::nullopt);
  for (const U u : AllIslerUtilities()) {
    IslerPlannerOptions o;
    o.utility = u;
    EXPECT_EQ(IslerPlanner(o).name(), "isler-" + std::string(ToString(u)));
  }
  IslerPlannerOptions bad;
  bad.cost_weight = -1.0;
  bad.rays.ray_stride_px = 0;
  EXPECT_THAT(bad.Validate().message(), HasSubstr("cost_weight (-1)"));
  EXPECT_THAT(bad.Validate().message(), HasSubstr("rays.ray_stride_px (0 px) must be >= 1"));
  EXPECT_THROW(IslerPlanner{bad}, Error);
}

const robot::ArmModel& Arm() {
  static const robot::ArmModel model = robot::LoadDefaultArm(AVP_CONFIG_DIR).value();
  return model;
}

/// A fruit cluster behind a partial leaf wall, partly observed: free space in front of it.
mapping::SemanticMap PlantMap() {
  mapping::SemanticMap map = MakeMap(0.01);
  for (int z = 60; z < 66; ++z) {
    for (int y = -3; y < 3; ++y) {
      for (int x = 70; x < 76; ++x) {
        SetP(map, {x, y, z}, 0.9);
        mapping::SemanticCell* c = map.grid().MutableSemantic({x, y, z});
        c->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
        c->confidence = 0.6f;
      }
    }
  }
  for (int z = 55; z < 75; ++z) {
    for (int y = -12; y < 0; ++y) SetP(map, {62, y, z}, 0.8);
  }
  for (int z = 50; z < 80; ++z) {
    for (int y = -15; y < 15; ++y) {
      for (int x = 40; x < 60; ++x) SetP(map, {x, y, z}, 0.3);
    }
  }
  return map;
}

TEST(IslerUtilitiesTest, PlannerRanksByWeightedLinearUtilityDeterministically) {
  const mapping::SemanticMap map = PlantMap();
  PlanningRequest request;
  request.map = &map;
  request.arm = &Arm();
  request.q_start = Arm().home_joints();
  request.q_current = request.q_start;
  request.X_WC_start = Arm().CameraPose(request.q_start);
  request.X_WC_current = request.X_WC_start;
  request.K = CameraIntrinsics::RealSenseD435();
  request.roi = Box3(Eigen::Vector3d(0.55, -0.2, 0.45), Eigen::Vector3d(0.9, 0.2, 0.85));
  request.fused_views = {request.X_WC_start};
  for (const U u : {U::kOcclusionAware, U::kRearSideEntropy, U::kProximityCount}) {
    IslerPlannerOptions options;
    options.utility = u;
    options.candidates.max_candidates = 40;
    options.rays.ray_stride_px = 40;
    IslerPlanner planner(options);
    Rng rng(21);
    const PlanResult plan = [&] {
      const ThreadScope one(1);
      return planner.Plan(request, rng);
    }();
    ASSERT_TRUE(plan.status.ok()) << plan.status.ToString();
    ASSERT_GT(plan.ranked.size(), 3u) << ToString(u);
    double sum_g = 0.0, sum_c = 0.0;
    for (const ViewCandidate& c : plan.ranked) {
      EXPECT_TRUE(c.reachable);
      EXPECT_TRUE(Arm().WithinLimits(c.q));
      EXPECT_FALSE(IsNearAny(c.X_WC, request.fused_views));
      EXPECT_GE(c.gain, 0.0);
      sum_g += c.gain;
      sum_c += c.cost;
    }
    EXPECT_GT(sum_g, 0.0) << ToString(u);
    for (size_t i = 0; i < plan.ranked.size(); ++i) {
      const ViewCandidate& c = plan.ranked[i];
      EXPECT_NEAR(c.utility, c.gain / sum_g - 0.1 * c.cost / sum_c, 1e-12);
      if (i > 0) {
        EXPECT_GE(plan.ranked[i - 1].utility, c.utility);
      }
    }
    // The gain is the view gain of the candidate, as IslerViewGain computes it.
    const auto grid = GainGrid::Build(map, request.target_class, request.roi);
    ASSERT_TRUE(grid.ok());
    const auto prox = ProximityField::Build(map, options.rays.proximity_max_distance_m);
    ASSERT_TRUE(prox.ok());
    EXPECT_DOUBLE_EQ(plan.ranked[0].gain,
                     IslerViewGain(u, *grid, &*prox, plan.ranked[0].X_WC, request.K, options.rays));
    // Same seed, more threads: the same plan.
    IslerPlanner threaded(options);
    Rng rng2(21);
    const ThreadScope three(3);
    const PlanResult again = threaded.Plan(request, rng2);
    ASSERT_EQ(again.ranked.size(), plan.ranked.size());
    for (size_t i = 0; i < plan.ranked.size(); ++i) {
      EXPECT_EQ(again.ranked[i].X_WC.translation(), plan.ranked[i].X_WC.translation());
      EXPECT_EQ(again.ranked[i].utility, plan.ranked[i].utility);
    }
  }
}

}  // namespace
}  // namespace avp::planning

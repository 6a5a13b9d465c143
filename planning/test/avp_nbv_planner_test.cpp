// avp-nbv: the ray gain on a hand-computed ray, the fast evaluator against the slow reference on
// random rays, and the planner on a rendered plant (deterministic, reachable, never a fused view,
// enough candidates, stopping rule).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <tuple>
#include <utility>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/core/segmentation.h>
#include <avp/mapping/integrator.h>
#include <avp/planning/avp_nbv_planner.h>
#include <avp/planning/candidates.h>
#include <avp/planning/gain_grid.h>
#include <avp/planning/isler_utilities.h>
#include <avp/planning/predefined_planner.h>
#include <avp/planning/reference_nbv_planner.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

#include "start_view_world.h"

namespace avp::planning {
namespace {

constexpr double kVoxel = 0.01;

mapping::SemanticMap MakeMap(double voxel = kVoxel) {
  mapping::MapOptions o;
  o.grid.voxel_size_m = voxel;
  return mapping::SemanticMap(o);
}

void SetFree(mapping::SemanticMap& m, const VoxelKey& k) {
  ASSERT_TRUE(m.grid().SetLogOdds(k, -1.0f));
}
void SetFruit(mapping::SemanticMap& m, const VoxelKey& k, float confidence) {
  ASSERT_TRUE(m.grid().SetLogOdds(k, 2.0f));
  mapping::SemanticCell* c = m.grid().MutableSemantic(k);
  c->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
  c->confidence = confidence;
}

double Hb(double p) { return -(p * std::log2(p) + (1 - p) * std::log2(1 - p)); }

/// Along +x through voxel centres: free, free, unknown, unknown, fruit (c = 0.7), then more.
mapping::SemanticMap HandRayMap() {
  mapping::SemanticMap map = MakeMap();
  SetFree(map, {0, 0, 0});
  SetFree(map, {1, 0, 0});
  SetFruit(map, {4, 0, 0}, 0.7f);
  SetFree(map, {5, 0, 0});  // behind the fruit: never reached
  return map;
}

/// The options HandComputedRay starts from.
AvpNbvOptions HandRayOptions() {
  AvpNbvOptions o;
  o.p_unknown = 0.5;               // so that the visibilities below are powers of 1/2
  o.occlusion_voxel_size_m = 0.0;  // per voxel of this 1 cm map, as given; rescaling is below
  o.range_weight_ref_m = 0.0;      // unweighted first; range weighting is checked below
  o.min_gain_range_m = 0.0;
  o.unknown_occlusion_sigma_m = 0.0;  // flat p_unknown first; its fall-off is checked below
  o.w_unknown_near_target = 1.0;
  o.grid.near_target_radius_m = 0.025;  // voxels 2 and 3 are 2 and 1 voxels from the fruit
  return o;
}

TEST(AvpRayGainTest, HandComputedRay) {
  mapping::SemanticMap map = HandRayMap();
  const Box3 roi(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1));
  AvpNbvOptions o = HandRayOptions();
  auto grid = GainGrid::Build(map, SemanticClass::kFruit, roi, o.grid);
  ASSERT_TRUE(grid.ok()) << grid.status().ToString();
  const Eigen::Vector3d from(0.005, 0.005, 0.005), to(0.305, 0.005, 0.005);
  // Unknown near the fruit: 1 bit at p_vis 1, then 1 bit at p_vis 0.5; the fruit voxel's entropy
  // at p_vis 0.25 (its confidence quantised to 1/255 as GainGrid stores it).
  const double c = QuantizeProbability(0.7f);  // the stored float confidence
  const double want = 1.0 + 0.5 + 0.25 * Hb(c);
  EXPECT_NEAR(AvpRayGain(*grid, from, to, o), want, 1e-9);
  EXPECT_NEAR(AvpRayGainReference(map, from, to, SemanticClass::kFruit, roi, o), want, 1e-9);
  // Given per 5 mm voxel, 0.5 becomes 1 - 0.5^2 = 0.75 per voxel of this 1 cm map: a centimetre of
  // unknown space lets through what two 5 mm voxels would.
  o.occlusion_voxel_size_m = 0.005;
  EXPECT_NEAR(AvpRayGain(*grid, from, to, o), 1.0 + 0.25 + 0.0625 * Hb(c), 1e-9);
  EXPECT_NEAR(AvpRayGainReference(map, from, to, SemanticClass::kFruit, roi, o),
              1.0 + 0.25 + 0.0625 * Hb(c), 1e-9);
  o.occlusion_voxel_size_m = 0.0;

  // Unknown voxels outside the near radius count w_unknown_roi; outside the ROI nothing.
  o.grid.near_target_radius_m = 0.005;
  auto far = GainGrid::Build(map, SemanticClass::kFruit, roi, o.grid);
  ASSERT_TRUE(far.ok());
  o.roi_axis_sigma_m = 0.0;  // flat ROI weight
  EXPECT_NEAR(AvpRayGain(*far, from, to, o), o.w_unknown_roi * 1.5 + 0.25 * Hb(c), 1e-9);
  // With the axis prior, each unknown voxel's weight falls with its horizontal distance from the
  // ROI's vertical axis (here through the origin): voxel centres at x = 0.025 and 0.035, y = 0.005.
  o.roi_axis_sigma_m = 0.03;
  const auto axis_w = [&](double x) {
    return o.w_unknown_roi * std::exp(-0.5 * (x * x + 0.005 * 0.005) / (0.03 * 0.03));
  };
  EXPECT_NEAR(AvpRayGain(*far, from, to, o), axis_w(0.025) + 0.5 * axis_w(0.035) + 0.25 * Hb(c),
              1e-9);
  EXPECT_NEAR(AvpRayGainReference(map, from, to, SemanticClass::kFruit, roi, o),
              axis_w(0.025) + 0.5 * axis_w(0.035) + 0.25 * Hb(c), 1e-9);
  const Box3 elsewhere(Eigen::Vector3d(5, 5, 5), Eigen::Vector3d(6, 6, 6));
  auto outside = GainGrid::Build(map, SemanticClass::kFruit, elsewhere, o.grid);
  ASSERT_TRUE(outside.ok());
  // A ray that misses the ROI gains nothing, even from a target voxel (the target lies in it).
  EXPECT_EQ(AvpRayGain(*outside, from, to, o), 0.0);
  EXPECT_EQ(AvpRayGainReference(map, from, to, SemanticClass::kFruit, elsewhere, o), 0.0);
  // Outside the ROI unknown space is air: it occludes with p_unknown_outside_roi (0 by default).
  // Here the ROI starts between voxels 3 and 4, so voxels 2 and 3 lie outside it.
  const Box3 partial(Eigen::Vector3d(0.038, -1, -1), Eigen::Vector3d(1, 1, 1));
  auto beyond = GainGrid::Build(map, SemanticClass::kFruit, partial, o.grid);
  ASSERT_TRUE(beyond.ok());
  EXPECT_NEAR(AvpRayGain(*beyond, from, to, o), Hb(c), 1e-9);
  o.p_unknown_outside_roi = 0.5;
  EXPECT_NEAR(AvpRayGain(*beyond, from, to, o), 0.25 * Hb(c), 1e-9);
  EXPECT_NEAR(AvpRayGainReference(map, from, to, SemanticClass::kFruit, partial, o), 0.25 * Hb(c),
              1e-9);
  o.p_unknown_outside_roi = 0.0;

  // Inside the ROI, an unknown voxel occludes with p_unknown times a Gaussian of its distance
  // from the plant's core (here the ROI's vertical axis through the origin).
  o.roi_axis_sigma_m = 0.0;
  o.unknown_occlusion_sigma_m = 0.03;
  const auto occ = [&](double x) {
    return o.p_unknown * std::exp(-0.5 * (x * x + 0.005 * 0.005) / (0.03 * 0.03));
  };
  const double vis_fruit = (1.0 - occ(0.025)) * (1.0 - occ(0.035));
  const double want_occ = o.w_unknown_roi * (1.0 + (1.0 - occ(0.025))) + vis_fruit * Hb(c);
  EXPECT_NEAR(AvpRayGain(*far, from, to, o), want_occ, 1e-9);
  EXPECT_NEAR(AvpRayGainReference(map, from, to, SemanticClass::kFruit, roi, o), want_occ, 1e-9);
  o.unknown_occlusion_sigma_m = 0.0;

  // Range weighting: each contribution times (distance from the eye / ref)^2; the eye is at the
  // centre of voxel 0, so voxels 2, 3, 4 are 0.02, 0.03, 0.04 m away.
  o.roi_axis_sigma_m = 0.0;
  o.range_weight_ref_m = 0.02;
  EXPECT_NEAR(AvpRayGain(*far, from, to, o),
              o.w_unknown_roi * (1.0 + 0.5 * 2.25) + 0.25 * Hb(c) * 4.0, 1e-9);
  EXPECT_NEAR(AvpRayGainReference(map, from, to, SemanticClass::kFruit, roi, o),
              o.w_unknown_roi * (1.0 + 0.5 * 2.25) + 0.25 * Hb(c) * 4.0, 1e-9);
  o.range_weight_ref_m = 0.0;
  // Voxels nearer than min_gain_range_m count nothing (voxel 2 at 0.02 m) but still occlude.
  o.min_gain_range_m = 0.025;
  EXPECT_NEAR(AvpRayGain(*far, from, to, o), o.w_unknown_roi * 0.5 + 0.25 * Hb(c), 1e-9);
  EXPECT_NEAR(AvpRayGainReference(map, from, to, SemanticClass::kFruit, roi, o),
              o.w_unknown_roi * 0.5 + 0.25 * Hb(c), 1e-9);
  o.min_gain_range_m = 0.0;
}

TEST(AvpRayGainTest, AnOccupiedNonFruitVoxelEndsTheRayWithoutGain) {
  mapping::SemanticMap map = HandRayMap();
  const Box3 roi(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1));
  AvpNbvOptions o = HandRayOptions();
  o.grid.near_target_radius_m = 0.005;
  o.roi_axis_sigma_m = 0.0;
  const Eigen::Vector3d from(0.005, 0.005, 0.005), to(0.305, 0.005, 0.005);
  ASSERT_TRUE(map.grid().SetLogOdds({2, 0, 0}, 2.0f));
  auto blocked = GainGrid::Build(map, SemanticClass::kFruit, roi, o.grid);
  ASSERT_TRUE(blocked.ok());
  EXPECT_EQ(AvpRayGain(*blocked, from, to, o), 0.0);
}

TEST(OcclusionPerVoxelTest, KeepsTheTransmittancePerMetre) {
  EXPECT_EQ(OcclusionPerVoxel(0.05, 0.005, 0.005), 0.05);  // exactly, at the reference size
  EXPECT_EQ(OcclusionPerVoxel(0.05, 0.01, 0.0), 0.05);     // 0: as given
  EXPECT_NEAR(OcclusionPerVoxel(0.5, 0.01, 0.005), 0.75, 1e-15);
  EXPECT_NEAR(OcclusionPerVoxel(0.75, 0.005, 0.01), 0.5, 1e-15);
  // 10 cm of unknown space: 20 voxels of 5 mm or 5 of 2 cm let through the same fraction.
  const double at_5mm = std::pow(1.0 - 0.05, 20);
  EXPECT_NEAR(std::pow(1.0 - OcclusionPerVoxel(0.05, 0.02, 0.005), 5), at_5mm, 1e-12);
  EXPECT_EQ(OcclusionPerVoxel(0.0, 0.02, 0.005), 0.0);
}

TEST(PlantCoreDistanceTest, AxisForSquareRoisMidPlaneForLongOnes) {
  // A square ROI: the distance from its vertical centre axis.
  const Box3 square(Eigen::Vector3d(0, -0.5, 0), Eigen::Vector3d(1, 0.5, 1));
  EXPECT_NEAR(PlantCoreDistance({0.5, 0.0, 0.3}, square), 0.0, 1e-12);
  EXPECT_NEAR(PlantCoreDistance({0.8, 0.4, 0.9}, square), 0.5, 1e-12);
  // An espalier 2 m wide in y and 0.4 m deep in x: its core is the mid-plane x = 0.7 over
  // |y| <= 1 - 0.2, and the distance grows beyond the segment's ends.
  const Box3 wall(Eigen::Vector3d(0.5, -1, 0), Eigen::Vector3d(0.9, 1, 1));
  EXPECT_NEAR(PlantCoreDistance({0.7, 0.75, 0.5}, wall), 0.0, 1e-12);
  EXPECT_NEAR(PlantCoreDistance({0.4, -0.5, 0.5}, wall), 0.3, 1e-12);
  EXPECT_NEAR(PlantCoreDistance({0.7, 1.1, 0.5}, wall), 0.3, 1e-12);
  EXPECT_NEAR(PlantCoreDistance({1.0, 1.2, 0.5}, wall), 0.5, 1e-12);
}

TEST(InSeenFreeSpaceTest, EveryPointOfTheBallInsideTheRoiMustBeSeenFree) {
  mapping::OccupancyGrid grid;  // 5 mm voxels
  // Seen free: the cube [0, 0.3]^3; one occupied voxel at (0.25, 0.15, 0.15).
  for (double x = 0.0025; x < 0.3; x += 0.005) {
    for (double y = 0.0025; y < 0.3; y += 0.005) {
      for (double z = 0.0025; z < 0.3; z += 0.005) {
        grid.SetLogOdds(grid.KeyOf({x, y, z}), grid.clamp_min_log_odds());
      }
    }
  }
  grid.SetLogOdds(grid.KeyOf({0.2525, 0.1525, 0.1525}), grid.clamp_max_log_odds());
  const Box3 roi(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 1, 1));
  EXPECT_TRUE(InSeenFreeSpace(grid, roi, {0.1, 0.15, 0.15}, 0.08));
  EXPECT_FALSE(InSeenFreeSpace(grid, roi, {0.2, 0.15, 0.15}, 0.08));   // reaches the occupied one
  EXPECT_FALSE(InSeenFreeSpace(grid, roi, {0.15, 0.25, 0.15}, 0.08));  // reaches unseen y > 0.3
  // Outside the ROI nothing needs to have been seen.
  const Box3 small(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.29, 0.29, 0.29));
  EXPECT_TRUE(InSeenFreeSpace(grid, small, {0.15, 0.25, 0.15}, 0.08));
  EXPECT_TRUE(InSeenFreeSpace(grid, small, {0.5, 0.5, 0.5}, 0.08));
}

TEST(CoreTargetsTest, PointsAlongTheCoreOfALongRoiTheCentreOfASquareOne) {
  const Box3 square(Eigen::Vector3d(0, -0.5, 0), Eigen::Vector3d(1, 0.5, 1));
  for (double spacing : {0.0, 0.3}) {
    const auto c = CoreTargets(square, spacing, 4);
    ASSERT_EQ(c.size(), 1u);
    EXPECT_TRUE(c[0].isApprox(Eigen::Vector3d(0.5, 0.0, 0.5)));
  }
  // Almost square (the axis 0.1 m long): shorter than the spacing, the centre alone.
  const Box3 almost(Eigen::Vector3d(0, -0.5, 0), Eigen::Vector3d(0.9, 0.5, 1));
  EXPECT_EQ(CoreTargets(almost, 0.3, 4).size(), 1u);
  // The wall above: core segment x = 0.7, y in [-0.8, 0.8] (1.6 m), at mid-height.
  const Box3 wall(Eigen::Vector3d(0.5, -1, 0), Eigen::Vector3d(0.9, 1, 1));
  const auto w = CoreTargets(wall, 0.5, 8);  // 1 + floor(1.6 / 0.5) = 4, 0.533 m apart
  ASSERT_EQ(w.size(), 4u);
  for (size_t i = 0; i < w.size(); ++i) {
    EXPECT_NEAR(w[i].x(), 0.7, 1e-12);
    EXPECT_NEAR(w[i].z(), 0.5, 1e-12);
    EXPECT_NEAR(w[i].y(), -0.8 + 1.6 * static_cast<double>(i) / 3.0, 1e-12);
    EXPECT_NEAR(PlantCoreDistance(w[i], wall), 0.0, 1e-12);
  }
  EXPECT_EQ(CoreTargets(wall, 0.5, 3).size(), 3u);     // capped
  EXPECT_EQ(CoreTargets(wall, 0.15, 30).size(), 11u);  // 1 + floor(10.7)
  EXPECT_EQ(CoreTargets(wall, 0.0, 8).size(), 1u);     // off
}

TEST(AvpRayGainTest, FastEvaluatorEqualsTheReferenceOnRandomRays) {
  mapping::SemanticMap map = MakeMap(0.008);
  Rng rng(5);
  for (int z = -12; z < 12; ++z) {
    for (int y = -12; y < 12; ++y) {
      for (int x = -12; x < 12; ++x) {
        const double u = rng.Uniform01();
        if (u < 0.35) {
          SetFree(map, {x, y, z});
        } else if (u < 0.40) {
          SetFruit(map, {x, y, z}, static_cast<float>(rng.Uniform(0.05, 0.99)));
        } else if (u < 0.43) {
          ASSERT_TRUE(map.grid().SetLogOdds({x, y, z}, 1.5f));
        }
      }
    }
  }
  const Box3 roi(Eigen::Vector3d(-0.06, -0.08, -0.05), Eigen::Vector3d(0.07, 0.05, 0.08));
  AvpNbvOptions o;
  o.grid.near_target_radius_m = 0.02;
  o.min_gain_range_m = 0.05;  // the rays are 0.3 m long: most of each counts
  auto grid = GainGrid::Build(map, SemanticClass::kFruit, roi, o.grid);
  ASSERT_TRUE(grid.ok());
  int nonzero = 0;
  for (int i = 0; i < 400; ++i) {
    Eigen::Vector3d dir(rng.Normal(), rng.Normal(), rng.Normal());
    dir.normalize();
    const Eigen::Vector3d from =
        -0.15 * dir + Eigen::Vector3d(rng.Uniform(-0.05, 0.05), rng.Uniform(-0.05, 0.05), 0.0);
    const Eigen::Vector3d to = from + 0.3 * dir;
    const double fast = AvpRayGain(*grid, from, to, o);
    const double slow = AvpRayGainReference(map, from, to, SemanticClass::kFruit, roi, o);
    ASSERT_NEAR(fast, slow, 1e-9 * std::max(1.0, slow)) << "ray " << i;
    nonzero += fast > 0.0;
  }
  EXPECT_GT(nonzero, 100);
}

TEST(TargetSphereTest, FitsTheSeenHalfOfAFruitAndPredictsItsHiddenSide) {
  // The camera-facing half (x < cx) of a sphere of radius 3 cm, as occupied fruit voxels of
  // instance 7; the hidden half stays unknown.
  mapping::SemanticMap map = MakeMap(0.005);
  const Eigen::Vector3d centre(0.6012, 0.0531, 0.7043);
  const double radius = 0.03;
  for (int z = 110; z < 170; ++z) {
    for (int y = -20; y < 40; ++y) {
      for (int x = 100; x < 140; ++x) {
        const VoxelKey k{x, y, z};
        const Eigen::Vector3d c = k.Center(0.005);
        if (std::abs((c - centre).norm() - radius) > 0.0025 || c.x() > centre.x()) continue;
        SetFruit(map, k, 0.9f);
        map.grid().MutableSemantic(k)->instance_id = 7;
      }
    }
  }
  const std::vector<TargetSphere> spheres = FitTargetSpheres(map, SemanticClass::kFruit);
  ASSERT_EQ(spheres.size(), 1u);
  EXPECT_EQ(spheres[0].instance_id, 7);
  EXPECT_LT((spheres[0].center_W - centre).norm(), 0.003);
  EXPECT_NEAR(spheres[0].radius_m, radius, 0.003);
  // The grid marks the predicted surface exactly as the slow per-voxel read does, including the
  // hidden half behind the seen one.
  const Box3 roi(Eigen::Vector3d(0, -1, 0), Eigen::Vector3d(2, 1, 2));
  auto grid = GainGrid::Build(map, SemanticClass::kFruit, roi);
  ASSERT_TRUE(grid.ok());
  int predicted_hidden = 0;
  for (int z = 125; z < 160; ++z) {
    for (int y = -10; y < 25; ++y) {
      for (int x = 108; x < 135; ++x) {
        const VoxelKey k{x, y, z};
        const GainVoxel fast = grid->At(k);
        const GainVoxel slow = ReadGainVoxel(map, k, SemanticClass::kFruit, roi, 0.04, &spheres);
        ASSERT_EQ(fast.predicted_target, slow.predicted_target) << k.x << " " << k.y << " " << k.z;
        if (fast.predicted_target && fast.state == mapping::VoxelState::kUnknown &&
            k.Center(0.005).x() > centre.x() + 0.01) {
          ++predicted_hidden;
        }
      }
    }
  }
  EXPECT_GT(predicted_hidden, 150);  // about 190 of the hidden half's shell
  // Too few voxels, or an implausible radius: no sphere.
  EXPECT_TRUE(FitTargetSpheres(map, SemanticClass::kFruit, 100000).empty());
  EXPECT_TRUE(FitTargetSpheres(map, SemanticClass::kFruit, 12, 0.05, 0.08).empty());
}

/// A map of the plant after its start view (perfect masks), as the loop has it at step 1.
class AvpNbvPlannerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    std::string error;
    world_ = test::MakeStartViewWorld("tomato-multiple-clusters", 2, 0.005, &error).release();
    ASSERT_NE(world_, nullptr) << error;
    arm_ = &world_->arm;
    scene_ = &world_->scene;
    map_ = &world_->map;
    q0_ = world_->q0;
    X0_ = world_->X0;
  }
  static void TearDownTestSuite() { delete world_; }
  PlanningRequest Request() const { return world_->Request(); }
  static test::StartViewWorld* world_;
  static robot::ArmModel* arm_;
  static sim::Scene* scene_;
  static mapping::SemanticMap* map_;
  static Eigen::VectorXd q0_;
  static RigidTransform X0_;
};
test::StartViewWorld* AvpNbvPlannerTest::world_ = nullptr;
robot::ArmModel* AvpNbvPlannerTest::arm_ = nullptr;
sim::Scene* AvpNbvPlannerTest::scene_ = nullptr;
mapping::SemanticMap* AvpNbvPlannerTest::map_ = nullptr;
Eigen::VectorXd AvpNbvPlannerTest::q0_;
RigidTransform AvpNbvPlannerTest::X0_;

TEST_F(AvpNbvPlannerTest, RanksReachableCandidatesDeterministicallyBySeed) {
  AvpNbvPlanner planner;
  Rng a(11), b(11), c(12);
  const PlanResult ra = planner.Plan(Request(), a);
  const PlanResult rb = planner.Plan(Request(), b);
  const PlanResult rc = planner.Plan(Request(), c);
  ASSERT_TRUE(ra.status.ok()) << ra.status.ToString();
  EXPECT_GE(ra.generated, 300u);
  EXPECT_GE(ra.reachable, 50u);
  ASSERT_EQ(ra.ranked.size(), rb.ranked.size());
  for (size_t i = 0; i < ra.ranked.size(); ++i) {
    ASSERT_EQ(ra.ranked[i].X_WC.translation(), rb.ranked[i].X_WC.translation()) << i;
    ASSERT_EQ(ra.ranked[i].utility, rb.ranked[i].utility) << i;
  }
  // Another seed jitters the candidates differently.
  EXPECT_NE(ra.ranked.front().X_WC.translation(), rc.ranked.front().X_WC.translation());
  // Best first; every ranked candidate is reachable, in limits, where its joints put the camera,
  // and not a fused view.
  for (size_t i = 0; i < ra.ranked.size(); ++i) {
    const ViewCandidate& v = ra.ranked[i];
    if (i > 0) {
      EXPECT_LE(v.utility, ra.ranked[i - 1].utility);
    }
    ASSERT_TRUE(v.reachable);
    ASSERT_TRUE(arm_->WithinLimits(v.q));
    const RigidTransform X = arm_->CameraPose(v.q);
    EXPECT_LT((X.translation() - v.X_WC.translation()).norm(), 1e-3);
    EXPECT_FALSE(IsNearAny(v.X_WC, {X0_}));
  }
  EXPECT_GT(ra.ranked.front().gain, 0.0);
  EXPECT_FALSE(ra.stop);
}

TEST_F(AvpNbvPlannerTest, ThreadCountDoesNotChangeTheResult) {
  // One parallelism setting (core/parallel.h): 1 thread, then 2.
  const auto plan = [&](int threads) {
    const ThreadScope scope(threads);
    Rng rng(3);
    return AvpNbvPlanner(AvpNbvOptions{}).Plan(Request(), rng);
  };
  const PlanResult r1 = plan(1);
  const PlanResult r2 = plan(2);
  ASSERT_EQ(r1.ranked.size(), r2.ranked.size());
  for (size_t i = 0; i < r1.ranked.size(); ++i) ASSERT_EQ(r1.ranked[i].gain, r2.ranked[i].gain);
}

TEST_F(AvpNbvPlannerTest, GridLayoutAndFreeBrickSkippingDoNotChangeTheResult) {
  // The default grid (8^3 bricks) against the plain dense walk, other brick sizes and all-free
  // bricks skipped: the same candidates with bit-identical gains.
  Rng a(5);
  const PlanResult ref = AvpNbvPlanner().Plan(Request(), a);
  ASSERT_TRUE(ref.status.ok()) << ref.status.ToString();
  ASSERT_GT(ref.ranked.size(), 50u);
  for (const auto& [shift, skip] : {std::pair{0, false}, {3, true}, {2, true}, {4, true}}) {
    AvpNbvOptions o;
    o.grid.brick_shift = shift;
    o.grid.skip_free_bricks = skip;
    Rng b(5);
    const PlanResult r = AvpNbvPlanner(o).Plan(Request(), b);
    ASSERT_EQ(r.ranked.size(), ref.ranked.size()) << shift << " " << skip;
    for (size_t i = 0; i < r.ranked.size(); ++i) {
      ASSERT_EQ(r.ranked[i].gain, ref.ranked[i].gain) << shift << " " << skip << " " << i;
      ASSERT_EQ(r.ranked[i].X_WC.translation(), ref.ranked[i].X_WC.translation()) << i;
    }
  }
}

TEST_F(AvpNbvPlannerTest, CoarseToFineRefinesTheBestCandidatesWithTheFineRays) {
  // Every candidate scored with every fine ray (coarse off) against the default coarse-to-fine
  // pass: the same candidates; exactly refine_top of them carry their fine gain, the chosen one
  // among them; the others the coarse estimate.
  AvpNbvOptions full;
  full.coarse_ray_stride_px = 0;
  const AvpNbvOptions c2f;
  ASSERT_GT(c2f.coarse_ray_stride_px, c2f.ray_stride_px);
  Rng a(7), b(7);
  const PlanResult rf = AvpNbvPlanner(full).Plan(Request(), a);
  const PlanResult rc = AvpNbvPlanner(c2f).Plan(Request(), b);
  ASSERT_TRUE(rf.status.ok() && rc.status.ok());
  ASSERT_GT(rc.ranked.size(), static_cast<size_t>(c2f.refine_top));
  ASSERT_EQ(rf.ranked.size(), rc.ranked.size());
  auto key = [](const ViewCandidate& v) {
    const Eigen::Vector3d t = v.X_WC.translation();
    return std::tuple(t.x(), t.y(), t.z());
  };
  std::map<std::tuple<double, double, double>, double> fine;
  for (const ViewCandidate& v : rf.ranked) fine[key(v)] = v.gain;
  int refined = 0;
  for (const ViewCandidate& v : rc.ranked) {
    ASSERT_EQ(fine.count(key(v)), 1u);
    refined += v.gain == fine[key(v)] ? 1 : 0;
  }
  EXPECT_EQ(refined, c2f.refine_top);
  EXPECT_EQ(rc.ranked.front().gain, fine[key(rc.ranked.front())]);
  // The coarse estimates are close to the fine gains (same scene, a quarter of the rays): the
  // view ranked first by the full pass is within the coarse pass's top refine_top.
  bool best_refined = false;
  for (int i = 0; i < c2f.refine_top; ++i) {
    best_refined = best_refined || key(rc.ranked[static_cast<size_t>(i)]) == key(rf.ranked.front());
  }
  EXPECT_TRUE(best_refined);
  // With at least as many refinements as reachable candidates it is the full pass.
  AvpNbvOptions all = c2f;
  all.refine_top = static_cast<int>(rc.ranked.size());
  Rng d(7);
  const PlanResult ra = AvpNbvPlanner(all).Plan(Request(), d);
  ASSERT_EQ(ra.ranked.size(), rf.ranked.size());
  for (size_t i = 0; i < ra.ranked.size(); ++i) ASSERT_EQ(ra.ranked[i].gain, rf.ranked[i].gain);
}

TEST(AvpNbvOptionTest, SetsFieldsByNameAndNamesBadKeysAndValues) {
  const OptionTable<AvpNbvOptions>& table = AvpNbvOptionTable();
  AvpNbvOptions o;
  EXPECT_TRUE(table.Set(o, "p_unknown", "0.25").ok());
  EXPECT_EQ(o.p_unknown, 0.25);
  EXPECT_TRUE(table.Set(o, "refine_top", "12").ok());
  EXPECT_EQ(o.refine_top, 12);
  EXPECT_TRUE(table.Set(o, "occlusion_voxel_size_m", "-0.01").ok());  // parsed; not valid
  EXPECT_NE(o.Validate().message().find("occlusion_voxel_size_m (-0.01 m) must be >= 0"),
            std::string::npos)
      << o.Validate().message();
  EXPECT_TRUE(table.Set(o, "occlusion_voxel_size_m", "0.01").ok());
  EXPECT_TRUE(o.Validate().ok());
  EXPECT_TRUE(table.Set(o, "candidates.radii_m", "0.3,0.5").ok());
  EXPECT_EQ(o.candidates.radii_m, (std::vector<double>{0.3, 0.5}));
  EXPECT_TRUE(table.Set(o, "candidates.max_targets", "20").ok());
  EXPECT_EQ(o.candidates.max_targets, 20);
  EXPECT_TRUE(table.Set(o, "grid.predict_target_surface", "false").ok());
  EXPECT_FALSE(o.grid.predict_target_surface);
  EXPECT_TRUE(table.Set(o, "grid.near_target_radius_m", "0.03").ok());
  EXPECT_EQ(o.grid.near_target_radius_m, 0.03);
  EXPECT_TRUE(o.Validate().ok()) << o.Validate().ToString();

  const Status unknown = table.Set(o, "p_unknwn", "0.1");
  EXPECT_NE(unknown.message().find("unknown avp-nbv option 'p_unknwn'"), std::string::npos);
  EXPECT_NE(unknown.message().find("p_unknown_outside_roi"), std::string::npos);
  for (const auto& [key, value, what] :
       {std::tuple{"w_motion", "fast", "a finite number"},
        {"w_motion", "nan", "a finite number"},
        {"w_motion", "0.1x", "a finite number"},
        {"w_motion", "", "a finite number"},
        {"refine_top", "2.5", "a whole number"},
        {"grid.predict_target_surface", "1", "true or false"},
        {"candidates.radii_m", "0.3,x", "a comma-separated list of finite numbers"}}) {
    const Status s = table.Set(o, key, value);
    EXPECT_NE(s.message().find(fmt::format("{}: '{}' is not", key, value)), std::string::npos)
        << s.message();
    EXPECT_NE(s.message().find(what), std::string::npos) << s.message();
  }
  // A failed set leaves the field as it was.
  EXPECT_EQ(o.candidates.radii_m, (std::vector<double>{0.3, 0.5}));
  // Every key of the options before the table (docs/planning.md) is still there, and settable.
  const std::vector<std::string> keys = table.Keys();
  EXPECT_EQ(keys.size(), 43u);
  for (const std::string& k : keys) {
    AvpNbvOptions x;
    const bool ok =
        table.Set(x, k, "1").ok() || table.Set(x, k, "true").ok() || table.Set(x, k, "1,2").ok();
    EXPECT_TRUE(ok) << k;
  }
  // Values() round-trips every field exactly.
  AvpNbvOptions back;
  ASSERT_TRUE(table.SetAll(back, table.Values(o)).ok());
  EXPECT_TRUE(table.Differences(back, o).empty());
}

TEST_F(AvpNbvPlannerTest, StoppingRuleFiresBelowTheGainThreshold) {
  AvpNbvOptions o;
  o.min_gain_bits = 1e9;
  Rng rng(1);
  const PlanResult r = AvpNbvPlanner(o).Plan(Request(), rng);
  EXPECT_TRUE(r.stop);
  EXPECT_NE(r.stop_reason.find("below the stopping threshold"), std::string::npos);
}

TEST_F(AvpNbvPlannerTest, RelativeStoppingRuleComparesWithTheFirstPlan) {
  AvpNbvOptions o;
  o.min_gain_fraction = 0.5;
  AvpNbvPlanner planner(o);
  Rng rng(1);
  PlanningRequest first = Request();
  first.view_index = 1;
  const PlanResult a = planner.Plan(first, rng);
  ASSERT_TRUE(a.status.ok());
  EXPECT_FALSE(a.stop);  // the first plan sets the scale
  // Later, a region of interest of 4 cm around the plant's centre: far less to gain.
  PlanningRequest second = first;
  second.view_index = 2;
  second.roi = Box3::FromCenterAndHalfSize(first.roi.center(), Eigen::Vector3d::Constant(0.02));
  const PlanResult b = planner.Plan(second, rng);
  ASSERT_TRUE(b.status.ok());
  const auto max_gain = [](const PlanResult& r) {
    double g = 0.0;
    for (const ViewCandidate& c : r.ranked) g = std::max(g, c.gain);
    return g;
  };
  ASSERT_LT(max_gain(b), 0.5 * max_gain(a));
  EXPECT_TRUE(b.stop);
  EXPECT_NE(b.stop_reason.find("x the first plan's"), std::string::npos) << b.stop_reason;
  // A new episode (view 1 again) starts a new scale.
  EXPECT_FALSE(planner.Plan(first, rng).stop);
  o.min_gain_fraction = 1.0;
  EXPECT_NE(o.Validate().message().find("min_gain_fraction (1)"), std::string::npos);
}

TEST_F(AvpNbvPlannerTest, GainTermsSumToTheGainAndChangeNoChoice) {
  AvpNbvOptions o;
  Rng rng_plain(4), rng_terms(4);
  const PlanResult plain = AvpNbvPlanner(o).Plan(Request(), rng_plain);
  o.record_gain_terms = true;
  const PlanResult terms = AvpNbvPlanner(o).Plan(Request(), rng_terms);
  ASSERT_TRUE(plain.status.ok());
  ASSERT_TRUE(terms.status.ok());
  ASSERT_EQ(plain.ranked.size(), terms.ranked.size());
  std::array<double, kGainTermCount> total{};
  for (size_t i = 0; i < plain.ranked.size(); ++i) {
    const ViewCandidate& c = terms.ranked[i];
    EXPECT_TRUE(plain.ranked[i].gain_terms.empty());
    EXPECT_EQ(c.X_WC.translation(), plain.ranked[i].X_WC.translation());
    EXPECT_DOUBLE_EQ(c.gain, plain.ranked[i].gain);
    ASSERT_EQ(c.gain_terms.size(), static_cast<size_t>(kGainTermCount));
    double sum = 0.0;
    for (int t = 0; t < kGainTermCount; ++t) {
      EXPECT_EQ(c.gain_terms[t].first, AvpGainTermName(static_cast<AvpGainTerm>(t)));
      EXPECT_GE(c.gain_terms[t].second, 0.0);
      sum += c.gain_terms[t].second;
      total[t] += c.gain_terms[t].second;
    }
    EXPECT_NEAR(sum, c.gain, 1e-9 * std::max(1.0, c.gain));
  }
  // The start view sees fruit: every part is at work somewhere in the candidate set.
  for (int t = 0; t < kGainTermCount; ++t) {
    EXPECT_GT(total[t], 0.0) << AvpGainTermName(static_cast<AvpGainTerm>(t));
  }
}

TEST_F(AvpNbvPlannerTest, LookaheadPicksAmongTheBestAndIsGreedyWhenNothingFollows) {
  const auto plan = [&](int views, double discount, int view_index) {
    AvpNbvOptions o;
    o.lookahead_views = views;
    o.lookahead_discount = discount;
    PlanningRequest r = Request();
    r.view_index = view_index;
    Rng rng(6);
    return AvpNbvPlanner(o).Plan(r, rng);
  };
  const PlanResult greedy = plan(0, 0.5, 1);
  ASSERT_TRUE(greedy.status.ok());
  // A discount of 0, or no view left after this one: the greedy ranking, exactly.
  for (const PlanResult& same : {plan(2, 0.0, 1), plan(2, 1.0, 7)}) {
    ASSERT_EQ(same.ranked.size(), greedy.ranked.size());
    for (size_t i = 0; i < greedy.ranked.size(); ++i) {
      EXPECT_EQ(same.ranked[i].X_WC.translation(), greedy.ranked[i].X_WC.translation());
      EXPECT_EQ(same.ranked[i].utility, greedy.ranked[i].utility);
    }
  }
  // Looking ahead: only the 16 best by utility get a bonus, so the choice is one of them, and
  // every bonus is at most the discount times the views looked ahead.
  for (const int views : {1, 2}) {
    const PlanResult ahead = plan(views, 1.0, 1);
    ASSERT_EQ(ahead.ranked.size(), greedy.ranked.size());
    std::vector<double> greedy_utilities;
    for (const ViewCandidate& c : greedy.ranked) greedy_utilities.push_back(c.utility);
    std::sort(greedy_utilities.rbegin(), greedy_utilities.rend());
    const auto chosen =
        std::find_if(greedy.ranked.begin(), greedy.ranked.end(), [&](const auto& c) {
          return c.X_WC.translation() == ahead.ranked.front().X_WC.translation();
        });
    ASSERT_NE(chosen, greedy.ranked.end());
    EXPECT_GE(chosen->utility, greedy_utilities[15]);
    const double bonus = ahead.ranked.front().utility - chosen->utility;
    EXPECT_GT(bonus, 0.0);
    EXPECT_LE(bonus, views + 1e-9);
  }
}

TEST_F(AvpNbvPlannerTest, SpreadFrontierTargetsCoverMoreOfTheBoundary) {
  const PlanningRequest r = Request();
  AvpNbvOptions o;
  const Result<GainGrid> grid = GainGrid::Build(*r.map, r.target_class, r.roi, o.grid);
  ASSERT_TRUE(grid.ok());
  // The frontier targets' mean distance to their nearest neighbour among all targets.
  const auto frontier_spacing = [&](double spread_m) {
    ShellCandidateOptions c = o.candidates;
    c.max_targets = 24;  // room for frontier targets beside the fruit
    c.frontier_spread_m = spread_m;
    const std::vector<ViewTarget> t = FindViewTargets(r, *grid, c);
    double sum = 0.0;
    int n = 0;
    for (size_t i = 0; i < t.size(); ++i) {
      if (t[i].source != "frontier") continue;
      double d = std::numeric_limits<double>::infinity();
      for (size_t j = 0; j < t.size(); ++j) {
        if (j != i) d = std::min(d, (t[i].p_W - t[j].p_W).norm());
      }
      sum += d;
      ++n;
    }
    return std::pair{n, sum / n};
  };
  const auto [n_heaviest, heaviest] = frontier_spacing(0.0);
  const auto [n_spread, spread] = frontier_spacing(0.3);
  ASSERT_GE(n_heaviest, 4);
  EXPECT_EQ(n_spread, n_heaviest);
  EXPECT_GT(spread, 1.5 * heaviest) << heaviest << " m -> " << spread << " m";

  // frontier_spread_after: the heaviest N come first as without spreading, the rest spread.
  const auto frontiers = [&](double spread_m, int after) {
    ShellCandidateOptions c = o.candidates;
    c.max_targets = 24;
    c.frontier_spread_m = spread_m;
    c.frontier_spread_after = after;
    std::vector<Eigen::Vector3d> p;
    for (const ViewTarget& t : FindViewTargets(r, *grid, c)) {
      if (t.source == "frontier") p.push_back(t.p_W);
    }
    return p;
  };
  const std::vector<Eigen::Vector3d> by_weight = frontiers(0.0, 0);
  const std::vector<Eigen::Vector3d> spread_all = frontiers(0.3, 0);
  const std::vector<Eigen::Vector3d> after2 = frontiers(0.3, 2);
  ASSERT_EQ(after2.size(), by_weight.size());
  EXPECT_EQ(after2[0], by_weight[0]);
  EXPECT_EQ(after2[1], by_weight[1]);
  EXPECT_NE(after2, by_weight);  // the others are spread
  EXPECT_NE(after2, spread_all);
  EXPECT_EQ(frontiers(0.3, 256), by_weight);  // all kept: heaviest first
}

TEST_F(AvpNbvPlannerTest, ExtraFrontierTargetsAddToTheDefaultOnes) {
  const PlanningRequest r = Request();
  AvpNbvOptions o;
  const Result<GainGrid> grid = GainGrid::Build(*r.map, r.target_class, r.roi, o.grid);
  ASSERT_TRUE(grid.ok());
  const std::vector<ViewTarget> plain = FindViewTargets(r, *grid, o.candidates);
  ShellCandidateOptions c = o.candidates;
  c.extra_frontier_targets = 3;
  const std::vector<ViewTarget> more = FindViewTargets(r, *grid, c);
  ASSERT_EQ(more.size(), plain.size() + 3);
  // The default targets are all there, in order; the three extras are frontier clusters that
  // are not among them, placed after the other frontiers (before the plant's core).
  size_t extras = 0;
  for (size_t i = 0, j = 0; i < more.size(); ++i) {
    if (j < plain.size() && more[i].p_W == plain[j].p_W && more[i].source == plain[j].source) {
      ++j;
      continue;
    }
    EXPECT_EQ(more[i].source, "frontier");
    for (const ViewTarget& t : plain) EXPECT_NE(t.p_W, more[i].p_W);
    ++extras;
  }
  EXPECT_EQ(extras, 3u);
  EXPECT_EQ(more.back().source, "roi");
  // Every target gets max_candidates / max_targets candidates to draw: the extras add to them.
  Rng a(7), b(7);
  c.ik_restarts = 0;
  ShellCandidateOptions p = o.candidates;
  p.ik_restarts = 0;
  const size_t n_plain = GenerateShellCandidates(r, *grid, plain, p, a).size();
  const size_t n_more = GenerateShellCandidates(r, *grid, more, c, b).size();
  EXPECT_GT(n_more, n_plain);
  EXPECT_LE(n_more, n_plain + 3 * static_cast<size_t>(c.max_candidates / c.max_targets));
}

TEST_F(AvpNbvPlannerTest, UnseenTargetsSitInCubesNoViewHasSeen) {
  const PlanningRequest r = Request();
  AvpNbvOptions o;
  const Result<GainGrid> grid = GainGrid::Build(*r.map, r.target_class, r.roi, o.grid);
  ASSERT_TRUE(grid.ok());
  ShellCandidateOptions c = o.candidates;
  c.max_targets = 24;
  const auto count = [](const std::vector<ViewTarget>& t, const std::string& source) {
    return std::count_if(t.begin(), t.end(),
                         [&](const ViewTarget& v) { return v.source == source; });
  };
  const std::vector<ViewTarget> plain = FindViewTargets(r, *grid, c);
  EXPECT_EQ(count(plain, "unseen"), 0);
  c.unseen_targets = 3;
  c.unseen_cell_m = 0.1;
  const std::vector<ViewTarget> t = FindViewTargets(r, *grid, c);
  ASSERT_EQ(count(t, "unseen"), 3);
  // They come out of the frontiers' share; fruit and the ROI centre keep theirs.
  EXPECT_EQ(t.size(), plain.size());
  EXPECT_EQ(count(t, "frontier"), count(plain, "frontier") - 3);
  EXPECT_EQ(count(t, "fruit-shell"), count(plain, "fruit-shell"));
  // Each sits in a cube of the ROI with at most 10 % of its voxels known, never two in one
  // cube.
  const double s = r.map->grid().voxel_size_m();
  std::vector<Eigen::Vector3d> unseen;
  for (const ViewTarget& v : t) {
    if (v.source != "unseen") continue;
    EXPECT_TRUE(r.roi.Contains(v.p_W));
    const Eigen::Vector3d lo =
        r.roi.min() + 0.1 * ((v.p_W - r.roi.min()) / 0.1).array().floor().matrix();
    const Box3 cube(lo, (lo + Eigen::Vector3d::Constant(0.1)).cwiseMin(r.roi.max()));
    size_t known = 0;
    r.map->grid().ForEachKnownVoxel([&](const VoxelKey& k, float) {
      const Eigen::Vector3d p = k.Center(s);
      if (cube.Contains(p) && r.roi.Contains(p)) ++known;
    });
    EXPECT_LE(static_cast<double>(known), 0.1 * cube.size().prod() / (s * s * s) + 1.0);
    for (const Eigen::Vector3d& q : unseen) EXPECT_GE((q - v.p_W).norm(), 0.1 - 1e-9);
    unseen.push_back(v.p_W);
  }
  // With room for all of them, exactly the unseen cubes that border seen plant (counted here,
  // voxel by voxel) are targets; the start view saw part of the plant, so some cubes are seen.
  const Eigen::Vector3i n = (r.roi.size() / 0.1 - Eigen::Vector3d::Constant(1e-9))
                                .array()
                                .ceil()
                                .cast<int>()
                                .max(1)
                                .matrix();
  const auto at = [&](int x, int y, int z) {
    return static_cast<size_t>(x + n.x() * (y + n.y() * z));
  };
  std::vector<size_t> known(static_cast<size_t>(n.prod()), 0), occupied(known.size(), 0);
  r.map->grid().ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    const Eigen::Vector3d p = k.Center(s);
    if (!r.roi.Contains(p)) return;
    const Eigen::Vector3i i =
        ((p - r.roi.min()) / 0.1).array().floor().cast<int>().min(n.array() - 1).matrix();
    ++known[at(i.x(), i.y(), i.z())];
    if (log_odds >= r.map->grid().occupied_log_odds()) ++occupied[at(i.x(), i.y(), i.z())];
  });
  int unseen_cubes = 0, bordering = 0;
  for (int z = 0; z < n.z(); ++z) {
    for (int y = 0; y < n.y(); ++y) {
      for (int x = 0; x < n.x(); ++x) {
        const Eigen::Vector3d lo = r.roi.min() + 0.1 * Eigen::Vector3d(x, y, z);
        const double volume =
            ((lo + Eigen::Vector3d::Constant(0.1)).cwiseMin(r.roi.max()) - lo).prod();
        if (static_cast<double>(known[at(x, y, z)]) > 0.1 * volume / (s * s * s)) continue;
        ++unseen_cubes;
        size_t plant = 0;
        for (int dz = -1; dz <= 1; ++dz) {
          for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
              const Eigen::Vector3i q(x + dx, y + dy, z + dz);
              if ((q.array() >= 0).all() && (q.array() < n.array()).all()) {
                plant += occupied[at(q.x(), q.y(), q.z())];
              }
            }
          }
        }
        if (plant > 0) ++bordering;
      }
    }
  }
  ASSERT_GT(bordering, 3);
  ASSERT_LT(bordering, unseen_cubes);  // some unseen cubes are nowhere near the seen plant
  ASSERT_LT(unseen_cubes, n.prod());
  c.unseen_targets = 64;
  c.max_targets = 256;
  EXPECT_EQ(count(FindViewTargets(r, *grid, c), "unseen"), std::min(64, bordering));

  // 1 cm cubes would be more than 2^20 over this ROI: coarser ones, still targets, bounded work.
  ASSERT_GT(r.roi.size().prod() / 1e-6, double(size_t{1} << 20));
  c.unseen_cell_m = 0.01;
  c.unseen_targets = 3;
  c.max_targets = 24;
  EXPECT_EQ(count(FindViewTargets(r, *grid, c), "unseen"), 3);
}

TEST_F(AvpNbvPlannerTest, BadRequestsAndOptionsAreErrors) {
  PlanningRequest r = Request();
  r.map = nullptr;
  Rng rng(1);
  EXPECT_FALSE(AvpNbvPlanner().Plan(r, rng).status.ok());
  AvpNbvOptions o;
  o.ray_stride_px = 0;
  EXPECT_THROW(AvpNbvPlanner{o}, Error);
  o = AvpNbvOptions{};
  o.p_unknown = 1.0;
  EXPECT_NE(o.Validate().message().find("p_unknown (1)"), std::string::npos);
  o = AvpNbvOptions{};
  o.coarse_ray_stride_px = 10;
  EXPECT_NE(o.Validate().message().find(
                "coarse_ray_stride_px (10 px) must be 0 (off) or >= ray_stride_px (20 px)"),
            std::string::npos);
  o = AvpNbvOptions{};
  o.refine_top = 0;
  EXPECT_NE(o.Validate().message().find("refine_top (0)"), std::string::npos);
}

}  // namespace
}  // namespace avp::planning

namespace avp::planning {
namespace {

/// `key=value` set through `table` must parse and then fail Validate() with `message`.
template <typename O>
void ExpectRefused(const OptionTable<O>& table, const std::string& key, const std::string& value,
                   const std::string& message) {
  O o;
  ASSERT_TRUE(table.Set(o, key, value).ok()) << key;
  const Status s = table.Validate(o);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << key;
  EXPECT_NE(s.message().find(message), std::string::npos) << s.message();
}

TEST(PlannerOptionBoundsTest, OptionsThatScaleWorkHaveUpperBounds) {
  ExpectRefused(AvpNbvOptionTable(), "candidates.max_candidates", "1000000000",
                "candidates.max_candidates (1000000000) must be in [1, 20000]");
  ExpectRefused(AvpNbvOptionTable(), "candidates.ik_restarts", "1000",
                "candidates.ik_restarts (1000) must be in [0, 32]");
  ExpectRefused(AvpNbvOptionTable(), "candidates.max_targets", "100000",
                "candidates.max_targets (100000) must be in [1, 256]");
  ExpectRefused(AvpNbvOptionTable(), "grid.near_target_radius_m", "5",
                "grid.near_target_radius_m (5 m) must be in [0, 0.1]");
  ExpectRefused(AvpNbvOptionTable(), "max_range_m", "1000",
                "max_range_m (1000 m) must be in (0, 10]");
  ExpectRefused(ReferenceNbvOptionTable(), "grid_size", "1000",
                "grid_size (1000) must be in [1, 64]");
  ExpectRefused(ReferenceNbvOptionTable(), "max_range_m", "1000",
                "max_range_m (1000 m) must be in (0, 10]");
  ExpectRefused(IslerPlannerOptionTable(), "rays.max_range_m", "1000",
                "rays.max_range_m (1000 m) must be in (0, 10]");
  ExpectRefused(PredefinedOptionTable(), "generic_waypoints", "1000000",
                "generic_waypoints (1000000) must be in [0, 1000]");
  // The bounds themselves are accepted.
  AvpNbvOptions o;
  ASSERT_TRUE(AvpNbvOptionTable().Set(o, "candidates.max_candidates", "20000").ok());
  ASSERT_TRUE(AvpNbvOptionTable().Set(o, "candidates.ik_restarts", "32").ok());
  ASSERT_TRUE(AvpNbvOptionTable().Set(o, "grid.near_target_radius_m", "0.1").ok());
  EXPECT_TRUE(o.Validate().ok()) << o.Validate().ToString();
  // Each bound is in the table's description (avp run --planner help).
  bool found = false;
  for (const OptionInfo& info : AvpNbvOptionTable().Info()) {
    if (info.key == "candidates.max_candidates") {
      found = true;
      EXPECT_NE(info.range.find("20000"), std::string::npos) << info.range;
    }
  }
  EXPECT_TRUE(found);
}

}  // namespace
}  // namespace avp::planning

// ReferenceNbvPlanner: the 180 candidates around the start pose, the full_attention ROI in one
// frame, the true-FOV ray filter, the utility against hand-computed entropies, no NaN at c = 0
// or 1, and planning that is deterministic by seed and never returns unreachable or fused views.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/mapping/ray_traversal.h>
#include <avp/planning/reference_nbv_planner.h>
#include <avp/robot/arm_model.h>

namespace avp::planning {
namespace {

using ::testing::HasSubstr;

const robot::ArmModel& Arm() {
  static const robot::ArmModel model = robot::LoadDefaultArm(AVP_CONFIG_DIR).value();
  return model;
}

mapping::SemanticMap MakeMap(double voxel_size_m) {
  mapping::MapOptions options;
  options.grid.voxel_size_m = voxel_size_m;
  return mapping::SemanticMap(options);
}

void SetVoxel(mapping::SemanticMap& map, const VoxelKey& k, bool occupied, SemanticClass cls,
              float confidence) {
  ASSERT_TRUE(map.grid().SetLogOdds(k, occupied ? 2.0f : -1.0f));
  if (cls != SemanticClass::kBackground) {
    mapping::SemanticCell* c = map.grid().MutableSemantic(k);
    c->semantic_class = static_cast<uint8_t>(cls);
    c->confidence = confidence;
  }
}

/// A fruit cluster (a 6 x 6 x 6 voxel cube of fruit, confidence 0.6) half hidden behind a leaf
/// wall, in front of the reference start pose.
mapping::SemanticMap ClusterMap() {
  mapping::SemanticMap map = MakeMap(0.01);
  for (int z = 60; z < 66; ++z) {
    for (int y = -3; y < 3; ++y) {
      for (int x = 70; x < 76; ++x) SetVoxel(map, {x, y, z}, true, SemanticClass::kFruit, 0.6f);
    }
  }
  for (int z = 55; z < 75; ++z) {
    for (int y = -12; y < 0; ++y) SetVoxel(map, {62, y, z}, true, SemanticClass::kLeaf, 0.8f);
  }
  for (int z = 30; z < 90; z += 3) {
    for (int y = -20; y < 20; y += 3) SetVoxel(map, {85, y, z}, true, SemanticClass::kStem, 0.5f);
  }
  return map;
}

PlanningRequest StartRequest(const mapping::SemanticMap& map) {
  PlanningRequest r;
  r.map = &map;
  r.arm = &Arm();
  r.q_start = Arm().home_joints();
  r.q_current = r.q_start;
  r.X_WC_start = Arm().CameraPose(r.q_start);
  r.X_WC_current = r.X_WC_start;
  r.K = CameraIntrinsics::RealSenseD435();
  r.roi = Box3(Eigen::Vector3d(0.5, -0.3, 0.2), Eigen::Vector3d(1.0, 0.3, 1.0));
  r.view_index = 1;
  r.views_total = 8;
  r.fused_views = {r.X_WC_start};
  return r;
}

TEST(ReferenceNbvPlannerTest, GeneratesTheReferences180CandidatesAroundTheStartPose) {
  const RigidTransform X_WS = Arm().CameraPose(Arm().home_joints());
  // The start camera looks along +x with image right = -y, image down = -z.
  ASSERT_TRUE(X_WS.rotation().col(2).isApprox(Eigen::Vector3d::UnitX(), 1e-9));
  const ReferenceNbvOptions options;
  Rng rng(7);
  const std::vector<ViewCandidate> c = ReferenceCandidatePoses(X_WS, options, rng);
  ASSERT_EQ(c.size(), 180u);
  const double offsets[6] = {-0.2, -0.12, -0.04, 0.04, 0.12, 0.2};
  double max_jitter = 0.0;
  for (int iz = 0; iz < 6; ++iz) {
    for (int iy = 0; iy < 6; ++iy) {
      const size_t base = static_cast<size_t>(5 * (6 * iz + iy));
      const Eigen::Vector3d grid_point =
          X_WS.translation() + Eigen::Vector3d(0.0, offsets[iy], offsets[iz]);
      const Eigen::Vector3d p = c[base].X_WC.translation();
      // x fixed (the jitter runs along local y = world y and local z = world z here).
      EXPECT_NEAR(p.x(), X_WS.translation().x(), 1e-9);
      const Eigen::Vector3d jitter = p - grid_point;
      EXPECT_LE(jitter.cwiseAbs().maxCoeff(), 0.04 + 1e-12);
      max_jitter = std::max(max_jitter, jitter.cwiseAbs().maxCoeff());
      // Straight, then +-30 deg about local Y (pitch: the view direction stays in the x-z plane),
      // then +-30 deg about local Z (yaw: it stays horizontal), all at the same position.
      EXPECT_TRUE(c[base].X_WC.rotation().isApprox(X_WS.rotation(), 1e-12));
      for (int o = 1; o < 5; ++o) {
        const ViewCandidate& v = c[base + static_cast<size_t>(o)];
        EXPECT_EQ(v.X_WC.translation(), p);
        EXPECT_NEAR(v.X_WC.AngleTo(X_WS), DegToRad(30.0), 1e-9);
        EXPECT_EQ(v.source, "grid");
        EXPECT_FALSE(v.reachable);
        EXPECT_EQ(v.q.size(), 0);
        const Eigen::Vector3d view = v.X_WC.rotation().col(2);
        EXPECT_NEAR(view.x(), std::cos(DegToRad(30.0)), 1e-9);
        if (o <= 2) {
          EXPECT_NEAR(view.y(), 0.0, 1e-9);
          EXPECT_NEAR(std::abs(view.z()), 0.5, 1e-9);
        } else {
          EXPECT_NEAR(view.z(), 0.0, 1e-9);
          EXPECT_NEAR(std::abs(view.y()), 0.5, 1e-9);
        }
      }
      // The two signs of each tilt are mirror images.
      EXPECT_NEAR(c[base + 1].X_WC.rotation().col(2).z(), -c[base + 2].X_WC.rotation().col(2).z(),
                  1e-12);
      EXPECT_NEAR(c[base + 3].X_WC.rotation().col(2).y(), -c[base + 4].X_WC.rotation().col(2).y(),
                  1e-12);
    }
  }
  EXPECT_GT(max_jitter, 0.03);  // the jitter is really drawn
  // Deterministic by seed; another seed jitters differently.
  Rng same(7), other(8);
  const std::vector<ViewCandidate> c2 = ReferenceCandidatePoses(X_WS, options, same);
  const std::vector<ViewCandidate> c3 = ReferenceCandidatePoses(X_WS, options, other);
  for (size_t i = 0; i < c.size(); ++i) {
    EXPECT_EQ(c[i].X_WC.translation(), c2[i].X_WC.translation());
    EXPECT_EQ(c[i].X_WC.rotation(), c2[i].X_WC.rotation());
  }
  EXPECT_NE(c[0].X_WC.translation(), c3[0].X_WC.translation());
}

TEST(ReferenceNbvPlannerTest, FullAttentionRoiIsBuiltAndTestedInTheStartFrame) {
  mapping::SemanticMap map = MakeMap(0.01);
  // Occupied voxel centres spanning x 0.605..0.995 (depth), y -0.195..0.195 (width),
  // z 0.305..0.895 (height); a free voxel outside does not count.
  for (int x = 60; x < 100; x += 39) {
    for (int y = -20; y < 20; y += 39) {
      for (int z = 30; z < 90; z += 59) SetVoxel(map, {x, y, z}, true, SemanticClass::kLeaf, 1.0f);
    }
  }
  SetVoxel(map, {150, 0, 50}, false, SemanticClass::kBackground, 0.0f);
  const RigidTransform X_WS =
      RigidTransform::LookAt(Eigen::Vector3d(0.2, 0.0, 0.6), Eigen::Vector3d(1.0, 0.0, 0.6));
  const FullAttentionRoi roi = ComputeFullAttentionRoi(map, X_WS, ReferenceNbvOptions{});
  ASSERT_FALSE(roi.box_S.IsEmpty());
  // Depth (z_S = x - 0.2): [0.405, 0.795], centre 0.6, kept +-0.39 / 8 = +-0.04875.
  EXPECT_NEAR(roi.box_S.min().z(), 0.6 - 0.04875, 1e-9);
  EXPECT_NEAR(roi.box_S.max().z(), 0.6 + 0.04875, 1e-9);
  // Width (x_S = -y): [-0.195, 0.195], kept +-0.195 / 4.
  EXPECT_NEAR(roi.box_S.min().x(), -0.04875, 1e-9);
  EXPECT_NEAR(roi.box_S.max().x(), 0.04875, 1e-9);
  // Height (y_S = 0.6 - z): [-0.295, 0.295], full.
  EXPECT_NEAR(roi.box_S.min().y(), -0.295, 1e-9);
  EXPECT_NEAR(roi.box_S.max().y(), 0.295, 1e-9);
  // World points, tested in frame S.
  EXPECT_TRUE(roi.Contains(Eigen::Vector3d(0.8, 0.04, 0.35)));
  EXPECT_TRUE(roi.Contains(Eigen::Vector3d(0.8, 0.0, 0.5)));
  EXPECT_FALSE(roi.Contains(Eigen::Vector3d(0.8, 0.06, 0.5)));  // too wide
  EXPECT_FALSE(roi.Contains(Eigen::Vector3d(0.7, 0.0, 0.5)));   // too shallow
  EXPECT_FALSE(roi.Contains(Eigen::Vector3d(0.8, 0.0, 0.95)));  // above every occupied voxel
  // The reference's bug: comparing the S-frame bounds with world coordinates rejects the ROI's
  // own centre.
  EXPECT_FALSE(roi.box_S.Contains(Eigen::Vector3d(0.8, 0.0, 0.6)));
  EXPECT_TRUE(roi.Contains(Eigen::Vector3d(0.8, 0.0, 0.6)));

  // Targets: labelled voxels of the class inside the ROI (one fruit voxel inside, one outside).
  SetVoxel(map, {80, 0, 50}, true, SemanticClass::kFruit, 0.5f);
  SetVoxel(map, {80, 10, 50}, true, SemanticClass::kFruit, 0.5f);
  const FullAttentionRoi roi2 = ComputeFullAttentionRoi(map, X_WS, ReferenceNbvOptions{});
  const std::vector<ReferenceTarget> targets = ReferenceTargets(map, SemanticClass::kFruit, roi2);
  ASSERT_EQ(targets.size(), 1u);
  EXPECT_TRUE(targets[0].p_W.isApprox(Eigen::Vector3d(0.805, 0.005, 0.505), 1e-12));
  // An empty map has an empty ROI and no targets.
  const FullAttentionRoi none = ComputeFullAttentionRoi(MakeMap(0.01), X_WS, {});
  EXPECT_TRUE(none.box_S.IsEmpty());
  EXPECT_TRUE(ReferenceTargets(MakeMap(0.01), SemanticClass::kFruit, none).empty());
}

TEST(ReferenceNbvPlannerTest, RaysOnlyGoToTargetsInsideTheTrueFieldOfView) {
  mapping::SemanticMap map = MakeMap(0.005);
  const RigidTransform X_WC =
      RigidTransform::LookAt(Eigen::Vector3d(0.0, 0.0, 0.5), Eigen::Vector3d(1.0, 0.0, 0.5));
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();  // 55.0 deg x 42.6 deg
  const double half_fov = std::atan(319.5 / K.fx);               // to the last pixel's edge
  // A fruit voxel 0.5 m away at 0.97 and at 1.03 of the horizontal half field of view (left of
  // the image: +y), and one behind the camera.
  auto place = [&](double angle) {
    return Eigen::Vector3d(0.5 * std::cos(angle), 0.5 * std::sin(angle), 0.5);
  };
  const VoxelKey inside = VoxelKey::FromPoint(place(0.97 * half_fov), 0.005);
  const VoxelKey outside = VoxelKey::FromPoint(place(1.03 * half_fov), 0.005);
  const VoxelKey behind = VoxelKey::FromPoint(Eigen::Vector3d(-0.3, 0.0, 0.5), 0.005);
  for (const VoxelKey& k : {inside, outside, behind}) {
    SetVoxel(map, k, true, SemanticClass::kFruit, 0.7f);
  }
  const auto grid = GainGrid::Build(map, SemanticClass::kFruit, Box3());
  ASSERT_TRUE(grid.ok());
  const ReferenceNbvOptions options;
  auto eval = [&](const VoxelKey& k, const CameraIntrinsics& cam) {
    return EvaluateReferenceView(*grid, map, {{k.Center(0.005)}}, X_WC, cam, options);
  };
  const ReferenceViewEvaluation in = eval(inside, K);
  EXPECT_EQ(in.rays, 1u);
  EXPECT_EQ(in.target_hits, 1u);
  EXPECT_NEAR(in.utility, 0.8812909138027454, 1e-12);  // H_b(0.7f)
  EXPECT_EQ(eval(outside, K).rays, 0u);
  EXPECT_EQ(eval(behind, K).rays, 0u);
  // The reference's Gazebo FOV, 2 atan(w / 4f), is about half: the "inside" voxel falls out.
  CameraIntrinsics halved = K;
  halved.fx *= 2.0;
  halved.fy *= 2.0;
  EXPECT_EQ(eval(inside, halved).rays, 0u);
  // Beyond max range (2 m) the ray ends before reaching the voxel: cast, but no hit.
  ReferenceNbvOptions short_range;
  short_range.max_range_m = 0.4;
  const ReferenceViewEvaluation cut =
      EvaluateReferenceView(*grid, map, {{inside.Center(0.005)}}, X_WC, K, short_range);
  EXPECT_EQ(cut.rays, 1u);
  EXPECT_EQ(cut.target_hits, 0u);
  EXPECT_EQ(cut.utility, 0.0);
}

TEST(ReferenceNbvPlannerTest, UtilityIsTheSumOfTheFirstHitTargetEntropies) {
  mapping::SemanticMap map = MakeMap(0.01);
  const Eigen::Vector3d eye(0.005, 0.005, 0.005);  // the centre of voxel (0, 0, 0)
  const RigidTransform X_WC = RigidTransform::LookAt(eye, Eigen::Vector3d(1.0, 0.005, 0.005));
  const VoxelKey a{50, 0, 0}, b{50, 5, 0}, c{50, -5, 0}, d{45, 0, 3}, e{60, 0, 0};
  SetVoxel(map, a, true, SemanticClass::kFruit, 0.7f);
  SetVoxel(map, b, true, SemanticClass::kFruit, 0.9f);
  SetVoxel(map, c, true, SemanticClass::kFruit, 0.6f);
  SetVoxel(map, d, true, SemanticClass::kFruit, 1.0f);  // clamped to 1 - 1e-6
  SetVoxel(map, e, true, SemanticClass::kFruit, 0.5f);  // straight behind a
  // A leaf voxel on the ray to c, 0.3 m along it: that ray stops at the leaf.
  const Eigen::Vector3d c_centre = c.Center(0.01);
  const VoxelKey leaf = VoxelKey::FromPoint(eye + 0.6 * (c_centre - eye), 0.01);
  SetVoxel(map, leaf, true, SemanticClass::kLeaf, 0.9f);
  // Free voxels in front of b (passed) and an unknown-state fruit label (a target, passed).
  SetVoxel(map, {20, 2, 0}, false, SemanticClass::kBackground, 0.0f);
  const auto grid = GainGrid::Build(map, SemanticClass::kFruit, Box3());
  ASSERT_TRUE(grid.ok());
  std::vector<ReferenceTarget> targets;
  for (const VoxelKey& k : {a, b, c, d, e}) targets.push_back({k.Center(0.01)});
  const ReferenceViewEvaluation r =
      EvaluateReferenceView(*grid, map, targets, X_WC, CameraIntrinsics::RealSenseD435(), {});
  EXPECT_EQ(r.rays, 5u);
  EXPECT_EQ(r.target_hits, 4u);  // a, b, d, and a again (on the way to e); c's ray hits the leaf
  // By hand: 2 H_b(0.7f) + H_b(0.9f) + H_b(1 - 1e-6), in bits.
  const double expected = 2 * 0.8812909138027454 + 0.4689956691661781 + 2.1374262889438523e-05;
  EXPECT_NEAR(r.utility, expected, 1e-9);
  // Confidence 0 and 1 give finite, tiny entropies instead of NaN.
  mapping::SemanticMap extremes = MakeMap(0.01);
  SetVoxel(extremes, a, true, SemanticClass::kFruit, 0.0f);
  SetVoxel(extremes, b, true, SemanticClass::kFruit, 1.0f);
  const auto grid2 = GainGrid::Build(extremes, SemanticClass::kFruit, Box3());
  ASSERT_TRUE(grid2.ok());
  const ReferenceViewEvaluation x =
      EvaluateReferenceView(*grid2, extremes, {{a.Center(0.01)}, {b.Center(0.01)}}, X_WC,
                            CameraIntrinsics::RealSenseD435(), {});
  EXPECT_FALSE(std::isnan(x.utility));
  EXPECT_NEAR(x.utility, 2 * 2.1374262889438523e-05, 1e-12);
}

void ExpectValidRanking(const PlanResult& plan, const PlanningRequest& request) {
  for (const ViewCandidate& c : plan.ranked) {
    EXPECT_TRUE(c.reachable);
    ASSERT_EQ(c.q.size(), 6);
    EXPECT_TRUE(Arm().WithinLimits(c.q));
    EXPECT_TRUE(Arm().CameraPose(c.q).IsNearlyEqualTo(c.X_WC, 1e-3, 1e-2));
    EXPECT_FALSE(IsNearAny(c.X_WC, request.fused_views));
    EXPECT_FALSE(IsNearAny(c.X_WC, {request.X_WC_current}));
    EXPECT_FALSE(std::isnan(c.utility));
    EXPECT_NEAR(c.cost, (c.q - request.q_current).norm(), 1e-12);
  }
}

TEST(ReferenceNbvPlannerTest, PlansDeterministicallyAndNeverReturnsUnreachableOrFusedViews) {
  const mapping::SemanticMap map = ClusterMap();
  PlanningRequest request = StartRequest(map);
  ReferenceNbvPlanner planner;
  EXPECT_EQ(planner.name(), "reference-nbv");
  Rng rng(11);
  const PlanResult plan = [&] {
    const ThreadScope one(1);
    return planner.Plan(request, rng);
  }();
  ASSERT_TRUE(plan.status.ok()) << plan.status.ToString();
  EXPECT_EQ(plan.generated, 180u);
  EXPECT_GT(plan.reachable, 40u);
  EXPECT_LT(plan.reachable, 180u);
  EXPECT_EQ(plan.ranked.size(), plan.reachable);
  ExpectValidRanking(plan, request);
  // Sorted by utility; the best sees the fruit.
  EXPECT_GT(plan.ranked[0].utility, 1.0);
  EXPECT_EQ(plan.ranked[0].gain, plan.ranked[0].utility);
  for (size_t i = 1; i < plan.ranked.size(); ++i) {
    EXPECT_GE(plan.ranked[i - 1].utility, plan.ranked[i].utility);
  }
  EXPECT_EQ(plan.ranked[0].source, "grid");

  // The same seed gives the same plan; multi-threaded evaluation changes nothing.
  Rng rng2(11);
  ReferenceNbvPlanner threaded_planner{ReferenceNbvOptions{}};
  const PlanResult again = [&] {
    const ThreadScope three(3);
    return threaded_planner.Plan(request, rng2);
  }();
  ASSERT_EQ(again.ranked.size(), plan.ranked.size());
  for (size_t i = 0; i < plan.ranked.size(); ++i) {
    EXPECT_EQ(again.ranked[i].X_WC.translation(), plan.ranked[i].X_WC.translation());
    EXPECT_EQ(again.ranked[i].utility, plan.ranked[i].utility);
    EXPECT_EQ(again.ranked[i].q, plan.ranked[i].q);
  }

  // Next step: the chosen view is fused; it is never chosen again, and neither is the pose the
  // camera now has.
  request.view_index = 2;
  request.q_current = plan.ranked[0].q;
  request.X_WC_current = plan.ranked[0].X_WC;
  request.fused_views.push_back(plan.ranked[0].X_WC);
  Rng rng3(12);
  const PlanResult next = planner.Plan(request, rng3);
  ASSERT_TRUE(next.status.ok()) << next.status.ToString();
  ExpectValidRanking(next, request);
}

TEST(ReferenceNbvPlannerTest, WithoutPositiveUtilityRanksReachableCandidatesInSeededRandomOrder) {
  const mapping::SemanticMap empty = MakeMap(0.01);
  const PlanningRequest request = StartRequest(empty);
  ReferenceNbvPlanner planner;
  Rng a(5), b(5), c(6);
  const PlanResult pa = planner.Plan(request, a);
  const PlanResult pb = planner.Plan(request, b);
  const PlanResult pc = planner.Plan(request, c);
  ASSERT_TRUE(pa.status.ok()) << pa.status.ToString();
  EXPECT_GT(pa.ranked.size(), 40u);
  EXPECT_EQ(pa.ranked.size(), pa.reachable);
  ExpectValidRanking(pa, request);
  for (const ViewCandidate& v : pa.ranked) {
    EXPECT_EQ(v.utility, 0.0);
    EXPECT_EQ(v.source, "grid-random");
  }
  ASSERT_EQ(pa.ranked.size(), pb.ranked.size());
  for (size_t i = 0; i < pa.ranked.size(); ++i) {
    EXPECT_EQ(pa.ranked[i].X_WC.translation(), pb.ranked[i].X_WC.translation());
  }
  // Another seed: another order (and other jitter).
  EXPECT_NE(pa.ranked[0].X_WC.translation(), pc.ranked[0].X_WC.translation());
  // Not the cost order RankCandidates would give: the order is shuffled.
  bool sorted_by_cost = true;
  for (size_t i = 1; i < pa.ranked.size(); ++i) {
    sorted_by_cost = sorted_by_cost && pa.ranked[i - 1].cost <= pa.ranked[i].cost;
  }
  EXPECT_FALSE(sorted_by_cost);
}

TEST(ReferenceNbvPlannerTest, NoReachableCandidateIsAStatusNotACrash) {
  const mapping::SemanticMap map = ClusterMap();
  PlanningRequest request = StartRequest(map);
  // A start pose far out of reach: every candidate fails IK.
  request.X_WC_start =
      RigidTransform::LookAt(Eigen::Vector3d(2.0, 0.0, 0.6), Eigen::Vector3d(3.0, 0.0, 0.6));
  ReferenceNbvPlanner planner;
  Rng rng(1);
  const PlanResult plan = planner.Plan(request, rng);
  EXPECT_EQ(plan.status.code(), StatusCode::kNotFound);
  EXPECT_THAT(plan.status.message(), HasSubstr("no valid candidate: 180 generated"));
  EXPECT_THAT(plan.status.message(), HasSubstr("0 of 180 reachable"));
  EXPECT_TRUE(plan.ranked.empty());
  EXPECT_EQ(plan.generated, 180u);
  EXPECT_EQ(plan.reachable, 0u);

  ReferenceNbvOptions bad;
  bad.depth_ratio = 0.5;
  bad.confidence_epsilon = 0.0;
  EXPECT_THAT(bad.Validate().message(), HasSubstr("depth_ratio (0.5) must be >= 1"));
  EXPECT_THAT(bad.Validate().message(), HasSubstr("confidence_epsilon (0)"));
  EXPECT_THROW(ReferenceNbvPlanner{bad}, Error);
}

// ---- Shared planner helpers (view_planner.h) ------------------------------------------------

TEST(ViewPlannerTest, RankCandidatesSortsByUtilityThenCostThenOrderAndDropsUnreachable) {
  auto make = [](double utility, double cost, bool reachable, const char* source) {
    ViewCandidate c;
    c.utility = utility;
    c.cost = cost;
    c.reachable = reachable;
    c.source = source;
    return c;
  };
  std::vector<ViewCandidate> c = {make(1.0, 0.5, true, "a"), make(2.0, 0.9, true, "b"),
                                  make(1.0, 0.2, true, "c"), make(5.0, 0.1, false, "d"),
                                  make(1.0, 0.2, true, "e"), make(std::nan(""), 0.0, true, "f"),
                                  make(-1.0, 0.0, true, "g")};
  const PlanResult r = RankCandidates(c, 10, "test");
  ASSERT_TRUE(r.status.ok());
  EXPECT_EQ(r.generated, 10u);
  EXPECT_EQ(r.reachable, 6u);
  std::string order;
  for (const ViewCandidate& v : r.ranked) order += v.source;
  EXPECT_EQ(order, "bceagf");  // NaN last; ties by lower cost, then generation order
  const PlanResult none = RankCandidates({make(1.0, 0.0, false, "x")}, 3, "test");
  EXPECT_EQ(none.status.code(), StatusCode::kNotFound);
  EXPECT_THAT(none.status.message(), HasSubstr("test: no valid candidate: 3 generated, 1 kept"));
  EXPECT_TRUE(none.ranked.empty());
}

TEST(ViewPlannerTest, IsNearAnyUsesBothTolerances) {
  const RigidTransform a =
      RigidTransform::LookAt(Eigen::Vector3d(0.2, 0, 0.6), Eigen::Vector3d(1, 0, 0.6));
  const RigidTransform moved(a.rotation(), a.translation() + Eigen::Vector3d(0.0, 0.019, 0.0));
  const RigidTransform far(a.rotation(), a.translation() + Eigen::Vector3d(0.0, 0.021, 0.0));
  const RigidTransform turned = RigidTransform::LookAt(
      a.translation(), a.translation() + Eigen::Vector3d(1.0, std::tan(DegToRad(11.0)), 0.0));
  EXPECT_TRUE(IsNearAny(a, {far, a}));
  EXPECT_TRUE(IsNearAny(moved, {a}));
  EXPECT_FALSE(IsNearAny(far, {a}));
  EXPECT_FALSE(IsNearAny(turned, {a}));
  EXPECT_TRUE(IsNearAny(turned, {a}, 0.02, DegToRad(12.0)));
  EXPECT_FALSE(IsNearAny(a, {}));
}

TEST(ViewPlannerTest, ValidateRequestNamesEveryBadField) {
  const mapping::SemanticMap map = MakeMap(0.01);
  EXPECT_TRUE(ValidateRequest(StartRequest(map)).ok());
  PlanningRequest r = StartRequest(map);
  r.map = nullptr;
  r.q_current = Eigen::VectorXd::Zero(5);
  r.K.fx = -1.0;
  r.roi = Box3();
  r.view_index = 0;
  r.target_class = SemanticClass::kBackground;
  const Status s = ValidateRequest(r);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("map must not be null"));
  EXPECT_THAT(s.message(), HasSubstr("q_current has 5 joints, the arm has 6"));
  EXPECT_THAT(s.message(), HasSubstr("fx (-1)"));
  EXPECT_THAT(s.message(), HasSubstr("roi"));
  EXPECT_THAT(s.message(), HasSubstr("view_index (0) must be >= 1"));
  EXPECT_THAT(s.message(), HasSubstr("target_class (0)"));
  PlanningRequest nan = StartRequest(map);
  nan.q_start[2] = std::nan("");
  EXPECT_THAT(ValidateRequest(nan).message(), HasSubstr("q_start has a non-finite entry"));
  PlanningRequest no_start = StartRequest(map);
  no_start.q_start.resize(0);  // optional
  EXPECT_TRUE(ValidateRequest(no_start).ok());
}

}  // namespace
}  // namespace avp::planning

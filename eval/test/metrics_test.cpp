// Map metrics on hand-made maps and ground truths with hand-counted answers: exact and tolerant
// voxel scores, the found-fruit rule at its threshold, the sphere fit, entropy, coverage.
#include <cmath>
#include <limits>
#include <optional>
#include <unordered_map>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/entropy.h>
#include <avp/core/error.h>
#include <avp/eval/metrics.h>
#include <avp/sim/ground_truth.h>

namespace avp::eval {
namespace {

using ::testing::HasSubstr;

constexpr double kS = 0.01;  // voxel edge of the hand-made maps

mapping::SemanticMap EmptyMap(double s = kS) {
  mapping::MapOptions options;
  options.grid.voxel_size_m = s;
  return mapping::SemanticMap(options);
}

/// Marks k occupied (or free) and labels it.
void Label(mapping::SemanticMap& map, const VoxelKey& k, SemanticClass c, bool occupied = true,
           float confidence = 0.9f, uint16_t instance = 0) {
  mapping::OccupancyGrid& grid = map.grid();
  ASSERT_TRUE(grid.SetLogOdds(k, occupied ? grid.clamp_max_log_odds() : grid.clamp_min_log_odds()));
  mapping::SemanticCell* cell = grid.MutableSemantic(k);
  ASSERT_NE(cell, nullptr);
  cell->semantic_class = static_cast<uint8_t>(c);
  cell->confidence = confidence;
  cell->instance_id = instance;
  cell->observations = 1;
}

sim::FruitTruth Fruit(uint16_t id, const Eigen::Vector3d& c = Eigen::Vector3d::Zero(),
                      double r = 0.03) {
  sim::FruitTruth f;
  f.instance_id = id;
  f.name = "fruit";
  f.center_W = c;
  f.radii = Eigen::Vector3d::Constant(r);
  return f;
}

/// A ground truth from (key, fruit) pairs; voxels_per_fruit counted, every fruit listed.
GroundTruth MakeGt(const std::vector<std::pair<VoxelKey, uint16_t>>& voxels,
                   const std::vector<sim::FruitTruth>& fruits, double s = kS) {
  GroundTruth gt;
  gt.voxel_size_m = s;
  gt.fruits = fruits;
  for (const sim::FruitTruth& f : fruits) gt.voxels_per_fruit[f.instance_id] = 0;
  for (const auto& [k, id] : voxels) {
    gt.voxels[k] = id;
    ++gt.voxels_per_fruit[id];
  }
  gt.source = "hand-made";
  return gt;
}

/// Fruit 1: five voxels in a row; fruit 2: two voxels; fruit 3: never observable.
GroundTruth RowGt() {
  return MakeGt({{{0, 0, 0}, 1},
                 {{1, 0, 0}, 1},
                 {{2, 0, 0}, 1},
                 {{3, 0, 0}, 1},
                 {{4, 0, 0}, 1},
                 {{20, 0, 0}, 2},
                 {{21, 0, 0}, 2}},
                {Fruit(1), Fruit(2), Fruit(3)});
}

TEST(MetricsTest, ExactAndTolerantCountsMatchHandCounts) {
  const GroundTruth gt = RowGt();
  mapping::SemanticMap map = EmptyMap();
  Label(map, {0, 0, 0}, SemanticClass::kFruit);                        // exact hit
  Label(map, {1, 0, 0}, SemanticClass::kFruit);                        // exact hit
  Label(map, {3, 1, 0}, SemanticClass::kFruit);                        // next to (2..4, 0, 0)
  Label(map, {10, 10, 10}, SemanticClass::kFruit);                     // far from everything
  Label(map, {20, 0, 0}, SemanticClass::kFruit);                       // exact hit, fruit 2
  Label(map, {4, 0, 0}, SemanticClass::kFruit, /*occupied=*/false);    // free: not predicted
  Label(map, {2, 0, 0}, SemanticClass::kLeaf);                         // other class
  map.grid().SetLogOdds({21, 0, 0}, map.grid().clamp_max_log_odds());  // occupied, unlabelled

  const MapMetrics m = EvaluateMap(map, gt);
  EXPECT_EQ(m.predicted_voxels, 5u);
  // Exact: tp = 3 of 5 predicted, 7 GT.
  EXPECT_EQ(m.exact.predicted, 5u);
  EXPECT_EQ(m.exact.ground_truth, 7u);
  EXPECT_EQ(m.exact.tp, 3u);
  EXPECT_EQ(m.exact.fp, 2u);
  EXPECT_EQ(m.exact.fn, 4u);
  EXPECT_DOUBLE_EQ(m.exact.precision, 3.0 / 5.0);
  EXPECT_DOUBLE_EQ(m.exact.recall, 3.0 / 7.0);
  EXPECT_NEAR(m.exact.f1, 0.5, 1e-12);  // 2 (9/35) / (36/35)
  // Tolerant: only (10, 10, 10) has no GT neighbour; every GT voxel has a predicted neighbour
  // ((4, 0, 0) through (3, 1, 0) diagonally, (21, 0, 0) through (20, 0, 0)).
  EXPECT_EQ(m.tolerant.fp, 1u);
  EXPECT_EQ(m.tolerant.tp, 7u);
  EXPECT_EQ(m.tolerant.fn, 0u);
  EXPECT_DOUBLE_EQ(m.tolerant.precision, 4.0 / 5.0);
  EXPECT_DOUBLE_EQ(m.tolerant.recall, 1.0);
  EXPECT_NEAR(m.tolerant.f1, 2.0 * 0.8 / 1.8, 1e-12);
  // Fruits: 1 is found (5 of 5 recalled), 2 is not (2 < 3 voxels), 3 is never observable.
  EXPECT_EQ(m.fruits.total, 3u);
  EXPECT_EQ(m.fruits.observable, 2u);
  EXPECT_EQ(m.fruits.found, 1u);
  EXPECT_DOUBLE_EQ(m.fruits.found_fraction, 1.0 / 3.0);
  EXPECT_FALSE(std::isnan(m.fruits.mean_center_error_m));
  EXPECT_EQ(m.fruits.map_instances, 0u);
}

TEST(MetricsTest, ScoreVoxelSetsIgnoresDuplicatesAndWidensWithTolerance) {
  const GroundTruth gt = RowGt();
  const std::vector<VoxelKey> pred = {{0, 0, 0}, {0, 0, 0}, {6, 0, 0}, {8, 0, 0}};
  const VoxelScores exact = ScoreVoxelSets(pred, gt, 0);
  EXPECT_EQ(exact.predicted, 3u);
  EXPECT_EQ(exact.tp, 1u);
  EXPECT_EQ(exact.fp, 2u);
  EXPECT_EQ(exact.fn, 6u);
  const VoxelScores one = ScoreVoxelSets(pred, gt, 1);
  EXPECT_EQ(one.fp, 2u);  // (6, 0, 0) is two voxels from (4, 0, 0)
  EXPECT_EQ(one.tp, 2u);  // (0, 0, 0), (1, 0, 0)
  const VoxelScores two = ScoreVoxelSets(pred, gt, 2);
  EXPECT_EQ(two.fp, 1u);  // (8, 0, 0) is still four away
  EXPECT_EQ(two.tp, 4u);  // (0..2, 0, 0) via (0, 0, 0); (4, 0, 0) via (6, 0, 0)
  EXPECT_DOUBLE_EQ(two.precision, 2.0 / 3.0);
  EXPECT_DOUBLE_EQ(two.recall, 4.0 / 7.0);

  const VoxelScores none = ScoreVoxelSets({}, gt, 1);
  EXPECT_EQ(none.precision, 0.0);
  EXPECT_EQ(none.recall, 0.0);
  EXPECT_EQ(none.f1, 0.0);
  EXPECT_EQ(none.fn, 7u);
  EXPECT_THROW(ScoreVoxelSets(pred, gt, -1), Error);
}

TEST(MetricsTest, FoundRuleAtItsThreshold) {
  // Fruit 1: 16 GT voxels two apart along x, so a predicted voxel on one recalls exactly one.
  // With found_min_fraction 0.25 it needs max(3, 4) = 4 recalled voxels.
  // Fruit 2: 8 voxels two apart along y at x = 100; 0.25 x 8 = 2, so found_min_voxels (3) rules.
  std::vector<std::pair<VoxelKey, uint16_t>> voxels;
  for (int i = 0; i < 16; ++i) voxels.push_back({{2 * i, 0, 0}, 1});
  for (int i = 0; i < 8; ++i) voxels.push_back({{100, 2 * i, 0}, 2});
  const GroundTruth gt = MakeGt(voxels, {Fruit(1), Fruit(2)});
  EvalOptions options;
  options.found_min_fraction = 0.25;
  options.found_min_voxels = 3;
  for (int recalled = 0; recalled <= 6; ++recalled) {
    mapping::SemanticMap map = EmptyMap();
    for (int i = 0; i < recalled; ++i) {
      Label(map, {2 * i, 0, 0}, SemanticClass::kFruit);
      Label(map, {100, 2 * i, 0}, SemanticClass::kFruit);
    }
    const MapMetrics m = EvaluateMap(map, gt, options);
    const size_t expected = (recalled >= 4 ? 1u : 0u) + (recalled >= 3 ? 1u : 0u);
    EXPECT_EQ(m.fruits.found, expected) << recalled << " recalled";
    EXPECT_EQ(m.tolerant.tp, 2u * static_cast<size_t>(recalled));
    if (expected == 0) {
      EXPECT_TRUE(std::isnan(m.fruits.mean_center_error_m));
      EXPECT_TRUE(std::isnan(m.fruits.mean_radius_error_m));
    }
  }
  // The fraction rules for large fruits: 0.5 x 16 = 8 needed.
  options.found_min_fraction = 0.5;
  mapping::SemanticMap map = EmptyMap();
  for (int i = 0; i < 7; ++i) Label(map, {2 * i, 0, 0}, SemanticClass::kFruit);
  EXPECT_EQ(EvaluateMap(map, gt, options).fruits.found, 0u);
  Label(map, {14, 0, 0}, SemanticClass::kFruit);
  EXPECT_EQ(EvaluateMap(map, gt, options).fruits.found, 1u);
}

TEST(MetricsTest, SphereFitRecoversVoxelisedSphere) {
  const double s = 0.005;
  const Eigen::Vector3d c(0.1234, -0.0567, 0.4321);
  const double r = 0.035;
  sim::Scene scene;
  sim::SceneObject o;
  o.name = "fruit";
  o.semantic_class = SemanticClass::kFruit;
  sim::Ellipsoid e;
  e.center_W = c;
  e.radii = Eigen::Vector3d::Constant(r);
  o.shape = e;
  scene.Add(o);
  const sim::FruitVoxels surface = sim::VoxelizeFruitSurfaces(scene, s);
  std::vector<Eigen::Vector3d> all;
  std::vector<Eigen::Vector3d> front;  // the half facing -x, as one side of a fruit is seen
  for (const VoxelKey& k : surface.SortedKeys()) {
    all.push_back(k.Center(s));
    if (k.Center(s).x() < c.x()) front.push_back(k.Center(s));
  }
  ASSERT_GT(all.size(), 300u);
  const SphereFit full = FitSphere(all);
  EXPECT_TRUE(full.fitted);
  EXPECT_LT((full.center - c).norm(), 0.2 * s);
  EXPECT_NEAR(full.radius_m, r, 0.2 * s);
  const SphereFit half = FitSphere(front);
  EXPECT_TRUE(half.fitted);
  EXPECT_LT((half.center - c).norm(), s);
  EXPECT_NEAR(half.radius_m, r, s);

  // Fewer than 10 points: the centroid, radius = mean distance to it.
  const std::vector<Eigen::Vector3d> few = {{0, 0, 0}, {2, 0, 0}, {1, 1, 0}, {1, -1, 0}};
  const SphereFit f = FitSphere(few);
  EXPECT_FALSE(f.fitted);
  EXPECT_TRUE(f.center.isApprox(Eigen::Vector3d(1, 0, 0)));
  EXPECT_DOUBLE_EQ(f.radius_m, 1.0);
  // A flat patch is degenerate (rank-deficient): the centroid.
  std::vector<Eigen::Vector3d> flat;
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 5; ++j) flat.emplace_back(0.01 * i, 0.01 * j, 0.3);
  }
  const SphereFit p = FitSphere(flat);
  EXPECT_FALSE(p.fitted);
  EXPECT_TRUE(p.center.isApprox(Eigen::Vector3d(0.02, 0.02, 0.3)));
  EXPECT_THROW(FitSphere({}), Error);
}

TEST(MetricsTest, CentreAndSizeErrorOfAPerfectMapAreBelowAVoxel) {
  const double s = 0.005;
  const Eigen::Vector3d c1(0.50, 0.10, 0.60);
  const Eigen::Vector3d c2(0.50, 0.20, 0.62);
  sim::Scene scene;
  for (const auto& [c, r] : {std::pair{c1, 0.03}, std::pair{c2, 0.025}}) {
    sim::SceneObject o;
    o.name = "fruit";
    o.semantic_class = SemanticClass::kFruit;
    sim::Ellipsoid e;
    e.center_W = c;
    e.radii = Eigen::Vector3d::Constant(r);
    o.shape = e;
    scene.Add(o);
  }
  const sim::FruitVoxels surface = sim::VoxelizeFruitSurfaces(scene, s);
  std::vector<std::pair<VoxelKey, uint16_t>> voxels(surface.voxels.begin(), surface.voxels.end());
  const GroundTruth gt = MakeGt(voxels, scene.Fruits(), s);
  mapping::SemanticMap map = EmptyMap(s);
  for (const auto& [k, id] : voxels) Label(map, k, SemanticClass::kFruit, true, 0.9f, id);
  const MapMetrics m = EvaluateMap(map, gt);
  EXPECT_DOUBLE_EQ(m.exact.f1, 1.0);
  EXPECT_DOUBLE_EQ(m.tolerant.f1, 1.0);
  EXPECT_EQ(m.fruits.found, 2u);
  EXPECT_EQ(m.fruits.map_instances, 2u);
  EXPECT_LT(m.fruits.mean_center_error_m, 0.2 * s);
  EXPECT_LT(m.fruits.mean_radius_error_m, 0.2 * s);
  // Shift the prediction by one voxel along x: exact F1 collapses, tolerant F1 stays high, and
  // the centre error is about one voxel.
  mapping::SemanticMap shifted = EmptyMap(s);
  for (const auto& [k, id] : voxels) {
    Label(shifted, {k.x + 1, k.y, k.z}, SemanticClass::kFruit, true, 0.9f, id);
  }
  const MapMetrics ms = EvaluateMap(shifted, gt);
  EXPECT_LT(ms.exact.f1, 0.8);
  EXPECT_DOUBLE_EQ(ms.tolerant.f1, 1.0);  // every shifted voxel touches its original
  EXPECT_EQ(ms.fruits.found, 2u);
  EXPECT_NEAR(ms.fruits.mean_center_error_m, s, 0.3 * s);
}

TEST(MetricsTest, PerFruitResultsMatchHandCountsAndTheAggregates) {
  // RowGt: fruit 1 = keys x 0..4, fruit 2 = x 20, 21, fruit 3 never observable. Predicted: x 0..3
  // (recall all five of fruit 1: x 4 touches x 3) and x 22 (recalls x 21 only).
  GroundTruth gt = RowGt();
  gt.best_visible_fraction = {{1, 0.8}, {2, 0.1}, {3, 0.0}};
  mapping::SemanticMap map = EmptyMap();
  for (int x = 0; x <= 3; ++x) Label(map, {x, 0, 0}, SemanticClass::kFruit);
  Label(map, {22, 0, 0}, SemanticClass::kFruit);
  std::vector<FruitResult> fruits;
  const MapMetrics m = EvaluateMap(map, gt, {}, &fruits);
  ASSERT_EQ(fruits.size(), 3u);
  EXPECT_EQ(fruits[0].instance_id, 1);
  EXPECT_EQ(fruits[0].observable_voxels, 5u);
  EXPECT_EQ(fruits[0].recalled_voxels, 5u);
  EXPECT_EQ(fruits[0].matched_voxels, 4u);
  EXPECT_TRUE(fruits[0].found);
  EXPECT_DOUBLE_EQ(fruits[0].best_visible_fraction, 0.8);
  EXPECT_DOUBLE_EQ(fruits[0].radius_m, 0.03);
  // Four points: the centroid (0.02, 0.005, 0.005), radius = mean distance 0.01.
  EXPECT_TRUE(fruits[0].estimated);
  EXPECT_FALSE(fruits[0].sphere_fitted);
  EXPECT_TRUE(fruits[0].estimated_center_W.isApprox(Eigen::Vector3d(0.02, 0.005, 0.005)));
  EXPECT_NEAR(fruits[0].estimated_radius_m, 0.01, 1e-12);
  EXPECT_NEAR(fruits[0].center_error_m, std::sqrt(0.00045), 1e-12);
  EXPECT_NEAR(fruits[0].radius_error_m, 0.02, 1e-12);
  // Fruit 2: one recalled voxel of the three needed: not found, no estimate.
  EXPECT_EQ(fruits[1].recalled_voxels, 1u);
  EXPECT_EQ(fruits[1].matched_voxels, 1u);
  EXPECT_FALSE(fruits[1].found);
  EXPECT_FALSE(fruits[1].estimated);
  EXPECT_TRUE(std::isnan(fruits[1].center_error_m));
  EXPECT_DOUBLE_EQ(fruits[1].best_visible_fraction, 0.1);
  EXPECT_EQ(fruits[2].observable_voxels, 0u);
  EXPECT_FALSE(fruits[2].found);
  // The episode fields are the runner's: unset here.
  for (const FruitResult& f : fruits) {
    EXPECT_EQ(f.found_view, -1);
    EXPECT_TRUE(std::isnan(f.episode_visible_fraction));
  }
  // The same found set and errors as the aggregates, and as FoundFruitIds.
  EXPECT_EQ(m.fruits.found, 1u);
  EXPECT_DOUBLE_EQ(m.fruits.mean_center_error_m, fruits[0].center_error_m);
  EXPECT_DOUBLE_EQ(m.fruits.mean_radius_error_m, fruits[0].radius_error_m);
  EXPECT_EQ(FoundFruitIds(PredictedVoxels(map, SemanticClass::kFruit), gt, {}),
            std::vector<uint16_t>{1});
  // EvaluateFruits gives the same list; a ground truth without fruits gives none.
  const std::vector<FruitResult> again = EvaluateFruits(map, gt);
  ASSERT_EQ(again.size(), 3u);
  EXPECT_EQ(again[0].center_error_m, fruits[0].center_error_m);
  GroundTruth file = MakeGt({{{0, 0, 0}, 0}, {{1, 0, 0}, 0}}, {});
  EXPECT_TRUE(EvaluateFruits(map, file).empty());
  // No best visible fraction in the ground truth: NaN.
  EXPECT_TRUE(std::isnan(EvaluateFruits(map, RowGt())[0].best_visible_fraction));
}

TEST(MetricsTest, PerFruitErrorsOfTwoSpheresAverageToTheAggregates) {
  const double s = 0.005;
  sim::Scene scene;
  for (const auto& [c, r] : {std::pair{Eigen::Vector3d(0.50, 0.10, 0.60), 0.03},
                             std::pair{Eigen::Vector3d(0.50, 0.20, 0.62), 0.025}}) {
    sim::SceneObject o;
    o.name = "fruit";
    o.semantic_class = SemanticClass::kFruit;
    sim::Ellipsoid e;
    e.center_W = c;
    e.radii = Eigen::Vector3d::Constant(r);
    o.shape = e;
    scene.Add(o);
  }
  const sim::FruitVoxels surface = sim::VoxelizeFruitSurfaces(scene, s);
  std::vector<std::pair<VoxelKey, uint16_t>> voxels(surface.voxels.begin(), surface.voxels.end());
  const GroundTruth gt = MakeGt(voxels, scene.Fruits(), s);
  // The prediction: the half of each fruit facing -x, shifted one voxel along +x.
  mapping::SemanticMap map = EmptyMap(s);
  for (const auto& [k, id] : voxels) {
    if (k.Center(s).x() < 0.50) Label(map, {k.x + 1, k.y, k.z}, SemanticClass::kFruit);
  }
  std::vector<FruitResult> fruits;
  const MapMetrics m = EvaluateMap(map, gt, {}, &fruits);
  ASSERT_EQ(fruits.size(), 2u);
  ASSERT_TRUE(fruits[0].found && fruits[1].found);
  EXPECT_TRUE(fruits[0].sphere_fitted && fruits[1].sphere_fitted);
  EXPECT_DOUBLE_EQ(fruits[1].radius_m, 0.025);
  for (const FruitResult& f : fruits) {
    EXPECT_GT(f.matched_voxels, 50u);
    EXPECT_LT(f.center_error_m, 2.0 * s) << f.instance_id;  // about the one-voxel shift
    EXPECT_LT(f.radius_error_m, 1.5 * s) << f.instance_id;
  }
  EXPECT_NEAR(m.fruits.mean_center_error_m,
              (fruits[0].center_error_m + fruits[1].center_error_m) / 2.0, 1e-15);
  EXPECT_NEAR(m.fruits.mean_radius_error_m,
              (fruits[0].radius_error_m + fruits[1].radius_error_m) / 2.0, 1e-15);
}

TEST(MetricsTest, FruitTrackerKeepsTheFirstFindAndTheLastFoundRun) {
  // RowGt's fruit 1 (x 0..4) and fruit 2 (x 20, 21; needs 3 recalled: never found) over four
  // views: fruit 1 found after view 0, lost after view 1 (its voxels carved away), found again
  // after view 2 and kept. Fruit 1 is visible 0.3, then 0.6 at view 2; view 1 has no labels.
  const GroundTruth gt = RowGt();
  mapping::SemanticMap found = EmptyMap();
  for (int x = 0; x <= 4; ++x) Label(found, {x, 0, 0}, SemanticClass::kFruit);
  mapping::SemanticMap lost = EmptyMap();
  Label(lost, {0, 0, 0}, SemanticClass::kFruit);  // two recalled voxels: below 3
  using Visible = std::optional<std::unordered_map<uint16_t, double>>;
  FruitTracker tracker;
  EXPECT_TRUE(tracker.Result().empty());
  tracker.AfterView(0, EvaluateFruits(found, gt), Visible({{1, 0.3}}));
  tracker.AfterView(1, EvaluateFruits(lost, gt), std::nullopt);
  std::vector<FruitResult> r = tracker.Result();
  ASSERT_EQ(r.size(), 3u);
  EXPECT_FALSE(r[0].found);  // the last view's evaluation
  EXPECT_EQ(r[0].found_view, 0);
  EXPECT_EQ(r[0].found_since_view, -1);  // not found at the end
  tracker.AfterView(2, EvaluateFruits(found, gt), Visible({{1, 0.6}, {2, 0.1}}));
  tracker.AfterView(3, EvaluateFruits(found, gt), Visible({{1, 0.5}}));
  r = tracker.Result();
  EXPECT_TRUE(r[0].found);
  EXPECT_EQ(r[0].found_view, 0);
  EXPECT_EQ(r[0].found_since_view, 2);
  EXPECT_DOUBLE_EQ(r[0].episode_visible_fraction, 0.6);
  EXPECT_EQ(r[0].episode_best_view, 2);
  EXPECT_FALSE(r[1].found);
  EXPECT_EQ(r[1].found_view, -1);
  EXPECT_DOUBLE_EQ(r[1].episode_visible_fraction, 0.1);
  EXPECT_EQ(r[1].episode_best_view, 2);
  // Fruit 3 was in no view's fractions: 0 from the first labelled view on.
  EXPECT_DOUBLE_EQ(r[2].episode_visible_fraction, 0.0);
  EXPECT_EQ(r[2].episode_best_view, 0);
  // The map fields are the last evaluation's.
  EXPECT_EQ(r[0].recalled_voxels, 5u);
}

TEST(MetricsTest, EntropyOfTargetLabelledVoxels) {
  const GroundTruth gt = RowGt();
  mapping::SemanticMap map = EmptyMap();
  Label(map, {0, 0, 0}, SemanticClass::kFruit, true, 0.5f);
  Label(map, {1, 0, 0}, SemanticClass::kFruit, true, 0.9f);
  Label(map, {2, 0, 0}, SemanticClass::kFruit, false, 1.0f);  // free but labelled: counts
  Label(map, {3, 0, 0}, SemanticClass::kFruit, true, 0.0f);
  Label(map, {4, 0, 0}, SemanticClass::kLeaf, true, 0.5f);  // other class: does not count
  const MapMetrics m = EvaluateMap(map, gt);
  const double h09 = -(0.9 * std::log2(0.9) + 0.1 * std::log2(0.1));  // 0.468996 bits
  const double h_edge = -((1 - 1e-6) * std::log2(1 - 1e-6) + 1e-6 * std::log2(1e-6));
  EXPECT_EQ(m.labelled_voxels, 4u);
  EXPECT_EQ(m.predicted_voxels, 3u);
  // 0.9f is not 0.9: compare with the float's entropy.
  EXPECT_NEAR(m.entropy_sum_bits, 1.0 + ClampedBinaryEntropyBits(0.9f) + 2.0 * h_edge, 1e-12);
  EXPECT_NEAR(m.entropy_mean_bits, m.entropy_sum_bits / 4.0, 1e-15);
  EXPECT_NEAR(ClampedBinaryEntropyBits(0.9), h09, 1e-15);
  EXPECT_NEAR(ClampedBinaryEntropyBits(0.9f), h09, 1e-7);
  EXPECT_NEAR(h_edge, 2.137e-5, 1e-8);
  EXPECT_DOUBLE_EQ(ClampedBinaryEntropyBits(0.5), 1.0);
  EXPECT_NEAR(ClampedBinaryEntropyBits(0.0), h_edge, 1e-15);
  EXPECT_NEAR(ClampedBinaryEntropyBits(1.0), ClampedBinaryEntropyBits(0.0), 1e-15);
  EXPECT_DOUBLE_EQ(ClampedBinaryEntropyBits(std::numeric_limits<double>::quiet_NaN()), 1.0);
  EXPECT_NEAR(ClampedBinaryEntropyBits(0.2), ClampedBinaryEntropyBits(0.8), 1e-15);
  EXPECT_NEAR(ClampedBinaryEntropyBits(0.2), 0.7219280948873623, 1e-15);
  const MapMetrics empty = EvaluateMap(EmptyMap(), gt);
  EXPECT_EQ(empty.entropy_sum_bits, 0.0);
  EXPECT_EQ(empty.entropy_mean_bits, 0.0);
}

TEST(MetricsTest, RoiCoverageCountsKnownVoxelCentresInTheBox) {
  const GroundTruth gt = RowGt();
  mapping::SemanticMap map = EmptyMap();
  mapping::OccupancyGrid& grid = map.grid();
  for (int i = 0; i < 10; ++i) grid.SetLogOdds({i, i, 0}, grid.clamp_min_log_odds());  // inside
  for (int i = 0; i < 5; ++i) grid.SetLogOdds({-1 - i, 0, 0}, 0.0f);                   // outside
  EvalOptions options;
  // Centres (k + 0.5) * 0.01 in [0, 0.1]: k = 0..9 on each axis, 1000 voxels.
  options.roi = Box3(Eigen::Vector3d::Zero(), Eigen::Vector3d::Constant(0.1));
  const MapMetrics m = EvaluateMap(map, gt, options);
  EXPECT_EQ(m.roi_voxels, 1000u);
  EXPECT_EQ(m.roi_known_voxels, 10u);
  EXPECT_DOUBLE_EQ(m.roi_coverage, 0.01);
  // No ROI: skipped.
  const MapMetrics none = EvaluateMap(map, gt);
  EXPECT_EQ(none.roi_voxels, 0u);
  EXPECT_EQ(none.roi_coverage, 0.0);
}

TEST(MetricsTest, RejectsBadOptionsAndMismatchedVoxelSizes) {
  const GroundTruth gt = RowGt();
  EvalOptions bad;
  bad.found_min_fraction = 1.5;
  bad.target = SemanticClass::kBackground;
  EXPECT_THAT(bad.Validate().message(), HasSubstr("found_min_fraction (1.5)"));
  EXPECT_THAT(bad.Validate().message(), HasSubstr("target class (0)"));
  EXPECT_THROW(EvaluateMap(EmptyMap(), gt, bad), Error);
  EXPECT_THROW(EvaluateMap(EmptyMap(0.005), gt), Error);
  EXPECT_TRUE(EvalOptions{}.Validate().ok());
}

}  // namespace
}  // namespace avp::eval

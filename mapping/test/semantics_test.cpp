#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/segmentation.h>
#include <avp/mapping/semantics.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::mapping {
namespace {

using ::testing::HasSubstr;

constexpr double kVoxel = 0.005;

// ---- Helpers ------------------------------------------------------------------------------------

/// Masks without pixels: Fuse only reads their class and confidence.
Segmentation Masks(const std::vector<std::pair<SemanticClass, float>>& masks) {
  Segmentation seg;
  for (const auto& [cls, confidence] : masks) {
    InstanceMask m;
    m.semantic_class = cls;
    m.confidence = confidence;
    seg.instances.push_back(std::move(m));
  }
  return seg;
}

Segmentation Fruits(int count, float confidence = 0.9f) {
  return Masks(std::vector<std::pair<SemanticClass, float>>(static_cast<size_t>(count),
                                                            {SemanticClass::kFruit, confidence}));
}

void Add(std::vector<VoxelObservation>& obs, const std::vector<VoxelKey>& keys, int mask) {
  for (const VoxelKey& k : keys) obs.push_back({k, mask, 1});
}

OccupancyGrid MakeGrid() {
  GridOptions options;
  options.voxel_size_m = kVoxel;
  return OccupancyGrid(options);
}

SemanticOptions Policy(FusionPolicy policy) {
  SemanticOptions o;
  o.policy = policy;
  return o;
}

/// The fixed-point value FuseBayesianHit stores for one observation of score s.
float HitLogOdds(double s) {
  return static_cast<float>(std::lround((std::log(s / (1.0 - s)) + std::log(6.0)) * 1024.0)) /
         1024.0f;
}
float LogOdds(const SemanticCell& c, SemanticClass cls) {
  return c.class_log_odds[static_cast<int>(cls)] / kClassLogOddsScale;
}

// ---- Names and options --------------------------------------------------------------------------

TEST(SemanticOptionsTest, PolicyNamesRoundTrip) {
  for (FusionPolicy p : {FusionPolicy::kReferenceMax, FusionPolicy::kBayesian}) {
    EXPECT_EQ(FusionPolicyFromString(ToString(p)), p);
  }
  EXPECT_EQ(ToString(FusionPolicy::kReferenceMax), "reference-max");
  EXPECT_EQ(ToString(FusionPolicy::kBayesian), "bayesian");
  EXPECT_EQ(FusionPolicyFromString("max"), std::nullopt);
  EXPECT_EQ(FusionPolicyFromString(""), std::nullopt);
}

TEST(SemanticOptionsTest, DefaultsAreValid) {
  const Status s = SemanticOptions{}.Validate();
  EXPECT_TRUE(s.ok()) << s.ToString();
  EXPECT_NO_THROW(SemanticFusion{});
}

TEST(SemanticOptionsTest, ValidateNamesEveryBadValue) {
  SemanticOptions o;
  o.reference_penalty = 1.5f;
  o.class_log_odds_min = 1.0f;
  o.class_log_odds_max = 40.0f;
  o.miss_log_odds = -0.1f;
  o.label_threshold = NAN;
  o.score_epsilon = 0.5f;
  o.instance_join_fraction = 0.0f;
  o.instance_min_overlap_fraction = -0.5f;
  o.instance_merge_fraction = 2.0f;
  o.instance_merge_max_separation = -1.0f;
  o.instance_flip_frames = 0;
  o.outlier_min_neighbours = 27;
  const Status s = o.Validate();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  const std::string& m = s.message();
  EXPECT_THAT(m, HasSubstr("invalid semantic options"));
  EXPECT_THAT(m, HasSubstr("reference_penalty (1.5)"));
  EXPECT_THAT(m, HasSubstr("class_log_odds_min (1)"));
  EXPECT_THAT(m, HasSubstr("class_log_odds_max (40)"));
  EXPECT_THAT(m, HasSubstr("miss_log_odds (-0.1)"));
  EXPECT_THAT(m, HasSubstr("label_threshold (nan)"));
  EXPECT_THAT(m, HasSubstr("score_epsilon (0.5)"));
  EXPECT_THAT(m, HasSubstr("instance_join_fraction (0)"));
  EXPECT_THAT(m, HasSubstr("instance_min_overlap_fraction (-0.5)"));
  EXPECT_THAT(m, HasSubstr("instance_merge_fraction (2)"));
  EXPECT_THAT(m, HasSubstr("instance_merge_max_separation (-1)"));
  EXPECT_THAT(m, HasSubstr("instance_flip_frames (0)"));
  EXPECT_THAT(m, HasSubstr("outlier_min_neighbours (27)"));

  SemanticOptions bad_policy;
  bad_policy.policy = static_cast<FusionPolicy>(7);
  EXPECT_THAT(bad_policy.Validate().message(), HasSubstr("policy (7)"));
}

TEST(SemanticOptionsTest, ConstructorThrowsWithTheMessage) {
  SemanticOptions o;
  o.label_threshold = 0.0f;
  try {
    SemanticFusion fusion(o);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("label_threshold (0) must be in (0, 1]"));
  }
}

// ---- Reference max fusion -----------------------------------------------------------------------

TEST(FusionReferenceMaxTest, HandComputedSequence) {
  SemanticCell c;
  const float p = 0.9f;
  // Fresh voxel = ("none", 0): a different class with a larger confidence -> 0.9 * 0.8.
  FuseReferenceMax(c, SemanticClass::kFruit, 0.8f, p);
  EXPECT_EQ(c.cls(), SemanticClass::kFruit);
  EXPECT_EQ(c.confidence, 0.9f * 0.8f);
  EXPECT_NEAR(c.confidence, 0.72, 1e-6);
  // Same class: the average.
  FuseReferenceMax(c, SemanticClass::kFruit, 0.6f, p);
  EXPECT_EQ(c.cls(), SemanticClass::kFruit);
  EXPECT_EQ(c.confidence, (0.9f * 0.8f + 0.6f) / 2.0f);
  EXPECT_NEAR(c.confidence, 0.66, 1e-6);
  // Other class, 0.7 > 0.66: the class switches, c = 0.9 * 0.7.
  FuseReferenceMax(c, SemanticClass::kLeaf, 0.7f, p);
  EXPECT_EQ(c.cls(), SemanticClass::kLeaf);
  EXPECT_EQ(c.confidence, 0.9f * 0.7f);
  EXPECT_NEAR(c.confidence, 0.63, 1e-6);
  // Other class, 0.5 < 0.63: the class stays, penalised: 0.9 * 0.63.
  FuseReferenceMax(c, SemanticClass::kFruit, 0.5f, p);
  EXPECT_EQ(c.cls(), SemanticClass::kLeaf);
  EXPECT_EQ(c.confidence, 0.9f * (0.9f * 0.7f));
  EXPECT_NEAR(c.confidence, 0.567, 1e-6);
  // A tie keeps the old class (penalised).
  const float tie = c.confidence;
  FuseReferenceMax(c, SemanticClass::kFruit, tie, p);
  EXPECT_EQ(c.cls(), SemanticClass::kLeaf);
  EXPECT_EQ(c.confidence, 0.9f * tie);
  EXPECT_NEAR(c.confidence, 0.5103, 1e-6);
  // Same class again: EMA with weight 1/2.
  FuseReferenceMax(c, SemanticClass::kLeaf, 1.0f, p);
  EXPECT_EQ(c.confidence, (0.9f * tie + 1.0f) / 2.0f);
  EXPECT_NEAR(c.confidence, 0.75515, 1e-6);
  EXPECT_EQ(c.observations, 6);
  EXPECT_EQ(c.misses, 0);
  EXPECT_EQ(c.instance_id, 0);
  for (int16_t l : c.class_log_odds) EXPECT_EQ(l, 0);
}

TEST(FusionReferenceMaxTest, RepeatedSameClassIsAnAverageWithWeightOneHalf) {
  SemanticCell c;
  FuseReferenceMax(c, SemanticClass::kFruit, 0.5f, 0.9f);  // 0.45
  for (int i = 0; i < 40; ++i) FuseReferenceMax(c, SemanticClass::kFruit, 0.5f, 0.9f);
  EXPECT_NEAR(c.confidence, 0.5, 1e-6);  // 0.5 + (0.45 - 0.5) / 2^40
  SemanticCell d;
  FuseReferenceMax(d, SemanticClass::kFruit, 1.0f, 0.5f);  // another penalty: 0.5
  EXPECT_EQ(d.confidence, 0.5f);
}

TEST(FusionReferenceMaxTest, BackgroundUnknownClassOrNonFiniteScoreIsANoOp) {
  SemanticCell c;
  FuseReferenceMax(c, SemanticClass::kBackground, 0.8f, 0.9f);
  FuseReferenceMax(c, static_cast<SemanticClass>(kNumSemanticClasses), 0.8f, 0.9f);
  FuseReferenceMax(c, SemanticClass::kFruit, NAN, 0.9f);
  EXPECT_EQ(c, SemanticCell{});
}

// ---- Bayesian fusion ----------------------------------------------------------------------------

TEST(FusionBayesianTest, OneObservationFromTheUniformPriorGivesTheScore) {
  const SemanticOptions o;
  for (float s : {0.3f, 0.6f, 0.9f}) {
    SemanticCell c;
    FuseBayesianHit(c, SemanticClass::kFruit, s, o);
    EXPECT_NEAR(LogOdds(c, SemanticClass::kFruit), std::log(s / (1 - s)) + std::log(6.0), 1e-3);
    // Labelled when the posterior reaches label_threshold (0.5).
    EXPECT_EQ(c.cls(), s >= 0.5f ? SemanticClass::kFruit : SemanticClass::kBackground) << s;
    EXPECT_NEAR(c.confidence, s, 1e-3);
    EXPECT_NEAR(BayesianPosteriors(c)[1], s, 1e-3);
    EXPECT_EQ(c.observations, 1);
  }
}

TEST(FusionBayesianTest, HandComputedSequence) {
  const SemanticOptions o;  // clamp [-4, 6], miss 0.4, threshold 0.5
  SemanticCell c;
  // Fruit 0.9: logit(0.9) + log 6 = 2.19722 + 1.79176 = 3.98898; posterior = 0.9.
  FuseBayesianHit(c, SemanticClass::kFruit, 0.9f, o);
  EXPECT_NEAR(LogOdds(c, SemanticClass::kFruit), 3.98898, 1e-3);
  EXPECT_EQ(c.cls(), SemanticClass::kFruit);
  EXPECT_NEAR(c.confidence, 0.9, 1e-3);
  // Fruit 0.3: + (-0.84730 + 1.79176) = +0.94446 -> 4.93344; e^4.93344 = 138.87;
  // p = 138.87 / (1 + 138.87 + 5) = 0.95859.
  FuseBayesianHit(c, SemanticClass::kFruit, 0.3f, o);
  EXPECT_NEAR(LogOdds(c, SemanticClass::kFruit), 4.93344, 2e-3);
  EXPECT_NEAR(c.confidence, 0.95859, 1e-3);
  // Leaf 0.8: leaf = 1.38629 + 1.79176 = 3.17805 (e = 24.0);
  // p_fruit = 138.87 / (1 + 138.87 + 24.0 + 4) = 0.82729, p_leaf = 0.14292.
  FuseBayesianHit(c, SemanticClass::kLeaf, 0.8f, o);
  EXPECT_NEAR(LogOdds(c, SemanticClass::kLeaf), 3.17805, 1e-3);
  EXPECT_EQ(c.cls(), SemanticClass::kFruit);
  EXPECT_NEAR(c.confidence, 0.82729, 1e-3);
  EXPECT_NEAR(BayesianPosteriors(c)[2], 0.14292, 1e-3);
  // A miss lowers every class by 0.4: fruit 4.53344, leaf 2.77805, the others -0.4;
  // p_fruit = 93.08 / (1 + 93.08 + 16.09 + 4 * 0.67032) = 0.82487.
  FuseBayesianMiss(c, o);
  EXPECT_NEAR(LogOdds(c, SemanticClass::kFruit), 4.53344, 2e-3);
  EXPECT_NEAR(LogOdds(c, SemanticClass::kLeaf), 2.77805, 2e-3);
  EXPECT_NEAR(LogOdds(c, SemanticClass::kStem), -0.4, 1e-3);
  EXPECT_EQ(c.class_log_odds[0], 0);
  EXPECT_NEAR(c.confidence, 0.82487, 1e-3);
  EXPECT_NEAR(BayesianPosteriors(c)[0], 0.00886, 1e-3);
  EXPECT_EQ(c.observations, 3);
  EXPECT_EQ(c.misses, 1);
  float sum = 0.0f;
  for (float p : BayesianPosteriors(c)) sum += p;
  EXPECT_NEAR(sum, 1.0f, 1e-6);
}

TEST(FusionBayesianTest, LogOddsAreClampedAndScoresBounded) {
  SemanticOptions o;
  SemanticCell c;
  for (int i = 0; i < 10; ++i) FuseBayesianHit(c, SemanticClass::kFruit, 0.99f, o);
  EXPECT_EQ(c.class_log_odds[1], 6 * 1024);
  // p = e^6 / (1 + e^6 + 5) = 0.98535.
  EXPECT_NEAR(c.confidence, 0.98535, 1e-3);
  for (int i = 0; i < 100; ++i) FuseBayesianMiss(c, o);
  for (int k = 1; k < kNumSemanticClasses; ++k) EXPECT_EQ(c.class_log_odds[k], -4 * 1024);
  EXPECT_EQ(c.cls(), SemanticClass::kBackground);
  EXPECT_EQ(c.misses, 100);

  // s = 1 is clamped to 1 - eps: logit(0.999) + log 6 = 8.69855 -> clamped to 6.
  SemanticCell one;
  FuseBayesianHit(one, SemanticClass::kFruit, 1.0f, o);
  EXPECT_EQ(one.class_log_odds[1], 6 * 1024);
  // s = 0 -> logit(0.001) + log 6 = -5.11502 -> clamped to -4: evidence against fruit, no label.
  SemanticCell zero;
  FuseBayesianHit(zero, SemanticClass::kFruit, 0.0f, o);
  EXPECT_EQ(zero.class_log_odds[1], -4 * 1024);
  EXPECT_EQ(zero.cls(), SemanticClass::kBackground);
  EXPECT_NEAR(BayesianPosteriors(zero)[1], 0.00304, 1e-4);
  // s = 1/K carries no information.
  SemanticCell flat;
  FuseBayesianHit(flat, SemanticClass::kFruit, 1.0f / 7.0f, o);
  EXPECT_EQ(flat.class_log_odds[1], 0);
  EXPECT_EQ(flat.cls(), SemanticClass::kBackground);
  EXPECT_NEAR(flat.confidence, 1.0 / 7.0, 1e-6);
}

TEST(FusionBayesianTest, LabelThresholdDecidesTheLabel) {
  SemanticOptions o;
  o.label_threshold = 0.7f;
  SemanticCell c;
  FuseBayesianHit(c, SemanticClass::kFruit, 0.6f, o);
  EXPECT_EQ(c.cls(), SemanticClass::kBackground);  // posterior 0.6 < 0.7
  EXPECT_NEAR(c.confidence, 0.6, 1e-3);            // the best class's posterior, unlabelled
  FuseBayesianHit(c, SemanticClass::kFruit, 0.6f, o);
  // 2 * 2.19722 = 4.39445: p = 80.99 / 86.99 = 0.93103.
  EXPECT_EQ(c.cls(), SemanticClass::kFruit);
  EXPECT_NEAR(c.confidence, 0.93103, 1e-3);
  SemanticCell none;
  FuseBayesianHit(none, SemanticClass::kBackground, 0.9f, o);
  FuseBayesianHit(none, SemanticClass::kFruit, INFINITY, o);
  EXPECT_EQ(none, SemanticCell{});
}

TEST(FusionBayesianTest, HitLogOddsHelperMatches) {
  SemanticCell c;
  FuseBayesianHit(c, SemanticClass::kStem, 0.75f, SemanticOptions{});
  EXPECT_EQ(LogOdds(c, SemanticClass::kStem), HitLogOdds(0.75));
}

// ---- Fuse on a grid -----------------------------------------------------------------------------

/// A false positive: one frame labels a voxel, then every later frame sees it outside every mask.
/// The reference policy keeps the label forever; the Bayesian one drops it after 10 frames.
TEST(SemanticFusionTest, FalsePositiveDecaysOnlyUnderTheBayesianPolicy) {
  const VoxelKey key{3, -2, 7};
  const Segmentation fp = Fruits(1, 0.9f);
  const Segmentation none;
  const std::vector<VoxelObservation> hit = {{key, 0, 4}};
  const std::vector<VoxelObservation> miss = {{key, -1, 4}};

  OccupancyGrid ref_grid = MakeGrid();
  SemanticFusion ref(Policy(FusionPolicy::kReferenceMax));
  ref.Fuse(ref_grid, hit, fp, 1);
  for (uint32_t f = 2; f < 100; ++f) {
    const SemanticFrameStats s = ref.Fuse(ref_grid, miss, none, f);
    EXPECT_EQ(s.miss_updates, 0u);
  }
  ASSERT_NE(ref_grid.Semantic(key), nullptr);
  EXPECT_EQ(ref_grid.Semantic(key)->cls(), SemanticClass::kFruit);
  EXPECT_EQ(ref_grid.Semantic(key)->confidence, 0.9f * 0.9f);
  EXPECT_EQ(ref_grid.Semantic(key)->misses, 0);  // the reference never sees negative evidence

  OccupancyGrid grid = MakeGrid();
  SemanticFusion bayes(Policy(FusionPolicy::kBayesian));
  bayes.Fuse(grid, hit, fp, 1);
  ASSERT_EQ(grid.Semantic(key)->cls(), SemanticClass::kFruit);
  const uint16_t instance = grid.Semantic(key)->instance_id;
  EXPECT_NE(instance, 0);
  // Fruit log-odds after n misses: 3.98926 - 0.4 n; the others -0.4 n (clamped at -4):
  // n = 1: p = 0.8927, n = 9: 0.5642, n = 10: e^-0.0107 / (1 + e^-0.0107 + 5 e^-4) = 0.4745.
  std::vector<float> p;
  int cleared_after = 0;
  for (uint32_t f = 2; f < 30 && cleared_after == 0; ++f) {
    const SemanticFrameStats s = bayes.Fuse(grid, miss, none, f);
    EXPECT_EQ(s.miss_updates, 1u);
    p.push_back(grid.Semantic(key)->confidence);
    if (!grid.Semantic(key)->has_label()) cleared_after = static_cast<int>(f - 1);
  }
  EXPECT_NEAR(p.front(), 0.8927, 1e-3);
  EXPECT_EQ(cleared_after, 10);
  EXPECT_NEAR(p[8], 0.5642, 1e-3);
  EXPECT_NEAR(p.back(), 0.4745, 1e-3);
  EXPECT_EQ(grid.Semantic(key)->instance_id, 0);  // the label and its instance went together
  EXPECT_EQ(grid.Semantic(key)->misses, 10);
  EXPECT_EQ(grid.Semantic(key)->observations, 1);
  EXPECT_TRUE(bayes.Instances(grid).empty());
}

TEST(SemanticFusionTest, MissesNeverCreateCells) {
  for (FusionPolicy policy : {FusionPolicy::kReferenceMax, FusionPolicy::kBayesian}) {
    OccupancyGrid grid = MakeGrid();
    SemanticFusion fusion(Policy(policy));
    std::vector<VoxelObservation> obs;
    for (int i = 0; i < 100; ++i) obs.push_back({{i, 2 * i, -i}, -1, 3});
    const SemanticFrameStats s = fusion.Fuse(grid, obs, Segmentation{}, 1);
    EXPECT_EQ(s.observations, 100u);
    EXPECT_EQ(s.miss_updates, 0u);
    EXPECT_EQ(s.labelled_updates, 0u);
    EXPECT_EQ(grid.num_semantic_blocks(), 0u);
    EXPECT_EQ(grid.num_blocks(), 0u);
    for (const auto& o : obs) EXPECT_EQ(grid.Semantic(o.key), nullptr);
  }
}

TEST(SemanticFusionTest, BadObservationsAreSkippedAndCounted) {
  OccupancyGrid grid = MakeGrid();
  SemanticFusion fusion;
  Segmentation seg = Masks({{SemanticClass::kFruit, 0.9f},
                            {SemanticClass::kBackground, 0.9f},
                            {SemanticClass::kFruit, NAN},
                            {SemanticClass::kFruit, 1.5f},
                            {static_cast<SemanticClass>(9), 0.9f}});
  const std::vector<VoxelObservation> obs = {
      {{0, 0, 0}, 0, 1}, {{1, 0, 0}, 1, 1}, {{2, 0, 0}, 2, 1},  {{3, 0, 0}, 3, 1},
      {{4, 0, 0}, 4, 1}, {{5, 0, 0}, 5, 1}, {{6, 0, 0}, -2, 1}, {{kMaxKeyMagnitude, 0, 0}, 0, 1}};
  SemanticFrameStats s;
  EXPECT_NO_THROW(s = fusion.Fuse(grid, obs, seg, 1));
  EXPECT_EQ(s.observations, 8u);
  EXPECT_EQ(s.labelled_updates, 1u);
  EXPECT_EQ(s.skipped, 7u);  // background, NaN, > 1, unknown class, index 5, index -2, key
  EXPECT_EQ(s.new_instances, 1u);
  EXPECT_EQ(grid.CountSemanticVoxels(), 1u);
  ASSERT_NE(grid.Semantic({0, 0, 0}), nullptr);
  for (int x = 1; x <= 6; ++x) EXPECT_EQ(grid.Semantic({x, 0, 0}), nullptr);
}

TEST(SemanticFusionTest, RemoveOutliersEachFrame) {
  SemanticOptions o;
  o.remove_outliers_each_frame = true;
  OccupancyGrid grid = MakeGrid();
  SemanticFusion fusion(o);
  // A pair of neighbours (kept) and a lone voxel (its own mask and instance: removed).
  const std::vector<VoxelObservation> obs = {
      {{0, 0, 0}, 0, 1}, {{1, 0, 0}, 0, 1}, {{10, 0, 0}, 1, 1}};
  const SemanticFrameStats s = fusion.Fuse(grid, obs, Fruits(2), 1);
  EXPECT_EQ(s.new_instances, 2u);
  EXPECT_EQ(s.outliers_removed, 1u);
  EXPECT_TRUE(grid.Semantic({0, 0, 0})->has_label());
  EXPECT_FALSE(grid.Semantic({10, 0, 0})->has_label());
  EXPECT_EQ(grid.Semantic({10, 0, 0})->observations, 1);
}

// ---- Instance association -----------------------------------------------------------------------

/// Surface voxels of spheres; each voxel belongs to the sphere whose centre is nearest, and voxels
/// inside the other sphere are not surface.
struct Spheres {
  std::vector<Eigen::Vector3d> centres;
  double radius = 0.03;
  std::vector<std::vector<VoxelKey>> surface;  ///< [sphere]

  Spheres(std::vector<Eigen::Vector3d> c, double r) : centres(std::move(c)), radius(r) {
    surface.resize(centres.size());
    const int reach = static_cast<int>(std::ceil((radius + kVoxel) / kVoxel)) + 1;
    std::set<VoxelKey> seen;
    for (size_t s = 0; s < centres.size(); ++s) {
      const VoxelKey c0 = VoxelKey::FromPoint(centres[s], kVoxel);
      for (int z = -reach; z <= reach; ++z) {
        for (int y = -reach; y <= reach; ++y) {
          for (int x = -reach; x <= reach; ++x) {
            const VoxelKey k{c0.x + x, c0.y + y, c0.z + z};
            if (!seen.insert(k).second) continue;
            const Eigen::Vector3d p = k.Center(kVoxel);
            size_t nearest = 0;
            bool inside_other = false, on_shell = false;
            for (size_t t = 0; t < centres.size(); ++t) {
              const double d = (p - centres[t]).norm();
              if (d < (p - centres[nearest]).norm()) nearest = t;
              if (std::abs(d - radius) <= 0.5 * kVoxel) on_shell = true;
              if (d < radius - 0.5 * kVoxel) inside_other = true;
            }
            if (on_shell && !inside_other) surface[nearest].push_back(k);
          }
        }
      }
    }
  }
  /// The sphere's surface voxels whose offset from its centre satisfies `visible` (a view).
  template <typename F>
  std::vector<VoxelKey> Visible(size_t s, F&& visible) const {
    std::vector<VoxelKey> out;
    for (const VoxelKey& k : surface[s]) {
      if (visible(Eigen::Vector3d(k.Center(kVoxel) - centres[s]))) out.push_back(k);
    }
    return out;
  }
};

auto kFront = [](const Eigen::Vector3d& d) { return d.y() < 0.0; };
auto kBack = [](const Eigen::Vector3d& d) { return d.y() > 0.0; };
auto kTop = [](const Eigen::Vector3d& d) { return d.z() > 0.0; };
auto kLeft = [](const Eigen::Vector3d& d) { return d.x() < -1e-9; };

class InstanceAssociationTest : public ::testing::TestWithParam<FusionPolicy> {};

/// Two fruits of radius 3 cm whose centres are 5.5 cm apart (they overlap by 5 mm), observed:
///   frames 1-3: from the front, one mask per fruit;
///   frame 4:    from the top, ONE mask covering both (a segmenter that merged them);
///   frames 5-6: from the back, one mask per fruit.
/// Documented outcome: exactly two instances, ids 1 (the left fruit, mask 0 of frame 1) and 2;
/// every voxel stays with its own fruit: frame 4's mask spans both instances, whose centroids
/// are 5.5 cm apart, more than 0.8 x the sum of their radii of gyration (~2 x 2.6 cm), so they do
/// not merge, and its new (top) voxels go to the nearer instance centroid. No voxel ever changes
/// instance.
TEST_P(InstanceAssociationTest, TwoOverlappingFruits) {
  const Spheres spheres({{-0.0275, 0.0, 0.0}, {0.0275, 0.0, 0.0}}, 0.03);
  ASSERT_GT(spheres.surface[0].size(), 300u);
  ASSERT_EQ(spheres.surface[0].size(), spheres.surface[1].size());

  OccupancyGrid grid = MakeGrid();
  SemanticFusion fusion(Policy(GetParam()));
  size_t new_instances = 0, merged = 0, reassigned = 0;
  auto fuse = [&](const std::vector<VoxelObservation>& obs, int masks, uint32_t frame) {
    const SemanticFrameStats s = fusion.Fuse(grid, obs, Fruits(masks), frame);
    new_instances += s.new_instances;
    merged += s.merged_instances;
    reassigned += s.reassigned_voxels;
    EXPECT_EQ(s.skipped, 0u);
    EXPECT_EQ(s.labelled_updates, obs.size());
  };
  for (uint32_t f = 1; f <= 3; ++f) {
    std::vector<VoxelObservation> obs;
    Add(obs, spheres.Visible(0, kFront), 0);
    Add(obs, spheres.Visible(1, kFront), 1);
    fuse(obs, 2, f);
    EXPECT_EQ(fusion.Instances(grid).size(), 2u);
  }
  {
    std::vector<VoxelObservation> obs;
    Add(obs, spheres.Visible(0, kTop), 0);
    Add(obs, spheres.Visible(1, kTop), 0);
    fuse(obs, 1, 4);
  }
  for (uint32_t f = 5; f <= 6; ++f) {
    std::vector<VoxelObservation> obs;
    Add(obs, spheres.Visible(0, kBack), 0);
    Add(obs, spheres.Visible(1, kBack), 1);
    fuse(obs, 2, f);
  }
  EXPECT_EQ(new_instances, 2u);
  EXPECT_EQ(merged, 0u);
  EXPECT_EQ(reassigned, 0u);

  for (uint16_t s = 0; s < 2; ++s) {
    for (const VoxelKey& k : spheres.surface[s]) {
      const SemanticCell* c = grid.Semantic(k);
      ASSERT_NE(c, nullptr);
      EXPECT_EQ(c->cls(), SemanticClass::kFruit);
      EXPECT_EQ(c->instance_id, s + 1)
          << "sphere " << s << " voxel " << k.x << "," << k.y << "," << k.z;
    }
  }
  const std::vector<InstanceInfo> instances = fusion.Instances(grid);
  ASSERT_EQ(instances.size(), 2u);
  for (uint16_t s = 0; s < 2; ++s) {
    const InstanceInfo& info = instances[s];
    EXPECT_EQ(info.id, s + 1);
    EXPECT_EQ(info.semantic_class, SemanticClass::kFruit);
    EXPECT_EQ(info.voxels, spheres.surface[s].size());
    EXPECT_EQ(info.first_frame, 1u);
    EXPECT_EQ(info.last_frame, 6u);
    EXPECT_LT((info.centroid_W - spheres.centres[s]).norm(), 0.5 * kVoxel);
    EXPECT_GT(info.mean_confidence, 0.5);
  }
}

/// One fruit seen from the front (instance 1) and then from the back: the two caps share no voxel,
/// so the back view starts instance 2 (a split). A view from the side covers about half of each;
/// their centroids are one radius apart, well within 0.8 x the sum of their radii of gyration, so
/// the side mask merges them into the lower id, 1.
TEST_P(InstanceAssociationTest, SplitFruitMergesWhenASpanningMaskSeesItWhole) {
  const Spheres sphere({{0.0275, 0.0, 0.0}}, 0.03);
  OccupancyGrid grid = MakeGrid();
  SemanticFusion fusion(Policy(GetParam()));
  std::vector<VoxelObservation> front, back, side;
  Add(front, sphere.Visible(0, kFront), 0);
  Add(back, sphere.Visible(0, kBack), 0);
  Add(side, sphere.Visible(0, kLeft), 0);

  EXPECT_EQ(fusion.Fuse(grid, front, Fruits(1), 1).new_instances, 1u);
  const SemanticFrameStats second = fusion.Fuse(grid, back, Fruits(1), 2);
  EXPECT_EQ(second.new_instances, 1u);
  ASSERT_EQ(fusion.Instances(grid).size(), 2u);
  EXPECT_EQ(fusion.Instances(grid)[1].first_frame, 2u);

  const SemanticFrameStats third = fusion.Fuse(grid, side, Fruits(1), 3);
  EXPECT_EQ(third.merged_instances, 1u);
  EXPECT_EQ(third.new_instances, 0u);
  const std::vector<InstanceInfo> instances = fusion.Instances(grid);
  ASSERT_EQ(instances.size(), 1u);
  EXPECT_EQ(instances[0].id, 1);
  EXPECT_EQ(instances[0].first_frame, 1u);
  EXPECT_EQ(instances[0].last_frame, 3u);
  std::set<VoxelKey> seen;
  for (const auto* v : {&front, &back, &side}) {
    for (const auto& o : *v) seen.insert(o.key);
  }
  EXPECT_EQ(instances[0].voxels, seen.size());

  // The retired id is never reused.
  const std::vector<VoxelObservation> other = {{{100, 100, 100}, 0, 1}};
  fusion.Fuse(grid, other, Fruits(1), 4);
  EXPECT_EQ(grid.Semantic({100, 100, 100})->instance_id, 3);
}

INSTANTIATE_TEST_SUITE_P(Policies, InstanceAssociationTest,
                         ::testing::Values(FusionPolicy::kReferenceMax, FusionPolicy::kBayesian),
                         [](const auto& param_info) {
                           return param_info.param == FusionPolicy::kReferenceMax ? "ReferenceMax"
                                                                                  : "Bayesian";
                         });

std::vector<VoxelKey> Row(int x0, int x1, int y = 0) {
  std::vector<VoxelKey> keys;
  for (int x = x0; x <= x1; ++x) keys.push_back({x, y, 0});
  return keys;
}

/// A voxel of fruit B that fruit A's mask bleeds onto: B is not spanned by A's mask (1 vote of 21),
/// so the voxel may move, but only after `instance_flip_frames` (2) claims without B reclaiming it.
TEST(InstanceAssociationRulesTest, OwnedVoxelsDoNotFlipOnASingleWeakVote) {
  OccupancyGrid grid = MakeGrid();
  SemanticFusion fusion;
  const VoxelKey v{20, 0, 0};
  auto frame = [&](bool bleed, uint32_t f) {
    std::vector<VoxelObservation> obs;
    Add(obs, Row(0, 19), 0);  // fruit A: x 0..19
    if (bleed) obs.push_back({v, 0, 1});
    Add(obs, Row(bleed ? 21 : 20, 39), 1);  // fruit B: x 20..39
    return fusion.Fuse(grid, obs, Fruits(2), f);
  };
  frame(false, 1);
  ASSERT_EQ(grid.Semantic(v)->instance_id, 2);
  EXPECT_EQ(frame(true, 2).reassigned_voxels, 0u);  // one claim: stays with B
  EXPECT_EQ(grid.Semantic(v)->instance_id, 2);
  frame(false, 3);  // B reclaims it: the count restarts
  EXPECT_EQ(frame(true, 4).reassigned_voxels, 0u);
  EXPECT_EQ(grid.Semantic(v)->instance_id, 2);
  EXPECT_EQ(frame(true, 5).reassigned_voxels, 1u);  // second claim in a row: moves to A
  EXPECT_EQ(grid.Semantic(v)->instance_id, 1);
  EXPECT_EQ(fusion.Instances(grid)[0].voxels, 21u);
  EXPECT_EQ(fusion.Instances(grid)[1].voxels, 19u);

  SemanticOptions once;
  once.instance_flip_frames = 1;
  SemanticFusion eager(once);
  OccupancyGrid g2 = MakeGrid();
  std::vector<VoxelObservation> obs;
  Add(obs, Row(0, 19), 0);
  Add(obs, Row(20, 39), 1);
  eager.Fuse(g2, obs, Fruits(2), 1);
  obs.clear();
  Add(obs, Row(0, 20), 0);
  Add(obs, Row(21, 39), 1);
  EXPECT_EQ(eager.Fuse(g2, obs, Fruits(2), 2).reassigned_voxels, 1u);
  EXPECT_EQ(g2.Semantic(v)->instance_id, 1);
}

/// A mask joins an instance holding >= 30 % of its votes and >= 10 % of its voxels; a mask that
/// merely touches an instance starts a new one.
TEST(InstanceAssociationRulesTest, JoinNeedsEnoughOverlap) {
  OccupancyGrid grid = MakeGrid();
  SemanticFusion fusion;
  std::vector<VoxelObservation> obs;
  Add(obs, Row(0, 9), 0);
  fusion.Fuse(grid, obs, Fruits(1), 1);
  // 1 of 10 voxels (10 %) overlaps instance 1: joins it.
  obs.clear();
  Add(obs, Row(9, 18), 0);
  EXPECT_EQ(fusion.Fuse(grid, obs, Fruits(1), 2).new_instances, 0u);
  EXPECT_EQ(grid.Semantic({18, 0, 0})->instance_id, 1);
  // 1 of 20 voxels (5 %) overlaps: a new instance; the shared voxel stays with 1 (one claim).
  obs.clear();
  Add(obs, Row(18, 37), 0);
  const SemanticFrameStats s = fusion.Fuse(grid, obs, Fruits(1), 3);
  EXPECT_EQ(s.new_instances, 1u);
  EXPECT_EQ(s.reassigned_voxels, 0u);
  EXPECT_EQ(grid.Semantic({18, 0, 0})->instance_id, 1);
  EXPECT_EQ(grid.Semantic({19, 0, 0})->instance_id, 2);
  // A mask over two instances, 60 % / 40 % of its votes (both spanned): joins the larger, keeps
  // each voxel's owner, and sends its new voxels to the nearer centroid. They do not merge: each
  // is covered only partly (3 of 19 and 2 of 20 voxels, below instance_merge_fraction).
  obs.clear();
  Add(obs, Row(16, 20), 0);     // 16, 17, 18 -> 1; 19, 20 -> 2
  Add(obs, Row(16, 20, 1), 0);  // new voxels in the row above
  const SemanticFrameStats both = fusion.Fuse(grid, obs, Fruits(1), 4);
  EXPECT_EQ(both.new_instances, 0u);
  EXPECT_EQ(both.merged_instances, 0u);
  EXPECT_EQ(grid.Semantic({18, 0, 0})->instance_id, 1);
  EXPECT_EQ(grid.Semantic({19, 0, 0})->instance_id, 2);
  EXPECT_EQ(grid.Semantic({16, 1, 0})->instance_id, 1);  // centroid of 1 is at x = 9.5
  EXPECT_EQ(grid.Semantic({20, 1, 0})->instance_id, 2);  // centroid of 2 is at x = 28.5
}

TEST(InstanceAssociationRulesTest, ClassChangeDropsTheInstance) {
  OccupancyGrid grid = MakeGrid();
  SemanticFusion fusion(Policy(FusionPolicy::kReferenceMax));
  std::vector<VoxelObservation> obs;
  Add(obs, Row(0, 4), 0);
  fusion.Fuse(grid, obs, Fruits(1, 0.5f), 1);  // fruit, c = 0.45, instance 1
  // A leaf mask with 0.6 > 0.45 over two of them: those become leaf with a leaf instance (2).
  obs.clear();
  Add(obs, Row(3, 4), 0);
  const SemanticFrameStats s = fusion.Fuse(grid, obs, Masks({{SemanticClass::kLeaf, 0.6f}}), 2);
  EXPECT_EQ(s.new_instances, 1u);
  EXPECT_EQ(grid.Semantic({3, 0, 0})->cls(), SemanticClass::kLeaf);
  EXPECT_EQ(grid.Semantic({3, 0, 0})->instance_id, 2);
  EXPECT_EQ(grid.Semantic({2, 0, 0})->instance_id, 1);
  const std::vector<InstanceInfo> instances = fusion.Instances(grid);
  ASSERT_EQ(instances.size(), 2u);
  EXPECT_EQ(instances[0].voxels, 3u);
  EXPECT_EQ(instances[1].semantic_class, SemanticClass::kLeaf);
  // A leaf mask with 0.3 < 0.45 leaves fruit voxels (and their instance) alone.
  obs.clear();
  Add(obs, Row(0, 1), 0);
  fusion.Fuse(grid, obs, Masks({{SemanticClass::kLeaf, 0.3f}}), 3);
  EXPECT_EQ(grid.Semantic({0, 0, 0})->cls(), SemanticClass::kFruit);
  EXPECT_EQ(grid.Semantic({0, 0, 0})->instance_id, 1);
}

/// InstanceInfo is computed from the cells; the per-voxel confidences are never overwritten with
/// the instance mean (the reference system did that).
TEST(InstanceAssociationRulesTest, StatisticsAreComputedFromCellsNotWrittenBack) {
  OccupancyGrid grid = MakeGrid();
  SemanticFusion fusion(Policy(FusionPolicy::kReferenceMax));
  std::vector<VoxelObservation> obs;
  Add(obs, Row(0, 1), 0);
  fusion.Fuse(grid, obs, Fruits(1, 0.8f), 1);  // 0.72, 0.72
  obs.clear();
  Add(obs, Row(0, 2), 0);
  fusion.Fuse(grid, obs, Fruits(1, 0.4f), 2);  // (0.72 + 0.4) / 2 = 0.56, 0.56; new 0.36
  const std::vector<InstanceInfo> instances = fusion.Instances(grid);
  ASSERT_EQ(instances.size(), 1u);
  EXPECT_EQ(instances[0].voxels, 3u);
  EXPECT_NEAR(instances[0].mean_confidence, (0.56 + 0.56 + 0.36) / 3.0, 1e-6);
  const Eigen::Vector3d expected_centroid(1.5 * kVoxel, 0.5 * kVoxel, 0.5 * kVoxel);
  EXPECT_LT((instances[0].centroid_W - expected_centroid).norm(), 1e-12);
  EXPECT_EQ(instances[0].first_frame, 1u);
  EXPECT_EQ(instances[0].last_frame, 2u);
  EXPECT_NEAR(grid.Semantic({0, 0, 0})->confidence, 0.56, 1e-6);
  EXPECT_NEAR(grid.Semantic({2, 0, 0})->confidence, 0.36, 1e-6);
}

TEST(InstanceAssociationRulesTest, MasksAreProcessedInIndexOrderDeterministically) {
  auto run = [] {
    OccupancyGrid grid = MakeGrid();
    SemanticFusion fusion;
    std::vector<VoxelObservation> obs;
    Add(obs, Row(10, 14), 1);  // listed first, but mask 0 gets the first id
    Add(obs, Row(0, 4), 0);
    fusion.Fuse(grid, obs, Fruits(2), 1);
    std::vector<SemanticCell> cells;
    for (int x = 0; x < 15; ++x) {
      const SemanticCell* c = grid.Semantic({x, 0, 0});
      cells.push_back(c ? *c : SemanticCell{});
    }
    return cells;
  };
  const std::vector<SemanticCell> a = run();
  EXPECT_EQ(a[0].instance_id, 1);
  EXPECT_EQ(a[10].instance_id, 2);
  EXPECT_EQ(a, run());
}

TEST(InstanceAssociationRulesTest, ResetFromGridContinuesAfterTheLargestId) {
  OccupancyGrid grid = MakeGrid();
  SemanticFusion writer;
  std::vector<VoxelObservation> obs;
  Add(obs, Row(0, 2), 0);
  Add(obs, Row(10, 12), 1);
  Add(obs, Row(20, 22), 2);
  writer.Fuse(grid, obs, Fruits(3), 5);

  SemanticFusion reader;
  reader.ResetFromGrid(grid);
  const std::vector<InstanceInfo> loaded = reader.Instances(grid);
  ASSERT_EQ(loaded.size(), 3u);
  EXPECT_EQ(loaded[2].id, 3);
  EXPECT_EQ(loaded[2].first_frame, 0u);  // unknown after a reset
  obs.clear();
  Add(obs, Row(40, 42), 0);
  reader.Fuse(grid, obs, Fruits(1), 6);
  EXPECT_EQ(grid.Semantic({40, 0, 0})->instance_id, 4);
  EXPECT_EQ(reader.Instances(grid)[3].first_frame, 6u);
}

TEST(InstanceAssociationRulesTest, ExhaustedIdsLeaveNewMasksWithoutInstance) {
  OccupancyGrid grid = MakeGrid();
  SemanticFusion fusion;
  std::vector<VoxelObservation> obs = {{{0, 0, 0}, 0, 1}};
  fusion.Fuse(grid, obs, Fruits(1), 1);
  grid.MutableSemantic({0, 0, 0})->instance_id = 65535;  // as loaded from a full map
  fusion.ResetFromGrid(grid);
  obs = {{{50, 0, 0}, 0, 1}};
  const SemanticFrameStats s = fusion.Fuse(grid, obs, Fruits(1), 2);
  EXPECT_EQ(s.new_instances, 0u);
  EXPECT_EQ(s.labelled_updates, 1u);
  EXPECT_TRUE(grid.Semantic({50, 0, 0})->has_label());
  EXPECT_EQ(grid.Semantic({50, 0, 0})->instance_id, 0);
}

// ---- Outlier removal ----------------------------------------------------------------------------

SemanticCell* Label(OccupancyGrid& grid, const VoxelKey& k, uint16_t instance,
                    SemanticClass cls = SemanticClass::kFruit) {
  SemanticCell* c = grid.MutableSemantic(k);
  c->semantic_class = static_cast<uint8_t>(cls);
  c->instance_id = instance;
  c->confidence = 0.8f;
  c->observations = 3;
  c->misses = 1;
  c->class_log_odds[static_cast<int>(cls)] = 2048;
  return c;
}

TEST(OutlierRemovalTest, IsolatedLabelsAreClearedCountsKept) {
  OccupancyGrid grid = MakeGrid();
  for (int z = 0; z < 3; ++z) {
    for (int y = 0; y < 3; ++y) {
      for (int x = 0; x < 3; ++x) Label(grid, {x, y, z}, 1);
    }
  }
  Label(grid, {10, 10, 10}, 1);  // isolated
  Label(grid, {3, 3, 3}, 2);     // diagonal neighbour of the cube, but another instance
  Label(grid, {20, 0, 0}, 0);    // no instance: neighbours of its class count
  Label(grid, {21, 1, 1}, 0, SemanticClass::kLeaf);  // same for the leaf: another class
  Label(grid, {30, 0, 0}, 0);
  Label(grid, {31, 0, 0}, 0);

  const SemanticFusion fusion;  // outlier_min_neighbours = 1
  const OutlierStats s = fusion.RemoveOutliers(grid);
  EXPECT_EQ(s.examined, 27u + 6u);
  EXPECT_EQ(s.removed, 4u);
  for (const VoxelKey k :
       {VoxelKey{10, 10, 10}, VoxelKey{3, 3, 3}, VoxelKey{20, 0, 0}, VoxelKey{21, 1, 1}}) {
    const SemanticCell* c = grid.Semantic(k);
    ASSERT_NE(c, nullptr);
    EXPECT_FALSE(c->has_label());
    EXPECT_EQ(c->instance_id, 0);
    EXPECT_EQ(c->confidence, 0.0f);
    EXPECT_EQ(c->observations, 3);
    EXPECT_EQ(c->misses, 1);
    for (int16_t l : c->class_log_odds) EXPECT_EQ(l, 0);
  }
  EXPECT_TRUE(grid.Semantic({1, 1, 1})->has_label());
  EXPECT_TRUE(grid.Semantic({2, 2, 2})->has_label());  // corner: 7 neighbours of its instance
  EXPECT_TRUE(grid.Semantic({30, 0, 0})->has_label());
  EXPECT_EQ(grid.CountSemanticVoxels(), 29u);

  // Idempotent, and never creates labels.
  const OutlierStats again = fusion.RemoveOutliers(grid);
  EXPECT_EQ(again.examined, 29u);
  EXPECT_EQ(again.removed, 0u);
  EXPECT_EQ(grid.CountSemanticVoxels(), 29u);
}

TEST(OutlierRemovalTest, ThresholdCountsNeighboursOfTheSameInstance) {
  OccupancyGrid grid = MakeGrid();
  for (int x = 0; x < 10; ++x) Label(grid, {x, 0, 0}, 1);  // a line: ends have 1, inside 2
  SemanticOptions o;
  o.outlier_min_neighbours = 2;
  const OutlierStats s = SemanticFusion(o).RemoveOutliers(grid);
  EXPECT_EQ(s.removed, 2u);
  EXPECT_FALSE(grid.Semantic({0, 0, 0})->has_label());
  EXPECT_FALSE(grid.Semantic({9, 0, 0})->has_label());
  EXPECT_TRUE(grid.Semantic({1, 0, 0})->has_label());  // decided on the map before the call

  o.outlier_min_neighbours = 0;  // disabled
  const OutlierStats none = SemanticFusion(o).RemoveOutliers(grid);
  EXPECT_EQ(none.examined, 8u);
  EXPECT_EQ(none.removed, 0u);
}

TEST(OutlierRemovalTest, ExaminesOnlyLabelledVoxels) {
  OccupancyGrid grid = MakeGrid();
  Label(grid, {0, 0, 0}, 1);
  Label(grid, {1, 0, 0}, 1);
  Label(grid, {50, 0, 0}, 2);
  const SemanticFusion fusion;
  OccupancyGrid copy = MakeGrid();
  Label(copy, {0, 0, 0}, 1);
  Label(copy, {1, 0, 0}, 1);
  Label(copy, {50, 0, 0}, 2);
  // 64,000 occupied voxels without semantics around them.
  for (int z = -20; z < 20; ++z) {
    for (int y = -20; y < 20; ++y) {
      for (int x = -20; x < 20; ++x) ASSERT_TRUE(copy.SetLogOdds({x, y, z}, 2.0f));
    }
  }
  // An unlabelled cell with evidence next to the lone voxel does not count as a neighbour.
  copy.MutableSemantic({51, 0, 0})->observations = 2;
  ASSERT_GE(copy.CountKnownVoxels(), 64000u);
  const OutlierStats a = fusion.RemoveOutliers(grid);
  const OutlierStats b = fusion.RemoveOutliers(copy);
  EXPECT_EQ(a.examined, 3u);
  EXPECT_EQ(b.examined, 3u);
  EXPECT_EQ(a.removed, 1u);
  EXPECT_EQ(b.removed, 1u);
  EXPECT_EQ(copy.CountSemanticVoxels(), 2u);
}

}  // namespace
}  // namespace avp::mapping

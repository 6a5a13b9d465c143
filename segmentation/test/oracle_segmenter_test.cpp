#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/segmentation/mask_ops.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

#include "test_frames.h"

namespace avp::segmentation {
namespace {

using test::TestScene;
using ::testing::HasSubstr;

/// Expects `count` successes out of `n` to match probability p within 4.5 binomial sigmas.
void ExpectRate(int count, int n, double p, const char* what) {
  const double rate = static_cast<double>(count) / n;
  const double sigma = std::sqrt(std::max(p * (1.0 - p), 1e-4) / n);
  EXPECT_NEAR(rate, p, 4.5 * sigma) << what << ": " << count << " of " << n;
}

/// Only the detection model: exact masks, no false positives, no merges.
OracleOptions DetectionOnly() {
  OracleOptions o;
  o.max_boundary_px = 0;
  o.p_false_positive = 0.0;
  o.p_merge = 0.0;
  return o;
}

/// Every fruit with a pixel detected, exact masks (the caller switches one part back on).
OracleOptions AlwaysDetect() {
  OracleOptions o = OracleOptions::Perfect();
  o.confidence_mean_at_0 = 0.8;
  return o;
}

bool IsSubset(const MaskImage& a, const MaskImage& b) {
  for (size_t i = 0; i < a.num_pixels(); ++i) {
    if (a.data()[i] != 0 && b.data()[i] == 0) return false;
  }
  return true;
}

MaskImage Union(const MaskImage& a, const MaskImage& b) {
  MaskImage out = a;
  for (size_t i = 0; i < out.num_pixels(); ++i) out.data()[i] = (a.data()[i] | b.data()[i]) ? 1 : 0;
  return out;
}

// ---- Options
// -------------------------------------------------------------------------------------

TEST(OracleOptionsTest, DefaultsAndPerfectAreValid) {
  EXPECT_TRUE(OracleOptions{}.Validate().ok()) << OracleOptions{}.Validate().ToString();
  EXPECT_TRUE(OracleOptions::Perfect().Validate().ok());
}

TEST(OracleOptionsTest, ValidateNamesEveryBadField) {
  OracleOptions o;
  o.p_max = 1.5;
  o.v_min = 0.6;  // above v_full (0.5)
  o.min_pixels = 0;
  o.confidence_stddev = -1.0;
  o.max_boundary_px = 40;
  o.p_merge = std::nan("");
  o.fruit_words.push_back("Tomato");
  const Status s = o.Validate();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("p_max (1.5) must be in [0, 1]"));
  EXPECT_THAT(s.message(), HasSubstr("v_full (0.5) must be >= v_min (0.6)"));
  EXPECT_THAT(s.message(), HasSubstr("min_pixels (0 px)"));
  EXPECT_THAT(s.message(), HasSubstr("confidence_stddev (-1)"));
  EXPECT_THAT(s.message(), HasSubstr("max_boundary_px (40 px)"));
  EXPECT_THAT(s.message(), HasSubstr("p_merge (nan)"));
  EXPECT_THAT(s.message(), HasSubstr("\"Tomato\""));
  EXPECT_THROW(OracleSegmenter(o, 1), Error);
}

TEST(OracleOptionsTest, DetectionProbabilityIsASmoothstepInTheVisibleFraction) {
  const OracleOptions o;
  EXPECT_EQ(o.DetectionProbability(0.0), 0.0);
  EXPECT_EQ(o.DetectionProbability(0.05), 0.0);
  EXPECT_NEAR(o.DetectionProbability(0.275), 0.97 * 0.5, 1e-12);  // midpoint of [0.05, 0.5]
  EXPECT_NEAR(o.DetectionProbability(0.1), 0.97 * 0.034293553, 1e-8);
  EXPECT_EQ(o.DetectionProbability(0.5), 0.97);
  EXPECT_EQ(o.DetectionProbability(1.0), 0.97);
  EXPECT_EQ(o.DetectionProbability(7.0), 0.97);  // clamped
  EXPECT_NEAR(o.MeanConfidence(0.0), 0.55, 1e-12);
  EXPECT_NEAR(o.MeanConfidence(1.0), 0.90, 1e-12);
  // A step when v_min == v_full.
  OracleOptions step;
  step.v_min = step.v_full = 0.3;
  EXPECT_EQ(step.DetectionProbability(0.29), 0.0);
  EXPECT_EQ(step.DetectionProbability(0.3), 0.97);
}

TEST(OracleOptionsTest, ExpectedAreaIsTheProjectedDisc) {
  const CameraIntrinsics K = test::TestCamera(160, 120, 100.0);
  GroundTruthFruit f;
  f.center_W = Eigen::Vector3d(0.1, 0.0, 2.0);
  f.radius_m = 0.04;  // 100 * 0.04 / 2 = 2 px radius
  const auto area = ExpectedFruitAreaPx(K, RigidTransform::Identity(), f);
  ASSERT_TRUE(area.has_value());
  EXPECT_NEAR(*area, M_PI * 4.0, 1e-9);
  // The camera 2 m further back along its axis: half the radius, a quarter of the area.
  const auto further = ExpectedFruitAreaPx(K, RigidTransform(Eigen::Vector3d(0.0, 0.0, -2.0)), f);
  ASSERT_TRUE(further.has_value());
  EXPECT_NEAR(*further, M_PI * 1.0, 1e-9);
  // Behind the camera, or the camera inside the fruit: undefined.
  f.center_W.z() = -1.0;
  EXPECT_FALSE(ExpectedFruitAreaPx(K, RigidTransform::Identity(), f).has_value());
  f.center_W.z() = 0.03;
  EXPECT_FALSE(ExpectedFruitAreaPx(K, RigidTransform::Identity(), f).has_value());
}

TEST(OracleSegmenterTest, PromptPhrasesMapToFruit) {
  const OracleSegmenter oracle;
  for (const char* phrase : {"tomato", "Tomatoes", "ripe tomato", "green apple", "fruit",
                             "Strawberries", "red pepper"}) {
    EXPECT_EQ(oracle.ClassForPhrase(phrase), SemanticClass::kFruit) << phrase;
  }
  for (const char* phrase : {"leaf", "tomato leaf", "bicycle", "", "   "}) {
    EXPECT_FALSE(oracle.ClassForPhrase(phrase).has_value()) << phrase;
  }
}

// ---- Perfect
// -------------------------------------------------------------------------------------

TEST(OracleSegmenterTest, PerfectReproducesTheVisibleMasksExactly) {
  TestScene s(120, 90, 100.0);
  s.PaintRect(0, 60, 120, 90, 30, SemanticClass::kGround, {90, 70, 50});
  s.PaintFruit(30, 30, 12, 1);
  s.PaintFruit(70, 30, 10, 2);
  s.PaintFruit(100, 70, 6, 3);
  s.PaintRect(20, 28, 110, 40, 10, SemanticClass::kLeaf, {60, 160, 40});  // occludes 1 and 2
  s.PaintRect(98, 50, 102, 90, 11, SemanticClass::kStem, {60, 120, 40});
  s.PaintRect(5, 5, 6, 6, 4, SemanticClass::kFruit, {200, 30, 20});  // a one-pixel fruit, no GT
  OracleSegmenter oracle(OracleOptions::Perfect(), 3);
  const auto r = oracle.Segment(s.Request("Ripe Tomatoes, leaf", 9));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->instances.size(), 4u);
  const Segmentation truth =
      Segmentation::FromLabelImages(s.labels.instance_ids, s.labels.class_ids);
  ASSERT_EQ(truth.instances.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(r->instances[i].mask, truth.instances[i].mask) << i;
    EXPECT_EQ(r->instances[i].confidence, 0.95f);
    EXPECT_EQ(r->instances[i].semantic_class, SemanticClass::kFruit);
    EXPECT_EQ(r->instances[i].label, "Ripe Tomatoes");
  }
  // In instance-id order: 1, 2, 3, 4.
  EXPECT_EQ(r->instances[0].mask, s.MaskOf(1));
  EXPECT_EQ(r->instances[3].mask, s.MaskOf(4));
  EXPECT_EQ(CountPixels(r->instances[3].mask), 1u);
}

// ---- Detection and confidence
// --------------------------------------------------------------------

TEST(OracleSegmenterTest, DetectionRateFollowsTheVisibleFraction) {
  TestScene s(160, 120, 100.0);
  // Fruit 1: fully visible, 20 px radius. Fruit 2: the same size, but a leaf covers all of it
  // except the top cap, about 10 % of it.
  s.PaintFruit(40, 60, 20, 1);
  s.PaintFruit(115, 60, 20, 2);
  s.PaintRect(90, 47, 140, 90, 10, SemanticClass::kLeaf, {60, 160, 40});
  const double area = M_PI * 20.0 * 20.0;
  const double v1 = std::min(1.0, CountPixels(s.MaskOf(1)) / area);
  const double v2 = CountPixels(s.MaskOf(2)) / area;
  ASSERT_EQ(v1, 1.0);
  ASSERT_NEAR(v2, 0.10, 0.02);
  const OracleOptions o = DetectionOnly();
  const double p1 = o.DetectionProbability(v1);
  const double p2 = o.DetectionProbability(v2);
  EXPECT_NEAR(p1, 0.97, 1e-12);
  EXPECT_GT(p2, 0.015);
  EXPECT_LT(p2, 0.06);

  constexpr int kSeeds = 3000;
  int found1 = 0;
  int found2 = 0;
  double confidence_sum1 = 0.0;
  for (int seed = 0; seed < kSeeds; ++seed) {
    OracleSegmenter oracle(o, seed);
    const auto r = oracle.Segment(s.Request("tomato"));
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    for (const InstanceMask& m : r->instances) {
      if (m.mask == s.MaskOf(1)) {
        ++found1;
        confidence_sum1 += m.confidence;
      } else if (m.mask == s.MaskOf(2)) {
        ++found2;
      } else {
        ADD_FAILURE() << "unexpected mask at " << test::Centroid(m.mask).transpose();
      }
    }
  }
  ExpectRate(found1, kSeeds, p1, "fully visible fruit");
  ExpectRate(found2, kSeeds, p2, "10 %-visible fruit");
  // Confidence of a fully visible fruit: N(0.55 + 0.35, 0.08), so a mean of 0.90.
  EXPECT_NEAR(confidence_sum1 / found1, 0.90, 0.01);
}

TEST(OracleSegmenterTest, FruitsBelowMinPixelsAreNeverDetected) {
  TestScene s(80, 60, 100.0);
  // No ground truth for these fruits: their visible fraction counts as 1.
  s.PaintRect(10, 10, 29, 11, 1, SemanticClass::kFruit, {200, 30, 20});  // 19 pixels
  s.PaintRect(10, 30, 30, 31, 2, SemanticClass::kFruit, {200, 30, 20});  // 20 pixels
  int found1 = 0;
  int found2 = 0;
  for (int seed = 0; seed < 400; ++seed) {
    OracleSegmenter oracle(DetectionOnly(), seed);
    const auto r = oracle.Segment(s.Request());
    ASSERT_TRUE(r.ok());
    for (const InstanceMask& m : r->instances) {
      found1 += m.mask == s.MaskOf(1) ? 1 : 0;
      found2 += m.mask == s.MaskOf(2) ? 1 : 0;
    }
  }
  EXPECT_EQ(found1, 0);
  ExpectRate(found2, 400, 0.97, "20-pixel fruit");
}

TEST(OracleSegmenterTest, ConfidenceRisesWithVisibilityAndStaysClamped) {
  TestScene s(160, 120, 100.0);
  s.PaintFruit(40, 60, 20, 1);                                             // v = 1
  s.PaintFruit(115, 60, 20, 2);                                            // v = 0.5
  s.PaintRect(115, 30, 150, 90, 10, SemanticClass::kLeaf, {60, 160, 40});  // right half hidden
  OracleOptions o = AlwaysDetect();
  o.confidence_mean_at_0 = 0.55;
  o.confidence_gain = 0.35;
  o.confidence_stddev = 0.08;
  std::vector<double> c1;
  std::vector<double> c2;
  for (uint64_t i = 0; i < 1000; ++i) {
    OracleSegmenter oracle(o, 5);
    const auto r = oracle.Segment(s.Request("tomato", i));
    ASSERT_TRUE(r.ok());
    ASSERT_EQ(r->instances.size(), 2u);
    c1.push_back(r->instances[0].confidence);
    c2.push_back(r->instances[1].confidence);
  }
  const auto mean = [](const std::vector<double>& x) {
    double sum = 0.0;
    for (double value : x) sum += value;
    return sum / x.size();
  };
  const double v2 = CountPixels(s.MaskOf(2)) / (M_PI * 400.0);
  EXPECT_NEAR(mean(c1), 0.90, 0.01);
  EXPECT_NEAR(mean(c2), 0.55 + 0.35 * v2, 0.01);
  EXPECT_LT(mean(c2), mean(c1) - 0.1);
  for (double c : c1) {
    EXPECT_GE(c, 0.05);
    EXPECT_LE(c, 0.99 + 1e-6);
  }
  // Huge spread: the clamp holds, and both ends are reached.
  o.confidence_stddev = 2.0;
  int at_min = 0;
  int at_max = 0;
  for (uint64_t i = 0; i < 200; ++i) {
    OracleSegmenter oracle(o, 5);
    const auto r = oracle.Segment(s.Request("tomato", i));
    ASSERT_TRUE(r.ok());
    for (const InstanceMask& m : r->instances) {
      EXPECT_GE(m.confidence, 0.05f);
      EXPECT_LE(m.confidence, 0.99f);
      at_min += m.confidence == 0.05f ? 1 : 0;
      at_max += m.confidence == 0.99f ? 1 : 0;
    }
  }
  EXPECT_GT(at_min, 50);
  EXPECT_GT(at_max, 50);
}

// ---- Boundary noise
// ------------------------------------------------------------------------------

TEST(OracleSegmenterTest, BoundaryNoiseErodesOrDilatesByUpToMaxBoundaryPx) {
  TestScene s(80, 80, 100.0);
  s.PaintFruit(40, 40, 15, 1);
  const MaskImage exact = s.MaskOf(1);
  const size_t area = CountPixels(exact);
  OracleOptions o = AlwaysDetect();
  o.max_boundary_px = 2;
  std::map<int, int> seen;  // radius -> count
  const std::map<size_t, int> radius_of_area = {{CountPixels(Erode(exact, 2)), -2},
                                                {CountPixels(Erode(exact, 1)), -1},
                                                {area, 0},
                                                {CountPixels(Dilate(exact, 1)), 1},
                                                {CountPixels(Dilate(exact, 2)), 2}};
  ASSERT_EQ(radius_of_area.size(), 5u);
  for (uint64_t i = 0; i < 500; ++i) {
    OracleSegmenter oracle(o, 2);
    const auto r = oracle.Segment(s.Request("tomato", i));
    ASSERT_TRUE(r.ok());
    ASSERT_EQ(r->instances.size(), 1u);
    const MaskImage& m = r->instances[0].mask;
    const size_t n = CountPixels(m);
    const auto it = radius_of_area.find(n);
    ASSERT_NE(it, radius_of_area.end()) << "area " << n;
    const int radius = it->second;
    ++seen[radius];
    EXPECT_EQ(m, AdjustBoundary(exact, radius));
    if (radius < 0) {
      EXPECT_TRUE(IsSubset(m, exact));  // eroded: inside the true mask
    }
    if (radius > 0) {
      EXPECT_TRUE(IsSubset(exact, m));  // dilated: contains it
    }
  }
  // A uniform radius in {-2, ..., 2}: each about 100 of 500.
  ASSERT_EQ(seen.size(), 5u);
  for (const auto& [radius, count] : seen) ExpectRate(count, 500, 0.2, "boundary radius");
  // Eroded areas are smaller than the true one, dilated ones larger.
  EXPECT_LT(CountPixels(Erode(exact, 1)), area);
  EXPECT_GT(CountPixels(Dilate(exact, 1)), area);
}

TEST(OracleSegmenterTest, ErodedAwayMasksAreDropped) {
  TestScene s(40, 40, 100.0);
  s.PaintRect(10, 10, 13, 20, 1, SemanticClass::kFruit, {200, 30, 20});  // 3 px wide
  OracleOptions o = AlwaysDetect();
  o.max_boundary_px = 2;
  int empty_or_missing = 0;
  for (uint64_t i = 0; i < 300; ++i) {
    OracleSegmenter oracle(o, 4);
    const auto r = oracle.Segment(s.Request("tomato", i));
    ASSERT_TRUE(r.ok());
    for (const InstanceMask& m : r->instances) EXPECT_GT(CountPixels(m.mask), 0u);
    empty_or_missing += r->instances.empty() ? 1 : 0;
  }
  // Erosion by 2 empties a 3-pixel-wide bar: a fifth of the radii.
  ExpectRate(empty_or_missing, 300, 0.2, "eroded away");
}

TEST(OracleSegmenterTest, BoundaryOffsetShiftsEveryRadius) {
  TestScene s(80, 80, 100.0);
  s.PaintFruit(40, 40, 15, 1);
  const MaskImage exact = s.MaskOf(1);
  for (const int offset : {-2, 2}) {
    OracleOptions o = AlwaysDetect();
    o.max_boundary_px = 0;
    o.boundary_offset_px = offset;
    OracleSegmenter oracle(o, 3);
    const auto r = oracle.Segment(s.Request("tomato", 0));
    ASSERT_TRUE(r.ok());
    ASSERT_EQ(r->instances.size(), 1u);
    EXPECT_EQ(r->instances[0].mask, AdjustBoundary(exact, offset)) << "offset " << offset;
  }
  // With the spread as well, the radii are offset + {-1, 0, 1}: always eroded for -2.
  OracleOptions o = AlwaysDetect();
  o.max_boundary_px = 1;
  o.boundary_offset_px = -2;
  std::set<size_t> areas;
  for (uint64_t i = 0; i < 100; ++i) {
    OracleSegmenter oracle(o, 5);
    const auto r = oracle.Segment(s.Request("tomato", i));
    ASSERT_TRUE(r.ok());
    ASSERT_EQ(r->instances.size(), 1u);
    areas.insert(CountPixels(r->instances[0].mask));
  }
  EXPECT_EQ(areas, (std::set<size_t>{CountPixels(Erode(exact, 3)), CountPixels(Erode(exact, 2)),
                                     CountPixels(Erode(exact, 1))}));
  o.boundary_offset_px = 17;
  EXPECT_THAT(o.Validate().message(), HasSubstr("boundary_offset_px (17 px)"));
}

// ---- False positives
// -----------------------------------------------------------------------------

TEST(OracleSegmenterTest, FalsePositivesComeAtTheConfiguredRateAndOnlyOnLeaves) {
  TestScene s(120, 90, 100.0);
  s.PaintFruit(30, 30, 10, 1);
  const int leaf_a = s.PaintRect(60, 10, 100, 20, 10, SemanticClass::kLeaf, {60, 160, 40});
  const int leaf_b = s.PaintRect(60, 40, 90, 50, 11, SemanticClass::kLeaf, {60, 160, 40});
  s.PaintRect(10, 70, 13, 73, 12, SemanticClass::kLeaf, {60, 160, 40});  // 9 px: too small
  s.PaintRect(20, 60, 60, 80, 13, SemanticClass::kStem, {60, 120, 40});  // not a leaf
  ASSERT_EQ(leaf_a, 400);
  ASSERT_EQ(leaf_b, 300);
  OracleOptions o = AlwaysDetect();
  o.p_false_positive = 0.15;
  o.min_pixels = 20;  // leaves need as many pixels as fruit
  constexpr int kFrames = 3000;
  int false_positives = 0;
  std::map<uint16_t, int> on_leaf;
  for (uint64_t i = 0; i < kFrames; ++i) {
    OracleSegmenter oracle(o, 8);
    const auto r = oracle.Segment(s.Request("tomato", i));
    ASSERT_TRUE(r.ok());
    ASSERT_GE(r->instances.size(), 1u);
    ASSERT_LE(r->instances.size(), 2u);
    EXPECT_EQ(r->instances[0].mask, s.MaskOf(1));  // the fruit comes first
    if (r->instances.size() == 2) {
      const InstanceMask& fp = r->instances[1];
      ++false_positives;
      EXPECT_EQ(fp.semantic_class, SemanticClass::kFruit);
      EXPECT_EQ(fp.label, "tomato");
      EXPECT_GE(fp.confidence, 0.1f);
      EXPECT_LE(fp.confidence, 0.4f);
      if (fp.mask == s.MaskOf(10)) {
        ++on_leaf[10];
      } else if (fp.mask == s.MaskOf(11)) {
        ++on_leaf[11];
      } else {
        ADD_FAILURE() << "false positive is not a whole visible leaf";
      }
    }
  }
  ExpectRate(false_positives, kFrames, 0.15, "false positives per frame");
  // The leaf is chosen uniformly among the eligible ones.
  ExpectRate(on_leaf[10], false_positives, 0.5, "leaf 10 among false positives");
  EXPECT_EQ(on_leaf[10] + on_leaf[11], false_positives);
}

// ---- Merges
// --------------------------------------------------------------------------------------

/// Fruits 1 and 2 touch (4-neighbours), 3 is apart, 4 and 5 touch only at a corner.
TestScene MergeScene() {
  TestScene s(140, 120, 100.0);
  s.PaintFruit(40, 40, 15, 1);
  s.PaintFruit(68, 40, 15, 2);  // overlaps fruit 1 and paints over it
  s.PaintFruit(115, 40, 15, 3);
  s.PaintRect(30, 80, 40, 90, 4, SemanticClass::kFruit, {200, 30, 20});
  s.PaintRect(40, 90, 50, 100, 5, SemanticClass::kFruit, {200, 30, 20});
  return s;
}

TEST(OracleSegmenterTest, MergesJoinOnlyTouchingFruits) {
  const TestScene s = MergeScene();
  OracleOptions o = AlwaysDetect();
  o.p_merge = 1.0;
  OracleSegmenter oracle(o, 1);
  const auto r = oracle.Segment(s.Request());
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->instances.size(), 4u);
  EXPECT_EQ(r->instances[0].mask, Union(s.MaskOf(1), s.MaskOf(2)));
  EXPECT_EQ(r->instances[1].mask, s.MaskOf(3));
  EXPECT_EQ(r->instances[2].mask, s.MaskOf(4));  // diagonal contact is not touching
  EXPECT_EQ(r->instances[3].mask, s.MaskOf(5));

  // At p_merge = 0.5 the touching pair merges in about half the frames, nothing else ever does.
  o.p_merge = 0.5;
  int merged = 0;
  constexpr int kFrames = 2000;
  for (uint64_t i = 0; i < kFrames; ++i) {
    OracleSegmenter half(o, 1);
    const auto ri = half.Segment(s.Request("tomato", i));
    ASSERT_TRUE(ri.ok());
    ASSERT_TRUE(ri->instances.size() == 4u || ri->instances.size() == 5u);
    if (ri->instances.size() == 4u) {
      ++merged;
      EXPECT_EQ(ri->instances[0].mask, Union(s.MaskOf(1), s.MaskOf(2)));
    }
    EXPECT_EQ(ri->instances[ri->instances.size() - 3].mask, s.MaskOf(3));
  }
  ExpectRate(merged, kFrames, 0.5, "merged pair");
}

TEST(OracleSegmenterTest, EachFruitMergesAtMostOncePerFrame) {
  TestScene s(120, 40, 100.0);
  s.PaintRect(10, 10, 30, 30, 1, SemanticClass::kFruit, {200, 30, 20});
  s.PaintRect(30, 10, 50, 30, 2, SemanticClass::kFruit, {200, 30, 20});
  s.PaintRect(50, 10, 70, 30, 3, SemanticClass::kFruit, {200, 30, 20});
  OracleOptions o = AlwaysDetect();
  o.p_merge = 1.0;
  OracleSegmenter oracle(o, 1);
  const auto r = oracle.Segment(s.Request());
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->instances.size(), 2u);
  EXPECT_EQ(r->instances[0].mask, Union(s.MaskOf(1), s.MaskOf(2)));
  EXPECT_EQ(r->instances[1].mask, s.MaskOf(3));
}

TEST(OracleSegmenterTest, UndetectedFruitsDoNotMerge) {
  TestScene s = MergeScene();
  // Hide fruit 2 (and 3) behind a leaf except a 27-pixel sliver that still touches fruit 1.
  s.PaintRect(56, 0, 140, 70, 20, SemanticClass::kLeaf, {60, 160, 40});
  ASSERT_EQ(CountPixels(s.MaskOf(2)), 27u);
  OracleOptions o = AlwaysDetect();
  o.min_pixels = 40;
  o.p_merge = 1.0;
  OracleSegmenter oracle(o, 1);
  const auto r = oracle.Segment(s.Request());
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->instances.size(), 3u);  // fruit 1 alone, then fruits 4 and 5 (100 px each)
  EXPECT_EQ(r->instances[0].mask, s.MaskOf(1));
  EXPECT_EQ(r->instances[1].mask, s.MaskOf(4));
}

// ---- Errors
// --------------------------------------------------------------------------------------

TEST(OracleSegmenterTest, BadGroundTruthFruitsAreErrorsNamingThem) {
  TestScene s(40, 30, 50.0);
  s.PaintFruit(20, 15, 5, 7);
  s.labels.fruits[0].radius_m = -0.01;
  OracleSegmenter oracle;
  auto r = oracle.Segment(s.Request());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("fruit 7: radius_m (-0.01)"));
  s.labels.fruits[0].radius_m = 0.1;
  s.labels.fruits[0].center_W.x() = std::nan("");
  r = oracle.Segment(s.Request());
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("fruit 7: center_W (nan"));
}

// ---- End to end on a rendered scene
// --------------------------------------------------------------

TEST(OracleSegmenterTest, RenderedTomatoPlantGivesPlausibleDetections) {
  auto scene = sim::MakeScenario("tomato-single-cluster", 4);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  const sim::RgbdRenderer renderer(*scene);
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435().Scaled(0.5);  // 320 x 240
  const sim::RenderedFrame f = renderer.Render(K, scene->X_WC_start);
  SimulatorLabels labels{f.instance_ids, f.class_ids, {}};
  for (const sim::FruitTruth& t : scene->Fruits()) {
    labels.fruits.push_back({t.instance_id, t.center_W, t.mean_radius_m()});
  }
  SegmentationRequest request;
  request.frame = &f.rgbd;
  request.labels = &labels;
  request.prompt = "tomato";

  // Perfect: exactly the visible fruit of the label images.
  const Segmentation truth = Segmentation::FromLabelImages(f.instance_ids, f.class_ids);
  ASSERT_GE(truth.instances.size(), 2u) << "the start view should see some fruit";
  OracleSegmenter perfect(OracleOptions::Perfect(), 4);
  const auto p = perfect.Segment(request);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->instances.size(), truth.instances.size());
  for (size_t i = 0; i < truth.instances.size(); ++i) {
    EXPECT_EQ(p->instances[i].mask, truth.instances[i].mask);
  }

  // Default noise: most well-visible fruit found, and the masks lie mostly on fruit pixels.
  OracleSegmenter oracle(OracleOptions{}, 4);
  size_t mask_pixels = 0;
  size_t fruit_pixels = 0;
  size_t instances = 0;
  for (uint64_t i = 0; i < 20; ++i) {
    request.frame_index = i;
    const auto r = oracle.Segment(request);
    ASSERT_TRUE(r.ok());
    ASSERT_TRUE(r->ValidateFor(320, 240).ok());
    instances += r->instances.size();
    for (const InstanceMask& m : r->instances) {
      for (size_t k = 0; k < m.mask.num_pixels(); ++k) {
        if (m.mask.data()[k] == 0) continue;
        ++mask_pixels;
        fruit_pixels += f.class_ids.data()[k] == static_cast<uint8_t>(SemanticClass::kFruit);
      }
    }
  }
  const double precision = static_cast<double>(fruit_pixels) / mask_pixels;
  EXPECT_GT(precision, 0.8) << fruit_pixels << " of " << mask_pixels;
  EXPECT_LT(precision, 1.0);  // noise does change the masks
  // Six visible fruit, most of them well visible: about 4.5 detections per frame.
  EXPECT_GE(instances, 60u);
  EXPECT_LE(instances, 20u * (truth.instances.size() + 1));
}

}  // namespace
}  // namespace avp::segmentation

#include "detections.h"

#include <cmath>
#include <random>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>

namespace avp::zsl {
namespace {

using ::testing::HasSubstr;

void ExpectBoxEq(const PixelBox& actual, const PixelBox& expected) {
  EXPECT_FLOAT_EQ(actual.x0, expected.x0);
  EXPECT_FLOAT_EQ(actual.y0, expected.y0);
  EXPECT_FLOAT_EQ(actual.x1, expected.x1);
  EXPECT_FLOAT_EQ(actual.y1, expected.y1);
}

// A head with 3 class slots and 5 anchors, as rows of [cx, cy, w, h, s0, s1, s2] per anchor.
const std::vector<std::vector<float>> kAnchors = {
    {100, 50, 20, 10, 0.10f, 0.70f, 0.20f},   // → class 1, 0.7, box (90, 45)–(110, 55)
    {200, 200, 40, 40, 0.05f, 0.02f, 0.90f},  // only slot 2 fires
    {320, 320, 64, 32, 0.30f, 0.30f, 0.00f},  // tie → class 0, box (288, 304)–(352, 336)
    {10, 10, 4, 4, 0.25f, 0.00f, 0.00f},      // exactly the threshold → dropped
    {600, 600, 10, 10, 0.00f, 0.26f, 0.99f},  // class 1, 0.26 unless slot 2 is active
};
constexpr int kSlots = 3;
constexpr int kNumAnchors = 5;

std::vector<float> AnchorsFirst() {
  std::vector<float> out;
  for (const auto& a : kAnchors) out.insert(out.end(), a.begin(), a.end());
  return out;
}

std::vector<float> AttributesFirst() {
  std::vector<float> out(kAnchors.size() * kAnchors[0].size());
  for (size_t a = 0; a < kAnchors.size(); ++a) {
    for (size_t k = 0; k < kAnchors[a].size(); ++k) out[k * kAnchors.size() + a] = kAnchors[a][k];
  }
  return out;
}

TEST(SigmoidTest, Values) {
  EXPECT_FLOAT_EQ(Sigmoid(0.f), 0.5f);
  EXPECT_FLOAT_EQ(Sigmoid(2.f), 1.f / (1.f + std::exp(-2.f)));
  EXPECT_FLOAT_EQ(Sigmoid(-2.f), 0.11920292f);  // e^−2 / (1 + e^−2), no cancellation
  EXPECT_FLOAT_EQ(Sigmoid(200.f), 1.f);
  EXPECT_EQ(Sigmoid(-200.f), 0.f);  // no inf/inf
  EXPECT_EQ(Sigmoid(INFINITY), 1.f);
  EXPECT_EQ(Sigmoid(-INFINITY), 0.f);
}

TEST(BoxIouTest, ExactFractions) {
  EXPECT_FLOAT_EQ(BoxIou({0, 0, 10, 10}, {0, 0, 10, 10}), 1.f);
  EXPECT_FLOAT_EQ(BoxIou({0, 0, 10, 10}, {0, 0, 10, 5}), 0.5f);       // 50 / 100
  EXPECT_FLOAT_EQ(BoxIou({0, 0, 10, 10}, {5, 0, 15, 10}), 1.f / 3);   // 50 / 150
  EXPECT_FLOAT_EQ(BoxIou({0, 0, 10, 10}, {1, 0, 11, 10}), 9.f / 11);  // 90 / 110
  EXPECT_EQ(BoxIou({0, 0, 10, 10}, {10, 0, 20, 10}), 0.f);            // touching
  EXPECT_EQ(BoxIou({0, 0, 10, 10}, {20, 20, 30, 30}), 0.f);
  EXPECT_EQ(BoxIou({5, 5, 5, 5}, {5, 5, 5, 5}), 0.f);    // no area
  EXPECT_EQ(BoxIou({0, 0, 10, 10}, {8, 8, 2, 2}), 0.f);  // inverted box
}

TEST(DecodeYoloHeadTest, XywhToXyxyBestClassAndStrictThreshold) {
  const std::vector<float> head = AttributesFirst();
  const auto result = DecodeYoloHead(head, kSlots, kNumAnchors, HeadLayout::kAttributesFirst,
                                     ScoreActivation::kNone, 0.25f, /*num_active_classes=*/3);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  const std::vector<Detection>& d = *result;
  ASSERT_EQ(d.size(), 4u);  // anchor 3 (score == threshold) is dropped
  ExpectBoxEq(d[0].box, {90, 45, 110, 55});
  EXPECT_FLOAT_EQ(d[0].score, 0.7f);
  EXPECT_EQ(d[0].class_index, 1);
  ExpectBoxEq(d[1].box, {180, 180, 220, 220});
  EXPECT_EQ(d[1].class_index, 2);
  EXPECT_FLOAT_EQ(d[1].score, 0.9f);
  ExpectBoxEq(d[2].box, {288, 304, 352, 336});
  EXPECT_EQ(d[2].class_index, 0);  // tie: the first slot
  EXPECT_FLOAT_EQ(d[2].score, 0.3f);
  ExpectBoxEq(d[3].box, {595, 595, 605, 605});
  EXPECT_EQ(d[3].class_index, 2);
  EXPECT_FLOAT_EQ(d[3].score, 0.99f);
}

TEST(DecodeYoloHeadTest, UnusedClassSlotsAreIgnored) {
  const std::vector<float> head = AttributesFirst();
  const auto result = DecodeYoloHead(head, kSlots, kNumAnchors, HeadLayout::kAttributesFirst,
                                     ScoreActivation::kNone, 0.25f, /*num_active_classes=*/2);
  ASSERT_TRUE(result.ok());
  const std::vector<Detection>& d = *result;
  // Anchor 1 fired only in slot 2 (best active 0.05): gone. Anchor 4 falls back to slot 1.
  ASSERT_EQ(d.size(), 3u);
  EXPECT_EQ(d[0].class_index, 1);
  EXPECT_EQ(d[1].class_index, 0);
  ExpectBoxEq(d[1].box, {288, 304, 352, 336});
  EXPECT_EQ(d[2].class_index, 1);
  EXPECT_FLOAT_EQ(d[2].score, 0.26f);
  ExpectBoxEq(d[2].box, {595, 595, 605, 605});

  const auto none = DecodeYoloHead(head, kSlots, kNumAnchors, HeadLayout::kAttributesFirst,
                                   ScoreActivation::kNone, 0.f, /*num_active_classes=*/0);
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->empty());
}

TEST(DecodeYoloHeadTest, BothLayoutsGiveIdenticalDetections) {
  for (const int active : {1, 2, 3}) {
    const auto a =
        DecodeYoloHead(AttributesFirst(), kSlots, kNumAnchors, HeadLayout::kAttributesFirst,
                       ScoreActivation::kNone, 0.01f, active);
    const auto b = DecodeYoloHead(AnchorsFirst(), kSlots, kNumAnchors, HeadLayout::kAnchorsFirst,
                                  ScoreActivation::kNone, 0.01f, active);
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_EQ(a->size(), b->size());
    ASSERT_FALSE(a->empty());
    for (size_t i = 0; i < a->size(); ++i) {
      EXPECT_EQ((*a)[i].box, (*b)[i].box);
      EXPECT_EQ((*a)[i].score, (*b)[i].score);
      EXPECT_EQ((*a)[i].class_index, (*b)[i].class_index);
    }
  }
  // A non-symmetric random head: layouts differ in memory, not in detections.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  const int slots = 7, anchors = 50;
  std::vector<float> attrs_first((4 + slots) * anchors);
  for (float& v : attrs_first) v = u(rng);
  std::vector<float> anchors_first(attrs_first.size());
  for (int k = 0; k < 4 + slots; ++k) {
    for (int a = 0; a < anchors; ++a) {
      anchors_first[a * (4 + slots) + k] = attrs_first[k * anchors + a];
    }
  }
  const auto a = DecodeYoloHead(attrs_first, slots, anchors, HeadLayout::kAttributesFirst,
                                ScoreActivation::kSigmoid, 0.6f, 5);
  const auto b = DecodeYoloHead(anchors_first, slots, anchors, HeadLayout::kAnchorsFirst,
                                ScoreActivation::kSigmoid, 0.6f, 5);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->size(), b->size());
  ASSERT_GT(a->size(), 10u);
  for (size_t i = 0; i < a->size(); ++i) {
    EXPECT_EQ((*a)[i].box, (*b)[i].box);
    EXPECT_EQ((*a)[i].score, (*b)[i].score);
    EXPECT_EQ((*a)[i].class_index, (*b)[i].class_index);
  }
}

TEST(DecodeYoloHeadTest, SigmoidOrNot) {
  // One anchor, two slots with logits 0 and 2.
  const std::vector<float> head = {10, 20, 4, 6, 0.f, 2.f};
  const auto sig =
      DecodeYoloHead(head, 2, 1, HeadLayout::kAnchorsFirst, ScoreActivation::kSigmoid, 0.6f, 2);
  ASSERT_TRUE(sig.ok());
  ASSERT_EQ(sig->size(), 1u);
  EXPECT_FLOAT_EQ((*sig)[0].score, Sigmoid(2.f));  // 0.8808
  EXPECT_EQ((*sig)[0].class_index, 1);
  ExpectBoxEq((*sig)[0].box, {8, 17, 12, 23});

  const auto raw =
      DecodeYoloHead(head, 2, 1, HeadLayout::kAnchorsFirst, ScoreActivation::kNone, 0.6f, 2);
  ASSERT_TRUE(raw.ok());
  ASSERT_EQ(raw->size(), 1u);
  EXPECT_FLOAT_EQ((*raw)[0].score, 2.f);

  // Slot 0 only: logit 0 → 0.5 fails 0.6 after the sigmoid, raw 0 fails too.
  const auto sig0 =
      DecodeYoloHead(head, 2, 1, HeadLayout::kAnchorsFirst, ScoreActivation::kSigmoid, 0.6f, 1);
  ASSERT_TRUE(sig0.ok());
  EXPECT_TRUE(sig0->empty());
  const auto sig0_low =
      DecodeYoloHead(head, 2, 1, HeadLayout::kAnchorsFirst, ScoreActivation::kSigmoid, 0.4f, 1);
  ASSERT_TRUE(sig0_low.ok());
  ASSERT_EQ(sig0_low->size(), 1u);
  EXPECT_FLOAT_EQ((*sig0_low)[0].score, 0.5f);
  // Negative logits: a raw score of −1 never passes 0.2; its sigmoid 0.2689 does.
  const std::vector<float> negative = {10, 20, 4, 6, -1.f};
  EXPECT_TRUE(
      DecodeYoloHead(negative, 1, 1, HeadLayout::kAnchorsFirst, ScoreActivation::kNone, 0.2f, 1)
          ->empty());
  EXPECT_EQ(
      DecodeYoloHead(negative, 1, 1, HeadLayout::kAnchorsFirst, ScoreActivation::kSigmoid, 0.2f, 1)
          ->size(),
      1u);
}

TEST(DecodeYoloHeadTest, ErrorsNameTheSizes) {
  const std::vector<float> head(27);
  const auto r =
      DecodeYoloHead(head, 3, 4, HeadLayout::kAttributesFirst, ScoreActivation::kNone, 0.1f, 3);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(r.status().message(),
            "YOLO head output has 27 values, expected (4 + 3 class slots) x 4 anchors = 28");

  const auto active = DecodeYoloHead(std::vector<float>(28), 3, 4, HeadLayout::kAttributesFirst,
                                     ScoreActivation::kNone, 0.1f, 4);
  ASSERT_FALSE(active.ok());
  EXPECT_THAT(active.status().message(), HasSubstr("num_active_classes (4)"));
  EXPECT_THAT(active.status().message(), HasSubstr("num_class_slots (3)"));

  const auto slots =
      DecodeYoloHead({}, 0, 0, HeadLayout::kAttributesFirst, ScoreActivation::kNone, 0.1f, 0);
  ASSERT_FALSE(slots.ok());
  EXPECT_THAT(slots.status().message(), HasSubstr("num_class_slots (0)"));

  const auto empty =
      DecodeYoloHead({}, 3, 0, HeadLayout::kAttributesFirst, ScoreActivation::kNone, 0.1f, 3);
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->empty());
}

TEST(NonMaxSuppressionTest, AgnosticAgainstPerClass) {
  const std::vector<Detection> in = {
      {{1, 0, 11, 10}, 0.8f, 1},  // IoU 9/11 with the first
      {{0, 0, 10, 10}, 0.9f, 0},
      {{20, 20, 30, 30}, 0.7f, 1},  // disjoint
  };
  const std::vector<Detection> agnostic = NonMaxSuppression(in, 0.5f, /*class_agnostic=*/true);
  ASSERT_EQ(agnostic.size(), 2u);
  EXPECT_EQ(agnostic[0].score, 0.9f);
  EXPECT_EQ(agnostic[1].score, 0.7f);

  const std::vector<Detection> per_class = NonMaxSuppression(in, 0.5f, /*class_agnostic=*/false);
  ASSERT_EQ(per_class.size(), 3u);  // sorted by score
  EXPECT_EQ(per_class[0].score, 0.9f);
  EXPECT_EQ(per_class[1].score, 0.8f);
  EXPECT_EQ(per_class[2].score, 0.7f);

  // Same class, so suppressed per class too.
  std::vector<Detection> same = in;
  same[0].class_index = 0;
  EXPECT_EQ(NonMaxSuppression(same, 0.5f, false).size(), 2u);
}

TEST(NonMaxSuppressionTest, SuppressesOnlyAboveTheThreshold) {
  const std::vector<Detection> in = {{{0, 0, 10, 10}, 0.9f, 0}, {{0, 0, 10, 5}, 0.8f, 0}};
  EXPECT_EQ(NonMaxSuppression(in, 0.5f, true).size(), 2u);  // IoU 0.5 is not > 0.5
  EXPECT_EQ(NonMaxSuppression(in, 0.49f, true).size(), 1u);
}

TEST(NonMaxSuppressionTest, TiesKeepTheEarlierInput) {
  // Identical boxes and scores; class_index tells them apart.
  const std::vector<Detection> in = {{{0, 0, 10, 10}, 0.5f, 7}, {{0, 0, 10, 10}, 0.5f, 3}};
  const auto kept = NonMaxSuppression(in, 0.3f, true);
  ASSERT_EQ(kept.size(), 1u);
  EXPECT_EQ(kept[0].class_index, 7);
  const auto reversed = NonMaxSuppression({in[1], in[0]}, 0.3f, true);
  ASSERT_EQ(reversed.size(), 1u);
  EXPECT_EQ(reversed[0].class_index, 3);
  // Disjoint ties come out in input order.
  const std::vector<Detection> disjoint = {
      {{0, 0, 1, 1}, 0.5f, 2}, {{5, 5, 6, 6}, 0.6f, 0}, {{2, 2, 3, 3}, 0.5f, 1}};
  const auto order = NonMaxSuppression(disjoint, 0.3f, true);
  ASSERT_EQ(order.size(), 3u);
  EXPECT_EQ(order[0].class_index, 0);
  EXPECT_EQ(order[1].class_index, 2);
  EXPECT_EQ(order[2].class_index, 1);
  // Enough ties that an unstable sort would reorder them: 64 disjoint boxes, scores alternating
  // 0.5 / 0.6 → the 0.6 ones in input order, then the 0.5 ones in input order.
  std::vector<Detection> many;
  for (int i = 0; i < 64; ++i) {
    many.push_back({{10.f * i, 0, 10.f * i + 5, 5}, i % 2 == 0 ? 0.5f : 0.6f, i});
  }
  const auto stable = NonMaxSuppression(many, 0.3f, true);
  ASSERT_EQ(stable.size(), 64u);
  for (int k = 0; k < 32; ++k) {
    EXPECT_EQ(stable[k].class_index, 2 * k + 1);
    EXPECT_EQ(stable[32 + k].class_index, 2 * k);
  }
}

TEST(NonMaxSuppressionTest, EmptyInputMaxDetectionsAndNaN) {
  EXPECT_TRUE(NonMaxSuppression({}, 0.5f, true).empty());
  EXPECT_TRUE(NonMaxSuppression({}, 0.5f, false).empty());

  std::vector<Detection> in;
  for (int i = 0; i < 5; ++i) {
    in.push_back({{10.f * i, 0, 10.f * i + 5, 5}, 0.1f * (i + 1), 0});
  }
  const auto top3 = NonMaxSuppression(in, 0.5f, true, 3);
  ASSERT_EQ(top3.size(), 3u);
  EXPECT_FLOAT_EQ(top3[0].score, 0.5f);
  EXPECT_FLOAT_EQ(top3[1].score, 0.4f);
  EXPECT_FLOAT_EQ(top3[2].score, 0.3f);
  EXPECT_TRUE(NonMaxSuppression(in, 0.5f, true, 0).empty());

  in.push_back({{100, 100, 110, 110}, NAN, 0});
  EXPECT_EQ(NonMaxSuppression(in, 0.5f, true).size(), 5u);
}

// The fast path against OpenCV's NMSBoxes, class-agnostic and per class through class offsets
// (design §4.1), on random overlapping boxes.
TEST(NonMaxSuppressionTest, MatchesOpenCvNmsBoxesWithClassOffsets) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> pos(0.f, 200.f), size(5.f, 60.f), score(0.f, 1.f);
  std::uniform_int_distribution<int> cls(0, 3);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<Detection> in;
    for (int i = 0; i < 150; ++i) {
      const float x = pos(rng), y = pos(rng);
      in.push_back({{x, y, x + size(rng), y + size(rng)}, score(rng), cls(rng)});
    }
    for (const bool agnostic : {true, false}) {
      std::vector<cv::Rect2d> rects;
      std::vector<float> scores;
      for (const Detection& d : in) {
        const double offset = agnostic ? 0.0 : 1000.0 * d.class_index;  // > any coordinate
        rects.emplace_back(d.box.x0 + offset, d.box.y0 + offset, d.box.x1 - d.box.x0,
                           d.box.y1 - d.box.y0);
        scores.push_back(d.score);
      }
      std::vector<int> indices;
      cv::dnn::NMSBoxes(rects, scores, 0.f, 0.45f, indices);  // scores are > 0
      const std::vector<Detection> ours = NonMaxSuppression(in, 0.45f, agnostic, in.size());
      ASSERT_EQ(ours.size(), indices.size()) << "trial " << trial << " agnostic " << agnostic;
      for (size_t i = 0; i < ours.size(); ++i) {
        EXPECT_EQ(ours[i].box, in[indices[i]].box);
        EXPECT_EQ(ours[i].score, in[indices[i]].score);
      }
    }
  }
}

TEST(DetectionsToSourceTest, UnLetterboxesAndClips) {
  const Letterbox lb = Letterbox::Compute(1000, 667);  // scale 0.64, pad top 106
  const auto out =
      DetectionsToSource({{{64, 170, 320, 426}, 0.5f, 2}, {{-5, 0, 10, 90}, 0.4f, 1}}, lb);
  ASSERT_EQ(out.size(), 2u);
  ExpectBoxEq(out[0].box, {100, 100, 500, 500});
  EXPECT_EQ(out[0].score, 0.5f);
  EXPECT_EQ(out[0].class_index, 2);
  ExpectBoxEq(out[1].box, {0, 0, 15.625f, 0});  // 10/0.64; rows above the image clip to 0
}

TEST(NormalizedCxcywhToPixelsTest, ScalesAndClips) {
  // cx 0.5·1000 = 500 ± 100; cy 0.5·500 = 250 ± 100.
  ExpectBoxEq(NormalizedCxcywhToPixels(0.5f, 0.5f, 0.2f, 0.4f, 1000, 500), {400, 150, 600, 350});
  // x0 = −0.05·1000 → 0, y1 = 1.1·500 → 500.
  ExpectBoxEq(NormalizedCxcywhToPixels(0.05f, 0.9f, 0.2f, 0.4f, 1000, 500), {0, 350, 150, 500});
  ExpectBoxEq(NormalizedCxcywhToPixels(0.5f, 0.5f, 1.f, 1.f, 1200, 800), {0, 0, 1200, 800});
}

}  // namespace
}  // namespace avp::zsl

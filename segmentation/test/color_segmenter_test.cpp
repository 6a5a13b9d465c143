#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/segmentation/color_segmenter.h>
#include <avp/segmentation/mask_ops.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

#include "test_frames.h"

namespace avp::segmentation {
namespace {

using test::Rgb;
using test::TestScene;
using ::testing::HasSubstr;

constexpr Rgb kRed = {200, 30, 20};           // hue 2
constexpr Rgb kWrapRed = {255, 0, 43};        // hue 175 (350 degrees)
constexpr Rgb kGreyishRed = {150, 130, 125};  // hue 6 but saturation 43
constexpr Rgb kDarkRed = {30, 3, 3};          // hue 0, saturation 230, but value 30
constexpr Rgb kGreen = {170, 200, 20};        // hue 35
constexpr Rgb kBlue = {20, 40, 200};          // hue 117

Segmentation Segment(const TestScene& s, const std::string& prompt,
                     const ColorOptions& options = {}) {
  ColorSegmenter seg(options);
  auto r = seg.Segment(s.Request(prompt));
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  if (!r.ok()) return {};
  EXPECT_TRUE(r->ValidateFor(s.width(), s.height()).ok());
  return std::move(r).value();
}

TEST(RgbToHsvTest, MatchesOpenCvOnKnownColours) {
  EXPECT_EQ(RgbToHsv(255, 0, 0), (Hsv8{0, 255, 255}));
  EXPECT_EQ(RgbToHsv(255, 255, 0), (Hsv8{30, 255, 255}));
  EXPECT_EQ(RgbToHsv(0, 255, 0), (Hsv8{60, 255, 255}));
  EXPECT_EQ(RgbToHsv(0, 255, 255), (Hsv8{90, 255, 255}));
  EXPECT_EQ(RgbToHsv(0, 0, 255), (Hsv8{120, 255, 255}));
  EXPECT_EQ(RgbToHsv(255, 0, 255), (Hsv8{150, 255, 255}));
  EXPECT_EQ(RgbToHsv(255, 255, 255), (Hsv8{0, 0, 255}));
  EXPECT_EQ(RgbToHsv(0, 0, 0), (Hsv8{0, 0, 0}));
  EXPECT_EQ(RgbToHsv(128, 128, 128), (Hsv8{0, 0, 128}));
  // OpenCV: (255, 0, 43) -> hue 360 - 60 * 43 / 255 = 349.9 deg -> 175; (255, 85, 0) -> 10.
  EXPECT_EQ(RgbToHsv(255, 0, 43), (Hsv8{175, 255, 255}));
  EXPECT_EQ(RgbToHsv(255, 85, 0), (Hsv8{10, 255, 255}));
  EXPECT_EQ(RgbToHsv(255, 90, 0).h, 11);
  EXPECT_EQ(RgbToHsv(200, 30, 20), (Hsv8{2, 230, 200}));
  EXPECT_EQ(RgbToHsv(170, 200, 20), (Hsv8{35, 230, 200}));
  EXPECT_EQ(RgbToHsv(150, 130, 125), (Hsv8{6, 43, 150}));
  // A hue just below 0 wraps to 179, never 180.
  EXPECT_EQ(RgbToHsv(255, 0, 5).h, 179);
  EXPECT_EQ(RgbToHsv(255, 0, 1).h, 0);
}

TEST(ColorSegmenterTest, RedDiscsAreSeparateInstancesWithExactPixelCounts) {
  TestScene s(120, 80, 100.0);
  const int a = s.PaintDisc(20, 20, 8, 1, SemanticClass::kFruit, kRed);
  const int b = s.PaintDisc(60, 20, 5, 2, SemanticClass::kFruit, kRed);
  const int c = s.PaintDisc(95, 55, 10, 3, SemanticClass::kFruit, kWrapRed);  // wrap-around red
  s.PaintDisc(30, 60, 8, 4, SemanticClass::kOther, kGreyishRed);              // rejected: S
  s.PaintDisc(60, 60, 8, 5, SemanticClass::kOther, kDarkRed);                 // rejected: V
  s.PaintDisc(90, 20, 8, 6, SemanticClass::kOther, kBlue);                    // rejected: H
  s.PaintDisc(5, 75, 4, 6, SemanticClass::kOther, {255, 255, 255});           // white
  ASSERT_EQ(a, 197);
  ASSERT_EQ(b, 81);
  const Segmentation seg = Segment(s, "tomato");
  ASSERT_EQ(seg.instances.size(), 3u);
  // Raster order of the first pixel: the disc at (20, 20) (top row 12), then (60, 20) (row 15),
  // then (95, 55).
  EXPECT_EQ(CountPixels(seg.instances[0].mask), static_cast<size_t>(a));
  EXPECT_EQ(CountPixels(seg.instances[1].mask), static_cast<size_t>(b));
  EXPECT_EQ(CountPixels(seg.instances[2].mask), static_cast<size_t>(c));
  EXPECT_EQ(seg.instances[0].mask, s.MaskOf(1));
  EXPECT_EQ(seg.instances[1].mask, s.MaskOf(2));
  EXPECT_EQ(seg.instances[2].mask, s.MaskOf(3));
  for (const InstanceMask& m : seg.instances) {
    EXPECT_EQ(m.semantic_class, SemanticClass::kFruit);
    EXPECT_EQ(m.confidence, 0.8f);
    EXPECT_EQ(m.label, "tomato");
  }
}

TEST(ColorSegmenterTest, ReferenceRangesMissWrapAroundRedAndPassGreys) {
  // The reference filter: red hue 1-10 and no saturation or value floor.
  TestScene s(120, 80, 100.0);
  s.PaintDisc(20, 20, 8, 1, SemanticClass::kFruit, {255, 0, 0});  // hue 0
  s.PaintDisc(60, 20, 8, 2, SemanticClass::kFruit, kWrapRed);     // hue 175
  const int greyish = s.PaintDisc(30, 60, 8, 3, SemanticClass::kOther, kGreyishRed);
  ColorOptions reference;
  reference.red_hues = {{1, 10}};
  reference.min_saturation = 0;
  reference.min_value = 0;
  const Segmentation ref = Segment(s, "red", reference);
  ASSERT_EQ(ref.instances.size(), 1u);  // only the grey-ish one
  EXPECT_EQ(CountPixels(ref.instances[0].mask), static_cast<size_t>(greyish));
  // The defaults find both reds and reject the grey.
  const Segmentation fixed = Segment(s, "red");
  ASSERT_EQ(fixed.instances.size(), 2u);
  EXPECT_EQ(fixed.instances[0].mask, s.MaskOf(1));
  EXPECT_EQ(fixed.instances[1].mask, s.MaskOf(2));
}

TEST(ColorSegmenterTest, PromptChoosesTheColour) {
  TestScene s(120, 80, 100.0);
  s.PaintDisc(20, 20, 8, 1, SemanticClass::kFruit, kRed);
  s.PaintDisc(70, 40, 9, 2, SemanticClass::kLeaf, kGreen);
  const Segmentation green = Segment(s, "green");
  ASSERT_EQ(green.instances.size(), 1u);
  EXPECT_EQ(green.instances[0].mask, s.MaskOf(2));
  EXPECT_EQ(green.instances[0].label, "green");
  const Segmentation green_apple = Segment(s, "green apple");
  ASSERT_EQ(green_apple.instances.size(), 1u);
  EXPECT_EQ(green_apple.instances[0].mask, s.MaskOf(2));
  const Segmentation both = Segment(s, "red-green");
  ASSERT_EQ(both.instances.size(), 2u);
  EXPECT_EQ(both.instances[0].mask, s.MaskOf(1));
  EXPECT_EQ(both.instances[1].mask, s.MaskOf(2));
  // Two phrases: the red instances (labelled "tomato") first, then the green ones.
  const Segmentation two = Segment(s, "tomato, green");
  ASSERT_EQ(two.instances.size(), 2u);
  EXPECT_EQ(two.instances[0].label, "tomato");
  EXPECT_EQ(two.instances[0].mask, s.MaskOf(1));
  EXPECT_EQ(two.instances[1].label, "green");
  EXPECT_TRUE(Segment(s, "banana").instances.empty());
}

TEST(ColorSegmenterTest, PhrasesMapToFilters) {
  const ColorSegmenter seg;
  EXPECT_EQ(seg.FilterForPhrase("tomato"), ColorFilter::kRed);
  EXPECT_EQ(seg.FilterForPhrase("Cherry Tomatoes"), ColorFilter::kRed);
  EXPECT_EQ(seg.FilterForPhrase("strawberries"), ColorFilter::kRed);
  EXPECT_EQ(seg.FilterForPhrase("green apple"), ColorFilter::kGreen);
  EXPECT_EQ(seg.FilterForPhrase("lime"), ColorFilter::kGreen);
  EXPECT_EQ(seg.FilterForPhrase("RED"), ColorFilter::kRed);
  EXPECT_EQ(seg.FilterForPhrase("red-green"), ColorFilter::kRedGreen);
  EXPECT_EQ(seg.FilterForPhrase("red and green peppers"), ColorFilter::kRedGreen);
  EXPECT_FALSE(seg.FilterForPhrase("banana").has_value());
  EXPECT_FALSE(seg.FilterForPhrase("").has_value());
  EXPECT_EQ(ColorFilterFromString("red-green"), ColorFilter::kRedGreen);
  EXPECT_EQ(ToString(ColorFilter::kGreen), "green");
  EXPECT_FALSE(ColorFilterFromString("blue").has_value());
}

TEST(ColorSegmenterTest, MinAreaDropsSmallComponents) {
  TestScene s(80, 40, 100.0);
  s.PaintRect(5, 5, 11, 10, 1, SemanticClass::kFruit, kRed);  // 6 x 5 = 30 pixels
  s.PaintRect(30, 5, 36, 10, 2, SemanticClass::kFruit, kRed);
  s.PaintRect(35, 9, 36, 10, 0, SemanticClass::kBackground, {128, 128, 128});  // 29 pixels
  const Segmentation kept = Segment(s, "red");
  ASSERT_EQ(kept.instances.size(), 1u);
  EXPECT_EQ(kept.instances[0].mask, s.MaskOf(1));
  ColorOptions strict;
  strict.min_area_px = 31;
  EXPECT_TRUE(Segment(s, "red", strict).instances.empty());
  ColorOptions loose;
  loose.min_area_px = 1;
  loose.confidence = 0.6f;
  const Segmentation all = Segment(s, "red", loose);
  ASSERT_EQ(all.instances.size(), 2u);
  EXPECT_EQ(CountPixels(all.instances[1].mask), 29u);
  EXPECT_EQ(all.instances[1].confidence, 0.6f);
}

TEST(ColorSegmenterTest, DiagonallyTouchingPixelsFormOneComponent) {
  TestScene s(60, 40, 100.0);
  s.PaintRect(5, 5, 15, 15, 1, SemanticClass::kFruit, kRed);
  s.PaintRect(15, 15, 25, 25, 2, SemanticClass::kFruit, kRed);  // meets the first at a corner
  const Segmentation seg = Segment(s, "red");
  ASSERT_EQ(seg.instances.size(), 1u);
  EXPECT_EQ(CountPixels(seg.instances[0].mask), 200u);
}

TEST(ColorSegmenterTest, ValidateNamesBadValues) {
  ColorOptions o;
  o.red_hues = {{0, 10}, {170, 190}};
  o.green_hues = {};
  o.min_saturation = 300;
  o.min_area_px = 0;
  o.confidence = 1.5f;
  const Status s = o.Validate();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("red_hues[1] (170-190)"));
  EXPECT_THAT(s.message(), HasSubstr("green_hues must not be empty"));
  EXPECT_THAT(s.message(), HasSubstr("min_saturation (300)"));
  EXPECT_THAT(s.message(), HasSubstr("min_area_px (0 px) must be >= 1"));
  EXPECT_THAT(s.message(), HasSubstr("confidence (1.5)"));
  EXPECT_THROW(ColorSegmenter{o}, Error);
  EXPECT_TRUE(ColorOptions{}.Validate().ok());
}

TEST(ColorSegmenterTest, RenderedRedApplesAreFoundOnFruitPixels) {
  // The espalier's start view at seed 4 sees one red apple (hue about 2) and two green-yellow
  // ones (hue 31-35). (The tomato scenarios' fruit render orange, hue 15-25, which the
  // reference's red range 0-10 misses.)
  auto scene = sim::MakeScenario("espalier-multiple-fruits", 4);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  const sim::RgbdRenderer renderer(*scene);
  const sim::RenderedFrame f =
      renderer.Render(CameraIntrinsics::RealSenseD435().Scaled(0.5), scene->X_WC_start);
  SegmentationRequest request;
  request.frame = &f.rgbd;
  request.prompt = "apple";
  ColorSegmenter seg;
  const auto r = seg.Segment(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_FALSE(r->instances.empty());
  size_t mask_pixels = 0;
  size_t fruit_pixels = 0;
  for (const InstanceMask& m : r->instances) {
    for (size_t k = 0; k < m.mask.num_pixels(); ++k) {
      if (m.mask.data()[k] == 0) continue;
      ++mask_pixels;
      fruit_pixels += f.class_ids.data()[k] == static_cast<uint8_t>(SemanticClass::kFruit);
    }
  }
  EXPECT_GT(static_cast<double>(fruit_pixels) / mask_pixels, 0.95)
      << fruit_pixels << " of " << mask_pixels;
}

}  // namespace
}  // namespace avp::segmentation

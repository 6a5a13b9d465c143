#include "letterbox.h"

#include <cstdint>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include <avp/core/error.h>

namespace avp::zsl {
namespace {

void ExpectBoxEq(const PixelBox& actual, const PixelBox& expected) {
  EXPECT_FLOAT_EQ(actual.x0, expected.x0);
  EXPECT_FLOAT_EQ(actual.y0, expected.y0);
  EXPECT_FLOAT_EQ(actual.x1, expected.x1);
  EXPECT_FLOAT_EQ(actual.y1, expected.y1);
}

// Element (c, y, x) of a CHW tensor of width w, height h.
float At(const std::vector<float>& t, int w, int h, int c, int y, int x) {
  return t[(static_cast<size_t>(c) * h + y) * w + x];
}

TEST(LetterboxTest, LandscapeOddPaddingPutsTheExtraPixelAtTheBottom) {
  // r = min(640/667, 640/1000) = 0.64; 667·0.64 = 426.88 → 427; d = 213: top round(106.4) = 106,
  // bottom round(106.6) = 107.
  const Letterbox lb = Letterbox::Compute(1000, 667);
  EXPECT_EQ(lb.src_w, 1000);
  EXPECT_EQ(lb.src_h, 667);
  EXPECT_EQ(lb.dst_w, 640);
  EXPECT_EQ(lb.dst_h, 640);
  EXPECT_DOUBLE_EQ(lb.scale, 0.64);
  EXPECT_EQ(lb.resized_w, 640);
  EXPECT_EQ(lb.resized_h, 427);
  EXPECT_EQ(lb.pad_left, 0);
  EXPECT_EQ(lb.pad_right, 0);
  EXPECT_EQ(lb.pad_top, 106);
  EXPECT_EQ(lb.pad_bottom, 107);
}

TEST(LetterboxTest, PortraitOddPaddingPutsTheExtraPixelAtTheRight) {
  // r = 640/641; 482·640/641 = 481.248 → 481; d = 159: left round(79.4) = 79, right 80.
  const Letterbox lb = Letterbox::Compute(482, 641);
  EXPECT_DOUBLE_EQ(lb.scale, 640.0 / 641.0);
  EXPECT_EQ(lb.resized_w, 481);
  EXPECT_EQ(lb.resized_h, 640);
  EXPECT_EQ(lb.pad_left, 79);
  EXPECT_EQ(lb.pad_right, 80);
  EXPECT_EQ(lb.pad_top, 0);
  EXPECT_EQ(lb.pad_bottom, 0);
}

TEST(LetterboxTest, EvenPaddingSplitsEqually) {
  // r = 2 (upscaling): 640 x 480, d = 160: round(79.9) = round(80.1) = 80.
  const Letterbox lb = Letterbox::Compute(320, 240);
  EXPECT_DOUBLE_EQ(lb.scale, 2.0);
  EXPECT_EQ(lb.resized_w, 640);
  EXPECT_EQ(lb.resized_h, 480);
  EXPECT_EQ(lb.pad_top, 80);
  EXPECT_EQ(lb.pad_bottom, 80);
  EXPECT_EQ(lb.pad_left + lb.pad_right, 0);

  const Letterbox square = Letterbox::Compute(640, 640);
  EXPECT_DOUBLE_EQ(square.scale, 1.0);
  EXPECT_EQ(square.resized_w, 640);
  EXPECT_EQ(square.pad_left + square.pad_top + square.pad_right + square.pad_bottom, 0);
}

TEST(LetterboxTest, ResizedSizeRoundsHalfToEvenAsPython) {
  // r = min(640/5, 640/256) = 2.5: 5·2.5 = 12.5 → 12 and 7·2.5 = 17.5 → 18 (Python round()).
  const Letterbox five = Letterbox::Compute(256, 5);
  EXPECT_EQ(five.resized_w, 640);
  EXPECT_EQ(five.resized_h, 12);
  EXPECT_EQ(five.pad_top, 314);  // d = 628
  EXPECT_EQ(five.pad_bottom, 314);
  const Letterbox seven = Letterbox::Compute(256, 7);
  EXPECT_EQ(seven.resized_h, 18);
  EXPECT_EQ(seven.pad_top, 311);  // d = 622
  EXPECT_EQ(seven.pad_bottom, 311);
}

TEST(LetterboxTest, NonSquareDestination) {
  // r = min(48/50, 64/100) = 0.64: 64 x 32, d = 16 on the height.
  const Letterbox lb = Letterbox::Compute(100, 50, 64, 48);
  EXPECT_EQ(lb.resized_w, 64);
  EXPECT_EQ(lb.resized_h, 32);
  EXPECT_EQ(lb.pad_top, 8);
  EXPECT_EQ(lb.pad_bottom, 8);
  EXPECT_EQ(lb.pad_left, 0);
}

TEST(LetterboxTest, PaddingAlwaysFillsTheDestination) {
  for (int w = 1; w <= 1500; w += 37) {
    for (int h = 1; h <= 1500; h += 41) {
      const Letterbox lb = Letterbox::Compute(w, h);
      ASSERT_EQ(lb.pad_left + lb.resized_w + lb.pad_right, 640) << w << "x" << h;
      ASSERT_EQ(lb.pad_top + lb.resized_h + lb.pad_bottom, 640) << w << "x" << h;
      ASSERT_GE(lb.pad_right - lb.pad_left, 0);
      ASSERT_LE(lb.pad_right - lb.pad_left, 1);
      ASSERT_GE(lb.pad_bottom - lb.pad_top, 0);
      ASSERT_LE(lb.pad_bottom - lb.pad_top, 1);
    }
  }
}

TEST(LetterboxTest, RejectsNonPositiveSizes) {
  EXPECT_THROW(Letterbox::Compute(0, 10), avp::Error);
  EXPECT_THROW(Letterbox::Compute(10, -1), avp::Error);
  EXPECT_THROW(Letterbox::Compute(10, 10, 0, 640), avp::Error);
}

TEST(LetterboxTest, ToSourceSubtractsPadDividesByScale) {
  const Letterbox lb = Letterbox::Compute(1000, 667);  // scale 0.64, pad top 106
  // x: 64/0.64 = 100, 320/0.64 = 500; y: (170−106)/0.64 = 100, (426−106)/0.64 = 500.
  ExpectBoxEq(lb.ToSource({64, 170, 320, 426}), {100, 100, 500, 500});
  ExpectBoxEq(lb.ToLetterboxed({100, 100, 500, 500}), {64, 170, 320, 426});

  const Letterbox portrait = Letterbox::Compute(482, 641);  // scale 640/641, pad left 79
  // x1: (560 − 79)·641/640 = 481.7515625; y1: 640·641/640 = 641.
  ExpectBoxEq(portrait.ToSource({79, 0, 560, 640}), {0, 0, 481.7515625f, 641});
}

TEST(LetterboxTest, ToSourceClipsToTheImage) {
  const Letterbox lb = Letterbox::Compute(1000, 667);
  // x0 = −15.6 → 0, y0 = −87.5 → 0, x1 = 1015.6 → 1000, y1 = 771.875 → 667.
  ExpectBoxEq(lb.ToSource({-10, 50, 650, 600}), {0, 0, 1000, 667});
  // Partly clipped: y0 = (80 − 106)/0.64 < 0 → 0, y1 = (300 − 106)/0.64 = 303.125.
  ExpectBoxEq(lb.ToSource({32, 80, 96, 300}), {50, 0, 150, 303.125f});
}

TEST(LetterboxTest, RoundTripInsideTheSource) {
  std::mt19937 rng(7);
  for (const auto& [w, h] : {std::pair{1000, 667}, std::pair{482, 641}, std::pair{333, 999}}) {
    const Letterbox lb = Letterbox::Compute(w, h);
    std::uniform_real_distribution<float> ux(0.f, static_cast<float>(w));
    std::uniform_real_distribution<float> uy(0.f, static_cast<float>(h));
    for (int i = 0; i < 100; ++i) {
      const PixelBox b{ux(rng), uy(rng), ux(rng), uy(rng)};
      const PixelBox back = lb.ToSource(lb.ToLetterboxed(b));
      EXPECT_NEAR(back.x0, b.x0, 1e-3);
      EXPECT_NEAR(back.y0, b.y0, 1e-3);
      EXPECT_NEAR(back.x1, b.x1, 1e-3);
      EXPECT_NEAR(back.y1, b.y1, 1e-3);
    }
  }
}

TEST(LetterboxTest, TensorIsChwRgbScaledWithPad114) {
  // 8x4 into 8x8: r = 1 (no resize), pad top 2, bottom 2. Every pixel distinct per channel.
  ImageRgb8 rgb(8, 4);
  for (int v = 0; v < 4; ++v) {
    for (int u = 0; u < 8; ++u) {
      rgb.at(u, v, 0) = static_cast<uint8_t>(10 * v + u);        // R
      rgb.at(u, v, 1) = static_cast<uint8_t>(100 + 10 * v + u);  // G
      rgb.at(u, v, 2) = static_cast<uint8_t>(200 + 10 * v + u);  // B
    }
  }
  const Letterbox lb = Letterbox::Compute(8, 4, 8, 8);
  ASSERT_EQ(lb.pad_top, 2);
  const std::vector<float> t = LetterboxTensor(rgb, lb);
  ASSERT_EQ(t.size(), 3u * 8 * 8);
  const float k = 1.f / 255.f;
  // Pixel (u=5, v=1) lands at (x=5, y=3).
  EXPECT_FLOAT_EQ(At(t, 8, 8, 0, 3, 5), 15.f * k);
  EXPECT_FLOAT_EQ(At(t, 8, 8, 1, 3, 5), 115.f * k);
  EXPECT_FLOAT_EQ(At(t, 8, 8, 2, 3, 5), 215.f * k);
  // Pixel (0, 0) at (0, 2) and (7, 3) at (7, 5).
  EXPECT_FLOAT_EQ(At(t, 8, 8, 0, 2, 0), 0.f);
  EXPECT_FLOAT_EQ(At(t, 8, 8, 2, 5, 7), 237.f * k);
  // Pad rows 0, 1, 6, 7 are 114/255 in every channel.
  for (int c = 0; c < 3; ++c) {
    for (const int y : {0, 1, 6, 7}) {
      for (int x = 0; x < 8; ++x) EXPECT_FLOAT_EQ(At(t, 8, 8, c, y, x), 114.f / 255.f);
    }
  }
  EXPECT_FLOAT_EQ(At(t, 8, 8, 0, 0, 0), 114.f * k);
}

TEST(LetterboxTest, TensorPadsLeftAndRightOfAPortraitImage) {
  // 3x8 into 8x8: r = 1, d = 5: left round(2.4) = 2, right round(2.6) = 3.
  ImageRgb8 rgb(3, 8, 50);
  const Letterbox lb = Letterbox::Compute(3, 8, 8, 8);
  ASSERT_EQ(lb.pad_left, 2);
  ASSERT_EQ(lb.pad_right, 3);
  const std::vector<float> t = LetterboxTensor(rgb, lb, 114.f, 1.f);  // unscaled values
  for (int y = 0; y < 8; ++y) {
    for (int x = 0; x < 8; ++x) {
      const float expected = (x >= 2 && x < 5) ? 50.f : 114.f;
      EXPECT_EQ(At(t, 8, 8, 1, y, x), expected) << x << "," << y;
    }
  }
}

TEST(LetterboxTest, TensorResizesTheImage) {
  // 4x2 into 8x8: r = 2, resized 8x4, pad top 2. A constant colour stays exact under bilinear.
  ImageRgb8 rgb(4, 2);
  for (int v = 0; v < 2; ++v) {
    for (int u = 0; u < 4; ++u) {
      rgb.at(u, v, 0) = 10;
      rgb.at(u, v, 1) = 20;
      rgb.at(u, v, 2) = 30;
    }
  }
  const Letterbox lb = Letterbox::Compute(4, 2, 8, 8);
  ASSERT_EQ(lb.resized_h, 4);
  const std::vector<float> t = LetterboxTensor(rgb, lb, 114.f, 1.f);
  for (int x = 0; x < 8; ++x) {
    EXPECT_EQ(At(t, 8, 8, 0, 1, x), 114.f);
    EXPECT_EQ(At(t, 8, 8, 0, 2, x), 10.f);
    EXPECT_EQ(At(t, 8, 8, 1, 4, x), 20.f);
    EXPECT_EQ(At(t, 8, 8, 2, 5, x), 30.f);
    EXPECT_EQ(At(t, 8, 8, 2, 6, x), 114.f);
  }
  // A left/right step 0 | 200 becomes a bilinear ramp: 8 columns from 4, with x = 2k, 2k+1
  // sampling source (x + 0.5)/2 − 0.5; the middle pair straddles the step at 1.25 and 1.75.
  ImageRgb8 step(4, 2, 0);
  for (int v = 0; v < 2; ++v) {
    for (int u = 2; u < 4; ++u) step.at(u, v, 0) = 200;
  }
  const std::vector<float> s = LetterboxTensor(step, lb, 114.f, 1.f);
  EXPECT_EQ(At(s, 8, 8, 0, 3, 2), 0.f);    // source 0.75: between 0 and 0
  EXPECT_EQ(At(s, 8, 8, 0, 3, 3), 50.f);   // source 1.25: 0.75·0 + 0.25·200
  EXPECT_EQ(At(s, 8, 8, 0, 3, 4), 150.f);  // source 1.75
  EXPECT_EQ(At(s, 8, 8, 0, 3, 5), 200.f);
}

TEST(LetterboxTest, TensorRejectsAnImageOfAnotherSize) {
  const Letterbox lb = Letterbox::Compute(10, 10);
  EXPECT_THROW(LetterboxTensor(ImageRgb8(10, 11), lb), avp::Error);
}

}  // namespace
}  // namespace avp::zsl

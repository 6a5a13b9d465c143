#include "sam_geometry.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include <avp/core/error.h>

namespace avp::zsl {
namespace {

// The SAM decoder stub of design §8.2: 256² logits, pixel (i, j) = +10 if
// x0 <= 4(j + 0.5) <= x1 and y0 <= 4(i + 0.5) <= y1, else −10 (box in the 1024 prompt frame).
std::vector<float> StubLowResLogits(const std::array<float, 4>& box) {
  std::vector<float> logits(256 * 256);
  for (int i = 0; i < 256; ++i) {
    for (int j = 0; j < 256; ++j) {
      const float x = 4.f * (j + 0.5f), y = 4.f * (i + 0.5f);
      const bool inside = box[0] <= x && x <= box[2] && box[1] <= y && y <= box[3];
      logits[i * 256 + j] = inside ? 10.f : -10.f;
    }
  }
  return logits;
}

struct Extent {
  int first = -1;  // first positive index, −1 if none
  int last = -1;   // last positive index
};

Extent RowExtent(const MaskImage& m, int v) {
  Extent e;
  for (int u = 0; u < m.width(); ++u) {
    if (m.at(u, v) == 0) continue;
    if (e.first < 0) e.first = u;
    e.last = u;
  }
  return e;
}

Extent ColumnExtent(const MaskImage& m, int u) {
  Extent e;
  for (int v = 0; v < m.height(); ++v) {
    if (m.at(u, v) == 0) continue;
    if (e.first < 0) e.first = v;
    e.last = v;
  }
  return e;
}

int CountNonzero(const MaskImage& m) {
  return static_cast<int>(
      std::count_if(m.data().begin(), m.data().end(), [](uint8_t v) { return v != 0; }));
}

TEST(SamTransformTest, LandscapeWith512Input) {
  const SamTransform t = SamTransform::Compute(1000, 667, 512);
  EXPECT_EQ(t.encoder_size, 512);
  EXPECT_DOUBLE_EQ(t.encoder_scale, 0.512);
  EXPECT_EQ(t.encoder_resized_w, 512);
  EXPECT_EQ(t.encoder_resized_h, 342);  // int(341.504 + 0.5)
  EXPECT_EQ(t.prompt_frame, 1024);
  EXPECT_DOUBLE_EQ(t.prompt_scale, 1.024);
  EXPECT_EQ(t.prompt_resized_w, 1024);
  EXPECT_EQ(t.prompt_resized_h, 683);  // int(683.008 + 0.5)
}

TEST(SamTransformTest, PortraitAnd1024Input) {
  const SamTransform p = SamTransform::Compute(667, 1000, 512);
  EXPECT_EQ(p.encoder_resized_w, 342);
  EXPECT_EQ(p.encoder_resized_h, 512);
  EXPECT_EQ(p.prompt_resized_w, 683);
  EXPECT_EQ(p.prompt_resized_h, 1024);

  const SamTransform xl = SamTransform::Compute(1000, 667, 1024);
  EXPECT_DOUBLE_EQ(xl.encoder_scale, 1.024);
  EXPECT_EQ(xl.encoder_resized_w, 1024);
  EXPECT_EQ(xl.encoder_resized_h, 683);
  EXPECT_EQ(xl.prompt_resized_h, 683);

  const SamTransform exact = SamTransform::Compute(1024, 768, 512);
  EXPECT_DOUBLE_EQ(exact.encoder_scale, 0.5);
  EXPECT_EQ(exact.encoder_resized_w, 512);
  EXPECT_EQ(exact.encoder_resized_h, 384);
  EXPECT_DOUBLE_EQ(exact.prompt_scale, 1.0);
  EXPECT_EQ(exact.prompt_resized_w, 1024);
  EXPECT_EQ(exact.prompt_resized_h, 768);
}

TEST(SamTransformTest, SizesRoundHalvesUp) {
  // int(x + 0.5): 5·0.5 = 2.5 → 3 and 7·0.5 = 3.5 → 4 (not half to even).
  EXPECT_EQ(SamTransform::Compute(1024, 5, 512).encoder_resized_h, 3);
  EXPECT_EQ(SamTransform::Compute(1024, 7, 512).encoder_resized_h, 4);
  EXPECT_EQ(SamTransform::Compute(1024, 5, 512).prompt_resized_h, 5);
  // 2048 x 3 → 1024 x int(1.5 + 0.5) = 2 in the prompt frame, 512 x int(0.75 + 0.5) = 1.
  const SamTransform t = SamTransform::Compute(2048, 3, 512);
  EXPECT_EQ(t.prompt_resized_h, 2);
  EXPECT_EQ(t.encoder_resized_h, 1);
  EXPECT_THROW(SamTransform::Compute(0, 5, 512), avp::Error);
  EXPECT_THROW(SamTransform::Compute(5, 5, 0), avp::Error);
}

TEST(SamEncoderTensorTest, NormalisesChwRgbAndZeroPadsBottomRight) {
  // 8x4 with S = 8: no resize; rows 4..7 are padding.
  ImageRgb8 rgb(8, 4);
  for (int v = 0; v < 4; ++v) {
    for (int u = 0; u < 8; ++u) {
      rgb.at(u, v, 0) = static_cast<uint8_t>(200 + u);
      rgb.at(u, v, 1) = static_cast<uint8_t>(100 + v);
      rgb.at(u, v, 2) = 0;
    }
  }
  const SamTransform t = SamTransform::Compute(8, 4, 8);
  ASSERT_EQ(t.encoder_resized_w, 8);
  ASSERT_EQ(t.encoder_resized_h, 4);
  const std::vector<float> x = SamEncoderTensor(rgb, t);
  ASSERT_EQ(x.size(), 3u * 8 * 8);
  const auto at = [&](int c, int y, int xx) { return x[(c * 8 + y) * 8 + xx]; };
  EXPECT_FLOAT_EQ(at(0, 2, 5), (205.f - 123.675f) / 58.395f);
  EXPECT_FLOAT_EQ(at(1, 3, 0), (103.f - 116.28f) / 57.12f);
  EXPECT_FLOAT_EQ(at(2, 0, 7), (0.f - 103.53f) / 57.375f);
  for (int c = 0; c < 3; ++c) {
    for (int y = 4; y < 8; ++y) {
      for (int xx = 0; xx < 8; ++xx) EXPECT_EQ(at(c, y, xx), 0.f);
    }
  }
}

TEST(SamEncoderTensorTest, ResizesTheLongSideToS) {
  // 1024x768 → 512x384 in a 512² tensor; a constant image stays constant under bilinear.
  const SamTransform t = SamTransform::Compute(1024, 768, 512);
  ImageRgb8 rgb(1024, 768);
  for (int v = 0; v < 768; ++v) {
    for (int u = 0; u < 1024; ++u) {
      rgb.at(u, v, 0) = 124;
      rgb.at(u, v, 1) = 116;
      rgb.at(u, v, 2) = 104;
    }
  }
  const std::vector<float> x = SamEncoderTensor(rgb, t);
  ASSERT_EQ(x.size(), 3u * 512 * 512);
  const auto at = [&](int c, int y, int xx) {
    return x[(static_cast<size_t>(c) * 512 + y) * 512 + xx];
  };
  const float r = (124.f - 123.675f) / 58.395f, b = (104.f - 103.53f) / 57.375f;
  EXPECT_FLOAT_EQ(at(0, 0, 0), r);
  EXPECT_FLOAT_EQ(at(0, 383, 511), r);
  EXPECT_FLOAT_EQ(at(2, 200, 300), b);
  EXPECT_EQ(at(0, 384, 0), 0.f);  // first padded row
  EXPECT_EQ(at(1, 511, 511), 0.f);
  EXPECT_THROW(SamEncoderTensor(ImageRgb8(10, 10), t), avp::Error);
}

TEST(SamBoxPromptCoordsTest, ScalesIntoThe1024PromptFrame) {
  EXPECT_EQ(kSamBoxPromptLabels[0], 2.f);
  EXPECT_EQ(kSamBoxPromptLabels[1], 3.f);
  // 1024x768 with a 512 encoder: the prompt frame is the image itself.
  const auto same = SamBoxPromptCoords({100, 200, 300, 500}, SamTransform::Compute(1024, 768, 512));
  EXPECT_EQ(same, (std::array<float, 4>{100, 200, 300, 500}));
  // 1000x667: x·1024/1000, y·683/667 (the resized prompt size over the source size).
  const auto c = SamBoxPromptCoords({100, 200, 300, 500}, SamTransform::Compute(1000, 667, 512));
  EXPECT_FLOAT_EQ(c[0], 102.4f);
  EXPECT_FLOAT_EQ(c[1], 204.79760f);  // 200·683/667
  EXPECT_FLOAT_EQ(c[2], 307.2f);
  EXPECT_FLOAT_EQ(c[3], 511.99400f);  // 500·683/667
  // Same with a 1024 encoder: the prompt frame does not depend on S.
  EXPECT_EQ(c, SamBoxPromptCoords({100, 200, 300, 500}, SamTransform::Compute(1000, 667, 1024)));
  // 512x256 is upscaled ×2 into the prompt frame.
  const auto up = SamBoxPromptCoords({10, 20, 30, 40}, SamTransform::Compute(512, 256, 512));
  EXPECT_EQ(up, (std::array<float, 4>{20, 40, 60, 80}));
}

TEST(SamMaskChainTest, StubLogitsAtTheDesignExampleGiveTheDesignLowResRectangle) {
  // §8.2: box (100,200)–(300,500) lights low-res columns 25–74 and rows 50–124.
  const std::vector<float> logits = StubLowResLogits({100, 200, 300, 500});
  for (int i = 0; i < 256; ++i) {
    for (int j = 0; j < 256; ++j) {
      const bool inside = j >= 25 && j <= 74 && i >= 50 && i <= 124;
      ASSERT_EQ(logits[i * 256 + j], inside ? 10.f : -10.f) << i << "," << j;
    }
  }
}

TEST(SamMaskChainTest, Image1024x768GivesTheRectangleLessItsFourCornerPixels) {
  // Upsampling ×4 (align_corners=False) samples low-res (x + 0.5)/4 − 0.5, so column 99 has
  // 0.375 of low-res column 25 (−2.5) and column 100 has 0.625 (+2.5): columns 100–299, rows
  // 200–499 (crop and final resize are the identity here). At a corner both weights are 0.625:
  // −10 + 20·0.625² = −2.1875 < 0, so the four corner pixels are off — the rectangle is exact
  // along every edge but not at its corners (bilinear of a product of two step functions).
  const SamTransform t = SamTransform::Compute(1024, 768, 512);
  const MaskImage m =
      SamLowResLogitsToMask(StubLowResLogits(SamBoxPromptCoords({100, 200, 300, 500}, t)), 256, t);
  ASSERT_EQ(m.width(), 1024);
  ASSERT_EQ(m.height(), 768);
  for (int v = 0; v < 768; ++v) {
    for (int u = 0; u < 1024; ++u) {
      const bool corner = (u == 100 || u == 299) && (v == 200 || v == 499);
      const bool inside = u >= 100 && u <= 299 && v >= 200 && v <= 499 && !corner;
      ASSERT_EQ(m.at(u, v), inside ? 255 : 0) << u << "," << v;
    }
  }
  EXPECT_EQ(CountNonzero(m), 200 * 300 - 4);
}

TEST(SamMaskChainTest, Image1024x768BoxesOnMultiplesOf4AreExactAlongTheirEdges) {
  const SamTransform t = SamTransform::Compute(1024, 768, 1024);
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> qx(0, 256), qy(0, 192);
  for (int trial = 0; trial < 10; ++trial) {
    int a = qx(rng), c = qx(rng), b = qy(rng), d = qy(rng);
    if (a > c) std::swap(a, c);
    if (b > d) std::swap(b, d);
    if (c - a < 3 || d - b < 3) continue;
    const int x0 = 4 * a, x1 = 4 * c, y0 = 4 * b, y1 = 4 * d;
    const MaskImage m =
        SamLowResLogitsToMask(StubLowResLogits(SamBoxPromptCoords(
                                  PixelBox{static_cast<float>(x0), static_cast<float>(y0),
                                           static_cast<float>(x1), static_cast<float>(y1)},
                                  t)),
                              256, t);
    // Columns x0..x1−1 and rows y0..y1−1, less the corners whose edges are not on the border of
    // the 1024² prompt frame (there the edge-replicated sample is inside; the bottom of a 768-row
    // image is not on that border: prompt rows 768.. are padding).
    for (int v = 0; v < 768; ++v) {
      for (int u = 0; u < 1024; ++u) {
        const bool corner_x = (u == x0 && x0 > 0) || (u == x1 - 1 && x1 < 1024);
        const bool corner_y = (v == y0 && y0 > 0) || v == y1 - 1;
        const bool inside = u >= x0 && u < x1 && v >= y0 && v < y1 && !(corner_x && corner_y);
        ASSERT_EQ(m.at(u, v), inside ? 255 : 0)
            << "box " << x0 << "," << y0 << "–" << x1 << "," << y1 << " at " << u << "," << v;
      }
    }
  }
}

// The quantised stub rectangle of a prompt-frame box, mapped back to source pixels: the stub
// lights low-res indices ceil((p0 − 2)/4) .. floor((p1 − 2)/4), i.e. prompt pixels [4·first,
// 4·(last + 1)), and the source pixel u covers prompt [u·s, (u + 1)·s) with s = resized/src.
struct Span {
  double begin, end;
};
Span ExpectedSpan(float p0, float p1, double scale, int prompt_resized) {
  const int first = std::max(0, static_cast<int>(std::ceil((p0 - 2.0) / 4.0)));
  const int last = std::min(255, static_cast<int>(std::floor((p1 - 2.0) / 4.0)));
  return {4.0 * first / scale, std::min(4.0 * (last + 1), 1.0 * prompt_resized) / scale};
}

TEST(SamMaskChainTest, Image1000x667IsWithinOnePixelOfTheStubRectangle) {
  const SamTransform t = SamTransform::Compute(1000, 667, 512);
  // Derivation for box (100,200)–(300,500): prompt coords (102.4, 204.80)–(307.2, 511.99) light
  // low-res columns 26–76 and rows 51–127, i.e. prompt columns 104–307 and rows 204–511. Source
  // column u samples prompt (u + 0.5)·1.024 − 0.5: u = 101 → 103.41 (−0.44, off), u = 102 →
  // 104.44 (on), u = 300 → 307.21 (+1.44, on), u = 301 → 308.24 (off). Source row v samples
  // (v + 0.5)·683/667 − 0.5: v = 198 → 202.76 (off), 199 → 203.79 (+1.43, on), 499 → 510.98 (on),
  // 500 → 512.01 (off). The stub rectangle maps back to [101.56, 300.78) x [199.22, 500.01).
  const MaskImage m =
      SamLowResLogitsToMask(StubLowResLogits(SamBoxPromptCoords({100, 200, 300, 500}, t)), 256, t);
  ASSERT_EQ(m.width(), 1000);
  ASSERT_EQ(m.height(), 667);
  const Extent row = RowExtent(m, 350);
  EXPECT_EQ(row.first, 102);
  EXPECT_EQ(row.last, 300);
  const Extent col = ColumnExtent(m, 200);
  EXPECT_EQ(col.first, 199);
  EXPECT_EQ(col.last, 499);

  // Random boxes: every mask lies inside its stub rectangle grown by 1 px and covers it shrunk
  // by 1 px, i.e. each edge is within ±1 px.
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> ux(0.f, 1000.f), uy(0.f, 667.f);
  int checked = 0;
  for (int trial = 0; trial < 40; ++trial) {
    PixelBox box{ux(rng), uy(rng), ux(rng), uy(rng)};
    if (box.x0 > box.x1) std::swap(box.x0, box.x1);
    if (box.y0 > box.y1) std::swap(box.y0, box.y1);
    if (box.x1 - box.x0 < 20 || box.y1 - box.y0 < 20) continue;
    const std::array<float, 4> p = SamBoxPromptCoords(box, t);
    const Span sx = ExpectedSpan(p[0], p[2], 1024.0 / 1000.0, t.prompt_resized_w);
    const Span sy = ExpectedSpan(p[1], p[3], 683.0 / 667.0, t.prompt_resized_h);
    const MaskImage mask = SamLowResLogitsToMask(StubLowResLogits(p), 256, t);
    for (int v = 0; v < 667; ++v) {
      for (int u = 0; u < 1000; ++u) {
        // Pixel u covers [u, u + 1).
        const bool outer =
            u + 1 > sx.begin - 1 && u < sx.end + 1 && v + 1 > sy.begin - 1 && v < sy.end + 1;
        const bool inner =
            u >= sx.begin + 1 && u + 1 <= sx.end - 1 && v >= sy.begin + 1 && v + 1 <= sy.end - 1;
        if (mask.at(u, v) != 0) {
          ASSERT_TRUE(outer) << "trial " << trial << " at " << u << "," << v;
        } else {
          ASSERT_FALSE(inner) << "trial " << trial << " at " << u << "," << v;
        }
      }
    }
    ++checked;
  }
  EXPECT_GT(checked, 20);
}

TEST(SamMaskChainTest, ThresholdAndEmptyMasks) {
  const SamTransform t = SamTransform::Compute(64, 32, 512);
  // All −10: empty; all +10: full; threshold above every logit: empty.
  EXPECT_EQ(CountNonzero(SamLowResLogitsToMask(std::vector<float>(256 * 256, -10.f), 256, t)), 0);
  EXPECT_EQ(CountNonzero(SamLowResLogitsToMask(std::vector<float>(256 * 256, 10.f), 256, t)),
            64 * 32);
  EXPECT_EQ(CountNonzero(SamLowResLogitsToMask(std::vector<float>(256 * 256, 10.f), 256, t, 10.f)),
            0);
  // A logit of exactly the threshold is off (> threshold).
  EXPECT_EQ(CountNonzero(SamLowResLogitsToMask(std::vector<float>(256 * 256, 0.f), 256, t)), 0);
  EXPECT_THROW(SamLowResLogitsToMask(std::vector<float>(100), 256, t), avp::Error);
}

TEST(SamMaskChainTest, OnlyThePrePaddingRegionIsKept) {
  // 1024x512: prompt frame rows 0..511 hold the image. Light low-res rows 0..127 (prompt rows
  // 0..511) → the full mask; light rows 128..255 only (the padding) → nothing.
  const SamTransform t = SamTransform::Compute(1024, 512, 512);
  ASSERT_EQ(t.prompt_resized_h, 512);
  std::vector<float> top(256 * 256, -10.f), bottom(256 * 256, -10.f);
  for (int i = 0; i < 256; ++i) {
    for (int j = 0; j < 256; ++j) (i < 128 ? top : bottom)[i * 256 + j] = 10.f;
  }
  EXPECT_EQ(CountNonzero(SamLowResLogitsToMask(top, 256, t)), 1024 * 512);
  EXPECT_EQ(CountNonzero(SamLowResLogitsToMask(bottom, 256, t)), 0);
}

}  // namespace
}  // namespace avp::zsl

#include <array>
#include <cstdint>
#include <random>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/io/mask_codec.h>

namespace avp::io {
namespace {

using Polygon = std::vector<std::array<int, 2>>;

MaskImage Rectangle(int w, int h, int u0, int v0, int u1, int v1, uint8_t value = 255) {
  MaskImage m(w, h);
  for (int v = v0; v <= v1; ++v) {
    for (int u = u0; u <= u1; ++u) m.at(u, v) = value;
  }
  return m;
}

TEST(MaskToRleTest, KnownSmallMaskIsColumnMajorStartingWithBackground) {
  // Row 0: 0 1 1, row 1: 0 0 1 → columns (0,0), (1,0), (1,1) → 0 0 | 1 | 0 | 1 1.
  MaskImage m(3, 2);
  m.at(1, 0) = 255;
  m.at(2, 0) = 1;  // any nonzero value is foreground
  m.at(2, 1) = 255;
  EXPECT_EQ(MaskToRle(m), (std::vector<uint32_t>{2, 1, 1, 2}));
  // Row-major would have given {1, 2, 2, 1}.
}

TEST(MaskToRleTest, LeadingForegroundEmptyAndFull) {
  EXPECT_EQ(MaskToRle(MaskImage(2, 2, 255)), (std::vector<uint32_t>{0, 4}));
  EXPECT_EQ(MaskToRle(MaskImage(2, 3)), (std::vector<uint32_t>{6}));
  EXPECT_EQ(MaskToRle(MaskImage()), (std::vector<uint32_t>{0}));
  MaskImage first(2, 2);
  first.at(0, 0) = 255;
  EXPECT_EQ(MaskToRle(first), (std::vector<uint32_t>{0, 1, 3}));
  MaskImage last(2, 2);
  last.at(1, 1) = 255;
  EXPECT_EQ(MaskToRle(last), (std::vector<uint32_t>{3, 1}));
}

TEST(RleToMaskTest, DecodesTheKnownMask) {
  const std::vector<uint32_t> counts = {2, 1, 1, 2};
  const auto m = RleToMask(counts, 3, 2);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  MaskImage expected(3, 2);
  expected.at(1, 0) = 255;
  expected.at(2, 0) = 255;
  expected.at(2, 1) = 255;
  EXPECT_EQ(*m, expected);
  // Zero-length runs are allowed.
  const std::vector<uint32_t> zeros = {0, 0, 6};
  EXPECT_EQ(*RleToMask(zeros, 3, 2), MaskImage(3, 2));
  const std::vector<uint32_t> empty = {0};
  EXPECT_TRUE(RleToMask(empty, 0, 0)->empty());
}

TEST(RleToMaskTest, RoundTripsRandomMasks) {
  std::mt19937 rng(1);
  std::bernoulli_distribution fg(0.3);
  for (const auto& [w, h] :
       {std::pair{1, 1}, std::pair{7, 5}, std::pair{64, 3}, std::pair{13, 40}}) {
    for (int trial = 0; trial < 5; ++trial) {
      MaskImage m(w, h);
      for (uint8_t& v : m.data()) v = fg(rng) ? 255 : 0;
      const std::vector<uint32_t> counts = MaskToRle(m);
      uint64_t sum = 0;
      for (const uint32_t c : counts) sum += c;
      EXPECT_EQ(sum, static_cast<uint64_t>(w) * h);
      const auto back = RleToMask(counts, w, h);
      ASSERT_TRUE(back.ok());
      EXPECT_EQ(*back, m);
    }
  }
}

TEST(RleToMaskTest, ErrorsNameTheSumAndSize) {
  const std::vector<uint32_t> counts = {2, 1};
  const auto r = RleToMask(counts, 3, 2);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(r.status().message(), "RLE counts (2 runs) sum to 3, expected 3 x 2 = 6 pixels");
  const auto negative = RleToMask(counts, -3, 2);
  ASSERT_FALSE(negative.ok());
  EXPECT_THAT(negative.status().message(), ::testing::HasSubstr("-3 x 2"));
}

TEST(MaskToPolygonsTest, RectangleGivesItsFourCornerPixels) {
  // Columns 5..14, rows 2..6: one polygon, from the top-left pixel, down the left side first.
  const auto polygons = MaskToPolygons(Rectangle(20, 10, 5, 2, 14, 6));
  ASSERT_EQ(polygons.size(), 1u);
  EXPECT_EQ(polygons[0], (Polygon{{5, 2}, {5, 6}, {14, 6}, {14, 2}}));
  // The whole image: vertices on the border pixels.
  EXPECT_EQ(MaskToPolygons(MaskImage(4, 3, 1)),
            (std::vector<Polygon>{{{0, 0}, {0, 2}, {3, 2}, {3, 0}}}));
}

TEST(MaskToPolygonsTest, ComponentsOrderedByFirstVertexHolesIgnored) {
  MaskImage m(20, 10);
  // A ring (rows 5..9, columns 0..4, hole at 2,7) and a lone pixel at (15, 1).
  for (int v = 5; v <= 9; ++v) {
    for (int u = 0; u <= 4; ++u) m.at(u, v) = 255;
  }
  m.at(2, 7) = 0;
  m.at(15, 1) = 255;
  const auto polygons = MaskToPolygons(m);
  ASSERT_EQ(polygons.size(), 2u);
  EXPECT_EQ(polygons[0], (Polygon{{15, 1}}));
  EXPECT_EQ(polygons[1], (Polygon{{0, 5}, {0, 9}, {4, 9}, {4, 5}}));
  EXPECT_TRUE(MaskToPolygons(MaskImage(5, 5)).empty());
  EXPECT_TRUE(MaskToPolygons(MaskImage()).empty());
}

}  // namespace
}  // namespace avp::io

#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/segmentation/mask_ops.h>

namespace avp::segmentation {
namespace {

/// A w x h mask with the axis-aligned rectangle [u0, u1) x [v0, v1) set.
MaskImage Rect(int w, int h, int u0, int v0, int u1, int v1) {
  MaskImage m(w, h, 0);
  for (int v = v0; v < v1; ++v) {
    for (int u = u0; u < u1; ++u) m.at(u, v) = 1;
  }
  return m;
}

bool IsSubset(const MaskImage& a, const MaskImage& b) {
  for (size_t i = 0; i < a.num_pixels(); ++i) {
    if (a.data()[i] != 0 && b.data()[i] == 0) return false;
  }
  return true;
}

TEST(MaskOpsTest, DiskOffsetsAreTheDigitalDisk) {
  EXPECT_EQ(DiskOffsets(0).size(), 1u);
  EXPECT_EQ(DiskOffsets(1).size(), 5u);   // the 4-neighbour cross
  EXPECT_EQ(DiskOffsets(2).size(), 13u);  // + the 4 diagonals and the 4 at distance 2
  EXPECT_EQ(DiskOffsets(3).size(), 29u);
  EXPECT_THROW(DiskOffsets(-1), Error);
}

TEST(MaskOpsTest, DilatingASquareGrowsItByTheDiskExactly) {
  const MaskImage square = Rect(30, 30, 10, 10, 20, 20);  // 10 x 10 = 100 pixels
  ASSERT_EQ(CountPixels(square), 100u);
  // Radius 1 (cross): one pixel on each side, corners not filled: 100 + 4 * 10.
  EXPECT_EQ(CountPixels(Dilate(square, 1)), 140u);
  // Radius 2: 14 x 14 minus 3 pixels per corner (offsets (2,1), (1,2), (2,2) lie outside).
  EXPECT_EQ(CountPixels(Dilate(square, 2)), 184u);
  EXPECT_TRUE(IsSubset(square, Dilate(square, 2)));
  EXPECT_EQ(AdjustBoundary(square, 2), Dilate(square, 2));
}

TEST(MaskOpsTest, ErodingASquareShrinksIt) {
  const MaskImage square = Rect(30, 30, 10, 10, 20, 20);
  EXPECT_EQ(CountPixels(Erode(square, 1)), 64u);  // 8 x 8
  EXPECT_EQ(CountPixels(Erode(square, 2)), 36u);  // 6 x 6
  EXPECT_EQ(Erode(square, 1), Rect(30, 30, 11, 11, 19, 19));
  EXPECT_EQ(AdjustBoundary(square, -1), Erode(square, 1));
  EXPECT_EQ(CountPixels(Erode(square, 5)), 0u);  // nothing is 5 px from every edge
  EXPECT_EQ(AdjustBoundary(square, 0), square);
}

TEST(MaskOpsTest, MorphologyIsClippedToTheImage) {
  // A square in the top-left corner: dilation cannot write outside, and the border itself does
  // not erode (the mask was cut by the image edge, not by its own boundary).
  const MaskImage corner = Rect(20, 20, 0, 0, 5, 5);
  EXPECT_EQ(CountPixels(Dilate(corner, 1)), 25u + 5u + 5u);  // only right and bottom sides grow
  EXPECT_EQ(Erode(corner, 1), Rect(20, 20, 0, 0, 4, 4));
  // Values become 0/1 even for other nonzero inputs.
  MaskImage twos(4, 4, 0);
  twos.at(1, 1) = 7;
  EXPECT_EQ(AdjustBoundary(twos, 0).at(1, 1), 1);
}

TEST(MaskOpsTest, ComponentsAreLabelledInRasterOrderWithTheirSizes) {
  MaskImage m(10, 6, 0);
  // Component A: 2 x 2 at (6, 0); component B: a diagonal line from (0, 2) to (2, 4).
  m.at(6, 0) = m.at(7, 0) = m.at(6, 1) = m.at(7, 1) = 1;
  m.at(0, 2) = m.at(1, 3) = m.at(2, 4) = 1;
  const Components eight = LabelComponents(m, true);
  ASSERT_EQ(eight.count(), 2u);
  EXPECT_EQ(eight.sizes[0], 4u);
  EXPECT_EQ(eight.sizes[1], 3u);
  EXPECT_EQ(eight.labels.at(7, 1), 1);
  EXPECT_EQ(eight.labels.at(2, 4), 2);
  EXPECT_EQ(eight.labels.at(5, 5), 0);
  // With 4-connectivity the diagonal falls apart into three single pixels.
  const Components four = LabelComponents(m, false);
  ASSERT_EQ(four.count(), 4u);
  EXPECT_EQ(four.sizes[0], 4u);
  EXPECT_EQ(four.sizes[1], 1u);
  EXPECT_EQ(four.labels.at(1, 3), 3);
}

}  // namespace
}  // namespace avp::segmentation

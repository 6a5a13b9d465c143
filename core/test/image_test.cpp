#include <cmath>
#include <cstdint>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/image.h>

namespace avp {
namespace {

using ::testing::HasSubstr;

TEST(ImageTest, DefaultIsEmpty) {
  const DepthImage image;
  EXPECT_TRUE(image.empty());
  EXPECT_EQ(image.width(), 0);
  EXPECT_EQ(image.height(), 0);
  EXPECT_EQ(image.num_pixels(), 0u);
  EXPECT_TRUE(image.data().empty());
  EXPECT_FALSE(image.Contains(0, 0));
}

TEST(ImageTest, SizeAndFill) {
  const DepthImage depth(5, 3, 1.5f);
  EXPECT_FALSE(depth.empty());
  EXPECT_EQ(depth.width(), 5);
  EXPECT_EQ(depth.height(), 3);
  EXPECT_EQ(depth.num_pixels(), 15u);
  ASSERT_EQ(depth.data().size(), 15u);
  for (const float d : depth.data()) EXPECT_EQ(d, 1.5f);

  const ImageRgb8 rgb(4, 2, 7);
  EXPECT_EQ(ImageRgb8::channels, 3);
  EXPECT_EQ(rgb.num_pixels(), 8u);
  ASSERT_EQ(rgb.data().size(), 24u);  // three interleaved channels
  for (const uint8_t c : rgb.data()) EXPECT_EQ(c, 7);

  const InstanceImage ids(3, 3);  // value-initialised
  for (const uint16_t id : ids.data()) EXPECT_EQ(id, 0);
}

TEST(ImageTest, FillOverwritesEveryValue) {
  ImageRgb8 rgb(3, 2, 1);
  rgb.at(2, 1, 2) = 99;
  rgb.Fill(200);
  for (const uint8_t c : rgb.data()) EXPECT_EQ(c, 200);
}

TEST(ImageTest, RowMajorWithUAsColumn) {
  Image<int> image(4, 3);
  for (int v = 0; v < 3; ++v) {
    for (int u = 0; u < 4; ++u) image(u, v) = 10 * v + u;
  }
  // Rows of width 4, one after another: data[v * width + u].
  const int expected[] = {0, 1, 2, 3, 10, 11, 12, 13, 20, 21, 22, 23};
  ASSERT_EQ(image.data().size(), 12u);
  for (size_t i = 0; i < 12; ++i) EXPECT_EQ(image.data()[i], expected[i]) << "index " << i;
  // (u, v) = (3, 0) is the top-right pixel, (0, 2) the bottom-left one.
  EXPECT_EQ(image.at(3, 0), 3);
  EXPECT_EQ(image.at(0, 2), 20);
  image.data()[6] = -1;  // row 1, column 2
  EXPECT_EQ(image(2, 1), -1);
}

TEST(ImageTest, ChannelsAreInterleaved) {
  ImageRgb8 rgb(3, 2);
  rgb.at(1, 1, 0) = 10;  // R
  rgb.at(1, 1, 1) = 20;  // G
  rgb.at(1, 1, 2) = 30;  // B
  // Pixel (1, 1) starts at (1 * 3 + 1) * 3 = 12.
  EXPECT_EQ(rgb.data()[12], 10);
  EXPECT_EQ(rgb.data()[13], 20);
  EXPECT_EQ(rgb.data()[14], 30);
  const auto pixel = rgb.pixel(1, 1);
  EXPECT_EQ(pixel[0], 10);
  EXPECT_EQ(pixel[1], 20);
  EXPECT_EQ(pixel[2], 30);
  rgb.pixel(2, 0)[1] = 77;
  EXPECT_EQ(rgb.data()[(0 * 3 + 2) * 3 + 1], 77);
  const ImageRgb8& const_rgb = rgb;
  EXPECT_EQ(const_rgb(2, 0, 1), 77);
  EXPECT_EQ(const_rgb.pixel(1, 1)[2], 30);
}

TEST(ImageTest, Equality) {
  Image<uint16_t> a(3, 2, 5);
  Image<uint16_t> b(3, 2, 5);
  EXPECT_EQ(a, b);
  b.at(2, 1) = 6;
  EXPECT_NE(a, b);
  b.at(2, 1) = 5;
  EXPECT_EQ(a, b);
  // Same number of values, different shape.
  EXPECT_NE(Image<uint16_t>(3, 2, 5), Image<uint16_t>(2, 3, 5));
  EXPECT_NE(Image<uint16_t>(3, 2, 5), Image<uint16_t>(6, 1, 5));
  EXPECT_EQ(Image<uint16_t>(), Image<uint16_t>());
}

TEST(ImageTest, SameSizeAs) {
  const ImageRgb8 rgb(640, 480);
  const DepthImage depth(640, 480);
  const DepthImage small(320, 240);
  EXPECT_TRUE(rgb.SameSizeAs(depth));
  EXPECT_TRUE(depth.SameSizeAs(rgb));
  EXPECT_FALSE(rgb.SameSizeAs(small));
  EXPECT_TRUE(rgb.SameSizeAs(640, 480));
  EXPECT_FALSE(rgb.SameSizeAs(480, 640));
}

TEST(ImageTest, Contains) {
  const ClassImage image(4, 3);
  EXPECT_TRUE(image.Contains(0, 0));
  EXPECT_TRUE(image.Contains(3, 2));
  EXPECT_FALSE(image.Contains(4, 0));
  EXPECT_FALSE(image.Contains(0, 3));
  EXPECT_FALSE(image.Contains(-1, 0));
  EXPECT_FALSE(image.Contains(0, -1));
}

TEST(ImageTest, NegativeSizeThrowsWithTheSize) {
  try {
    const DepthImage image(-1, 3);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("width >= 0 && height >= 0"));
    EXPECT_THAT(e.what(), HasSubstr("width = -1, height = 3"));
  }
  EXPECT_THROW(ImageRgb8(2, -5), Error);
}

TEST(ImageTest, ZeroSizeIsAllowed) {
  const DepthImage image(0, 5);
  EXPECT_TRUE(image.empty());
  EXPECT_EQ(image.height(), 5);
  EXPECT_EQ(image.num_pixels(), 0u);
}

TEST(ImageTest, CheckedAccessThrowsOutOfBoundsInEveryBuild) {
  ImageRgb8 rgb(4, 3);
  try {
    (void)rgb.AtChecked(4, 0);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("u = 4, v = 0, c = 0, width_ = 4, height_ = 3"));
  }
  EXPECT_THROW((void)rgb.AtChecked(0, 3), Error);
  EXPECT_THROW((void)rgb.AtChecked(-1, 0), Error);
  EXPECT_THROW((void)rgb.AtChecked(0, 0, 3), Error);
  rgb.AtChecked(3, 2, 2) = 7;
  EXPECT_EQ(rgb.at(3, 2, 2), 7);
}

#ifndef NDEBUG
// Unchecked at()/pixel() are also bounds-checked in builds without NDEBUG (compiled only there).
TEST(ImageTest, UncheckedAccessIsCheckedInDebugBuilds) {
  ImageRgb8 rgb(4, 3);
  EXPECT_THROW((void)rgb.at(4, 0), Error);
  EXPECT_THROW((void)rgb.pixel(0, -1), Error);
  EXPECT_NO_THROW((void)rgb.at(3, 2, 2));
}
#endif

TEST(ImageTest, IsValidDepth) {
  EXPECT_TRUE(IsValidDepth(0.5f));
  EXPECT_TRUE(IsValidDepth(1e-6f));
  EXPECT_TRUE(IsValidDepth(100.0f));
  EXPECT_FALSE(IsValidDepth(0.0f));
  EXPECT_FALSE(IsValidDepth(-0.0f));
  EXPECT_FALSE(IsValidDepth(-1.0f));
  EXPECT_FALSE(IsValidDepth(std::numeric_limits<float>::quiet_NaN()));
  EXPECT_FALSE(IsValidDepth(std::numeric_limits<float>::infinity()));
}

}  // namespace
}  // namespace avp

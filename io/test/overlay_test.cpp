#include <array>
#include <cstdint>
#include <string>

#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/io/overlay.h>

namespace avp::io {
namespace {

constexpr uint8_t kGrey = 40;

InstanceMask Instance(int w, int h, int u0, int v0, int u1, int v1, std::string label,
                      float confidence) {
  InstanceMask inst;
  inst.mask = MaskImage(w, h);
  for (int v = v0; v <= v1; ++v) {
    for (int u = u0; u <= u1; ++u) inst.mask.at(u, v) = 255;
  }
  inst.label = std::move(label);
  inst.confidence = confidence;
  return inst;
}

std::array<uint8_t, 3> Pixel(const ImageRgb8& image, int u, int v) {
  return {image.at(u, v, 0), image.at(u, v, 1), image.at(u, v, 2)};
}

const std::array<uint8_t, 3> kGreyPixel = {kGrey, kGrey, kGrey};

TEST(OverlayTest, BlendsMaskedPixelsOutlinesAndLeavesOthers) {
  const ImageRgb8 image(120, 100, kGrey);
  Segmentation seg{120, 100, {Instance(120, 100, 40, 50, 79, 89, "tomato", 0.87f)}, {}};
  const ImageRgb8 out = DrawSegmentationOverlay(image, seg);
  const std::array<uint8_t, 3> color = PreferredOverlayColor("tomato");
  ASSERT_EQ(OverlayColors(seg), (std::vector<std::array<uint8_t, 3>>{color}));
  // Inside: each channel (40 + colour + 1) / 2.
  const std::array<uint8_t, 3> blended = {static_cast<uint8_t>((kGrey + color[0] + 1) / 2),
                                          static_cast<uint8_t>((kGrey + color[1] + 1) / 2),
                                          static_cast<uint8_t>((kGrey + color[2] + 1) / 2)};
  EXPECT_EQ(Pixel(out, 60, 70), blended);
  EXPECT_EQ(Pixel(out, 41, 88), blended);
  // The outline is the mask's boundary pixels in full colour.
  EXPECT_EQ(Pixel(out, 40, 70), color);
  EXPECT_EQ(Pixel(out, 79, 89), color);
  EXPECT_EQ(Pixel(out, 60, 89), color);
  // Away from the mask and its tag (drawn above (40, 50)) nothing changes.
  for (const auto& [u, v] :
       {std::pair{5, 5}, std::pair{115, 5}, std::pair{5, 95}, std::pair{115, 95}, std::pair{39, 70},
        std::pair{80, 70}, std::pair{60, 90}, std::pair{100, 60}}) {
    EXPECT_EQ(Pixel(out, u, v), kGreyPixel) << u << "," << v;
  }
  // The tag changed something just above the mask's top-left corner.
  bool tag = false;
  for (int v = 30; v < 50; ++v) {
    for (int u = 40; u < 60; ++u) tag = tag || Pixel(out, u, v) != kGreyPixel;
  }
  EXPECT_TRUE(tag);
  // Deterministic.
  EXPECT_EQ(DrawSegmentationOverlay(image, seg), out);
  // The input is untouched.
  EXPECT_EQ(image, ImageRgb8(120, 100, kGrey));
}

TEST(OverlayTest, DrawsTheBoxOnItsPixels) {
  const ImageRgb8 image(120, 100, kGrey);
  InstanceMask inst = Instance(120, 100, 0, 0, -1, -1, "leaf", 0.5f);  // empty mask
  inst.box = PixelBox{10, 40, 30, 60};
  Segmentation seg{120, 100, {inst}, {}};
  const ImageRgb8 out = DrawSegmentationOverlay(image, seg);
  const std::array<uint8_t, 3> color = PreferredOverlayColor("leaf");
  EXPECT_EQ(Pixel(out, 10, 55), color);       // left edge: column round(x0) = 10
  EXPECT_EQ(Pixel(out, 29, 55), color);       // right edge: column round(x1) − 1 = 29
  EXPECT_EQ(Pixel(out, 20, 59), color);       // bottom edge: row 59
  EXPECT_EQ(Pixel(out, 20, 55), kGreyPixel);  // inside an empty mask
  EXPECT_EQ(Pixel(out, 30, 55), kGreyPixel);
  EXPECT_EQ(Pixel(out, 20, 60), kGreyPixel);
  EXPECT_EQ(Pixel(out, 100, 90), kGreyPixel);
}

TEST(OverlayTest, ColoursPerLabelAreDeterministicAndDistinct) {
  EXPECT_EQ(PreferredOverlayColor("tomato"), PreferredOverlayColor("tomato"));
  InstanceMask fruit;
  fruit.semantic_class = SemanticClass::kFruit;
  EXPECT_EQ(OverlayKey(fruit), "fruit");
  fruit.label = "apple";
  EXPECT_EQ(OverlayKey(fruit), "apple");

  // A label whose preferred colour collides with "tomato" still gets another colour.
  std::string clash;
  for (int i = 0; i < 1000 && clash.empty(); ++i) {
    const std::string key = "label" + std::to_string(i);
    if (PreferredOverlayColor(key) == PreferredOverlayColor("tomato")) clash = key;
  }
  ASSERT_FALSE(clash.empty());
  Segmentation seg{
      8,
      8,
      {Instance(8, 8, 0, 0, 1, 1, "tomato", 0.9f), Instance(8, 8, 2, 2, 3, 3, clash, 0.8f),
       Instance(8, 8, 4, 4, 5, 5, "tomato", 0.7f)},
      {}};
  const auto colors = OverlayColors(seg);
  ASSERT_EQ(colors.size(), 3u);
  EXPECT_EQ(colors[0], colors[2]);
  EXPECT_NE(colors[0], colors[1]);
}

TEST(OverlayTest, RejectsMismatchedSizes) {
  const ImageRgb8 image(10, 10);
  Segmentation wrong_seg{10, 11, {}, {}};
  EXPECT_THROW(DrawSegmentationOverlay(image, wrong_seg), avp::Error);
  Segmentation wrong_mask{10, 10, {Instance(9, 10, 0, 0, 1, 1, "x", 1.f)}, {}};
  EXPECT_THROW(DrawSegmentationOverlay(image, wrong_mask), avp::Error);
}

}  // namespace
}  // namespace avp::io

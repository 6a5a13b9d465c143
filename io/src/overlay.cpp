#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <avp/core/error.h>
#include <avp/core/semantic_class.h>
#include <avp/io/overlay.h>

namespace avp::io {

namespace {

// Twenty well-separated colours (R, G, B).
constexpr std::array<std::array<uint8_t, 3>, 20> kPalette = {{
    {230, 25, 75},   {60, 180, 75},   {255, 225, 25},  {0, 130, 200},   {245, 130, 48},
    {145, 30, 180},  {70, 240, 240},  {240, 50, 230},  {210, 245, 60},  {250, 190, 212},
    {0, 128, 128},   {220, 190, 255}, {170, 110, 40},  {255, 250, 200}, {128, 0, 0},
    {170, 255, 195}, {128, 128, 0},   {255, 215, 180}, {0, 0, 128},     {255, 255, 255},
}};

size_t PreferredIndex(std::string_view key) {
  uint32_t h = 2166136261u;
  for (const char c : key) {
    h ^= static_cast<uint8_t>(c);
    h *= 16777619u;
  }
  return h % kPalette.size();
}

cv::Scalar ToScalar(const std::array<uint8_t, 3>& c) { return cv::Scalar(c[0], c[1], c[2]); }

int RoundToInt(float v) { return static_cast<int>(std::lround(v)); }

}  // namespace

std::string OverlayKey(const InstanceMask& instance) {
  return instance.label.empty() ? std::string(ToString(instance.semantic_class)) : instance.label;
}

std::array<uint8_t, 3> PreferredOverlayColor(std::string_view key) {
  return kPalette[PreferredIndex(key)];
}

std::vector<std::array<uint8_t, 3>> OverlayColors(const Segmentation& seg) {
  std::set<std::string> keys;
  for (const InstanceMask& inst : seg.instances) keys.insert(OverlayKey(inst));
  std::map<std::string, size_t> assigned;
  std::vector<bool> taken(kPalette.size(), false);
  size_t num_taken = 0;
  for (const std::string& key : keys) {
    size_t index = PreferredIndex(key);
    if (num_taken < kPalette.size()) {
      while (taken[index]) index = (index + 1) % kPalette.size();
      taken[index] = true;
      ++num_taken;
    }
    assigned[key] = index;
  }
  std::vector<std::array<uint8_t, 3>> colors;
  colors.reserve(seg.instances.size());
  for (const InstanceMask& inst : seg.instances)
    colors.push_back(kPalette[assigned[OverlayKey(inst)]]);
  return colors;
}

ImageRgb8 DrawSegmentationOverlay(const ImageRgb8& image, const Segmentation& seg) {
  AVP_THROW_UNLESS(seg.width == image.width() && seg.height == image.height(), seg.width,
                   seg.height, image.width(), image.height());
  for (size_t i = 0; i < seg.instances.size(); ++i) {
    const MaskImage& m = seg.instances[i].mask;
    AVP_THROW_UNLESS(m.SameSizeAs(image), i, m.width(), m.height(), image.width(), image.height());
  }
  ImageRgb8 out = image;
  if (out.empty()) return out;
  const std::vector<std::array<uint8_t, 3>> colors = OverlayColors(seg);

  // 1. Blend every mask.
  for (size_t i = 0; i < seg.instances.size(); ++i) {
    const MaskImage& m = seg.instances[i].mask;
    for (int v = 0; v < out.height(); ++v) {
      for (int u = 0; u < out.width(); ++u) {
        if (m.at(u, v) == 0) continue;
        for (int c = 0; c < 3; ++c) {
          out.at(u, v, c) = static_cast<uint8_t>((out.at(u, v, c) + colors[i][c] + 1) / 2);
        }
      }
    }
  }

  cv::Mat canvas(out.height(), out.width(), CV_8UC3, out.data().data());
  std::vector<cv::Point> anchors(seg.instances.size(), cv::Point(-1, -1));
  // 2. Outlines and boxes.
  for (size_t i = 0; i < seg.instances.size(); ++i) {
    const InstanceMask& inst = seg.instances[i];
    cv::Mat binary(out.height(), out.width(), CV_8UC1);
    for (int v = 0; v < out.height(); ++v) {
      uint8_t* row = binary.ptr<uint8_t>(v);
      for (int u = 0; u < out.width(); ++u) row[u] = inst.mask.at(u, v) != 0 ? 1 : 0;
    }
    const cv::Rect bounds = cv::boundingRect(binary);
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(binary, contours, cv::RETR_LIST, cv::CHAIN_APPROX_NONE);
    cv::drawContours(canvas, contours, -1, ToScalar(colors[i]), 1, cv::LINE_8);
    if (inst.box) {
      const cv::Point p0(RoundToInt(inst.box->x0), RoundToInt(inst.box->y0));
      const cv::Point p1(RoundToInt(inst.box->x1) - 1, RoundToInt(inst.box->y1) - 1);
      if (p1.x >= p0.x && p1.y >= p0.y) {
        cv::rectangle(canvas, p0, p1, ToScalar(colors[i]), 1, cv::LINE_8);
      }
      anchors[i] = p0;
    } else if (bounds.area() > 0) {
      anchors[i] = bounds.tl();
    }
  }

  // 3. Tags, on top of everything.
  constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;
  constexpr double kFontScale = 0.4;
  for (size_t i = 0; i < seg.instances.size(); ++i) {
    if (anchors[i].x < 0) continue;
    const InstanceMask& inst = seg.instances[i];
    const std::string text = fmt::format("{} {:.2f}", OverlayKey(inst), inst.confidence);
    int baseline = 0;
    const cv::Size size = cv::getTextSize(text, kFont, kFontScale, 1, &baseline);
    const int patch_h = size.height + baseline + 2;
    const int x = anchors[i].x;
    const int top = anchors[i].y >= patch_h ? anchors[i].y - patch_h : anchors[i].y;
    cv::rectangle(canvas, cv::Rect(x, top, size.width + 2, patch_h), ToScalar(colors[i]),
                  cv::FILLED);
    const auto& c = colors[i];
    const bool dark_text = 299 * c[0] + 587 * c[1] + 114 * c[2] > 128000;
    cv::putText(canvas, text, cv::Point(x + 1, top + 1 + size.height), kFont, kFontScale,
                dark_text ? cv::Scalar(0, 0, 0) : cv::Scalar(255, 255, 255), 1, cv::LINE_8);
  }
  return out;
}

}  // namespace avp::io

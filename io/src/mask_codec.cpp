#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <avp/io/image_limits.h>
#include <avp/io/mask_codec.h>

namespace avp::io {

std::vector<uint32_t> MaskToRle(const MaskImage& mask) {
  std::vector<uint32_t> counts;
  bool current = false;  // runs start with background
  uint32_t run = 0;
  for (int u = 0; u < mask.width(); ++u) {
    for (int v = 0; v < mask.height(); ++v) {
      const bool fg = mask.at(u, v) != 0;
      if (fg != current) {
        counts.push_back(run);
        run = 0;
        current = fg;
      }
      ++run;
    }
  }
  counts.push_back(run);
  return counts;
}

Result<MaskImage> RleToMask(std::span<const uint32_t> counts, int width, int height) {
  if (width < 0 || height < 0) {
    return InvalidArgumentError(
        fmt::format("RLE mask size {} x {} must not be negative", width, height));
  }
  const uint64_t pixels = static_cast<uint64_t>(width) * static_cast<uint64_t>(height);
  // The size is checked before the mask is allocated.
  AVP_RETURN_IF_ERROR(
      MaxImagePixels().Check(fmt::format("RLE mask of {} x {} pixels", width, height), pixels));
  uint64_t sum = 0;
  for (const uint32_t c : counts) sum += c;
  if (sum != pixels) {
    return InvalidArgumentError(
        fmt::format("RLE counts ({} runs) sum to {}, expected {} x {} = {} pixels", counts.size(),
                    sum, width, height, pixels));
  }
  MaskImage mask(width, height);
  uint64_t index = 0;  // column-major pixel index
  bool fg = false;
  for (const uint32_t c : counts) {
    if (fg) {
      for (uint64_t i = index; i < index + c; ++i) {
        mask.at(static_cast<int>(i / height), static_cast<int>(i % height)) = 255;
      }
    }
    index += c;
    fg = !fg;
  }
  return mask;
}

std::vector<std::vector<std::array<int, 2>>> MaskToPolygons(const MaskImage& mask) {
  std::vector<std::vector<std::array<int, 2>>> polygons;
  if (mask.empty()) return polygons;
  cv::Mat binary(mask.height(), mask.width(), CV_8UC1);
  for (int v = 0; v < mask.height(); ++v) {
    uint8_t* row = binary.ptr<uint8_t>(v);
    for (int u = 0; u < mask.width(); ++u) row[u] = mask.at(u, v) != 0 ? 1 : 0;
  }
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(binary, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  for (const auto& contour : contours) {
    std::vector<std::array<int, 2>> polygon;
    polygon.reserve(contour.size());
    for (const cv::Point& p : contour) polygon.push_back({p.x, p.y});
    polygons.push_back(std::move(polygon));
  }
  std::sort(polygons.begin(), polygons.end(), [](const auto& a, const auto& b) {
    return std::array{a[0][1], a[0][0]} < std::array{b[0][1], b[0][0]};
  });
  return polygons;
}

}  // namespace avp::io

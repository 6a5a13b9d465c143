#include "letterbox.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <avp/core/error.h>

namespace avp::zsl {

namespace {

// Python 3 round(): to nearest, exact halves to even.
double RoundHalfEven(double x) {
  if (std::abs(x - std::trunc(x)) == 0.5) return 2.0 * std::round(x / 2.0);
  return std::round(x);
}

float Clip(double v, double hi) { return static_cast<float>(std::clamp(v, 0.0, hi)); }

}  // namespace

Letterbox Letterbox::Compute(int src_w, int src_h, int dst_w, int dst_h) {
  AVP_THROW_UNLESS(src_w > 0 && src_h > 0 && dst_w > 0 && dst_h > 0, src_w, src_h, dst_w, dst_h);
  Letterbox lb;
  lb.src_w = src_w;
  lb.src_h = src_h;
  lb.dst_w = dst_w;
  lb.dst_h = dst_h;
  lb.scale = std::min(static_cast<double>(dst_h) / src_h, static_cast<double>(dst_w) / src_w);
  // An extreme aspect ratio could round a side to 0 (where the reference fails); keep one pixel.
  lb.resized_w = std::clamp(static_cast<int>(RoundHalfEven(src_w * lb.scale)), 1, dst_w);
  lb.resized_h = std::clamp(static_cast<int>(RoundHalfEven(src_h * lb.scale)), 1, dst_h);
  const double half_w = (dst_w - lb.resized_w) / 2.0;
  const double half_h = (dst_h - lb.resized_h) / 2.0;
  lb.pad_left = static_cast<int>(RoundHalfEven(half_w - 0.1));
  lb.pad_right = static_cast<int>(RoundHalfEven(half_w + 0.1));
  lb.pad_top = static_cast<int>(RoundHalfEven(half_h - 0.1));
  lb.pad_bottom = static_cast<int>(RoundHalfEven(half_h + 0.1));
  return lb;
}

PixelBox Letterbox::ToSource(const PixelBox& b) const {
  return {Clip((b.x0 - pad_left) / scale, src_w), Clip((b.y0 - pad_top) / scale, src_h),
          Clip((b.x1 - pad_left) / scale, src_w), Clip((b.y1 - pad_top) / scale, src_h)};
}

PixelBox Letterbox::ToLetterboxed(const PixelBox& b) const {
  return {static_cast<float>(b.x0 * scale + pad_left), static_cast<float>(b.y0 * scale + pad_top),
          static_cast<float>(b.x1 * scale + pad_left), static_cast<float>(b.y1 * scale + pad_top)};
}

std::vector<float> LetterboxTensor(const ImageRgb8& rgb, const Letterbox& lb, float pad_value,
                                   float value_scale) {
  AVP_THROW_UNLESS(rgb.width() == lb.src_w && rgb.height() == lb.src_h, rgb.width(), rgb.height(),
                   lb.src_w, lb.src_h);
  // cv::Mat only reads through this header.
  const cv::Mat src(rgb.height(), rgb.width(), CV_8UC3, const_cast<uint8_t*>(rgb.data().data()));
  cv::Mat resized = src;
  if (lb.resized_w != rgb.width() || lb.resized_h != rgb.height()) {
    cv::resize(src, resized, cv::Size(lb.resized_w, lb.resized_h), 0, 0, cv::INTER_LINEAR);
  }
  const size_t plane = static_cast<size_t>(lb.dst_w) * lb.dst_h;
  std::vector<float> out(3 * plane, pad_value * value_scale);
  for (int y = 0; y < lb.resized_h; ++y) {
    const uint8_t* row = resized.ptr<uint8_t>(y);
    const size_t offset = static_cast<size_t>(y + lb.pad_top) * lb.dst_w + lb.pad_left;
    for (int x = 0; x < lb.resized_w; ++x) {
      for (int c = 0; c < 3; ++c) {
        out[c * plane + offset + x] = static_cast<float>(row[3 * x + c]) * value_scale;
      }
    }
  }
  return out;
}

}  // namespace avp::zsl

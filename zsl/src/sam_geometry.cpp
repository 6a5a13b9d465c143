#include "sam_geometry.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <avp/core/error.h>

namespace avp::zsl {

namespace {

constexpr std::array<float, 3> kMean = {123.675f, 116.28f, 103.53f};
constexpr std::array<float, 3> kStd = {58.395f, 57.12f, 57.375f};

// The reference get_preprocess_shape: int(x·scale + 0.5) (x·scale >= 0, so int() is floor).
int PreprocessSize(int x, double scale, int long_side) {
  return std::clamp(static_cast<int>(x * scale + 0.5), 1, long_side);
}

}  // namespace

SamTransform SamTransform::Compute(int src_w, int src_h, int encoder_size, int prompt_frame) {
  AVP_THROW_UNLESS(src_w > 0 && src_h > 0 && encoder_size > 0 && prompt_frame > 0, src_w, src_h,
                   encoder_size, prompt_frame);
  SamTransform t;
  t.src_w = src_w;
  t.src_h = src_h;
  const double long_side = std::max(src_w, src_h);
  t.encoder_size = encoder_size;
  t.encoder_scale = encoder_size / long_side;
  t.encoder_resized_w = PreprocessSize(src_w, t.encoder_scale, encoder_size);
  t.encoder_resized_h = PreprocessSize(src_h, t.encoder_scale, encoder_size);
  t.prompt_frame = prompt_frame;
  t.prompt_scale = prompt_frame / long_side;
  t.prompt_resized_w = PreprocessSize(src_w, t.prompt_scale, prompt_frame);
  t.prompt_resized_h = PreprocessSize(src_h, t.prompt_scale, prompt_frame);
  return t;
}

std::vector<float> SamEncoderTensor(const ImageRgb8& rgb, const SamTransform& t) {
  AVP_THROW_UNLESS(rgb.width() == t.src_w && rgb.height() == t.src_h, rgb.width(), rgb.height(),
                   t.src_w, t.src_h);
  const cv::Mat src(rgb.height(), rgb.width(), CV_8UC3, const_cast<uint8_t*>(rgb.data().data()));
  cv::Mat resized = src;
  if (t.encoder_resized_w != rgb.width() || t.encoder_resized_h != rgb.height()) {
    cv::resize(src, resized, cv::Size(t.encoder_resized_w, t.encoder_resized_h), 0, 0,
               cv::INTER_LINEAR);
  }
  const int s = t.encoder_size;
  const size_t plane = static_cast<size_t>(s) * s;
  std::vector<float> out(3 * plane, 0.f);
  for (int y = 0; y < t.encoder_resized_h; ++y) {
    const uint8_t* row = resized.ptr<uint8_t>(y);
    for (int x = 0; x < t.encoder_resized_w; ++x) {
      for (int c = 0; c < 3; ++c) {
        out[c * plane + static_cast<size_t>(y) * s + x] =
            (static_cast<float>(row[3 * x + c]) - kMean[c]) / kStd[c];
      }
    }
  }
  return out;
}

std::array<float, 4> SamBoxPromptCoords(const PixelBox& box, const SamTransform& t) {
  const double sx = static_cast<double>(t.prompt_resized_w) / t.src_w;
  const double sy = static_cast<double>(t.prompt_resized_h) / t.src_h;
  return {static_cast<float>(box.x0 * sx), static_cast<float>(box.y0 * sy),
          static_cast<float>(box.x1 * sx), static_cast<float>(box.y1 * sy)};
}

MaskImage SamLowResLogitsToMask(std::span<const float> logits, int low_res, const SamTransform& t,
                                float threshold) {
  AVP_THROW_UNLESS(low_res > 0 && logits.size() == static_cast<size_t>(low_res) * low_res, low_res,
                   logits.size());
  const cv::Mat low(low_res, low_res, CV_32F, const_cast<float*>(logits.data()));
  cv::Mat frame;
  cv::resize(low, frame, cv::Size(t.prompt_frame, t.prompt_frame), 0, 0, cv::INTER_LINEAR);
  const cv::Mat cropped = frame(cv::Rect(0, 0, t.prompt_resized_w, t.prompt_resized_h));
  cv::Mat full;
  cv::resize(cropped, full, cv::Size(t.src_w, t.src_h), 0, 0, cv::INTER_LINEAR);
  MaskImage mask(t.src_w, t.src_h);
  for (int v = 0; v < t.src_h; ++v) {
    const float* row = full.ptr<float>(v);
    for (int u = 0; u < t.src_w; ++u) mask.at(u, v) = row[u] > threshold ? 255 : 0;
  }
  return mask;
}

}  // namespace avp::zsl

#include "detections.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <numeric>
#include <vector>

#include <fmt/format.h>

namespace avp::zsl {

float Sigmoid(float x) {
  if (x >= 0.f) return 1.f / (1.f + std::exp(-x));
  const float e = std::exp(x);
  return e / (1.f + e);
}

float BoxIou(const PixelBox& a, const PixelBox& b) {
  const float iw = std::min(a.x1, b.x1) - std::max(a.x0, b.x0);
  const float ih = std::min(a.y1, b.y1) - std::max(a.y0, b.y0);
  const float inter = (iw > 0.f && ih > 0.f) ? iw * ih : 0.f;
  const float area_a = std::max(a.x1 - a.x0, 0.f) * std::max(a.y1 - a.y0, 0.f);
  const float area_b = std::max(b.x1 - b.x0, 0.f) * std::max(b.y1 - b.y0, 0.f);
  const float uni = area_a + area_b - inter;
  return uni > 0.f ? inter / uni : 0.f;
}

Result<std::vector<Detection>> DecodeYoloHead(std::span<const float> output, int num_class_slots,
                                              int num_anchors, HeadLayout layout,
                                              ScoreActivation activation, float score_threshold,
                                              int num_active_classes) {
  if (num_class_slots < 1 || num_anchors < 0) {
    return InvalidArgumentError(
        fmt::format("YOLO head: num_class_slots ({}) must be >= 1 and num_anchors ({}) >= 0",
                    num_class_slots, num_anchors));
  }
  if (num_active_classes < 0 || num_active_classes > num_class_slots) {
    return InvalidArgumentError(
        fmt::format("YOLO head: num_active_classes ({}) must be in [0, num_class_slots ({})]",
                    num_active_classes, num_class_slots));
  }
  const size_t attrs = 4 + static_cast<size_t>(num_class_slots);
  const size_t anchors = static_cast<size_t>(num_anchors);
  if (output.size() != attrs * anchors) {
    return InvalidArgumentError(fmt::format(
        "YOLO head output has {} values, expected (4 + {} class slots) x {} anchors = {}",
        output.size(), num_class_slots, num_anchors, attrs * anchors));
  }
  // Element k (0..3 box, 4.. scores) of anchor a.
  const auto at = [&](size_t k, size_t a) {
    return layout == HeadLayout::kAttributesFirst ? output[k * anchors + a] : output[a * attrs + k];
  };
  std::vector<Detection> out;
  if (num_active_classes == 0) return out;
  for (size_t a = 0; a < anchors; ++a) {
    int best = 0;
    float best_raw = at(4, a);
    for (int c = 1; c < num_active_classes; ++c) {
      const float s = at(4 + static_cast<size_t>(c), a);
      if (s > best_raw || (std::isnan(best_raw) && !std::isnan(s))) {
        best_raw = s;
        best = c;
      }
    }
    const float score = activation == ScoreActivation::kSigmoid ? Sigmoid(best_raw) : best_raw;
    if (!(score > score_threshold)) continue;
    const float cx = at(0, a), cy = at(1, a), hw = at(2, a) / 2.f, hh = at(3, a) / 2.f;
    out.push_back({PixelBox{cx - hw, cy - hh, cx + hw, cy + hh}, score, best});
  }
  return out;
}

std::vector<Detection> NonMaxSuppression(std::vector<Detection> detections, float iou_threshold,
                                         bool class_agnostic, size_t max_detections) {
  std::erase_if(detections, [](const Detection& d) { return std::isnan(d.score); });
  std::vector<size_t> order(detections.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return detections[a].score > detections[b].score; });
  std::vector<Detection> kept;
  for (const size_t i : order) {
    if (kept.size() >= max_detections) break;
    const Detection& d = detections[i];
    const bool suppressed = std::any_of(kept.begin(), kept.end(), [&](const Detection& k) {
      return (class_agnostic || k.class_index == d.class_index) &&
             BoxIou(k.box, d.box) > iou_threshold;
    });
    if (!suppressed) kept.push_back(d);
  }
  return kept;
}

std::vector<Detection> DetectionsToSource(std::vector<Detection> detections, const Letterbox& lb) {
  for (Detection& d : detections) d.box = lb.ToSource(d.box);
  return detections;
}

PixelBox NormalizedCxcywhToPixels(float cx, float cy, float w, float h, int image_w, int image_h) {
  const auto clip = [](double v, int hi) {
    return static_cast<float>(std::clamp(v, 0.0, static_cast<double>(std::max(hi, 0))));
  };
  const double hw = w / 2.0, hh = h / 2.0;
  return {clip((cx - hw) * image_w, image_w), clip((cy - hh) * image_h, image_h),
          clip((cx + hw) * image_w, image_w), clip((cy + hh) * image_h, image_h)};
}

}  // namespace avp::zsl

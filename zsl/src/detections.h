#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <cstddef>
#include <span>
#include <vector>

#include <avp/core/segmentation.h>
#include <avp/core/status.h>

#include "letterbox.h"

namespace avp::zsl {

/// One detector box: continuous pixel coordinates (letterboxed or source, as the producer says),
/// its score and the index of its class among the active prompt classes.
struct Detection {
  PixelBox box;
  float score = 0;
  int class_index = -1;
};

/// How a YOLO head output of 4 + N attributes per anchor is laid out in memory.
enum class HeadLayout {
  kAttributesFirst,  ///< [4+N, A]: the Ultralytics `output0` [1, 4+N, 8400]
  kAnchorsFirst,     ///< [A, 4+N]: a transposed export [1, 8400, 4+N]
};

/// What to apply to the raw class scores of a head (the manifest's `score_activation`).
enum class ScoreActivation {
  kNone,     ///< scores are already probabilities (the stock Ultralytics head)
  kSigmoid,  ///< scores are logits
};

/// The logistic function 1 / (1 + e^−x), computed without overflow for any finite x (and
/// Sigmoid(±inf) = 1 or 0).
float Sigmoid(float x);

/// Intersection over union of two boxes in continuous coordinates. A box with x1 <= x0 or
/// y1 <= y0 has no area; the IoU is 0 when the union is empty.
float BoxIou(const PixelBox& a, const PixelBox& b);

/// Decodes a YOLO head (design/zero-shot-models.md §4.1): attributes 0–3 of every anchor are
/// cx, cy, w, h in letterboxed pixels, attributes 4 .. 4+num_class_slots−1 its class scores.
/// Per anchor, the best score over the first `num_active_classes` slots (unused slots — zeroed
/// txt_feats rows of a fixed-N_max export — are ignored) is taken, after `activation`, and the
/// anchor is kept when that score is > score_threshold (strictly, like Ultralytics). The best
/// class is chosen on the raw scores, the first slot on ties, so a saturated sigmoid cannot move
/// it. Boxes become x0 = cx − w/2, y0 = cy − h/2, x1 = cx + w/2, y1 = cy + h/2, still letterboxed
/// (use DetectionsToSource after NMS). Detections come in anchor order.
/// @return InvalidArgument when output.size() != (4 + num_class_slots)·num_anchors (the message
///   names both sizes), when num_class_slots < 1 or num_anchors < 0, or when num_active_classes
///   is outside [0, num_class_slots].
Result<std::vector<Detection>> DecodeYoloHead(std::span<const float> output, int num_class_slots,
                                              int num_anchors, HeadLayout layout,
                                              ScoreActivation activation, float score_threshold,
                                              int num_active_classes);

/// Greedy non-maximum suppression: visits detections by descending score (ties in input order,
/// so the result is deterministic) and keeps one unless a kept detection — of any class when
/// `class_agnostic`, else of the same class_index — overlaps it with BoxIou > iou_threshold.
/// Stops after `max_detections` kept. Per-class suppression gives the same result as OpenCV's
/// NMSBoxes on class-offset boxes (design §4.1) without the offsets. Detections with a NaN
/// score are dropped. Returns the kept detections by descending score; empty input → empty.
std::vector<Detection> NonMaxSuppression(std::vector<Detection> detections, float iou_threshold,
                                         bool class_agnostic, size_t max_detections = 300);

/// Maps letterboxed detections to source pixels with Letterbox::ToSource (subtract the pad,
/// divide by the scale, clip). Scores and classes are unchanged; boxes clipped to nothing are
/// kept (with zero width or height).
std::vector<Detection> DetectionsToSource(std::vector<Detection> detections, const Letterbox& lb);

/// True when a box in source pixels has no area: it was clipped to nothing (a YOLO box entirely in
/// the letterbox padding, a Grounding DINO box outside the image). Both backends drop such boxes
/// before their max_detections cut.
inline bool ClipsToNothing(const PixelBox& box) { return !(box.x1 > box.x0 && box.y1 > box.y0); }

/// A Grounding DINO box (normalised cx, cy, w, h in [0, 1] of the image, design §4.4) in pixels
/// of an image_w x image_h image: x0 = (cx − w/2)·image_w, ..., clipped to [0, image_w] x
/// [0, image_h].
PixelBox NormalizedCxcywhToPixels(float cx, float cy, float w, float h, int image_w, int image_h);

}  // namespace avp::zsl

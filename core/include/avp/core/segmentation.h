#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <avp/core/image.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>

namespace avp {

/// A binary mask: nonzero pixels belong to the instance.
using MaskImage = Image<uint8_t, 1>;

/// An axis-aligned box in pixel coordinates: x0 <= x < x1, y0 <= y < y1 (continuous, so a box
/// covering pixel columns 0..9 is [0, 10)).
struct PixelBox {
  float x0 = 0.0f;
  float y0 = 0.0f;
  float x1 = 0.0f;
  float y1 = 0.0f;
  friend bool operator==(const PixelBox&, const PixelBox&) = default;
};

/// One segmented instance in an image: its pixels, class and (calibrated) confidence.
struct InstanceMask {
  MaskImage mask;
  SemanticClass semantic_class = SemanticClass::kFruit;
  /// Calibrated score in [0, 1] (the probability that the mask is of `semantic_class`).
  float confidence = 1.0f;
  /// The phrase that produced it (e.g. the prompt "tomato"); informative only.
  std::string label;
  /// The detector's box, when the instance came from a detector (network backends).
  std::optional<PixelBox> box;
  /// The mask head's own quality estimate (SAM's predicted IoU), or a negative value if none.
  float mask_score = -1.0f;
};

/// Wall time of one stage of a segmenter (e.g. "detector", "sam_encoder"), in milliseconds.
struct StageTiming {
  std::string stage;
  double ms = 0.0;
};

/// What a segmenter returns for one image: any number of possibly overlapping instance masks, all
/// of size width x height. Pixels in no mask carry no semantic evidence of their own.
struct Segmentation {
  int width = 0;
  int height = 0;
  std::vector<InstanceMask> instances;
  /// Per-stage timings of the segmenter that produced it, in execution order (may be empty).
  std::vector<StageTiming> timings;

  /// Every mask is width x height, every confidence finite and in [0, 1]; the error names the
  /// first bad instance and value.
  Status Validate() const;
  /// Validate() plus the size must match an image of width x height.
  Status ValidateFor(int image_width, int image_height) const;

  /// One mask per nonzero instance id of a simulator's label images, with that id's majority
  /// class and the given confidence, ordered by instance id. Ids whose majority class is not in
  /// `keep_classes` are skipped (by default only fruit is kept, as a fruit prompt would).
  static Segmentation FromLabelImages(const InstanceImage& instance_ids,
                                      const ClassImage& class_ids, float confidence = 1.0f,
                                      const std::vector<SemanticClass>& keep_classes = {
                                          SemanticClass::kFruit});
};

}  // namespace avp

#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/camera.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation/segmenter_registry.h>

namespace avp::segmentation {

/// The zero-shot-like error model of OracleSegmenter (docs/segmentation.md). Each part can be
/// switched off by its parameters; OracleOptions::Perfect() switches all of them off.
struct OracleOptions {
  // ---- Prompt --------------------------------------------------------------------------------
  /// Words that make a phrase target SemanticClass::kFruit, lower case. A phrase targets fruit
  /// when its last word (case-insensitive, or that word's singular: "tomatoes" -> "tomato") is in
  /// this list, so "tomato", "Ripe Tomatoes" and "green apple" do and "leaf" does not.
  std::vector<std::string> fruit_words = {"tomato", "apple",  "fruit",   "strawberry", "pepper",
                                          "cherry", "grape",  "plum",    "peach",      "pear",
                                          "orange", "lemon",  "lime",    "cucumber",   "berry",
                                          "melon",  "squash", "eggplant"};

  // ---- Detection: p_det(v) = p_max * smoothstep(v_min, v_full, v) ------------------------------
  /// Detection probability of a fully visible fruit, in [0, 1].
  double p_max = 0.97;
  /// Visible fraction at and below which a fruit is never detected, in [0, v_full].
  double v_min = 0.05;
  /// Visible fraction from which a fruit is detected with p_max, in [v_min, 1]. v_min == v_full
  /// makes p_det a step: p_max for v >= v_min, else 0.
  double v_full = 0.5;
  /// Fruits with fewer visible pixels are never detected (>= 1).
  int min_pixels = 20;

  // ---- Confidence: clamp(N(mean_at_0 + gain * v, stddev), min, max) ---------------------------
  double confidence_mean_at_0 = 0.55;  ///< mean score of a fruit seen at v = 0 (finite)
  double confidence_gain = 0.35;       ///< mean rises by this from v = 0 to v = 1 (finite)
  double confidence_stddev = 0.08;     ///< spread of the score, >= 0 (0: the mean exactly)
  double confidence_min = 0.05;        ///< clamp, 0 <= min <= max <= 1
  double confidence_max = 0.99;

  // ---- Boundary: per instance a radius boundary_offset_px + uniform in [-max, +max] ------------
  /// Negative radii erode the mask, positive ones dilate it (disk structuring element, clipped to
  /// the image; dilation may spill onto neighbours, as a real segmenter does). In [0, 16].
  int max_boundary_px = 2;
  /// A bias added to every mask's radius: a segmenter whose masks are systematically too small
  /// (< 0, eroded) or too large (> 0, dilated). In [-16, 16].
  int boundary_offset_px = 0;

  // ---- False positives on leaves --------------------------------------------------------------
  /// Per frame, the probability that one visible leaf instance (>= min_pixels pixels), chosen
  /// uniformly, is reported as a fruit. In [0, 1].
  double p_false_positive = 0.15;
  /// Its confidence, uniform in [false_positive_confidence_min, false_positive_confidence_max],
  /// 0 <= min <= max <= 1.
  double false_positive_confidence_min = 0.1;
  double false_positive_confidence_max = 0.4;

  // ---- Merged neighbours ----------------------------------------------------------------------
  /// For each pair of detected fruits whose visible pixels touch (4-neighbour adjacency in the
  /// instance image), the probability that they come out as one mask. Each fruit merges at most
  /// once per frame. In [0, 1].
  double p_merge = 0.2;

  /// No noise: every fruit with >= 1 visible pixel is detected with its exact visible mask and
  /// confidence 0.95; no false positives, no merges.
  static OracleOptions Perfect();

  /// Every bad field at once: "invalid oracle options: p_max (1.5) must be in [0, 1]; ...".
  Status Validate() const;

  /// p_det(v) for a visible fraction v (clamped to [0, 1]); min_pixels is not applied here.
  double DetectionProbability(double visible_fraction) const;
  /// The mean confidence of a detection at visible fraction v (before noise and clamping).
  double MeanConfidence(double visible_fraction) const;
};

/// The area in pixels a fruit would cover unoccluded and fully inside the image: π (f r / z)²
/// with f = sqrt(fx fy) and z the depth of its centre in the camera frame (X_WC⁻¹ · center_W).
/// nullopt when the camera is within the fruit's radius of its centre plane (z <= radius_m), where
/// the projection is undefined.
std::optional<double> ExpectedFruitAreaPx(const CameraIntrinsics& K, const RigidTransform& X_WC,
                                          const GroundTruthFruit& fruit);

/// Simulator labels through a seeded zero-shot-like error model (OracleOptions), so planners are
/// tested against realistic detector noise. Fruit instances are the instance ids whose majority
/// class (request.labels->class_ids) is fruit; their visible fraction v is visible pixels /
/// ExpectedFruitAreaPx (clamped to [0, 1]; 1 when the fruit is missing from labels->fruits or
/// the area is undefined). Randomness of a frame comes only from
/// Rng(seed).Fork("oracle").Fork(request.frame_index), so results do not depend on call order.
///
/// Output: the detected fruits in ascending instance-id order (a merged pair at its smaller id),
/// then the false positive if any; labels are the prompt's first fruit phrase. Instances scoring
/// below request.score_threshold are dropped. A prompt with no fruit phrase gives no instances.
///
/// Errors: InvalidArgument for a null or invalid frame, an empty prompt, a score threshold outside
/// [0, 1], label images whose size differs from the frame (naming both sizes) or a ground-truth
/// fruit with a bad radius or centre; FailedPrecondition when request.labels is null.
/// The fields of OracleOptions (every one of them), with the rules between them.
const OptionTable<OracleOptions>& OracleOptionTable();

/// "oracle" (OracleOptions{}) and "oracle-perfect" (OracleOptions::Perfect() as its defaults).
SegmenterEntry OracleSegmenterEntry();
SegmenterEntry OraclePerfectSegmenterEntry();

class OracleSegmenter : public Segmenter {
 public:
  /// @throws avp::Error if options.Validate() fails (the message names the bad fields).
  explicit OracleSegmenter(OracleOptions options = {}, uint64_t seed = 0);

  std::string_view name() const override { return "oracle"; }
  Result<Segmentation> Segment(const SegmentationRequest& request) override;
  bool keeps_up_with_stream() const override { return true; }

  const OracleOptions& options() const { return options_; }
  uint64_t seed() const { return seed_; }

  /// The class a prompt phrase targets (kFruit, see OracleOptions::fruit_words), or nullopt.
  std::optional<SemanticClass> ClassForPhrase(std::string_view phrase) const;

 private:
  OracleOptions options_;
  uint64_t seed_;
};

}  // namespace avp::segmentation

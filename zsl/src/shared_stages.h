#pragma once
// Internal to avp_zsl (zsl/src, not installed): the stages YwesSegmenter and LsamSegmenter share
// (the SAM box segmenter, request checks, loading, instances), implemented in ywes_segmenter.cpp;
// used by both backends and zsl's unit tests.

#include <filesystem>
#include <initializer_list>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <avp/core/image.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/segmentation/segmenter.h>

#include "manifest.h"
#include "ort_runtime.h"

namespace avp::zsl {

/// What SamBoxSegmenter::Segment returns: one mask and one IoU prediction per box, in box order,
/// and the time of each stage.
struct SamBoxMasks {
  std::vector<MaskImage> masks;  ///< source-image size, 255 = instance
  std::vector<float> iou;        ///< the decoder's `iou_predictions`
  double encoder_ms = 0.0;       ///< resize + normalise + the encoder run
  double decoder_ms = 0.0;       ///< prompt coordinates + the decoder run(s)
  double masks_ms = 0.0;         ///< SamLowResLogitsToMask for every box
};

/// EfficientViT-SAM with box prompts (design: zero-shot-models.md §4.3), the mask stage of both
/// YwesSegmenter and LsamSegmenter: the encoder runs once per image (SamEncoderTensor: long side
/// to S, ImageNet-style mean/std, zero padding bottom/right); the decoder runs once for all boxes
/// (`point_coords` [B,2,2] = SamBoxPromptCoords, `point_labels` [B,2] = (2, 3)), or in chunks of
/// B when the export fixes B; each low-res logit map becomes a source-size mask with
/// SamLowResLogitsToMask (threshold: the manifest's `mask_threshold`).
/// Thread-safe (`Segment` is const; sessions allow concurrent runs). Move-only.
class SamBoxSegmenter {
 public:
  /// Takes the `segmenter.encoder` (evitsam.encoder/1) and `segmenter.decoder`
  /// (evitsam.decoder.single/1) roles of a loaded backend.
  /// Errors (InvalidArgument, naming the role and field): the encoder's `preprocess` is not the
  /// fixed EfficientViT-SAM one (resize "fit", padding "bottom_right" with 0 in "normalized"
  /// space, "rgb", scale 1, mean (123.675, 116.28, 103.53), std (58.395, 57.12, 57.375),
  /// interpolation "linear"); the decoder fixes P to a value other than 2 points.
  static Result<SamBoxSegmenter> Create(LoadedModel encoder, LoadedModel decoder);

  SamBoxSegmenter(SamBoxSegmenter&&) noexcept;
  SamBoxSegmenter& operator=(SamBoxSegmenter&&) noexcept;
  ~SamBoxSegmenter();

  /// Masks of `boxes` (source pixels of `rgb`). No boxes: nothing runs and the result is empty.
  /// Errors: the models' run errors, naming the role ("segmenter.decoder: ...").
  Result<SamBoxMasks> Segment(const ImageRgb8& rgb, std::span<const PixelBox> boxes) const;

  int encoder_size() const;  ///< S
  int prompt_frame() const;  ///< 1024
  int low_res() const;       ///< 256
  float mask_threshold() const;
  int decoder_batch() const;  ///< the decoder's static B, or 0 when dynamic
  const TensorModel& encoder() const;
  const TensorModel& decoder() const;

 private:
  struct Impl;
  explicit SamBoxSegmenter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

namespace internal {

/// The request checks every zsl backend makes, as statuses starting with "<backend>: ": frame not
/// null, image not empty, RgbdFrame::Validate, score_threshold in [0, 1].
Status ValidateRequest(std::string_view backend, const segmentation::SegmentationRequest& request);

/// One check of a backend's options (YwesOptions::Validate, LsamOptions::Validate): each named
/// threshold in [0, 1], max_detections > 0 and the session settings; every bad field named at
/// once: "invalid <backend> options: nms_iou (1.5) must be in [0, 1]; ...".
Status ValidateBackendOptions(std::string_view backend,
                              std::initializer_list<std::pair<const char*, float>> thresholds,
                              int max_detections, const RuntimeOptions& session);

/// LoadBackend(backend, model_dir, {session, verify_sha256, warm_up}) when it ends READY; else its
/// status, with the message "<backend>: model directory '<dir>' is <STATE>: <reason>".
Result<LoadedBackend> LoadReadyBackend(std::string_view backend,
                                       const std::filesystem::path& model_dir,
                                       const SessionOptions& session, bool verify_sha256,
                                       bool warm_up);

/// A detector box (source pixels) waiting for its mask.
struct BoxCandidate {
  PixelBox box;
  float score = 0.f;
  std::string label;
};

/// Appends one SemanticClass::kFruit instance per candidate whose mask is not empty: confidence
/// = the score clamped to [0, 1], label, box, mask_score = the IoU prediction.
/// @pre masks has one mask and one IoU per candidate.
void AppendInstances(const std::vector<BoxCandidate>& candidates, SamBoxMasks masks,
                     Segmentation& out);

}  // namespace internal

}  // namespace avp::zsl

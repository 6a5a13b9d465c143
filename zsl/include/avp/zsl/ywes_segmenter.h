#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/segmentation/segmenter.h>
#include <avp/zsl/zsl.h>

namespace avp::zsl {

// Internal parts of the backends (zsl/src), named only by the accessors that zsl's own tests use.
class TensorModel;      // tensor_model.h: one network, in process or on a model server
class SamBoxSegmenter;  // shared_stages.h: the SAM stage of ywes and lsam
class TextEncoder;      // text_encoder.h: CLIP text embeddings

/// Settings of a YwesSegmenter, with the reference values (design §1) as defaults.
struct YwesOptions {
  /// Detector score an anchor must exceed (strictly, as Ultralytics) to become a detection: the
  /// reference's confidence 0.002. A request's `score_threshold` applies on top of it:
  /// detections scoring below it are dropped too, before NMS (which gives the same result as
  /// dropping them after NMS: a weaker box never suppresses a stronger one).
  float score_threshold = 0.002f;
  /// NMS IoU threshold: a detection overlapping a better kept one by more is suppressed
  /// (reference 0.3).
  float nms_iou = 0.3f;
  /// Class-agnostic NMS (reference) or per class (a box of "tomato" does not suppress one of
  /// "leaf").
  bool class_agnostic_nms = true;
  /// Detections kept after NMS, best first (Ultralytics' max_det 300).
  int max_detections = 300;
  /// ORT sessions: intra-op threads (0 = ORT's default), device (auto/cpu/cuda).
  RuntimeOptions session;
  /// Check each file's sha256 against the manifest at creation (slow for real weights).
  bool verify_sha256 = false;
  /// Run each model once on zeros at creation and log the times (stderr).
  bool warm_up = false;
  /// Entries of the text-embedding LRU cache.
  size_t text_cache_capacity = 1024;

  /// OK, or InvalidArgument listing every bad field: "score_threshold (-1) must be in [0, 1];
  /// max_detections (0) must be > 0".
  Status Validate() const;
};

/// YOLO-World → EfficientViT-SAM ("ywes", design: zero-shot-models.md §1, §4.1–4.3, §7), built
/// from a model directory (manifest.json, docs/zero-shot-models.md). Per `Segment`:
///  1. prompt → ParsePromptClasses(prompt, N_max): comma-separated phrases, normalised and
///     de-duplicated; more than N_max classes is an InvalidArgument naming both counts.
///     With a baked-vocabulary detector (`yoloworld.baked/1`) each class must be one of the
///     manifest's `baked_names` (else InvalidArgument naming the phrase and listing the names).
///  2. text-feature detector: TextEncoder embeddings (CLIP, L2-normalised, LRU-cached) into
///     `txt_feats` [1,N_max,512], row i = class i, unused rows zero (and their scores ignored).
///  3. letterbox (the detector's `preprocess`: fit + centre padding, pad value, scale,
///     mean/std, channel order) → the detector → DecodeYoloHead over the active classes (layout
///     and `score_activation` from the manifest) → drop boxes that clip to nothing (entirely in
///     the padding: they neither suppress nor count) → NMS → DetectionsToSource.
///  4. SamBoxSegmenter: the encoder once, the decoder for all boxes at once.
///  5. one instance per box, best score first: mask, label = the class phrase (normalised, so
///     each instance of "tomato, green apple" keeps its own phrase), box (source pixels),
///     confidence = the detector score (clamped to [0, 1]), mask_score = SAM's IoU prediction.
///     Instances whose mask is empty after thresholding are dropped.
///
/// **Semantic class.** Every instance is SemanticClass::kFruit: the prompt names what the user is
/// looking for, and kFruit is avp's target class ("the target organ", semantic_class.h) that the
/// map and the planner act on. The phrase itself stays in `label`. (The oracle segmenter, by
/// contrast, knows the scene's classes and only labels fruit phrases; a zero-shot detector cannot
/// tell a leaf prompt from a fruit prompt.)
///
/// Timings (Segmentation::timings, in this order): "tokenize", "text" (text-feature detectors
/// only; near 0 ms when every phrase is cached), "letterbox", "detector", "nms" (decode, NMS and
/// un-letterboxing), then, when there is at least one box, "sam_encoder", "sam_decoder",
/// "masks".
///
/// Thread-safe: `Segment` may run on several threads at once; results do not depend on the
/// thread or the call order (request.frame_index is not used: the pipeline is deterministic).
class YwesSegmenter final : public segmentation::Segmenter {
 public:
  static constexpr std::string_view kName = "ywes";

  /// Loads and validates the ywes models of `model_dir` (LoadBackend("ywes", ...)).
  /// Errors: the backend's state reason with its code (NotFound when the directory, manifest, a
  /// role or a file is missing; InvalidArgument / ParseError for a bad manifest, size, sha256,
  /// contract or cross-check), prefixed "ywes (model directory '<dir>'): "; InvalidArgument for
  /// bad options or a manifest field this pipeline does not support (naming it).
  static Result<std::unique_ptr<YwesSegmenter>> Create(const std::filesystem::path& model_dir,
                                                       const YwesOptions& options = {});

  ~YwesSegmenter() override;

  std::string_view name() const override { return kName; }

  /// See the class comment. Errors (InvalidArgument unless noted, all starting with "ywes: "):
  /// request.frame is null; the image is empty; the frame is inconsistent (RgbdFrame::Validate:
  /// rgb, depth and intrinsics sizes); score_threshold outside [0, 1]; the prompt has no class,
  /// too many classes, or (baked) an unknown class; the models' run errors.
  Result<Segmentation> Segment(const segmentation::SegmentationRequest& request) override;

  /// The classes `prompt` selects, as Segment uses them (normalised, de-duplicated, in prompt
  /// order), with the same errors.
  Result<std::vector<std::string>> PromptClasses(std::string_view prompt) const;

  /// The `txt_feats` tensor [1, N_max, dim] that Segment gives the detector for `prompt`
  /// (row-major; rows past the prompt's classes are zero). FailedPrecondition for a baked
  /// detector.
  Result<std::vector<float>> TextFeatures(std::string_view prompt) const;

  /// True for a `yoloworld.baked/1` detector.
  bool baked() const;
  /// The detector's class slots: N_max (text features) or NC (baked).
  int max_classes() const;
  /// The baked vocabulary (empty for a text-feature detector).
  const std::vector<std::string>& baked_names() const;
  /// The text encoder, or nullptr for a baked detector.
  const TextEncoder* text_encoder() const;
  const SamBoxSegmenter& sam() const;
  const TensorModel& detector() const;
  const YwesOptions& options() const;
  const std::filesystem::path& model_dir() const;

 private:
  struct Impl;
  explicit YwesSegmenter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace avp::zsl

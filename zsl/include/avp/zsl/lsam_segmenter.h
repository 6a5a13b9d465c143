#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/image.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/segmentation/segmenter.h>
#include <avp/zsl/zsl.h>

namespace avp::zsl {

// Internal parts of the backends (zsl/src), named only by the accessors that zsl's own tests use.
class TensorModel;      // tensor_model.h
class SamBoxSegmenter;  // shared_stages.h

/// Settings of an LsamSegmenter, with the reference values (design §1, lang-segment-anything) as
/// defaults.
struct LsamOptions {
  /// A query becomes a box when its score (see LsamSegmenter) is > box_threshold (reference 0.3).
  float box_threshold = 0.3f;
  /// ... and its phrase's best token is > text_threshold (reference 0.25).
  float text_threshold = 0.25f;
  /// Boxes kept, best first (the reference keeps all: Grounding DINO has 900 queries).
  int max_detections = 900;
  RuntimeOptions session;
  bool verify_sha256 = false;
  bool warm_up = false;

  /// OK, or InvalidArgument listing every bad field.
  Status Validate() const;
};

/// One Grounding DINO box before SAM: source pixels, score, the phrase it was given, its query.
struct GroundedBox {
  PixelBox box;
  float score = 0.f;
  std::string phrase;
  int query = -1;
};

/// LsamSegmenter::Ground's result: the boxes, best first, and the timings of its stages
/// ("tokenize", "preprocess", "grounding", "boxes").
struct Grounding {
  std::vector<GroundedBox> boxes;
  std::vector<StageTiming> timings;
};

/// Grounding DINO → EfficientViT-SAM ("lsam", design: zero-shot-models.md §1, §4.4), built from a
/// model directory with a `grounding` (gdino.ort/1) role and the SAM roles. Per `Segment`:
///  1. prompt → ParsePromptClasses (no class limit) → WordPieceTokenizer::EncodeGroundingPrompt:
///     "tomato . green apple .", position ids restarting per phrase, the phrase attention mask.
///     When the export fixes the text length L, the caption is padded to L ([PAD], attention 0,
///     each padding token attending only itself); a longer caption is an InvalidArgument.
///  2. the image resized (the manifest's `preprocess`: "stretch" to 800 x 1200 in the reference
///     export, its interpolation) and normalised ((v · scale − mean) / std, ImageNet), CHW.
///  3. `logits` [1,Q,T] through a sigmoid (unless `score_activation` is "none") and `boxes`
///     [1,Q,4] (normalised cx, cy, w, h). For each query, each phrase scores the maximum over
///     its own tokens; the query's **phrase is the phrase whose tokens score highest** (the first
///     one in prompt order on ties), and its score is that maximum. Only phrase tokens count:
///     [CLS], [SEP] and the "." separators are ignored (the reference takes the maximum over all
///     positions and builds the label from every token above text_threshold, which can join
///     words of several phrases; here each box has exactly one prompt phrase). A query is kept
///     when its score is > box_threshold and > text_threshold. No NMS (as the reference).
///  4. boxes → source pixels (NormalizedCxcywhToPixels, clipped); empty boxes are dropped; best
///     score first (ties by query index), at most max_detections.
///  5. SamBoxSegmenter, then instances as YwesSegmenter makes them (SemanticClass::kFruit, label
///     = the phrase, box, confidence = the score, mask_score = SAM's IoU; empty masks dropped).
///
/// Timings: "tokenize", "preprocess", "grounding", "boxes", then with at least one box
/// "sam_encoder", "sam_decoder", "masks". Thread-safe; deterministic.
class LsamSegmenter final : public segmentation::Segmenter {
 public:
  static constexpr std::string_view kName = "lsam";

  /// Loads and validates the lsam models of `model_dir` (LoadBackend("lsam", ...)).
  /// Errors: as YwesSegmenter::Create, prefixed "lsam: model directory '<dir>' is ...";
  /// InvalidArgument for bad options or unsupported manifest fields (naming them).
  static Result<std::unique_ptr<LsamSegmenter>> Create(const std::filesystem::path& model_dir,
                                                       const LsamOptions& options = {});

  ~LsamSegmenter() override;

  std::string_view name() const override { return kName; }

  /// See the class comment; errors as YwesSegmenter::Segment, starting with "lsam: ".
  Result<Segmentation> Segment(const segmentation::SegmentationRequest& request) override;

  /// Steps 1-4 only: Grounding DINO's boxes for `prompt` on `rgb`, best first. Errors: an empty
  /// image, the prompt's errors, the model's run errors (all starting with "lsam: ").
  Result<Grounding> Ground(const ImageRgb8& rgb, std::string_view prompt) const;

  const SamBoxSegmenter& sam() const;
  const TensorModel& grounding() const;
  const LsamOptions& options() const;
  const std::filesystem::path& model_dir() const;

 private:
  struct Impl;
  explicit LsamSegmenter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace avp::zsl

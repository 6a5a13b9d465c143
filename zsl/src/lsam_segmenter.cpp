#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <avp/core/stopwatch.h>
#include <avp/zsl/lsam_segmenter.h>

#include "detections.h"
#include "manifest.h"
#include "prompt.h"
#include "shared_stages.h"
#include "wordpiece_tokenizer.h"

namespace avp::zsl {

namespace {

using Clock = SteadyClock;

/// Pads an encoded prompt to an export's fixed length L: pad tokens, zero positions and types,
/// no attention, and a token mask that lets each pad token see only itself.
template <class Pad>
void PadGroundingText(GroundingText& text, int length, Pad pad_id) {
  const size_t old_l = static_cast<size_t>(text.length);
  const size_t new_l = static_cast<size_t>(length);
  text.input_ids.resize(new_l, pad_id);
  text.position_ids.resize(new_l, 0);
  text.token_type_ids.resize(new_l, 0);
  text.attention_mask.resize(new_l, 0);
  std::vector<uint8_t> mask(new_l * new_l, 0);
  for (size_t i = 0; i < new_l; ++i) {
    for (size_t j = 0; j < new_l; ++j) {
      mask[i * new_l + j] = i < old_l && j < old_l ? text.text_token_mask[i * old_l + j]
                                                   : static_cast<uint8_t>(i == j);
    }
  }
  text.text_token_mask = std::move(mask);
  text.length = length;
}

LoadedModel Take(LoadedBackend& backend, const char* role) {
  auto node = backend.models.extract(role);
  return std::move(node.mapped());
}

int CvInterpolation(Interpolation i) {
  switch (i) {
    case Interpolation::kNearest:
      return cv::INTER_NEAREST;
    case Interpolation::kArea:
      return cv::INTER_AREA;
    case Interpolation::kCubic:
      return cv::INTER_CUBIC;
    case Interpolation::kLinear:
      break;
  }
  return cv::INTER_LINEAR;
}

/// The image stretched to the model input and normalised: (v · scale − mean) / std, CHW.
std::vector<float> GroundingTensor(const ImageRgb8& rgb, const Preprocess& p) {
  const cv::Mat src(rgb.height(), rgb.width(), CV_8UC3, const_cast<uint8_t*>(rgb.data().data()));
  cv::Mat resized = src;
  if (rgb.width() != p.width || rgb.height() != p.height) {
    cv::resize(src, resized, cv::Size(p.width, p.height), 0, 0, CvInterpolation(p.interpolation));
  }
  const size_t plane = static_cast<size_t>(p.width) * p.height;
  std::vector<float> out(3 * plane);
  for (int y = 0; y < p.height; ++y) {
    const uint8_t* row = resized.ptr<uint8_t>(y);
    for (int x = 0; x < p.width; ++x) {
      for (int c = 0; c < 3; ++c) {
        const int source_channel = p.channel_order == ChannelOrder::kBgr ? 2 - c : c;
        const float v = static_cast<float>(row[3 * x + source_channel]) * p.scale;
        out[c * plane + static_cast<size_t>(y) * p.width + x] = (v - p.mean[c]) / p.stddev[c];
      }
    }
  }
  return out;
}

}  // namespace

Status LsamOptions::Validate() const {
  return internal::ValidateBackendOptions(
      "lsam", {{"box_threshold", box_threshold}, {"text_threshold", text_threshold}},
      max_detections, session);
}

struct LsamSegmenter::Impl {
  Impl(const LsamOptions& o, std::filesystem::path dir, LoadedModel g, WordPieceTokenizer t,
       SamBoxSegmenter s)
      : options(o),
        model_dir(std::move(dir)),
        grounding(std::move(g)),
        tokenizer(std::move(t)),
        sam(std::move(s)) {}

  LsamOptions options;
  std::filesystem::path model_dir;
  LoadedModel grounding;
  WordPieceTokenizer tokenizer;
  SamBoxSegmenter sam;
  int static_length = 0;  // the export's L, 0 when dynamic
  int context = 256;
  bool sigmoid = true;
  std::string img, input_ids, position_ids, token_type_ids, attention_mask, text_token_mask, logits,
      boxes;
};

LsamSegmenter::LsamSegmenter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
LsamSegmenter::~LsamSegmenter() = default;

Result<std::unique_ptr<LsamSegmenter>> LsamSegmenter::Create(const std::filesystem::path& model_dir,
                                                             const LsamOptions& options) {
  AVP_RETURN_IF_ERROR(options.Validate());
  AVP_ASSIGN_OR_RETURN(
      LoadedBackend backend,
      internal::LoadReadyBackend(kBackendLsam, model_dir, ToSessionOptions(options.session),
                                 options.verify_sha256, options.warm_up));
  LoadedModel grounding = Take(backend, kRoleGrounding);
  const ModelEntry& g = grounding.entry;
  std::vector<std::string> bad;
  if (g.preprocess.resize != ResizeMode::kStretch) {
    bad.push_back("preprocess.resize must be \"stretch\"");
  }
  if (g.preprocess.height <= 0 || g.preprocess.width <= 0) {
    bad.push_back(fmt::format("preprocess.size [{},{}] must be positive", g.preprocess.height,
                              g.preprocess.width));
  }
  if (g.postprocess.box_format != BoxFormat::kCxCyWhNormalized) {
    bad.push_back("postprocess.box_format must be \"cxcywh_normalized\"");
  }
  if (!g.text || g.text->tokenizer != TokenizerKind::kBertWordPiece) {
    bad.push_back("text.tokenizer must be \"bert_wordpiece\"");
  }
  if (!bad.empty()) {
    return InvalidArgumentError(
        fmt::format("lsam: {}: {} (the Grounding DINO export of zero-shot-models.md §4.4)", g.role,
                    fmt::join(bad, "; ")));
  }
  const TextConfig& text = *g.text;
  Result<WordPieceTokenizer> tokenizer = WordPieceTokenizer::FromVocabFile(text.vocabulary.path);
  if (!tokenizer.ok()) return tokenizer.status().WithContext("lsam: grounding");
  if (tokenizer->cls_id() != text.cls || tokenizer->sep_id() != text.sep ||
      tokenizer->dot_id() != text.period) {
    return InvalidArgumentError(fmt::format(
        "lsam: grounding: the vocabulary '{}' has [CLS] {}, [SEP] {} and \".\" {}; text.cls, "
        "text.sep and text.period say {}, {} and {}",
        text.vocabulary.path.string(), tokenizer->cls_id(), tokenizer->sep_id(),
        tokenizer->dot_id(), text.cls, text.sep, text.period));
  }
  Result<SamBoxSegmenter> sam = SamBoxSegmenter::Create(Take(backend, kRoleSegmenterEncoder),
                                                        Take(backend, kRoleSegmenterDecoder));
  if (!sam.ok()) return sam.status().WithContext("lsam");

  auto impl = std::make_unique<Impl>(options, model_dir, std::move(grounding),
                                     std::move(tokenizer).value(), std::move(sam).value());
  const ContractBinding& b = impl->grounding.binding;
  const int64_t l = b.Dim("L");
  impl->static_length = l == kDynamicDim ? 0 : static_cast<int>(l);
  impl->context = text.context;
  impl->sigmoid = impl->grounding.entry.postprocess.score_activation == ScoreActivation::kSigmoid;
  impl->img = b.Name("img");
  impl->input_ids = b.Name("input_ids");
  impl->position_ids = b.Name("position_ids");
  impl->token_type_ids = b.Name("token_type_ids");
  impl->attention_mask = b.Name("attention_mask");
  impl->text_token_mask = b.Name("text_token_mask");
  impl->logits = b.Name("logits");
  impl->boxes = b.Name("boxes");
  return std::unique_ptr<LsamSegmenter>(new LsamSegmenter(std::move(impl)));
}

Result<Grounding> LsamSegmenter::Ground(const ImageRgb8& rgb, std::string_view prompt) const {
  const Impl& m = *impl_;
  if (rgb.empty()) {
    return InvalidArgumentError(
        fmt::format("lsam: the image is empty ({}x{})", rgb.width(), rgb.height()));
  }
  Grounding out;

  // 1. Text.
  auto start = Clock::now();
  Result<std::vector<std::string>> phrases = ParsePromptClasses(prompt);
  if (!phrases.ok()) return phrases.status().WithContext(kName);
  const size_t max_length =
      static_cast<size_t>(m.static_length > 0 ? std::min(m.static_length, m.context) : m.context);
  Result<GroundingText> encoded = m.tokenizer.EncodeGroundingPrompt(*phrases, max_length);
  if (!encoded.ok()) return encoded.status().WithContext(kName);
  GroundingText text = std::move(encoded).value();
  const int length = m.static_length > 0 ? m.static_length : text.length;
  if (length > text.length) PadGroundingText(text, length, m.tokenizer.pad_id());
  out.timings.push_back({"tokenize", MsSince(start)});

  // 2. Image.
  start = Clock::now();
  const Preprocess& pre = m.grounding.entry.preprocess;
  const std::vector<float> image = GroundingTensor(rgb, pre);
  out.timings.push_back({"preprocess", MsSince(start)});

  // 3. The model.
  start = Clock::now();
  const int64_t l = length;
  const std::array<InputTensor, 6> inputs = {
      InputTensor::Float32(m.img, image, {1, 3, pre.height, pre.width}),
      InputTensor::Int64(m.input_ids, text.input_ids, {1, l}),
      InputTensor::Int64(m.position_ids, text.position_ids, {1, l}),
      InputTensor::Int64(m.token_type_ids, text.token_type_ids, {1, l}),
      InputTensor::Bool(m.attention_mask, text.attention_mask, {1, l}),
      InputTensor::Bool(m.text_token_mask, text.text_token_mask, {1, l, l})};
  const std::vector<std::string> output_names = {m.logits, m.boxes};
  Result<std::vector<OutputTensor>> run = m.grounding.model.Run(inputs, output_names);
  if (!run.ok()) return run.status().WithContext(kName);
  const OutputTensor& logits = (*run)[0];
  const OutputTensor& boxes = (*run)[1];
  out.timings.push_back({"grounding", MsSince(start)});

  // 4. Scores, phrases and boxes.
  start = Clock::now();
  if (logits.shape.size() != 3 || boxes.shape.size() != 3 || boxes.shape[2] != 4 ||
      logits.shape[1] != boxes.shape[1] || logits.shape[2] < l) {
    return InternalError(fmt::format("lsam: grounding outputs '{}' {} and '{}' {} do not match",
                                     m.logits, ShapeToString(logits.shape), m.boxes,
                                     ShapeToString(boxes.shape)));
  }
  const auto queries = static_cast<size_t>(logits.shape[1]);
  const auto tokens = static_cast<size_t>(logits.shape[2]);
  const float threshold = std::max(m.options.box_threshold, m.options.text_threshold);
  for (size_t q = 0; q < queries; ++q) {
    int best_phrase = -1;
    float best = 0.f;
    for (size_t p = 0; p < text.phrase_token_spans.size(); ++p) {
      const auto [begin, end] = text.phrase_token_spans[p];
      for (int t = begin; t < end; ++t) {
        const float raw = logits.f32[q * tokens + static_cast<size_t>(t)];
        const float s = m.sigmoid ? Sigmoid(raw) : raw;
        if (best_phrase < 0 || s > best) {
          best = s;
          best_phrase = static_cast<int>(p);
        }
      }
    }
    if (best_phrase < 0 || !(best > threshold)) continue;
    const float* b = boxes.f32.data() + q * 4;
    const PixelBox box =
        NormalizedCxcywhToPixels(b[0], b[1], b[2], b[3], rgb.width(), rgb.height());
    if (ClipsToNothing(box)) continue;
    out.boxes.push_back(
        {box, best, (*phrases)[static_cast<size_t>(best_phrase)], static_cast<int>(q)});
  }
  std::stable_sort(out.boxes.begin(), out.boxes.end(),
                   [](const GroundedBox& a, const GroundedBox& b) { return a.score > b.score; });
  if (out.boxes.size() > static_cast<size_t>(m.options.max_detections)) {
    out.boxes.resize(static_cast<size_t>(m.options.max_detections));
  }
  out.timings.push_back({"boxes", MsSince(start)});
  return out;
}

Result<Segmentation> LsamSegmenter::Segment(const segmentation::SegmentationRequest& request) {
  AVP_RETURN_IF_ERROR(internal::ValidateRequest(kName, request));
  const ImageRgb8& rgb = request.frame->rgb;
  Segmentation out;
  out.width = rgb.width();
  out.height = rgb.height();
  AVP_ASSIGN_OR_RETURN(Grounding grounding, Ground(rgb, request.prompt));
  out.timings = std::move(grounding.timings);
  std::vector<internal::BoxCandidate> candidates;
  std::vector<PixelBox> boxes;
  for (GroundedBox& g : grounding.boxes) {
    if (g.score < request.score_threshold) continue;
    boxes.push_back(g.box);
    candidates.push_back({g.box, g.score, std::move(g.phrase)});
  }
  if (boxes.empty()) return out;
  Result<SamBoxMasks> masks = impl_->sam.Segment(rgb, boxes);
  if (!masks.ok()) return masks.status().WithContext(kName);
  out.timings.push_back({"sam_encoder", masks->encoder_ms});
  out.timings.push_back({"sam_decoder", masks->decoder_ms});
  out.timings.push_back({"masks", masks->masks_ms});
  internal::AppendInstances(candidates, std::move(masks).value(), out);
  return out;
}

const SamBoxSegmenter& LsamSegmenter::sam() const { return impl_->sam; }
const TensorModel& LsamSegmenter::grounding() const { return impl_->grounding.model.get(); }
const LsamOptions& LsamSegmenter::options() const { return impl_->options; }
const std::filesystem::path& LsamSegmenter::model_dir() const { return impl_->model_dir; }

}  // namespace avp::zsl

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/stopwatch.h>
#include <avp/zsl/ywes_segmenter.h>

#include "detections.h"
#include "letterbox.h"
#include "manifest.h"
#include "prompt.h"
#include "sam_geometry.h"
#include "shared_stages.h"
#include "text_encoder.h"

namespace avp::zsl {

namespace {

using Clock = SteadyClock;

/// Moves the model of `role` out of a ready backend (LoadBackend guarantees it is there).
LoadedModel Take(LoadedBackend& backend, const char* role) {
  auto node = backend.models.extract(role);
  return std::move(node.mapped());
}

bool Near(float a, float b) { return std::abs(a - b) <= 1e-3f * std::max(1.f, std::abs(b)); }

std::string Triple(const std::array<float, 3>& v) {
  return fmt::format("({}, {}, {})", v[0], v[1], v[2]);
}

/// The detector input: the YOLO letterbox under the manifest's pre-processing, as model-input
/// values (pixel · scale − mean) / std, CHW, in the model's channel order.
std::vector<float> DetectorTensor(const ImageRgb8& rgb, const Letterbox& lb, const Preprocess& p) {
  const bool pad_in_pixels = p.pad_space == PadSpace::kPixels;
  std::vector<float> t = LetterboxTensor(rgb, lb, pad_in_pixels ? p.pad_value : 0.f, p.scale);
  const size_t plane = static_cast<size_t>(lb.dst_w) * lb.dst_h;
  if (p.channel_order == ChannelOrder::kBgr) {
    std::swap_ranges(t.begin(), t.begin() + static_cast<std::ptrdiff_t>(plane),
                     t.begin() + static_cast<std::ptrdiff_t>(2 * plane));
  }
  for (size_t c = 0; c < 3; ++c) {
    if (p.mean[c] == 0.f && p.stddev[c] == 1.f) continue;
    for (size_t i = c * plane; i < (c + 1) * plane; ++i) t[i] = (t[i] - p.mean[c]) / p.stddev[c];
  }
  if (!pad_in_pixels) {
    for (size_t c = 0; c < 3; ++c) {
      for (int y = 0; y < lb.dst_h; ++y) {
        const bool pad_row = y < lb.pad_top || y >= lb.pad_top + lb.resized_h;
        for (int x = 0; x < lb.dst_w; ++x) {
          if (pad_row || x < lb.pad_left || x >= lb.pad_left + lb.resized_w) {
            t[c * plane + static_cast<size_t>(y) * lb.dst_w + x] = p.pad_value;
          }
        }
      }
    }
  }
  return t;
}

}  // namespace

// ---- shared request checks and instances
// -----------------------------------------------------------

namespace internal {

Result<LoadedBackend> LoadReadyBackend(std::string_view backend,
                                       const std::filesystem::path& model_dir,
                                       const SessionOptions& session, bool verify_sha256,
                                       bool warm_up) {
  BackendLoadOptions load;
  load.session = session;
  load.verify_sha256 = verify_sha256;
  load.warm_up = warm_up;
  LoadedBackend loaded = LoadBackend(backend, model_dir, load);
  if (!loaded.ready()) {
    return Status(loaded.status.code(),
                  fmt::format("{}: model directory '{}' is {}: {}", backend, model_dir.string(),
                              ToString(loaded.state), loaded.reason));
  }
  return loaded;
}

Status ValidateRequest(std::string_view backend, const segmentation::SegmentationRequest& request) {
  if (request.frame == nullptr) {
    return InvalidArgumentError(fmt::format("{}: request.frame is null", backend));
  }
  const RgbdFrame& frame = *request.frame;
  if (frame.rgb.empty()) {
    return InvalidArgumentError(fmt::format("{}: the image (request.frame->rgb) is empty ({}x{})",
                                            backend, frame.rgb.width(), frame.rgb.height()));
  }
  AVP_RETURN_IF_ERROR(frame.Validate().WithContext(backend));
  if (!(request.score_threshold >= 0.f && request.score_threshold <= 1.f)) {
    return InvalidArgumentError(fmt::format("{}: request.score_threshold ({}) must be in [0, 1]",
                                            backend, request.score_threshold));
  }
  return Status::Ok();
}

void AppendInstances(const std::vector<BoxCandidate>& candidates, SamBoxMasks masks,
                     Segmentation& out) {
  for (size_t i = 0; i < candidates.size(); ++i) {
    MaskImage& mask = masks.masks[i];
    const auto data = mask.data();
    if (std::none_of(data.begin(), data.end(), [](uint8_t v) { return v != 0; })) continue;
    InstanceMask instance;
    instance.mask = std::move(mask);
    instance.semantic_class = SemanticClass::kFruit;
    instance.confidence = std::clamp(candidates[i].score, 0.f, 1.f);
    instance.label = candidates[i].label;
    instance.box = candidates[i].box;
    instance.mask_score = masks.iou[i];
    out.instances.push_back(std::move(instance));
  }
}

Status ValidateBackendOptions(std::string_view backend,
                              std::initializer_list<std::pair<const char*, float>> thresholds,
                              int max_detections, const RuntimeOptions& session) {
  std::vector<std::string> bad;
  for (const auto& [name, value] : thresholds) {
    if (!(value >= 0.f && value <= 1.f)) {
      bad.push_back(fmt::format("{} ({}) must be in [0, 1]", name, value));
    }
  }
  if (max_detections <= 0) {
    bad.push_back(fmt::format("max_detections ({}) must be > 0", max_detections));
  }
  const Status session_status = ToSessionOptions(session).Validate();
  if (!session_status.ok()) bad.push_back(session_status.message());
  if (bad.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid {} options: {}", backend, fmt::join(bad, "; ")));
}

}  // namespace internal

// ---- SamBoxSegmenter
// -----------------------------------------------------------------------------

struct SamBoxSegmenter::Impl {
  Impl(LoadedModel e, LoadedModel d) : encoder(std::move(e)), decoder(std::move(d)) {}

  LoadedModel encoder;
  LoadedModel decoder;
  int encoder_size = 0;
  int prompt_frame = 1024;
  int low_res = 256;
  float mask_threshold = 0.f;
  int decoder_batch = 0;  // 0 = dynamic
  std::string input_image, image_embeddings, point_coords, point_labels, masks, iou;
};

SamBoxSegmenter::SamBoxSegmenter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SamBoxSegmenter::SamBoxSegmenter(SamBoxSegmenter&&) noexcept = default;
SamBoxSegmenter& SamBoxSegmenter::operator=(SamBoxSegmenter&&) noexcept = default;
SamBoxSegmenter::~SamBoxSegmenter() = default;

Result<SamBoxSegmenter> SamBoxSegmenter::Create(LoadedModel encoder, LoadedModel decoder) {
  const Preprocess& p = encoder.entry.preprocess;
  const std::string& role = encoder.entry.role;
  std::vector<std::string> bad;
  if (p.resize != ResizeMode::kFit) bad.push_back("preprocess.resize must be \"fit\"");
  if (p.interpolation != Interpolation::kLinear) {
    bad.push_back("preprocess.interpolation must be \"linear\"");
  }
  if (p.padding != PaddingMode::kBottomRight) {
    bad.push_back("preprocess.padding must be \"bottom_right\"");
  }
  if (p.pad_value != 0.f || p.pad_space != PadSpace::kNormalized) {
    bad.push_back(
        fmt::format("preprocess.pad_value ({}) must be 0 in \"normalized\" space", p.pad_value));
  }
  if (p.channel_order != ChannelOrder::kRgb) bad.push_back("preprocess.channel_order must be rgb");
  if (!Near(p.scale, 1.f)) bad.push_back(fmt::format("preprocess.scale ({}) must be 1", p.scale));
  const std::array<float, 3> mean = {123.675f, 116.28f, 103.53f};
  const std::array<float, 3> stddev = {58.395f, 57.12f, 57.375f};
  for (size_t c = 0; c < 3; ++c) {
    if (!Near(p.mean[c], mean[c]) || !Near(p.stddev[c], stddev[c])) {
      bad.push_back(fmt::format("preprocess.mean {} / std {} must be {} / {}", Triple(p.mean),
                                Triple(p.stddev), Triple(mean), Triple(stddev)));
      break;
    }
  }
  if (p.height != p.width || p.height <= 0) {
    bad.push_back(fmt::format("preprocess.size [{},{}] must be square", p.height, p.width));
  }
  if (!bad.empty()) {
    return InvalidArgumentError(
        fmt::format("{}: {} (avp's EfficientViT-SAM pre-processing is fixed: SamEncoderTensor)",
                    role, fmt::join(bad, "; ")));
  }
  const int64_t points = decoder.binding.Dim("P");
  if (points != kDynamicDim && points != 2) {
    return InvalidArgumentError(fmt::format(
        "{}: point_coords fixes P = {} points; a box prompt needs 2", decoder.entry.role, points));
  }
  auto impl = std::make_unique<Impl>(std::move(encoder), std::move(decoder));
  impl->encoder_size = impl->encoder.entry.preprocess.height;
  const Postprocess& post = impl->decoder.entry.postprocess;
  impl->prompt_frame = post.prompt_frame;
  impl->low_res = post.low_res;
  impl->mask_threshold = post.mask_threshold;
  const int64_t b = impl->decoder.binding.Dim("B");
  impl->decoder_batch = b == kDynamicDim ? 0 : static_cast<int>(b);
  const ContractBinding& eb = impl->encoder.binding;
  const ContractBinding& db = impl->decoder.binding;
  impl->input_image = eb.Name("input_image");
  impl->image_embeddings = eb.Name("image_embeddings");
  impl->point_coords = db.Name("point_coords");
  impl->point_labels = db.Name("point_labels");
  impl->masks = db.Name("masks");
  impl->iou = db.Name("iou_predictions");
  return SamBoxSegmenter(std::move(impl));
}

Result<SamBoxMasks> SamBoxSegmenter::Segment(const ImageRgb8& rgb,
                                             std::span<const PixelBox> boxes) const {
  const Impl& m = *impl_;
  SamBoxMasks out;
  if (boxes.empty()) return out;
  const SamTransform t =
      SamTransform::Compute(rgb.width(), rgb.height(), m.encoder_size, m.prompt_frame);

  // Encoder, once per image.
  auto start = Clock::now();
  const std::vector<float> image = SamEncoderTensor(rgb, t);
  const int64_t s = m.encoder_size;
  const InputTensor image_input = InputTensor::Float32(m.input_image, image, {1, 3, s, s});
  const std::vector<std::string> embedding_name = {m.image_embeddings};
  AVP_ASSIGN_OR_RETURN(
      std::vector<OutputTensor> encoded,
      m.encoder.model.Run(std::span<const InputTensor>(&image_input, 1), embedding_name));
  const OutputTensor& embedding = encoded.front();
  out.encoder_ms = MsSince(start);

  // Decoder, all boxes at once (or in chunks of a static B, the last padded with its first box).
  start = Clock::now();
  const size_t n = boxes.size();
  const size_t chunk = m.decoder_batch > 0 ? static_cast<size_t>(m.decoder_batch) : n;
  const size_t mask_size = static_cast<size_t>(m.low_res) * m.low_res;
  std::vector<float> logits;
  logits.reserve(n * mask_size);
  out.iou.reserve(n);
  const std::vector<std::string> decoder_outputs = {m.masks, m.iou};
  for (size_t first = 0; first < n; first += chunk) {
    const size_t rows = std::min(chunk, n - first);
    std::vector<float> coords;
    std::vector<float> labels;
    coords.reserve(chunk * 4);
    labels.reserve(chunk * 2);
    for (size_t k = 0; k < chunk; ++k) {
      const PixelBox& box = boxes[first + (k < rows ? k : 0)];
      const std::array<float, 4> c = SamBoxPromptCoords(box, t);
      coords.insert(coords.end(), c.begin(), c.end());
      labels.insert(labels.end(), kSamBoxPromptLabels.begin(), kSamBoxPromptLabels.end());
    }
    const auto b = static_cast<int64_t>(chunk);
    const std::array<InputTensor, 3> inputs = {
        InputTensor::Float32(m.image_embeddings, embedding.f32, embedding.shape),
        InputTensor::Float32(m.point_coords, coords, {b, 2, 2}),
        InputTensor::Float32(m.point_labels, labels, {b, 2})};
    AVP_ASSIGN_OR_RETURN(std::vector<OutputTensor> decoded,
                         m.decoder.model.Run(inputs, decoder_outputs));
    const OutputTensor& masks = decoded[0];
    const OutputTensor& iou = decoded[1];
    if (masks.f32.size() != chunk * mask_size || iou.f32.size() != chunk) {
      return InternalError(
          fmt::format("{}: outputs '{}' {} and '{}' {} do not hold {} masks of {}x{} and {} scores",
                      m.decoder.entry.role, m.masks, ShapeToString(masks.shape), m.iou,
                      ShapeToString(iou.shape), chunk, m.low_res, m.low_res, chunk));
    }
    logits.insert(logits.end(), masks.f32.begin(),
                  masks.f32.begin() + static_cast<std::ptrdiff_t>(rows * mask_size));
    out.iou.insert(out.iou.end(), iou.f32.begin(),
                   iou.f32.begin() + static_cast<std::ptrdiff_t>(rows));
  }
  out.decoder_ms = MsSince(start);

  start = Clock::now();
  out.masks.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    out.masks.push_back(
        SamLowResLogitsToMask(std::span<const float>(logits).subspan(i * mask_size, mask_size),
                              m.low_res, t, m.mask_threshold));
  }
  out.masks_ms = MsSince(start);
  return out;
}

int SamBoxSegmenter::encoder_size() const { return impl_->encoder_size; }
int SamBoxSegmenter::prompt_frame() const { return impl_->prompt_frame; }
int SamBoxSegmenter::low_res() const { return impl_->low_res; }
float SamBoxSegmenter::mask_threshold() const { return impl_->mask_threshold; }
int SamBoxSegmenter::decoder_batch() const { return impl_->decoder_batch; }
const TensorModel& SamBoxSegmenter::encoder() const { return impl_->encoder.model.get(); }
const TensorModel& SamBoxSegmenter::decoder() const { return impl_->decoder.model.get(); }

// ---- YwesSegmenter
// -------------------------------------------------------------------------------

Status YwesOptions::Validate() const {
  return internal::ValidateBackendOptions(
      "ywes", {{"score_threshold", score_threshold}, {"nms_iou", nms_iou}}, max_detections,
      session);
}

struct YwesSegmenter::Impl {
  Impl(const YwesOptions& o, std::filesystem::path dir, LoadedModel det, SamBoxSegmenter s)
      : options(o), model_dir(std::move(dir)), detector(std::move(det)), sam(std::move(s)) {}

  YwesOptions options;
  std::filesystem::path model_dir;
  LoadedModel detector;
  std::optional<TextEncoder> text;  // text-feature detectors only
  SamBoxSegmenter sam;
  bool baked = false;
  std::vector<std::string> baked_names;
  int slots = 0;        // N_max or NC
  int feats_dim = 512;  // txt_feats width
  int anchors = 8400;
  HeadLayout layout = HeadLayout::kAttributesFirst;
  ScoreActivation activation = ScoreActivation::kNone;
  std::string images, txt_feats, output;

  /// txt_feats [1, slots, feats_dim] for `classes`; appends the "tokenize" and "text" timings.
  Result<std::vector<float>> Features(const std::vector<std::string>& classes,
                                      std::vector<StageTiming>* timings) const {
    AVP_ASSIGN_OR_RETURN(const TextEmbeddings e, text->Encode(classes));
    if (e.dim != feats_dim) {
      return InternalError(
          fmt::format("text: embeddings have width {}; txt_feats takes {}", e.dim, feats_dim));
    }
    std::vector<float> feats(static_cast<size_t>(slots) * feats_dim, 0.f);
    std::copy(e.values.begin(), e.values.end(), feats.begin());
    if (timings != nullptr) {
      timings->push_back({"tokenize", e.tokenize_ms});
      timings->push_back({"text", e.model_ms});
    }
    return feats;
  }
};

YwesSegmenter::YwesSegmenter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
YwesSegmenter::~YwesSegmenter() = default;

Result<std::unique_ptr<YwesSegmenter>> YwesSegmenter::Create(const std::filesystem::path& model_dir,
                                                             const YwesOptions& options) {
  AVP_RETURN_IF_ERROR(options.Validate());
  AVP_ASSIGN_OR_RETURN(
      LoadedBackend backend,
      internal::LoadReadyBackend(kBackendYwes, model_dir, ToSessionOptions(options.session),
                                 options.verify_sha256, options.warm_up));

  LoadedModel detector = Take(backend, kRoleDetector);
  const ModelEntry& det = detector.entry;
  const Preprocess& pre = det.preprocess;
  std::vector<std::string> bad;
  if (pre.resize != ResizeMode::kFit) bad.push_back("preprocess.resize must be \"fit\"");
  if (pre.padding != PaddingMode::kCentre) bad.push_back("preprocess.padding must be \"centre\"");
  if (pre.interpolation != Interpolation::kLinear) {
    bad.push_back("preprocess.interpolation must be \"linear\"");
  }
  if (det.postprocess.box_format != BoxFormat::kCxCyWh) {
    bad.push_back("postprocess.box_format must be \"cxcywh\"");
  }
  if (!bad.empty()) {
    return InvalidArgumentError(
        fmt::format("ywes: {}: {} (the YOLO letterbox and head of zero-shot-models.md §4.1)",
                    det.role, fmt::join(bad, "; ")));
  }
  Result<SamBoxSegmenter> sam = SamBoxSegmenter::Create(Take(backend, kRoleSegmenterEncoder),
                                                        Take(backend, kRoleSegmenterDecoder));
  if (!sam.ok()) return sam.status().WithContext("ywes");

  auto impl =
      std::make_unique<Impl>(options, model_dir, std::move(detector), std::move(sam).value());
  const ModelEntry& entry = impl->detector.entry;
  const ContractBinding& binding = impl->detector.binding;
  impl->baked = entry.contract == kYoloWorldBaked;
  impl->images = binding.Name("images");
  impl->output = binding.Name("output0");
  impl->layout = binding.transposed ? HeadLayout::kAnchorsFirst : HeadLayout::kAttributesFirst;
  impl->activation = entry.postprocess.score_activation == ScoreActivation::kSigmoid
                         ? ScoreActivation::kSigmoid
                         : ScoreActivation::kNone;
  const TensorInfo* out = impl->detector.model.io().FindOutput(impl->output);
  if (out != nullptr && out->shape.size() == 3) {
    impl->anchors = static_cast<int>(binding.transposed ? out->shape[1] : out->shape[2]);
  }
  if (impl->baked) {
    impl->baked_names.reserve(entry.postprocess.baked_names.size());
    for (const std::string& name : entry.postprocess.baked_names) {
      impl->baked_names.push_back(NormalizeClassName(name));
    }
    impl->slots = static_cast<int>(impl->baked_names.size());
  } else {
    impl->slots = entry.postprocess.n_max;
    impl->txt_feats = binding.Name("txt_feats");
    const TensorInfo* feats = impl->detector.model.io().FindInput(impl->txt_feats);
    if (feats != nullptr && feats->shape.size() == 3 && feats->shape[2] > 0) {
      impl->feats_dim = static_cast<int>(feats->shape[2]);
    }
    TextEncoderOptions text_options;
    text_options.cache_capacity = options.text_cache_capacity;
    Result<TextEncoder> text = TextEncoder::Create(Take(backend, kRoleText), text_options);
    if (!text.ok()) return text.status().WithContext("ywes");
    impl->text.emplace(std::move(text).value());
  }
  return std::unique_ptr<YwesSegmenter>(new YwesSegmenter(std::move(impl)));
}

Result<std::vector<std::string>> YwesSegmenter::PromptClasses(std::string_view prompt) const {
  const Impl& m = *impl_;
  Result<std::vector<std::string>> classes =
      ParsePromptClasses(prompt, m.baked ? 0 : static_cast<size_t>(m.slots));
  if (!classes.ok()) return classes.status().WithContext(kName);
  if (m.baked) {
    for (const std::string& c : *classes) {
      if (std::find(m.baked_names.begin(), m.baked_names.end(), c) == m.baked_names.end()) {
        return InvalidArgumentError(
            fmt::format("ywes: class '{}' is not in the detector's baked vocabulary ({}); this "
                        "yoloworld.baked/1 export detects only those classes",
                        c, fmt::join(m.baked_names, ", ")));
      }
    }
  }
  return classes;
}

Result<std::vector<float>> YwesSegmenter::TextFeatures(std::string_view prompt) const {
  if (impl_->baked) {
    return FailedPreconditionError(
        "ywes: the detector has a baked vocabulary (yoloworld.baked/1) and takes no txt_feats");
  }
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> classes, PromptClasses(prompt));
  Result<std::vector<float>> feats = impl_->Features(classes, nullptr);
  if (!feats.ok()) return feats.status().WithContext(kName);
  return feats;
}

Result<Segmentation> YwesSegmenter::Segment(const segmentation::SegmentationRequest& request) {
  const Impl& m = *impl_;
  AVP_RETURN_IF_ERROR(internal::ValidateRequest(kName, request));
  const ImageRgb8& rgb = request.frame->rgb;
  Segmentation out;
  out.width = rgb.width();
  out.height = rgb.height();

  // 1-2. Prompt classes and their text features.
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> classes, PromptClasses(request.prompt));
  std::vector<float> feats;
  if (!m.baked) {
    Result<std::vector<float>> f = m.Features(classes, &out.timings);
    if (!f.ok()) return f.status().WithContext(kName);
    feats = std::move(f).value();
  }

  // 3. Letterbox, detector, decode, NMS, back to source pixels.
  auto start = Clock::now();
  const Preprocess& pre = m.detector.entry.preprocess;
  const Letterbox lb = Letterbox::Compute(rgb.width(), rgb.height(), pre.width, pre.height);
  const std::vector<float> image = DetectorTensor(rgb, lb, pre);
  out.timings.push_back({"letterbox", MsSince(start)});

  start = Clock::now();
  std::vector<InputTensor> inputs = {
      InputTensor::Float32(m.images, image, {1, 3, pre.height, pre.width})};
  if (!m.baked) {
    inputs.push_back(InputTensor::Float32(m.txt_feats, feats, {1, m.slots, m.feats_dim}));
  }
  const std::vector<std::string> output_name = {m.output};
  Result<std::vector<OutputTensor>> run = m.detector.model.Run(inputs, output_name);
  if (!run.ok()) return run.status().WithContext(kName);
  const std::vector<float>& head = run->front().f32;
  out.timings.push_back({"detector", MsSince(start)});

  start = Clock::now();
  Result<std::vector<Detection>> decoded = std::vector<Detection>{};
  const int active = static_cast<int>(classes.size());
  if (m.baked) {
    // The selected baked rows, in prompt order, as a [4 + k, A] head: class index = prompt index.
    const size_t attrs = 4 + static_cast<size_t>(m.slots);
    const size_t anchors = static_cast<size_t>(m.anchors);
    if (head.size() != attrs * anchors) {
      return InternalError(fmt::format("ywes: detector output has {} values; expected {} x {}",
                                       head.size(), attrs, anchors));
    }
    std::vector<size_t> rows = {0, 1, 2, 3};
    for (const std::string& c : classes) {
      rows.push_back(4 +
                     static_cast<size_t>(std::find(m.baked_names.begin(), m.baked_names.end(), c) -
                                         m.baked_names.begin()));
    }
    std::vector<float> compact(rows.size() * anchors);
    for (size_t r = 0; r < rows.size(); ++r) {
      for (size_t a = 0; a < anchors; ++a) {
        compact[r * anchors + a] = m.layout == HeadLayout::kAttributesFirst
                                       ? head[rows[r] * anchors + a]
                                       : head[a * attrs + rows[r]];
      }
    }
    decoded = DecodeYoloHead(compact, active, m.anchors, HeadLayout::kAttributesFirst, m.activation,
                             m.options.score_threshold, active);
  } else {
    decoded = DecodeYoloHead(head, m.slots, m.anchors, m.layout, m.activation,
                             m.options.score_threshold, active);
  }
  if (!decoded.ok()) return decoded.status().WithContext(kName);
  std::vector<Detection> detections = std::move(decoded).value();
  // Below the request's threshold, or entirely in the letterbox padding (the box clips to
  // nothing in the image): dropped before NMS, so that such a box neither suppresses a box in the
  // image nor takes one of the max_detections places.
  std::erase_if(detections, [&](const Detection& d) {
    return d.score < request.score_threshold || ClipsToNothing(lb.ToSource(d.box));
  });
  detections =
      NonMaxSuppression(std::move(detections), m.options.nms_iou, m.options.class_agnostic_nms,
                        static_cast<size_t>(m.options.max_detections));
  detections = DetectionsToSource(std::move(detections), lb);
  std::vector<internal::BoxCandidate> candidates;
  std::vector<PixelBox> boxes;
  for (const Detection& d : detections) {
    candidates.push_back({d.box, d.score, classes[static_cast<size_t>(d.class_index)]});
    boxes.push_back(d.box);
  }
  out.timings.push_back({"nms", MsSince(start)});
  if (boxes.empty()) return out;

  // 4-5. SAM and the instances.
  Result<SamBoxMasks> masks = m.sam.Segment(rgb, boxes);
  if (!masks.ok()) return masks.status().WithContext(kName);
  out.timings.push_back({"sam_encoder", masks->encoder_ms});
  out.timings.push_back({"sam_decoder", masks->decoder_ms});
  out.timings.push_back({"masks", masks->masks_ms});
  internal::AppendInstances(candidates, std::move(masks).value(), out);
  return out;
}

bool YwesSegmenter::baked() const { return impl_->baked; }
int YwesSegmenter::max_classes() const { return impl_->slots; }
const std::vector<std::string>& YwesSegmenter::baked_names() const { return impl_->baked_names; }
const TextEncoder* YwesSegmenter::text_encoder() const {
  return impl_->text ? &*impl_->text : nullptr;
}
const SamBoxSegmenter& YwesSegmenter::sam() const { return impl_->sam; }
const TensorModel& YwesSegmenter::detector() const { return impl_->detector.model.get(); }
const YwesOptions& YwesSegmenter::options() const { return impl_->options; }
const std::filesystem::path& YwesSegmenter::model_dir() const { return impl_->model_dir; }

}  // namespace avp::zsl

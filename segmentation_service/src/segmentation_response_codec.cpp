// A segmentation on the wire: Segmentation -> InferResponse (the server's EncodeSegmentation) and
// back (the client's DecodeSegmentation): the masks (dense, or compact: compact_masks.cpp), each
// instance's class, score, label, box and mask score, and the stage timings.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <avp/core/semantic_class.h>
#include <avp/segmentation_service/segmentation_codec.h>

#include "segmentation_codec_internal.h"

namespace avp::segmentation_service {

namespace {

using codec::ExpectTensor;
using codec::kMaxSide;

// ---- Stages of EncodeSegmentation ---------------------------------------------------------------

/// A size that is not negative, at most 65535 instances for instance_ids, every mask of its size.
Status CheckEncodable(const Segmentation& segmentation, MaskFormat format) {
  const int w = segmentation.width;
  const int h = segmentation.height;
  const size_t n = segmentation.instances.size();
  if (w < 0 || h < 0) {
    return InvalidArgumentError(fmt::format("segmentation size {}x{} is negative", w, h));
  }
  if (format == MaskFormat::kInstanceIds && n > 65535) {
    return InvalidArgumentError(fmt::format(
        "{} instances do not fit the UINT16 ids of mask_format instance_ids (at most 65535)", n));
  }
  for (size_t i = 0; i < n; ++i) {
    const MaskImage& mask = segmentation.instances[i].mask;
    if (!mask.SameSizeAs(w, h)) {
      return InvalidArgumentError(fmt::format("instance {}: mask is {}x{}, the segmentation {}x{}",
                                              i, mask.width(), mask.height(), w, h));
    }
  }
  return Status::Ok();
}

/// 'masks' UINT8 [N, H, W].
Tensor DenseMasks(const Segmentation& segmentation) {
  const int w = segmentation.width;
  const int h = segmentation.height;
  const size_t n = segmentation.instances.size();
  const size_t pixels = static_cast<size_t>(w) * static_cast<size_t>(h);
  Tensor masks;
  masks.name = std::string(names::kMasks);
  masks.datatype = DataType::kUint8;
  masks.shape = {static_cast<int64_t>(n), h, w};
  masks.data.resize(n * pixels);
  for (size_t i = 0; i < n; ++i) {
    const MaskImage& mask = segmentation.instances[i].mask;
    std::copy(mask.data().begin(), mask.data().end(),
              reinterpret_cast<uint8_t*>(masks.data.data()) + i * pixels);
  }
  return masks;
}

/// 'classes', 'scores', 'labels', 'boxes', 'has_box' and 'mask_scores', one per instance.
void AddInstanceOutputs(const Segmentation& segmentation, InferResponse& out) {
  const size_t n = segmentation.instances.size();
  std::vector<int32_t> classes(n);
  std::vector<float> scores(n);
  std::vector<std::string> labels(n);
  std::vector<float> boxes(4 * n, 0.0f);
  std::vector<uint8_t> has_box(n, 0);
  std::vector<float> mask_scores(n);
  for (size_t i = 0; i < n; ++i) {
    const InstanceMask& m = segmentation.instances[i];
    classes[i] = static_cast<int32_t>(m.semantic_class);
    scores[i] = m.confidence;
    labels[i] = m.label;
    if (m.box) {
      has_box[i] = 1;
      boxes[4 * i + 0] = m.box->x0;
      boxes[4 * i + 1] = m.box->y0;
      boxes[4 * i + 2] = m.box->x1;
      boxes[4 * i + 3] = m.box->y1;
    }
    mask_scores[i] = m.mask_score;
  }
  const int64_t ni = static_cast<int64_t>(n);
  out.outputs.push_back(MakeTensor<int32_t>(std::string(names::kClasses), DataType::kInt32, {ni},
                                            std::span<const int32_t>(classes)));
  out.outputs.push_back(MakeTensor<float>(std::string(names::kScores), DataType::kFp32, {ni},
                                          std::span<const float>(scores)));
  out.outputs.push_back(MakeBytesTensor(std::string(names::kLabels), labels));
  out.outputs.push_back(MakeTensor<float>(std::string(names::kBoxes), DataType::kFp32, {ni, 4},
                                          std::span<const float>(boxes)));
  out.outputs.push_back(MakeTensor<uint8_t>(std::string(names::kHasBox), DataType::kBool, {ni},
                                            std::span<const uint8_t>(has_box)));
  out.outputs.push_back(MakeTensor<float>(std::string(names::kMaskScores), DataType::kFp32, {ni},
                                          std::span<const float>(mask_scores)));
}

/// The stage timings as the JSON array of parameter 'timings'.
std::string TimingsJson(const std::vector<StageTiming>& stages) {
  nlohmann::json timings = nlohmann::json::array();
  for (const StageTiming& t : stages) timings.push_back({{"stage", t.stage}, {"ms", t.ms}});
  return timings.dump();
}

// ---- Stages of DecodeSegmentation ---------------------------------------------------------------

/// Where the answer's masks are and their size: dense 'masks', or compact 'mask_rle' (decoded to
/// `rle`) or 'mask_ids', with 'image_size'.
struct MaskLayout {
  bool compact = false;
  const Tensor* masks_t = nullptr;
  const Tensor* rle_t = nullptr;
  const Tensor* ids_t = nullptr;
  const Tensor* scores_t = nullptr;
  int64_t n = 0, h = 0, w = 0;
  std::vector<std::string> rle;
};

/// N, H and W of compact masks, from 'image_size' and 'mask_rle' or 'mask_ids'.
Status ReadCompactSize(const InferResponse& response, MaskLayout& layout) {
  const Tensor* size_t_ = response.FindOutput(names::kImageSize);
  if (size_t_ == nullptr) {
    return InvalidArgumentError(
        fmt::format("the response has '{}' but no 'image_size' INT32 [2] (H, W)",
                    layout.rle_t != nullptr ? names::kMaskRle : names::kMaskIds));
  }
  AVP_RETURN_IF_ERROR(ExpectTensor(*size_t_, "output", DataType::kInt32, {2}, "[2]", "(H, W)"));
  AVP_ASSIGN_OR_RETURN(const std::vector<int32_t> size, ReadValues<int32_t>(*size_t_));
  layout.h = size[0];
  layout.w = size[1];
  if (layout.h < 0 || layout.w < 0) {
    return InvalidArgumentError(
        fmt::format("output 'image_size' ({}, {}) must not be negative", layout.h, layout.w));
  }
  if (layout.rle_t != nullptr) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*layout.rle_t, "output", DataType::kBytes, {-1}, "[N]"));
    AVP_ASSIGN_OR_RETURN(layout.rle, ReadBytesElements(*layout.rle_t));
    layout.n = static_cast<int64_t>(layout.rle.size());
  } else {
    AVP_RETURN_IF_ERROR(ExpectTensor(*layout.ids_t, "output", DataType::kUint16,
                                     {layout.h, layout.w}, "[H, W]", "(the size of 'image_size')"));
    layout.n = layout.scores_t->shape.empty() ? 0 : layout.scores_t->shape[0];
  }
  return Status::Ok();
}

Result<MaskLayout> ReadMaskLayout(const InferResponse& response) {
  MaskLayout layout;
  layout.masks_t = response.FindOutput(names::kMasks);
  layout.rle_t = response.FindOutput(names::kMaskRle);
  layout.ids_t = response.FindOutput(names::kMaskIds);
  layout.scores_t = response.FindOutput(names::kScores);
  layout.compact =
      layout.masks_t == nullptr && (layout.rle_t != nullptr || layout.ids_t != nullptr);
  if ((layout.masks_t == nullptr && !layout.compact) || layout.scores_t == nullptr) {
    return InvalidArgumentError(fmt::format(
        "the response lacks output '{}' ({}); a segmentation needs 'masks' UINT8 [N, H, W] (or "
        "'mask_rle' / 'mask_ids' with 'image_size') and 'scores' FP32 [N]",
        layout.scores_t != nullptr ? names::kMasks : names::kScores,
        layout.scores_t != nullptr ? "UINT8 [N, H, W]" : "FP32 [N]"));
  }
  if (!layout.compact) {
    const Tensor& masks = *layout.masks_t;
    AVP_RETURN_IF_ERROR(ExpectTensor(
        masks, "output", masks.datatype == DataType::kBool ? DataType::kBool : DataType::kUint8,
        {-1, -1, -1}, "[N, H, W]"));
    layout.n = masks.shape[0];
    layout.h = masks.shape[1];
    layout.w = masks.shape[2];
  } else {
    AVP_RETURN_IF_ERROR(ReadCompactSize(response, layout));
  }
  if (layout.h > kMaxSide || layout.w > kMaxSide) {
    return InvalidArgumentError(
        fmt::format("the masks are {} x {}: H and W must be <= {}", layout.h, layout.w, kMaxSide));
  }
  // A compact answer of a few bytes may declare many large masks: bound what it expands to.
  const double decoded_bytes =
      static_cast<double>(layout.n) * static_cast<double>(layout.h) * static_cast<double>(layout.w);
  if (layout.compact && decoded_bytes > static_cast<double>(kMaxDecodedMaskBytes)) {
    return ResourceExhaustedError(
        fmt::format("the answer's {} masks of {} x {} would take {} bytes decoded, over the limit "
                    "of {}",
                    layout.n, layout.h, layout.w, decoded_bytes, kMaxDecodedMaskBytes));
  }
  return layout;
}

constexpr std::string_view kPerInstance = "(one per instance of the masks)";

/// Each instance's attributes besides its mask, with their defaults when not sent.
struct InstanceAttributes {
  std::vector<float> scores;
  std::vector<int32_t> classes;
  std::vector<std::string> labels;
  std::vector<float> boxes;
  std::vector<uint8_t> has_box;
  std::vector<float> mask_scores;
  std::vector<uint8_t> mask_on;
};

/// 'scores' FP32 [N], each a confidence in [0, 1].
Result<std::vector<float>> ReadScores(const Tensor& scores_t, int64_t n) {
  AVP_RETURN_IF_ERROR(ExpectTensor(scores_t, "output", DataType::kFp32, {n}, "[N]", kPerInstance));
  AVP_ASSIGN_OR_RETURN(const std::vector<float> scores, ReadValues<float>(scores_t));
  for (size_t i = 0; i < scores.size(); ++i) {
    if (!(std::isfinite(scores[i]) && scores[i] >= 0.0f && scores[i] <= 1.0f)) {
      return InvalidArgumentError(fmt::format(
          "output 'scores'[{}] ({}) must be a confidence: finite and in [0, 1]", i, scores[i]));
    }
  }
  return scores;
}

/// 'classes' INT32 [N], each a semantic class id; fruit when not sent.
Result<std::vector<int32_t>> ReadClasses(const InferResponse& response, int64_t n) {
  std::vector<int32_t> classes(static_cast<size_t>(n), static_cast<int32_t>(SemanticClass::kFruit));
  if (const Tensor* t = response.FindOutput(names::kClasses)) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kInt32, {n}, "[N]", kPerInstance));
    AVP_ASSIGN_OR_RETURN(classes, ReadValues<int32_t>(*t));
    for (size_t i = 0; i < classes.size(); ++i) {
      if (classes[i] < 0 || classes[i] >= kNumSemanticClasses) {
        return InvalidArgumentError(
            fmt::format("output 'classes'[{}] ({}) is not a semantic class id (0 - {})", i,
                        classes[i], kNumSemanticClasses - 1));
      }
    }
  }
  return classes;
}

/// 'boxes' FP32 [N, 4] and 'has_box' BOOL [N] (every box when 'has_box' is not sent).
Status ReadBoxes(const InferResponse& response, int64_t n, InstanceAttributes& a) {
  if (const Tensor* t = response.FindOutput(names::kBoxes)) {
    AVP_RETURN_IF_ERROR(
        ExpectTensor(*t, "output", DataType::kFp32, {n, 4}, "[N, 4]", "(x0, y0, x1, y1)"));
    AVP_ASSIGN_OR_RETURN(a.boxes, ReadValues<float>(*t));
    a.has_box.assign(static_cast<size_t>(n), 1);
  }
  if (const Tensor* t = response.FindOutput(names::kHasBox)) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kBool, {n}, "[N]", kPerInstance));
    if (a.boxes.empty() && n > 0) {
      return InvalidArgumentError("output 'has_box' is given without 'boxes' FP32 [N, 4]");
    }
    AVP_ASSIGN_OR_RETURN(a.has_box, ReadValues<uint8_t>(*t));
  }
  return Status::Ok();
}

/// 'mask_on' UINT8 [N] of compact masks, each nonzero; 255 when not sent.
Result<std::vector<uint8_t>> ReadMaskOn(const InferResponse& response, int64_t n, bool compact) {
  std::vector<uint8_t> mask_on(static_cast<size_t>(n), 255);
  if (const Tensor* t = response.FindOutput(names::kMaskOn); t != nullptr && compact) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kUint8, {n}, "[N]", kPerInstance));
    AVP_ASSIGN_OR_RETURN(mask_on, ReadValues<uint8_t>(*t));
    for (size_t i = 0; i < mask_on.size(); ++i) {
      if (mask_on[i] == 0) {
        return InvalidArgumentError(
            fmt::format("output 'mask_on'[{}] is 0: a foreground value must be nonzero", i));
      }
    }
  }
  return mask_on;
}

Result<InstanceAttributes> ReadInstanceAttributes(const InferResponse& response,
                                                  const MaskLayout& layout) {
  const int64_t n = layout.n;
  InstanceAttributes a;
  AVP_ASSIGN_OR_RETURN(a.scores, ReadScores(*layout.scores_t, n));
  AVP_ASSIGN_OR_RETURN(a.classes, ReadClasses(response, n));
  a.labels.resize(static_cast<size_t>(n));
  if (const Tensor* t = response.FindOutput(names::kLabels)) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kBytes, {n}, "[N]", kPerInstance));
    AVP_ASSIGN_OR_RETURN(a.labels, ReadBytesElements(*t));
  }
  AVP_RETURN_IF_ERROR(ReadBoxes(response, n, a));
  a.mask_scores.assign(static_cast<size_t>(n), -1.0f);
  if (const Tensor* t = response.FindOutput(names::kMaskScores)) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kFp32, {n}, "[N]", kPerInstance));
    AVP_ASSIGN_OR_RETURN(a.mask_scores, ReadValues<float>(*t));
  }
  AVP_ASSIGN_OR_RETURN(a.mask_on, ReadMaskOn(response, n, layout.compact));
  return a;
}

/// The instances, masks and attributes; compact instance-id masks are filled in one pass after.
Status BuildInstances(const MaskLayout& layout, InstanceAttributes& a, Segmentation& out) {
  const size_t pixels = static_cast<size_t>(layout.w * layout.h);
  out.instances.resize(static_cast<size_t>(layout.n));
  for (size_t i = 0; i < out.instances.size(); ++i) {
    InstanceMask& m = out.instances[i];
    if (!layout.compact) {
      m.mask = MaskImage(out.width, out.height);
      const auto* src = reinterpret_cast<const uint8_t*>(layout.masks_t->data.data()) + i * pixels;
      std::copy(src, src + pixels, m.mask.data().begin());
    } else if (layout.rle_t != nullptr) {
      AVP_ASSIGN_OR_RETURN(
          m.mask, codec::MaskFromRle(layout.rle[i], i, out.width, out.height, a.mask_on[i]));
    } else {
      m.mask = MaskImage(out.width, out.height);  // filled from mask_ids below, in one pass
    }
    m.semantic_class = static_cast<SemanticClass>(a.classes[i]);
    m.confidence = a.scores[i];
    m.label = std::move(a.labels[i]);
    if (!a.has_box.empty() && a.has_box[i] != 0) {
      m.box = PixelBox{a.boxes[4 * i], a.boxes[4 * i + 1], a.boxes[4 * i + 2], a.boxes[4 * i + 3]};
    }
    m.mask_score = a.mask_scores[i];
  }
  if (layout.compact && layout.rle_t == nullptr) {
    AVP_RETURN_IF_ERROR(
        codec::FillMasksFromIds(*layout.ids_t, a.mask_on, out.width, out.instances));
  }
  return Status::Ok();
}

/// Parameter 'timings': a JSON array of {"stage": string, "ms": number}, when given.
Result<std::vector<StageTiming>> ReadTimings(const InferResponse& response) {
  std::vector<StageTiming> stages;
  AVP_ASSIGN_OR_RETURN(const std::optional<std::string> timings,
                       GetStringParameter(response.parameters, names::kTimings));
  if (!timings || timings->empty()) return stages;
  const nlohmann::json j = nlohmann::json::parse(*timings, nullptr, /*allow_exceptions=*/false);
  const auto bad = [&] {
    return InvalidArgumentError(fmt::format(
        "parameter 'timings' (\"{}\") must be a JSON array of {{\"stage\": string, \"ms\": "
        "number}}",
        *timings));
  };
  if (!j.is_array()) return bad();
  for (const nlohmann::json& e : j) {
    if (!e.is_object() || !e.contains("stage") || !e.contains("ms") || !e["stage"].is_string() ||
        !e["ms"].is_number()) {
      return bad();
    }
    stages.push_back({e["stage"].get<std::string>(), e["ms"].get<double>()});
  }
  return stages;
}

}  // namespace

Result<InferResponse> EncodeSegmentation(const Segmentation& segmentation, MaskFormat format) {
  AVP_RETURN_IF_ERROR(CheckEncodable(segmentation, format));
  InferResponse out;
  if (format == MaskFormat::kDense) {
    out.outputs.push_back(DenseMasks(segmentation));
  } else {
    for (Tensor& t : codec::CompactMaskOutputs(segmentation, format)) {
      out.outputs.push_back(std::move(t));
    }
  }
  AddInstanceOutputs(segmentation, out);
  out.parameters[std::string(names::kTimings)] = TimingsJson(segmentation.timings);
  return out;
}

Result<Segmentation> DecodeSegmentation(const InferResponse& response) {
  for (const Tensor& t : response.outputs) AVP_RETURN_IF_ERROR(CheckTensor(t, "output"));
  AVP_ASSIGN_OR_RETURN(const MaskLayout layout, ReadMaskLayout(response));
  AVP_ASSIGN_OR_RETURN(InstanceAttributes attributes, ReadInstanceAttributes(response, layout));
  Segmentation out;
  out.width = static_cast<int>(layout.w);
  out.height = static_cast<int>(layout.h);
  AVP_RETURN_IF_ERROR(BuildInstances(layout, attributes, out));
  AVP_ASSIGN_OR_RETURN(out.timings, ReadTimings(response));
  return out;
}

}  // namespace avp::segmentation_service

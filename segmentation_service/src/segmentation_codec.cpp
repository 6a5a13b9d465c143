// The segmentation codec's metadata (the tensors of a segmentation request and response, mask
// formats, image encodings) and the helpers its parts share (segmentation_codec_internal.h).

#include <algorithm>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/segmentation_service/segmentation_codec.h>

#include "segmentation_codec_internal.h"

namespace avp::segmentation_service {

namespace codec {

std::string JoinNames(const std::vector<TensorSpec>& specs) {
  std::vector<std::string> names;
  for (const TensorSpec& s : specs) names.push_back(s.name);
  return fmt::format("{}", fmt::join(names, ", "));
}

namespace {

/// "FP32 [H, W] = [120, 160]" style expectations.
std::string Expectation(DataType datatype, std::string_view symbolic,
                        const std::vector<int64_t>& concrete) {
  if (concrete.empty()) return fmt::format("{} {}", ToString(datatype), symbolic);
  if (symbolic.empty()) return fmt::format("{} {}", ToString(datatype), ShapeToString(concrete));
  return fmt::format("{} {} = {}", ToString(datatype), symbolic, ShapeToString(concrete));
}

}  // namespace

Status ExpectTensor(const Tensor& t, std::string_view role, DataType datatype,
                    const std::vector<int64_t>& shape, std::string_view symbolic,
                    std::string_view meaning) {
  bool shape_ok = t.shape.size() == shape.size();
  for (size_t i = 0; shape_ok && i < shape.size(); ++i) {
    shape_ok = shape[i] < 0 || t.shape[i] == shape[i];
  }
  if (t.datatype == datatype && shape_ok) return Status::Ok();
  const bool concrete = std::none_of(shape.begin(), shape.end(), [](int64_t d) { return d < 0; });
  return InvalidArgumentError(fmt::format(
      "{} '{}' must be {}{}{}, got {} {}", role, t.name,
      Expectation(datatype, symbolic, concrete ? shape : std::vector<int64_t>{}),
      meaning.empty() ? "" : " ", meaning, ToString(t.datatype), ShapeToString(t.shape)));
}

uint32_t ReadU32LeAt(std::string_view d, size_t pos) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(d[pos + static_cast<size_t>(i)]);
  return v;
}

}  // namespace codec

// ---- metadata -----------------------------------------------------------------------------------

const std::vector<TensorSpec>& SegmentationInputs() {
  static const std::vector<TensorSpec> kInputs = {
      {std::string(names::kRgb), DataType::kUint8, {-1, -1, 3}, true},
      {std::string(names::kImage), DataType::kBytes, {1}, true},
      {std::string(names::kDepth), DataType::kFp32, {-1, -1}, true},
      {std::string(names::kIntrinsics), DataType::kFp64, {6}, true},
      {std::string(names::kCameraPose), DataType::kFp64, {4, 4}, true},
      {std::string(names::kInstanceIds), DataType::kUint16, {-1, -1}, true},
      {std::string(names::kClassIds), DataType::kUint8, {-1, -1}, true},
      {std::string(names::kFruits), DataType::kFp64, {-1, 5}, true},
      {std::string(names::kPrompt), DataType::kBytes, {-1}, false},
  };
  return kInputs;
}

const std::vector<TensorSpec>& SegmentationOutputs() {
  static const std::vector<TensorSpec> kOutputs = {
      {std::string(names::kMasks), DataType::kUint8, {-1, -1, -1}, false},
      {std::string(names::kClasses), DataType::kInt32, {-1}, false},
      {std::string(names::kScores), DataType::kFp32, {-1}, false},
      {std::string(names::kLabels), DataType::kBytes, {-1}, false},
      {std::string(names::kBoxes), DataType::kFp32, {-1, 4}, false},
      {std::string(names::kHasBox), DataType::kBool, {-1}, false},
      {std::string(names::kMaskScores), DataType::kFp32, {-1}, false},
      // The compact forms of `masks` (request parameter mask_format).
      {std::string(names::kMaskRle), DataType::kBytes, {-1}, true},
      {std::string(names::kMaskIds), DataType::kUint16, {-1, -1}, true},
      {std::string(names::kImageSize), DataType::kInt32, {2}, true},
      {std::string(names::kMaskOn), DataType::kUint8, {-1}, true},
  };
  return kOutputs;
}

std::string_view ToString(MaskFormat format) {
  switch (format) {
    case MaskFormat::kDense:
      return "dense";
    case MaskFormat::kRle:
      return "rle";
    case MaskFormat::kInstanceIds:
      return "instance_ids";
  }
  return "?";
}

std::optional<MaskFormat> MaskFormatFromString(std::string_view name) {
  for (MaskFormat f : {MaskFormat::kDense, MaskFormat::kRle, MaskFormat::kInstanceIds}) {
    if (ToString(f) == name) return f;
  }
  return std::nullopt;
}

std::string_view ToString(ImageEncoding encoding) {
  switch (encoding) {
    case ImageEncoding::kRaw:
      return "raw";
    case ImageEncoding::kPng:
      return "png";
    case ImageEncoding::kJpeg:
      return "jpeg";
  }
  return "unknown";
}

std::optional<ImageEncoding> ImageEncodingFromString(std::string_view name) {
  if (name == "raw") return ImageEncoding::kRaw;
  if (name == "png") return ImageEncoding::kPng;
  if (name == "jpeg" || name == "jpg") return ImageEncoding::kJpeg;
  return std::nullopt;
}

}  // namespace avp::segmentation_service

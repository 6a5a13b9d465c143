#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <set>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

#include <avp/core/limits.h>
#include <avp/core/semantic_class.h>
#include <avp/core/text.h>
#include <avp/core/transform.h>
#include <avp/interop/segmentation_codec.h>
#include <avp/io/image_codec.h>
#include <avp/io/mask_codec.h>

namespace avp::interop {

namespace {

/// Largest image side accepted from the wire.
constexpr int64_t kMaxSide = 1 << 15;

constexpr const char* kBothImages =
    "inputs 'rgb' and 'image' are both given: send the colour image once, as 'rgb' UINT8 "
    "[H, W, 3] or as 'image' BYTES [1] (PNG or JPEG)";

std::string JoinNames(const std::vector<TensorSpec>& specs) {
  std::vector<std::string> names;
  for (const TensorSpec& s : specs) names.push_back(s.name);
  return fmt::format("{}", fmt::join(names, ", "));
}

/// "FP32 [H, W] = [120, 160]" style expectations.
std::string Expectation(DataType datatype, std::string_view symbolic,
                        const std::vector<int64_t>& concrete) {
  if (concrete.empty()) return fmt::format("{} {}", ToString(datatype), symbolic);
  if (symbolic.empty()) return fmt::format("{} {}", ToString(datatype), ShapeToString(concrete));
  return fmt::format("{} {} = {}", ToString(datatype), symbolic, ShapeToString(concrete));
}

/// The tensor has `datatype` and `shape` (-1 = any size in that dimension).
Status ExpectTensor(const Tensor& t, std::string_view role, DataType datatype,
                    const std::vector<int64_t>& shape, std::string_view symbolic,
                    std::string_view meaning = "") {
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

template <typename T>
Status CopyImage(const Tensor& t, Image<T, 1>& out, int w, int h) {
  out = Image<T, 1>(w, h);
  internal::CopyLittleEndian(out.data().data(), t.data.data(), out.num_pixels(), sizeof(T));
  return Status::Ok();
}

Result<ImageRgb8> DecodeImage(const Tensor& t) {
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> elements, ReadBytesElements(t));
  if (elements.size() != 1) {
    return InvalidArgumentError(
        fmt::format("input 'image' must be BYTES [1] holding one PNG or JPEG, got {} elements",
                    elements.size()));
  }
  const std::string& bytes = elements.front();
  Result<ImageRgb8> rgb = io::DecodeImage(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()));
  if (!rgb.ok()) {
    return InvalidArgumentError(fmt::format(
        "input 'image': the {} bytes are not a PNG or JPEG image OpenCV can decode", bytes.size()));
  }
  if (rgb->width() > kMaxSide || rgb->height() > kMaxSide) {
    return InvalidArgumentError(fmt::format("input 'image' is {}x{}: larger than {} pixels a side",
                                            rgb->width(), rgb->height(), kMaxSide));
  }
  return std::move(*rgb);
}

Result<std::string> EncodeImage(const ImageRgb8& rgb, ImageEncoding encoding, int jpeg_quality) {
  Result<std::vector<uint8_t>> bytes =
      encoding == ImageEncoding::kPng ? io::EncodePng(rgb) : io::EncodeJpeg(rgb, jpeg_quality);
  if (!bytes.ok()) {
    return IoError(fmt::format("cannot encode the {}x{} image as {}: {}", rgb.width(), rgb.height(),
                               ToString(encoding), bytes.status().message()));
  }
  return std::string(bytes->begin(), bytes->end());
}

// ---- Stages of DecodeSegmentationRequest --------------------------------------------------------

/// Every input is a known one, given once, and well-formed.
Status CheckInputsKnownAndDistinct(const InferRequest& request) {
  const std::vector<TensorSpec>& specs = SegmentationInputs();
  std::set<std::string_view> seen;
  for (const Tensor& t : request.inputs) {
    const bool known = std::any_of(specs.begin(), specs.end(),
                                   [&](const TensorSpec& s) { return s.name == t.name; });
    if (!known) {
      return InvalidArgumentError(
          fmt::format("unknown input {}; known inputs: {}", t.Describe(), JoinNames(specs)));
    }
    if (!seen.insert(t.name).second) {
      return InvalidArgumentError(fmt::format("input '{}' is given twice", t.name));
    }
    AVP_RETURN_IF_ERROR(CheckTensor(t, "input"));
  }
  return Status::Ok();
}

/// The colour image, from exactly one of 'rgb' (raw, optionally batched) and 'image' (encoded).
Result<ImageRgb8> ColourImageInput(const Tensor* rgb_t, const Tensor* image_t) {
  if (rgb_t != nullptr && image_t != nullptr) return InvalidArgumentError(kBothImages);
  if (rgb_t == nullptr && image_t == nullptr) {
    return InvalidArgumentError(
        "missing input 'rgb' (UINT8 [H, W, 3]) or 'image' (BYTES [1], a PNG or JPEG)");
  }
  if (rgb_t == nullptr) {
    AVP_RETURN_IF_ERROR(
        ExpectTensor(*image_t, "input", DataType::kBytes, {1}, "[1]", "(a PNG or JPEG)"));
    return DecodeImage(*image_t);
  }
  const bool batched = rgb_t->shape.size() == 4;
  if (batched) {
    AVP_RETURN_IF_ERROR(
        ExpectTensor(*rgb_t, "input", DataType::kUint8, {1, -1, -1, 3}, "[1, H, W, 3]", "RGB8"));
  } else {
    AVP_RETURN_IF_ERROR(
        ExpectTensor(*rgb_t, "input", DataType::kUint8, {-1, -1, 3}, "[H, W, 3]", "RGB8"));
  }
  const int64_t h = rgb_t->shape[batched ? 1 : 0];
  const int64_t w = rgb_t->shape[batched ? 2 : 1];
  if (h < 1 || w < 1 || h > kMaxSide || w > kMaxSide) {
    return InvalidArgumentError(fmt::format("input 'rgb' has shape {}: H and W must be in [1, {}]",
                                            ShapeToString(rgb_t->shape), kMaxSide));
  }
  ImageRgb8 rgb(static_cast<int>(w), static_cast<int>(h));
  std::copy(rgb_t->data.begin(), rgb_t->data.end(), reinterpret_cast<char*>(rgb.data().data()));
  return rgb;
}

/// An input of the colour image's size: `datatype` [H, W] = [h, w].
Status ExpectImageSized(const Tensor& t, DataType datatype, int w, int h) {
  return ExpectTensor(t, "input", datatype, {h, w}, "[H, W]", "(the colour image's size)");
}

/// The depth image (metres), zeros when 'depth' is not given.
Result<DepthImage> DepthInput(const Tensor* depth_t, int w, int h) {
  if (depth_t == nullptr) return DepthImage(w, h, 0.0f);
  AVP_RETURN_IF_ERROR(ExpectImageSized(*depth_t, DataType::kFp32, w, h));
  DepthImage depth_m;
  AVP_RETURN_IF_ERROR(CopyImage(*depth_t, depth_m, w, h));
  return depth_m;
}

/// The intrinsics of a w x h image: from 'intrinsics', or a 90-degree-ish default (fx = fy = w,
/// centred principal point) when it is not given.
Result<CameraIntrinsics> IntrinsicsInput(const Tensor* k_t, int w, int h) {
  CameraIntrinsics K;
  K.width = w;
  K.height = h;
  if (k_t != nullptr) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*k_t, "input", DataType::kFp64, {6}, "",
                                     "(fx, fy, cx, cy, min_depth_m, max_depth_m)"));
    AVP_ASSIGN_OR_RETURN(const std::vector<double> k, ReadValues<double>(*k_t));
    K.fx = k[0];
    K.fy = k[1];
    K.cx = k[2];
    K.cy = k[3];
    K.min_depth_m = k[4];
    K.max_depth_m = k[5];
  } else {
    K.fx = K.fy = static_cast<double>(w);
    K.cx = (w - 1) / 2.0;
    K.cy = (h - 1) / 2.0;
  }
  AVP_RETURN_IF_ERROR(K.Validate().WithContext("input 'intrinsics'"));
  return K;
}

/// X_WC from 'camera_pose' (row-major 4 x 4); InvalidArgument unless it is a rigid transform.
Result<RigidTransform> CameraPoseInput(const Tensor& pose_t) {
  AVP_RETURN_IF_ERROR(
      ExpectTensor(pose_t, "input", DataType::kFp64, {4, 4}, "", "(X_WC, row-major)"));
  AVP_ASSIGN_OR_RETURN(const std::vector<double> X, ReadValues<double>(pose_t));
  Eigen::Matrix3d R;
  Eigen::Vector3d p;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R(r, c) = X[4 * r + c];
    p(r) = X[4 * r + 3];
  }
  if (!R.allFinite() || !p.allFinite() || !IsRotationMatrix(R) || X[12] != 0.0 || X[13] != 0.0 ||
      X[14] != 0.0 || X[15] != 1.0) {
    return InvalidArgumentError(
        fmt::format("input 'camera_pose' ({}) is not a rigid transform: expected a rotation matrix "
                    "(orthonormal, det +1) with a finite translation and the last row 0, 0, 0, 1",
                    fmt::join(X, ", ")));
  }
  return RigidTransform(R, p);
}

/// The ground-truth fruits of 'fruits' [F, 5] (instance_id, x, y, z, radius_m).
Result<std::vector<GroundTruthFruit>> GroundTruthFruitsInput(const Tensor& fruits_t) {
  AVP_RETURN_IF_ERROR(ExpectTensor(fruits_t, "input", DataType::kFp64, {-1, 5}, "[F, 5]",
                                   "(instance_id, x, y, z, radius_m)"));
  AVP_ASSIGN_OR_RETURN(const std::vector<double> f, ReadValues<double>(fruits_t));
  std::vector<GroundTruthFruit> fruits;
  for (size_t i = 0; i + 5 <= f.size(); i += 5) {
    const double id = f[i];
    if (!(id >= 0.0 && id <= 65535.0 && std::floor(id) == id)) {
      return InvalidArgumentError(
          fmt::format("input 'fruits' row {}: instance_id ({}) must be an integer in [0, "
                      "65535]",
                      i / 5, id));
    }
    GroundTruthFruit fruit;
    fruit.instance_id = static_cast<uint16_t>(id);
    fruit.center_W = Eigen::Vector3d(f[i + 1], f[i + 2], f[i + 3]);
    fruit.radius_m = f[i + 4];
    fruits.push_back(fruit);
  }
  return fruits;
}

/// The simulator labels, when 'instance_ids' and 'class_ids' are given (both or neither), with
/// the optional 'fruits'.
Result<std::optional<SimulatorLabels>> SimulatorLabelsInput(const Tensor* ids_t,
                                                            const Tensor* classes_t,
                                                            const Tensor* fruits_t, int w, int h) {
  if ((ids_t == nullptr) != (classes_t == nullptr)) {
    return InvalidArgumentError(fmt::format(
        "input '{}' is given without '{}': simulator labels need both instance_ids UINT16 [H, W] "
        "and class_ids UINT8 [H, W]",
        ids_t != nullptr ? names::kInstanceIds : names::kClassIds,
        ids_t != nullptr ? names::kClassIds : names::kInstanceIds));
  }
  if (fruits_t != nullptr && ids_t == nullptr) {
    return InvalidArgumentError(
        "input 'fruits' is given without the simulator labels 'instance_ids' and 'class_ids'");
  }
  if (ids_t == nullptr) return std::optional<SimulatorLabels>();
  SimulatorLabels labels;
  AVP_RETURN_IF_ERROR(ExpectImageSized(*ids_t, DataType::kUint16, w, h));
  AVP_RETURN_IF_ERROR(ExpectImageSized(*classes_t, DataType::kUint8, w, h));
  AVP_RETURN_IF_ERROR(CopyImage(*ids_t, labels.instance_ids, w, h));
  AVP_RETURN_IF_ERROR(CopyImage(*classes_t, labels.class_ids, w, h));
  if (fruits_t != nullptr) {
    AVP_ASSIGN_OR_RETURN(labels.fruits, GroundTruthFruitsInput(*fruits_t));
  }
  return std::optional<SimulatorLabels>(std::move(labels));
}

/// The prompt: the phrases of 'prompt' joined by ", "; InvalidArgument when it names nothing.
Result<std::string> PromptInput(const Tensor* prompt_t) {
  if (prompt_t == nullptr) {
    return InvalidArgumentError(
        "missing input 'prompt' (BYTES [P]): class phrases such as \"tomato\"");
  }
  AVP_RETURN_IF_ERROR(
      ExpectTensor(*prompt_t, "input", DataType::kBytes, {-1}, "[P]", "(class phrases)"));
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> phrases, ReadBytesElements(*prompt_t));
  std::string prompt =
      phrases.size() == 1 ? phrases.front() : fmt::format("{}", fmt::join(phrases, ", "));
  if (Result<std::vector<std::string>> split = segmentation::SplitPrompt(prompt); !split.ok()) {
    if (split.status().code() != StatusCode::kInvalidArgument) {
      return split.status().WithContext("input 'prompt'");
    }
    return InvalidArgumentError(fmt::format(
        "input 'prompt' (\"{}\") is empty: expected class phrases such as \"tomato\" or "
        "\"tomato, apple\"",
        EscapeText(prompt)));
  }
  return prompt;
}

}  // namespace

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

// ---- budgets ------------------------------------------------------------------------------------

namespace {

uint32_t ReadU32Be(const unsigned char* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | uint32_t{p[3]};
}

uint32_t ReadU32LeAt(std::string_view d, size_t pos) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(d[pos + static_cast<size_t>(i)]);
  return v;
}

/// The elements' lengths of a BYTES tensor's contents, without copying them; nullopt when the
/// length prefixes do not parse (CheckTensor names that later).
std::optional<std::vector<uint32_t>> BytesElementLengths(std::string_view d, uint64_t max_count) {
  std::vector<uint32_t> lengths;
  size_t pos = 0;
  while (pos < d.size()) {
    if (d.size() - pos < 4 || lengths.size() >= max_count) return std::nullopt;
    const uint32_t len = ReadU32LeAt(d, pos);
    pos += 4;
    if (len > d.size() - pos) return std::nullopt;
    lengths.push_back(len);
    pos += len;
  }
  return lengths;
}

/// H x W of an [H, W] or [H, W, 3] or [1, H, W, 3] shape (negative dimensions count as 0: the
/// shape checks name them later), saturating instead of overflowing.
uint64_t ImagePixels(int64_t h, int64_t w) {
  const uint64_t uh = h > 0 ? static_cast<uint64_t>(h) : 0;
  const uint64_t uw = w > 0 ? static_cast<uint64_t>(w) : 0;
  if (uw != 0 && uh > std::numeric_limits<uint64_t>::max() / uw)
    return std::numeric_limits<uint64_t>::max();
  return uh * uw;
}

constexpr std::string_view kRaisePixels =
    "raise it with `avp serve segmentation --max-image-pixels N` (docs/segmentation-service.md)";
constexpr std::string_view kRaisePromptBytes =
    "raise it with `avp serve segmentation --max-prompt-bytes N` (docs/segmentation-service.md)";
constexpr std::string_view kRaisePromptPhrases =
    "raise it with `avp serve segmentation --max-prompt-phrases N` (docs/segmentation-service.md)";

}  // namespace

std::optional<std::pair<uint32_t, uint32_t>> EncodedImageSize(std::string_view bytes) {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  const size_t n = bytes.size();
  static constexpr unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n >= 8 && std::equal(kPng, kPng + 8, p)) {
    // The first chunk must be IHDR: length (13), "IHDR", width, height (big-endian).
    if (n < 24 || std::string_view(bytes.data() + 12, 4) != "IHDR") return std::nullopt;
    return std::make_pair(ReadU32Be(p + 16), ReadU32Be(p + 20));
  }
  if (n >= 3 && p[0] == 0xff && p[1] == 0xd8 && p[2] == 0xff) {
    size_t pos = 2;
    while (pos + 4 <= n) {
      if (p[pos] != 0xff) return std::nullopt;
      const unsigned char marker = p[pos + 1];
      if (marker == 0xff) {  // fill byte
        ++pos;
        continue;
      }
      if (marker == 0x01 || (marker >= 0xd0 && marker <= 0xd7)) {  // no length
        pos += 2;
        continue;
      }
      if (marker == 0xd9 || marker == 0xda) return std::nullopt;  // end, or scan before a frame
      const size_t len = (size_t{p[pos + 2]} << 8) | p[pos + 3];
      const bool sof =
          marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc;
      if (sof) {
        // length (2), precision (1), height (2), width (2)
        if (len < 7 || pos + 9 > n) return std::nullopt;
        const uint32_t h = (uint32_t{p[pos + 5]} << 8) | p[pos + 6];
        const uint32_t w = (uint32_t{p[pos + 7]} << 8) | p[pos + 8];
        return std::make_pair(w, h);
      }
      if (len < 2) return std::nullopt;
      pos += 2 + len;
    }
  }
  return std::nullopt;
}

Status CheckRequestBudget(const InferRequest& request, const RequestBudget& budget) {
  if (request.inputs.size() > kMaxRequestInputs) {
    return InvalidArgumentError(fmt::format(
        "the request has {} inputs: a segmentation request has at most {} (one of each: {})",
        request.inputs.size(), kMaxRequestInputs, JoinNames(SegmentationInputs())));
  }
  if (request.requested_outputs.size() > kMaxRequestedOutputs) {
    return InvalidArgumentError(fmt::format("the request asks for {} outputs: there are {} ({})",
                                            request.requested_outputs.size(), kMaxRequestedOutputs,
                                            JoinNames(SegmentationOutputs())));
  }
  if (request.parameters.size() > kMaxRequestParameters) {
    return InvalidArgumentError(
        fmt::format("the request has {} parameters: at most {} are accepted",
                    request.parameters.size(), kMaxRequestParameters));
  }
  for (const auto& [key, value] : request.parameters) {
    const auto* text = std::get_if<std::string>(&value);
    if (key.size() > kMaxStringParameterBytes ||
        (text != nullptr && text->size() > kMaxStringParameterBytes)) {
      return InvalidArgumentError(fmt::format(
          "parameter {} is {} bytes long (name and value): at most {} bytes each are accepted",
          QuoteText(key), key.size() + (text != nullptr ? text->size() : 0),
          kMaxStringParameterBytes));
    }
  }
  if (request.FindInput(names::kRgb) != nullptr && request.FindInput(names::kImage) != nullptr) {
    return InvalidArgumentError(kBothImages);
  }
  const std::vector<TensorSpec>& specs = SegmentationInputs();
  for (const Tensor& t : request.inputs) {
    if (std::none_of(specs.begin(), specs.end(),
                     [&](const TensorSpec& spec) { return spec.name == t.name; })) {
      return InvalidArgumentError(fmt::format("unknown input {} {} {}; known inputs: {}",
                                              QuoteText(t.name), ToString(t.datatype),
                                              ShapeToString(t.shape), JoinNames(specs)));
    }
    const std::vector<int64_t>& d = t.shape;
    if (t.name == names::kRgb && (d.size() == 3 || d.size() == 4)) {
      const size_t o = d.size() - 3;
      AVP_RETURN_IF_ERROR(CheckLimit(fmt::format("input 'rgb' of {} x {} pixels", d[o + 1], d[o]),
                                     ImagePixels(d[o], d[o + 1]), "max_image_pixels",
                                     budget.max_image_pixels, kRaisePixels));
    } else if (t.name == names::kImage) {
      AVP_RETURN_IF_ERROR(
          ExpectTensor(t, "input", DataType::kBytes, {1}, "[1]", "(a PNG or JPEG)"));
      const std::string_view data(t.data);
      if (data.size() < 4 || ReadU32LeAt(data, 0) != data.size() - 4) {
        return InvalidArgumentError(fmt::format(
            "input 'image': its {} bytes are not one BYTES element (a 4-byte length, then the "
            "PNG or JPEG)",
            data.size()));
      }
      const std::optional<std::pair<uint32_t, uint32_t>> size = EncodedImageSize(data.substr(4));
      if (!size) {
        return InvalidArgumentError(
            fmt::format("input 'image': the {} bytes are not a PNG or JPEG image OpenCV can decode",
                        data.size() - 4));
      }
      AVP_RETURN_IF_ERROR(CheckLimit(
          fmt::format("input 'image' declaring {} x {} pixels", size->first, size->second),
          uint64_t{size->first} * size->second, "max_image_pixels", budget.max_image_pixels,
          kRaisePixels));
    } else if ((t.name == names::kDepth || t.name == names::kInstanceIds ||
                t.name == names::kClassIds) &&
               d.size() == 2) {
      AVP_RETURN_IF_ERROR(CheckLimit(
          fmt::format("input '{}' of {} x {} pixels", t.name, d[1], d[0]), ImagePixels(d[0], d[1]),
          "max_image_pixels", budget.max_image_pixels, kRaisePixels));
    } else if (t.name == names::kFruits && !d.empty() && d[0] > kMaxFruits) {
      return InvalidArgumentError(fmt::format(
          "input 'fruits' has {} rows: at most {} (one per UINT16 instance id)", d[0], kMaxFruits));
    } else if (t.name == names::kPrompt) {
      if (d.size() == 1) {
        AVP_RETURN_IF_ERROR(CheckLimit(
            "phrases (elements) of input 'prompt'", d[0] > 0 ? static_cast<uint64_t>(d[0]) : 0,
            "max_prompt_phrases", budget.max_prompt_phrases, kRaisePromptPhrases));
      }
      if (t.datatype != DataType::kBytes) continue;  // named by the shape checks later
      // The budget covers the element contents; their 4-byte prefixes are the format's.
      const std::optional<std::vector<uint32_t>> lengths =
          BytesElementLengths(t.data, budget.max_prompt_phrases);
      if (!lengths) {
        AVP_RETURN_IF_ERROR(CheckLimit("input 'prompt'", t.data.size(), "max_prompt_bytes",
                                       budget.max_prompt_bytes + 4 * budget.max_prompt_phrases,
                                       kRaisePromptBytes));
        continue;  // malformed: CheckTensor names it
      }
      uint64_t bytes = 0;
      for (const uint32_t len : *lengths) bytes += len;
      if (lengths->size() > 1) bytes += 2 * (lengths->size() - 1);  // joined with ", "
      AVP_RETURN_IF_ERROR(CheckLimit("input 'prompt'", bytes, "max_prompt_bytes",
                                     budget.max_prompt_bytes, kRaisePromptBytes));
      // Phrases within the elements: each comma-separated non-empty piece counts.
      uint64_t phrases = 0;
      size_t pos = 0;
      for (const uint32_t len : *lengths) {
        const std::string_view e(t.data.data() + pos + 4, len);
        pos += 4 + len;
        bool in_phrase = false;
        for (const char c : e) {
          if (c == ',') {
            in_phrase = false;
          } else if (!in_phrase && c != ' ' && c != '\t' && c != '\n' && c != '\r' && c != '\f' &&
                     c != '\v') {
            in_phrase = true;
            ++phrases;
          }
        }
      }
      AVP_RETURN_IF_ERROR(CheckLimit("phrases in input 'prompt'", phrases, "max_prompt_phrases",
                                     budget.max_prompt_phrases, kRaisePromptPhrases));
    }
  }
  return Status::Ok();
}

// ---- requests -----------------------------------------------------------------------------------

Result<InferRequest> EncodeSegmentationRequest(const segmentation::SegmentationRequest& request,
                                               const RequestEncodeOptions& options) {
  if (request.frame == nullptr) {
    return InvalidArgumentError("segmentation request: frame is null");
  }
  const RgbdFrame& frame = *request.frame;
  AVP_RETURN_IF_ERROR(frame.Validate().WithContext("segmentation request"));
  AVP_RETURN_IF_ERROR(
      segmentation::SplitPrompt(request.prompt).status().WithContext("segmentation request"));
  if (!std::isfinite(request.score_threshold)) {
    return InvalidArgumentError(fmt::format(
        "segmentation request: score_threshold ({}) must be finite", request.score_threshold));
  }
  if (options.image == ImageEncoding::kJpeg &&
      (options.jpeg_quality < 0 || options.jpeg_quality > 100)) {
    return InvalidArgumentError(
        fmt::format("JPEG quality ({}) must be in [0, 100]", options.jpeg_quality));
  }
  const int w = frame.rgb.width();
  const int h = frame.rgb.height();
  const SimulatorLabels* labels = options.send_labels ? request.labels : nullptr;
  if (labels != nullptr &&
      (!labels->instance_ids.SameSizeAs(w, h) || !labels->class_ids.SameSizeAs(w, h))) {
    return InvalidArgumentError(fmt::format(
        "segmentation request: simulator labels are {}x{} (instance ids) and {}x{} (class ids), "
        "but the frame is {}x{}",
        labels->instance_ids.width(), labels->instance_ids.height(), labels->class_ids.width(),
        labels->class_ids.height(), w, h));
  }

  InferRequest out;
  out.model_name = options.model_name;
  out.id = fmt::format("{}@{}", frame.frame_id, frame.stamp_ns);
  out.parameters[std::string(names::kScoreThreshold)] =
      static_cast<double>(request.score_threshold);
  // uint64 values as int64 holding the same bits: every OIP peer knows int64_param.
  out.parameters[std::string(names::kFrameIndex)] = std::bit_cast<int64_t>(request.frame_index);
  if (options.seed)
    out.parameters[std::string(names::kSeed)] = std::bit_cast<int64_t>(*options.seed);
  out.parameters[std::string(names::kFrameId)] = frame.frame_id;
  out.parameters[std::string(names::kStampNs)] = frame.stamp_ns;
  if (options.mask_format != MaskFormat::kDense) {
    out.parameters[std::string(names::kMaskFormat)] = std::string(ToString(options.mask_format));
  }

  if (options.image == ImageEncoding::kRaw) {
    out.inputs.push_back(MakeTensor<uint8_t>(std::string(names::kRgb), DataType::kUint8, {h, w, 3},
                                             frame.rgb.data()));
  } else {
    AVP_ASSIGN_OR_RETURN(std::string encoded,
                         EncodeImage(frame.rgb, options.image, options.jpeg_quality));
    out.inputs.push_back(MakeBytesTensor(std::string(names::kImage), {std::move(encoded)}));
  }
  if (options.send_depth) {
    out.inputs.push_back(MakeTensor<float>(std::string(names::kDepth), DataType::kFp32, {h, w},
                                           frame.depth_m.data()));
  }
  const std::vector<double> k = {frame.K.fx, frame.K.fy,          frame.K.cx,
                                 frame.K.cy, frame.K.min_depth_m, frame.K.max_depth_m};
  out.inputs.push_back(MakeTensor<double>(std::string(names::kIntrinsics), DataType::kFp64, {6},
                                          std::span<const double>(k)));
  std::vector<double> pose(16);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) pose[4 * r + c] = frame.X_WC.rotation()(r, c);
    pose[4 * r + 3] = frame.X_WC.translation()(r);
  }
  pose[15] = 1.0;
  out.inputs.push_back(MakeTensor<double>(std::string(names::kCameraPose), DataType::kFp64, {4, 4},
                                          std::span<const double>(pose)));
  if (labels != nullptr) {
    out.inputs.push_back(MakeTensor<uint16_t>(std::string(names::kInstanceIds), DataType::kUint16,
                                              {h, w}, labels->instance_ids.data()));
    out.inputs.push_back(MakeTensor<uint8_t>(std::string(names::kClassIds), DataType::kUint8,
                                             {h, w}, labels->class_ids.data()));
    std::vector<double> fruits;
    fruits.reserve(labels->fruits.size() * 5);
    for (const GroundTruthFruit& f : labels->fruits) {
      fruits.insert(fruits.end(), {static_cast<double>(f.instance_id), f.center_W.x(),
                                   f.center_W.y(), f.center_W.z(), f.radius_m});
    }
    out.inputs.push_back(MakeTensor<double>(std::string(names::kFruits), DataType::kFp64,
                                            {static_cast<int64_t>(labels->fruits.size()), 5},
                                            std::span<const double>(fruits)));
  }
  out.inputs.push_back(MakeBytesTensor(std::string(names::kPrompt), {request.prompt}));
  return out;
}

segmentation::SegmentationRequest DecodedSegmentationRequest::request() const {
  segmentation::SegmentationRequest r;
  r.frame = &frame;
  r.prompt = prompt;
  r.score_threshold = score_threshold;
  r.labels = labels ? &*labels : nullptr;
  r.frame_index = frame_index;
  return r;
}

Result<DecodedSegmentationRequest> DecodeSegmentationRequest(const InferRequest& request,
                                                             const RequestBudget& budget) {
  AVP_RETURN_IF_ERROR(CheckRequestBudget(request, budget));
  AVP_RETURN_IF_ERROR(CheckInputsKnownAndDistinct(request));
  const Tensor* rgb_t = request.FindInput(names::kRgb);
  const Tensor* image_t = request.FindInput(names::kImage);
  const Tensor* depth_t = request.FindInput(names::kDepth);
  const Tensor* k_t = request.FindInput(names::kIntrinsics);
  const Tensor* pose_t = request.FindInput(names::kCameraPose);
  const Tensor* ids_t = request.FindInput(names::kInstanceIds);
  const Tensor* classes_t = request.FindInput(names::kClassIds);
  const Tensor* fruits_t = request.FindInput(names::kFruits);
  const Tensor* prompt_t = request.FindInput(names::kPrompt);

  DecodedSegmentationRequest out;
  RgbdFrame& frame = out.frame;
  AVP_ASSIGN_OR_RETURN(frame.rgb, ColourImageInput(rgb_t, image_t));
  const int w = frame.rgb.width();
  const int h = frame.rgb.height();
  AVP_ASSIGN_OR_RETURN(frame.depth_m, DepthInput(depth_t, w, h));
  AVP_ASSIGN_OR_RETURN(frame.K, IntrinsicsInput(k_t, w, h));
  if (pose_t != nullptr) {
    AVP_ASSIGN_OR_RETURN(frame.X_WC, CameraPoseInput(*pose_t));
  }
  if (auto id = GetStringParameter(request.parameters, names::kFrameId); !id.ok()) {
    return id.status();
  } else if (id->has_value()) {
    frame.frame_id = **id;
  }
  AVP_ASSIGN_OR_RETURN(const std::optional<int64_t> stamp,
                       GetInt64Parameter(request.parameters, names::kStampNs));
  if (stamp) frame.stamp_ns = *stamp;
  AVP_ASSIGN_OR_RETURN(out.labels, SimulatorLabelsInput(ids_t, classes_t, fruits_t, w, h));

  AVP_ASSIGN_OR_RETURN(out.prompt, PromptInput(prompt_t));
  AVP_ASSIGN_OR_RETURN(const std::optional<double> threshold,
                       GetDoubleParameter(request.parameters, names::kScoreThreshold));
  if (threshold) {
    if (!(*threshold >= 0.0 && *threshold <= 1.0)) {
      return InvalidArgumentError(
          fmt::format("parameter 'score_threshold' ({}) must be in [0, 1]", *threshold));
    }
    out.score_threshold = static_cast<float>(*threshold);
  }
  AVP_ASSIGN_OR_RETURN(const std::optional<uint64_t> frame_index,
                       GetUint64Parameter(request.parameters, names::kFrameIndex));
  out.frame_index = frame_index.value_or(0);
  AVP_ASSIGN_OR_RETURN(out.seed, GetUint64Parameter(request.parameters, names::kSeed));
  AVP_ASSIGN_OR_RETURN(const std::optional<std::string> format,
                       GetStringParameter(request.parameters, names::kMaskFormat));
  if (format) {
    const std::optional<MaskFormat> f = MaskFormatFromString(*format);
    if (!f) {
      return InvalidArgumentError(fmt::format(
          "parameter 'mask_format' ({}) must be dense, rle or instance_ids", QuoteText(*format)));
    }
    out.mask_format = *f;
  }
  return out;
}

// ---- responses ----------------------------------------------------------------------------------

Result<InferResponse> EncodeSegmentation(const Segmentation& segmentation, MaskFormat format) {
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
  const size_t pixels = static_cast<size_t>(w) * static_cast<size_t>(h);
  std::vector<Tensor> mask_outputs;
  if (format == MaskFormat::kDense) {
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
    mask_outputs.push_back(std::move(masks));
  } else {
    if (format == MaskFormat::kRle) {
      std::vector<std::string> runs(n);
      for (size_t i = 0; i < n; ++i) {
        const std::vector<uint32_t> counts = io::MaskToRle(segmentation.instances[i].mask);
        runs[i].resize(counts.size() * sizeof(uint32_t));
        internal::CopyLittleEndian(runs[i].data(), counts.data(), counts.size(), sizeof(uint32_t));
      }
      mask_outputs.push_back(MakeBytesTensor(std::string(names::kMaskRle), runs));
    } else {
      // The earliest instance (the best-scoring, as segmenters order them) keeps a pixel.
      std::vector<uint16_t> ids(pixels, 0);
      for (size_t i = n; i-- > 0;) {
        const auto& data = segmentation.instances[i].mask.data();
        for (size_t p = 0; p < pixels; ++p) {
          if (data[p] != 0) ids[p] = static_cast<uint16_t>(i + 1);
        }
      }
      mask_outputs.push_back(MakeTensor<uint16_t>(std::string(names::kMaskIds), DataType::kUint16,
                                                  {h, w}, std::span<const uint16_t>(ids)));
    }
    const std::array<int32_t, 2> size = {h, w};
    mask_outputs.push_back(MakeTensor<int32_t>(std::string(names::kImageSize), DataType::kInt32,
                                               {2}, std::span<const int32_t>(size)));
    // Each mask's foreground value (masks are "nonzero = instance": 1 from the oracle, 255 from
    // the networks), so that the client rebuilds the very bytes.
    std::vector<uint8_t> on(n, 255);
    for (size_t i = 0; i < n; ++i) {
      const auto& data = segmentation.instances[i].mask.data();
      const auto it = std::find_if(data.begin(), data.end(), [](uint8_t v) { return v != 0; });
      if (it != data.end()) on[i] = *it;
    }
    mask_outputs.push_back(MakeTensor<uint8_t>(std::string(names::kMaskOn), DataType::kUint8,
                                               {static_cast<int64_t>(n)},
                                               std::span<const uint8_t>(on)));
  }
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
  InferResponse out;
  for (Tensor& t : mask_outputs) out.outputs.push_back(std::move(t));
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
  nlohmann::json timings = nlohmann::json::array();
  for (const StageTiming& t : segmentation.timings) {
    timings.push_back({{"stage", t.stage}, {"ms", t.ms}});
  }
  out.parameters[std::string(names::kTimings)] = timings.dump();
  return out;
}

Result<Segmentation> DecodeSegmentation(const InferResponse& response) {
  for (const Tensor& t : response.outputs) AVP_RETURN_IF_ERROR(CheckTensor(t, "output"));
  const Tensor* masks_t = response.FindOutput(names::kMasks);
  const Tensor* rle_t = response.FindOutput(names::kMaskRle);
  const Tensor* ids_t = response.FindOutput(names::kMaskIds);
  const Tensor* scores_t = response.FindOutput(names::kScores);
  const bool compact = masks_t == nullptr && (rle_t != nullptr || ids_t != nullptr);
  if ((masks_t == nullptr && !compact) || scores_t == nullptr) {
    return InvalidArgumentError(fmt::format(
        "the response lacks output '{}' ({}); a segmentation needs 'masks' UINT8 [N, H, W] (or "
        "'mask_rle' / 'mask_ids' with 'image_size') and 'scores' FP32 [N]",
        scores_t != nullptr ? names::kMasks : names::kScores,
        scores_t != nullptr ? "UINT8 [N, H, W]" : "FP32 [N]"));
  }
  int64_t n = 0, h = 0, w = 0;
  std::vector<std::string> rle;
  if (!compact) {
    if (masks_t->datatype == DataType::kBool) {
      AVP_RETURN_IF_ERROR(
          ExpectTensor(*masks_t, "output", DataType::kBool, {-1, -1, -1}, "[N, H, W]"));
    } else {
      AVP_RETURN_IF_ERROR(
          ExpectTensor(*masks_t, "output", DataType::kUint8, {-1, -1, -1}, "[N, H, W]"));
    }
    n = masks_t->shape[0];
    h = masks_t->shape[1];
    w = masks_t->shape[2];
  } else {
    const Tensor* size_t_ = response.FindOutput(names::kImageSize);
    if (size_t_ == nullptr) {
      return InvalidArgumentError(
          fmt::format("the response has '{}' but no 'image_size' INT32 [2] (H, W)",
                      rle_t != nullptr ? names::kMaskRle : names::kMaskIds));
    }
    AVP_RETURN_IF_ERROR(ExpectTensor(*size_t_, "output", DataType::kInt32, {2}, "[2]", "(H, W)"));
    AVP_ASSIGN_OR_RETURN(const std::vector<int32_t> size, ReadValues<int32_t>(*size_t_));
    h = size[0];
    w = size[1];
    if (h < 0 || w < 0) {
      return InvalidArgumentError(
          fmt::format("output 'image_size' ({}, {}) must not be negative", h, w));
    }
    if (rle_t != nullptr) {
      AVP_RETURN_IF_ERROR(ExpectTensor(*rle_t, "output", DataType::kBytes, {-1}, "[N]"));
      AVP_ASSIGN_OR_RETURN(rle, ReadBytesElements(*rle_t));
      n = static_cast<int64_t>(rle.size());
    } else {
      AVP_RETURN_IF_ERROR(ExpectTensor(*ids_t, "output", DataType::kUint16, {h, w}, "[H, W]",
                                       "(the size of 'image_size')"));
      n = scores_t->shape.empty() ? 0 : scores_t->shape[0];
    }
  }
  if (h > kMaxSide || w > kMaxSide) {
    return InvalidArgumentError(
        fmt::format("the masks are {} x {}: H and W must be <= {}", h, w, kMaxSide));
  }
  // A compact answer of a few bytes may declare many large masks: bound what it expands to.
  const double decoded_bytes =
      static_cast<double>(n) * static_cast<double>(h) * static_cast<double>(w);
  if (compact && decoded_bytes > static_cast<double>(kMaxDecodedMaskBytes)) {
    return ResourceExhaustedError(
        fmt::format("the answer's {} masks of {} x {} would take {} bytes decoded, over the limit "
                    "of {}",
                    n, h, w, decoded_bytes, kMaxDecodedMaskBytes));
  }
  const std::string_view per_instance = "(one per instance of the masks)";
  AVP_RETURN_IF_ERROR(ExpectTensor(*scores_t, "output", DataType::kFp32, {n}, "[N]", per_instance));
  AVP_ASSIGN_OR_RETURN(const std::vector<float> scores, ReadValues<float>(*scores_t));
  for (size_t i = 0; i < scores.size(); ++i) {
    if (!(std::isfinite(scores[i]) && scores[i] >= 0.0f && scores[i] <= 1.0f)) {
      return InvalidArgumentError(fmt::format(
          "output 'scores'[{}] ({}) must be a confidence: finite and in [0, 1]", i, scores[i]));
    }
  }

  std::vector<int32_t> classes(static_cast<size_t>(n), static_cast<int32_t>(SemanticClass::kFruit));
  if (const Tensor* t = response.FindOutput(names::kClasses)) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kInt32, {n}, "[N]", per_instance));
    AVP_ASSIGN_OR_RETURN(classes, ReadValues<int32_t>(*t));
    for (size_t i = 0; i < classes.size(); ++i) {
      if (classes[i] < 0 || classes[i] >= kNumSemanticClasses) {
        return InvalidArgumentError(
            fmt::format("output 'classes'[{}] ({}) is not a semantic class id (0 - {})", i,
                        classes[i], kNumSemanticClasses - 1));
      }
    }
  }
  std::vector<std::string> labels(static_cast<size_t>(n));
  if (const Tensor* t = response.FindOutput(names::kLabels)) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kBytes, {n}, "[N]", per_instance));
    AVP_ASSIGN_OR_RETURN(labels, ReadBytesElements(*t));
  }
  std::vector<float> boxes;
  std::vector<uint8_t> has_box;
  if (const Tensor* t = response.FindOutput(names::kBoxes)) {
    AVP_RETURN_IF_ERROR(
        ExpectTensor(*t, "output", DataType::kFp32, {n, 4}, "[N, 4]", "(x0, y0, x1, y1)"));
    AVP_ASSIGN_OR_RETURN(boxes, ReadValues<float>(*t));
    has_box.assign(static_cast<size_t>(n), 1);
  }
  if (const Tensor* t = response.FindOutput(names::kHasBox)) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kBool, {n}, "[N]", per_instance));
    if (boxes.empty() && n > 0) {
      return InvalidArgumentError("output 'has_box' is given without 'boxes' FP32 [N, 4]");
    }
    AVP_ASSIGN_OR_RETURN(has_box, ReadValues<uint8_t>(*t));
  }
  std::vector<float> mask_scores(static_cast<size_t>(n), -1.0f);
  if (const Tensor* t = response.FindOutput(names::kMaskScores)) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kFp32, {n}, "[N]", per_instance));
    AVP_ASSIGN_OR_RETURN(mask_scores, ReadValues<float>(*t));
  }

  std::vector<uint8_t> mask_on(static_cast<size_t>(n), 255);
  if (const Tensor* t = response.FindOutput(names::kMaskOn); t != nullptr && compact) {
    AVP_RETURN_IF_ERROR(ExpectTensor(*t, "output", DataType::kUint8, {n}, "[N]", per_instance));
    AVP_ASSIGN_OR_RETURN(mask_on, ReadValues<uint8_t>(*t));
    for (size_t i = 0; i < mask_on.size(); ++i) {
      if (mask_on[i] == 0) {
        return InvalidArgumentError(
            fmt::format("output 'mask_on'[{}] is 0: a foreground value must be nonzero", i));
      }
    }
  }
  Segmentation out;
  out.width = static_cast<int>(w);
  out.height = static_cast<int>(h);
  const size_t pixels = static_cast<size_t>(w * h);
  out.instances.resize(static_cast<size_t>(n));
  for (size_t i = 0; i < out.instances.size(); ++i) {
    InstanceMask& m = out.instances[i];
    if (!compact) {
      m.mask = MaskImage(out.width, out.height);
      const auto* src = reinterpret_cast<const uint8_t*>(masks_t->data.data()) + i * pixels;
      std::copy(src, src + pixels, m.mask.data().begin());
    } else if (rle_t != nullptr) {
      const std::string& bytes = rle[i];
      if (bytes.size() % sizeof(uint32_t) != 0) {
        return InvalidArgumentError(fmt::format(
            "output 'mask_rle'[{}] has {} bytes: not whole UINT32 run lengths", i, bytes.size()));
      }
      std::vector<uint32_t> counts(bytes.size() / sizeof(uint32_t));
      internal::CopyLittleEndian(counts.data(), bytes.data(), counts.size(), sizeof(uint32_t));
      Result<MaskImage> mask = io::RleToMask(counts, out.width, out.height);
      if (!mask.ok()) {
        return InvalidArgumentError(
            fmt::format("output 'mask_rle'[{}]: {}", i, mask.status().message()));
      }
      m.mask = std::move(*mask);
      if (mask_on[i] != 255) {
        for (uint8_t& v : m.mask.data()) v = v != 0 ? mask_on[i] : 0;
      }
    } else {
      m.mask = MaskImage(out.width, out.height);  // filled from mask_ids below, in one pass
    }
    m.semantic_class = static_cast<SemanticClass>(classes[i]);
    m.confidence = scores[i];
    m.label = std::move(labels[i]);
    if (!has_box.empty() && has_box[i] != 0) {
      m.box = PixelBox{boxes[4 * i], boxes[4 * i + 1], boxes[4 * i + 2], boxes[4 * i + 3]};
    }
    m.mask_score = mask_scores[i];
  }
  if (compact && rle_t == nullptr) {
    AVP_ASSIGN_OR_RETURN(const std::vector<uint16_t> ids, ReadValues<uint16_t>(*ids_t));
    for (size_t p = 0; p < ids.size(); ++p) {
      if (ids[p] == 0) continue;
      if (ids[p] > out.instances.size()) {
        return InvalidArgumentError(fmt::format(
            "output 'mask_ids' holds id {} at pixel ({}, {}), but there are {} instances", ids[p],
            p % static_cast<size_t>(w), p / static_cast<size_t>(w), out.instances.size()));
      }
      out.instances[ids[p] - 1].mask.data()[p] = mask_on[ids[p] - 1];
    }
  }
  AVP_ASSIGN_OR_RETURN(const std::optional<std::string> timings,
                       GetStringParameter(response.parameters, names::kTimings));
  if (timings && !timings->empty()) {
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
      out.timings.push_back({e["stage"].get<std::string>(), e["ms"].get<double>()});
    }
  }
  return out;
}

}  // namespace avp::interop

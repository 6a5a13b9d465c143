// A segmentation request on the wire: SegmentationRequest -> InferRequest (the client's
// EncodeSegmentationRequest) and back (the server's DecodeSegmentationRequest), one named stage
// per input.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/text.h>
#include <avp/core/transform.h>
#include <avp/io/image_codec.h>
#include <avp/segmentation_service/segmentation_codec.h>

#include "segmentation_codec_internal.h"

namespace avp::segmentation_service {

namespace {

using codec::ExpectTensor;
using codec::JoinNames;
using codec::kBothImages;
using codec::kMaxSide;

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

// ---- Stages of EncodeSegmentationRequest --------------------------------------------------------

/// The request can be sent: a valid frame and prompt, a finite threshold, a JPEG quality in
/// range, and `labels` (when sent) of the frame's size.
Status CheckEncodable(const segmentation::SegmentationRequest& request,
                      const RequestEncodeOptions& options, const SimulatorLabels* labels) {
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
  if (labels != nullptr &&
      (!labels->instance_ids.SameSizeAs(w, h) || !labels->class_ids.SameSizeAs(w, h))) {
    return InvalidArgumentError(fmt::format(
        "segmentation request: simulator labels are {}x{} (instance ids) and {}x{} (class ids), "
        "but the frame is {}x{}",
        labels->instance_ids.width(), labels->instance_ids.height(), labels->class_ids.width(),
        labels->class_ids.height(), w, h));
  }
  return Status::Ok();
}

/// The request's parameters: score threshold, frame index, seed, frame id and stamp, and the
/// mask format when not dense.
void AddRequestParameters(const segmentation::SegmentationRequest& request,
                          const RequestEncodeOptions& options, InferRequest& out) {
  const RgbdFrame& frame = *request.frame;
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
}

/// The colour image: raw 'rgb' UINT8 [H, W, 3], or 'image' encoded as PNG or JPEG.
Result<Tensor> ColourImageTensor(const ImageRgb8& rgb, const RequestEncodeOptions& options) {
  if (options.image == ImageEncoding::kRaw) {
    return MakeTensor<uint8_t>(std::string(names::kRgb), DataType::kUint8,
                               {rgb.height(), rgb.width(), 3}, rgb.data());
  }
  AVP_ASSIGN_OR_RETURN(std::string encoded, EncodeImage(rgb, options.image, options.jpeg_quality));
  return MakeBytesTensor(std::string(names::kImage), {std::move(encoded)});
}

/// 'intrinsics' FP64 [6] and 'camera_pose' FP64 [4, 4] (X_WC, row-major).
void AddCameraInputs(const RgbdFrame& frame, InferRequest& out) {
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
}

/// The simulator labels: 'instance_ids', 'class_ids' and 'fruits' [F, 5].
void AddLabelInputs(const SimulatorLabels& labels, int w, int h, InferRequest& out) {
  out.inputs.push_back(MakeTensor<uint16_t>(std::string(names::kInstanceIds), DataType::kUint16,
                                            {h, w}, labels.instance_ids.data()));
  out.inputs.push_back(MakeTensor<uint8_t>(std::string(names::kClassIds), DataType::kUint8, {h, w},
                                           labels.class_ids.data()));
  std::vector<double> fruits;
  fruits.reserve(labels.fruits.size() * 5);
  for (const GroundTruthFruit& f : labels.fruits) {
    fruits.insert(fruits.end(), {static_cast<double>(f.instance_id), f.center_W.x(), f.center_W.y(),
                                 f.center_W.z(), f.radius_m});
  }
  out.inputs.push_back(MakeTensor<double>(std::string(names::kFruits), DataType::kFp64,
                                          {static_cast<int64_t>(labels.fruits.size()), 5},
                                          std::span<const double>(fruits)));
}

}  // namespace

Result<InferRequest> EncodeSegmentationRequest(const segmentation::SegmentationRequest& request,
                                               const RequestEncodeOptions& options) {
  const SimulatorLabels* labels = options.send_labels ? request.labels : nullptr;
  AVP_RETURN_IF_ERROR(CheckEncodable(request, options, labels));
  const RgbdFrame& frame = *request.frame;
  const int w = frame.rgb.width();
  const int h = frame.rgb.height();
  InferRequest out;
  out.model_name = options.model_name;
  out.id = fmt::format("{}@{}", frame.frame_id, frame.stamp_ns);
  AddRequestParameters(request, options, out);
  AVP_ASSIGN_OR_RETURN(Tensor image, ColourImageTensor(frame.rgb, options));
  out.inputs.push_back(std::move(image));
  if (options.send_depth) {
    out.inputs.push_back(MakeTensor<float>(std::string(names::kDepth), DataType::kFp32, {h, w},
                                           frame.depth_m.data()));
  }
  AddCameraInputs(frame, out);
  if (labels != nullptr) AddLabelInputs(*labels, w, h, out);
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

}  // namespace avp::segmentation_service

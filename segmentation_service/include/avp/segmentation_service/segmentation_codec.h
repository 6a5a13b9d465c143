#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <avp/core/rgbd_frame.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation_service/tensor.h>

namespace avp::segmentation_service {

/// The segmentation tensor protocol over KServe v2 / Open Inference Protocol (the full table,
/// with shapes and defaults, is in docs/segmentation-service.md).
///
/// Inputs (raw contents little-endian, row-major; H x W is the image size):
///   rgb           UINT8  [H, W, 3] (or [1, H, W, 3])  RGB8; or instead:
///   image         BYTES  [1]     an encoded PNG or JPEG (decoded with OpenCV)
///   depth         FP32   [H, W]  z-depth in metres, 0 = no return (optional: all 0)
///   intrinsics    FP64   [6]     fx, fy, cx, cy, min_depth_m, max_depth_m (optional)
///   camera_pose   FP64   [4, 4]  X_WC, homogeneous, row-major (optional: identity)
///   instance_ids  UINT16 [H, W]  simulator labels (optional, with class_ids)
///   class_ids     UINT8  [H, W]  SemanticClass per pixel (optional, with instance_ids)
///   fruits        FP64   [F, 5]  instance_id, centre x, y, z (world, m), radius (m) (optional)
///   prompt        BYTES  [P]     class phrases; P > 1 phrases are joined with ", "
/// Request parameters: score_threshold (double), frame_index and seed (uint64, sent as int64
/// holding the same 64 bits), frame_id (string), stamp_ns (int64), mask_format (string: dense,
/// rle or instance_ids; default dense).
///
/// Outputs (N instances):
///   masks UINT8 [N, H, W] (nonzero = instance), classes INT32 [N] (SemanticClass),
///   scores FP32 [N], labels BYTES [N], boxes FP32 [N, 4] (x0, y0, x1, y1; 0 when has_box is
///   false), has_box BOOL [N], mask_scores FP32 [N] (negative = none).
///   With mask_format "rle" the masks come as mask_rle BYTES [N] (each element an instance's
///   COCO uncompressed RLE: little-endian UINT32 run lengths, column-major, starting with
///   background, summing to H x W; io::MaskToRle) and image_size INT32 [2] (H, W) instead of
///   `masks`; with "instance_ids" as mask_ids UINT16 [H, W] (0 = none, i + 1 = instance i; where
///   instances overlap the earlier, better-scoring one keeps the pixel) and image_size; both with
///   mask_on UINT8 [N], each mask's foreground value (1 from the oracle, 255 from the networks;
///   compact masks are binary: a mask with several nonzero values comes back with its first).
/// Response parameter: timings (string), a JSON array [{"stage": "...", "ms": 1.5}, ...].
namespace names {
inline constexpr std::string_view kRgb = "rgb";
inline constexpr std::string_view kImage = "image";
inline constexpr std::string_view kDepth = "depth";
inline constexpr std::string_view kIntrinsics = "intrinsics";
inline constexpr std::string_view kCameraPose = "camera_pose";
inline constexpr std::string_view kInstanceIds = "instance_ids";
inline constexpr std::string_view kClassIds = "class_ids";
inline constexpr std::string_view kFruits = "fruits";
inline constexpr std::string_view kPrompt = "prompt";

inline constexpr std::string_view kScoreThreshold = "score_threshold";
inline constexpr std::string_view kFrameIndex = "frame_index";
inline constexpr std::string_view kSeed = "seed";
inline constexpr std::string_view kFrameId = "frame_id";
inline constexpr std::string_view kStampNs = "stamp_ns";
inline constexpr std::string_view kMaskFormat = "mask_format";

inline constexpr std::string_view kMasks = "masks";
inline constexpr std::string_view kClasses = "classes";
inline constexpr std::string_view kScores = "scores";
inline constexpr std::string_view kLabels = "labels";
inline constexpr std::string_view kBoxes = "boxes";
inline constexpr std::string_view kHasBox = "has_box";
inline constexpr std::string_view kMaskScores = "mask_scores";
inline constexpr std::string_view kMaskRle = "mask_rle";
inline constexpr std::string_view kMaskIds = "mask_ids";
inline constexpr std::string_view kImageSize = "image_size";
inline constexpr std::string_view kMaskOn = "mask_on";

inline constexpr std::string_view kTimings = "timings";
}  // namespace names

/// A tensor of a model's signature as ModelMetadata lists it (-1 = variable dimension).
struct TensorSpec {
  std::string name;
  DataType datatype = DataType::kUint8;
  std::vector<int64_t> shape;
  bool optional = false;
  friend bool operator==(const TensorSpec&, const TensorSpec&) = default;
};

/// The inputs every segmentation model served by avp accepts, in the order above.
const std::vector<TensorSpec>& SegmentationInputs();
/// The outputs it returns, in the order above.
const std::vector<TensorSpec>& SegmentationOutputs();

/// How the server sends the masks (request parameter mask_format).
enum class MaskFormat : uint8_t {
  kDense = 0,        ///< `masks` UINT8 [N, H, W]: N x H x W bytes, what standard clients expect
  kRle = 1,          ///< `mask_rle` BYTES [N] + `image_size`: exact, a few kB per instance
  kInstanceIds = 2,  ///< `mask_ids` UINT16 [H, W] + `image_size`: 2 x H x W bytes for any N;
                     ///< overlaps keep only the earlier instance
};
/// "dense", "rle", "instance_ids".
std::string_view ToString(MaskFormat format);
std::optional<MaskFormat> MaskFormatFromString(std::string_view name);

/// How the client sends the colour image.
enum class ImageEncoding : uint8_t {
  kRaw = 0,   ///< `rgb` UINT8 [H, W, 3]: exact, the largest
  kPng = 1,   ///< `image` BYTES [1] holding a PNG: exact, smaller
  kJpeg = 2,  ///< `image` BYTES [1] holding a JPEG: lossy (results differ from in-process ones)
};
/// "raw", "png", "jpeg".
std::string_view ToString(ImageEncoding encoding);
std::optional<ImageEncoding> ImageEncodingFromString(std::string_view name);

struct RequestEncodeOptions {
  /// ModelInferRequest.model_name.
  std::string model_name = "oracle";
  /// The `seed` parameter (the server's seed of the segmenter); not sent when unset.
  std::optional<uint64_t> seed;
  ImageEncoding image = ImageEncoding::kRaw;
  /// 0 - 100, for ImageEncoding::kJpeg.
  int jpeg_quality = 95;
  /// Send the depth image (segmenters of images alone do not need it).
  bool send_depth = true;
  /// Send the simulator labels when the request has them.
  bool send_labels = true;
  /// The mask_format parameter (not sent for kDense, the protocol's default).
  MaskFormat mask_format = MaskFormat::kDense;
};

/// The KServe request for `request` (everything the OracleSegmenter reads crosses exactly, with
/// raw images). `id` is "<frame_id>@<stamp_ns>". InvalidArgument when request.frame is null or
/// invalid, the prompt is empty, or the labels do not match the frame's size; IoError when an
/// image cannot be encoded.
Result<InferRequest> EncodeSegmentationRequest(const segmentation::SegmentationRequest& request,
                                               const RequestEncodeOptions& options);

/// A request decoded on the server: it owns the frame and labels that request() points into.
struct DecodedSegmentationRequest {
  RgbdFrame frame;
  std::optional<SimulatorLabels> labels;
  std::string prompt;
  float score_threshold = 0.0f;
  uint64_t frame_index = 0;
  /// The `seed` parameter, when sent.
  std::optional<uint64_t> seed;
  /// How the answer's masks are to be sent.
  MaskFormat mask_format = MaskFormat::kDense;

  /// A SegmentationRequest pointing into this object: valid while it lives, unmoved.
  segmentation::SegmentationRequest request() const;
};

/// What one request may ask for. The server's come from its ServerOptions; each is named in the
/// refusal together with the `avp serve segmentation` flag that raises it.
struct RequestBudget {
  /// H x W of the colour image: from the shape of 'rgb', or from the PNG / JPEG header of 'image'
  /// (read before its pixels are decoded); also bounds depth and the label images.
  uint64_t max_image_pixels = uint64_t{16} << 20;
  /// Bytes of the prompt's phrases together.
  uint64_t max_prompt_bytes = 4096;
  /// Phrases of the prompt (its BYTES elements and comma-separated phrases), duplicates included.
  uint64_t max_prompt_phrases = 64;
};

/// Fixed bounds of the request format (not configurable: a valid request never comes near them).
inline constexpr size_t kMaxRequestInputs = 9;       ///< one of each known input
inline constexpr size_t kMaxRequestedOutputs = 11;   ///< one of each output
inline constexpr size_t kMaxRequestParameters = 64;  ///< known and unknown ones together
inline constexpr size_t kMaxStringParameterBytes = 1024;
inline constexpr int64_t kMaxFruits = 65535;  ///< one per UINT16 instance id
/// The most bytes a compact answer's masks (mask_rle, mask_ids) may expand to when decoded, N x H
/// x W (a dense answer is bounded by its message size already).
inline constexpr int64_t kMaxDecodedMaskBytes = int64_t{1} << 28;

/// The request's cost against `budget` and the format's fixed bounds, from shapes, counts and
/// image headers alone: nothing is decoded, copied or parsed into elements. ResourceExhausted
/// naming the limit (max_image_pixels, max_prompt_bytes, max_prompt_phrases) and how to raise
/// it; InvalidArgument for an unknown input name (quoted, escaped), too many inputs, outputs or
/// parameters, an over-long string parameter, an 'image' that is not BYTES [1] holding a PNG or
/// JPEG, or more fruit rows than kMaxFruits.
Status CheckRequestBudget(const InferRequest& request, const RequestBudget& budget);

/// The width and height in the header of an encoded PNG (IHDR) or JPEG (the first SOFn frame
/// header), without decoding it; nullopt when `bytes` is neither or the header is cut short.
std::optional<std::pair<uint32_t, uint32_t>> EncodedImageSize(std::string_view bytes);

/// Decodes and checks a request, after CheckRequestBudget(request, budget) passed (so nothing is
/// decoded for a request past its budget). InvalidArgument naming the tensor or parameter and
/// what was expected: an unknown input; a wrong datatype or shape; contents that do not match the
/// shape; neither or both of rgb and image; an image OpenCV cannot decode; an empty prompt; sizes
/// that differ from the image's; one of instance_ids / class_ids without the other; fruits
/// without labels; a pose that is not rigid; a bad parameter type or value.
Result<DecodedSegmentationRequest> DecodeSegmentationRequest(const InferRequest& request,
                                                             const RequestBudget& budget = {});

/// The outputs and parameters for `segmentation` (model name and id are left to the caller), its
/// masks in `format`. InvalidArgument when a mask's size differs from width x height, or (ids)
/// for more than 65535 instances.
Result<InferResponse> EncodeSegmentation(const Segmentation& segmentation,
                                         MaskFormat format = MaskFormat::kDense);

/// A Segmentation from a response's outputs: the masks (`masks`, or `mask_rle` or `mask_ids`
/// with `image_size`) and `scores` are required; `classes`
/// (default fruit), `labels` (default ""), `boxes` with `has_box` (default none; boxes without
/// has_box means every instance has one), `mask_scores` (default -1) and the `timings`
/// parameter are optional. ResourceExhausted when compact masks would expand beyond
/// kMaxDecodedMaskBytes. masks may also be BOOL. InvalidArgument naming the output on a wrong
/// datatype, shape, size or value.
Result<Segmentation> DecodeSegmentation(const InferResponse& response);

}  // namespace avp::segmentation_service

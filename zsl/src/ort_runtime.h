#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>
#include <avp/zsl/zsl.h>  // Device, RuntimeOptions

#include "tensor_model.h"

// ONNX Runtime's C++ types, for code that needs the raw session (IoBinding, device tensors).
// Include <onnxruntime_cxx_api.h> (target onnxruntime::onnxruntime) to use them; this header does
// not.
namespace Ort {
struct Session;
}  // namespace Ort

namespace avp::zsl {

/// The ONNX Runtime layer of the zero-shot backends (design: zero-shot-models.md §2, §3, §5, §7):
/// one process-wide `Ort::Env`, execution-provider (EP) selection, and `OrtModel`, one shared
/// session per model file. No ONNX Runtime exception leaves this layer: every failure is a Status
/// whose message names the model.

// ---- Sessions ----------------------------------------------------------------------------------

/// Session settings (design §5). Defaults: ORT's thread count, device auto, no spinning; inter-op
/// threads are always 1.
struct SessionOptions {
  /// Intra-op threads; 0 = ORT's default (one per physical core). Must be >= 0.
  int intra_op_threads = 0;
  Device device = Device::kAuto;
  /// `session.intra_op.allow_spinning`; false so that an idle service leaves the CPU free.
  bool allow_spinning = false;
  /// The CUDA device ordinal when CUDA is tried. Must be >= 0.
  int cuda_device_id = 0;
  /// "grpc://HOST:PORT": the backends run their networks on this KServe v2 server (avp serve
  /// models, Triton, ...), each model named by its manifest role, instead of in this process
  /// (RuntimeOptions::model_server). The other fields then do not apply. Empty: in process.
  std::string model_server;
  /// Dynamic batching of the networks run in process (RuntimeOptions::batching); max_batch 1 =
  /// off. Ignored with a model_server (the server batches, or not).
  segmentation_service::BatchingOptions batching;

  /// OK, or InvalidArgument listing every bad field: "intra_op_threads (-1) must be >= 0".
  Status Validate() const;
};

/// The session settings of the backends' public RuntimeOptions (zsl.h): its device and thread
/// count; allow_spinning and cuda_device_id keep their defaults.
SessionOptions ToSessionOptions(const RuntimeOptions& runtime);

/// The names ORT gives its providers, as `OrtModel::provider()` reports them.
inline constexpr const char* kCpuProvider = "CPUExecutionProvider";
inline constexpr const char* kCudaProvider = "CUDAExecutionProvider";

/// ORT's version string ("1.29.0").
std::string OrtVersion();

/// The providers compiled into the loaded ORT core (`Ort::GetAvailableProviders`). The asus4 core
/// lists only "CPUExecutionProvider" even though it can load the CUDA EP library (V1 path).
Result<std::vector<std::string>> AvailableProviders();

// ---- Tensors -----------------------------------------------------------------------------------

/// ONNX tensor element types (the ones the contracts use, plus a catch-all).
enum class ElementType {
  kUndefined,
  kFloat32,
  kFloat16,
  kFloat64,
  kInt8,
  kUint8,
  kInt16,
  kInt32,
  kInt64,
  kBool,
  kString,
  kOther,  ///< any other ONNX type (bfloat16, complex, …) or a non-tensor value
};

/// "float32", "float16", "float64", "int8", "uint8", "int16", "int32", "int64", "bool", "string",
/// "undefined", "other".
std::string_view ToString(ElementType type);

/// Parses the names `ToString` gives, plus "float" (= float32) and "double" (= float64).
/// Errors: InvalidArgument "element type 'f32' is not one of float32, …".
Result<ElementType> ParseElementType(std::string_view text);

/// A dimension that is not fixed in the graph (dynamic or symbolic), as ORT and manifests write it.
inline constexpr int64_t kDynamicDim = -1;

/// "[1,3,640,640]"; dynamic dimensions print as -1: "[-1,77]".
std::string ShapeToString(std::span<const int64_t> shape);

/// One graph input or output as declared by the model (or a manifest).
struct TensorInfo {
  std::string name;
  ElementType type = ElementType::kUndefined;
  std::vector<int64_t> shape;  ///< kDynamicDim (-1) for a dynamic axis

  size_t rank() const { return shape.size(); }
  friend bool operator==(const TensorInfo&, const TensorInfo&) = default;
};

/// A model's graph inputs and outputs, in graph order.
struct ModelIo {
  std::vector<TensorInfo> inputs;
  std::vector<TensorInfo> outputs;

  const TensorInfo* FindInput(std::string_view name) const;
  const TensorInfo* FindOutput(std::string_view name) const;
};

/// A non-owning input for `OrtModel::Run`: a name, an element type (float32, int64 or bool), a
/// shape and `count` contiguous row-major values that must outlive the call. Build with the
/// factories.
struct InputTensor {
  std::string name;
  ElementType type = ElementType::kUndefined;
  std::vector<int64_t> shape;
  const void* data = nullptr;
  size_t count = 0;

  static InputTensor Float32(std::string name, std::span<const float> values,
                             std::vector<int64_t> shape);
  static InputTensor Int64(std::string name, std::span<const int64_t> values,
                           std::vector<int64_t> shape);
  /// ORT booleans are one byte: 0 is false, anything else true.
  static InputTensor Bool(std::string name, std::span<const uint8_t> values,
                          std::vector<int64_t> shape);
};

/// One output of `OrtModel::Run`, copied out of ORT. float32 outputs fill `f32`; int64, int32 and
/// bool outputs fill `i64` (bool as 0/1). Values are row-major.
struct OutputTensor {
  std::string name;
  ElementType type = ElementType::kUndefined;
  std::vector<int64_t> shape;
  std::vector<float> f32;
  std::vector<int64_t> i64;

  /// The number of elements (product of `shape`).
  size_t size() const;
};

/// The output called `name`, or nullptr.
const OutputTensor* FindOutput(std::span<const OutputTensor> outputs, std::string_view name);

// ---- Models ------------------------------------------------------------------------------------

/// One ONNX model in one ORT session, shared by every caller (`Run` is thread-safe: ORT allows
/// concurrent `Session::Run` calls). Move-only. Created from a file or from bytes in memory.
///
/// The model's `label` (a manifest role such as "segmenter.decoder", or the file name) starts every
/// error message about it: "segmenter.decoder: cannot load '…/decoder.onnx': …".
class OrtModel final : public TensorModel {
 public:
  /// Loads `file` with `options`. On kAuto a CUDA failure falls back to CPU (see
  /// `cuda_fallback_reason()`); on kCuda it is an error.
  /// Errors: NotFound (no such file), InvalidArgument (bad options), FailedPrecondition (kCuda and
  /// the CUDA EP cannot be used: the message names the library or the reason), InvalidArgument
  /// (ORT cannot load the model: truncated, not ONNX, unsupported op). All start with the label.
  static Result<OrtModel> Load(const std::filesystem::path& file,
                               const SessionOptions& options = {}, std::string label = "");

  /// The same from a serialised ModelProto in memory (copied by ORT during the call). `label`
  /// defaults to "model".
  static Result<OrtModel> LoadFromBuffer(std::span<const std::byte> model_bytes,
                                         const SessionOptions& options = {},
                                         std::string label = "");

  OrtModel(OrtModel&&) noexcept;
  OrtModel& operator=(OrtModel&&) noexcept;
  ~OrtModel() override;

  /// The label errors start with.
  const std::string& label() const override;
  /// The file the model came from (empty for a buffer).
  const std::filesystem::path& file() const;

  /// "CPUExecutionProvider" or "CUDAExecutionProvider": the EP the session was created with.
  const std::string& provider() const override;
  /// kCpu or kCuda: where the session runs.
  Device device() const;
  /// Why CUDA was not used although the options allowed it (kAuto), e.g. "Failed to load library
  /// …/libonnxruntime_providers_cuda.so with error: … cannot open shared object file"; empty when
  /// CUDA is in use or was not asked for.
  const std::string& cuda_fallback_reason() const;

  /// Graph inputs and outputs with element types and shapes (-1 = dynamic).
  const ModelIo& io() const override;

  /// Runs the model. Every graph input must be bound exactly once, by name; each input's type must
  /// be the graph's, its shape must have the graph's rank and static dimensions, and `count` must
  /// be the product of its shape. `output_names` empty = all outputs, in graph order; otherwise
  /// those, in that order. Errors: InvalidArgument naming the label and the tensor ("detector:
  /// input 'txt_feats' has 100 values; shape [1,32,512] needs 16384"), or ORT's run error with the
  /// label.
  Result<std::vector<OutputTensor>> Run(
      std::span<const InputTensor> inputs,
      std::span<const std::string> output_names = {}) const override;

  /// The raw session for advanced use (IoBinding keeps tensors on the device). Include
  /// <onnxruntime_cxx_api.h>; catch Ort::Exception yourself.
  Ort::Session& session() const;

 private:
  struct Impl;
  explicit OrtModel(std::unique_ptr<Impl> impl);
  /// Load and LoadFromBuffer: from `file`, or from `bytes` when `file` is empty.
  static Result<OrtModel> Create(const std::filesystem::path& file,
                                 std::span<const std::byte> bytes, const SessionOptions& options,
                                 const std::string& label);
  std::unique_ptr<Impl> impl_;
};

/// OrtModel::Load, shared (LoadedModel::model).
Result<ModelRef> LoadOrtModel(const std::filesystem::path& file, const SessionOptions& options,
                              std::string label);

namespace internal {
/// Forgets the process-wide "CUDA failed under auto" state, so the next kAuto load tries CUDA again
/// and logs again. For tests.
void ResetCudaProbeForTesting();
/// How many times this process has tried to create a CUDA session (appended the CUDA EP). For
/// tests: a kCpu load never changes it.
int CudaAttemptCountForTesting();
}  // namespace internal

}  // namespace avp::zsl

// The ONNX Runtime layer: one Ort::Env, EP selection, OrtModel (design: zero-shot-models.md §3,
// §5).
#include "ort_runtime.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <optional>
#include <system_error>
#include <utility>

#include <fmt/format.h>
#include <onnxruntime_cxx_api.h>
#include <onnxruntime_session_options_config_keys.h>

#include <avp/segmentation_service/tensor_service.h>

namespace avp::zsl {

// ---- devices, element types, shapes ------------------------------------------------------------

std::string_view ToString(Device device) {
  switch (device) {
    case Device::kAuto:
      return "auto";
    case Device::kCpu:
      return "cpu";
    case Device::kCuda:
      return "cuda";
  }
  return "auto";
}

namespace {

std::string Trimmed(std::string_view text) {
  size_t begin = 0;
  size_t end = text.size();
  while (begin < end && std::isspace(static_cast<unsigned char>(text[begin]))) ++begin;
  while (end > begin && std::isspace(static_cast<unsigned char>(text[end - 1]))) --end;
  return std::string(text.substr(begin, end - begin));
}

std::string Lowered(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

/// One line: newlines and tabs become spaces.
std::string OneLine(std::string text) {
  for (char& c : text) {
    if (c == '\n' || c == '\r' || c == '\t') c = ' ';
  }
  return Trimmed(text);
}

/// ORT status text without its source location: "/onnxruntime_src/…cc:1988 … [ONNXRuntimeError] :
/// 1 : FAIL : Failed to load library …" becomes "Failed to load library …".
std::string CleanOrtMessage(std::string message) {
  const std::string marker = "[ONNXRuntimeError] : ";
  const size_t at = message.find(marker);
  if (at != std::string::npos) {
    size_t pos = at + marker.size();
    for (int i = 0; i < 2; ++i) {  // the numeric code, then the code name
      const size_t sep = message.find(" : ", pos);
      if (sep == std::string::npos) break;
      pos = sep + 3;
    }
    message = message.substr(pos);
  }
  return OneLine(std::move(message));
}

}  // namespace

Result<Device> ParseDevice(std::string_view text) {
  const std::string value = Lowered(Trimmed(text));
  if (value == "auto") return Device::kAuto;
  if (value == "cpu") return Device::kCpu;
  if (value == "cuda") return Device::kCuda;
  return InvalidArgumentError(fmt::format("device '{}' is not one of auto, cpu, cuda", text));
}

Result<Device> DeviceFromEnvironment() {
  const char* value = std::getenv(kDeviceEnvVar);
  if (value == nullptr || Trimmed(value).empty()) return Device::kAuto;
  Result<Device> device = ParseDevice(value);
  if (!device.ok()) return device.status().WithContext(kDeviceEnvVar);
  return device;
}

Status SessionOptions::Validate() const {
  std::vector<std::string> errors;
  if (intra_op_threads < 0) {
    errors.push_back(fmt::format("intra_op_threads ({}) must be >= 0", intra_op_threads));
  }
  if (cuda_device_id < 0) {
    errors.push_back(fmt::format("cuda_device_id ({}) must be >= 0", cuda_device_id));
  }
  if (!model_server.empty()) {
    if (Result<std::string> a = segmentation_service::ParseGrpcAddress(model_server); !a.ok()) {
      errors.push_back(a.status().message());
    }
  }
  if (Status b = batching.Validate(); !b.ok()) errors.push_back(b.message());
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid session options: {}", fmt::join(errors, "; ")));
}

SessionOptions ToSessionOptions(const RuntimeOptions& runtime) {
  SessionOptions session;
  session.intra_op_threads = runtime.intra_op_threads;
  session.device = runtime.device;
  session.model_server = runtime.model_server;
  session.batching = runtime.batching;
  return session;
}

std::string_view ToString(ElementType type) {
  switch (type) {
    case ElementType::kUndefined:
      return "undefined";
    case ElementType::kFloat32:
      return "float32";
    case ElementType::kFloat16:
      return "float16";
    case ElementType::kFloat64:
      return "float64";
    case ElementType::kInt8:
      return "int8";
    case ElementType::kUint8:
      return "uint8";
    case ElementType::kInt16:
      return "int16";
    case ElementType::kInt32:
      return "int32";
    case ElementType::kInt64:
      return "int64";
    case ElementType::kBool:
      return "bool";
    case ElementType::kString:
      return "string";
    case ElementType::kOther:
      return "other";
  }
  return "other";
}

Result<ElementType> ParseElementType(std::string_view text) {
  static constexpr ElementType kAll[] = {
      ElementType::kFloat32, ElementType::kFloat16, ElementType::kFloat64, ElementType::kInt8,
      ElementType::kUint8,   ElementType::kInt16,   ElementType::kInt32,   ElementType::kInt64,
      ElementType::kBool,    ElementType::kString};
  if (text == "float") return ElementType::kFloat32;
  if (text == "double") return ElementType::kFloat64;
  for (ElementType type : kAll) {
    if (text == ToString(type)) return type;
  }
  return InvalidArgumentError(
      fmt::format("element type '{}' is not one of float32, float16, float64, int8, uint8, int16, "
                  "int32, int64, "
                  "bool, string",
                  text));
}

std::string ShapeToString(std::span<const int64_t> shape) {
  return fmt::format("[{}]", fmt::join(shape, ","));
}

const TensorInfo* ModelIo::FindInput(std::string_view name) const {
  for (const TensorInfo& t : inputs) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

const TensorInfo* ModelIo::FindOutput(std::string_view name) const {
  for (const TensorInfo& t : outputs) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

InputTensor InputTensor::Float32(std::string name, std::span<const float> values,
                                 std::vector<int64_t> shape) {
  return {std::move(name), ElementType::kFloat32, std::move(shape), values.data(), values.size()};
}

InputTensor InputTensor::Int64(std::string name, std::span<const int64_t> values,
                               std::vector<int64_t> shape) {
  return {std::move(name), ElementType::kInt64, std::move(shape), values.data(), values.size()};
}

InputTensor InputTensor::Bool(std::string name, std::span<const uint8_t> values,
                              std::vector<int64_t> shape) {
  return {std::move(name), ElementType::kBool, std::move(shape), values.data(), values.size()};
}

size_t OutputTensor::size() const {
  size_t n = 1;
  for (int64_t d : shape) n *= static_cast<size_t>(std::max<int64_t>(d, 0));
  return n;
}

const OutputTensor* FindOutput(std::span<const OutputTensor> outputs, std::string_view name) {
  for (const OutputTensor& t : outputs) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

// ---- the process-wide environment --------------------------------------------------------------

namespace {

// While a thread tries the CUDA EP, ORT's log lines from that thread are collected here instead of
// printed: they carry the reason (the library and dlerror text) that the exception lacks.
thread_local std::vector<std::string>* t_log_capture = nullptr;

void ORT_API_CALL LogToStderr(void* /*param*/, OrtLoggingLevel severity, const char* /*category*/,
                              const char* /*logid*/, const char* /*code_location*/,
                              const char* message) {
  if (t_log_capture != nullptr) {
    t_log_capture->push_back(message != nullptr ? message : "");
    return;
  }
  static constexpr const char* kLevel[] = {"verbose", "info", "warning", "error", "fatal"};
  const int level = std::clamp(static_cast<int>(severity), 0, 4);
  std::fprintf(stderr, "onnxruntime %s: %s\n", kLevel[level],
               CleanOrtMessage(message != nullptr ? message : "").c_str());
}

struct EnvHolder {
  std::unique_ptr<Ort::Env> env;
  std::string error;
};

/// The one Ort::Env of the process, created on first use and never destroyed (sessions held in
/// other static objects may outlive any destruction order we could pick).
Result<Ort::Env*> Env() {
  static EnvHolder* holder = [] {
    auto* h = new EnvHolder;
    try {
      h->env = std::make_unique<Ort::Env>(ORT_LOGGING_LEVEL_WARNING, "avp", LogToStderr, nullptr);
    } catch (const Ort::Exception& e) {
      h->error = CleanOrtMessage(e.what());
    }
    return h;
  }();
  if (holder->env == nullptr) {
    return FailedPreconditionError(
        fmt::format("cannot create the ONNX Runtime environment: {}", holder->error));
  }
  return holder->env.get();
}

/// What kAuto learnt about CUDA in this process: after one failure, later kAuto loads go straight
/// to CPU with the same reason, and the reason is logged once.
struct CudaProbe {
  std::mutex mutex;
  bool failed = false;
  bool logged = false;
  std::string reason;
};

CudaProbe& Probe() {
  static CudaProbe* probe = new CudaProbe;
  return *probe;
}

std::atomic<int> g_cuda_attempts{0};

}  // namespace

namespace internal {
void ResetCudaProbeForTesting() {
  CudaProbe& probe = Probe();
  std::lock_guard<std::mutex> lock(probe.mutex);
  probe.failed = false;
  probe.logged = false;
  probe.reason.clear();
}
int CudaAttemptCountForTesting() { return g_cuda_attempts.load(); }
}  // namespace internal

std::string OrtVersion() {
  try {
    return Ort::GetVersionString();
  } catch (const Ort::Exception& e) {
    return fmt::format("unknown ({})", CleanOrtMessage(e.what()));
  }
}

Result<std::vector<std::string>> AvailableProviders() {
  try {
    return Ort::GetAvailableProviders();
  } catch (const Ort::Exception& e) {
    return FailedPreconditionError(
        fmt::format("cannot list ONNX Runtime providers: {}", CleanOrtMessage(e.what())));
  }
}

// ---- OrtModel ----------------------------------------------------------------------------------

namespace {

ElementType FromOnnx(ONNXTensorElementDataType type) {
  switch (type) {
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_UNDEFINED:
      return ElementType::kUndefined;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT:
      return ElementType::kFloat32;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT16:
      return ElementType::kFloat16;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_DOUBLE:
      return ElementType::kFloat64;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_INT8:
      return ElementType::kInt8;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_UINT8:
      return ElementType::kUint8;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_INT16:
      return ElementType::kInt16;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_INT32:
      return ElementType::kInt32;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_INT64:
      return ElementType::kInt64;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_BOOL:
      return ElementType::kBool;
    case ONNX_TENSOR_ELEMENT_DATA_TYPE_STRING:
      return ElementType::kString;
    default:
      return ElementType::kOther;
  }
}

/// The ONNX type and byte size of the element types `Run` accepts as inputs.
bool ToOnnx(ElementType type, ONNXTensorElementDataType& onnx, size_t& bytes) {
  switch (type) {
    case ElementType::kFloat32:
      onnx = ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT;
      bytes = sizeof(float);
      return true;
    case ElementType::kInt64:
      onnx = ONNX_TENSOR_ELEMENT_DATA_TYPE_INT64;
      bytes = sizeof(int64_t);
      return true;
    case ElementType::kBool:
      onnx = ONNX_TENSOR_ELEMENT_DATA_TYPE_BOOL;
      bytes = 1;
      return true;
    default:
      return false;
  }
}

TensorInfo ReadTensorInfo(std::string name, const Ort::TypeInfo& type_info) {
  TensorInfo info;
  info.name = std::move(name);
  if (type_info.GetONNXType() != ONNX_TYPE_TENSOR) {
    info.type = ElementType::kOther;
    return info;
  }
  // `type_info` stays alive while its tensor view is read: a temporary gives an empty shape (§7).
  const auto tensor = type_info.GetTensorTypeAndShapeInfo();
  info.type = FromOnnx(tensor.GetElementType());
  info.shape = tensor.GetShape();
  for (int64_t& d : info.shape) {
    if (d < 0) d = kDynamicDim;
  }
  return info;
}

ModelIo ReadIo(Ort::Session& session) {
  ModelIo io;
  Ort::AllocatorWithDefaultOptions allocator;
  for (size_t i = 0; i < session.GetInputCount(); ++i) {
    const Ort::AllocatedStringPtr name = session.GetInputNameAllocated(i, allocator);
    const Ort::TypeInfo type_info = session.GetInputTypeInfo(i);
    io.inputs.push_back(ReadTensorInfo(name.get(), type_info));
  }
  for (size_t i = 0; i < session.GetOutputCount(); ++i) {
    const Ort::AllocatedStringPtr name = session.GetOutputNameAllocated(i, allocator);
    const Ort::TypeInfo type_info = session.GetOutputTypeInfo(i);
    io.outputs.push_back(ReadTensorInfo(name.get(), type_info));
  }
  return io;
}

/// Where the model comes from: a file, or bytes in memory.
struct ModelSource {
  std::filesystem::path file;
  std::span<const std::byte> bytes;

  std::string Describe() const {
    return file.empty() ? fmt::format("a {}-byte buffer", bytes.size())
                        : fmt::format("'{}'", file.string());
  }
};

std::unique_ptr<Ort::Session> NewSession(Ort::Env& env, const ModelSource& source,
                                         const Ort::SessionOptions& options) {
  if (!source.file.empty()) {
    return std::make_unique<Ort::Session>(env, source.file.c_str(), options);
  }
  return std::make_unique<Ort::Session>(env, source.bytes.data(), source.bytes.size(), options);
}

Ort::SessionOptions BaseOptions(const SessionOptions& options) {
  Ort::SessionOptions so;
  so.SetIntraOpNumThreads(options.intra_op_threads);  // 0 = ORT's default
  so.SetInterOpNumThreads(1);
  so.SetExecutionMode(ORT_SEQUENTIAL);
  so.SetGraphOptimizationLevel(GraphOptimizationLevel::ORT_ENABLE_ALL);
  const char* spin = options.allow_spinning ? "1" : "0";
  so.AddConfigEntry(kOrtSessionOptionsConfigAllowIntraOpSpinning, spin);
  so.AddConfigEntry(kOrtSessionOptionsConfigAllowInterOpSpinning, spin);
  return so;
}

/// The most useful line among ORT's captured log lines and its exception text.
std::string CudaReason(const std::vector<std::string>& log, const std::string& what) {
  std::vector<std::string> lines;
  for (const std::string& line : log) {
    std::string cleaned = CleanOrtMessage(line);
    if (!cleaned.empty() && std::find(lines.begin(), lines.end(), cleaned) == lines.end()) {
      lines.push_back(std::move(cleaned));
    }
  }
  std::string reason = CleanOrtMessage(what);
  if (lines.empty()) return reason;
  // The log names the library ("Failed to load library …/libonnxruntime_providers_cuda.so with
  // error: …"); the exception only says "Failed to load shared library".
  return fmt::format("{} ({})", fmt::join(lines, "; "), reason);
}

enum class CudaStage { kNone, kAppend, kSession };

}  // namespace

struct OrtModel::Impl {
  std::string label;
  std::filesystem::path file;
  std::unique_ptr<Ort::Session> session;
  std::string provider;
  Device device = Device::kCpu;
  std::string cuda_fallback_reason;
  ModelIo io;
};

OrtModel::OrtModel(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
OrtModel::OrtModel(OrtModel&&) noexcept = default;
OrtModel& OrtModel::operator=(OrtModel&&) noexcept = default;
OrtModel::~OrtModel() = default;

Result<ModelRef> LoadOrtModel(const std::filesystem::path& file, const SessionOptions& options,
                              std::string label) {
  AVP_ASSIGN_OR_RETURN(OrtModel model, OrtModel::Load(file, options, std::move(label)));
  return ModelRef(std::make_shared<const OrtModel>(std::move(model)));
}

Result<OrtModel> OrtModel::Load(const std::filesystem::path& file, const SessionOptions& options,
                                std::string label) {
  if (label.empty()) label = file.filename().string();
  std::error_code ec;
  if (file.empty() || !std::filesystem::is_regular_file(file, ec)) {
    return NotFoundError(fmt::format("{}: model file '{}' does not exist", label, file.string()));
  }
  return Create(file, {}, options, label);
}

Result<OrtModel> OrtModel::LoadFromBuffer(std::span<const std::byte> model_bytes,
                                          const SessionOptions& options, std::string label) {
  if (label.empty()) label = "model";
  if (model_bytes.empty())
    return InvalidArgumentError(fmt::format("{}: empty model buffer", label));
  return Create({}, model_bytes, options, label);
}

namespace {

/// A try to make a CUDA session: the session, or why not and at which stage.
struct CudaAttempt {
  std::unique_ptr<Ort::Session> session;
  std::string reason;
  CudaStage failed_stage = CudaStage::kNone;
};

/// Collects this thread's ORT log lines until the attempt is over, whatever happens.
class LogCapture {
 public:
  explicit LogCapture(std::vector<std::string>* lines) { t_log_capture = lines; }
  ~LogCapture() { t_log_capture = nullptr; }
  LogCapture(const LogCapture&) = delete;
  LogCapture& operator=(const LogCapture&) = delete;
};

CudaAttempt TryCudaSession(Ort::Env& env, const ModelSource& source,
                           const SessionOptions& options) {
  ++g_cuda_attempts;
  CudaAttempt attempt;
  std::vector<std::string> log;
  std::optional<LogCapture> capture(std::in_place, &log);
  CudaStage stage = CudaStage::kAppend;
  try {
    Ort::SessionOptions so = BaseOptions(options);
    OrtCUDAProviderOptions cuda;  // the V1 path (§3): V2 reports "not enabled in this build"
    cuda.device_id = options.cuda_device_id;
    so.AppendExecutionProvider_CUDA(cuda);
    stage = CudaStage::kSession;
    attempt.session = NewSession(env, source, so);
  } catch (const Ort::Exception& e) {
    attempt.reason = CudaReason(log, e.what());
    attempt.failed_stage = stage;
  } catch (const std::exception& e) {
    attempt.reason = OneLine(e.what());
    attempt.failed_stage = stage;
  }
  capture.reset();
  if (attempt.failed_stage == CudaStage::kNone) {
    // CUDA works: what ORT said meanwhile (e.g. nodes placed on CPU) is printed as usual.
    for (const std::string& line : log) {
      std::fprintf(stderr, "onnxruntime: %s\n", CleanOrtMessage(line).c_str());
    }
  }
  return attempt;
}

/// The CPU session, when CUDA was not tried or failed.
Result<std::unique_ptr<Ort::Session>> CpuSession(Ort::Env& env, const ModelSource& source,
                                                 const SessionOptions& options,
                                                 const std::string& label) {
  try {
    return NewSession(env, source, BaseOptions(options));
  } catch (const Ort::Exception& e) {
    // Not a CUDA problem (CPU fails too): do not blame CUDA for it.
    return InvalidArgumentError(fmt::format("{}: ONNX Runtime cannot load {}: {}", label,
                                            source.Describe(), CleanOrtMessage(e.what())));
  } catch (const std::exception& e) {
    return InternalError(
        fmt::format("{}: cannot load {}: {}", label, source.Describe(), OneLine(e.what())));
  }
}

/// device auto on CPU: remembers a CUDA failure for the process and logs the fallback once.
/// Returns why this model runs on CPU ("" when CUDA was never found wanting).
std::string RecordCpuFallback(const CudaAttempt& attempt, const std::string& known_reason) {
  CudaProbe& probe = Probe();
  std::lock_guard<std::mutex> lock(probe.mutex);
  if (attempt.failed_stage != CudaStage::kNone) {
    probe.failed = true;
    probe.reason = attempt.reason;
  }
  const std::string reason =
      attempt.failed_stage != CudaStage::kNone ? attempt.reason : known_reason;
  if (!probe.logged && !reason.empty()) {
    probe.logged = true;
    std::fprintf(stderr, "avp zsl: CUDA is not available, running on CPU (%s=auto): %s\n",
                 kDeviceEnvVar, reason.c_str());
  }
  return reason;
}

}  // namespace

Result<OrtModel> OrtModel::Create(const std::filesystem::path& file,
                                  std::span<const std::byte> bytes, const SessionOptions& options,
                                  const std::string& label) {
  ModelSource source;
  source.file = file;
  source.bytes = bytes;
  Status valid = options.Validate();
  if (!valid.ok()) return valid.WithContext(label);
  AVP_ASSIGN_OR_RETURN(Ort::Env * env, Env());

  auto impl = std::make_unique<Impl>();
  impl->label = label;

  // CUDA first, unless the options say CPU or kAuto already saw CUDA fail in this process.
  bool try_cuda = options.device != Device::kCpu;
  std::string known_reason;
  if (options.device == Device::kAuto) {
    CudaProbe& probe = Probe();
    std::lock_guard<std::mutex> lock(probe.mutex);
    if (probe.failed) {
      try_cuda = false;
      known_reason = probe.reason;
    }
  }
  CudaAttempt cuda;
  if (try_cuda) {
    cuda = TryCudaSession(*env, source, options);
    if (cuda.failed_stage == CudaStage::kAppend && options.device == Device::kCuda) {
      return FailedPreconditionError(
          fmt::format("{}: AVP_ZSL_DEVICE=cuda but the CUDA execution provider cannot be used: {}",
                      label, cuda.reason));
    }
    if (cuda.failed_stage != CudaStage::kNone && options.device == Device::kCuda) {
      return FailedPreconditionError(fmt::format("{}: cannot create a CUDA session for {}: {}",
                                                 label, source.Describe(), cuda.reason));
    }
  }
  if (cuda.session != nullptr) {
    impl->session = std::move(cuda.session);
    impl->provider = kCudaProvider;
    impl->device = Device::kCuda;
  } else {
    AVP_ASSIGN_OR_RETURN(impl->session, CpuSession(*env, source, options, label));
    impl->provider = kCpuProvider;
    impl->device = Device::kCpu;
    if (options.device == Device::kAuto) {
      impl->cuda_fallback_reason = RecordCpuFallback(cuda, known_reason);
    }
  }

  try {
    impl->io = ReadIo(*impl->session);
  } catch (const Ort::Exception& e) {
    return InternalError(fmt::format("{}: cannot read the model's inputs and outputs: {}", label,
                                     CleanOrtMessage(e.what())));
  }
  impl->file = file;
  return OrtModel(std::move(impl));
}

const std::string& OrtModel::label() const { return impl_->label; }
const std::filesystem::path& OrtModel::file() const { return impl_->file; }
const std::string& OrtModel::provider() const { return impl_->provider; }
Device OrtModel::device() const { return impl_->device; }
const std::string& OrtModel::cuda_fallback_reason() const { return impl_->cuda_fallback_reason; }
const ModelIo& OrtModel::io() const { return impl_->io; }
const std::vector<TensorInfo>& TensorModel::inputs() const { return io().inputs; }
const std::vector<TensorInfo>& TensorModel::outputs() const { return io().outputs; }
Ort::Session& OrtModel::session() const { return *impl_->session; }

// ---- OrtModel::Run's stages ---------------------------------------------------------------------

namespace {

/// The names of `tensors` joined by "', '", for "(it has 'a', 'b')".
std::string JoinedNames(const std::vector<TensorInfo>& tensors) {
  std::vector<std::string> names;
  for (const TensorInfo& t : tensors) names.push_back(t.name);
  return fmt::format("{}", fmt::join(names, "', '"));
}

/// OK when `in` (one of `inputs`) binds a graph input of `io` exactly once, with the graph's type,
/// rank and static dimensions, as many values as its shape needs, and data.
Status CheckInput(const std::string& label, const ModelIo& io, std::span<const InputTensor> inputs,
                  const InputTensor& in) {
  const TensorInfo* info = io.FindInput(in.name);
  if (info == nullptr) {
    return InvalidArgumentError(fmt::format("{}: the model has no input '{}' (it has '{}')", label,
                                            in.name, JoinedNames(io.inputs)));
  }
  const auto same = std::count_if(inputs.begin(), inputs.end(),
                                  [&](const InputTensor& o) { return o.name == in.name; });
  if (same > 1) {
    return InvalidArgumentError(
        fmt::format("{}: input '{}' is bound {} times", label, in.name, same));
  }
  if (in.type != info->type) {
    return InvalidArgumentError(fmt::format("{}: input '{}' is given as {}; the model takes {}",
                                            label, in.name, ToString(in.type),
                                            ToString(info->type)));
  }
  bool shape_ok = in.shape.size() == info->shape.size();
  size_t count = 1;
  for (size_t d = 0; d < in.shape.size(); ++d) {
    if (in.shape[d] < 0) shape_ok = false;
    if (shape_ok && info->shape[d] != kDynamicDim && info->shape[d] != in.shape[d]) {
      shape_ok = false;
    }
    count *= static_cast<size_t>(std::max<int64_t>(in.shape[d], 0));
  }
  if (!shape_ok) {
    return InvalidArgumentError(fmt::format("{}: input '{}' has shape {}; the model takes {}",
                                            label, in.name, ShapeToString(in.shape),
                                            ShapeToString(info->shape)));
  }
  if (count != in.count) {
    return InvalidArgumentError(fmt::format("{}: input '{}' has {} values; shape {} needs {}",
                                            label, in.name, in.count, ShapeToString(in.shape),
                                            count));
  }
  if (in.data == nullptr && in.count > 0) {
    return InvalidArgumentError(fmt::format("{}: input '{}' has no data", label, in.name));
  }
  return Status::Ok();
}

/// OK when `inputs` bind each graph input of `io` exactly once (CheckInput, in input order), then
/// no graph input is left unbound.
Status CheckInputs(const std::string& label, const ModelIo& io,
                   std::span<const InputTensor> inputs) {
  for (const InputTensor& in : inputs) AVP_RETURN_IF_ERROR(CheckInput(label, io, inputs, in));
  for (const TensorInfo& t : io.inputs) {
    const bool bound = std::any_of(inputs.begin(), inputs.end(),
                                   [&](const InputTensor& in) { return in.name == t.name; });
    if (!bound) {
      return InvalidArgumentError(fmt::format("{}: input '{}' ({} {}) is not bound", label, t.name,
                                              ToString(t.type), ShapeToString(t.shape)));
    }
  }
  return Status::Ok();
}

/// The outputs Run fetches: `output_names`, or every graph output (in graph order) when it is
/// empty. Errors: a name the model has no output of.
Result<std::vector<std::string>> OutputsToFetch(const std::string& label, const ModelIo& io,
                                                std::span<const std::string> output_names) {
  std::vector<std::string> wanted(output_names.begin(), output_names.end());
  if (wanted.empty()) {
    for (const TensorInfo& t : io.outputs) wanted.push_back(t.name);
  }
  for (const std::string& name : wanted) {
    if (io.FindOutput(name) == nullptr) {
      return InvalidArgumentError(fmt::format("{}: the model has no output '{}' (it has '{}')",
                                              label, name, JoinedNames(io.outputs)));
    }
  }
  return wanted;
}

/// ORT tensors over the callers' buffers (no copy), in input order. Errors: an element type Run
/// does not bind. ORT exceptions propagate.
Result<std::vector<Ort::Value>> InputValues(const std::string& label, const Ort::MemoryInfo& memory,
                                            std::span<const InputTensor> inputs) {
  std::vector<Ort::Value> values;
  values.reserve(inputs.size());
  for (const InputTensor& in : inputs) {
    ONNXTensorElementDataType onnx_type{};
    size_t bytes = 0;
    if (!ToOnnx(in.type, onnx_type, bytes)) {
      return InvalidArgumentError(
          fmt::format("{}: input '{}' is {}; Run binds float32, int64 "
                      "and bool inputs",
                      label, in.name, ToString(in.type)));
    }
    // ORT does not write to inputs; its API takes a non-const pointer all the same.
    values.push_back(Ort::Value::CreateTensor(memory, const_cast<void*>(in.data), in.count * bytes,
                                              in.shape.data(), in.shape.size(), onnx_type));
  }
  return values;
}

/// `out` = the `n` values of the tensor `value`, whose elements are `T`, converted to `U`.
template <typename T, typename U>
void CopyValues(const Ort::Value& value, size_t n, std::vector<U>& out) {
  const T* p = value.GetTensorData<T>();
  out.assign(p, p + n);
}

/// Output `name` (`value`) copied out of ORT: float32 into `f32`; int64, int32 and bool into `i64`
/// (bool as 0/1). Errors: not a tensor, or another element type. ORT exceptions propagate.
Result<OutputTensor> CopyOutput(const std::string& label, const std::string& name,
                                const Ort::Value& value) {
  OutputTensor out;
  out.name = name;
  if (!value.IsTensor()) {
    return InvalidArgumentError(fmt::format("{}: output '{}' is not a tensor", label, out.name));
  }
  const auto info = value.GetTensorTypeAndShapeInfo();
  out.type = FromOnnx(info.GetElementType());
  out.shape = info.GetShape();
  const size_t n = info.GetElementCount();
  switch (out.type) {
    case ElementType::kFloat32:
      CopyValues<float>(value, n, out.f32);
      break;
    case ElementType::kInt64:
      CopyValues<int64_t>(value, n, out.i64);
      break;
    case ElementType::kInt32:
      CopyValues<int32_t>(value, n, out.i64);
      break;
    case ElementType::kBool:  // ORT booleans convert to 0 / 1
      CopyValues<bool>(value, n, out.i64);
      break;
    default:
      return InvalidArgumentError(
          fmt::format("{}: output '{}' is {}; Run returns float32, int64, int32 and bool outputs",
                      label, out.name, ToString(out.type)));
  }
  return out;
}

}  // namespace

Result<std::vector<OutputTensor>> OrtModel::Run(std::span<const InputTensor> inputs,
                                                std::span<const std::string> output_names) const {
  const std::string& label = impl_->label;
  AVP_RETURN_IF_ERROR(CheckInputs(label, impl_->io, inputs));
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> wanted,
                       OutputsToFetch(label, impl_->io, output_names));
  try {
    const Ort::MemoryInfo memory = Ort::MemoryInfo::CreateCpu(OrtArenaAllocator, OrtMemTypeDefault);
    AVP_ASSIGN_OR_RETURN(std::vector<Ort::Value> values, InputValues(label, memory, inputs));
    std::vector<const char*> in_names;
    for (const InputTensor& in : inputs) in_names.push_back(in.name.c_str());
    std::vector<const char*> out_names;
    for (const std::string& name : wanted) out_names.push_back(name.c_str());

    std::vector<Ort::Value> results =
        impl_->session->Run(Ort::RunOptions{nullptr}, in_names.data(), values.data(), values.size(),
                            out_names.data(), out_names.size());

    std::vector<OutputTensor> outputs;
    outputs.reserve(results.size());
    for (size_t i = 0; i < results.size(); ++i) {
      AVP_ASSIGN_OR_RETURN(OutputTensor out, CopyOutput(label, wanted[i], results[i]));
      outputs.push_back(std::move(out));
    }
    return outputs;
  } catch (const Ort::Exception& e) {
    return InvalidArgumentError(
        fmt::format("{}: ONNX Runtime run failed: {}", label, CleanOrtMessage(e.what())));
  } catch (const std::exception& e) {
    return InternalError(fmt::format("{}: run failed: {}", label, OneLine(e.what())));
  }
}

}  // namespace avp::zsl

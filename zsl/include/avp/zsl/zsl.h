#pragma once

#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>
#include <avp/interop/tensor_service.h>  // BatchingOptions

namespace avp::zsl {

/// True when this build has ONNX Runtime (AVP_WITH_ONNX), i.e. the ywes and lsam backends. The
/// functions below, like the backends, are defined only in such builds.
bool BuiltWithOnnxRuntime();

// ---- Devices and sessions, as the backends' options take them ----------------------------------

/// Which execution provider the backends' ONNX Runtime sessions use.
enum class Device {
  kAuto,  ///< try CUDA; on failure log the reason once (one stderr line) and run on CPU
  kCpu,   ///< CPU only; CUDA is never tried
  kCuda,  ///< CUDA or an error naming the library or reason
};

/// The environment variable that selects the device: `auto` (default), `cpu` or `cuda`.
inline constexpr const char* kDeviceEnvVar = "AVP_ZSL_DEVICE";

/// "auto", "cpu", "cuda".
std::string_view ToString(Device device);

/// Parses "auto", "cpu" or "cuda" (ASCII case-insensitive, surrounding blanks ignored).
/// Errors: InvalidArgument naming the text, e.g. "device 'gpu' is not one of auto, cpu, cuda".
Result<Device> ParseDevice(std::string_view text);

/// The device `AVP_ZSL_DEVICE` asks for: kAuto when it is unset or empty. Errors: InvalidArgument
/// "AVP_ZSL_DEVICE: device 'gpu' is not one of auto, cpu, cuda".
Result<Device> DeviceFromEnvironment();

/// How a backend runs its ONNX Runtime sessions (design: zero-shot-models.md §5). Inter-op threads
/// are always 1, and an idle session does not spin.
struct RuntimeOptions {
  /// Intra-op threads; 0 = ORT's default (one per physical core). Must be >= 0.
  int intra_op_threads = 0;
  Device device = Device::kAuto;
  /// "grpc://HOST:PORT": run the networks on this KServe v2 / Open Inference Protocol server
  /// (`avp serve models`, Triton, OpenVINO Model Server, KServe), each model named by its manifest
  /// role; tokenisation, letterbox, NMS and the mask chain stay here. Empty: in this process.
  /// AVP_ZSL_MODEL_SERVER sets it for the "ywes" / "lsam" segmenter specs.
  std::string model_server;
  /// In process (no model_server), max_batch > 1: each network whose inputs and outputs all have
  /// a dynamic leading axis is loaded once per process and shared by every backend instance
  /// with the same file and settings, its concurrent calls stacked (interop::BatchingHandler).
  /// AVP_ZSL_MAX_BATCH and AVP_ZSL_BATCH_DELAY_US set max_batch and max_delay for the specs.
  interop::BatchingOptions batching;
};

/// A network loaded with RuntimeOptions::batching and alive in this process (shared by the
/// backend instances that use it), and what its batcher has done.
struct BatchedNetwork {
  std::string role;  ///< its manifest role ("text")
  std::string file;  ///< the .onnx file
  interop::BatchingOptions options;
  interop::BatchingStats stats;
};
/// The batched networks alive now (none in a build without ONNX Runtime).
std::vector<BatchedNetwork> BatchedNetworks();

}  // namespace avp::zsl

#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/segmentation_service/tensor_service.h>  // BatchingOptions

namespace avp::zsl {

/// True when this build has ONNX Runtime (AVP_WITH_ONNX), i.e. the ywes and lsam backends. The
/// functions below, like the backends, are defined only in such builds (BackendSettings and its
/// table in every build).
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
  /// The registered "ywes" / "lsam" take it from BackendSettings::model_server.
  std::string model_server;
  /// In process (no model_server), max_batch > 1: each network whose inputs and outputs all have
  /// a dynamic leading axis is loaded once per process and shared by every backend instance
  /// with the same file and settings, its concurrent calls stacked
  /// (segmentation_service::BatchingHandler). The registered "ywes" / "lsam" take max_batch and
  /// max_delay from BackendSettings.
  segmentation_service::BatchingOptions batching;
};

// ---- The registered backends' shared settings (the "ywes" / "lsam" option tables) -------------

/// The environment variables that give BackendSettings its defaults (read once, at start-up, by
/// BackendSettingsFromEnvironment; never while segmenting).
inline constexpr const char* kModelDirEnvVar = "AVP_ZSL_MODEL_DIR";
inline constexpr const char* kModelServerEnvVar = "AVP_ZSL_MODEL_SERVER";
inline constexpr const char* kMaxBatchEnvVar = "AVP_ZSL_MAX_BATCH";
inline constexpr const char* kBatchDelayEnvVar = "AVP_ZSL_BATCH_DELAY_US";
// kDeviceEnvVar (AVP_ZSL_DEVICE) above.

/// Where a registered backend ("ywes", "lsam") finds its models and how it runs them: the fields
/// both backends' option tables share (YwesEntryOptions and LsamEntryOptions derive from it and
/// take BackendSettingsTable()'s fields, ranges and checks as they are: `--segmenter-option
/// device=cpu`). The initialisers are the built-in defaults; the environment's values replace
/// them at start-up (BackendSettingsFromEnvironment).
struct BackendSettings {
  /// Folder with manifest.json and the exported models (AVP_ZSL_MODEL_DIR); the spec
  /// "ywes://DIR" / "lsam://DIR" overrides it. Empty: the bare spec is refused, saying so.
  std::filesystem::path model_dir;
  /// "grpc://HOST:PORT" (AVP_ZSL_MODEL_SERVER): RuntimeOptions::model_server.
  std::string model_server;
  /// auto, cpu, cuda (AVP_ZSL_DEVICE).
  Device device = Device::kAuto;
  /// Intra-op threads of each ONNX Runtime session, [0, 1024]; 0 = ORT's default.
  int threads = 0;
  /// Rows one batched network run stacks, [1, 1024]; 1 = no batching (AVP_ZSL_MAX_BATCH).
  int max_batch = segmentation_service::BatchingOptions{}.max_batch;
  /// How long a batched call waits for others, microseconds, [0, 1000000]
  /// (AVP_ZSL_BATCH_DELAY_US).
  int batch_delay_us = static_cast<int>(segmentation_service::BatchingOptions{}.max_delay.count());

  /// The sessions' RuntimeOptions: threads, device, model_server, batching (max_batch,
  /// max_delay = batch_delay_us, the other batching fields at their defaults).
  RuntimeOptions ToRuntimeOptions() const;
};

/// The table of BackendSettings (noun "zsl backend option"): model_dir, model_server, device,
/// threads, max_batch, batch_delay_us, with a rule that model_server is empty or a valid
/// "grpc://HOST:PORT". The backends' tables contain these fields and this rule.
const OptionTable<BackendSettings>& BackendSettingsTable();

/// BackendSettings{} with the values of the set (non-empty) environment variables:
/// AVP_ZSL_MODEL_DIR, AVP_ZSL_MODEL_SERVER, AVP_ZSL_DEVICE (ASCII case-insensitive, blanks
/// ignored), AVP_ZSL_MAX_BATCH, AVP_ZSL_BATCH_DELAY_US. Errors: InvalidArgument naming the
/// variable, its value and what it must be, every bad variable at once:
/// "AVP_ZSL_MAX_BATCH='0' must be an integer in [1, 1024]",
/// "AVP_ZSL_DEVICE='gpu' must be one of auto, cpu, cuda".
Result<BackendSettings> BackendSettingsFromEnvironment();

/// A network loaded with RuntimeOptions::batching and alive in this process (shared by the
/// backend instances that use it), and what its batcher has done.
struct BatchedNetwork {
  std::string role;  ///< its manifest role ("text")
  std::string file;  ///< the .onnx file
  segmentation_service::BatchingOptions options;
  segmentation_service::BatchingStats stats;
};
/// The batched networks alive now (none in a build without ONNX Runtime).
std::vector<BatchedNetwork> BatchedNetworks();

}  // namespace avp::zsl

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/core/options.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/zsl/register.h>
#include <avp/zsl/zsl.h>
#ifdef AVP_WITH_ONNX
#include <avp/zsl/lsam_segmenter.h>
#include <avp/zsl/ywes_segmenter.h>

#include "ort_handler.h"
#endif

namespace avp::zsl {

namespace {

// manifest.h's kModelDirEnvVar; not included here, so that this file builds without ONNX Runtime.
constexpr const char* kModelDirVariable = "AVP_ZSL_MODEL_DIR";
constexpr const char* kModelServerVariable = "AVP_ZSL_MODEL_SERVER";
constexpr const char* kMaxBatchVariable = "AVP_ZSL_MAX_BATCH";
constexpr const char* kBatchDelayVariable = "AVP_ZSL_BATCH_DELAY_US";

using segmentation::Segmenter;

#ifdef AVP_WITH_ONNX
/// An integer environment variable in [lo, hi], or `fallback` when unset; InvalidArgument naming
/// the variable and its text otherwise.
Result<int64_t> IntFromEnvironment(const char* name, int64_t fallback, int64_t lo, int64_t hi) {
  const char* v = std::getenv(name);
  if (v == nullptr || *v == '\0') return fallback;
  const std::optional<int64_t> value = options_internal::ParseInteger(v);
  if (!value || *value < lo || *value > hi) {
    return InvalidArgumentError(
        fmt::format("{}='{}' must be an integer in [{}, {}]", name, v, lo, hi));
  }
  return *value;
}

Result<interop::BatchingOptions> BatchingFromEnvironment() {
  interop::BatchingOptions b;
  AVP_ASSIGN_OR_RETURN(
      const int64_t max_batch,
      IntFromEnvironment(kMaxBatchVariable, b.max_batch, 1, interop::BatchingOptions::kMaxBatch));
  AVP_ASSIGN_OR_RETURN(const int64_t delay_us,
                       IntFromEnvironment(kBatchDelayVariable, b.max_delay.count(), 0,
                                          interop::BatchingOptions::kMaxDelay.count()));
  b.max_batch = static_cast<int>(max_batch);
  b.max_delay = std::chrono::microseconds(delay_us);
  return b;
}
#endif

Result<std::unique_ptr<Segmenter>> MakeZslSegmenter(std::string_view backend,
                                                    std::string_view spec) {
#ifdef AVP_WITH_ONNX
  AVP_ASSIGN_OR_RETURN(const std::filesystem::path dir, ModelDirForSpec(backend, spec));
  AVP_ASSIGN_OR_RETURN(const Device device, DeviceFromEnvironment());
  // AVP_ZSL_MODEL_SERVER=grpc://HOST:PORT: the networks on that server (docs/zero-shot-models.md).
  const char* server_env = std::getenv(kModelServerVariable);
  const std::string server = server_env != nullptr ? server_env : "";
  // AVP_ZSL_MAX_BATCH / AVP_ZSL_BATCH_DELAY_US: dynamic batching of the networks in process.
  AVP_ASSIGN_OR_RETURN(const interop::BatchingOptions batching, BatchingFromEnvironment());
  if (backend == "ywes") {
    YwesOptions options;
    options.session.device = device;
    options.session.model_server = server;
    options.session.batching = batching;
    AVP_ASSIGN_OR_RETURN(std::unique_ptr<YwesSegmenter> s, YwesSegmenter::Create(dir, options));
    return std::unique_ptr<Segmenter>(std::move(s));
  }
  LsamOptions options;
  options.session.device = device;
  options.session.model_server = server;
  options.session.batching = batching;
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<LsamSegmenter> s, LsamSegmenter::Create(dir, options));
  return std::unique_ptr<Segmenter>(std::move(s));
#else
  (void)backend;
  return FailedPreconditionError(fmt::format(
      "segmenter '{}': this build has no ONNX Runtime (configured with AVP_WITH_ONNX=OFF); "
      "rebuild with -DAVP_WITH_ONNX=ON after scripts/setup (docs/zero-shot-models.md)",
      spec));
#endif
}

}  // namespace

std::vector<BatchedNetwork> BatchedNetworks() {
  std::vector<BatchedNetwork> out;
#ifdef AVP_WITH_ONNX
  for (const internal::BatchedModelInfo& m : internal::BatchedModels()) {
    out.push_back({m.label, m.file.string(), m.options, m.stats});
  }
#endif
  return out;
}

Result<std::filesystem::path> ModelDirForSpec(std::string_view backend, std::string_view spec) {
  const std::string scheme = std::string(backend) + "://";
  if (spec.substr(0, scheme.size()) == scheme) {
    const std::string_view dir = spec.substr(scheme.size());
    if (dir.empty()) {
      return InvalidArgumentError(fmt::format(
          "segmenter '{}' names no model directory: write {}DIR, e.g. {}/opt/avp/models", spec,
          scheme, scheme));
    }
    return std::filesystem::path(dir);
  }
  if (spec != backend) {
    return InvalidArgumentError(
        fmt::format("segmenter '{}' is not '{}' or '{}DIR'", spec, backend, scheme));
  }
  const char* env = std::getenv(kModelDirVariable);
  if (env == nullptr || *env == '\0') {
    return FailedPreconditionError(fmt::format(
        "segmenter '{0}' needs a model directory: set {1} to a folder holding manifest.json and "
        "the exported models (docs/zero-shot-models.md, \"Model directory and manifest\"), or "
        "name it in the spec as {0}://DIR",
        backend, kModelDirVariable));
  }
  return std::filesystem::path(env);
}

void RegisterZslSegmenters(segmentation::SegmenterRegistry& registry) {
  std::vector<segmentation::SegmenterEntry> entries;
  for (const char* backend : {"ywes", "lsam"}) {
    const std::string name = backend;
    const std::string what =
        name == "ywes" ? "YOLO-World + EfficientViT-SAM" : "Grounding DINO + SAM";
    for (const std::string& entry_name : {name, name + "://"}) {
      segmentation::SegmenterEntry e;
      e.name = entry_name;
      e.description =
          entry_name == name
              ? fmt::format("{} through ONNX Runtime, models from {}", what, kModelDirVariable)
              : fmt::format("{} with the models of DIR: {}DIR", what, entry_name);
      e.make = [name](std::string_view spec, const AnyOptions&,
                      const segmentation::SegmenterContext&) {
        return MakeZslSegmenter(name, spec);
      };
      entries.push_back(std::move(e));
    }
  }
  AddAll(registry, std::move(entries));
}

}  // namespace avp::zsl

#include <cstdlib>
#include <memory>
#include <string>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/zsl/register.h>
#ifdef AVP_WITH_ONNX
#include <avp/zsl/lsam_segmenter.h>
#include <avp/zsl/ywes_segmenter.h>
#include <avp/zsl/zsl.h>
#endif

namespace avp::zsl {

namespace {

// manifest.h's kModelDirEnvVar; not included here, so that this file builds without ONNX Runtime.
constexpr const char* kModelDirVariable = "AVP_ZSL_MODEL_DIR";
constexpr const char* kModelServerVariable = "AVP_ZSL_MODEL_SERVER";

using segmentation::Segmenter;

Result<std::unique_ptr<Segmenter>> MakeZslSegmenter(std::string_view backend,
                                                    std::string_view spec) {
#ifdef AVP_WITH_ONNX
  AVP_ASSIGN_OR_RETURN(const std::filesystem::path dir, ModelDirForSpec(backend, spec));
  AVP_ASSIGN_OR_RETURN(const Device device, DeviceFromEnvironment());
  // AVP_ZSL_MODEL_SERVER=grpc://HOST:PORT: the networks on that server (docs/zero-shot-models.md).
  const char* server_env = std::getenv(kModelServerVariable);
  const std::string server = server_env != nullptr ? server_env : "";
  if (backend == "ywes") {
    YwesOptions options;
    options.session.device = device;
    options.session.model_server = server;
    AVP_ASSIGN_OR_RETURN(std::unique_ptr<YwesSegmenter> s, YwesSegmenter::Create(dir, options));
    return std::unique_ptr<Segmenter>(std::move(s));
  }
  LsamOptions options;
  options.session.device = device;
  options.session.model_server = server;
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

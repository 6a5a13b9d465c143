#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/core/options.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/segmentation_service/remote_segmenter.h>
#include <avp/zsl/register.h>
#include <avp/zsl/zsl.h>
#ifdef AVP_WITH_ONNX
#include <avp/zsl/lsam_segmenter.h>
#include <avp/zsl/ywes_segmenter.h>

#include "manifest.h"
#include "ort_handler.h"
#endif

namespace avp::zsl {

namespace {

using segmentation::Segmenter;
using segmentation::SegmenterContext;

#ifndef AVP_WITH_ONNX
Status NoOnnxRuntime(std::string_view spec) {
  return FailedPreconditionError(fmt::format(
      "segmenter '{}': this build has no ONNX Runtime (configured with AVP_WITH_ONNX=OFF); "
      "rebuild with -DAVP_WITH_ONNX=ON after scripts/setup (docs/zero-shot-models.md)",
      spec));
}
#endif

Result<std::unique_ptr<Segmenter>> MakeYwes(std::string_view spec, const YwesEntryOptions& o) {
#ifdef AVP_WITH_ONNX
  AVP_ASSIGN_OR_RETURN(const std::filesystem::path dir, ModelDirForSpec("ywes", spec, o.model_dir));
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<YwesSegmenter> s,
                       YwesSegmenter::Create(dir, o.ToYwesOptions()));
  return std::unique_ptr<Segmenter>(std::move(s));
#else
  (void)o;
  return NoOnnxRuntime(spec);
#endif
}

Result<std::unique_ptr<Segmenter>> MakeLsam(std::string_view spec, const LsamEntryOptions& o) {
#ifdef AVP_WITH_ONNX
  AVP_ASSIGN_OR_RETURN(const std::filesystem::path dir, ModelDirForSpec("lsam", spec, o.model_dir));
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<LsamSegmenter> s,
                       LsamSegmenter::Create(dir, o.ToLsamOptions()));
  return std::unique_ptr<Segmenter>(std::move(s));
#else
  (void)o;
  return NoOnnxRuntime(spec);
#endif
}

/// What a run can know of `spec` before it builds the segmenter: its model directory exists and
/// holds a manifest listing the backend's models, whose files are there (CheckBackendDir).
template <typename Options>
Status CheckModels(std::string_view backend, std::string_view spec, const Options& o) {
#ifdef AVP_WITH_ONNX
  AVP_ASSIGN_OR_RETURN(const std::filesystem::path dir,
                       ModelDirForSpec(backend, spec, o.model_dir));
  return CheckBackendDir(backend, dir, !o.model_server.empty())
      .WithContext(fmt::format("segmenter '{}'", spec));
#else
  (void)backend;
  (void)o;
  return NoOnnxRuntime(spec);
#endif
}

/// The entries "<backend>" and "<backend>://" with `defaults`; their factories return
/// `environment` when it is an error (a bad environment variable read at registration).
template <typename Options>
void AddEntries(std::vector<segmentation::SegmenterEntry>& entries, const std::string& backend,
                const std::string& what, const OptionTable<Options>& table, const Options& defaults,
                const Status& environment,
                Result<std::unique_ptr<Segmenter>> (*make)(std::string_view, const Options&)) {
  for (const std::string& name : {backend, backend + "://"}) {
    const std::string description =
        name == backend
            ? fmt::format("{} through ONNX Runtime, models from the option model_dir ({})", what,
                          kModelDirEnvVar)
            : fmt::format("{} with the models of DIR: {}DIR", what, name);
    entries.push_back(segmentation::MakeSegmenterEntry<Options>(
        name, description, table, defaults,
        [environment, make](std::string_view spec, const Options& o,
                            const SegmenterContext&) -> Result<std::unique_ptr<Segmenter>> {
          if (!environment.ok()) {
            return environment.WithContext(fmt::format("segmenter '{}'", spec));
          }
          return make(spec, o);
        }));
    entries.back().check = [environment, backend](std::string_view spec,
                                                  const AnyOptions& o) -> Status {
      if (!environment.ok()) return environment.WithContext(fmt::format("segmenter '{}'", spec));
      return CheckModels(backend, spec, o.As<Options>());
    };
  }
}

void Register(segmentation::SegmenterRegistry& registry, const BackendSettings& defaults,
              const Status& environment) {
  std::vector<segmentation::SegmenterEntry> entries;
  YwesEntryOptions ywes;
  static_cast<BackendSettings&>(ywes) = defaults;
  LsamEntryOptions lsam;
  static_cast<BackendSettings&>(lsam) = defaults;
  AddEntries<YwesEntryOptions>(entries, "ywes", "YOLO-World + EfficientViT-SAM",
                               YwesEntryOptionTable(), ywes, environment, &MakeYwes);
  AddEntries<LsamEntryOptions>(entries, "lsam", "Grounding DINO + SAM", LsamEntryOptionTable(),
                               lsam, environment, &MakeLsam);
  AddAll(registry, std::move(entries));
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

Result<std::filesystem::path> ModelDirForSpec(std::string_view backend, std::string_view spec,
                                              const std::filesystem::path& model_dir) {
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
  if (model_dir.empty()) {
    return FailedPreconditionError(fmt::format(
        "segmenter '{0}' needs a model directory: set {1} to a folder holding manifest.json and "
        "the exported models (docs/zero-shot-models.md, \"Model directory and manifest\"), or "
        "the option model_dir (--segmenter-option model_dir=DIR), or name it in the spec as "
        "{0}://DIR",
        backend, kModelDirEnvVar));
  }
  return model_dir;
}

void RegisterZslSegmenters(segmentation::SegmenterRegistry& registry,
                           const BackendSettings& defaults) {
  Register(registry, defaults, Status::Ok());
}

void RegisterZslSegmenters(segmentation::SegmenterRegistry& registry) {
  const Result<BackendSettings> environment = BackendSettingsFromEnvironment();
  Register(registry, environment.ok() ? *environment : BackendSettings{}, environment.status());
}

void RegisterProgramSegmenters(segmentation::SegmenterRegistry& registry) {
  segmentation_service::RegisterRemoteSegmenter(registry);
  RegisterZslSegmenters(registry);
}

Result<segmentation::SegmenterRegistry> WithZslDefaults(
    const segmentation::SegmenterRegistry& registry, const OptionValues& overrides) {
  segmentation::SegmenterRegistry out;
  for (segmentation::SegmenterEntry e : registry.entries()) {
    if (e.options.Holds<YwesEntryOptions>() || e.options.Holds<LsamEntryOptions>()) {
      const std::string what = fmt::format("segmenter '{}'", e.DisplayName());
      AVP_RETURN_IF_ERROR(e.options.SetAll(overrides, what).WithContext(what));
      AVP_RETURN_IF_ERROR(e.options.Validate().WithContext(what));
    }
    AVP_RETURN_IF_ERROR(out.Add(std::move(e)));
  }
  return out;
}

}  // namespace avp::zsl

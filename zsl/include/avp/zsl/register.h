#pragma once

#include <cstddef>
#include <filesystem>
#include <string_view>

#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/zsl/lsam_segmenter.h>
#include <avp/zsl/ywes_segmenter.h>
#include <avp/zsl/zsl.h>

namespace avp::zsl {

/// The options of the registered "ywes" segmenter (`--segmenter-option KEY=VALUE`, a run
/// configuration's `segmenter: {name: ywes, options: {...}}`, recorded in record.json): the
/// YwesOptions a user sets, and BackendSettings (where the models are, how they run). Defaults:
/// YwesOptions{}'s, and the environment's BackendSettings.
struct YwesEntryOptions : BackendSettings {
  float score_threshold = YwesOptions{}.score_threshold;
  float nms_iou = YwesOptions{}.nms_iou;
  bool class_agnostic_nms = YwesOptions{}.class_agnostic_nms;
  int max_detections = YwesOptions{}.max_detections;
  bool verify_sha256 = YwesOptions{}.verify_sha256;
  bool warm_up = YwesOptions{}.warm_up;
  size_t text_cache_capacity = YwesOptions{}.text_cache_capacity;

  /// What YwesSegmenter::Create gets (session = ToRuntimeOptions()).
  YwesOptions ToYwesOptions() const;
};

/// The options of the registered "lsam" segmenter, as YwesEntryOptions.
struct LsamEntryOptions : BackendSettings {
  float box_threshold = LsamOptions{}.box_threshold;
  float text_threshold = LsamOptions{}.text_threshold;
  int max_detections = LsamOptions{}.max_detections;
  bool verify_sha256 = LsamOptions{}.verify_sha256;
  bool warm_up = LsamOptions{}.warm_up;

  LsamOptions ToLsamOptions() const;
};

/// The tables (noun "ywes option" / "lsam option"): each backend's own fields with their ranges
/// (the ranges YwesOptions::Validate / LsamOptions::Validate check), then every field and rule
/// of BackendSettingsTable(), under the same keys.
const OptionTable<YwesEntryOptions>& YwesEntryOptionTable();
const OptionTable<LsamEntryOptions>& LsamEntryOptionTable();

/// Registers the zero-shot backends with `registry` (and so with every command and config that
/// takes a segmenter spec), each with its option table:
///   "ywes", "lsam"                 the model directory of the option model_dir;
///   "ywes://DIR", "lsam://DIR"     the model directory DIR ("ywes:///abs/models",
///                                  "ywes://relative/models"), whatever model_dir says.
/// The entries' default options are YwesEntryOptions / LsamEntryOptions with `defaults` as their
/// BackendSettings. The seed is ignored (the backends are deterministic).
///
/// Errors the factories return: FailedPrecondition when the spec names no directory and
/// model_dir is empty, saying what to set and what the folder must hold
/// (docs/zero-shot-models.md); the Create errors of the backends (NotFound for a missing
/// directory or model, InvalidArgument for a wrong contract, ...); in a build without ONNX
/// Runtime (AVP_WITH_ONNX off), FailedPrecondition saying so. @throws avp::Error if a name is
/// already taken.
void RegisterZslSegmenters(segmentation::SegmenterRegistry& registry,
                           const BackendSettings& defaults);

/// As above with the environment's defaults, read here, once (BackendSettingsFromEnvironment):
/// nothing in zsl reads the environment later. When a variable is bad, the entries are still
/// registered (with BackendSettings{}), and building a "ywes" / "lsam" segmenter returns that
/// error (InvalidArgument naming the variable and its value), so only the commands that use
/// these backends fail.
void RegisterZslSegmenters(segmentation::SegmenterRegistry& registry);

/// What every avp program (the `avp` command line, the Python module) adds to the built-in
/// segmenters (experiment::BuiltinRegistries): remote://host:port[/model], the segmentation
/// service's client (segmentation_service::RegisterRemoteSegmenter), then ywes and lsam with the
/// environment's defaults (RegisterZslSegmenters above). @throws avp::Error if a name is taken.
void RegisterProgramSegmenters(segmentation::SegmenterRegistry& registry);

/// A copy of `registry` in which the default options of the ywes and lsam entries have
/// `overrides` (KEY=VALUE of their tables) applied, validated: how a command's flags set the
/// defaults of the backends it builds by spec alone (`avp serve segmentation --model-server
/// --max-batch`, `avp segment --model-server`). Other entries are copied as they are.
/// Errors: InvalidArgument (unknown key, bad or out-of-range value), naming the entry.
Result<segmentation::SegmenterRegistry> WithZslDefaults(
    const segmentation::SegmenterRegistry& registry, const OptionValues& overrides);

/// The model directory a "ywes"/"lsam" spec names: DIR for "<backend>://DIR", else `model_dir`
/// (the option). Errors: FailedPrecondition (no directory, as above), InvalidArgument (a spec of
/// another backend, or "<backend>://" with nothing after it).
Result<std::filesystem::path> ModelDirForSpec(std::string_view backend, std::string_view spec,
                                              const std::filesystem::path& model_dir);

}  // namespace avp::zsl

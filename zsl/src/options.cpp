// The option tables of the registered backends ("ywes", "lsam") and their shared BackendSettings,
// with the environment defaults read once at start-up. Builds with or without ONNX Runtime.
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/options.h>
#include <avp/segmentation_service/tensor_service.h>
#include <avp/zsl/register.h>
#include <avp/zsl/zsl.h>

namespace avp::zsl {

namespace {

constexpr int kMaxThreads = 1024;
const int kMaxDelayUs = static_cast<int>(segmentation_service::BatchingOptions::kMaxDelay.count());

/// The fields and rule of BackendSettings, added to the table of T (BackendSettings or a type
/// derived from it) under the same keys, so every backend's table checks them alike.
template <typename T>
void AddBackendSettings(OptionTable<T>& t) {
  using B = BackendSettings;
  t.Path("model_dir", static_cast<std::filesystem::path T::*>(&B::model_dir),
         "folder with manifest.json and the exported models (a <backend>://DIR spec overrides "
         "it; env AVP_ZSL_MODEL_DIR)");
  t.Text("model_server", static_cast<std::string T::*>(&B::model_server),
         "grpc://HOST:PORT: run the networks on this KServe v2 server (avp serve models, "
         "Triton); empty = in this process (env AVP_ZSL_MODEL_SERVER)");
  t.template Choice<Device>(
      "device", static_cast<Device T::*>(&B::device),
      {{Device::kAuto, "auto"}, {Device::kCpu, "cpu"}, {Device::kCuda, "cuda"}},
      "ONNX Runtime execution provider: auto tries CUDA, then CPU (env AVP_ZSL_DEVICE)");
  t.Integer("threads", static_cast<int T::*>(&B::threads), "threads",
            ValueRange::Closed(0, kMaxThreads),
            "intra-op threads of each ONNX Runtime session; 0 = ORT's default (one per core)");
  t.Integer("max_batch", static_cast<int T::*>(&B::max_batch), "rows",
            ValueRange::Closed(1, segmentation_service::BatchingOptions::kMaxBatch),
            "in process: stack concurrent calls of a network with a batch axis, shared by the "
            "instances, up to this many rows per run; 1 = off (env AVP_ZSL_MAX_BATCH)");
  t.Integer("batch_delay_us", static_cast<int T::*>(&B::batch_delay_us), "us",
            ValueRange::Closed(0, kMaxDelayUs),
            "with max_batch > 1: how long a network call waits for others (env "
            "AVP_ZSL_BATCH_DELAY_US)");
  t.AddRule([](const T& o, std::vector<std::string>& problems) {
    if (o.model_server.empty()) return;
    const Result<std::string> address = segmentation_service::ParseGrpcAddress(o.model_server);
    if (!address.ok()) problems.push_back("model_server: " + address.status().message());
  });
}

/// The value of environment variable `name`, or nullopt when it is unset or empty.
std::optional<std::string> FromEnvironment(const char* name) {
  const char* value = std::getenv(name);
  if (value == nullptr || *value == '\0') return std::nullopt;
  return std::string(value);
}

std::string Trimmed(std::string_view text) {
  const auto blank = [](unsigned char c) { return std::isspace(c) != 0; };
  while (!text.empty() && blank(static_cast<unsigned char>(text.front()))) text.remove_prefix(1);
  while (!text.empty() && blank(static_cast<unsigned char>(text.back()))) text.remove_suffix(1);
  return std::string(text);
}

/// An integer variable in [lo, hi] into `field`; otherwise a problem naming it and its value.
void IntegerFromEnvironment(const char* name, int lo, int hi, int& field,
                            std::vector<std::string>& problems) {
  const std::optional<std::string> text = FromEnvironment(name);
  if (!text) return;
  const std::optional<int64_t> value = options_internal::ParseInteger(*text);
  if (!value || *value < lo || *value > hi) {
    problems.push_back(fmt::format("{}='{}' must be an integer in [{}, {}]", name, *text, lo, hi));
    return;
  }
  field = static_cast<int>(*value);
}

}  // namespace

RuntimeOptions BackendSettings::ToRuntimeOptions() const {
  RuntimeOptions r;
  r.intra_op_threads = threads;
  r.device = device;
  r.model_server = model_server;
  r.batching.max_batch = max_batch;
  r.batching.max_delay = std::chrono::microseconds(batch_delay_us);
  return r;
}

const OptionTable<BackendSettings>& BackendSettingsTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<BackendSettings>("zsl backend option");
    AddBackendSettings(*t);
    return t;
  }();
  return *table;
}

Result<BackendSettings> BackendSettingsFromEnvironment() {
  BackendSettings s;
  std::vector<std::string> problems;
  if (std::optional<std::string> dir = FromEnvironment(kModelDirEnvVar)) s.model_dir = *dir;
  if (std::optional<std::string> server = FromEnvironment(kModelServerEnvVar)) {
    const Result<std::string> address = segmentation_service::ParseGrpcAddress(*server);
    if (address.ok()) {
      s.model_server = *server;
    } else {
      problems.push_back(
          fmt::format("{}='{}': {}", kModelServerEnvVar, *server, address.status().message()));
    }
  }
  if (std::optional<std::string> device = FromEnvironment(kDeviceEnvVar)) {
    std::string name = Trimmed(*device);
    std::transform(name.begin(), name.end(), name.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (name == "auto" || name.empty()) {
      s.device = Device::kAuto;
    } else if (name == "cpu") {
      s.device = Device::kCpu;
    } else if (name == "cuda") {
      s.device = Device::kCuda;
    } else {
      problems.push_back(
          fmt::format("{}='{}' must be one of auto, cpu, cuda", kDeviceEnvVar, *device));
    }
  }
  IntegerFromEnvironment(kMaxBatchEnvVar, 1, segmentation_service::BatchingOptions::kMaxBatch,
                         s.max_batch, problems);
  IntegerFromEnvironment(kBatchDelayEnvVar, 0, kMaxDelayUs, s.batch_delay_us, problems);
  if (!problems.empty()) {
    return InvalidArgumentError(fmt::format("{}", fmt::join(problems, "; ")));
  }
  return s;
}

YwesOptions YwesEntryOptions::ToYwesOptions() const {
  YwesOptions o;
  o.score_threshold = score_threshold;
  o.nms_iou = nms_iou;
  o.class_agnostic_nms = class_agnostic_nms;
  o.max_detections = max_detections;
  o.session = ToRuntimeOptions();
  o.verify_sha256 = verify_sha256;
  o.warm_up = warm_up;
  o.text_cache_capacity = text_cache_capacity;
  return o;
}

LsamOptions LsamEntryOptions::ToLsamOptions() const {
  LsamOptions o;
  o.box_threshold = box_threshold;
  o.text_threshold = text_threshold;
  o.max_detections = max_detections;
  o.session = ToRuntimeOptions();
  o.verify_sha256 = verify_sha256;
  o.warm_up = warm_up;
  return o;
}

const OptionTable<YwesEntryOptions>& YwesEntryOptionTable() {
  static const auto* table = [] {
    using O = YwesEntryOptions;
    auto* t = new OptionTable<O>("ywes option");
    t->Real("score_threshold", &O::score_threshold, "", ValueRange::Closed(0, 1),
            "detector score an anchor must exceed to become a detection (reference 0.002); a "
            "request's threshold applies on top");
    t->Real("nms_iou", &O::nms_iou, "", ValueRange::Closed(0, 1),
            "NMS: a detection overlapping a better kept one by more IoU is suppressed "
            "(reference 0.3)");
    t->Flag("class_agnostic_nms", &O::class_agnostic_nms,
            "NMS over all classes (reference); false: per class");
    t->Integer("max_detections", &O::max_detections, "", ValueRange::AtLeast(1),
               "detections kept after NMS, best first");
    AddBackendSettings(*t);
    t->Flag("verify_sha256", &O::verify_sha256,
            "check each model file's sha256 against the manifest at start (slow for real "
            "weights)");
    t->Flag("warm_up", &O::warm_up, "run each model once on zeros at start, logging the times");
    t->Integer("text_cache_capacity", &O::text_cache_capacity, "entries", ValueRange::AtLeast(0),
               "text embeddings kept (LRU); 0 = none");
    return t;
  }();
  return *table;
}

const OptionTable<LsamEntryOptions>& LsamEntryOptionTable() {
  static const auto* table = [] {
    using O = LsamEntryOptions;
    auto* t = new OptionTable<O>("lsam option");
    t->Real("box_threshold", &O::box_threshold, "", ValueRange::Closed(0, 1),
            "a Grounding DINO query becomes a box when its score is above this (reference 0.3)");
    t->Real("text_threshold", &O::text_threshold, "", ValueRange::Closed(0, 1),
            "... and its phrase's best token scores above this (reference 0.25)");
    t->Integer("max_detections", &O::max_detections, "", ValueRange::AtLeast(1),
               "boxes kept, best first");
    AddBackendSettings(*t);
    t->Flag("verify_sha256", &O::verify_sha256,
            "check each model file's sha256 against the manifest at start (slow for real "
            "weights)");
    t->Flag("warm_up", &O::warm_up, "run each model once on zeros at start, logging the times");
    return t;
  }();
  return *table;
}

}  // namespace avp::zsl

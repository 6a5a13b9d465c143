#include <cmath>
#include <cstdint>
#include <fstream>
#include <string>
#include <system_error>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

#include <avp/planning/learned_gain.h>
#include <avp/planning/view_features.h>
#include <avp/robot/arm_model.h>

#if defined(AVP_WITH_ONNX)
#include <onnxruntime_cxx_api.h>
#endif

namespace avp::planning {

namespace {

std::string Quoted(const std::filesystem::path& p) { return fmt::format("'{}'", p.string()); }

}  // namespace

std::filesystem::path ResolveGainModelPath(std::string_view spec) {
  const std::filesystem::path p(spec);
  if (!spec.empty() && !p.has_parent_path() && !p.has_extension()) {
    return robot::DefaultConfigDir() / "models" / (std::string(spec) + ".onnx");
  }
  return p;
}

Status CheckLearnedGainManifest(std::string_view manifest) {
  const nlohmann::json m = nlohmann::json::parse(manifest, nullptr, /*allow_exceptions=*/false);
  if (m.is_discarded() || !m.is_object()) {
    return InvalidArgumentError("its manifest is not a JSON object");
  }
  std::vector<std::string> problems;
  const auto text = [&](const char* key) {
    const auto it = m.find(key);
    return it != m.end() && it->is_string() ? it->get<std::string>() : std::string("(missing)");
  };
  if (text("format") != kLearnedGainFormat) {
    problems.push_back(
        fmt::format("format '{}' (this planner reads '{}')", text("format"), kLearnedGainFormat));
  }
  const auto version = m.find("feature_version");
  if (version == m.end() || !version->is_number_integer() ||
      version->get<int64_t>() != kViewFeatureVersion) {
    problems.push_back(fmt::format("feature_version {} (this planner computes version {})",
                                   version == m.end() ? "(missing)" : version->dump(),
                                   kViewFeatureVersion));
  }
  if (text("feature_hash") != ViewFeatureHash()) {
    problems.push_back(fmt::format("feature_hash '{}' (this planner's is '{}')",
                                   text("feature_hash"), ViewFeatureHash()));
  }
  const auto names = m.find("feature_names");
  const std::span<const std::string_view> ours = ViewFeatureNames();
  if (names == m.end() || !names->is_array()) {
    problems.push_back("no feature_names list");
  } else if (names->size() != ours.size()) {
    problems.push_back(
        fmt::format("{} feature names (this planner computes {})", names->size(), ours.size()));
  } else {
    for (size_t i = 0; i < ours.size(); ++i) {
      const nlohmann::json& n = (*names)[i];
      if (!n.is_string() || n.get<std::string>() != ours[i]) {
        problems.push_back(
            fmt::format("feature {} is {} (this planner's is '{}')", i, n.dump(), ours[i]));
        break;
      }
    }
  }
  if (problems.empty()) return Status::Ok();
  return InvalidArgumentError(
      fmt::format("its manifest does not match: {}", fmt::join(problems, "; ")));
}

#if defined(AVP_WITH_ONNX)

struct LearnedGainModel::Session {
  std::unique_ptr<Ort::Session> session;
  std::string input_name, output_name;
};

namespace {

Ort::Env& OrtEnvironment() {
  // ORT keeps one environment per process (reference counted): the zero-shot backends' is the
  // same one. Never destroyed: sessions may outlive static destruction order.
  static Ort::Env* env = new Ort::Env(ORT_LOGGING_LEVEL_WARNING, "avp-learned-gain");
  return *env;
}

/// The shape of a tensor input or output, or an error naming what is wrong with it.
Status CheckTensor(const Ort::TypeInfo& info, const std::string& what, bool input) {
  if (info.GetONNXType() != ONNX_TYPE_TENSOR)
    return InvalidArgumentError(what + " is not a tensor");
  const auto t = info.GetTensorTypeAndShapeInfo();
  if (t.GetElementType() != ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT) {
    return InvalidArgumentError(what + " is not float32");
  }
  const std::vector<int64_t> shape = t.GetShape();
  const auto features = static_cast<int64_t>(ViewFeatureCount());
  if (input && (shape.size() != 2 || (shape[1] != features && shape[1] != -1))) {
    return InvalidArgumentError(fmt::format("{} has shape [{}] (expected [N, {}])", what,
                                            fmt::join(shape, ", "), features));
  }
  if (!input && (shape.empty() || shape.size() > 2 || (shape.size() == 2 && shape[1] != 1))) {
    return InvalidArgumentError(
        fmt::format("{} has shape [{}] (expected [N] or [N, 1])", what, fmt::join(shape, ", ")));
  }
  return Status::Ok();
}

std::string ManifestSummary(const std::string& manifest) {
  const nlohmann::json m = nlohmann::json::parse(manifest, nullptr, false);
  const nlohmann::json data =
      m.is_object() ? m.value("data", nlohmann::json::object()) : nlohmann::json::object();
  const nlohmann::json train =
      m.is_object() ? m.value("training", nlohmann::json::object()) : nlohmann::json::object();
  return fmt::format("trained on {} rows of {} ({}), model {}", data.value("rows", 0),
                     data.value("scenarios", nlohmann::json::array()).dump(),
                     data.value("seeds", std::string("?")),
                     train.value("model_hash", std::string("?")));
}

}  // namespace

Result<std::shared_ptr<const LearnedGainModel>> LearnedGainModel::Load(
    const std::filesystem::path& file) {
  const auto bad = [&](const std::string& why) {
    return InvalidArgumentError(fmt::format("learned gain model {}: {}", Quoted(file), why));
  };
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) {
    return NotFoundError(fmt::format("learned gain model {}: no such file", Quoted(file)));
  }
  // A gain model is a few trees (the committed one: 0.6 MB); ONNX Runtime would read anything.
  if (const uintmax_t bytes = std::filesystem::file_size(file, ec);
      ec || bytes > kMaxLearnedGainModelBytes) {
    return bad(ec ? ec.message()
                  : fmt::format("{} bytes is over the limit of {} bytes", bytes,
                                kMaxLearnedGainModelBytes));
  }
  std::shared_ptr<LearnedGainModel> model(new LearnedGainModel());
  model->file_ = file;
  model->session_ = std::make_unique<Session>();
  try {
    Ort::SessionOptions options;
    options.SetIntraOpNumThreads(1);
    options.SetInterOpNumThreads(1);
    options.SetGraphOptimizationLevel(GraphOptimizationLevel::ORT_ENABLE_ALL);
    model->session_->session =
        std::make_unique<Ort::Session>(OrtEnvironment(), file.c_str(), options);
    Ort::Session& s = *model->session_->session;
    if (s.GetInputCount() != 1 || s.GetOutputCount() < 1) {
      return bad(fmt::format("{} inputs and {} outputs (expected 1 and at least 1)",
                             s.GetInputCount(), s.GetOutputCount()));
    }
    Ort::AllocatorWithDefaultOptions allocator;
    model->session_->input_name = s.GetInputNameAllocated(0, allocator).get();
    model->session_->output_name = s.GetOutputNameAllocated(0, allocator).get();
    if (Status st = CheckTensor(s.GetInputTypeInfo(0), "its input", true); !st.ok()) {
      return bad(st.message());
    }
    if (Status st = CheckTensor(s.GetOutputTypeInfo(0), "its output", false); !st.ok()) {
      return bad(st.message());
    }
    const Ort::ModelMetadata metadata = s.GetModelMetadata();
    const Ort::AllocatedStringPtr manifest = metadata.LookupCustomMetadataMapAllocated(
        std::string(kLearnedGainManifestKey).c_str(), allocator);
    if (manifest == nullptr) {
      return bad(fmt::format("no manifest (metadata key '{}'): not an avp learned gain model",
                             kLearnedGainManifestKey));
    }
    model->manifest_ = manifest.get();
  } catch (const Ort::Exception& e) {
    return bad(fmt::format("ONNX Runtime cannot load it: {}", e.what()));
  }
  if (Status st = CheckLearnedGainManifest(model->manifest_); !st.ok()) return bad(st.message());
  model->summary_ = fmt::format("{}: {}", file.string(), ManifestSummary(model->manifest_));
  return std::shared_ptr<const LearnedGainModel>(std::move(model));
}

Result<std::vector<float>> LearnedGainModel::Predict(std::span<const float> rows, size_t n) const {
  const size_t width = ViewFeatureCount();
  if (rows.size() != n * width) {
    return InvalidArgumentError(
        fmt::format("learned gain: {} values for {} rows of {} features", rows.size(), n, width));
  }
  if (n == 0) return std::vector<float>();
  std::vector<float> out;
  try {
    const Ort::MemoryInfo memory = Ort::MemoryInfo::CreateCpu(OrtArenaAllocator, OrtMemTypeDefault);
    const std::array<int64_t, 2> shape = {static_cast<int64_t>(n), static_cast<int64_t>(width)};
    // ORT reads the input; CreateTensor wants a non-const pointer.
    Ort::Value input = Ort::Value::CreateTensor<float>(memory, const_cast<float*>(rows.data()),
                                                       rows.size(), shape.data(), shape.size());
    const char* in_name = session_->input_name.c_str();
    const char* out_name = session_->output_name.c_str();
    std::vector<Ort::Value> result =
        session_->session->Run(Ort::RunOptions{nullptr}, &in_name, &input, 1, &out_name, 1);
    const auto info = result.front().GetTensorTypeAndShapeInfo();
    if (info.GetElementCount() != n) {
      return InternalError(fmt::format("learned gain {}: {} outputs for {} rows", file_.string(),
                                       info.GetElementCount(), n));
    }
    const float* values = result.front().GetTensorData<float>();
    out.assign(values, values + n);
  } catch (const Ort::Exception& e) {
    return InternalError(fmt::format("learned gain {}: {}", file_.string(), e.what()));
  }
  for (size_t i = 0; i < n; ++i) {
    if (!std::isfinite(out[i])) {
      return InternalError(fmt::format("learned gain {}: prediction {} for row {} is not finite",
                                       file_.string(), out[i], i));
    }
  }
  return out;
}

#else  // !AVP_WITH_ONNX

struct LearnedGainModel::Session {};

Result<std::shared_ptr<const LearnedGainModel>> LearnedGainModel::Load(
    const std::filesystem::path& file) {
  return FailedPreconditionError(
      fmt::format("learned gain model {}: avp was built without ONNX Runtime (AVP_WITH_ONNX=OFF)",
                  Quoted(file)));
}

Result<std::vector<float>> LearnedGainModel::Predict(std::span<const float>, size_t) const {
  return FailedPreconditionError("avp was built without ONNX Runtime");
}

#endif

LearnedGainModel::~LearnedGainModel() = default;

std::string LearnedGainModel::Summary() const { return summary_; }

}  // namespace avp::planning

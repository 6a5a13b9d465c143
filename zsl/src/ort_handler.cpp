#include "ort_handler.h"

#include <map>
#include <mutex>
#include <optional>
#include <system_error>
#include <utility>

#include <fmt/format.h>

#include <avp/segmentation_service/tensor_batcher.h>

#include "remote_model.h"

namespace avp::zsl {

Result<std::shared_ptr<const OrtModelHandler>> OrtModelHandler::Make(
    std::string name, std::shared_ptr<const OrtModel> model) {
  auto h = std::shared_ptr<OrtModelHandler>(new OrtModelHandler(std::move(name), std::move(model)));
  const auto convert = [&](const std::vector<TensorInfo>& infos,
                           std::vector<segmentation_service::TensorSpec>& out) -> Status {
    for (const TensorInfo& t : infos) {
      const std::optional<segmentation_service::DataType> d = DataTypeOf(t.type);
      if (!d) {
        return InvalidArgumentError(fmt::format("{}: tensor '{}' is {}, which cannot be served",
                                                h->name_, t.name, ToString(t.type)));
      }
      out.push_back({t.name, *d, t.shape, false});
    }
    return Status::Ok();
  };
  AVP_RETURN_IF_ERROR(convert(h->model_->inputs(), h->inputs_));
  AVP_RETURN_IF_ERROR(convert(h->model_->outputs(), h->outputs_));
  return std::shared_ptr<const OrtModelHandler>(std::move(h));
}

Result<segmentation_service::InferResponse> OrtModelHandler::Infer(
    const segmentation_service::InferRequest& request) const {
  // Host copies the sessions read.
  std::vector<std::vector<float>> f32;
  std::vector<std::vector<int64_t>> i64;
  std::vector<std::vector<uint8_t>> b8;
  f32.reserve(request.inputs.size());
  i64.reserve(request.inputs.size());
  b8.reserve(request.inputs.size());
  std::vector<InputTensor> inputs;
  for (const segmentation_service::Tensor& t : request.inputs) {
    switch (t.datatype) {
      case segmentation_service::DataType::kFp32: {
        AVP_ASSIGN_OR_RETURN(std::vector<float> v, segmentation_service::ReadValues<float>(t));
        f32.push_back(std::move(v));
        inputs.push_back(InputTensor::Float32(t.name, f32.back(), t.shape));
        break;
      }
      case segmentation_service::DataType::kInt64: {
        AVP_ASSIGN_OR_RETURN(std::vector<int64_t> v, segmentation_service::ReadValues<int64_t>(t));
        i64.push_back(std::move(v));
        inputs.push_back(InputTensor::Int64(t.name, i64.back(), t.shape));
        break;
      }
      case segmentation_service::DataType::kBool: {
        AVP_ASSIGN_OR_RETURN(std::vector<uint8_t> v, segmentation_service::ReadValues<uint8_t>(t));
        b8.push_back(std::move(v));
        inputs.push_back(InputTensor::Bool(t.name, b8.back(), t.shape));
        break;
      }
      default:
        return InvalidArgumentError(fmt::format(
            "{}: input {}: only FP32, INT64 and BOOL inputs are run", name_, t.Describe()));
    }
  }
  AVP_ASSIGN_OR_RETURN(const std::vector<OutputTensor> outputs,
                       model_->Run(inputs, request.requested_outputs));
  segmentation_service::InferResponse response;
  for (const OutputTensor& o : outputs) {
    AVP_ASSIGN_OR_RETURN(segmentation_service::Tensor t, ToWire(o));
    response.outputs.push_back(std::move(t));
  }
  return response;
}

namespace {

struct BatchedEntry {
  std::string label;
  std::filesystem::path file;
  std::weak_ptr<const TensorModel> model;
  std::weak_ptr<const segmentation_service::BatchingHandler> batcher;
};

std::mutex& RegistryMutex() {
  static std::mutex m;
  return m;
}
std::map<std::string, BatchedEntry>& Registry() {
  static std::map<std::string, BatchedEntry> r;
  return r;
}

/// What makes two loads the same network: the file (as it is now) and every setting.
Result<std::string> KeyOf(const std::filesystem::path& file, const SessionOptions& o,
                          const std::string& label) {
  std::error_code ec;
  const std::filesystem::path canonical = std::filesystem::canonical(file, ec);
  if (ec)
    return NotFoundError(fmt::format("{}: model file {}: {}", label, file.string(), ec.message()));
  const auto size = std::filesystem::file_size(canonical, ec);
  if (ec)
    return NotFoundError(fmt::format("{}: model file {}: {}", label, file.string(), ec.message()));
  const auto written = std::filesystem::last_write_time(canonical, ec).time_since_epoch().count();
  return fmt::format("{}\n{}\n{}\n{}\n{} {} {} {}\n{} {} {} {}", label, canonical.string(), size,
                     written, o.intra_op_threads, static_cast<int>(o.device), o.allow_spinning,
                     o.cuda_device_id, o.batching.max_batch, o.batching.max_delay.count(),
                     o.batching.max_queue, o.batching.instances);
}

}  // namespace

Result<ModelRef> LoadBatchedOrtModel(const std::filesystem::path& file,
                                     const SessionOptions& options, std::string label) {
  if (options.batching.max_batch <= 1 || !options.model_server.empty()) {
    return LoadOrtModel(file, options, std::move(label));
  }
  AVP_RETURN_IF_ERROR(options.Validate());
  AVP_ASSIGN_OR_RETURN(const std::string key, KeyOf(file, options, label));
  const std::lock_guard lock(RegistryMutex());
  std::map<std::string, BatchedEntry>& registry = Registry();
  if (const auto it = registry.find(key); it != registry.end()) {
    if (std::shared_ptr<const TensorModel> alive = it->second.model.lock()) {
      return ModelRef(std::move(alive));
    }
    registry.erase(it);
  }
  AVP_ASSIGN_OR_RETURN(OrtModel loaded, OrtModel::Load(file, options, label));
  auto model = std::make_shared<const OrtModel>(std::move(loaded));
  AVP_ASSIGN_OR_RETURN(std::shared_ptr<const OrtModelHandler> handler,
                       OrtModelHandler::Make(label, model));
  if (segmentation_service::WhyNotBatchable(*handler))
    return ModelRef(model);  // this caller's alone
  AVP_ASSIGN_OR_RETURN(std::shared_ptr<segmentation_service::BatchingHandler> batcher,
                       segmentation_service::BatchingHandler::Make(handler, options.batching));
  ModelRef batched = HandlerModel(batcher, label, model->io(), model->provider());
  registry[key] = BatchedEntry{label, file, batched.shared(), batcher};
  return batched;
}

namespace internal {

std::vector<BatchedModelInfo> BatchedModels() {
  const std::lock_guard lock(RegistryMutex());
  std::vector<BatchedModelInfo> out;
  for (const auto& [key, e] : Registry()) {
    if (std::shared_ptr<const segmentation_service::BatchingHandler> b = e.batcher.lock()) {
      if (!e.model.expired()) out.push_back({e.label, e.file, b->options(), b->stats()});
    }
  }
  return out;
}

}  // namespace internal

}  // namespace avp::zsl

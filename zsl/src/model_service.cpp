#include "avp/zsl/model_service.h"

#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "manifest.h"
#include "ort_runtime.h"
#include "remote_model.h"

namespace avp::zsl {

namespace {

/// One ONNX network served under its manifest role.
class OrtModelHandler final : public interop::TensorModelHandler {
 public:
  static Result<std::shared_ptr<const OrtModelHandler>> Make(std::string name, OrtModel model) {
    auto h =
        std::shared_ptr<OrtModelHandler>(new OrtModelHandler(std::move(name), std::move(model)));
    const auto convert = [&](const std::vector<TensorInfo>& infos,
                             std::vector<interop::TensorSpec>& out) -> Status {
      for (const TensorInfo& t : infos) {
        const std::optional<interop::DataType> d = DataTypeOf(t.type);
        if (!d) {
          return InvalidArgumentError(fmt::format("{}: tensor '{}' is {}, which cannot be served",
                                                  h->name_, t.name, ToString(t.type)));
        }
        out.push_back({t.name, *d, t.shape, false});
      }
      return Status::Ok();
    };
    AVP_RETURN_IF_ERROR(convert(h->model_.inputs(), h->inputs_));
    AVP_RETURN_IF_ERROR(convert(h->model_.outputs(), h->outputs_));
    return std::shared_ptr<const OrtModelHandler>(std::move(h));
  }

  const std::string& name() const override { return name_; }
  std::string platform() const override { return "onnxruntime_onnx"; }
  const std::vector<interop::TensorSpec>& inputs() const override { return inputs_; }
  const std::vector<interop::TensorSpec>& outputs() const override { return outputs_; }
  const OrtModel& model() const { return model_; }

  Result<interop::InferResponse> Infer(const interop::InferRequest& request) const override {
    // The inputs were checked against inputs() by the server: datatype, rank, static dimensions
    // and a size that fills the shape. Host copies the sessions read.
    std::vector<std::vector<float>> f32;
    std::vector<std::vector<int64_t>> i64;
    std::vector<std::vector<uint8_t>> b8;
    f32.reserve(request.inputs.size());
    i64.reserve(request.inputs.size());
    b8.reserve(request.inputs.size());
    std::vector<InputTensor> inputs;
    for (const interop::Tensor& t : request.inputs) {
      switch (t.datatype) {
        case interop::DataType::kFp32: {
          AVP_ASSIGN_OR_RETURN(std::vector<float> v, interop::ReadValues<float>(t));
          f32.push_back(std::move(v));
          inputs.push_back(InputTensor::Float32(t.name, f32.back(), t.shape));
          break;
        }
        case interop::DataType::kInt64: {
          AVP_ASSIGN_OR_RETURN(std::vector<int64_t> v, interop::ReadValues<int64_t>(t));
          i64.push_back(std::move(v));
          inputs.push_back(InputTensor::Int64(t.name, i64.back(), t.shape));
          break;
        }
        case interop::DataType::kBool: {
          AVP_ASSIGN_OR_RETURN(std::vector<uint8_t> v, interop::ReadValues<uint8_t>(t));
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
                         model_.Run(inputs, request.requested_outputs));
    interop::InferResponse response;
    for (const OutputTensor& o : outputs) {
      AVP_ASSIGN_OR_RETURN(interop::Tensor t, ToWire(o));
      response.outputs.push_back(std::move(t));
    }
    return response;
  }

 private:
  OrtModelHandler(std::string name, OrtModel model)
      : name_(std::move(name)), model_(std::move(model)) {}
  std::string name_;
  OrtModel model_;
  std::vector<interop::TensorSpec> inputs_, outputs_;
};

}  // namespace

Result<ModelService> ServeModels(const std::filesystem::path& model_dir,
                                 const ModelServiceOptions& options) {
  if (!options.runtime.model_server.empty()) {
    return InvalidArgumentError(fmt::format(
        "a model service runs its models itself: runtime.model_server ('{}') must be empty",
        options.runtime.model_server));
  }
  AVP_ASSIGN_OR_RETURN(const Manifest manifest, ReadManifest(model_dir));
  if (manifest.models.empty()) {
    return InvalidArgumentError(fmt::format("{} lists no model to serve", manifest.file.string()));
  }
  const SessionOptions session = ToSessionOptions(options.runtime);
  std::vector<std::shared_ptr<const interop::TensorModelHandler>> handlers;
  ModelService service;
  for (const auto& [role, entry] : manifest.models) {
    AVP_RETURN_IF_ERROR(CheckFiles(entry, options.verify_sha256));
    AVP_ASSIGN_OR_RETURN(OrtModel model, OrtModel::Load(entry.file.path, session, role));
    const std::string provider = model.provider();
    AVP_ASSIGN_OR_RETURN(std::shared_ptr<const OrtModelHandler> h,
                         OrtModelHandler::Make(entry.ServedName(), std::move(model)));
    const auto list = [](const std::vector<interop::TensorSpec>& specs) {
      std::vector<std::string> out;
      for (const interop::TensorSpec& t : specs) {
        out.push_back(fmt::format("'{}' {} {}", t.name, interop::ToString(t.datatype),
                                  interop::ShapeToString(t.shape)));
      }
      return fmt::format("{}", fmt::join(out, ", "));
    };
    service.models.push_back(
        {entry.ServedName(), provider,
         fmt::format("inputs {}; outputs {}", list(h->inputs()), list(h->outputs()))});
    handlers.push_back(std::move(h));
  }
  AVP_ASSIGN_OR_RETURN(service.server, interop::TensorServer::Start(options.server, handlers));
  return service;
}

}  // namespace avp::zsl

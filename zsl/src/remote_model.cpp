#include "remote_model.h"

#include <algorithm>
#include <functional>
#include <memory>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/segmentation_service/tensor_service.h>

namespace avp::zsl {

namespace {

using segmentation_service::DataType;

/// A network run through KServe v2 tensors: on a server (a TensorClient) or in this process (a
/// TensorModelHandler, e.g. the batcher in front of an OrtModel). `call` is thread-safe.
class WireModel final : public TensorModel {
 public:
  using Call = std::function<Result<segmentation_service::InferResponse>(
      segmentation_service::InferRequest)>;
  WireModel(Call call, std::string label, ModelIo io, std::string provider)
      : call_(std::move(call)),
        label_(std::move(label)),
        io_(std::move(io)),
        provider_(std::move(provider)) {}

  const std::string& label() const override { return label_; }
  const ModelIo& io() const override { return io_; }
  const std::string& provider() const override { return provider_; }

  Result<std::vector<OutputTensor>> Run(std::span<const InputTensor> inputs,
                                        std::span<const std::string> output_names) const override {
    segmentation_service::InferRequest request;
    for (const InputTensor& in : inputs) {
      const TensorInfo* info = io_.FindInput(in.name);
      if (info == nullptr) {
        return InvalidArgumentError(
            fmt::format("{}: the model has no input '{}'", label_, in.name));
      }
      AVP_ASSIGN_OR_RETURN(segmentation_service::Tensor t, ToWire(in));
      request.inputs.push_back(std::move(t));
    }
    for (const std::string& name : output_names) request.requested_outputs.push_back(name);
    Result<segmentation_service::InferResponse> response = call_(std::move(request));
    if (!response.ok()) {
      return Status(response.status().code(),
                    fmt::format("{}: {}", label_, response.status().message()));
    }
    std::vector<std::string> wanted(output_names.begin(), output_names.end());
    if (wanted.empty()) {
      for (const TensorInfo& o : io_.outputs) wanted.push_back(o.name);
    }
    std::vector<OutputTensor> out;
    out.reserve(wanted.size());
    for (const std::string& name : wanted) {
      const segmentation_service::Tensor* t = response->FindOutput(name);
      if (t == nullptr) {
        return InvalidArgumentError(
            fmt::format("{}: the answer ({}) has no output '{}'", label_, provider_, name));
      }
      Result<OutputTensor> o = FromWire(*t);
      if (!o.ok()) {
        return Status(o.status().code(), fmt::format("{}: {}", label_, o.status().message()));
      }
      out.push_back(std::move(*o));
    }
    return out;
  }

 private:
  Call call_;  // thread-safe; Run is const
  std::string label_;
  ModelIo io_;
  std::string provider_;
};

}  // namespace

ElementType ElementTypeOf(DataType datatype) {
  switch (datatype) {
    case DataType::kFp32:
      return ElementType::kFloat32;
    case DataType::kFp16:
      return ElementType::kFloat16;
    case DataType::kFp64:
      return ElementType::kFloat64;
    case DataType::kInt8:
      return ElementType::kInt8;
    case DataType::kUint8:
      return ElementType::kUint8;
    case DataType::kInt16:
      return ElementType::kInt16;
    case DataType::kInt32:
      return ElementType::kInt32;
    case DataType::kInt64:
      return ElementType::kInt64;
    case DataType::kBool:
      return ElementType::kBool;
    case DataType::kBytes:
      return ElementType::kString;
    default:
      return ElementType::kOther;
  }
}

std::optional<DataType> DataTypeOf(ElementType type) {
  switch (type) {
    case ElementType::kFloat32:
      return DataType::kFp32;
    case ElementType::kFloat16:
      return DataType::kFp16;
    case ElementType::kFloat64:
      return DataType::kFp64;
    case ElementType::kInt8:
      return DataType::kInt8;
    case ElementType::kUint8:
      return DataType::kUint8;
    case ElementType::kInt16:
      return DataType::kInt16;
    case ElementType::kInt32:
      return DataType::kInt32;
    case ElementType::kInt64:
      return DataType::kInt64;
    case ElementType::kBool:
      return DataType::kBool;
    case ElementType::kString:
      return DataType::kBytes;
    default:
      return std::nullopt;
  }
}

Result<segmentation_service::Tensor> ToWire(const InputTensor& in) {
  switch (in.type) {
    case ElementType::kFloat32:
      return segmentation_service::MakeTensor<float>(
          in.name, DataType::kFp32, in.shape,
          std::span<const float>(static_cast<const float*>(in.data), in.count));
    case ElementType::kInt64:
      return segmentation_service::MakeTensor<int64_t>(
          in.name, DataType::kInt64, in.shape,
          std::span<const int64_t>(static_cast<const int64_t*>(in.data), in.count));
    case ElementType::kBool: {
      // ORT booleans are one byte, anything but 0 true; the wire's BOOL is one byte 0 or 1.
      const auto* b = static_cast<const uint8_t*>(in.data);
      std::vector<uint8_t> v(b, b + in.count);
      for (uint8_t& x : v) x = x != 0 ? 1 : 0;
      return segmentation_service::MakeTensor<uint8_t>(in.name, DataType::kBool, in.shape,
                                                       std::span<const uint8_t>(v));
    }
    default:
      return InvalidArgumentError(
          fmt::format("input '{}' is {}: only float32, int64 and bool "
                      "inputs are sent to a model server",
                      in.name, ToString(in.type)));
  }
}

Result<OutputTensor> FromWire(const segmentation_service::Tensor& t) {
  AVP_RETURN_IF_ERROR(segmentation_service::CheckTensor(t, "output"));
  OutputTensor o;
  o.name = t.name;
  o.shape = t.shape;
  o.type = ElementTypeOf(t.datatype);
  switch (t.datatype) {
    case DataType::kFp32: {
      AVP_ASSIGN_OR_RETURN(o.f32, segmentation_service::ReadValues<float>(t));
      return o;
    }
    case DataType::kInt64: {
      AVP_ASSIGN_OR_RETURN(o.i64, segmentation_service::ReadValues<int64_t>(t));
      return o;
    }
    case DataType::kInt32: {
      AVP_ASSIGN_OR_RETURN(const std::vector<int32_t> v,
                           segmentation_service::ReadValues<int32_t>(t));
      o.i64.assign(v.begin(), v.end());
      return o;
    }
    case DataType::kBool: {
      AVP_ASSIGN_OR_RETURN(const std::vector<uint8_t> v,
                           segmentation_service::ReadValues<uint8_t>(t));
      o.i64.reserve(v.size());
      for (uint8_t x : v) o.i64.push_back(x != 0 ? 1 : 0);
      return o;
    }
    default:
      return InvalidArgumentError(fmt::format(
          "output {} is not FP32, INT64, INT32 or BOOL, which the backends read", t.Describe()));
  }
}

Result<segmentation_service::Tensor> ToWire(const OutputTensor& o) {
  switch (o.type) {
    case ElementType::kFloat32:
      return segmentation_service::MakeTensor<float>(o.name, DataType::kFp32, o.shape,
                                                     std::span<const float>(o.f32));
    case ElementType::kInt64:
      return segmentation_service::MakeTensor<int64_t>(o.name, DataType::kInt64, o.shape,
                                                       std::span<const int64_t>(o.i64));
    case ElementType::kInt32: {
      std::vector<int32_t> v(o.i64.begin(), o.i64.end());
      return segmentation_service::MakeTensor<int32_t>(o.name, DataType::kInt32, o.shape,
                                                       std::span<const int32_t>(v));
    }
    case ElementType::kBool: {
      std::vector<uint8_t> v;
      v.reserve(o.i64.size());
      for (int64_t x : o.i64) v.push_back(x != 0 ? 1 : 0);
      return segmentation_service::MakeTensor<uint8_t>(o.name, DataType::kBool, o.shape,
                                                       std::span<const uint8_t>(v));
    }
    default:
      return InvalidArgumentError(
          fmt::format("output '{}' is {}: not served", o.name, ToString(o.type)));
  }
}

Result<ModelRef> ConnectRemoteModel(std::string_view server, const std::string& model,
                                    const std::string& label_in, double deadline_s) {
  const std::string label = label_in.empty() ? model : label_in;
  AVP_ASSIGN_OR_RETURN(const std::string address, segmentation_service::ParseGrpcAddress(server));
  segmentation_service::TensorClientOptions options;
  options.address = address;
  options.model = model;
  options.deadline_s = deadline_s;
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<segmentation_service::TensorClient> client,
                       segmentation_service::TensorClient::Create(options));
  Result<segmentation_service::TensorModelMetadata> meta = client->Metadata();
  if (!meta.ok()) {
    return Status(meta.status().code(), fmt::format("{}: on model server {}: {}", model, server,
                                                    meta.status().message()));
  }
  ModelIo io;
  const auto convert = [&](const std::vector<segmentation_service::TensorSpec>& specs,
                           std::vector<TensorInfo>& out) -> Status {
    for (const segmentation_service::TensorSpec& s : specs) {
      const ElementType type = ElementTypeOf(s.datatype);
      if (type == ElementType::kOther) {
        return InvalidArgumentError(fmt::format("{}: model server {} declares tensor '{}' as {}",
                                                label, server, s.name, ToString(s.datatype)));
      }
      std::vector<int64_t> shape = s.shape;
      for (int64_t& d : shape) d = d < 0 ? kDynamicDim : d;
      out.push_back({s.name, type, std::move(shape)});
    }
    return Status::Ok();
  };
  AVP_RETURN_IF_ERROR(convert(meta->inputs, io.inputs));
  AVP_RETURN_IF_ERROR(convert(meta->outputs, io.outputs));
  std::shared_ptr<segmentation_service::TensorClient> shared(std::move(client));
  return ModelRef(std::make_shared<const WireModel>(
      [shared](segmentation_service::InferRequest request) {
        return shared->Infer(std::move(request));
      },
      model, std::move(io), fmt::format("remote {}/{}", server, model)));
}

ModelRef HandlerModel(std::shared_ptr<const segmentation_service::TensorModelHandler> handler,
                      std::string label, ModelIo io, std::string provider) {
  return ModelRef(std::make_shared<const WireModel>(
      [handler](segmentation_service::InferRequest request) { return handler->Infer(request); },
      std::move(label), std::move(io), std::move(provider)));
}

}  // namespace avp::zsl

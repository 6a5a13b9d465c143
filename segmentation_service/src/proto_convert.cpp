#include "proto_convert.h"

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>

#include <fmt/format.h>
#include <netdb.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <unistd.h>

#include <avp/core/text.h>

namespace avp::segmentation_service::internal {

namespace {

/// Elements in every typed field of `c`.
size_t TotalTypedElements(const inference::InferTensorContents& c) {
  return static_cast<size_t>(c.bool_contents_size()) + c.int_contents_size() +
         c.int64_contents_size() + c.uint_contents_size() + c.uint64_contents_size() +
         c.fp32_contents_size() + c.fp64_contents_size() + c.bytes_contents_size();
}

template <typename Dst, typename Field>
Status PackTyped(const Field& field, std::string_view field_name, Tensor& t, std::string_view role,
                 int64_t n) {
  if (static_cast<int64_t>(field.size()) != n) {
    return InvalidArgumentError(fmt::format("{} '{}': shape {} of {} needs {} {}, got {}", role,
                                            t.name, ShapeToString(t.shape), ToString(t.datatype), n,
                                            field_name, field.size()));
  }
  t.data.resize(static_cast<size_t>(n) * sizeof(Dst));
  char* out = t.data.data();
  int64_t i = 0;
  for (const auto v : field) {
    using Src = std::decay_t<decltype(v)>;
    if constexpr (std::is_integral_v<Src> && !std::is_same_v<Src, bool> &&
                  !std::is_same_v<Src, Dst>) {
      if (!std::in_range<Dst>(v)) {
        return InvalidArgumentError(fmt::format("{} '{}': {}[{}] ({}) is out of range for {}", role,
                                                t.name, field_name, i, v, ToString(t.datatype)));
      }
    }
    const Dst d = static_cast<Dst>(v);
    CopyLittleEndian(out + i * sizeof(Dst), &d, 1, sizeof(Dst));
    ++i;
  }
  return Status::Ok();
}

/// The tensor of an InferInputTensor / InferOutputTensor; `raw` is its raw contents or null.
template <typename Msg>
Result<Tensor> TensorFromProto(const Msg& m, const std::string* raw, std::string_view role) {
  Tensor t;
  t.name = m.name();
  const std::optional<DataType> datatype = DataTypeFromString(m.datatype());
  if (!datatype) {
    return InvalidArgumentError(fmt::format(
        "{} '{}': unknown datatype '{}' (expected BOOL, UINT8, UINT16, UINT32, UINT64, INT8, "
        "INT16, INT32, INT64, FP16, FP32, FP64, BF16 or BYTES)",
        role, m.name(), m.datatype()));
  }
  t.datatype = *datatype;
  t.shape.assign(m.shape().begin(), m.shape().end());
  if (raw != nullptr) {
    t.data = *raw;
    return t;
  }
  const std::optional<int64_t> n = t.NumElements();
  if (!n) {
    return InvalidArgumentError(
        fmt::format("{} {}: the shape has a negative or huge dimension", role, t.Describe()));
  }
  const inference::InferTensorContents& c = m.contents();
  size_t used = 0;
  Status s;
  switch (t.datatype) {
    case DataType::kBool:
      used = c.bool_contents_size();
      s = PackTyped<uint8_t>(c.bool_contents(), "bool_contents", t, role, *n);
      break;
    case DataType::kUint8:
      used = c.uint_contents_size();
      s = PackTyped<uint8_t>(c.uint_contents(), "uint_contents", t, role, *n);
      break;
    case DataType::kUint16:
      used = c.uint_contents_size();
      s = PackTyped<uint16_t>(c.uint_contents(), "uint_contents", t, role, *n);
      break;
    case DataType::kUint32:
      used = c.uint_contents_size();
      s = PackTyped<uint32_t>(c.uint_contents(), "uint_contents", t, role, *n);
      break;
    case DataType::kUint64:
      used = c.uint64_contents_size();
      s = PackTyped<uint64_t>(c.uint64_contents(), "uint64_contents", t, role, *n);
      break;
    case DataType::kInt8:
      used = c.int_contents_size();
      s = PackTyped<int8_t>(c.int_contents(), "int_contents", t, role, *n);
      break;
    case DataType::kInt16:
      used = c.int_contents_size();
      s = PackTyped<int16_t>(c.int_contents(), "int_contents", t, role, *n);
      break;
    case DataType::kInt32:
      used = c.int_contents_size();
      s = PackTyped<int32_t>(c.int_contents(), "int_contents", t, role, *n);
      break;
    case DataType::kInt64:
      used = c.int64_contents_size();
      s = PackTyped<int64_t>(c.int64_contents(), "int64_contents", t, role, *n);
      break;
    case DataType::kFp32:
      used = c.fp32_contents_size();
      s = PackTyped<float>(c.fp32_contents(), "fp32_contents", t, role, *n);
      break;
    case DataType::kFp64:
      used = c.fp64_contents_size();
      s = PackTyped<double>(c.fp64_contents(), "fp64_contents", t, role, *n);
      break;
    case DataType::kBytes: {
      used = c.bytes_contents_size();
      if (static_cast<int64_t>(c.bytes_contents_size()) != *n) {
        return InvalidArgumentError(
            fmt::format("{} '{}': shape {} of BYTES needs {} bytes_contents, got {}", role, t.name,
                        ShapeToString(t.shape), *n, c.bytes_contents_size()));
      }
      std::vector<std::string> elements(c.bytes_contents().begin(), c.bytes_contents().end());
      t.data = MakeBytesTensor(t.name, elements).data;
      break;
    }
    case DataType::kFp16:
    case DataType::kBf16:
      if (*n == 0) break;
      return InvalidArgumentError(
          fmt::format("{} '{}': {} has no typed contents field; send it in raw contents", role,
                      t.name, ToString(t.datatype)));
  }
  AVP_RETURN_IF_ERROR(s);
  if (TotalTypedElements(c) != used) {
    return InvalidArgumentError(
        fmt::format("{} '{}': typed contents in a field that does not match its datatype {}", role,
                    t.name, ToString(t.datatype)));
  }
  return t;
}

template <typename Msg>
void TensorToProto(Tensor& t, Msg* m) {
  m->set_name(std::move(t.name));
  m->set_datatype(std::string(ToString(t.datatype)));
  for (const int64_t d : t.shape) m->add_shape(d);
}

template <typename TensorMsgs, typename RawList>
Result<std::vector<Tensor>> TensorsFromProto(const TensorMsgs& tensors, const RawList& raw,
                                             std::string_view role, std::string_view raw_field) {
  if (raw.size() > 0 && raw.size() != tensors.size()) {
    return InvalidArgumentError(fmt::format("{} has {} entries for {} {}s: expected one per {}",
                                            raw_field, raw.size(), tensors.size(), role, role));
  }
  std::vector<Tensor> out;
  out.reserve(tensors.size());
  for (int i = 0; i < tensors.size(); ++i) {
    const auto& m = tensors.Get(i);
    if (raw.size() > 0 && m.has_contents() && TotalTypedElements(m.contents()) > 0) {
      return InvalidArgumentError(
          fmt::format("{} '{}' has typed contents although {} is given: use one or the other", role,
                      m.name(), raw_field));
    }
    AVP_ASSIGN_OR_RETURN(Tensor t,
                         TensorFromProto(m, raw.size() > 0 ? &raw.Get(i) : nullptr, role));
    out.push_back(std::move(t));
  }
  return out;
}

}  // namespace

Parameters FromProto(const google::protobuf::Map<std::string, inference::InferParameter>& in) {
  Parameters out;
  for (const auto& [key, p] : in) {
    switch (p.parameter_choice_case()) {
      case inference::InferParameter::kBoolParam:
        out[key] = p.bool_param();
        break;
      case inference::InferParameter::kInt64Param:
        out[key] = static_cast<int64_t>(p.int64_param());
        break;
      case inference::InferParameter::kStringParam:
        out[key] = p.string_param();
        break;
      case inference::InferParameter::kDoubleParam:
        out[key] = p.double_param();
        break;
      case inference::InferParameter::kUint64Param:
        out[key] = static_cast<uint64_t>(p.uint64_param());
        break;
      case inference::InferParameter::PARAMETER_CHOICE_NOT_SET:
        break;
    }
  }
  return out;
}

void ToProto(const Parameters& in,
             google::protobuf::Map<std::string, inference::InferParameter>* out) {
  for (const auto& [key, value] : in) {
    inference::InferParameter& p = (*out)[key];
    std::visit(
        [&p](const auto& v) {
          using V = std::decay_t<decltype(v)>;
          if constexpr (std::is_same_v<V, bool>) p.set_bool_param(v);
          if constexpr (std::is_same_v<V, int64_t>) p.set_int64_param(v);
          if constexpr (std::is_same_v<V, uint64_t>) p.set_uint64_param(v);
          if constexpr (std::is_same_v<V, double>) p.set_double_param(v);
          if constexpr (std::is_same_v<V, std::string>) p.set_string_param(v);
        },
        value);
  }
}

void ToProto(InferRequest request, inference::ModelInferRequest* out) {
  out->set_model_name(std::move(request.model_name));
  out->set_model_version(std::move(request.model_version));
  out->set_id(std::move(request.id));
  ToProto(request.parameters, out->mutable_parameters());
  for (Tensor& t : request.inputs) {
    TensorToProto(t, out->add_inputs());
    out->add_raw_input_contents(std::move(t.data));
  }
  for (std::string& name : request.requested_outputs) {
    out->add_outputs()->set_name(std::move(name));
  }
}

Result<InferRequest> FromProto(const inference::ModelInferRequest& request) {
  InferRequest out;
  out.model_name = request.model_name();
  out.model_version = request.model_version();
  out.id = request.id();
  out.parameters = FromProto(request.parameters());
  AVP_ASSIGN_OR_RETURN(out.inputs, TensorsFromProto(request.inputs(), request.raw_input_contents(),
                                                    "input", "raw_input_contents"));
  for (const auto& o : request.outputs()) out.requested_outputs.push_back(o.name());
  return out;
}

void ToProto(InferResponse response, inference::ModelInferResponse* out) {
  out->set_model_name(std::move(response.model_name));
  out->set_model_version(std::move(response.model_version));
  out->set_id(std::move(response.id));
  ToProto(response.parameters, out->mutable_parameters());
  for (Tensor& t : response.outputs) {
    TensorToProto(t, out->add_outputs());
    out->add_raw_output_contents(std::move(t.data));
  }
}

Result<InferResponse> FromProto(const inference::ModelInferResponse& response) {
  InferResponse out;
  out.model_name = response.model_name();
  out.model_version = response.model_version();
  out.id = response.id();
  out.parameters = FromProto(response.parameters());
  AVP_ASSIGN_OR_RETURN(
      out.outputs, TensorsFromProto(response.outputs(), response.raw_output_contents(), "output",
                                    "raw_output_contents"));
  return out;
}

grpc::Status ToGrpcStatus(const Status& status) {
  switch (status.code()) {
    case StatusCode::kOk:
      return grpc::Status::OK;
    case StatusCode::kInvalidArgument:
    case StatusCode::kParseError:
      return {grpc::StatusCode::INVALID_ARGUMENT, status.message()};
    case StatusCode::kNotFound:
      return {grpc::StatusCode::NOT_FOUND, status.message()};
    case StatusCode::kFailedPrecondition:
      return {grpc::StatusCode::FAILED_PRECONDITION, status.message()};
    case StatusCode::kOutOfRange:
      return {grpc::StatusCode::OUT_OF_RANGE, status.message()};
    case StatusCode::kDeadlineExceeded:
      return {grpc::StatusCode::DEADLINE_EXCEEDED, status.message()};
    case StatusCode::kUnavailable:
      return {grpc::StatusCode::UNAVAILABLE, status.message()};
    case StatusCode::kCancelled:
      return {grpc::StatusCode::CANCELLED, status.message()};
    case StatusCode::kResourceExhausted:
      return {grpc::StatusCode::RESOURCE_EXHAUSTED, status.message()};
    default:
      return {grpc::StatusCode::INTERNAL, status.message()};
  }
}

Status TensorSpecsFromProto(const google::protobuf::RepeatedPtrField<
                                inference::ModelMetadataResponse::TensorMetadata>& tensors,
                            std::string_view who, std::vector<TensorSpec>* out) {
  for (const auto& t : tensors) {
    const std::optional<DataType> datatype = DataTypeFromString(t.datatype());
    if (!datatype) {
      return InvalidArgumentError(
          fmt::format("{}: ModelMetadata lists tensor '{}' with unknown datatype '{}'", who,
                      t.name(), t.datatype()));
    }
    out->push_back({t.name(), *datatype, {t.shape().begin(), t.shape().end()}, false});
  }
  return Status::Ok();
}

Status CheckCanListen(std::string_view who, const std::string& host, int port) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* found = nullptr;
  const std::string service = std::to_string(port);
  if (const int rc = getaddrinfo(host.c_str(), service.c_str(), &hints, &found); rc != 0) {
    return InvalidArgumentError(
        fmt::format("{}: --host {} is not an address or a name this "
                    "machine resolves ({})",
                    who, QuoteText(host), gai_strerror(rc)));
  }
  std::string reason = "no address";
  bool ok = false;
  for (const addrinfo* a = found; a != nullptr && !ok; a = a->ai_next) {
    const int fd = socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd < 0) {
      reason = std::strerror(errno);
      continue;
    }
    const int on = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &on, sizeof(on));
    if (bind(fd, a->ai_addr, a->ai_addrlen) == 0) {
      ok = true;
    } else {
      reason = errno == EADDRINUSE      ? "the port is in use"
               : errno == EADDRNOTAVAIL ? "not an address of this machine"
               : errno == EACCES        ? "a port below 1024 needs privileges"
                                        : std::strerror(errno);
    }
    close(fd);
  }
  freeaddrinfo(found);
  if (ok) return Status::Ok();
  return IoError(fmt::format("{}: cannot listen on {}: {}", who, HostPort(host, port), reason));
}

std::string HostPort(const std::string& host, int port) {
  return host.find(':') != std::string::npos && host.front() != '['
             ? fmt::format("[{}]:{}", host, port)
             : fmt::format("{}:{}", host, port);
}

}  // namespace avp::segmentation_service::internal

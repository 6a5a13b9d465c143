#include "avp/segmentation_service/tensor_service.h"

#include <algorithm>
#include <atomic>
#include <charconv>
#include <map>
#include <set>
#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/resource_quota.h>

#include "avp/segmentation_service/tensor_batcher.h"
#include "grpc_predict_v2.grpc.pb.h"
#include "proto_convert.h"

namespace avp::segmentation_service {

namespace {

constexpr int kMinMessageBytes = 1 << 20;
/// The one version of every model (a std::string: GCC 12 warns falsely on "1" assigned inline).
const std::string& Version() {
  static const std::string v(1, '1');
  return v;
}
constexpr int kMaxMessageBytes = 1 << 30;

std::string SpecList(const std::vector<TensorSpec>& specs) {
  std::vector<std::string> out;
  for (const TensorSpec& s : specs) {
    out.push_back(fmt::format("'{}' {} {}", s.name, ToString(s.datatype), ShapeToString(s.shape)));
  }
  return fmt::format("{}", fmt::join(out, ", "));
}

/// The request's inputs against the model's: each declared input exactly once, no other, with
/// the declared datatype, rank and static dimensions, and contents that fill the shape.
Status CheckInputs(const TensorModelHandler& model, const InferRequest& request,
                   int64_t max_dynamic_dim) {
  std::set<std::string> seen;
  for (const Tensor& t : request.inputs) {
    const auto it = std::find_if(model.inputs().begin(), model.inputs().end(),
                                 [&](const TensorSpec& s) { return s.name == t.name; });
    if (it == model.inputs().end()) {
      return InvalidArgumentError(fmt::format("model '{}' has no input '{}' (its inputs: {})",
                                              model.name(), t.name, SpecList(model.inputs())));
    }
    if (!seen.insert(t.name).second) {
      return InvalidArgumentError(
          fmt::format("model '{}': input '{}' is given twice", model.name(), t.name));
    }
    bool shape_ok = t.datatype == it->datatype && t.shape.size() == it->shape.size();
    for (size_t d = 0; shape_ok && d < t.shape.size(); ++d) {
      shape_ok = it->shape[d] < 0 || it->shape[d] == t.shape[d];
    }
    // A dynamic dimension sizes the outputs too (SAM's B boxes give B masks): bounded before the
    // model runs, whatever the request's own size.
    for (size_t d = 0; shape_ok && d < t.shape.size(); ++d) {
      if (it->shape[d] < 0 && t.shape[d] > max_dynamic_dim) {
        return ResourceExhaustedError(fmt::format(
            "model '{}': input {}: dimension {} ({}) exceeds the limit max_dynamic_dim = {}",
            model.name(), t.Describe(), d, t.shape[d], max_dynamic_dim));
      }
    }
    if (!shape_ok) {
      return InvalidArgumentError(fmt::format("model '{}': input {} does not fit '{}' {} {}",
                                              model.name(), t.Describe(), it->name,
                                              ToString(it->datatype), ShapeToString(it->shape)));
    }
    AVP_RETURN_IF_ERROR(CheckTensor(t, fmt::format("model '{}': input", model.name())));
  }
  for (const TensorSpec& s : model.inputs()) {
    if (!s.optional && !seen.contains(s.name)) {
      return InvalidArgumentError(fmt::format("model '{}': input '{}' ({} {}) is missing",
                                              model.name(), s.name, ToString(s.datatype),
                                              ShapeToString(s.shape)));
    }
  }
  return Status::Ok();
}

void ToProto(
    const std::vector<TensorSpec>& specs,
    google::protobuf::RepeatedPtrField<inference::ModelMetadataResponse::TensorMetadata>* out) {
  for (const TensorSpec& s : specs) {
    auto* t = out->Add();
    t->set_name(s.name);
    t->set_datatype(std::string(ToString(s.datatype)));
    for (int64_t d : s.shape) t->add_shape(d);
  }
}

}  // namespace

Status TensorServerOptions::Validate() const {
  std::vector<std::string> problems;
  if (host.empty()) problems.push_back("host is empty");
  if (port < 0 || port > 65535)
    problems.push_back(fmt::format("port ({}) must be in [0, 65535]", port));
  if (threads < 1 || threads > 1024) {
    problems.push_back(fmt::format("threads ({}) must be in [1, 1024]", threads));
  }
  if (max_dynamic_dim < 1 || max_dynamic_dim > (int64_t{1} << 20)) {
    problems.push_back(
        fmt::format("max_dynamic_dim ({}) must be in [1, 1048576]", max_dynamic_dim));
  }
  if (max_message_bytes < kMinMessageBytes || max_message_bytes > kMaxMessageBytes) {
    problems.push_back(fmt::format("max_message_bytes ({}) must be in [{}, {}]", max_message_bytes,
                                   kMinMessageBytes, kMaxMessageBytes));
  }
  if (Status b = batching.Validate(); !b.ok()) problems.push_back(b.message());
  if (problems.empty()) return Status::Ok();
  return InvalidArgumentError(
      fmt::format("invalid tensor server options: {}", fmt::join(problems, "; ")));
}

struct TensorServer::Impl final : public inference::GRPCInferenceService::Service {
  TensorServerOptions options;
  std::map<std::string, std::shared_ptr<const TensorModelHandler>, std::less<>> models;
  /// The batched ones among them, and how each model is served (TensorServer::batching).
  std::map<std::string, std::shared_ptr<const BatchingHandler>> batched;
  std::map<std::string, std::string> batching;
  std::unique_ptr<grpc::Server> server;
  int port = 0;
  std::atomic<uint64_t> infer_ok{0}, infer_failed{0};

  const TensorModelHandler* Find(const std::string& name) const {
    const auto it = models.find(name);
    return it == models.end() ? nullptr : it->second.get();
  }
  grpc::Status NotServed(const std::string& name) const {
    std::vector<std::string> names;
    for (const auto& [n, m] : models) names.push_back(n);
    return grpc::Status(
        grpc::StatusCode::NOT_FOUND,
        fmt::format("no model '{}' here (this server serves {})", name,
                    names.empty() ? "none" : fmt::format("{}", fmt::join(names, ", "))));
  }

  grpc::Status ServerLive(grpc::ServerContext*, const inference::ServerLiveRequest*,
                          inference::ServerLiveResponse* response) override {
    response->set_live(true);
    return grpc::Status::OK;
  }
  grpc::Status ServerReady(grpc::ServerContext*, const inference::ServerReadyRequest*,
                           inference::ServerReadyResponse* response) override {
    response->set_ready(true);
    return grpc::Status::OK;
  }
  grpc::Status ServerMetadata(grpc::ServerContext*, const inference::ServerMetadataRequest*,
                              inference::ServerMetadataResponse* response) override {
    response->set_name("avp-serve-models");
    response->set_version("1");
    return grpc::Status::OK;
  }
  grpc::Status ModelReady(grpc::ServerContext*, const inference::ModelReadyRequest* request,
                          inference::ModelReadyResponse* response) override {
    response->set_ready(Find(request->name()) != nullptr);
    return grpc::Status::OK;
  }
  grpc::Status ModelMetadata(grpc::ServerContext*, const inference::ModelMetadataRequest* request,
                             inference::ModelMetadataResponse* response) override {
    const TensorModelHandler* m = Find(request->name());
    if (m == nullptr) return NotServed(request->name());
    response->set_name(m->name());
    response->add_versions(Version());
    response->set_platform(m->platform());
    ToProto(m->inputs(), response->mutable_inputs());
    ToProto(m->outputs(), response->mutable_outputs());
    return grpc::Status::OK;
  }
  grpc::Status ModelInfer(grpc::ServerContext*, const inference::ModelInferRequest* request,
                          inference::ModelInferResponse* response) override {
    const TensorModelHandler* m = Find(request->model_name());
    if (m == nullptr) {
      ++infer_failed;
      return NotServed(request->model_name());
    }
    Result<InferRequest> decoded = internal::FromProto(*request);
    Status s = decoded.status();
    if (s.ok()) s = CheckInputs(*m, *decoded, options.max_dynamic_dim);
    Result<InferResponse> answer = s.ok() ? m->Infer(*decoded) : Result<InferResponse>(s);
    if (!answer.ok()) {
      ++infer_failed;
      return internal::ToGrpcStatus(answer.status());
    }
    answer->model_name = m->name();
    answer->model_version = Version();
    answer->id = request->id();
    internal::ToProto(std::move(*answer), response);
    ++infer_ok;
    return grpc::Status::OK;
  }
};

Result<std::unique_ptr<TensorServer>> TensorServer::Start(
    const TensorServerOptions& options,
    std::vector<std::shared_ptr<const TensorModelHandler>> models) {
  AVP_RETURN_IF_ERROR(options.Validate());
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  for (std::shared_ptr<const TensorModelHandler>& m : models) {
    if (m == nullptr) return InvalidArgumentError("tensor server: a model handler is null");
    const std::string name = m->name();
    std::string how = "batching off";
    if (options.batching.max_batch > 1) {
      if (std::optional<std::string> why = WhyNotBatchable(*m)) {
        how = fmt::format("not batched: {}", *why);
      } else {
        AVP_ASSIGN_OR_RETURN(std::shared_ptr<BatchingHandler> b,
                             BatchingHandler::Make(m, options.batching));
        how = "batched: " + options.batching.Describe();
        impl->batched[name] = b;
        m = std::move(b);
      }
    }
    impl->batching[name] = how;
    if (!impl->models.emplace(name, std::move(m)).second) {
      return InvalidArgumentError(fmt::format("tensor server: two models are named '{}'", name));
    }
  }
  AVP_RETURN_IF_ERROR(internal::CheckCanListen("tensor server", options.host, options.port));
  const std::string address = internal::HostPort(options.host, options.port);
  grpc::ServerBuilder builder;
  builder.AddListeningPort(address, grpc::InsecureServerCredentials(), &impl->port);
  builder.RegisterService(impl.get());
  builder.SetMaxReceiveMessageSize(options.max_message_bytes);
  builder.SetMaxSendMessageSize(options.max_message_bytes);
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // `threads` calls at once. The quota counts every thread of the server: one completion queue
  // with 1 to 2 polling threads, and threads that have sent their answer but not yet returned to
  // polling (their client may already have sent the next call). With a quota of threads + 1 and
  // gRPC's default of one queue per core, 16 clients one call at a time on 16 threads were
  // refused "Server Threadpool Exhausted" a few hundred times in 5 s; the slack absorbs it.
  builder.SetSyncServerOption(grpc::ServerBuilder::NUM_CQS, 1);
  builder.SetSyncServerOption(grpc::ServerBuilder::MIN_POLLERS, 1);
  builder.SetSyncServerOption(grpc::ServerBuilder::MAX_POLLERS, 2);
  grpc::ResourceQuota quota("avp-tensor-server");
  quota.SetMaxThreads(2 * options.threads + 2);
  builder.SetResourceQuota(quota);
  impl->server = builder.BuildAndStart();
  if (impl->server == nullptr || impl->port == 0) {
    return IoError(
        fmt::format("tensor server: cannot listen on {} (address in use, or not an address of this "
                    "machine?)",
                    address));
  }
  return std::unique_ptr<TensorServer>(new TensorServer(std::move(impl)));
}

TensorServer::TensorServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TensorServer::~TensorServer() { Shutdown(std::chrono::milliseconds(0)); }

int TensorServer::port() const { return impl_->port; }
std::string TensorServer::address() const {
  return internal::HostPort(impl_->options.host, impl_->port);
}
TensorServerStats TensorServer::stats() const {
  TensorServerStats stats{impl_->infer_ok.load(), impl_->infer_failed.load(), {}};
  for (const auto& [name, b] : impl_->batched) stats.batching[name] = b->stats();
  return stats;
}
std::map<std::string, std::string> TensorServer::batching() const { return impl_->batching; }
void TensorServer::Shutdown(std::chrono::milliseconds grace) {
  if (impl_->server == nullptr) return;
  impl_->server->Shutdown(std::chrono::system_clock::now() + grace);
  impl_->server->Wait();
  impl_->server.reset();
}

// ---- client ------------------------------------------------------------------------------------

Status TensorClientOptions::Validate() const {
  std::vector<std::string> problems;
  if (address.empty()) problems.push_back("address is empty");
  if (model.empty()) problems.push_back("model is empty");
  if (!(deadline_s > 0.0))
    problems.push_back(fmt::format("deadline_s ({}) must be > 0", deadline_s));
  if (max_message_bytes < kMinMessageBytes || max_message_bytes > kMaxMessageBytes) {
    problems.push_back(fmt::format("max_message_bytes ({}) must be in [{}, {}]", max_message_bytes,
                                   kMinMessageBytes, kMaxMessageBytes));
  }
  if (problems.empty()) return Status::Ok();
  return InvalidArgumentError(
      fmt::format("invalid tensor client options: {}", fmt::join(problems, "; ")));
}

Result<std::string> ParseGrpcAddress(std::string_view url) {
  constexpr std::string_view kScheme = "grpc://";
  const auto bad = [&](std::string_view why) {
    return InvalidArgumentError(fmt::format(
        "model server '{}' must be grpc://HOST:PORT (e.g. grpc://127.0.0.1:8001): {}", url, why));
  };
  if (url.substr(0, kScheme.size()) != kScheme) return bad("no grpc:// in front");
  std::string_view rest = url.substr(kScheme.size());
  if (!rest.empty() && rest.back() == '/') rest.remove_suffix(1);
  const size_t colon = rest.rfind(':');
  if (colon == std::string_view::npos || colon == 0) return bad("no HOST:PORT");
  const std::string_view host = rest.substr(0, colon);
  const std::string_view port_text = rest.substr(colon + 1);
  if (host.find(':') != std::string_view::npos && (host.front() != '[' || host.back() != ']')) {
    return bad("an IPv6 host goes in brackets");
  }
  int port = 0;
  const auto [ptr, ec] =
      std::from_chars(port_text.data(), port_text.data() + port_text.size(), port);
  if (port_text.empty() || ec != std::errc() || ptr != port_text.data() + port_text.size() ||
      port < 1 || port > 65535) {
    return bad(fmt::format("port '{}' is not in [1, 65535]", port_text));
  }
  return std::string(rest);
}

struct TensorClient::Impl {
  TensorClientOptions options;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<inference::GRPCInferenceService::Stub> stub;

  void Deadline(grpc::ClientContext& context) const {
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::duration_cast<std::chrono::system_clock::duration>(
                             std::chrono::duration<double>(options.deadline_s)));
  }
  Status FromGrpc(const grpc::Status& s, std::string_view call) const {
    const std::string what = fmt::format("model '{}' at {}: {}: {}", options.model, options.address,
                                         call, s.error_message());
    switch (s.error_code()) {
      case grpc::StatusCode::OK:
        return Status::Ok();
      case grpc::StatusCode::INVALID_ARGUMENT:
        return InvalidArgumentError(what);
      case grpc::StatusCode::NOT_FOUND:
        return NotFoundError(what);
      case grpc::StatusCode::FAILED_PRECONDITION:
        return FailedPreconditionError(what);
      case grpc::StatusCode::RESOURCE_EXHAUSTED:
        if (s.error_message() == "Server Threadpool Exhausted") {
          return ResourceExhaustedError(
              what +
              " (every thread of the server is busy with another call: retry later, or "
              "raise its threads, e.g. avp serve models --threads N)");
        }
        return ResourceExhaustedError(what);
      case grpc::StatusCode::UNAVAILABLE:
        return UnavailableError(what);
      case grpc::StatusCode::DEADLINE_EXCEEDED:
        return DeadlineExceededError(what);
      case grpc::StatusCode::CANCELLED:
        return CancelledError(what);
      default:
        return IoError(what);
    }
  }
};

Result<std::unique_ptr<TensorClient>> TensorClient::Create(TensorClientOptions options) {
  AVP_RETURN_IF_ERROR(options.Validate());
  auto impl = std::make_unique<Impl>();
  impl->options = std::move(options);
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(impl->options.max_message_bytes);
  args.SetMaxSendMessageSize(impl->options.max_message_bytes);
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 2000);
  impl->channel =
      grpc::CreateCustomChannel(impl->options.address, grpc::InsecureChannelCredentials(), args);
  impl->stub = inference::GRPCInferenceService::NewStub(impl->channel);
  return std::unique_ptr<TensorClient>(new TensorClient(std::move(impl)));
}

TensorClient::TensorClient(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TensorClient::~TensorClient() = default;

const TensorClientOptions& TensorClient::options() const { return impl_->options; }

Result<bool> TensorClient::Ready() {
  grpc::ClientContext context;
  impl_->Deadline(context);
  inference::ModelReadyRequest request;
  request.set_name(impl_->options.model);
  inference::ModelReadyResponse response;
  const grpc::Status s = impl_->stub->ModelReady(&context, request, &response);
  if (!s.ok()) return impl_->FromGrpc(s, "ModelReady");
  return response.ready();
}

Result<TensorModelMetadata> TensorClient::Metadata() {
  grpc::ClientContext context;
  impl_->Deadline(context);
  inference::ModelMetadataRequest request;
  request.set_name(impl_->options.model);
  inference::ModelMetadataResponse response;
  const grpc::Status s = impl_->stub->ModelMetadata(&context, request, &response);
  if (!s.ok()) return impl_->FromGrpc(s, "ModelMetadata");
  TensorModelMetadata out;
  out.name = response.name();
  out.platform = response.platform();
  const std::string who =
      fmt::format("model '{}' at {}", impl_->options.model, impl_->options.address);
  AVP_RETURN_IF_ERROR(internal::TensorSpecsFromProto(response.inputs(), who, &out.inputs));
  AVP_RETURN_IF_ERROR(internal::TensorSpecsFromProto(response.outputs(), who, &out.outputs));
  return out;
}

Result<InferResponse> TensorClient::Infer(InferRequest request) {
  request.model_name = impl_->options.model;
  inference::ModelInferRequest proto_request;
  internal::ToProto(std::move(request), &proto_request);
  grpc::ClientContext context;
  impl_->Deadline(context);
  inference::ModelInferResponse proto_response;
  const grpc::Status s = impl_->stub->ModelInfer(&context, proto_request, &proto_response);
  if (!s.ok()) return impl_->FromGrpc(s, "ModelInfer");
  Result<InferResponse> out = internal::FromProto(proto_response);
  if (!out.ok()) {
    return InvalidArgumentError(fmt::format("model '{}' at {}: its answer: {}",
                                            impl_->options.model, impl_->options.address,
                                            out.status().message()));
  }
  return out;
}

}  // namespace avp::segmentation_service

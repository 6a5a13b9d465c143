#include <charconv>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <grpcpp/grpcpp.h>

#include <avp/core/error.h>
#include <avp/segmentation_service/remote_segmenter.h>

#include "grpc_predict_v2.grpc.pb.h"
#include "proto_convert.h"

namespace avp::segmentation_service {

namespace {

constexpr std::string_view kScheme = "remote://";

template <typename T>
std::optional<T> ParseNumber(std::string_view s) {
  T v{};
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size() || s.empty()) return std::nullopt;
  return v;
}

std::string BracketHost(const std::string& host) {
  return host.find(':') != std::string::npos ? "[" + host + "]" : host;
}

}  // namespace

// ---- options and specs --------------------------------------------------------------------------

std::string RemoteOptions::Address() const { return fmt::format("{}:{}", BracketHost(host), port); }

std::string RemoteOptions::Spec() const {
  return fmt::format("{}{}/{}", kScheme, Address(), model);
}

Status RemoteOptions::Validate() const {
  std::vector<std::string> errors;
  if (host.empty()) errors.push_back("host must not be empty");
  if (port < 1 || port > 65535)
    errors.push_back(fmt::format("port ({}) must be in [1, 65535]", port));
  if (model.empty()) errors.push_back("model must not be empty");
  if (!(std::isfinite(deadline_s) && deadline_s > 0.0)) {
    errors.push_back(fmt::format("deadline_s ({}) must be finite and > 0", deadline_s));
  }
  if (max_message_bytes < (1 << 20)) {
    errors.push_back(
        fmt::format("max_message_bytes ({}) must be >= 1 MiB (1048576)", max_message_bytes));
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(
      fmt::format("invalid remote segmenter options: {}", fmt::join(errors, "; ")));
}

namespace {

// Stages of ParseRemoteSpec: each returns what is wrong with its part of the spec ("" when
// nothing), which ParseRemoteSpec wraps in the spec's error message.

/// "/MODEL" after the authority, when given; `authority` is what precedes it.
std::string ReadSpecModel(std::string_view rest, std::string_view& authority, RemoteOptions& o) {
  authority = rest;
  const size_t slash = rest.find('/');
  if (slash == std::string_view::npos) return "";
  authority = rest.substr(0, slash);
  const std::string_view model = rest.substr(slash + 1);
  if (model.empty()) return "the model after '/' is empty";
  if (model.find('/') != std::string_view::npos) {
    return fmt::format("model \"{}\" must not contain '/'", model);
  }
  o.model = std::string(model);
  return "";
}

/// HOST[:PORT] or [IPV6][:PORT].
std::string ReadSpecHostAndPort(std::string_view authority, RemoteOptions& o) {
  std::string_view port_text;
  if (!authority.empty() && authority.front() == '[') {
    const size_t close = authority.find(']');
    if (close == std::string_view::npos) return "IPv6 host lacks its closing ']'";
    o.host = std::string(authority.substr(1, close - 1));
    const std::string_view after = authority.substr(close + 1);
    if (!after.empty()) {
      if (after.front() != ':') return "expected ':PORT' after the IPv6 host";
      port_text = after.substr(1);
      if (port_text.empty()) return "the port after ':' is empty";
    }
  } else {
    const size_t colon = authority.find(':');
    o.host = std::string(authority.substr(0, colon));
    if (colon != std::string_view::npos) {
      port_text = authority.substr(colon + 1);
      if (port_text.empty()) return "the port after ':' is empty";
    }
  }
  if (o.host.empty()) return "the host is empty";
  if (!port_text.empty()) {
    const std::optional<int> port = ParseNumber<int>(port_text);
    if (!port || *port < 1 || *port > 65535) {
      return fmt::format("port ({}) must be in [1, 65535]", port_text);
    }
    o.port = *port;
  }
  return "";
}

/// One "KEY=VALUE" of the query: deadline_s, image, depth, labels, masks.
std::string ReadSpecOption(std::string_view key, std::string_view value, RemoteOptions& o) {
  if (key == "deadline_s") {
    const std::optional<double> d = ParseNumber<double>(value);
    if (!d || !(std::isfinite(*d) && *d > 0.0)) {
      return fmt::format("deadline_s ({}) must be a number of seconds > 0", value);
    }
    o.deadline_s = *d;
  } else if (key == "image") {
    const std::optional<ImageEncoding> e = ImageEncodingFromString(value);
    if (!e) return fmt::format("image ({}) must be raw, png or jpeg", value);
    o.image = *e;
  } else if (key == "depth" || key == "labels") {
    if (value != "0" && value != "1") return fmt::format("{} ({}) must be 0 or 1", key, value);
    (key == "depth" ? o.send_depth : o.send_labels) = value == "1";
  } else if (key == "masks") {
    const std::optional<MaskFormat> f = MaskFormatFromString(value);
    if (!f) return fmt::format("masks ({}) must be dense, rle or instance_ids", value);
    o.mask_format = *f;
  } else {
    return fmt::format("unknown option '{}' (known: deadline_s, image, depth, labels, masks)", key);
  }
  return "";
}

}  // namespace

Result<RemoteOptions> ParseRemoteSpec(std::string_view spec) {
  const auto bad = [&](const std::string& what) {
    return InvalidArgumentError(
        fmt::format("remote segmenter spec \"{}\": {} (expected remote://HOST[:PORT][/MODEL], e.g. "
                    "remote://127.0.0.1:{}/{})",
                    spec, what, kDefaultServicePort, kDefaultRemoteModel));
  };
  if (spec.substr(0, kScheme.size()) != kScheme) return bad("does not start with remote://");
  std::string_view rest = spec.substr(kScheme.size());
  std::string_view query;
  if (const size_t q = rest.find('?'); q != std::string_view::npos) {
    query = rest.substr(q + 1);
    rest = rest.substr(0, q);
  }
  RemoteOptions o;
  std::string_view authority;
  if (std::string what = ReadSpecModel(rest, authority, o); !what.empty()) return bad(what);
  if (std::string what = ReadSpecHostAndPort(authority, o); !what.empty()) return bad(what);
  while (!query.empty()) {
    const size_t amp = query.find('&');
    const std::string_view item = query.substr(0, amp);
    query = amp == std::string_view::npos ? std::string_view() : query.substr(amp + 1);
    if (item.empty()) continue;
    const size_t eq = item.find('=');
    const std::string_view key = item.substr(0, eq);
    const std::string_view value =
        eq == std::string_view::npos ? std::string_view() : item.substr(eq + 1);
    if (std::string what = ReadSpecOption(key, value, o); !what.empty()) return bad(what);
  }
  AVP_RETURN_IF_ERROR(o.Validate().WithContext(fmt::format("remote segmenter spec \"{}\"", spec)));
  return o;
}

// ---- the client ---------------------------------------------------------------------------------

struct RemoteSegmenter::Impl {
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<inference::GRPCInferenceService::Stub> stub;
};

RemoteSegmenter::RemoteSegmenter(RemoteOptions options)
    : options_(std::move(options)), impl_(std::make_unique<Impl>()) {
  const Status status = options_.Validate();
  AVP_THROW_UNLESS(status.ok(), status.message());
  spec_ = options_.Spec();
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(options_.max_message_bytes);
  args.SetMaxSendMessageSize(options_.max_message_bytes);
  // Reconnect soon after a server (re)starts instead of backing off for up to two minutes.
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 2000);
  // A connection of its own: the server shares its queue fairly between connections, so two
  // segmenters of one process are two clients (gRPC would otherwise share one connection).
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  impl_->channel =
      grpc::CreateCustomChannel(options_.Address(), grpc::InsecureChannelCredentials(), args);
  impl_->stub = inference::GRPCInferenceService::NewStub(impl_->channel);
}

RemoteSegmenter::~RemoteSegmenter() = default;

std::string_view RemoteSegmenter::name() const { return spec_; }

namespace {

void SetDeadline(grpc::ClientContext& context, double deadline_s) {
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::duration_cast<std::chrono::system_clock::duration>(
                           std::chrono::duration<double>(deadline_s)));
}

/// A gRPC failure as an avp status naming the server.
Status FromGrpc(const grpc::Status& s, const RemoteOptions& o, std::string_view call) {
  const std::string where = fmt::format("remote segmenter {}: {}", o.Spec(), call);
  switch (s.error_code()) {
    case grpc::StatusCode::OK:
      return Status::Ok();
    case grpc::StatusCode::INVALID_ARGUMENT:
      return InvalidArgumentError(fmt::format("{}: {}", where, s.error_message()));
    case grpc::StatusCode::NOT_FOUND:
      return NotFoundError(fmt::format("{}: {}", where, s.error_message()));
    case grpc::StatusCode::FAILED_PRECONDITION:
      return FailedPreconditionError(fmt::format("{}: {}", where, s.error_message()));
    case grpc::StatusCode::OUT_OF_RANGE:
      return OutOfRangeError(fmt::format("{}: {}", where, s.error_message()));
    case grpc::StatusCode::UNAVAILABLE:
      return UnavailableError(fmt::format(
          "{}: the segmentation server at {} is unavailable (is `avp serve segmentation --port "
          "{}` running there?): {}",
          where, o.Address(), o.port, s.error_message()));
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return DeadlineExceededError(
          fmt::format("{}: no answer from {} within the deadline of {} s: {}", where, o.Address(),
                      o.deadline_s, s.error_message()));
    case grpc::StatusCode::CANCELLED:
      return CancelledError(fmt::format("{}: the call to {} was cancelled: {}", where, o.Address(),
                                        s.error_message()));
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return ResourceExhaustedError(fmt::format(
          "{}: {} refused the request (a limit of the server, its queue is full, or the message "
          "is larger than the {} bytes allowed on either end): {}",
          where, o.Address(), o.max_message_bytes, s.error_message()));
    case grpc::StatusCode::INTERNAL:
    case grpc::StatusCode::UNKNOWN:
      return InternalError(
          fmt::format("{}: the server at {} failed: {}", where, o.Address(), s.error_message()));
    default:
      return IoError(fmt::format("{}: gRPC status {} from {}: {}", where,
                                 static_cast<int>(s.error_code()), o.Address(), s.error_message()));
  }
}

}  // namespace

Result<Segmentation> RemoteSegmenter::Segment(const segmentation::SegmentationRequest& request) {
  RequestEncodeOptions eo;
  eo.model_name = options_.model;
  eo.seed = options_.seed;
  eo.image = options_.image;
  eo.send_depth = options_.send_depth;
  eo.send_labels = options_.send_labels;
  eo.mask_format = options_.mask_format;
  Result<InferRequest> encoded = EncodeSegmentationRequest(request, eo);
  if (!encoded.ok()) {
    return encoded.status().WithContext(fmt::format("remote segmenter {}", spec_));
  }
  inference::ModelInferRequest proto_request;
  internal::ToProto(std::move(*encoded), &proto_request);
  inference::ModelInferResponse proto_response;
  grpc::ClientContext context;
  SetDeadline(context, options_.deadline_s);
  grpc::Status s;
  if (!request.interrupt) {
    s = impl_->stub->ModelInfer(&context, proto_request, &proto_response);
  } else {
    // Asynchronously, asking the interrupt every 20 ms: a stop cancels the call (the server then
    // stops its work too) and returns the interrupt's status.
    std::mutex mutex;
    std::condition_variable cv;
    bool done = false;
    impl_->stub->async()->ModelInfer(&context, &proto_request, &proto_response,
                                     [&](grpc::Status status) {
                                       std::lock_guard lock(mutex);
                                       s = std::move(status);
                                       done = true;
                                       cv.notify_all();
                                     });
    Status stop;
    std::unique_lock lock(mutex);
    while (!cv.wait_for(lock, std::chrono::milliseconds(20), [&] { return done; })) {
      if (stop.ok()) {
        lock.unlock();
        stop = request.interrupt();
        if (!stop.ok()) context.TryCancel();
        lock.lock();
      }
    }
    if (!stop.ok()) return stop.WithContext(fmt::format("remote segmenter {}", spec_));
  }
  if (!s.ok()) return FromGrpc(s, options_, "ModelInfer");
  Result<InferResponse> response = internal::FromProto(proto_response);
  if (!response.ok()) {
    return response.status().WithContext(fmt::format("remote segmenter {}: the response", spec_));
  }
  Result<Segmentation> segmentation = DecodeSegmentation(*response);
  if (!segmentation.ok()) {
    return segmentation.status().WithContext(
        fmt::format("remote segmenter {}: the response", spec_));
  }
  const int w = request.frame->rgb.width();
  const int h = request.frame->rgb.height();
  if (Status v = segmentation->ValidateFor(w, h); !v.ok()) {
    return InternalError(
        fmt::format("remote segmenter {}: the server returned an invalid "
                    "segmentation for the {}x{} frame: {}",
                    spec_, w, h, v.message()));
  }
  return segmentation;
}

Result<bool> RemoteSegmenter::ServerLive() {
  grpc::ClientContext context;
  SetDeadline(context, options_.deadline_s);
  inference::ServerLiveResponse response;
  const grpc::Status s =
      impl_->stub->ServerLive(&context, inference::ServerLiveRequest(), &response);
  if (!s.ok()) return FromGrpc(s, options_, "ServerLive");
  return response.live();
}

Result<bool> RemoteSegmenter::ServerReady() {
  grpc::ClientContext context;
  SetDeadline(context, options_.deadline_s);
  inference::ServerReadyResponse response;
  const grpc::Status s =
      impl_->stub->ServerReady(&context, inference::ServerReadyRequest(), &response);
  if (!s.ok()) return FromGrpc(s, options_, "ServerReady");
  return response.ready();
}

Result<ModelReadiness> RemoteSegmenter::GetModelReadiness() {
  grpc::ClientContext context;
  SetDeadline(context, options_.deadline_s);
  inference::ModelReadyRequest request;
  request.set_name(options_.model);
  inference::ModelReadyResponse response;
  const grpc::Status s = impl_->stub->ModelReady(&context, request, &response);
  if (!s.ok()) return FromGrpc(s, options_, "ModelReady");
  ModelReadiness out;
  out.ready = response.ready();
  const auto& trailers = context.GetServerTrailingMetadata();
  if (const auto it = trailers.find("avp-model-reason"); it != trailers.end()) {
    out.reason = std::string(it->second.data(), it->second.size());
  }
  return out;
}

Result<ModelMetadata> RemoteSegmenter::GetModelMetadata() {
  grpc::ClientContext context;
  SetDeadline(context, options_.deadline_s);
  inference::ModelMetadataRequest request;
  request.set_name(options_.model);
  inference::ModelMetadataResponse response;
  const grpc::Status s = impl_->stub->ModelMetadata(&context, request, &response);
  if (!s.ok()) return FromGrpc(s, options_, "ModelMetadata");
  ModelMetadata out;
  out.name = response.name();
  out.versions.assign(response.versions().begin(), response.versions().end());
  out.platform = response.platform();
  const std::string who = fmt::format("remote segmenter {}", spec_);
  AVP_RETURN_IF_ERROR(internal::TensorSpecsFromProto(response.inputs(), who, &out.inputs));
  AVP_RETURN_IF_ERROR(internal::TensorSpecsFromProto(response.outputs(), who, &out.outputs));
  return out;
}

Result<ServerMetadata> RemoteSegmenter::GetServerMetadata() {
  grpc::ClientContext context;
  SetDeadline(context, options_.deadline_s);
  inference::ServerMetadataResponse response;
  const grpc::Status s =
      impl_->stub->ServerMetadata(&context, inference::ServerMetadataRequest(), &response);
  if (!s.ok()) return FromGrpc(s, options_, "ServerMetadata");
  ServerMetadata out;
  out.name = response.name();
  out.version = response.version();
  out.extensions.assign(response.extensions().begin(), response.extensions().end());
  return out;
}

void RegisterRemoteSegmenter(segmentation::SegmenterRegistry& registry) {
  segmentation::SegmenterEntry e;
  e.name = std::string(kScheme);
  e.description =
      "a segmentation server over KServe v2 / Open Inference Protocol gRPC: "
      "remote://HOST[:PORT][/MODEL][?deadline_s=..&image=..] (docs/segmentation-service.md)";
  e.make = [](std::string_view spec, const AnyOptions&, const segmentation::SegmenterContext& c)
      -> Result<std::unique_ptr<segmentation::Segmenter>> {
    AVP_ASSIGN_OR_RETURN(RemoteOptions options, ParseRemoteSpec(spec));
    options.seed = c.seed;
    return std::unique_ptr<segmentation::Segmenter>(
        std::make_unique<RemoteSegmenter>(std::move(options)));
  };
  // The spec is checked before a run starts (the server is asked only when the run needs it).
  e.check = [](std::string_view spec, const AnyOptions&) { return ParseRemoteSpec(spec).status(); };
  std::vector<segmentation::SegmenterEntry> entries;
  entries.push_back(std::move(e));
  AddAll(registry, std::move(entries));
}

}  // namespace avp::segmentation_service

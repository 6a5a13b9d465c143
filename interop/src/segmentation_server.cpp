#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <exception>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <grpcpp/grpcpp.h>

#include <avp/interop/segmentation_codec.h>
#include <avp/interop/segmentation_server.h>
#include <avp/segmentation/segmenter.h>

#include "grpc_predict_v2.grpc.pb.h"
#include "proto_convert.h"

namespace avp::interop {

namespace {

using Clock = std::chrono::steady_clock;

/// The one version of every model. (A std::string: assigning the literal "1" trips GCC 12's
/// -Wrestrict false positive at -O3.)
const std::string kModelVersion = "1";

double MsBetween(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

/// gRPC metadata values must be printable ASCII.
std::string MetadataValue(std::string_view s) {
  std::string out;
  for (const char c : s.substr(0, 2000)) out.push_back(c >= 0x20 && c <= 0x7e ? c : '?');
  return out;
}

/// The segmenters of one backend, per seed: up to `instances` each, each used by one request at
/// a time, the least recently used idle seeds dropped beyond `max_seeds`.
class SegmenterCache {
 public:
  SegmenterCache(const segmentation::SegmenterRegistry& registry, std::string backend,
                 int instances, int max_seeds)
      : registry_(registry),
        backend_(std::move(backend)),
        instances_(instances),
        max_seeds_(max_seeds) {}

  /// Adds an already built segmenter (the start-up instance).
  void Adopt(uint64_t seed, std::unique_ptr<segmentation::Segmenter> segmenter) {
    std::lock_guard lock(mutex_);
    Entry& e = entries_[seed];
    ++e.created;
    e.idle.push_back(std::move(segmenter));
    e.last_used = ++tick_;
  }

  /// A segmenter for `seed`, built on first use; waits for a free instance until `deadline`.
  Result<std::unique_ptr<segmentation::Segmenter>> Acquire(
      uint64_t seed, std::chrono::system_clock::time_point deadline) {
    std::unique_lock lock(mutex_);
    while (true) {
      Entry& e = entries_[seed];
      if (!e.idle.empty()) {
        std::unique_ptr<segmentation::Segmenter> s = std::move(e.idle.back());
        e.idle.pop_back();
        ++e.in_use;
        e.last_used = ++tick_;
        return s;
      }
      if (e.created < instances_) {
        ++e.created;
        ++e.in_use;
        e.last_used = ++tick_;
        EvictLocked(seed);
        lock.unlock();
        Result<std::unique_ptr<segmentation::Segmenter>> built =
            InternalError("segmenter not built");
        try {
          built = registry_.Make(backend_, seed);
        } catch (const std::exception& ex) {
          built = InternalError(fmt::format("building it threw: {}", ex.what()));
        }
        lock.lock();
        if (!built.ok()) {
          Entry& again = entries_[seed];
          --again.created;
          --again.in_use;
          cv_.notify_all();
          return built.status().WithContext(
              fmt::format("model '{}' with seed {}: cannot build the segmenter", backend_, seed));
        }
        return built;
      }
      if (cv_.wait_until(lock, deadline) == std::cv_status::timeout &&
          std::chrono::system_clock::now() >= deadline) {
        return Status(
            StatusCode::kIoError,
            fmt::format("deadline exceeded while waiting for a free '{}' segmenter", backend_));
      }
    }
  }

  void Release(uint64_t seed, std::unique_ptr<segmentation::Segmenter> segmenter) {
    std::lock_guard lock(mutex_);
    Entry& e = entries_[seed];
    --e.in_use;
    e.idle.push_back(std::move(segmenter));
    e.last_used = ++tick_;
    EvictLocked(seed);
    cv_.notify_all();
  }

 private:
  struct Entry {
    std::vector<std::unique_ptr<segmentation::Segmenter>> idle;
    int created = 0;
    int in_use = 0;
    uint64_t last_used = 0;
  };

  void EvictLocked(uint64_t keep) {
    while (entries_.size() > static_cast<size_t>(max_seeds_)) {
      auto victim = entries_.end();
      for (auto it = entries_.begin(); it != entries_.end(); ++it) {
        if (it->first == keep || it->second.in_use > 0) continue;
        if (victim == entries_.end() || it->second.last_used < victim->second.last_used) {
          victim = it;
        }
      }
      if (victim == entries_.end()) return;  // every other seed is busy: keep them for now
      entries_.erase(victim);
    }
  }

  const segmentation::SegmenterRegistry& registry_;
  const std::string backend_;
  const int instances_;
  const int max_seeds_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::map<uint64_t, Entry> entries_;
  uint64_t tick_ = 0;
};

struct Model {
  ModelState state;
  std::unique_ptr<SegmenterCache> cache;  // null when not ready
};

/// A fixed pool of worker threads over a FIFO queue.
class WorkQueue {
 public:
  explicit WorkQueue(int threads) {
    for (int i = 0; i < threads; ++i) workers_.emplace_back([this] { Loop(); });
  }
  ~WorkQueue() { Stop(); }

  void Push(std::function<void()> task) {
    {
      std::lock_guard lock(mutex_);
      tasks_.push_back(std::move(task));
    }
    cv_.notify_one();
  }

  /// Runs what is queued, then joins the workers.
  void Stop() {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    cv_.notify_all();
    for (std::thread& t : workers_) {
      if (t.joinable()) t.join();
    }
    workers_.clear();
  }

 private:
  void Loop() {
    while (true) {
      std::function<void()> task;
      {
        std::unique_lock lock(mutex_);
        cv_.wait(lock, [this] { return stopping_ || !tasks_.empty(); });
        if (tasks_.empty()) return;
        task = std::move(tasks_.front());
        tasks_.pop_front();
      }
      task();
    }
  }

  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> tasks_;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

}  // namespace

// ---- options ------------------------------------------------------------------------------------

Status ServerOptions::Validate() const {
  std::vector<std::string> errors;
  if (segmenters == nullptr) errors.push_back("segmenters must be set (the program's registry)");
  if (host.empty()) errors.push_back("host must not be empty");
  if (port < 0 || port > 65535)
    errors.push_back(fmt::format("port ({}) must be in [0, 65535]", port));
  if (backends.empty()) errors.push_back("backends must name at least one backend");
  for (size_t i = 0; i < backends.size(); ++i) {
    if (backends[i].empty()) errors.push_back(fmt::format("backends[{}] is empty", i));
    for (size_t j = 0; j < i; ++j) {
      if (backends[j] == backends[i] && !backends[i].empty()) {
        errors.push_back(fmt::format("backends[{}] (\"{}\") is listed twice", i, backends[i]));
      }
    }
  }
  if (threads < 1 || threads > 256) {
    errors.push_back(fmt::format("threads ({}) must be in [1, 256]", threads));
  }
  if (instances_per_model < 1 || instances_per_model > 64) {
    errors.push_back(
        fmt::format("instances_per_model ({}) must be in [1, 64]", instances_per_model));
  }
  if (max_cached_seeds < 1) {
    errors.push_back(fmt::format("max_cached_seeds ({}) must be >= 1", max_cached_seeds));
  }
  if (max_message_bytes < (1 << 20)) {
    errors.push_back(
        fmt::format("max_message_bytes ({}) must be >= 1 MiB (1048576)", max_message_bytes));
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid server options: {}", fmt::join(errors, "; ")));
}

// ---- the service --------------------------------------------------------------------------------

struct SegmentationServer::Impl final : public inference::GRPCInferenceService::CallbackService {
  ServerOptions options;
  std::vector<Model> models;  // in the order of options.backends
  std::unique_ptr<WorkQueue> queue;
  std::unique_ptr<grpc::Server> server;
  int port = 0;
  std::mutex shutdown_mutex;
  bool shut_down = false;
  std::atomic<uint64_t> infer_ok{0}, infer_failed{0}, infer_expired{0};

  const Model* FindModel(std::string_view name) const {
    for (const Model& m : models) {
      if (m.state.name == name) return &m;
    }
    return nullptr;
  }

  std::string ModelNames() const {
    std::vector<std::string> names;
    for (const Model& m : models) names.push_back(m.state.name);
    return fmt::format("{}", fmt::join(names, ", "));
  }

  /// The model, or NOT_FOUND naming it and the served ones; versions other than "" and "1" are
  /// NOT_FOUND too.
  Result<const Model*> Lookup(const std::string& name, const std::string& version) const {
    const Model* m = FindModel(name);
    if (m == nullptr) {
      return NotFoundError(
          fmt::format("unknown model '{}'; this server serves: {}", name, ModelNames()));
    }
    if (!version.empty() && version != "1") {
      return NotFoundError(
          fmt::format("model '{}' has no version '{}' (versions: 1)", name, version));
    }
    return m;
  }

  static grpc::ServerUnaryReactor* Done(grpc::CallbackServerContext* context,
                                        const grpc::Status& status) {
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    reactor->Finish(status);
    return reactor;
  }

  grpc::ServerUnaryReactor* ServerLive(grpc::CallbackServerContext* context,
                                       const inference::ServerLiveRequest*,
                                       inference::ServerLiveResponse* response) override {
    response->set_live(true);
    return Done(context, grpc::Status::OK);
  }

  grpc::ServerUnaryReactor* ServerReady(grpc::CallbackServerContext* context,
                                        const inference::ServerReadyRequest*,
                                        inference::ServerReadyResponse* response) override {
    response->set_ready(
        std::any_of(models.begin(), models.end(), [](const Model& m) { return m.state.ready; }));
    return Done(context, grpc::Status::OK);
  }

  grpc::ServerUnaryReactor* ModelReady(grpc::CallbackServerContext* context,
                                       const inference::ModelReadyRequest* request,
                                       inference::ModelReadyResponse* response) override {
    Result<const Model*> m = Lookup(request->name(), request->version());
    if (!m.ok()) return Done(context, internal::ToGrpcStatus(m.status()));
    response->set_ready((*m)->state.ready);
    // The protocol's answer is a bool; the reason of a backend that is not ready travels in the
    // trailing metadata (RemoteSegmenter::GetModelReadiness reads it).
    context->AddTrailingMetadata("avp-model-state", (*m)->state.ready ? "READY" : "UNAVAILABLE");
    if (!(*m)->state.ready) {
      context->AddTrailingMetadata("avp-model-reason", MetadataValue((*m)->state.reason));
    }
    return Done(context, grpc::Status::OK);
  }

  grpc::ServerUnaryReactor* ServerMetadata(grpc::CallbackServerContext* context,
                                           const inference::ServerMetadataRequest*,
                                           inference::ServerMetadataResponse* response) override {
    response->set_name("avp-segmentation");
    response->set_version("0.1.0");
    return Done(context, grpc::Status::OK);
  }

  grpc::ServerUnaryReactor* ModelMetadata(grpc::CallbackServerContext* context,
                                          const inference::ModelMetadataRequest* request,
                                          inference::ModelMetadataResponse* response) override {
    Result<const Model*> m = Lookup(request->name(), request->version());
    if (!m.ok()) return Done(context, internal::ToGrpcStatus(m.status()));
    response->set_name((*m)->state.name);
    response->add_versions(kModelVersion);
    response->set_platform("avp_segmenter");
    const auto add = [](const TensorSpec& spec,
                        inference::ModelMetadataResponse::TensorMetadata* t) {
      t->set_name(spec.name);
      t->set_datatype(std::string(ToString(spec.datatype)));
      for (const int64_t d : spec.shape) t->add_shape(d);
    };
    for (const TensorSpec& s : SegmentationInputs()) add(s, response->add_inputs());
    for (const TensorSpec& s : SegmentationOutputs()) add(s, response->add_outputs());
    return Done(context, grpc::Status::OK);
  }

  grpc::ServerUnaryReactor* ModelInfer(grpc::CallbackServerContext* context,
                                       const inference::ModelInferRequest* request,
                                       inference::ModelInferResponse* response) override {
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    const Clock::time_point queued = Clock::now();
    // Off the gRPC threads: a worker decodes, segments and answers. context, request and
    // response stay valid until the reactor finishes.
    queue->Push([this, context, request, response, reactor, queued] {
      grpc::Status status;
      try {
        status = Infer(context, *request, response, queued);
      } catch (const std::exception& e) {
        status = grpc::Status(grpc::StatusCode::INTERNAL,
                              fmt::format("model '{}' threw: {}", request->model_name(), e.what()));
      }
      (status.ok() ? infer_ok : infer_failed).fetch_add(1);
      reactor->Finish(status);
    });
    return reactor;
  }

  grpc::Status Infer(grpc::CallbackServerContext* context,
                     const inference::ModelInferRequest& proto,
                     inference::ModelInferResponse* response, Clock::time_point queued) {
    const Clock::time_point started = Clock::now();
    if (context->IsCancelled()) {
      infer_expired.fetch_add(1);
      return {grpc::StatusCode::CANCELLED, "the call was cancelled before a worker took it"};
    }
    const std::chrono::system_clock::time_point deadline = context->deadline();
    if (std::chrono::system_clock::now() >= deadline) {
      infer_expired.fetch_add(1);
      return {grpc::StatusCode::DEADLINE_EXCEEDED,
              fmt::format("the deadline passed while the request waited {:.0f} ms in the queue",
                          MsBetween(queued, started))};
    }
    Result<const Model*> model = Lookup(proto.model_name(), proto.model_version());
    if (!model.ok()) return internal::ToGrpcStatus(model.status());
    const Model& m = **model;
    if (!m.state.ready) {
      return {grpc::StatusCode::FAILED_PRECONDITION,
              fmt::format("model '{}' is not ready: {}", m.state.name, m.state.reason)};
    }
    Result<InferRequest> request = internal::FromProto(proto);
    if (!request.ok()) return internal::ToGrpcStatus(request.status());
    Result<DecodedSegmentationRequest> decoded = DecodeSegmentationRequest(*request);
    if (!decoded.ok()) return internal::ToGrpcStatus(decoded.status());
    for (const std::string& name : request->requested_outputs) {
      const auto& outs = SegmentationOutputs();
      if (std::none_of(outs.begin(), outs.end(),
                       [&](const TensorSpec& s) { return s.name == name; })) {
        return {grpc::StatusCode::INVALID_ARGUMENT,
                fmt::format("requested output '{}' does not exist; outputs: masks, classes, "
                            "scores, labels, boxes, has_box, mask_scores",
                            name)};
      }
    }
    const Clock::time_point decoded_at = Clock::now();

    const uint64_t seed = decoded->seed.value_or(options.default_seed);
    Result<std::unique_ptr<segmentation::Segmenter>> segmenter = m.cache->Acquire(seed, deadline);
    if (!segmenter.ok()) {
      if (segmenter.status().code() == StatusCode::kIoError) {
        return {grpc::StatusCode::DEADLINE_EXCEEDED, segmenter.status().message()};
      }
      return internal::ToGrpcStatus(segmenter.status());
    }
    const Clock::time_point acquired = Clock::now();
    Result<Segmentation> segmentation = InternalError("not segmented");
    try {
      segmentation = (*segmenter)->Segment(decoded->request());
    } catch (const std::exception& e) {
      segmentation = InternalError(fmt::format("model '{}' threw: {}", m.state.name, e.what()));
    }
    m.cache->Release(seed, std::move(*segmenter));
    const Clock::time_point segmented = Clock::now();
    if (!segmentation.ok()) {
      return internal::ToGrpcStatus(
          segmentation.status().WithContext(fmt::format("model '{}'", m.state.name)));
    }
    const int w = decoded->frame.rgb.width();
    const int h = decoded->frame.rgb.height();
    if (Status v = segmentation->ValidateFor(w, h); !v.ok()) {
      return {grpc::StatusCode::INTERNAL,
              fmt::format("model '{}' returned an invalid segmentation: {}", m.state.name,
                          v.message())};
    }
    Result<InferResponse> encoded = EncodeSegmentation(*segmentation);
    if (!encoded.ok()) return internal::ToGrpcStatus(encoded.status());
    InferResponse out = std::move(*encoded);
    if (!request->requested_outputs.empty()) {
      std::erase_if(out.outputs, [&](const Tensor& t) {
        return std::find(request->requested_outputs.begin(), request->requested_outputs.end(),
                         t.name) == request->requested_outputs.end();
      });
    }
    out.model_name = m.state.name;
    out.model_version = kModelVersion;
    out.id = proto.id();
    const Clock::time_point encoded_at = Clock::now();
    out.parameters["server_queue_ms"] = MsBetween(queued, started);
    out.parameters["server_decode_ms"] = MsBetween(started, decoded_at);
    out.parameters["server_wait_ms"] = MsBetween(decoded_at, acquired);
    out.parameters["server_segment_ms"] = MsBetween(acquired, segmented);
    out.parameters["server_encode_ms"] = MsBetween(segmented, encoded_at);
    internal::ToProto(std::move(out), response);
    return grpc::Status::OK;
  }
};

// ---- SegmentationServer -------------------------------------------------------------------------

SegmentationServer::SegmentationServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

SegmentationServer::~SegmentationServer() { Shutdown(); }

Result<std::unique_ptr<SegmentationServer>> SegmentationServer::Start(
    const ServerOptions& options) {
  AVP_RETURN_IF_ERROR(options.Validate());
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  for (const std::string& backend : options.backends) {
    Model m;
    m.state.name = backend;
    Result<std::unique_ptr<segmentation::Segmenter>> s = InternalError("not built");
    try {
      s = options.segmenters->Make(backend, options.default_seed);
    } catch (const std::exception& e) {
      s = InternalError(fmt::format("building it threw: {}", e.what()));
    }
    if (s.ok()) {
      m.state.ready = true;
      m.cache = std::make_unique<SegmenterCache>(
          *options.segmenters, backend, options.instances_per_model, options.max_cached_seeds);
      m.cache->Adopt(options.default_seed, std::move(*s));
    } else {
      m.state.reason = s.status().ToString();
    }
    impl->models.push_back(std::move(m));
  }
  impl->queue = std::make_unique<WorkQueue>(options.threads);

  const std::string address =
      options.host.find(':') != std::string::npos && options.host.front() != '['
          ? fmt::format("[{}]:{}", options.host, options.port)
          : fmt::format("{}:{}", options.host, options.port);
  grpc::ServerBuilder builder;
  builder.AddListeningPort(address, grpc::InsecureServerCredentials(), &impl->port);
  builder.RegisterService(impl.get());
  builder.SetMaxReceiveMessageSize(options.max_message_bytes);
  builder.SetMaxSendMessageSize(options.max_message_bytes);
  // Without this, Linux lets a second server bind the same port and steal half the calls.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  impl->server = builder.BuildAndStart();
  if (impl->server == nullptr || impl->port == 0) {
    impl->queue->Stop();
    return IoError(fmt::format(
        "segmentation server: cannot listen on {} (address in use, or not an address of this "
        "machine?)",
        address));
  }
  return std::unique_ptr<SegmentationServer>(new SegmentationServer(std::move(impl)));
}

int SegmentationServer::port() const { return impl_->port; }

std::string SegmentationServer::address() const {
  const std::string& host = impl_->options.host;
  if (host.find(':') != std::string::npos && host.front() != '[') {
    return fmt::format("[{}]:{}", host, impl_->port);
  }
  return fmt::format("{}:{}", host, impl_->port);
}

std::vector<ModelState> SegmentationServer::models() const {
  std::vector<ModelState> out;
  for (const Model& m : impl_->models) out.push_back(m.state);
  return out;
}

ServerStats SegmentationServer::stats() const {
  ServerStats s;
  s.infer_ok = impl_->infer_ok.load();
  s.infer_failed = impl_->infer_failed.load();
  s.infer_expired = impl_->infer_expired.load();
  return s;
}

void SegmentationServer::Shutdown(std::chrono::milliseconds grace) {
  if (impl_ == nullptr) return;
  std::lock_guard lock(impl_->shutdown_mutex);
  if (impl_->shut_down) return;
  impl_->shut_down = true;
  // The workers keep running while gRPC drains: Shutdown waits for every call to finish, and
  // the queued ones finish through them (cancelled calls quickly).
  if (impl_->server) {
    impl_->server->Shutdown(std::chrono::system_clock::now() + grace);
    impl_->server->Wait();
  }
  impl_->queue->Stop();
}

}  // namespace avp::interop

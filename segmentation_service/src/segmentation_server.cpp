#include <algorithm>
#include <atomic>
#include <cctype>
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

#include <avp/core/limits.h>
#include <avp/core/text.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation_service/segmentation_codec.h>
#include <avp/segmentation_service/segmentation_server.h>

#include "grpc_predict_v2.grpc.pb.h"
#include "proto_convert.h"

namespace avp::segmentation_service {

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

  /// A segmenter for `seed`, built on first use; waits for a free instance until `interrupt`
  /// says stop (the client left or the deadline passed: its status is returned).
  Result<std::unique_ptr<segmentation::Segmenter>> Acquire(
      uint64_t seed, const std::function<Status()>& interrupt) {
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
      // Woken by Release; asks the interrupt every 20 ms (a client that left frees its place).
      cv_.wait_for(lock, std::chrono::milliseconds(20));
      if (Status stop = interrupt(); !stop.ok()) {
        return stop.WithContext(fmt::format("while waiting for a free '{}' segmenter", backend_));
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

/// A fixed pool of worker threads over a bounded queue shared fairly between clients: each
/// client (a key, the gRPC peer) has its own FIFO, and the workers take the clients' next
/// requests in turn (round robin), skipping a client that already has `running_per_client`
/// tasks running. At most `max_depth` tasks wait in all, at most `per_client` of one client.
class WorkQueue {
 public:
  WorkQueue(int threads, size_t max_depth, size_t per_client, size_t running_per_client)
      : max_depth_(max_depth), per_client_(per_client), running_per_client_(running_per_client) {
    for (int i = 0; i < threads; ++i) workers_.emplace_back([this] { Loop(); });
  }
  ~WorkQueue() { Stop(); }

  enum class Pushed : uint8_t { kQueued, kQueueFull, kClientFull };

  /// Queues `task` for `client`, or refuses it (nothing queued) when the queue or the client's
  /// share is full.
  Pushed Push(const std::string& client, std::function<void()> task) {
    {
      std::lock_guard lock(mutex_);
      if (size_ >= max_depth_) return Pushed::kQueueFull;
      std::deque<std::function<void()>>& mine = clients_[client];
      if (mine.size() >= per_client_) return Pushed::kClientFull;
      if (mine.empty()) turns_.push_back(client);
      mine.push_back(std::move(task));
      ++size_;
    }
    cv_.notify_one();
    return Pushed::kQueued;
  }

  size_t max_depth() const { return max_depth_; }
  size_t size() const {
    std::lock_guard lock(mutex_);
    return size_;
  }
  size_t per_client() const { return per_client_; }

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
      std::string client;
      {
        std::unique_lock lock(mutex_);
        auto turn = turns_.end();
        cv_.wait(lock, [&] {
          turn = NextTurnLocked();
          return turn != turns_.end() || (stopping_ && size_ == 0);
        });
        if (turn == turns_.end()) return;
        // The first client in line that may run one more; back of the line if it has more.
        client = std::move(*turn);
        turns_.erase(turn);
        const auto it = clients_.find(client);
        task = std::move(it->second.front());
        it->second.pop_front();
        --size_;
        ++running_[client];
        if (it->second.empty()) {
          clients_.erase(it);
        } else {
          turns_.push_back(client);
        }
      }
      task();
      {
        std::lock_guard lock(mutex_);
        if (--running_[client] == 0) running_.erase(client);
      }
      cv_.notify_all();  // a client at its running limit may go again
    }
  }

  /// The first client in line with fewer than running_per_client_ tasks running, or end().
  std::deque<std::string>::iterator NextTurnLocked() {
    for (auto it = turns_.begin(); it != turns_.end(); ++it) {
      const auto r = running_.find(*it);
      if (r == running_.end() || r->second < running_per_client_) return it;
    }
    return turns_.end();
  }

  const size_t max_depth_;
  const size_t per_client_;
  const size_t running_per_client_;
  std::map<std::string, size_t> running_;  ///< tasks running now, per client
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::map<std::string, std::deque<std::function<void()>>> clients_;
  std::deque<std::string> turns_;  ///< clients with queued tasks, in the order they are served
  size_t size_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

}  // namespace

ServedBackend ParseServedBackend(std::string_view entry) {
  const size_t eq = entry.find('=');
  const std::string_view before = entry.substr(0, eq == std::string_view::npos ? 0 : eq);
  const bool plain_name = !before.empty() && std::all_of(before.begin(), before.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '.' || c == '_' || c == '-';
  });
  if (eq != std::string_view::npos && plain_name) {
    return {std::string(before), std::string(entry.substr(eq + 1))};
  }
  const size_t scheme = entry.find("://");
  if (scheme != std::string_view::npos && scheme > 0) {
    return {std::string(entry.substr(0, scheme)), std::string(entry)};
  }
  return {std::string(entry), std::string(entry)};
}

// ---- options ------------------------------------------------------------------------------------

Status ServerOptions::Validate() const {
  std::vector<std::string> errors;
  if (segmenters == nullptr) errors.push_back("segmenters must be set (the program's registry)");
  if (host.empty()) errors.push_back("host must not be empty");
  if (port < 0 || port > 65535)
    errors.push_back(fmt::format("port ({}) must be in [0, 65535]", port));
  if (backends.empty()) errors.push_back("backends must name at least one backend");
  for (size_t i = 0; i < backends.size(); ++i) {
    if (backends[i].empty()) {
      errors.push_back(fmt::format("backends[{}] is empty", i));
      continue;
    }
    const ServedBackend served = ParseServedBackend(backends[i]);
    if (served.spec.empty()) {
      errors.push_back(
          fmt::format("backends[{}] (\"{}\") names no segmenter after '='", i, backends[i]));
    }
    if (served.model.find('/') != std::string::npos) {
      errors.push_back(fmt::format(
          "backends[{}] (\"{}\") would be served as model \"{}\", which clients cannot name "
          "(remote://HOST:PORT/MODEL): give it a name, NAME=SPEC",
          i, backends[i], served.model));
    }
    for (size_t j = 0; j < i; ++j) {
      if (backends[j] == backends[i]) {
        errors.push_back(fmt::format("backends[{}] (\"{}\") is listed twice", i, backends[i]));
      } else if (!backends[j].empty() && ParseServedBackend(backends[j]).model == served.model) {
        errors.push_back(fmt::format(
            "backends[{}] (\"{}\") and backends[{}] (\"{}\") would both be served as model "
            "\"{}\": name them, NAME=SPEC",
            j, backends[j], i, backends[i], served.model));
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
  if (max_cached_seeds < 1 || max_cached_seeds > 1024) {
    errors.push_back(fmt::format("max_cached_seeds ({}) must be in [1, 1024]", max_cached_seeds));
  }
  if (max_message_bytes < (1 << 20) || max_message_bytes > (1 << 30)) {
    errors.push_back(
        fmt::format("max_message_bytes ({}) must be in [1 MiB (1048576), 1 GiB (1073741824)]",
                    max_message_bytes));
  }
  if (max_queue_depth < 1 || max_queue_depth > 100000) {
    errors.push_back(fmt::format("max_queue_depth ({}) must be in [1, 100000]", max_queue_depth));
  }
  if (max_queued_per_client < 1 || max_queued_per_client > std::max(max_queue_depth, 1)) {
    errors.push_back(fmt::format("max_queued_per_client ({}) must be in [1, max_queue_depth ({})]",
                                 max_queued_per_client, max_queue_depth));
  }
  if (max_running_per_client < 0 || max_running_per_client > std::max(threads, 1)) {
    errors.push_back(
        fmt::format("max_running_per_client ({}) must be in [0 (half the threads), "
                    "threads ({})]",
                    max_running_per_client, threads));
  }
  if (max_image_pixels < 1 || max_image_pixels > (uint64_t{1} << 30)) {
    errors.push_back(fmt::format("max_image_pixels ({}) must be in [1, 1073741824 (32768^2)]",
                                 max_image_pixels));
  }
  if (max_prompt_bytes < 1 || max_prompt_bytes > (uint64_t{1} << 20)) {
    errors.push_back(
        fmt::format("max_prompt_bytes ({}) must be in [1, 1048576 (1 MiB)]", max_prompt_bytes));
  }
  if (max_prompt_phrases < 1 || max_prompt_phrases > 4096) {
    errors.push_back(
        fmt::format("max_prompt_phrases ({}) must be in [1, 4096]", max_prompt_phrases));
  }
  if (max_instances < 1 || max_instances > 65535) {
    errors.push_back(fmt::format("max_instances ({}) must be in [1, 65535]", max_instances));
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid server options: {}", fmt::join(errors, "; ")));
}

// ---- the service --------------------------------------------------------------------------------

struct SegmentationServer::Impl final : public inference::GRPCInferenceService::CallbackService {
  ServerOptions options;
  RequestBudget budget_;
  std::vector<Model> models;  // in the order of options.backends
  std::unique_ptr<WorkQueue> queue;
  std::unique_ptr<grpc::Server> server;
  int port = 0;
  std::mutex shutdown_mutex;
  bool shut_down = false;
  std::atomic<uint64_t> infer_ok{0}, infer_failed{0}, infer_expired{0}, infer_interrupted{0},
      infer_queue_full{0}, infer_over_budget{0};

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
    const WorkQueue::Pushed pushed =
        queue->Push(context->peer(), [this, context, request, response, reactor, queued] {
          grpc::Status status;
          try {
            status = Infer(context, *request, response, queued);
          } catch (const std::exception& e) {
            status =
                grpc::Status(grpc::StatusCode::INTERNAL,
                             fmt::format("model '{}' threw: {}", request->model_name(), e.what()));
          }
          (status.ok() ? infer_ok : infer_failed).fetch_add(1);
          reactor->Finish(status);
        });
    if (pushed != WorkQueue::Pushed::kQueued) {
      infer_queue_full.fetch_add(1);
      infer_failed.fetch_add(1);
      const Status refused =
          pushed == WorkQueue::Pushed::kQueueFull
              ? ExceedsLimit("requests waiting for a worker", queue->max_depth() + 1,
                             "max_queue_depth", queue->max_depth(),
                             "the server is busy: retry later, or raise it with `avp serve "
                             "segmentation --max-queue-depth N`")
              : ExceedsLimit("requests of this client waiting for a worker",
                             queue->per_client() + 1, "max_queued_per_client", queue->per_client(),
                             "wait for answers before sending more, or raise it with `avp serve "
                             "segmentation --max-queued-per-client N`");
      reactor->Finish(internal::ToGrpcStatus(refused));
    }
    return reactor;
  }

  /// Clock readings of one call, for the server_*_ms parameters of its answer.
  struct InferTimes {
    Clock::time_point queued, started, decoded, acquired, segmented, encoded;
  };

  /// A call interrupted (cancelled, or past its deadline), counted.
  grpc::Status Stopped(const Status& status) {
    infer_interrupted.fetch_add(1);
    return internal::ToGrpcStatus(status);
  }

  /// The call is still waited for when a worker takes it: not cancelled, deadline not passed.
  grpc::Status CheckStillWaitedFor(grpc::CallbackServerContext* context, const InferTimes& times) {
    if (context->IsCancelled()) {
      infer_expired.fetch_add(1);
      return {grpc::StatusCode::CANCELLED, "the call was cancelled before a worker took it"};
    }
    if (std::chrono::system_clock::now() >= context->deadline()) {
      infer_expired.fetch_add(1);
      return {grpc::StatusCode::DEADLINE_EXCEEDED,
              fmt::format("the deadline passed while the request waited {:.0f} ms in the queue",
                          MsBetween(times.queued, times.started))};
    }
    return grpc::Status::OK;
  }

  /// The request from its proto, within the budget, asking only for outputs that exist.
  grpc::Status ReadRequest(const inference::ModelInferRequest& proto, InferRequest& out) {
    // Counts before anything is converted: a request with a million tensors or parameters is
    // refused without copying them.
    if (static_cast<size_t>(proto.inputs_size()) > kMaxRequestInputs ||
        static_cast<size_t>(proto.outputs_size()) > kMaxRequestedOutputs ||
        static_cast<size_t>(proto.parameters_size()) > kMaxRequestParameters) {
      return {grpc::StatusCode::INVALID_ARGUMENT,
              fmt::format("the request has {} inputs, {} requested outputs and {} parameters: a "
                          "segmentation request has at most {}, {} and {}",
                          proto.inputs_size(), proto.outputs_size(), proto.parameters_size(),
                          kMaxRequestInputs, kMaxRequestedOutputs, kMaxRequestParameters)};
    }
    Result<InferRequest> request = internal::FromProto(proto);
    if (!request.ok()) return internal::ToGrpcStatus(request.status());
    if (Status budget = CheckRequestBudget(*request, budget_); !budget.ok()) {
      if (budget.code() == StatusCode::kResourceExhausted) infer_over_budget.fetch_add(1);
      return internal::ToGrpcStatus(budget);
    }
    for (const std::string& name : request->requested_outputs) {
      const auto& outs = SegmentationOutputs();
      if (std::none_of(outs.begin(), outs.end(),
                       [&](const TensorSpec& s) { return s.name == name; })) {
        return {grpc::StatusCode::INVALID_ARGUMENT,
                fmt::format("requested output {} does not exist; outputs: masks, classes, "
                            "scores, labels, boxes, has_box, mask_scores, mask_rle, mask_ids, "
                            "image_size, mask_on",
                            QuoteText(name))};
      }
    }
    out = std::move(*request);
    return grpc::Status::OK;
  }

  /// The model's segmentation of the decoded request, with a segmenter of its cache for the
  /// request's seed; an interrupted call's answer is dropped.
  grpc::Status Segment(const Model& m, const DecodedSegmentationRequest& decoded,
                       const std::function<Status()>& interrupt, InferTimes& times,
                       Result<Segmentation>& segmentation) {
    const uint64_t seed = decoded.seed.value_or(options.default_seed);
    Result<std::unique_ptr<segmentation::Segmenter>> segmenter = m.cache->Acquire(seed, interrupt);
    if (!segmenter.ok()) {
      const StatusCode code = segmenter.status().code();
      if (code == StatusCode::kCancelled || code == StatusCode::kDeadlineExceeded) {
        return Stopped(segmenter.status());
      }
      return internal::ToGrpcStatus(segmenter.status());
    }
    times.acquired = Clock::now();
    segmentation::SegmentationRequest segmentation_request = decoded.request();
    segmentation_request.interrupt = interrupt;
    try {
      segmentation = (*segmenter)->Segment(segmentation_request);
    } catch (const std::exception& e) {
      segmentation = InternalError(fmt::format("model '{}' threw: {}", m.state.name, e.what()));
    }
    m.cache->Release(seed, std::move(*segmenter));
    times.segmented = Clock::now();
    // A backend that does not ask the interrupt still has its answer dropped when nobody waits.
    if (Status stop = interrupt(); !stop.ok()) {
      return Stopped(stop.WithContext(fmt::format("model '{}'", m.state.name)));
    }
    if (!segmentation.ok()) {
      const StatusCode code = segmentation.status().code();
      const Status status =
          segmentation.status().WithContext(fmt::format("model '{}'", m.state.name));
      if (code == StatusCode::kCancelled || code == StatusCode::kDeadlineExceeded) {
        return Stopped(status);
      }
      return internal::ToGrpcStatus(status);
    }
    return grpc::Status::OK;
  }

  /// The segmentation is within max_instances and valid for the frame.
  grpc::Status CheckSegmentation(const Model& m, const Segmentation& segmentation,
                                 const DecodedSegmentationRequest& decoded) {
    if (Status n = CheckLimit(fmt::format("instances found by model '{}'", m.state.name),
                              segmentation.instances.size(), "max_instances",
                              static_cast<uint64_t>(options.max_instances),
                              "raise it with `avp serve segmentation --max-instances N`, or "
                              "narrow the prompt");
        !n.ok()) {
      return internal::ToGrpcStatus(n);
    }
    const int w = decoded.frame.rgb.width();
    const int h = decoded.frame.rgb.height();
    if (Status v = segmentation.ValidateFor(w, h); !v.ok()) {
      return {grpc::StatusCode::INTERNAL,
              fmt::format("model '{}' returned an invalid segmentation: {}", m.state.name,
                          v.message())};
    }
    return grpc::Status::OK;
  }

  /// The answer: the segmentation encoded in the requested mask format, only the requested
  /// outputs (all when none are named), and the server's timings.
  grpc::Status Answer(const Model& m, const inference::ModelInferRequest& proto,
                      const InferRequest& request, const DecodedSegmentationRequest& decoded,
                      const Segmentation& segmentation, InferTimes& times,
                      inference::ModelInferResponse* response) {
    Result<InferResponse> encoded = EncodeSegmentation(segmentation, decoded.mask_format);
    if (!encoded.ok()) return internal::ToGrpcStatus(encoded.status());
    InferResponse out = std::move(*encoded);
    if (!request.requested_outputs.empty()) {
      std::erase_if(out.outputs, [&](const Tensor& t) {
        return std::find(request.requested_outputs.begin(), request.requested_outputs.end(),
                         t.name) == request.requested_outputs.end();
      });
    }
    out.model_name = m.state.name;
    out.model_version = kModelVersion;
    out.id = proto.id();
    times.encoded = Clock::now();
    out.parameters["server_queue_ms"] = MsBetween(times.queued, times.started);
    out.parameters["server_decode_ms"] = MsBetween(times.started, times.decoded);
    out.parameters["server_wait_ms"] = MsBetween(times.decoded, times.acquired);
    out.parameters["server_segment_ms"] = MsBetween(times.acquired, times.segmented);
    out.parameters["server_encode_ms"] = MsBetween(times.segmented, times.encoded);
    internal::ToProto(std::move(out), response);
    return grpc::Status::OK;
  }

  grpc::Status Infer(grpc::CallbackServerContext* context,
                     const inference::ModelInferRequest& proto,
                     inference::ModelInferResponse* response, Clock::time_point queued) {
    InferTimes times;
    times.queued = queued;
    times.started = Clock::now();
    if (grpc::Status s = CheckStillWaitedFor(context, times); !s.ok()) return s;
    // Stops the work once the client cancelled or left, or the deadline passed.
    const std::chrono::system_clock::time_point deadline = context->deadline();
    const std::function<Status()> interrupt = [context, deadline]() -> Status {
      if (context->IsCancelled()) return CancelledError("the client cancelled the call or left");
      if (std::chrono::system_clock::now() >= deadline) {
        return DeadlineExceededError("the call's deadline passed");
      }
      return Status::Ok();
    };
    Result<const Model*> model = Lookup(proto.model_name(), proto.model_version());
    if (!model.ok()) return internal::ToGrpcStatus(model.status());
    const Model& m = **model;
    if (!m.state.ready) {
      return {grpc::StatusCode::FAILED_PRECONDITION,
              fmt::format("model '{}' is not ready: {}", m.state.name, m.state.reason)};
    }
    InferRequest request;
    if (grpc::Status s = ReadRequest(proto, request); !s.ok()) return s;
    if (Status stop = interrupt(); !stop.ok()) return Stopped(stop.WithContext("before decoding"));
    Result<DecodedSegmentationRequest> decoded = DecodeSegmentationRequest(request, budget_);
    if (!decoded.ok()) return internal::ToGrpcStatus(decoded.status());
    times.decoded = Clock::now();
    Result<Segmentation> segmentation = InternalError("not segmented");
    if (grpc::Status s = Segment(m, *decoded, interrupt, times, segmentation); !s.ok()) return s;
    if (grpc::Status s = CheckSegmentation(m, *segmentation, *decoded); !s.ok()) return s;
    return Answer(m, proto, request, *decoded, *segmentation, times, response);
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
  for (const std::string& entry : options.backends) {
    const ServedBackend served = ParseServedBackend(entry);
    const std::string& backend = served.spec;
    Model m;
    m.state.name = served.model;
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
  impl->budget_.max_image_pixels = options.max_image_pixels;
  impl->budget_.max_prompt_bytes = options.max_prompt_bytes;
  impl->budget_.max_prompt_phrases = options.max_prompt_phrases;
  impl->queue = std::make_unique<WorkQueue>(
      options.threads, static_cast<size_t>(options.max_queue_depth),
      static_cast<size_t>(options.max_queued_per_client),
      static_cast<size_t>(options.max_running_per_client > 0 ? options.max_running_per_client
                                                             : std::max(1, options.threads / 2)));

  AVP_RETURN_IF_ERROR(internal::CheckCanListen("segmentation server", options.host, options.port));
  const std::string address = internal::HostPort(options.host, options.port);
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
  return internal::HostPort(impl_->options.host, impl_->port);
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
  s.infer_interrupted = impl_->infer_interrupted.load();
  s.infer_queue_full = impl_->infer_queue_full.load();
  s.infer_over_budget = impl_->infer_over_budget.load();
  s.queued = impl_->queue ? impl_->queue->size() : 0;
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

}  // namespace avp::segmentation_service

#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>
#include <avp/segmentation/segmenter_registry.h>

namespace avp::segmentation_service {

/// How one entry of ServerOptions::backends is served: the model name clients ask for, and the
/// segmenter spec behind it. "fast=ywes://models/s" -> ("fast", "ywes://models/s");
/// "ywes://models" -> ("ywes", "ywes://models"); "oracle" -> ("oracle", "oracle").
struct ServedBackend {
  std::string model;
  std::string spec;
};
ServedBackend ParseServedBackend(std::string_view entry);

/// Configuration of a SegmentationServer (`avp serve segmentation` fills it from its flags).
struct ServerOptions {
  /// Address to listen on: "0.0.0.0" (every interface), "127.0.0.1", "::", a host name.
  std::string host = "127.0.0.1";
  /// TCP port; 0 picks a free one (SegmentationServer::port() reports it).
  int port = 8001;
  /// Where the backends come from (required; must outlive the server): the program's
  /// segmenters.
  const segmentation::SegmenterRegistry* segmenters = nullptr;
  /// Backends to serve: any spec `segmenters` knows ("oracle", "oracle-perfect", "color", the
  /// registered network backends), each served as a model named by ParseServedBackend: "NAME=SPEC"
  /// as NAME, a spec with a scheme ("ywes://models") by its scheme ("ywes"), any other by itself.
  /// Model names are unique and contain no '/' (clients name them in remote://HOST:PORT/MODEL).
  std::vector<std::string> backends = {"oracle"};
  /// Worker threads running Segment(); requests beyond them wait in a queue (deadlines apply).
  int threads = 4;
  /// Requests waiting for a worker, all clients together, in [1, 100000]. A request beyond it
  /// is refused at once with RESOURCE_EXHAUSTED naming the limit (the client may retry).
  int max_queue_depth = 64;
  /// Requests of one client (one connection: gRPC's peer address) waiting at once, in [1,
  /// max_queue_depth]; beyond it that client's requests are refused (RESOURCE_EXHAUSTED) while
  /// the others' are still taken. Workers take the clients' requests in turn (round robin), so a
  /// flood from one client delays another's request by at most one request per worker.
  int max_queued_per_client = 16;
  /// Requests of one client running at once, in [0, threads]; 0 = half the workers (at least
  /// one), so that a client with many requests in flight leaves workers free for the others.
  int max_running_per_client = 0;
  /// Per-request budgets, checked before anything of the request is decoded
  /// (DecodeSegmentationRequest, RequestBudget): pixels of the colour image (from the shape of
  /// 'rgb' or the PNG / JPEG header of 'image'; also bounds depth and labels), in [1, 2^30].
  uint64_t max_image_pixels = uint64_t{16} << 20;
  /// Bytes of the prompt, in [1, 1 MiB]. The segmenters also apply the process-wide
  /// max_prompt_bytes (segmentation::MaxPromptBytes(), same default): raise both for more.
  uint64_t max_prompt_bytes = 4096;
  /// Phrases in the prompt, duplicates included, in [1, 4096] (and the process-wide
  /// max_prompt_phrases, same default).
  uint64_t max_prompt_phrases = 64;
  /// Instances in one answer, in [1, 65535]: a segmentation with more is refused with
  /// RESOURCE_EXHAUSTED before its masks are encoded (its masks would also have to fit
  /// max_message_bytes).
  int max_instances = 256;
  /// Segmenters built per (backend, seed): Segment() is not promised to be thread-safe, so each
  /// instance serves one request at a time, and up to this many requests of one (backend, seed)
  /// run at once. More instances cost memory (a network backend holds its sessions).
  int instances_per_model = 2;
  /// (backend, seed) pairs whose segmenters are kept, in [1, 1024]; the least recently used
  /// idle one goes. A request with a new seed builds a segmenter (costly for a network backend).
  int max_cached_seeds = 8;
  /// Seed of a request that sends no `seed` parameter, and of the start-up instance.
  uint64_t default_seed = 0;
  /// Largest request or response, both ways (gRPC's default 4 MiB is too small for RGB-D), in
  /// [1 MiB, 1 GiB].
  int max_message_bytes = 64 << 20;

  /// Every bad field at once: "invalid server options: port (70000) must be in [0, 65535]; ...".
  Status Validate() const;
};

/// Where a served backend stands (zero-shot-models.md §7: READY, MISSING or INVALID(reason)).
struct ModelState {
  std::string name;
  bool ready = false;
  /// Why the backend could not be built ("" when ready): the status of building it.
  std::string reason;
};

/// Counters since start.
struct ServerStats {
  uint64_t infer_ok = 0;
  uint64_t infer_failed = 0;
  /// Requests whose deadline had passed or whose client had gone before a worker took them.
  uint64_t infer_expired = 0;
  /// Requests stopped while a worker had them (decoding, waiting for a segmenter, segmenting)
  /// because their client cancelled or left, or their deadline passed.
  uint64_t infer_interrupted = 0;
  /// Requests refused at once because the queue (max_queue_depth) or the client's share of it
  /// (max_queued_per_client) was full.
  uint64_t infer_queue_full = 0;
  /// Requests refused by a per-request budget (RESOURCE_EXHAUSTED before any work).
  uint64_t infer_over_budget = 0;
  /// Requests waiting for a worker now.
  uint64_t queued = 0;
};

/// The segmentation service: KServe v2 / Open Inference Protocol over gRPC
/// (docs/segmentation-service.md). Each backend is a model named after it; ModelInfer checks the
/// request against its budget (ServerOptions; RESOURCE_EXHAUSTED naming the limit, before
/// anything is decoded), decodes the tensors (segmentation_codec.h), runs the backend with the
/// request's `seed` and answers with the instances. A request that finds the queue full is
/// refused at once (RESOURCE_EXHAUSTED); one whose client cancels or leaves, or whose deadline
/// passes, is stopped where it is (in the queue, waiting for a segmenter, or between the
/// segmenter's phrases and stages: SegmentationRequest::interrupt) and answered CANCELLED or
/// DEADLINE_EXCEEDED, so its worker is free for the next request. A backend that cannot be built
/// does not stop the server: it is listed as not ready with its reason, and requests to it are
/// refused with FAILED_PRECONDITION and that reason. Malformed requests get INVALID_ARGUMENT,
/// unknown models NOT_FOUND, each with a message naming the tensor or model and what was expected.
/// ServerReady is true while at least one model is ready. Thread-safe.
class SegmentationServer {
 public:
  /// Builds the backends and starts listening. InvalidArgument for bad options, IoError when the
  /// address cannot be bound (naming it). Backends that fail to build are not errors (see above).
  static Result<std::unique_ptr<SegmentationServer>> Start(const ServerOptions& options);

  /// Shuts down (as Shutdown()).
  ~SegmentationServer();
  SegmentationServer(const SegmentationServer&) = delete;
  SegmentationServer& operator=(const SegmentationServer&) = delete;

  /// The bound port (the picked one when options.port was 0).
  int port() const;
  /// "host:port" as bound, e.g. "127.0.0.1:43117".
  std::string address() const;
  /// The served models in the order of options.backends.
  std::vector<ModelState> models() const;
  ServerStats stats() const;

  /// Stops accepting calls, lets running ones finish for up to `grace` (then cancels them), and
  /// stops the workers. Idempotent; returns at once when already shut down.
  void Shutdown(std::chrono::milliseconds grace = std::chrono::seconds(5));

 private:
  struct Impl;
  explicit SegmentationServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace avp::segmentation_service

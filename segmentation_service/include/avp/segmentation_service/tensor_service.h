#pragma once
// Plain tensor inference over KServe v2 / the Open Inference Protocol (gRPC): a server that serves
// any set of models given as TensorModelHandlers (avp serve models serves a manifest's ONNX
// networks through ONNX Runtime with it), and a client for one model of such a server, or of
// Triton, OpenVINO Model Server or KServe (docs/zero-shot-models.md, "The networks on an inference
// server"). Unlike the segmentation service (segmentation_server.h) nothing here knows what the
// tensors mean. No gRPC or protobuf header is included.

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/segmentation_service/segmentation_codec.h>  // TensorSpec
#include <avp/segmentation_service/tensor.h>

namespace avp::segmentation_service {

/// One model a TensorServer serves. Infer() is called from several threads at once.
class TensorModelHandler {
 public:
  virtual ~TensorModelHandler() = default;
  /// The name clients ask for (ModelInferRequest.model_name).
  virtual const std::string& name() const = 0;
  /// ModelMetadata's platform ("onnxruntime_onnx").
  virtual std::string platform() const = 0;
  /// The tensors ModelMetadata lists (-1 for a dynamic dimension).
  virtual const std::vector<TensorSpec>& inputs() const = 0;
  virtual const std::vector<TensorSpec>& outputs() const = 0;
  /// Runs the model. Errors become the call's gRPC status (InvalidArgument -> INVALID_ARGUMENT,
  /// ...), their messages kept.
  virtual Result<InferResponse> Infer(const InferRequest& request) const = 0;
};

/// Dynamic batching of one model's requests (BatchingHandler, tensor_batcher.h).
struct BatchingOptions {
  /// The bounds Validate() checks.
  static constexpr int kMaxBatch = 1024;
  static constexpr std::chrono::microseconds kMaxDelay{1000000};
  static constexpr int kMaxQueue = 100000;
  static constexpr int kMaxInstances = 64;

  /// The most rows (sum of the requests' leading dimensions) one run stacks, [1, 1024]; 1 = no
  /// batching. A request larger than this runs alone.
  int max_batch = 1;
  /// How long the oldest waiting request waits for more before its batch runs anyway, [0, 1 s].
  std::chrono::microseconds max_delay{2000};
  /// Requests waiting for a batch, over all shapes, [1, 100000]; one more is refused with
  /// RESOURCE_EXHAUSTED naming the limit.
  int max_queue = 256;
  /// Batches that run at once, each on a thread of its own (Triton's instance count), [1, 64].
  int instances = 1;
  /// Every bad field at once, naming the values.
  Status Validate() const;
  /// "up to 8 rows, waiting at most 2000 us".
  std::string Describe() const;
};

struct TensorServerOptions {
  /// Address to listen on ("127.0.0.1", "0.0.0.0", "::").
  std::string host = "127.0.0.1";
  /// TCP port; 0 picks a free one (TensorServer::port()).
  int port = 8001;
  /// Calls handled at once (gRPC's synchronous server threads), [1, 1024].
  int threads = 4;
  /// Largest request or response, bytes, [1 MiB, 1 GiB].
  int max_message_bytes = 256 << 20;
  /// The largest value a request may give a dimension the model leaves dynamic (-1), [1, 2^20]:
  /// such a dimension sizes the outputs too (SAM's B boxes give B masks of 256 x 256), so it is
  /// bounded before the model runs (RESOURCE_EXHAUSTED naming the input).
  int64_t max_dynamic_dim = 1024;
  /// Dynamic batching of the models that allow it (tensor_batcher.h WhyNotBatchable); off by
  /// default (max_batch 1). Requests stack only when they are handled at once: `threads` bounds
  /// how many are, so it should be at least max_batch.
  BatchingOptions batching;
  /// Every bad field at once, naming the values.
  Status Validate() const;
};

/// What one batched model has done since it started (BatchingHandler::stats).
struct BatchingStats {
  uint64_t requests = 0;  ///< requests answered through the batcher (alone or stacked)
  uint64_t batches = 0;   ///< runs of the model
  uint64_t rows = 0;      ///< rows run
  uint64_t refused = 0;   ///< RESOURCE_EXHAUSTED: the waiting line was full
  uint64_t reruns = 0;    ///< stacked runs that failed or did not split, run again one by one
  int largest = 0;        ///< most requests stacked in one run
  uint64_t waiting = 0;   ///< requests waiting for a batch now
};

/// Requests answered and refused since the start.
struct TensorServerStats {
  uint64_t infer_ok = 0, infer_failed = 0;
  /// Per batched model (by name).
  std::map<std::string, BatchingStats> batching;
};

/// A KServe v2 gRPC server of TensorModelHandlers: ServerLive, ServerReady, ServerMetadata,
/// ModelReady, ModelMetadata and ModelInfer. A request for a model it does not serve is
/// NOT_FOUND naming the models it serves; a request whose inputs do not match the model's
/// ModelMetadata (a missing or unknown input, a datatype, a rank or a static dimension that
/// differs, contents that do not fill the shape) is INVALID_ARGUMENT naming the tensor, before the
/// handler runs.
class TensorServer {
 public:
  /// Listens and serves until Shutdown() or destruction. Errors: InvalidArgument (options, or
  /// two handlers with one name), IoError (cannot listen on host:port).
  static Result<std::unique_ptr<TensorServer>> Start(
      const TensorServerOptions& options,
      std::vector<std::shared_ptr<const TensorModelHandler>> models);
  ~TensorServer();
  TensorServer(const TensorServer&) = delete;
  TensorServer& operator=(const TensorServer&) = delete;

  /// The port it listens on (the one picked for port 0).
  int port() const;
  /// "127.0.0.1:PORT".
  std::string address() const;
  TensorServerStats stats() const;
  /// For each model (by name), how it is served: "batched: up to 8 rows, waiting at most 2000 us"
  /// or "not batched: input 'image_embeddings' has a fixed leading dimension 1" (or "batching
  /// off" when options.batching.max_batch is 1).
  std::map<std::string, std::string> batching() const;
  /// Stops accepting calls and waits up to `grace` for running ones.
  void Shutdown(std::chrono::milliseconds grace = std::chrono::seconds(5));

 private:
  struct Impl;
  explicit TensorServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Where a TensorClient finds its model.
struct TensorClientOptions {
  /// "host:port" ("127.0.0.1:8001", "[::1]:8001", "gpu-box:8001").
  std::string address;
  std::string model;
  /// Each call's deadline, seconds (> 0).
  double deadline_s = 60.0;
  /// Largest request or response, bytes, [1 MiB, 1 GiB].
  int max_message_bytes = 256 << 20;
  Status Validate() const;
};

/// Parses "grpc://HOST:PORT" (HOST may be an IPv6 address in brackets; PORT in [1, 65535]) into
/// "HOST:PORT". InvalidArgument naming the text otherwise.
Result<std::string> ParseGrpcAddress(std::string_view url);

/// The metadata of one model of a KServe v2 server.
struct TensorModelMetadata {
  std::string name, platform;
  std::vector<TensorSpec> inputs, outputs;
};

/// A client of one model on a KServe v2 server (avp serve models, Triton, ...). Thread-safe.
/// Every error names the model and the address: Unavailable (no server), NotFound (no such
/// model), InvalidArgument (the server refused the request), DeadlineExceeded, IoError.
class TensorClient {
 public:
  /// Connects lazily (never fails on a missing server). Errors: InvalidArgument (options).
  static Result<std::unique_ptr<TensorClient>> Create(TensorClientOptions options);
  ~TensorClient();
  TensorClient(const TensorClient&) = delete;
  TensorClient& operator=(const TensorClient&) = delete;

  const TensorClientOptions& options() const;
  /// ModelReady of the model.
  Result<bool> Ready();
  Result<TensorModelMetadata> Metadata();
  /// ModelInfer with the request's model_name set to the model.
  Result<InferResponse> Infer(InferRequest request);

 private:
  struct Impl;
  explicit TensorClient(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace avp::segmentation_service

#pragma once
// Dynamic batching of a TensorModelHandler, as Triton's dynamic_batching does it: requests that
// arrive together for one model are stacked along the leading (batch) axis, run once, and the
// outputs split back along that axis, one slice per request. A request waits at most
// `max_delay` for others (then runs with what is there) and the waiting line is bounded
// (RESOURCE_EXHAUSTED when full): no request ever waits without bound. TensorServer wraps every
// batchable model with it when TensorServerOptions::batching.max_batch > 1
// (docs/zero-shot-models.md, "Batching").

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/segmentation_service/tensor_service.h>

namespace avp::segmentation_service {

/// Why `model` cannot be batched ("input 'image_embeddings' has a fixed leading dimension 1"),
/// or nullopt when it can: every input and every output has a dynamic (-1) leading dimension and a
/// fixed-size datatype (not BYTES).
std::optional<std::string> WhyNotBatchable(const TensorModelHandler& model);

/// A TensorModelHandler that batches the calls to another (BatchingOptions, tensor_service.h).
/// Requests stack when their requested outputs, and each input's datatype and dimensions after
/// the first, are the same; a request with parameters runs alone (they may change what the model
/// does). When a stacked run fails, or an output of it cannot be split (its leading dimension is
/// not the rows run), each of its requests is run again alone: one bad request fails only itself,
/// and every answer is the one the model gives that request alone.
/// Thread-safe; Infer blocks the calling thread until its answer is there.
class BatchingHandler final : public TensorModelHandler {
 public:
  /// Errors: InvalidArgument (options; a model WhyNotBatchable names, or a null one).
  static Result<std::shared_ptr<BatchingHandler>> Make(
      std::shared_ptr<const TensorModelHandler> inner, const BatchingOptions& options);
  /// Answers every request still waiting with UNAVAILABLE, then joins the batch threads.
  ~BatchingHandler() override;
  BatchingHandler(const BatchingHandler&) = delete;
  BatchingHandler& operator=(const BatchingHandler&) = delete;

  const std::string& name() const override;
  std::string platform() const override;
  const std::vector<TensorSpec>& inputs() const override;
  const std::vector<TensorSpec>& outputs() const override;
  /// Queues the request for a batch and waits for its slice of the answer. Errors: the model's;
  /// ResourceExhausted when `max_queue` requests already wait; Unavailable when the handler is
  /// being destroyed.
  Result<InferResponse> Infer(const InferRequest& request) const override;

  const BatchingOptions& options() const;
  BatchingStats stats() const;

  struct Impl;

 private:
  explicit BatchingHandler(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace avp::segmentation_service

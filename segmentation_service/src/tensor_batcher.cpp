#include "avp/segmentation_service/tensor_batcher.h"

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <exception>
#include <future>
#include <mutex>
#include <thread>
#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>

namespace avp::segmentation_service {

namespace {

using Clock = std::chrono::steady_clock;

/// One request waiting for its batch; it lives on the stack of the thread that waits for it.
struct Pending {
  const InferRequest* request = nullptr;
  std::string key;  ///< requests with the same key stack
  int64_t rows = 0;
  Clock::time_point enqueued;
  std::promise<Result<InferResponse>> answer;
};

/// What must agree for two requests to stack: the requested outputs, and per input (by name)
/// the datatype and the dimensions after the first.
std::string StackKey(const InferRequest& request) {
  std::vector<const Tensor*> inputs;
  for (const Tensor& t : request.inputs) inputs.push_back(&t);
  std::sort(inputs.begin(), inputs.end(),
            [](const Tensor* a, const Tensor* b) { return a->name < b->name; });
  std::string key = fmt::format("{}", fmt::join(request.requested_outputs, "\n"));
  for (const Tensor* t : inputs) {
    key += fmt::format("\x1f{}\x1e{}", t->name, ToString(t->datatype));
    for (size_t d = 1; d < t->shape.size(); ++d) key += fmt::format(",{}", t->shape[d]);
  }
  return key;
}

/// The request's leading dimension (every input has one: WhyNotBatchable and the server's
/// checks), or -1 when they differ.
int64_t RowsOf(const InferRequest& request) {
  int64_t rows = -1;
  for (const Tensor& t : request.inputs) {
    if (t.shape.empty()) return -1;
    if (rows >= 0 && t.shape[0] != rows) return -1;
    rows = t.shape[0];
  }
  return rows;
}

Result<InferResponse> RunGuarded(const TensorModelHandler& model, const InferRequest& request) {
  try {
    return model.Infer(request);
  } catch (const std::exception& e) {
    return InternalError(fmt::format("model '{}' threw: {}", model.name(), e.what()));
  } catch (...) {
    return InternalError(fmt::format("model '{}' threw", model.name()));
  }
}

}  // namespace

Status BatchingOptions::Validate() const {
  std::vector<std::string> problems;
  if (max_batch < 1 || max_batch > kMaxBatch) {
    problems.push_back(fmt::format("max_batch ({}) must be in [1, {}]", max_batch, kMaxBatch));
  }
  if (max_delay.count() < 0 || max_delay > kMaxDelay) {
    problems.push_back(fmt::format("max_delay ({} us) must be in [0, {} us]", max_delay.count(),
                                   kMaxDelay.count()));
  }
  if (max_queue < 1 || max_queue > kMaxQueue) {
    problems.push_back(fmt::format("max_queue ({}) must be in [1, {}]", max_queue, kMaxQueue));
  }
  if (instances < 1 || instances > kMaxInstances) {
    problems.push_back(fmt::format("instances ({}) must be in [1, {}]", instances, kMaxInstances));
  }
  if (problems.empty()) return Status::Ok();
  return InvalidArgumentError(
      fmt::format("invalid batching options: {}", fmt::join(problems, "; ")));
}

std::string BatchingOptions::Describe() const {
  return fmt::format("up to {} rows, waiting at most {} us", max_batch, max_delay.count());
}

std::optional<std::string> WhyNotBatchable(const TensorModelHandler& model) {
  const auto check = [](const std::vector<TensorSpec>& specs,
                        std::string_view what) -> std::optional<std::string> {
    for (const TensorSpec& s : specs) {
      if (s.shape.empty()) return fmt::format("{} '{}' is a scalar (no batch axis)", what, s.name);
      if (s.shape[0] >= 0) {
        return fmt::format("{} '{}' has a fixed leading dimension {}", what, s.name, s.shape[0]);
      }
      if (s.datatype == DataType::kBytes) {
        return fmt::format("{} '{}' is BYTES (variable-size elements)", what, s.name);
      }
      if (s.optional) return fmt::format("{} '{}' is optional", what, s.name);
    }
    return std::nullopt;
  };
  if (model.inputs().empty()) return std::string("the model has no inputs");
  if (auto why = check(model.inputs(), "input")) return why;
  if (model.outputs().empty()) return std::string("the model declares no outputs");
  return check(model.outputs(), "output");
}

struct BatchingHandler::Impl {
  std::shared_ptr<const TensorModelHandler> inner;
  BatchingOptions options;
  mutable std::mutex mutex;
  std::condition_variable cv;
  std::deque<Pending*> queue;  // oldest first
  bool stopping = false;
  BatchingStats stats;
  std::vector<std::thread> threads;

  void Loop() {
    std::unique_lock lock(mutex);
    while (!stopping) {
      if (queue.empty()) {
        cv.wait(lock);
        continue;
      }
      // The oldest request decides what runs next: the requests that stack with it, oldest
      // first, as many rows as fit. It runs once they fill a batch or its wait is over.
      const Pending* first = queue.front();
      int64_t rows = 0;
      bool full = false;
      for (const Pending* p : queue) {
        if (p->key != first->key) continue;
        if (rows + p->rows > options.max_batch) {
          full = true;
          break;
        }
        rows += p->rows;
      }
      full = full || rows >= options.max_batch;
      const Clock::time_point until = first->enqueued + options.max_delay;
      if (!full && Clock::now() < until) {
        cv.wait_until(lock, until);
        continue;
      }
      std::vector<Pending*> batch;
      rows = 0;
      const std::string key = first->key;
      for (auto it = queue.begin(); it != queue.end();) {
        if ((*it)->key == key && rows + (*it)->rows <= options.max_batch) {
          rows += (*it)->rows;
          batch.push_back(*it);
          it = queue.erase(it);
        } else {
          ++it;
        }
      }
      lock.unlock();
      cv.notify_all();  // another instance may take the next batch
      Run(batch, rows);
      lock.lock();
    }
  }

  void Answer(Pending* p, Result<InferResponse> r) { p->answer.set_value(std::move(r)); }

  /// Runs each request alone (a batch of one, or a stacked run that failed).
  void RunAlone(const std::vector<Pending*>& batch) {
    for (Pending* p : batch) {
      {
        std::lock_guard lock(mutex);
        stats.batches += 1;
        stats.rows += static_cast<uint64_t>(p->rows);
        stats.requests += 1;
        stats.largest = std::max(stats.largest, 1);
      }
      Answer(p, RunGuarded(*inner, *p->request));
    }
  }

  void Run(const std::vector<Pending*>& batch, int64_t rows) {
    if (batch.size() == 1) {
      RunAlone(batch);
      return;
    }
    // The stacked request: the first request's inputs, in its order, each with every request's
    // rows after one another (row-major contents: the leading axis is the outermost).
    const InferRequest& head = *batch.front()->request;
    InferRequest stacked;
    stacked.model_name = head.model_name;
    stacked.model_version = head.model_version;
    stacked.requested_outputs = head.requested_outputs;
    for (const Tensor& t : head.inputs) {
      Tensor s;
      s.name = t.name;
      s.datatype = t.datatype;
      s.shape = t.shape;
      s.shape[0] = rows;
      size_t bytes = 0;
      for (const Pending* p : batch) bytes += p->request->FindInput(t.name)->data.size();
      s.data.reserve(bytes);
      for (const Pending* p : batch) s.data += p->request->FindInput(t.name)->data;
      stacked.inputs.push_back(std::move(s));
    }
    Result<InferResponse> out = RunGuarded(*inner, stacked);
    stacked = InferRequest();  // the copies go before the answers are made
    std::vector<InferResponse> answers(batch.size());
    bool split = out.ok();
    for (size_t o = 0; split && o < out->outputs.size(); ++o) {
      const Tensor& t = out->outputs[o];
      const size_t element = ElementSize(t.datatype);
      if (element == 0 || t.shape.empty() || t.shape[0] != rows ||
          t.data.size() % static_cast<size_t>(rows) != 0) {
        split = false;
        break;
      }
      const size_t row_bytes = t.data.size() / static_cast<size_t>(rows);
      size_t at = 0;
      for (size_t i = 0; i < batch.size(); ++i) {
        Tensor slice;
        slice.name = t.name;
        slice.datatype = t.datatype;
        slice.shape = t.shape;
        slice.shape[0] = batch[i]->rows;
        const size_t n = row_bytes * static_cast<size_t>(batch[i]->rows);
        slice.data = t.data.substr(at, n);
        at += n;
        answers[i].outputs.push_back(std::move(slice));
      }
    }
    if (!split) {
      // A failed stacked run, or outputs that do not split by rows: every request alone, so
      // each gets the answer (or the error) the model gives it alone.
      {
        std::lock_guard lock(mutex);
        stats.reruns += 1;
      }
      RunAlone(batch);
      return;
    }
    {
      std::lock_guard lock(mutex);
      stats.batches += 1;
      stats.rows += static_cast<uint64_t>(rows);
      stats.requests += batch.size();
      stats.largest = std::max(stats.largest, static_cast<int>(batch.size()));
    }
    for (size_t i = 0; i < batch.size(); ++i) {
      answers[i].model_name = out->model_name;
      answers[i].model_version = out->model_version;
      answers[i].id = batch[i]->request->id;
      answers[i].parameters = out->parameters;
      Answer(batch[i], std::move(answers[i]));
    }
  }
};

Result<std::shared_ptr<BatchingHandler>> BatchingHandler::Make(
    std::shared_ptr<const TensorModelHandler> inner, const BatchingOptions& options) {
  AVP_RETURN_IF_ERROR(options.Validate());
  if (inner == nullptr) return InvalidArgumentError("batching: the model handler is null");
  if (std::optional<std::string> why = WhyNotBatchable(*inner)) {
    return InvalidArgumentError(
        fmt::format("model '{}' cannot be batched: {}", inner->name(), *why));
  }
  auto impl = std::make_unique<Impl>();
  impl->inner = std::move(inner);
  impl->options = options;
  std::shared_ptr<BatchingHandler> handler(new BatchingHandler(std::move(impl)));
  Impl* raw = handler->impl_.get();
  for (int i = 0; i < options.instances; ++i) raw->threads.emplace_back([raw] { raw->Loop(); });
  return handler;
}

BatchingHandler::BatchingHandler(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

BatchingHandler::~BatchingHandler() {
  std::deque<Pending*> left;
  {
    std::lock_guard lock(impl_->mutex);
    impl_->stopping = true;
    left.swap(impl_->queue);
  }
  impl_->cv.notify_all();
  for (Pending* p : left) {
    impl_->Answer(p, UnavailableError(fmt::format("model '{}': the server is shutting down",
                                                  impl_->inner->name())));
  }
  for (std::thread& t : impl_->threads) t.join();
}

const std::string& BatchingHandler::name() const { return impl_->inner->name(); }
std::string BatchingHandler::platform() const { return impl_->inner->platform(); }
const std::vector<TensorSpec>& BatchingHandler::inputs() const { return impl_->inner->inputs(); }
const std::vector<TensorSpec>& BatchingHandler::outputs() const { return impl_->inner->outputs(); }
const BatchingOptions& BatchingHandler::options() const { return impl_->options; }

BatchingStats BatchingHandler::stats() const {
  std::lock_guard lock(impl_->mutex);
  BatchingStats stats = impl_->stats;
  stats.waiting = impl_->queue.size();
  return stats;
}

Result<InferResponse> BatchingHandler::Infer(const InferRequest& request) const {
  const int64_t rows = RowsOf(request);
  // Parameters may change what the model does; a request of no rows, of inputs that disagree on
  // the rows, or of more rows than a batch holds, has nothing to stack with.
  if (!request.parameters.empty() || rows <= 0 || rows > impl_->options.max_batch) {
    return RunGuarded(*impl_->inner, request);
  }
  Pending pending;
  pending.request = &request;
  pending.key = StackKey(request);
  pending.rows = rows;
  pending.enqueued = Clock::now();
  std::future<Result<InferResponse>> answer = pending.answer.get_future();
  {
    std::lock_guard lock(impl_->mutex);
    if (impl_->stopping) {
      return UnavailableError(
          fmt::format("model '{}': the server is shutting down", impl_->inner->name()));
    }
    if (impl_->queue.size() >= static_cast<size_t>(impl_->options.max_queue)) {
      impl_->stats.refused += 1;
      return ResourceExhaustedError(fmt::format(
          "model '{}': {} requests already wait for a batch (the limit max_queue = {}): the "
          "server is busy, retry later, or raise it with `avp serve models --max-batch-queue N`",
          impl_->inner->name(), impl_->queue.size(), impl_->options.max_queue));
    }
    impl_->queue.push_back(&pending);
  }
  impl_->cv.notify_all();
  return answer.get();
}

}  // namespace avp::segmentation_service

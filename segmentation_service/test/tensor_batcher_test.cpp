// segmentation_service::BatchingHandler (dynamic batching) around a hand-written model, y = 2x,
// that also says how many rows it ran at once (`n`, one value per row): requests that arrive
// together stack into one run and each gets its own rows back; a lone request runs once its wait is
// over; requests that cannot stack run apart; a full waiting line is RESOURCE_EXHAUSTED; a failed
// stacked run is rerun one request at a time; and through a TensorServer over loopback.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/segmentation_service/tensor_batcher.h>
#include <avp/segmentation_service/tensor_service.h>

namespace avp::segmentation_service {
namespace {

using ::testing::HasSubstr;

/// y = 2x for x [R, 2]; n [R] = R for every row (the rows of the run). A negative x fails the
/// run; `gate` (when set) holds every run until opened.
class Doubler final : public TensorModelHandler {
 public:
  struct Gate {
    std::mutex mutex;
    std::condition_variable cv;
    bool open = false;
    int entered = 0;
    void Open() {
      {
        std::lock_guard lock(mutex);
        open = true;
      }
      cv.notify_all();
    }
    void WaitEntered(int n) {
      std::unique_lock lock(mutex);
      cv.wait(lock, [&] { return entered >= n; });
    }
  };

  explicit Doubler(std::vector<int64_t> x_shape = {-1, 2}) {
    inputs_ = {{"x", DataType::kFp32, x_shape, false}};
    outputs_ = {{"y", DataType::kFp32, x_shape, false}, {"n", DataType::kInt64, {-1}, false}};
  }

  const std::string& name() const override { return name_; }
  std::string platform() const override { return "test"; }
  const std::vector<TensorSpec>& inputs() const override { return inputs_; }
  const std::vector<TensorSpec>& outputs() const override { return outputs_; }
  Result<InferResponse> Infer(const InferRequest& request) const override {
    runs.fetch_add(1);
    if (gate != nullptr) {
      std::unique_lock lock(gate->mutex);
      ++gate->entered;
      gate->cv.notify_all();
      gate->cv.wait(lock, [&] { return gate->open; });
    }
    const Tensor& xt = *request.FindInput("x");
    AVP_ASSIGN_OR_RETURN(std::vector<float> x, ReadValues<float>(xt));
    for (float& v : x) {
      if (v < 0.f) return InvalidArgumentError(fmt::format("x holds a negative value ({})", v));
      v *= 2.f;
    }
    const int64_t rows = xt.shape[0];
    const std::vector<int64_t> n(static_cast<size_t>(rows), rows);
    InferResponse r;
    bool want_y = request.requested_outputs.empty();
    bool want_n = want_y;
    for (const std::string& o : request.requested_outputs) {
      want_y = want_y || o == "y";
      want_n = want_n || o == "n";
    }
    if (want_y) {
      r.outputs.push_back(
          MakeTensor<float>("y", DataType::kFp32, xt.shape, std::span<const float>(x)));
    }
    if (want_n) {
      r.outputs.push_back(
          MakeTensor<int64_t>("n", DataType::kInt64, {rows}, std::span<const int64_t>(n)));
    }
    return r;
  }

  mutable std::atomic<int> runs{0};
  Gate* gate = nullptr;

 private:
  std::string name_ = "doubler";
  std::vector<TensorSpec> inputs_, outputs_;
};

InferRequest Rows(std::vector<float> x) {
  InferRequest r;
  const int64_t rows = static_cast<int64_t>(x.size() / 2);
  r.inputs.push_back(MakeTensor<float>("x", DataType::kFp32, {rows, 2}, std::span<const float>(x)));
  return r;
}

std::vector<float> Y(const Result<InferResponse>& r) {
  const Tensor* y = r->FindOutput("y");
  return y == nullptr ? std::vector<float>{} : *ReadValues<float>(*y);
}
std::vector<int64_t> N(const Result<InferResponse>& r) {
  const Tensor* n = r->FindOutput("n");
  return n == nullptr ? std::vector<int64_t>{} : *ReadValues<int64_t>(*n);
}

std::shared_ptr<BatchingHandler> Batcher(std::shared_ptr<const TensorModelHandler> model,
                                         BatchingOptions o) {
  Result<std::shared_ptr<BatchingHandler>> b = BatchingHandler::Make(std::move(model), o);
  EXPECT_TRUE(b.ok()) << b.status().ToString();
  return b.ok() ? *b : nullptr;
}

TEST(TensorBatcherTest, WhatCanBeBatched) {
  EXPECT_EQ(WhyNotBatchable(Doubler()), std::nullopt);
  EXPECT_EQ(WhyNotBatchable(Doubler({1, 2})), "input 'x' has a fixed leading dimension 1");
  const Result<std::shared_ptr<BatchingHandler>> refused =
      BatchingHandler::Make(std::make_shared<Doubler>(std::vector<int64_t>{1, 2}), {});
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.status().message(),
              HasSubstr("model 'doubler' cannot be batched: input 'x' has a fixed leading "
                        "dimension 1"));
  BatchingOptions bad;
  bad.max_batch = 0;
  bad.max_delay = std::chrono::microseconds(-1);
  bad.max_queue = 0;
  bad.instances = 65;
  const Status s = bad.Validate();
  EXPECT_EQ(s.message(),
            "invalid batching options: max_batch (0) must be in [1, 1024]; max_delay (-1 us) must "
            "be in [0, 1000000 us]; max_queue (0) must be in [1, 100000]; instances (65) must be "
            "in [1, 64]");
}

TEST(TensorBatcherTest, RequestsThatArriveTogetherRunAsOneBatch) {
  auto model = std::make_shared<Doubler>();
  BatchingOptions o;
  o.max_batch = 6;
  o.max_delay = std::chrono::seconds(1);  // the batch runs when full, long before that
  auto batcher = Batcher(model, o);
  ASSERT_NE(batcher, nullptr);
  // Four requests of 1, 2, 1 and 2 rows: 6 rows, one run.
  const std::vector<std::vector<float>> xs = {{1, 2}, {3, 4, 5, 6}, {7, 8}, {9, 10, 11, 12}};
  std::vector<Result<InferResponse>> answers(xs.size(), InternalError("not run"));
  std::vector<std::thread> threads;
  for (size_t i = 0; i < xs.size(); ++i) {
    threads.emplace_back([&, i] { answers[i] = batcher->Infer(Rows(xs[i])); });
  }
  for (std::thread& t : threads) t.join();
  for (size_t i = 0; i < xs.size(); ++i) {
    ASSERT_TRUE(answers[i].ok()) << answers[i].status().ToString();
    std::vector<float> want = xs[i];
    for (float& v : want) v *= 2.f;
    EXPECT_EQ(Y(answers[i]), want) << i;
    EXPECT_EQ(N(answers[i]), std::vector<int64_t>(xs[i].size() / 2, 6)) << i;
    EXPECT_EQ(answers[i]->FindOutput("y")->shape,
              (std::vector<int64_t>{static_cast<int64_t>(xs[i].size() / 2), 2}));
  }
  EXPECT_EQ(model->runs.load(), 1);
  const BatchingStats st = batcher->stats();
  EXPECT_EQ(st.batches, 1u);
  EXPECT_EQ(st.requests, 4u);
  EXPECT_EQ(st.rows, 6u);
  EXPECT_EQ(st.largest, 4);
  EXPECT_EQ(st.waiting, 0u);
}

TEST(TensorBatcherTest, ALoneRequestRunsWhenItsWaitIsOver) {
  auto model = std::make_shared<Doubler>();
  BatchingOptions o;
  o.max_batch = 8;
  o.max_delay = std::chrono::milliseconds(20);
  auto batcher = Batcher(model, o);
  const auto start = std::chrono::steady_clock::now();
  const Result<InferResponse> r = batcher->Infer(Rows({1, 2}));
  const auto waited = std::chrono::steady_clock::now() - start;
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(Y(r), (std::vector<float>{2, 4}));
  EXPECT_EQ(N(r), (std::vector<int64_t>{1}));
  EXPECT_GE(waited, std::chrono::milliseconds(20));  // it waited for company, then ran
  // Larger than a batch, or with parameters: runs at once, alone, past the batcher.
  o.max_delay = std::chrono::seconds(1);
  o.max_batch = 2;
  auto small = Batcher(model, o);
  const Result<InferResponse> big = small->Infer(Rows({1, 2, 3, 4, 5, 6}));
  ASSERT_TRUE(big.ok());
  EXPECT_EQ(N(big), (std::vector<int64_t>{3, 3, 3}));
  InferRequest with_parameter = Rows({1, 2});
  with_parameter.parameters["priority"] = int64_t{1};
  EXPECT_EQ(N(small->Infer(with_parameter)), (std::vector<int64_t>{1}));
  EXPECT_EQ(small->stats().batches, 0u);
}

TEST(TensorBatcherTest, RequestsForOtherOutputsDoNotStack) {
  auto model = std::make_shared<Doubler>();
  BatchingOptions o;
  o.max_batch = 2;
  o.max_delay = std::chrono::milliseconds(50);
  auto batcher = Batcher(model, o);
  InferRequest only_n = Rows({5, 6});
  only_n.requested_outputs = {"n"};
  Result<InferResponse> a = InternalError("not run"), b = InternalError("not run");
  std::thread ta([&] { a = batcher->Infer(Rows({1, 2})); });
  std::thread tb([&] { b = batcher->Infer(only_n); });
  ta.join();
  tb.join();
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(N(a), (std::vector<int64_t>{1}));
  EXPECT_EQ(N(b), (std::vector<int64_t>{1}));
  EXPECT_EQ(b->FindOutput("y"), nullptr);
  EXPECT_EQ(batcher->stats().batches, 2u);
}

TEST(TensorBatcherTest, AFullWaitingLineIsResourceExhausted) {
  auto model = std::make_shared<Doubler>();
  Doubler::Gate gate;
  model->gate = &gate;
  BatchingOptions o;
  o.max_batch = 2;
  o.max_delay = std::chrono::microseconds(0);
  o.max_queue = 2;
  auto batcher = Batcher(model, o);
  std::vector<std::thread> threads;
  std::vector<Result<InferResponse>> answers(3, InternalError("not run"));
  // The first runs (held at the gate); the next two wait, as many as the line holds.
  threads.emplace_back([&] { answers[0] = batcher->Infer(Rows({1, 2})); });
  gate.WaitEntered(1);
  for (int i = 1; i < 3; ++i) {
    threads.emplace_back([&, i] { answers[i] = batcher->Infer(Rows({1, 2})); });
  }
  while (batcher->stats().waiting < 2) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  const Result<InferResponse> refused = batcher->Infer(Rows({3, 4}));
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(refused.status().message(),
              HasSubstr("model 'doubler': 2 requests already wait for a batch (the limit "
                        "max_queue = 2)"));
  gate.Open();
  for (std::thread& t : threads) t.join();
  for (const auto& a : answers) ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(N(answers[1]), (std::vector<int64_t>{2}));  // the two that waited ran together
  const BatchingStats st = batcher->stats();
  EXPECT_EQ(st.refused, 1u);
  EXPECT_EQ(st.batches, 2u);
  EXPECT_EQ(st.requests, 3u);
}

TEST(TensorBatcherTest, AFailedStackedRunFailsOnlyTheBadRequest) {
  auto model = std::make_shared<Doubler>();
  BatchingOptions o;
  o.max_batch = 2;
  o.max_delay = std::chrono::seconds(1);
  auto batcher = Batcher(model, o);
  Result<InferResponse> good = InternalError("not run"), bad = InternalError("not run");
  std::thread tg([&] { good = batcher->Infer(Rows({1, 2})); });
  std::thread tb([&] { bad = batcher->Infer(Rows({-1, 2})); });
  tg.join();
  tb.join();
  ASSERT_TRUE(good.ok()) << good.status().ToString();
  EXPECT_EQ(Y(good), (std::vector<float>{2, 4}));
  EXPECT_EQ(N(good), (std::vector<int64_t>{1}));  // rerun alone
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bad.status().message(), HasSubstr("negative value (-1)"));
  EXPECT_EQ(model->runs.load(), 3);  // the stacked run, then each alone
  EXPECT_EQ(batcher->stats().reruns, 1u);
}

TEST(TensorBatcherTest, DestructionAnswersTheWaitingRequests) {
  auto model = std::make_shared<Doubler>();
  Doubler::Gate gate;
  model->gate = &gate;
  BatchingOptions o;
  o.max_batch = 2;
  o.max_delay = std::chrono::microseconds(0);
  auto batcher = Batcher(model, o);
  Result<InferResponse> running = InternalError("not run"), waiting = InternalError("not run");
  std::thread tr([&] { running = batcher->Infer(Rows({1, 2})); });
  gate.WaitEntered(1);
  std::thread tw([&] { waiting = batcher->Infer(Rows({3, 4})); });
  while (batcher->stats().waiting < 1) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  std::thread destroy([&] { batcher.reset(); });
  tw.join();  // answered while the running batch still holds the destructor
  EXPECT_EQ(waiting.status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(waiting.status().message(), HasSubstr("shutting down"));
  gate.Open();
  tr.join();
  destroy.join();
  ASSERT_TRUE(running.ok()) << running.status().ToString();
  EXPECT_EQ(Y(running), (std::vector<float>{2, 4}));
}

TEST(TensorBatcherTest, TheServerBatchesWhatCanBeBatched) {
  TensorServerOptions o;
  o.port = 0;
  o.threads = 8;
  o.batching.max_batch = 4;
  o.batching.max_delay = std::chrono::seconds(1);
  auto fixed = std::make_shared<Doubler>(std::vector<int64_t>{1, 2});
  Result<std::unique_ptr<TensorServer>> server =
      TensorServer::Start(o, {std::make_shared<Doubler>()});
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  EXPECT_EQ((*server)->batching().at("doubler"),
            "batched: up to 4 rows, waiting at most 1000000 us");
  std::vector<Result<InferResponse>> answers(4, InternalError("not run"));
  std::vector<std::thread> threads;
  for (int i = 0; i < 4; ++i) {
    threads.emplace_back([&, i] {
      TensorClientOptions c;
      c.address = (*server)->address();
      c.model = "doubler";
      c.deadline_s = 30.0;
      Result<std::unique_ptr<TensorClient>> client = TensorClient::Create(c);
      if (!client.ok()) {
        answers[i] = client.status();
        return;
      }
      answers[i] = (*client)->Infer(Rows({static_cast<float>(i), 1.f}));
    });
  }
  for (std::thread& t : threads) t.join();
  for (int i = 0; i < 4; ++i) {
    ASSERT_TRUE(answers[i].ok()) << answers[i].status().ToString();
    EXPECT_EQ(Y(answers[i]), (std::vector<float>{2.f * static_cast<float>(i), 2.f}));
    EXPECT_EQ(N(answers[i]), (std::vector<int64_t>{4}));
  }
  const TensorServerStats st = (*server)->stats();
  EXPECT_EQ(st.infer_ok, 4u);
  EXPECT_EQ(st.batching.at("doubler").batches, 1u);
  EXPECT_EQ(st.batching.at("doubler").largest, 4);

  // A model with a fixed batch of 1 is served as it is.
  TensorServerOptions plain = o;
  Result<std::unique_ptr<TensorServer>> other = TensorServer::Start(plain, {fixed});
  ASSERT_TRUE(other.ok()) << other.status().ToString();
  EXPECT_EQ((*other)->batching().at("doubler"),
            "not batched: input 'x' has a fixed leading dimension 1");
  EXPECT_TRUE((*other)->stats().batching.empty());
  plain.batching.max_batch = 1;
  Result<std::unique_ptr<TensorServer>> off =
      TensorServer::Start(plain, {std::make_shared<Doubler>()});
  ASSERT_TRUE(off.ok());
  EXPECT_EQ((*off)->batching().at("doubler"), "batching off");
  plain.batching.max_queue = 0;
  EXPECT_THAT(TensorServer::Start(plain, {fixed}).status().message(),
              HasSubstr("max_queue (0) must be in [1, 100000]"));
}

}  // namespace
}  // namespace avp::segmentation_service

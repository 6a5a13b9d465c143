// The segmentation service over loopback gRPC: health, readiness, metadata, results equal to the
// in-process ones, malformed requests refused with the right code and message (the server going
// on), a server that is down, deadlines, and concurrent clients.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <avp/segmentation/segmenter_registry.h>
#include <avp/segmentation_service/remote_segmenter.h>
#include <avp/segmentation_service/segmentation_codec.h>
#include <avp/segmentation_service/segmentation_server.h>

#include "grpc_predict_v2.grpc.pb.h"
#include "proto_convert.h"
#include "test_scene.h"

namespace avp::segmentation_service {
namespace {

using test::ExpectSameSegmentation;
using test::TestFrame;
using ::testing::HasSubstr;

/// Every field equal (for use off the test thread).
bool Same(const Segmentation& a, const Segmentation& b) {
  if (a.width != b.width || a.height != b.height || a.instances.size() != b.instances.size()) {
    return false;
  }
  for (size_t i = 0; i < a.instances.size(); ++i) {
    const InstanceMask& x = a.instances[i];
    const InstanceMask& y = b.instances[i];
    if (!(x.mask == y.mask) || x.semantic_class != y.semantic_class ||
        x.confidence != y.confidence || x.label != y.label || x.box != y.box ||
        x.mask_score != y.mask_score) {
      return false;
    }
  }
  return a.timings.size() == b.timings.size();
}

/// A backend that takes its time (for deadlines) and one that throws.
class SlowSegmenter final : public segmentation::Segmenter {
 public:
  std::string_view name() const override { return "test-slow"; }
  Result<Segmentation> Segment(const segmentation::SegmentationRequest& request) override {
    std::this_thread::sleep_for(std::chrono::milliseconds(600));
    Segmentation s;
    s.width = request.frame->rgb.width();
    s.height = request.frame->rgb.height();
    return s;
  }
};

class ThrowingSegmenter final : public segmentation::Segmenter {
 public:
  std::string_view name() const override { return "test-throws"; }
  Result<Segmentation> Segment(const segmentation::SegmentationRequest&) override {
    throw std::runtime_error("backend exploded");
  }
};

/// A backend that blocks until its request's interrupt says stop (at most 20 s), counting how
/// many calls entered and how many were stopped.
class BlockingSegmenter final : public segmentation::Segmenter {
 public:
  static inline std::atomic<int> entered{0};
  static inline std::atomic<int> stopped{0};
  std::string_view name() const override { return "test-block"; }
  Result<Segmentation> Segment(const segmentation::SegmentationRequest& request) override {
    entered.fetch_add(1);
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (std::chrono::steady_clock::now() < until) {
      if (Status stop = segmentation::CheckInterrupt(request); !stop.ok()) {
        stopped.fetch_add(1);
        return stop;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return InternalError("test-block: never interrupted");
  }
};

template <typename S>
segmentation::SegmenterEntry TestEntry(const char* name) {
  segmentation::SegmenterEntry e;
  e.name = name;
  e.description = "a test backend";
  e.make = [](std::string_view, const AnyOptions&, const segmentation::SegmenterContext&) {
    return Result<std::unique_ptr<segmentation::Segmenter>>(std::make_unique<S>());
  };
  return e;
}

/// The built-ins, two test backends and the remote:// client (never freed: servers outlive it).
const segmentation::SegmenterRegistry& TestSegmenters() {
  static const auto* registry = [] {
    auto* r = new segmentation::SegmenterRegistry(segmentation::BuiltinSegmenters());
    EXPECT_TRUE(r->Add(TestEntry<SlowSegmenter>("test-slow")).ok());
    EXPECT_TRUE(r->Add(TestEntry<ThrowingSegmenter>("test-throws")).ok());
    EXPECT_TRUE(r->Add(TestEntry<BlockingSegmenter>("test-block")).ok());
    RegisterRemoteSegmenter(*r);
    return r;
  }();
  return *registry;
}

class ServiceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    ServerOptions o;
    o.segmenters = &TestSegmenters();
    o.port = 0;
    o.threads = 4;
    o.instances_per_model = 2;
    o.backends = {"oracle", "color", "no-such-backend", "test-slow", "test-throws"};
    auto server = SegmentationServer::Start(o);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server).release();
    frame_ = new TestFrame();
  }
  static void TearDownTestSuite() {
    delete server_;
    server_ = nullptr;
    delete frame_;
    frame_ = nullptr;
  }

  static RemoteOptions Client(const std::string& model = "oracle") {
    RemoteOptions o;
    o.port = server_->port();
    o.model = model;
    return o;
  }

  /// A raw stub, for requests RemoteSegmenter would never send.
  static std::unique_ptr<inference::GRPCInferenceService::Stub> RawStub() {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(64 << 20);
    args.SetMaxSendMessageSize(64 << 20);
    return inference::GRPCInferenceService::NewStub(grpc::CreateCustomChannel(
        fmt::format("127.0.0.1:{}", server_->port()), grpc::InsecureChannelCredentials(), args));
  }

  static grpc::Status RawInfer(InferRequest request, inference::ModelInferResponse* response) {
    inference::ModelInferRequest proto;
    internal::ToProto(std::move(request), &proto);
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    return RawStub()->ModelInfer(&context, proto, response);
  }

  static InferRequest GoodRequest(const std::string& model = "oracle") {
    RequestEncodeOptions o;
    o.model_name = model;
    o.seed = 5;
    return *EncodeSegmentationRequest(frame_->Request(3), o);
  }

  /// The server still answers, and still segments correctly.
  static void ExpectStillServing() {
    RemoteSegmenter client(Client());
    auto live = client.ServerLive();
    ASSERT_TRUE(live.ok()) << live.status().ToString();
    EXPECT_TRUE(*live);
    auto s = client.Segment(frame_->Request(0));
    EXPECT_TRUE(s.ok()) << s.status().ToString();
  }

  static SegmentationServer* server_;
  static TestFrame* frame_;
};

SegmentationServer* ServiceTest::server_ = nullptr;
TestFrame* ServiceTest::frame_ = nullptr;

TEST_F(ServiceTest, HealthAndReadiness) {
  EXPECT_GT(server_->port(), 0);
  EXPECT_EQ(server_->address(), fmt::format("127.0.0.1:{}", server_->port()));
  const std::vector<ModelState> models = server_->models();
  ASSERT_EQ(models.size(), 5u);
  EXPECT_TRUE(models[0].ready);
  EXPECT_EQ(models[0].reason, "");
  EXPECT_FALSE(models[2].ready);
  EXPECT_THAT(models[2].reason, HasSubstr("unknown segmenter 'no-such-backend'"));

  RemoteSegmenter client(Client());
  EXPECT_TRUE(*client.ServerLive());
  EXPECT_TRUE(*client.ServerReady());
  auto ready = client.GetModelReadiness();
  ASSERT_TRUE(ready.ok()) << ready.status().ToString();
  EXPECT_TRUE(ready->ready);

  RemoteSegmenter broken(Client("no-such-backend"));
  ready = broken.GetModelReadiness();
  ASSERT_TRUE(ready.ok()) << ready.status().ToString();
  EXPECT_FALSE(ready->ready);
  EXPECT_THAT(ready->reason, HasSubstr("unknown segmenter 'no-such-backend'"));

  RemoteSegmenter unknown(Client("nope"));
  ready = unknown.GetModelReadiness();
  ASSERT_FALSE(ready.ok());
  EXPECT_EQ(ready.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(ready.status().message(),
              HasSubstr("unknown model 'nope'; this server serves: oracle, color, "
                        "no-such-backend, test-slow, test-throws"));
}

TEST_F(ServiceTest, Metadata) {
  RemoteSegmenter client(Client("color"));
  auto server = client.GetServerMetadata();
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  EXPECT_EQ(server->name, "avp-segmentation");
  auto m = client.GetModelMetadata();
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->name, "color");
  EXPECT_EQ(m->versions, std::vector<std::string>{"1"});
  ASSERT_EQ(m->inputs.size(), SegmentationInputs().size());
  for (size_t i = 0; i < m->inputs.size(); ++i) {
    EXPECT_EQ(m->inputs[i].name, SegmentationInputs()[i].name);
    EXPECT_EQ(m->inputs[i].datatype, SegmentationInputs()[i].datatype);
    EXPECT_EQ(m->inputs[i].shape, SegmentationInputs()[i].shape);
  }
  ASSERT_EQ(m->outputs.size(), SegmentationOutputs().size());
  EXPECT_EQ(m->outputs[0].name, "masks");
  EXPECT_EQ(m->outputs[0].shape, (std::vector<int64_t>{-1, -1, -1}));
}

TEST_F(ServiceTest, RemoteResultsEqualInProcessOnesForEachSeed) {
  for (const uint64_t seed : {uint64_t{0}, uint64_t{5}, ~uint64_t{0}}) {
    auto local = TestSegmenters().Make("oracle", seed);
    ASSERT_TRUE(local.ok());
    RemoteOptions o = Client();
    o.seed = seed;
    RemoteSegmenter remote(o);
    for (uint64_t frame_index = 0; frame_index < 4; ++frame_index) {
      const auto request = frame_->Request(frame_index);
      const auto expected = (*local)->Segment(request);
      ASSERT_TRUE(expected.ok());
      const auto got = remote.Segment(request);
      ASSERT_TRUE(got.ok()) << got.status().ToString();
      ExpectSameSegmentation(*got, *expected, fmt::format("seed {} frame {}", seed, frame_index));
    }
  }
  // The colour backend, and the image as a PNG.
  auto color = TestSegmenters().Make("color", 0);
  RemoteOptions o = Client("color");
  o.image = ImageEncoding::kPng;
  RemoteSegmenter remote(o);
  const auto expected = (*color)->Segment(frame_->Request(0));
  const auto got = remote.Segment(frame_->Request(0));
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  ExpectSameSegmentation(*got, *expected, "color");
}

TEST_F(ServiceTest, RemoteSchemeIsAFactory) {
  auto made = TestSegmenters().Make(fmt::format("remote://127.0.0.1:{}", server_->port()), 9);
  ASSERT_TRUE(made.ok()) << made.status().ToString();
  EXPECT_EQ((*made)->name(), fmt::format("remote://127.0.0.1:{}/oracle", server_->port()));
  auto local = TestSegmenters().Make("oracle", 9);
  const auto got = (*made)->Segment(frame_->Request(1));
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  ExpectSameSegmentation(*got, *(*local)->Segment(frame_->Request(1)));

  // The masks come back as RLE by default (exact), or dense when asked: the same segmentation.
  auto dense = TestSegmenters().Make(
      fmt::format("remote://127.0.0.1:{}/oracle?masks=dense", server_->port()), 9);
  ASSERT_TRUE(dense.ok()) << dense.status().ToString();
  const auto got_dense = (*dense)->Segment(frame_->Request(1));
  ASSERT_TRUE(got_dense.ok()) << got_dense.status().ToString();
  ExpectSameSegmentation(*got_dense, *(*local)->Segment(frame_->Request(1)));
  EXPECT_THAT(TestSegmenters().Make("remote://127.0.0.1:8001?masks=zip", 0).status().message(),
              HasSubstr("masks (zip) must be dense, rle or instance_ids"));

  auto bad = TestSegmenters().Make("remote://127.0.0.1:99999", 0);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bad.status().message(), HasSubstr("port (99999) must be in [1, 65535]"));
}

TEST_F(ServiceTest, TypedContentsAreAcceptedToo) {
  // A client that sends `contents` instead of raw bytes gets the same answer.
  const InferRequest good = GoodRequest();
  inference::ModelInferRequest proto;
  internal::ToProto(good, &proto);
  proto.clear_raw_input_contents();
  for (int i = 0; i < proto.inputs_size(); ++i) {
    const Tensor& t = good.inputs[static_cast<size_t>(i)];
    auto* c = proto.mutable_inputs(i)->mutable_contents();
    switch (t.datatype) {
      case DataType::kUint8:
        for (const char b : t.data) c->add_uint_contents(static_cast<uint8_t>(b));
        break;
      case DataType::kUint16: {
        const std::vector<uint16_t> values = ReadValues<uint16_t>(t).value();
        for (const uint16_t v : values) c->add_uint_contents(v);
        break;
      }
      case DataType::kFp32: {
        const std::vector<float> values = ReadValues<float>(t).value();
        for (const float v : values) c->add_fp32_contents(v);
        break;
      }
      case DataType::kFp64: {
        const std::vector<double> values = ReadValues<double>(t).value();
        for (const double v : values) c->add_fp64_contents(v);
        break;
      }
      case DataType::kBytes: {
        const std::vector<std::string> elements = ReadBytesElements(t).value();
        for (const std::string& e : elements) c->add_bytes_contents(e);
        break;
      }
      default:
        FAIL() << t.Describe();
    }
  }
  inference::ModelInferResponse typed_response, raw_response;
  {
    grpc::ClientContext context;
    ASSERT_TRUE(RawStub()->ModelInfer(&context, proto, &typed_response).ok());
  }
  ASSERT_TRUE(RawInfer(good, &raw_response).ok());
  auto typed = internal::FromProto(typed_response);
  auto raw = internal::FromProto(raw_response);
  ASSERT_TRUE(typed.ok() && raw.ok());
  EXPECT_EQ(typed->id, "test_camera@123456789");
  ExpectSameSegmentation(*DecodeSegmentation(*typed), *DecodeSegmentation(*raw));
  EXPECT_GE(std::get<double>(raw->parameters.at("server_segment_ms")), 0.0);
}

TEST_F(ServiceTest, RequestedOutputsOnly) {
  InferRequest r = GoodRequest();
  r.requested_outputs = {"scores", "masks"};
  inference::ModelInferResponse response;
  ASSERT_TRUE(RawInfer(r, &response).ok());
  ASSERT_EQ(response.outputs_size(), 2);
  EXPECT_EQ(response.outputs(0).name(), "masks");
  EXPECT_EQ(response.outputs(1).name(), "scores");
  r.requested_outputs = {"instance_map"};
  const grpc::Status s = RawInfer(r, &response);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("requested output 'instance_map' does not exist"));
}

struct MalformedCase {
  std::string what;
  std::function<void(InferRequest&)> mutate;
  grpc::StatusCode code;
  std::string message;
};

TEST_F(ServiceTest, MalformedRequestsAreRefusedAndTheServerGoesOn) {
  const auto input = [](InferRequest& r, std::string_view name) -> Tensor& {
    for (Tensor& t : r.inputs) {
      if (t.name == name) return t;
    }
    throw std::runtime_error("no input " + std::string(name));
  };
  const std::vector<MalformedCase> cases = {
      {"wrong dtype", [&](InferRequest& r) { input(r, "rgb").datatype = DataType::kInt8; },
       grpc::StatusCode::INVALID_ARGUMENT,
       "input 'rgb' must be UINT8 [H, W, 3] RGB8, got INT8 [120, 160, 3]"},
      {"wrong shape",
       [&](InferRequest& r) {
         input(r, "depth").shape = {160, 120};
       },
       grpc::StatusCode::INVALID_ARGUMENT,
       "input 'depth' must be FP32 [H, W] = [120, 160] (the colour image's size), got FP32 "
       "[160, 120]"},
      {"shape/bytes mismatch", [&](InferRequest& r) { input(r, "class_ids").data.resize(10); },
       grpc::StatusCode::INVALID_ARGUMENT,
       "input 'class_ids': shape [120, 160] of UINT8 needs 19200 bytes, got 10"},
      {"empty prompt",
       [&](InferRequest& r) { input(r, "prompt") = MakeBytesTensor("prompt", {""}); },
       grpc::StatusCode::INVALID_ARGUMENT, "input 'prompt' (\"\") is empty"},
      {"undecodable image",
       [&](InferRequest& r) {
         input(r, "rgb") = MakeBytesTensor("image", {std::string("\x89PNG\r\n\x1a\n garbage")});
       },
       grpc::StatusCode::INVALID_ARGUMENT,
       "input 'image': the 16 bytes are not a PNG or JPEG image OpenCV can decode"},
      {"unknown model", [](InferRequest& r) { r.model_name = "sam9000"; },
       grpc::StatusCode::NOT_FOUND, "unknown model 'sam9000'; this server serves: oracle"},
      {"model not ready", [](InferRequest& r) { r.model_name = "no-such-backend"; },
       grpc::StatusCode::FAILED_PRECONDITION,
       "model 'no-such-backend' is not ready: NotFound: unknown segmenter 'no-such-backend'"},
      {"missing rgb",
       [](InferRequest& r) {
         std::erase_if(r.inputs, [](const Tensor& t) { return t.name == "rgb"; });
       },
       grpc::StatusCode::INVALID_ARGUMENT,
       "missing input 'rgb' (UINT8 [H, W, 3]) or 'image' (BYTES [1], a PNG or JPEG)"},
      {"unknown version", [](InferRequest& r) { r.model_version = std::string(1, '3'); },
       grpc::StatusCode::NOT_FOUND, "model 'oracle' has no version '3' (versions: 1)"},
      {"backend refuses (no labels for the oracle)",
       [](InferRequest& r) {
         std::erase_if(r.inputs, [](const Tensor& t) {
           return t.name == "instance_ids" || t.name == "class_ids" || t.name == "fruits";
         });
       },
       grpc::StatusCode::FAILED_PRECONDITION,
       "model 'oracle': the oracle segmenter reads the simulator's labels"},
      {"backend throws", [](InferRequest& r) { r.model_name = "test-throws"; },
       grpc::StatusCode::INTERNAL, "model 'test-throws' threw: backend exploded"},
  };
  for (const MalformedCase& c : cases) {
    InferRequest r = GoodRequest();
    c.mutate(r);
    inference::ModelInferResponse response;
    const grpc::Status s = RawInfer(std::move(r), &response);
    EXPECT_EQ(s.error_code(), c.code) << c.what << ": " << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr(c.message)) << c.what;
    ExpectStillServing();
  }
  // A raw-contents count that does not match the inputs.
  inference::ModelInferRequest proto;
  internal::ToProto(GoodRequest(), &proto);
  proto.add_raw_input_contents("extra");
  grpc::ClientContext context;
  inference::ModelInferResponse response;
  const grpc::Status s = RawStub()->ModelInfer(&context, proto, &response);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("raw_input_contents has 9 entries for 8 inputs"));
  ExpectStillServing();

  // Through RemoteSegmenter, errors are statuses naming the server.
  RemoteSegmenter client(Client("no-such-backend"));
  auto seg = client.Segment(frame_->Request(0));
  ASSERT_FALSE(seg.ok());
  EXPECT_EQ(seg.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(seg.status().message(),
              HasSubstr(fmt::format("remote segmenter remote://127.0.0.1:{}/no-such-backend: "
                                    "ModelInfer: model 'no-such-backend' is not ready",
                                    server_->port())));
}

TEST_F(ServiceTest, DeadlineThatExpiresIsDeadlineExceeded) {
  RemoteOptions o = Client("test-slow");
  o.deadline_s = 0.1;
  RemoteSegmenter client(o);
  const auto t0 = std::chrono::steady_clock::now();
  auto s = client.Segment(frame_->Request(0));
  const double waited_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_THAT(s.status().message(),
              HasSubstr(fmt::format("no answer from 127.0.0.1:{} within the deadline of 0.1 s",
                                    server_->port())));
  EXPECT_LT(waited_s, 0.5);
  ExpectStillServing();
}

TEST_F(ServiceTest, ConcurrentClientsGetTheInProcessResults) {
  constexpr int kClients = 8;
  constexpr int kRequests = 50;
  constexpr uint64_t kSeed = 21;
  auto local = TestSegmenters().Make("oracle", kSeed);
  std::vector<Segmentation> expected;
  for (int i = 0; i < kRequests; ++i) {
    expected.push_back(*(*local)->Segment(frame_->Request(static_cast<uint64_t>(i))));
  }
  std::atomic<int> errors{0}, mismatches{0}, done{0};
  std::vector<std::string> first_error(kClients);
  std::vector<std::thread> threads;
  for (int c = 0; c < kClients; ++c) {
    threads.emplace_back([&, c] {
      RemoteOptions o = Client();
      o.seed = kSeed;
      RemoteSegmenter client(o);
      for (int i = 0; i < kRequests; ++i) {
        const int frame = (i + 7 * c) % kRequests;
        const auto got = client.Segment(frame_->Request(static_cast<uint64_t>(frame)));
        if (!got.ok()) {
          if (errors.fetch_add(1) == 0) first_error[c] = got.status().ToString();
          continue;
        }
        if (!Same(*got, expected[static_cast<size_t>(frame)])) mismatches.fetch_add(1);
        done.fetch_add(1);
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(errors.load(), 0) << testing::PrintToString(first_error);
  EXPECT_EQ(mismatches.load(), 0);
  EXPECT_EQ(done.load(), kClients * kRequests);
}

// ---- without the shared server
// -------------------------------------------------------------------

// ---- budgets: refused before any work
// ----------------------------------------------------------------------------

/// A PNG signature and IHDR declaring w x h, without pixels.
std::string PngHeader(uint32_t w, uint32_t h) {
  std::string png = "\x89PNG\r\n\x1a\n";
  const auto be32 = [&](uint32_t v) {
    for (int i = 3; i >= 0; --i) png.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  };
  be32(13);
  png += "IHDR";
  be32(w);
  be32(h);
  png += std::string("\x08\x02\x00\x00\x00\x00\x00\x00\x00", 9);
  return png;
}

Tensor& InputOf(InferRequest& r, std::string_view name) {
  for (Tensor& t : r.inputs) {
    if (t.name == name) return t;
  }
  throw std::runtime_error("no input " + std::string(name));
}

TEST_F(ServiceTest, AHundredThousandPhrasePromptIsRefusedAtOnce) {
  const ServerStats before = server_->stats();
  std::string prompt = "tomato";
  for (int i = 1; i < 100000; ++i) prompt += ", tomato";
  InferRequest r = GoodRequest("color");
  InputOf(r, "prompt") = MakeBytesTensor("prompt", {prompt});
  inference::ModelInferResponse response;
  grpc::Status s = RawInfer(r, &response);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_THAT(s.error_message(),
              HasSubstr("input 'prompt' (799998) exceeds the limit max_prompt_bytes = 4096; "
                        "raise it with `avp serve segmentation --max-prompt-bytes N`"));
  // As 100 000 elements of one phrase each.
  InputOf(r, "prompt") = MakeBytesTensor("prompt", std::vector<std::string>(100000, "tomato"));
  s = RawInfer(r, &response);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("(100000) exceeds the limit max_prompt_phrases = 64"));
  EXPECT_EQ(server_->stats().infer_over_budget, before.infer_over_budget + 2);
  // The client refuses it too, before sending (the process-wide limit of SplitPrompt).
  RemoteSegmenter client(Client("color"));
  auto seg = client.Segment(frame_->Request(0, prompt));
  ASSERT_FALSE(seg.ok());
  EXPECT_EQ(seg.status().code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(seg.status().message(), HasSubstr("max_prompt_bytes"));
  ExpectStillServing();
}

TEST_F(ServiceTest, AnImageDeclaring20000x20000PixelsIsRefusedBeforeDecoding) {
  InferRequest r = GoodRequest();
  InputOf(r, "rgb") = MakeBytesTensor("image", {PngHeader(20000, 20000)});
  inference::ModelInferResponse response;
  grpc::Status s = RawInfer(r, &response);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_THAT(s.error_message(),
              HasSubstr("input 'image' declaring 20000 x 20000 pixels (400000000) exceeds the "
                        "limit max_image_pixels = 16777216"));
  // A raw image's shape alone (no bytes sent) is enough.
  r = GoodRequest();
  InputOf(r, "rgb").shape = {20000, 20000, 3};
  InputOf(r, "rgb").data.clear();
  s = RawInfer(r, &response);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("input 'rgb' of 20000 x 20000 pixels"));
  // Thousands of tensors or parameters are refused from their counts.
  inference::ModelInferRequest proto;
  internal::ToProto(GoodRequest(), &proto);
  for (int i = 0; i < 5000; ++i) proto.add_inputs()->set_name("x");
  grpc::ClientContext context;
  s = RawStub()->ModelInfer(&context, proto, &response);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("the request has 5008 inputs"));
  ExpectStillServing();
}

// ---- a server of one worker: queue, fairness, cancellation
// ------------------------------------------------------

/// One ModelInfer in flight (a callback call); Wait() for its status.
struct AsyncInfer {
  grpc::ClientContext context;
  inference::ModelInferRequest request;
  inference::ModelInferResponse response;
  std::mutex mutex;
  std::condition_variable cv;
  bool done = false;
  grpc::Status status;

  AsyncInfer(inference::GRPCInferenceService::Stub& stub, InferRequest r, double deadline_s = 30) {
    internal::ToProto(std::move(r), &request);
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::milliseconds(static_cast<int>(deadline_s * 1000)));
    stub.async()->ModelInfer(&context, &request, &response, [this](grpc::Status s) {
      std::lock_guard lock(mutex);
      status = std::move(s);
      done = true;
      cv.notify_all();
    });
  }
  grpc::Status Wait() {
    std::unique_lock lock(mutex);
    cv.wait(lock, [this] { return done; });
    return status;
  }
};

/// Polls `done` every 2 ms for up to 10 s (a bound for a broken build, not a timing check).
bool Eventually(const std::function<bool()>& done) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (std::chrono::steady_clock::now() < until) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return done();
}

class OneWorkerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    BlockingSegmenter::entered = 0;
    BlockingSegmenter::stopped = 0;
  }
  void Start(int max_queue_depth, int max_queued_per_client, int max_instances = 256) {
    ServerOptions o;
    o.segmenters = &TestSegmenters();
    o.port = 0;
    o.threads = 1;
    o.max_queue_depth = max_queue_depth;
    o.max_queued_per_client = max_queued_per_client;
    o.max_instances = max_instances;
    o.backends = {"oracle", "test-block"};
    auto server = SegmentationServer::Start(o);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
  }
  /// A stub on a connection of its own (one client, as the server tells clients apart).
  std::unique_ptr<inference::GRPCInferenceService::Stub> NewClient() {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(64 << 20);
    args.SetMaxSendMessageSize(64 << 20);
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    return inference::GRPCInferenceService::NewStub(grpc::CreateCustomChannel(
        fmt::format("127.0.0.1:{}", server_->port()), grpc::InsecureChannelCredentials(), args));
  }
  InferRequest Request(const std::string& model) {
    RequestEncodeOptions o;
    o.model_name = model;
    return *EncodeSegmentationRequest(frame_.Request(3), o);
  }
  /// Occupies the one worker with a test-block call from its own client.
  std::unique_ptr<AsyncInfer> Occupy(inference::GRPCInferenceService::Stub& stub,
                                     double deadline_s = 30) {
    auto call = std::make_unique<AsyncInfer>(stub, Request("test-block"), deadline_s);
    EXPECT_TRUE(Eventually([] { return BlockingSegmenter::entered.load() == 1; }));
    return call;
  }
  test::TestFrame frame_;
  std::unique_ptr<SegmentationServer> server_;
};

TEST_F(OneWorkerTest, AFullQueueIsRefusedAtOnceAndACancelledCallFreesTheWorker) {
  Start(/*max_queue_depth=*/1, /*max_queued_per_client=*/1);
  auto a = NewClient(), b = NewClient(), c = NewClient();
  std::unique_ptr<AsyncInfer> blocked = Occupy(*a);
  AsyncInfer waiting(*b, Request("oracle"));
  ASSERT_TRUE(Eventually([&] { return server_->stats().queued == 1; }));
  // The queue holds one request: the next one is refused without waiting.
  inference::ModelInferRequest proto;
  internal::ToProto(Request("oracle"), &proto);
  inference::ModelInferResponse response;
  grpc::ClientContext context;
  const grpc::Status refused = c->ModelInfer(&context, proto, &response);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_THAT(refused.error_message(),
              HasSubstr("requests waiting for a worker (2) exceeds the limit max_queue_depth = 1"));
  EXPECT_EQ(server_->stats().infer_queue_full, 1u);
  // The blocked client leaves: its work stops, and the worker takes the waiting request.
  blocked->context.TryCancel();
  EXPECT_EQ(blocked->Wait().error_code(), grpc::StatusCode::CANCELLED);
  const grpc::Status served = waiting.Wait();
  EXPECT_TRUE(served.ok()) << served.error_message();
  EXPECT_TRUE(Eventually([&] { return server_->stats().infer_interrupted == 1; }));
  EXPECT_EQ(BlockingSegmenter::stopped.load(), 1);
}

TEST_F(OneWorkerTest, OneClientsFloodDoesNotPushOutAnother) {
  Start(/*max_queue_depth=*/8, /*max_queued_per_client=*/2);
  auto a = NewClient(), flood = NewClient(), other = NewClient();
  std::unique_ptr<AsyncInfer> blocked = Occupy(*a);
  std::vector<std::unique_ptr<AsyncInfer>> flooded;
  for (int i = 0; i < 5; ++i) {
    flooded.push_back(std::make_unique<AsyncInfer>(*flood, Request("oracle")));
  }
  // Two of the flood wait; the three others are refused at once.
  ASSERT_TRUE(Eventually([&] {
    const ServerStats st = server_->stats();
    return st.queued == 2 && st.infer_queue_full == 3;
  }));
  // Another client still gets a place, and its request is served.
  AsyncInfer mine(*other, Request("oracle"));
  ASSERT_TRUE(Eventually([&] { return server_->stats().queued == 3; }));
  blocked->context.TryCancel();
  EXPECT_EQ(blocked->Wait().error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_TRUE(mine.Wait().ok());
  int ok = 0, refused = 0;
  for (auto& call : flooded) {
    const grpc::Status st = call->Wait();
    if (st.ok()) {
      ++ok;
    } else {
      ++refused;
      EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << st.error_message();
      EXPECT_THAT(st.error_message(),
                  HasSubstr("requests of this client waiting for a worker (3) exceeds the limit "
                            "max_queued_per_client = 2"));
    }
  }
  EXPECT_EQ(ok, 2);
  EXPECT_EQ(refused, 3);
}

TEST_F(OneWorkerTest, AClientRunsOnAtMostHalfTheWorkers) {
  // Two workers: one client's two blocking calls take one of them; the second waits although a
  // worker is free, and another client's request is served by that worker.
  ServerOptions o;
  o.segmenters = &TestSegmenters();
  o.port = 0;
  o.threads = 2;
  o.backends = {"oracle", "test-block"};
  auto server = SegmentationServer::Start(o);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  server_ = std::move(*server);
  auto greedy = NewClient(), other = NewClient();
  AsyncInfer first(*greedy, Request("test-block"));
  ASSERT_TRUE(Eventually([] { return BlockingSegmenter::entered.load() == 1; }));
  AsyncInfer second(*greedy, Request("test-block"));
  ASSERT_TRUE(Eventually([&] { return server_->stats().queued == 1; }));
  inference::ModelInferRequest proto;
  internal::ToProto(Request("oracle"), &proto);
  inference::ModelInferResponse response;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  const grpc::Status served = other->ModelInfer(&context, proto, &response);
  EXPECT_TRUE(served.ok()) << served.error_message();
  EXPECT_EQ(BlockingSegmenter::entered.load(), 1);  // the greedy client's second call still waits
  first.context.TryCancel();
  EXPECT_EQ(first.Wait().error_code(), grpc::StatusCode::CANCELLED);
  ASSERT_TRUE(Eventually([] { return BlockingSegmenter::entered.load() == 2; }));
  second.context.TryCancel();
  EXPECT_EQ(second.Wait().error_code(), grpc::StatusCode::CANCELLED);

  ServerOptions bad = o;
  bad.max_running_per_client = 3;
  EXPECT_THAT(
      SegmentationServer::Start(bad).status().message(),
      HasSubstr("max_running_per_client (3) must be in [0 (half the threads), threads (2)]"));
}

TEST_F(OneWorkerTest, ADeadlinePassingStopsTheWorkAndFreesTheWorker) {
  Start(4, 4);
  auto a = NewClient(), b = NewClient();
  std::unique_ptr<AsyncInfer> late = Occupy(*a, /*deadline_s=*/0.3);
  EXPECT_EQ(late->Wait().error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  // The server stopped the segmenter (it would block for 20 s otherwise).
  EXPECT_TRUE(Eventually([] { return BlockingSegmenter::stopped.load() == 1; }));
  EXPECT_TRUE(Eventually([&] { return server_->stats().infer_interrupted == 1; }));
  inference::ModelInferRequest proto;
  internal::ToProto(Request("oracle"), &proto);
  inference::ModelInferResponse response;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  const grpc::Status s = b->ModelInfer(&context, proto, &response);
  EXPECT_TRUE(s.ok()) << s.error_message();
}

TEST_F(OneWorkerTest, TheClientsInterruptCancelsItsRemoteCall) {
  Start(4, 4);
  RemoteOptions o;
  o.port = server_->port();
  o.model = "test-block";
  RemoteSegmenter client(o);
  segmentation::SegmentationRequest r = frame_.Request(0);
  r.interrupt = []() -> Status {
    return BlockingSegmenter::entered.load() > 0 ? CancelledError("Ctrl-C") : Status::Ok();
  };
  auto seg = client.Segment(r);
  ASSERT_FALSE(seg.ok());
  EXPECT_EQ(seg.status().code(), StatusCode::kCancelled);
  EXPECT_THAT(seg.status().message(), HasSubstr("Ctrl-C"));
  EXPECT_TRUE(Eventually([] { return BlockingSegmenter::stopped.load() == 1; }));
}

TEST_F(OneWorkerTest, MoreInstancesThanTheLimitAreRefused) {
  Start(4, 4, /*max_instances=*/1);
  auto local = TestSegmenters().Make("oracle", 0);
  ASSERT_TRUE(local.ok());
  const auto expected = (*local)->Segment(frame_.Request(3));
  ASSERT_TRUE(expected.ok());
  ASSERT_GT(expected->instances.size(), 1u) << "the test frame must show several fruits";
  RemoteOptions o;
  o.port = server_->port();
  o.seed = 0;
  RemoteSegmenter client(o);
  auto seg = client.Segment(frame_.Request(3));
  ASSERT_FALSE(seg.ok());
  EXPECT_EQ(seg.status().code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(seg.status().message(),
              HasSubstr(fmt::format("instances found by model 'oracle' ({}) exceeds the limit "
                                    "max_instances = 1",
                                    expected->instances.size())));
}

TEST(ServerLifecycleTest, ServerDownIsUnavailableNamingTheAddress) {
  int port = 0;
  {
    ServerOptions o;
    o.segmenters = &TestSegmenters();
    o.port = 0;
    auto server = SegmentationServer::Start(o);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    port = (*server)->port();
    (*server)->Shutdown();
    (*server)->Shutdown();  // idempotent
  }
  RemoteOptions o;
  o.port = port;
  o.deadline_s = 5.0;
  RemoteSegmenter client(o);
  TestFrame scene;
  auto s = client.Segment(scene.Request(0));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(
      s.status().message(),
      HasSubstr(fmt::format("the segmentation server at 127.0.0.1:{} is unavailable", port)));
  auto live = client.ServerLive();
  ASSERT_FALSE(live.ok());
  EXPECT_THAT(live.status().message(), HasSubstr(fmt::format("127.0.0.1:{}", port)));
}

TEST(ServerLifecycleTest, BackendsAreServedUnderNamesClientsCanGive) {
  // A spec with a scheme is served by its scheme, NAME=SPEC by NAME; remote://HOST:PORT/MODEL
  // cannot name a model with '/' in it, so such a name is refused at start-up.
  EXPECT_EQ(ParseServedBackend("ywes://models").model, "ywes");
  EXPECT_EQ(ParseServedBackend("ywes://models").spec, "ywes://models");
  EXPECT_EQ(ParseServedBackend("fast=ywes:///m/s").model, "fast");
  EXPECT_EQ(ParseServedBackend("fast=ywes:///m/s").spec, "ywes:///m/s");
  EXPECT_EQ(ParseServedBackend("oracle").model, "oracle");
  EXPECT_EQ(ParseServedBackend("a/b=oracle").model, "a/b=oracle");
  ServerOptions bad;
  bad.segmenters = &TestSegmenters();
  bad.backends = {"ywes://a", "ywes://b", "a/b=oracle", "empty="};
  const Status s = bad.Validate();
  EXPECT_THAT(s.message(), HasSubstr("backends[0] (\"ywes://a\") and backends[1] (\"ywes://b\") "
                                     "would both be served as model \"ywes\": name them, "
                                     "NAME=SPEC"));
  EXPECT_THAT(s.message(), HasSubstr("backends[2] (\"a/b=oracle\") would be served as model "
                                     "\"a/b=oracle\", which clients cannot name"));
  EXPECT_THAT(s.message(), HasSubstr("backends[3] (\"empty=\") names no segmenter after '='"));

  ServerOptions o;
  o.segmenters = &TestSegmenters();
  o.port = 0;
  o.backends = {"truth=oracle", "color"};
  auto server = SegmentationServer::Start(o);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  ASSERT_EQ((*server)->models().size(), 2u);
  EXPECT_EQ((*server)->models()[0].name, "truth");
  EXPECT_TRUE((*server)->models()[0].ready) << (*server)->models()[0].reason;
  TestFrame frame;
  RemoteOptions ro;
  ro.port = (*server)->port();
  ro.model = "truth";
  RemoteSegmenter remote(ro);
  auto local = TestSegmenters().Make("oracle", o.default_seed);
  ASSERT_TRUE(local.ok());
  const auto expected = (*local)->Segment(frame.Request(0));
  const auto got = remote.Segment(frame.Request(0));
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  ExpectSameSegmentation(*got, *expected, "truth=oracle");
}

TEST(ServerLifecycleTest, BadOptionsAndBusyPorts) {
  ServerOptions bad;
  bad.segmenters = &TestSegmenters();
  bad.port = 70000;
  bad.threads = 0;
  bad.backends = {"oracle", "oracle"};
  const auto s = SegmentationServer::Start(bad);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().message(),
            "invalid server options: port (70000) must be in [0, 65535]; backends[1] "
            "(\"oracle\") is listed twice; threads (0) must be in [1, 256]");

  ServerOptions limits;
  limits.segmenters = &TestSegmenters();
  limits.max_queue_depth = 0;
  limits.max_queued_per_client = 5;
  limits.max_image_pixels = 0;
  limits.max_prompt_bytes = uint64_t{1} << 30;
  limits.max_prompt_phrases = 0;
  limits.max_instances = 70000;
  limits.max_cached_seeds = 5000;
  const auto l = SegmentationServer::Start(limits);
  ASSERT_FALSE(l.ok());
  for (const char* problem : {"max_cached_seeds (5000) must be in [1, 1024]",
                              "max_queue_depth (0) must be in [1, 100000]",
                              "max_queued_per_client (5) must be in [1, max_queue_depth (0)]",
                              "max_image_pixels (0) must be in [1, 1073741824 (32768^2)]",
                              "max_prompt_bytes (1073741824) must be in [1, 1048576 (1 MiB)]",
                              "max_prompt_phrases (0) must be in [1, 4096]",
                              "max_instances (70000) must be in [1, 65535]"}) {
    EXPECT_THAT(l.status().message(), HasSubstr(problem));
  }

  ServerOptions o;
  o.segmenters = &TestSegmenters();
  o.port = 0;
  auto first = SegmentationServer::Start(o);
  ASSERT_TRUE(first.ok());
  o.port = (*first)->port();
  auto second = SegmentationServer::Start(o);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), StatusCode::kIoError);
  EXPECT_THAT(second.status().message(),
              HasSubstr(fmt::format("cannot listen on 127.0.0.1:{}: the port is in use", o.port)));
  // A host that does not resolve, or is not this machine's, is named before gRPC is asked.
  o.port = 0;
  o.host = "no-such-host.invalid";
  auto unresolved = SegmentationServer::Start(o);
  ASSERT_FALSE(unresolved.ok());
  EXPECT_EQ(unresolved.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(unresolved.status().message(),
              HasSubstr("--host 'no-such-host.invalid' is not an address or a name this machine "
                        "resolves"));
  o.host = "192.0.2.1";  // TEST-NET-1: never an address of this machine
  auto foreign = SegmentationServer::Start(o);
  ASSERT_FALSE(foreign.ok());
  EXPECT_THAT(foreign.status().message(),
              HasSubstr("cannot listen on 192.0.2.1:0: not an address of this machine"));
}

TEST(RemoteSpecTest, ParsesHostPortModelAndOptions) {
  auto o = ParseRemoteSpec("remote://127.0.0.1:8001");
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  EXPECT_EQ(o->host, "127.0.0.1");
  EXPECT_EQ(o->port, 8001);
  EXPECT_EQ(o->model, "oracle");
  EXPECT_EQ(o->Spec(), "remote://127.0.0.1:8001/oracle");
  o = ParseRemoteSpec("remote://gpu-box/ywes");
  ASSERT_TRUE(o.ok());
  EXPECT_EQ(o->port, kDefaultServicePort);
  EXPECT_EQ(o->model, "ywes");
  o = ParseRemoteSpec("remote://[::1]:9000/color?deadline_s=2.5&image=png&labels=0");
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  EXPECT_EQ(o->host, "::1");
  EXPECT_EQ(o->Address(), "[::1]:9000");
  EXPECT_EQ(o->deadline_s, 2.5);
  EXPECT_EQ(o->image, ImageEncoding::kPng);
  EXPECT_FALSE(o->send_labels);
  EXPECT_TRUE(o->send_depth);

  for (const auto& [spec, message] : std::vector<std::pair<std::string, std::string>>{
           {"remote://", "the host is empty"},
           {"remote://h:", "the port after ':' is empty"},
           {"remote://h:0", "port (0) must be in [1, 65535]"},
           {"remote://h:80x", "port (80x) must be in [1, 65535]"},
           {"remote://h:1/", "the model after '/' is empty"},
           {"remote://h:1/a/b", "model \"a/b\" must not contain '/'"},
           {"remote://h?deadline_s=-1", "deadline_s (-1) must be a number of seconds > 0"},
           {"remote://h?colour=1", "unknown option 'colour'"},
           {"remote://[::1", "IPv6 host lacks its closing ']'"},
           {"grpc://h:1", "does not start with remote://"},
       }) {
    const auto r = ParseRemoteSpec(spec);
    ASSERT_FALSE(r.ok()) << spec;
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument) << spec;
    EXPECT_THAT(r.status().message(), HasSubstr(message)) << spec;
    EXPECT_THAT(r.status().message(), HasSubstr("remote segmenter spec \"" + spec + "\"")) << spec;
  }
}

}  // namespace
}  // namespace avp::segmentation_service

// The networks on an inference server: `avp serve models` (zsl::ServeModels, ONNX Runtime behind
// KServe v2 over gRPC on loopback) serves the stub models of make_stubs.py, and ywes and lsam
// built with RuntimeOptions::model_server give exactly what they give in process: the same
// instances, labels, scores, boxes and masks, bit for bit. A server that is not there, a model
// it does not serve, and requests that do not fit a model are errors naming them.
#include "remote_model.h"

#include <array>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <avp/core/camera.h>
#include <avp/core/rgbd_frame.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation_service/tensor_service.h>
#include <avp/zsl/lsam_segmenter.h>
#include <avp/zsl/model_service.h>
#include <avp/zsl/ywes_segmenter.h>

#include "manifest.h"
#include "ort_handler.h"
#include "tensor_model.h"

namespace avp::zsl {
namespace {

namespace fs = std::filesystem;
using segmentation::SegmentationRequest;
using ::testing::HasSubstr;

const fs::path kStubs = AVP_ZSL_STUB_DIR;

/// `dir`'s models served on a free loopback port.
ModelService Serve(const fs::path& dir) {
  ModelServiceOptions o;
  o.server.port = 0;
  o.server.threads = 4;
  o.runtime.device = Device::kCpu;
  o.runtime.intra_op_threads = 1;
  Result<ModelService> s = ServeModels(dir, o);
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  return s.ok() ? std::move(s).value() : ModelService{};
}

std::string Url(const ModelService& s) {
  return "grpc://127.0.0.1:" + std::to_string(s.server->port());
}

RgbdFrame Frame(int w, int h, std::array<uint8_t, 3> colour) {
  RgbdFrame f;
  f.rgb = ImageRgb8(w, h);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      for (int c = 0; c < 3; ++c) {
        // A gradient, so that the networks see more than one colour.
        f.rgb.at(u, v, c) =
            static_cast<uint8_t>((colour[static_cast<size_t>(c)] + u + 2 * v) % 256);
      }
    }
  }
  f.depth_m = DepthImage(w, h, 0.f);
  f.K = CameraIntrinsics::FromHorizontalFov(w, h, 60.0);
  return f;
}

Segmentation SegmentOk(segmentation::Segmenter& s, const RgbdFrame& frame,
                       const std::string& prompt) {
  SegmentationRequest r;
  r.frame = &frame;
  r.prompt = prompt;
  Result<Segmentation> seg = s.Segment(r);
  EXPECT_TRUE(seg.ok()) << seg.status().ToString();
  return seg.ok() ? std::move(seg).value() : Segmentation{};
}

void ExpectSame(const Segmentation& local, const Segmentation& remote) {
  ASSERT_EQ(local.instances.size(), remote.instances.size());
  ASSERT_EQ(local.width, remote.width);
  ASSERT_EQ(local.height, remote.height);
  for (size_t i = 0; i < local.instances.size(); ++i) {
    const InstanceMask& a = local.instances[i];
    const InstanceMask& b = remote.instances[i];
    EXPECT_EQ(a.label, b.label) << i;
    EXPECT_EQ(a.confidence, b.confidence) << i;
    EXPECT_EQ(a.mask_score, b.mask_score) << i;
    ASSERT_EQ(a.box.has_value(), b.box.has_value()) << i;
    if (a.box) {
      EXPECT_EQ(a.box->x0, b.box->x0);
      EXPECT_EQ(a.box->y0, b.box->y0);
      EXPECT_EQ(a.box->x1, b.box->x1);
      EXPECT_EQ(a.box->y1, b.box->y1);
    }
    EXPECT_TRUE(a.mask == b.mask) << "instance " << i << " mask differs";
  }
}

/// Each of `segmenters` segments `frame` with its prompt, all at once (one thread each).
std::vector<Segmentation> SegmentAtOnce(
    const std::vector<std::unique_ptr<YwesSegmenter>>& segmenters, const RgbdFrame& frame,
    const std::vector<std::string>& prompts) {
  std::vector<Segmentation> answers(prompts.size());
  std::vector<std::thread> threads;
  for (size_t i = 0; i < prompts.size(); ++i) {
    threads.emplace_back([&, i] { answers[i] = SegmentOk(*segmenters[i], frame, prompts[i]); });
  }
  for (std::thread& t : threads) t.join();
  return answers;
}

/// ExpectSame of `reference`'s answer for each prompt against `answers`; the instances compared.
size_t ExpectSameAsReference(YwesSegmenter& reference, const RgbdFrame& frame,
                             const std::vector<std::string>& prompts,
                             const std::vector<Segmentation>& answers) {
  size_t instances = 0;
  for (size_t i = 0; i < prompts.size(); ++i) {
    SCOPED_TRACE(prompts[i]);
    const Segmentation x = SegmentOk(reference, frame, prompts[i]);
    ExpectSame(x, answers[i]);
    instances += x.instances.size();
  }
  return instances;
}

TEST(RemoteModelTest, YwesOnTheModelServerEqualsYwesInProcess) {
  ModelService service = Serve(kStubs / "ywes");
  ASSERT_NE(service.server, nullptr);
  // Every role of the manifest is served, under its role's name.
  std::vector<std::string> names;
  for (const ModelService::Served& m : service.models) names.push_back(m.name);
  EXPECT_THAT(service.models.front().io, HasSubstr("inputs '"));
  EXPECT_THAT(names, ::testing::UnorderedElementsAre("detector", "text", "segmenter.encoder",
                                                     "segmenter.decoder"));
  YwesOptions local;
  local.session.device = Device::kCpu;
  local.session.intra_op_threads = 1;
  YwesOptions remote = local;
  remote.session.model_server = Url(service);
  Result<std::unique_ptr<YwesSegmenter>> a = YwesSegmenter::Create(kStubs / "ywes", local);
  Result<std::unique_ptr<YwesSegmenter>> b = YwesSegmenter::Create(kStubs / "ywes", remote);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_THAT((*b)->detector().provider(), HasSubstr("remote grpc://127.0.0.1:"));
  EXPECT_EQ((*a)->detector().provider(), "CPUExecutionProvider");
  const uint64_t before = service.server->stats().infer_ok;
  size_t instances = 0;
  for (const char* prompt : {"a", "b", "a, c", "b, c, d"}) {
    for (const auto& size : {std::pair{1024, 768}, std::pair{640, 480}}) {
      SCOPED_TRACE(std::string(prompt) + " " + std::to_string(size.first));
      const RgbdFrame frame = Frame(size.first, size.second, {200, 50, 10});
      const Segmentation x = SegmentOk(**a, frame, prompt);
      const Segmentation y = SegmentOk(**b, frame, prompt);
      ExpectSame(x, y);
      instances += x.instances.size();
    }
  }
  EXPECT_GT(instances, 4u);  // the planted anchors fired: real masks were compared
  // The networks ran on the server: per image at least the detector, the SAM encoder and its
  // decoder, and the text encoder for each new phrase (its embeddings are cached here).
  EXPECT_GE(service.server->stats().infer_ok - before, 3u * 8u + 4u);
}

TEST(RemoteModelTest, YwesOnABatchingModelServerEqualsYwesInProcess) {
  // avp serve models --max-batch 4: of the ywes stubs only the text encoder (input_ids [B,77])
  // has a batch axis. Four robots send one prompt each at once: their text requests run as one
  // stacked run, and every answer is the one ywes gives in process.
  ModelServiceOptions o;
  o.server.port = 0;
  o.server.threads = 8;
  o.server.batching.max_batch = 4;
  o.server.batching.max_delay = std::chrono::seconds(1);  // full long before: 4 rows
  o.runtime.device = Device::kCpu;
  o.runtime.intra_op_threads = 1;
  Result<ModelService> service = ServeModels(kStubs / "ywes", o);
  ASSERT_TRUE(service.ok()) << service.status().ToString();
  const std::map<std::string, std::string> how = service->server->batching();
  EXPECT_EQ(how.at("text"), "batched: up to 4 rows, waiting at most 1000000 us");
  EXPECT_EQ(how.at("detector"), "not batched: input 'images' has a fixed leading dimension 1");
  EXPECT_EQ(how.at("segmenter.decoder"),
            "not batched: input 'image_embeddings' has a fixed leading dimension 1");
  YwesOptions local;
  local.session.device = Device::kCpu;
  local.session.intra_op_threads = 1;
  YwesOptions remote = local;
  remote.session.model_server = "grpc://127.0.0.1:" + std::to_string(service->server->port());
  const std::vector<std::string> prompts = {"a", "b", "c", "d"};
  std::vector<std::unique_ptr<YwesSegmenter>> robots;
  for (size_t i = 0; i < prompts.size(); ++i) {
    Result<std::unique_ptr<YwesSegmenter>> r = YwesSegmenter::Create(kStubs / "ywes", remote);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    robots.push_back(std::move(r).value());
  }
  Result<std::unique_ptr<YwesSegmenter>> in_process = YwesSegmenter::Create(kStubs / "ywes", local);
  ASSERT_TRUE(in_process.ok()) << in_process.status().ToString();
  const RgbdFrame frame = Frame(640, 480, {200, 50, 10});
  const std::vector<Segmentation> answers = SegmentAtOnce(robots, frame, prompts);
  const size_t instances = ExpectSameAsReference(**in_process, frame, prompts, answers);
  EXPECT_GT(instances, 2u);  // the planted anchors fired: real masks were compared
  const segmentation_service::BatchingStats text = service->server->stats().batching.at("text");
  EXPECT_EQ(text.requests, 4u);
  EXPECT_EQ(text.batches, 1u);
  EXPECT_EQ(text.largest, 4);
  EXPECT_EQ(service->server->stats().batching.count("detector"), 0u);
}

TEST(RemoteModelTest, InProcessBatchingSharesANetworkAndStacksItsCalls) {
  // SessionOptions::batching in process (avp serve segmentation --max-batch): the backend
  // instances share one batched text encoder (the stubs' only network with a batch axis); four
  // instances segmenting at once have their text calls stacked into one run, and each answer is
  // the one an unbatched instance gives.
  YwesOptions plain;
  plain.session.device = Device::kCpu;
  plain.session.intra_op_threads = 1;
  YwesOptions batched = plain;
  batched.session.batching.max_batch = 4;
  batched.session.batching.max_delay = std::chrono::seconds(1);  // full long before: 4 rows
  const fs::path text_file = fs::canonical(kStubs / "ywes" / "text" / "clip_stub_text.onnx");
  const auto text_batchers = [&] {
    std::vector<internal::BatchedModelInfo> mine;
    for (const internal::BatchedModelInfo& m : internal::BatchedModels()) {
      if (fs::canonical(m.file) == text_file) mine.push_back(m);
    }
    return mine;
  };
  const std::vector<std::string> prompts = {"a", "b", "c", "d"};
  std::vector<Segmentation> answers(prompts.size());
  {
    std::vector<std::unique_ptr<YwesSegmenter>> instances;
    for (size_t i = 0; i < prompts.size(); ++i) {
      Result<std::unique_ptr<YwesSegmenter>> r = YwesSegmenter::Create(kStubs / "ywes", batched);
      ASSERT_TRUE(r.ok()) << r.status().ToString();
      instances.push_back(std::move(r).value());
    }
    ASSERT_EQ(text_batchers().size(), 1u);  // one text encoder for the four instances
    EXPECT_EQ(text_batchers()[0].label, "text");
    answers = SegmentAtOnce(instances, Frame(640, 480, {200, 50, 10}), prompts);
    const segmentation_service::BatchingStats stats = text_batchers().at(0).stats;
    EXPECT_EQ(stats.requests, 4u);
    EXPECT_EQ(stats.batches, 1u);
    EXPECT_EQ(stats.largest, 4);
  }
  EXPECT_TRUE(text_batchers().empty());  // gone with the last instance
  Result<std::unique_ptr<YwesSegmenter>> alone = YwesSegmenter::Create(kStubs / "ywes", plain);
  ASSERT_TRUE(alone.ok()) << alone.status().ToString();
  EXPECT_TRUE(text_batchers().empty());  // without batching nothing is shared
  const size_t found =
      ExpectSameAsReference(**alone, Frame(640, 480, {200, 50, 10}), prompts, answers);
  EXPECT_GT(found, 2u);
}

TEST(RemoteModelTest, AModelServiceBatchesOnlyThroughItsServerOptions) {
  ModelServiceOptions o;
  o.server.port = 0;
  o.runtime.device = Device::kCpu;
  o.runtime.batching.max_batch = 4;
  const Result<ModelService> s = ServeModels(kStubs / "ywes", o);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.status().message(), HasSubstr("runtime.batching.max_batch (4) must be 1"));
}

TEST(RemoteModelTest, LsamOnTheModelServerEqualsLsamInProcess) {
  ModelService service = Serve(kStubs / "lsam");
  ASSERT_NE(service.server, nullptr);
  LsamOptions local;
  local.session.device = Device::kCpu;
  local.session.intra_op_threads = 1;
  LsamOptions remote = local;
  remote.session.model_server = Url(service);
  Result<std::unique_ptr<LsamSegmenter>> a = LsamSegmenter::Create(kStubs / "lsam", local);
  Result<std::unique_ptr<LsamSegmenter>> b = LsamSegmenter::Create(kStubs / "lsam", remote);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  size_t instances = 0;
  for (const char* prompt : {"tomato", "tomato, leaf", "cat, dog"}) {
    SCOPED_TRACE(prompt);
    const RgbdFrame frame = Frame(1024, 768, {128, 128, 128});
    const Segmentation x = SegmentOk(**a, frame, prompt);
    ExpectSame(x, SegmentOk(**b, frame, prompt));
    instances += x.instances.size();
  }
  EXPECT_GT(instances, 2u);
}

TEST(RemoteModelTest, ManifestNamesTheModelsOnTheServer) {
  // A copy of the ywes stubs whose manifest serves the detector as "yolo-world-s" (served_as),
  // as a Triton repository of another naming would.
  const fs::path dir = fs::temp_directory_path() / "avp_remote_model_served_as";
  fs::remove_all(dir);
  fs::copy(kStubs / "ywes", dir, fs::copy_options::recursive);
  nlohmann::json manifest = nlohmann::json::parse(std::ifstream(dir / "manifest.json"));
  manifest["models"]["detector"]["served_as"] = "yolo-world-s";
  std::ofstream(dir / "manifest.json") << manifest.dump(2);
  ModelService service = Serve(dir);
  ASSERT_NE(service.server, nullptr);
  std::vector<std::string> names;
  for (const ModelService::Served& m : service.models) names.push_back(m.name);
  EXPECT_THAT(names, ::testing::Contains("yolo-world-s"));
  YwesOptions o;
  o.session.device = Device::kCpu;
  o.session.model_server = Url(service);
  Result<std::unique_ptr<YwesSegmenter>> renamed = YwesSegmenter::Create(dir, o);
  ASSERT_TRUE(renamed.ok()) << renamed.status().ToString();
  EXPECT_THAT((*renamed)->detector().provider(), HasSubstr("/yolo-world-s"));
  // The stubs' own manifest asks for "detector", which this server does not have.
  Result<std::unique_ptr<YwesSegmenter>> plain = YwesSegmenter::Create(kStubs / "ywes", o);
  ASSERT_FALSE(plain.ok());
  EXPECT_THAT(plain.status().message(),
              AllOf(HasSubstr("no model 'detector' here"), HasSubstr("yolo-world-s")));
  fs::remove_all(dir);
}

TEST(RemoteModelTest, ErrorsNameTheServerTheModelAndTheTensor) {
  // No server: the backend is not ready, naming the address.
  YwesOptions o;
  o.session.device = Device::kCpu;
  o.session.model_server = "grpc://127.0.0.1:1";
  Result<std::unique_ptr<YwesSegmenter>> none = YwesSegmenter::Create(kStubs / "ywes", o);
  ASSERT_FALSE(none.ok());
  EXPECT_THAT(none.status().message(), HasSubstr("127.0.0.1:1"));
  // Not an address.
  o.session.model_server = "http://127.0.0.1:8001";
  none = YwesSegmenter::Create(kStubs / "ywes", o);
  ASSERT_FALSE(none.ok());
  EXPECT_THAT(none.status().message(), HasSubstr("grpc://HOST:PORT"));

  // A server of the lsam models has no detector: ywes names the role it misses.
  ModelService lsam = Serve(kStubs / "lsam");
  ASSERT_NE(lsam.server, nullptr);
  o.session.model_server = Url(lsam);
  none = YwesSegmenter::Create(kStubs / "ywes", o);
  ASSERT_FALSE(none.ok());
  EXPECT_THAT(none.status().message(), AllOf(HasSubstr("detector"), HasSubstr("no model")));

  // A request that does not fit the model is refused before it runs, naming the tensor.
  Result<ModelRef> decoder = ConnectRemoteModel(Url(lsam), "segmenter.decoder");
  ASSERT_TRUE(decoder.ok()) << decoder.status().ToString();
  const std::vector<float> few(3, 0.f);
  const std::vector<InputTensor> inputs = {InputTensor::Float32("image_embeddings", few, {1, 3})};
  Result<std::vector<OutputTensor>> r = decoder->Run(inputs);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("image_embeddings"));
  EXPECT_GE(lsam.server->stats().infer_failed, 1u);

  // The manifest must be one: ServeModels names what is wrong.
  ModelServiceOptions bad;
  bad.server.port = 0;
  EXPECT_EQ(ServeModels(kStubs / "no-such-dir", bad).status().code(), StatusCode::kNotFound);
  bad.runtime.model_server = "grpc://127.0.0.1:9";
  EXPECT_THAT(ServeModels(kStubs / "ywes", bad).status().message(), HasSubstr("must be empty"));
}

}  // namespace
}  // namespace avp::zsl

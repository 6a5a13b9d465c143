// Zero-shot segmentation latency (avp::zsl): YwesSegmenter and LsamSegmenter on a 640x480 image,
// end to end (the benchmark's time) and per stage (counters "<stage>_ms", the mean over the
// iterations), with 1 and 2 ONNX Runtime intra-op threads. The service round trip is measured by
// the interop benchmarks.
//
// Models:
//   stub   the stub models of zsl/test/stubs/make_stubs.py, always: written at start-up into a
//          temporary folder with Debian's /usr/bin/python3 (python3-onnx), or taken from
//          AVP_ZSL_STUB_DIR when set (e.g. <build>/zsl/stub_models after ctest). They measure the
//          pipeline's own cost (letterbox, tokenizer, NMS, mask chain, ORT overhead), not networks.
//   real   the model directory of AVP_ZSL_MODEL_DIR, when set, on AVP_ZSL_TEST_IMAGE (default: a
//          synthetic 640x480 picture) with the prompt AVP_ZSL_TEST_PROMPT (default "tomato"), on
//          the device of AVP_ZSL_DEVICE. With AVP_ZSL_BENCH_BOXES=K[,K...] (at most 16
//          counts, each in [1, 300]) also
//          BM_Ywes/real_boxes:K: the K best-scoring anchors are the detections (no score
//          threshold, no suppression), so the SAM decoder runs on K boxes whatever the weights
//          (random-weight exports, scripts/export-random-weights, score every anchor below the
//          0.002 default).
// Cases: BM_Ywes/<models>/threads:N (the text embeddings cached after the first call, as in a
// running system), BM_YwesUncachedText/<models>/threads:N (text model every call), and
// BM_Lsam/<models>/threads:N. Prompts for the stubs: "a, b, c" (three planted boxes) and
// "tomato, leaf, stem".
//
// --serve-clients [--seconds=S] (instead of the cases above): dynamic batching in `avp serve
// models` (segmentation_service/tensor_batcher.h). The text model of the `ywes_heavy_text` stubs
// (the CLIP text contract, input_ids [B,77], with about 0.6 GMAC of residual MLP blocks per prompt:
// the work of a small transformer, not its accuracy) served on 127.0.0.1 with 16 gRPC threads:
// without batching (1 ONNX Runtime thread per run, runs side by side, one per request), and with
// it (up to 16 rows per run, 2 ms wait) as 2 batches at once of 1 ORT thread each (batched_2x1)
// or 1 batch at a time of 2 ORT threads (batched_1x2); 1, 4 and 16 clients, each its own
// connection, one request of one prompt at a time, S seconds each: requests per second, p50 and
// p99 latency, and the mean requests per run.
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include <benchmark/benchmark.h>
#include <fmt/format.h>
#include <unistd.h>

#include <avp/core/camera.h>
#include <avp/core/options.h>
#include <avp/core/rgbd_frame.h>
#include <avp/io/image_codec.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation_service/tensor_service.h>
#include <avp/zsl/lsam_segmenter.h>
#include <avp/zsl/model_service.h>
#include <avp/zsl/ywes_segmenter.h>

#include "bench_report.h"

namespace avp::zsl {
namespace {

namespace fs = std::filesystem;

std::optional<std::string> Env(const char* name) {
  const char* v = std::getenv(name);
  if (v == nullptr || *v == '\0') return std::nullopt;
  return std::string(v);
}

/// The stub model folder: AVP_ZSL_STUB_DIR, or make_stubs.py run into a temporary folder (removed
/// at exit).
Result<fs::path> StubDir(bool bench_models = false) {
  if (std::optional<std::string> dir = Env("AVP_ZSL_STUB_DIR")) {
    if (!bench_models || fs::exists(fs::path(*dir) / "ywes_heavy_text")) return fs::path(*dir);
  }
  static fs::path temp;
  temp = fs::temp_directory_path() / fmt::format("avp_bench_zsl_{}", ::getpid());
  const std::string command =
      fmt::format("/usr/bin/python3 '{}' '{}' --clip-merges '{}'{} > /dev/null", AVP_ZSL_MAKE_STUBS,
                  temp.string(), AVP_ZSL_CLIP_MERGES, bench_models ? " --bench" : "");
  if (std::system(command.c_str()) != 0) {
    return FailedPreconditionError(fmt::format(
        "'{}' failed: the stub models need Debian's python3-onnx (scripts/setup), or set "
        "AVP_ZSL_STUB_DIR to a folder of stubs",
        command));
  }
  std::atexit([] {
    std::error_code ec;
    fs::remove_all(temp, ec);
  });
  return temp;
}

RgbdFrame FrameOf(ImageRgb8 image) {
  RgbdFrame f;
  f.K = CameraIntrinsics::FromHorizontalFov(image.width(), image.height(), 60.0);
  f.depth_m = DepthImage(image.width(), image.height(), 0.f);
  f.rgb = std::move(image);
  return f;
}

/// 640x480 of colour (200, 50, 10): the stub detector scores mean(R) ≈ 0.7 on it.
ImageRgb8 StubImage() {
  ImageRgb8 image(640, 480);
  for (int v = 0; v < 480; ++v) {
    for (int u = 0; u < 640; ++u) {
      image.at(u, v, 0) = 200;
      image.at(u, v, 1) = 50;
      image.at(u, v, 2) = 10;
    }
  }
  return image;
}

/// 640x480 green with a few red discs, for real models without a test image.
ImageRgb8 SyntheticImage() {
  ImageRgb8 image(640, 480);
  const std::array<std::array<int, 3>, 4> discs = {
      {{160, 160, 50}, {330, 220, 60}, {480, 150, 45}, {250, 360, 55}}};
  for (int v = 0; v < 480; ++v) {
    for (int u = 0; u < 640; ++u) {
      bool red = false;
      for (const auto& d : discs) red = red || std::hypot(u - d[0], v - d[1]) < d[2];
      image.at(u, v, 0) = red ? 210 : 60;
      image.at(u, v, 1) = red ? 40 : 140;
      image.at(u, v, 2) = red ? 30 : 50;
    }
  }
  return image;
}

using Factory = std::function<Result<std::unique_ptr<segmentation::Segmenter>>(int threads)>;

/// Times Segment; per-stage means and the instance count as counters.
void RunSegment(benchmark::State& state, const Factory& make, const RgbdFrame& frame,
                const std::string& prompt) {
  Result<std::unique_ptr<segmentation::Segmenter>> segmenter =
      make(static_cast<int>(state.range(0)));
  if (!segmenter.ok()) {
    state.SkipWithError(segmenter.status().ToString().c_str());
    return;
  }
  segmentation::SegmentationRequest request;
  request.frame = &frame;
  request.prompt = prompt;
  std::map<std::string, double> stage_ms;
  std::vector<std::string> order;
  size_t instances = 0;
  // One untimed call first: the sessions' first-run costs (allocations, kernel selection) are not
  // what a running system pays per image, and BM_Ywes measures with its phrases' embeddings
  // cached, as they are from the second image on.
  if (Result<Segmentation> warm = (*segmenter)->Segment(request); !warm.ok()) {
    state.SkipWithError(warm.status().ToString().c_str());
    return;
  }
  for (auto _ : state) {
    Result<Segmentation> seg = (*segmenter)->Segment(request);
    if (!seg.ok()) {
      state.SkipWithError(seg.status().ToString().c_str());
      return;
    }
    for (const StageTiming& t : seg->timings) {
      if (stage_ms.emplace(t.stage, 0.0).second) order.push_back(t.stage);
      stage_ms[t.stage] += t.ms;
    }
    instances = seg->instances.size();
  }
  const double n = static_cast<double>(state.iterations());
  for (const std::string& stage : order) state.counters[stage + "_ms"] = stage_ms[stage] / n;
  state.counters["threads"] = static_cast<double>(state.range(0));
  state.counters["instances"] = static_cast<double>(instances);
  state.SetLabel(fmt::format("{}x{} \"{}\"", frame.rgb.width(), frame.rgb.height(), prompt));
}

Device BenchDevice(bool stub) {
  if (stub) return Device::kCpu;
  Result<Device> d = DeviceFromEnvironment();
  return d.ok() ? *d : Device::kAuto;
}

/// `boxes` > 0: the `boxes` best-scoring anchors are the detections (YwesOptions::score_threshold
/// 0, nms_iou 1 = no suppression, max_detections `boxes`), so the SAM decoder runs on that many
/// boxes whatever the detector's weights: a random-weight detector scores every anchor near
/// sigmoid(-10), below the 0.002 default, and its boxes overlap so that NMS would keep only a few.
/// (A box entirely in the letterbox padding is dropped before the cut, as in any ywes run; a box
/// whose mask comes out empty gives no instance: `instances` <= `boxes`.)
Factory YwesFactory(const fs::path& dir, bool stub, size_t text_cache, int boxes = 0) {
  return [dir, stub, text_cache,
          boxes](int threads) -> Result<std::unique_ptr<segmentation::Segmenter>> {
    YwesOptions o;
    o.session.device = BenchDevice(stub);
    o.session.intra_op_threads = threads;
    o.text_cache_capacity = text_cache;
    if (boxes > 0) {
      o.score_threshold = 0.0f;
      o.nms_iou = 1.0f;
      o.max_detections = boxes;
    }
    AVP_ASSIGN_OR_RETURN(std::unique_ptr<YwesSegmenter> s, YwesSegmenter::Create(dir, o));
    return std::unique_ptr<segmentation::Segmenter>(std::move(s));
  };
}

Factory LsamFactory(const fs::path& dir, bool stub) {
  return [dir, stub](int threads) -> Result<std::unique_ptr<segmentation::Segmenter>> {
    LsamOptions o;
    o.session.device = BenchDevice(stub);
    o.session.intra_op_threads = threads;
    AVP_ASSIGN_OR_RETURN(std::unique_ptr<LsamSegmenter> s, LsamSegmenter::Create(dir, o));
    return std::unique_ptr<segmentation::Segmenter>(std::move(s));
  };
}

/// `min_time_s` > 0: at least that long per case (a real model runs ~1 s per image: without it
/// Google Benchmark stops after one iteration).
void Register(const std::string& name, Factory make, std::shared_ptr<const RgbdFrame> frame,
              std::string prompt, double min_time_s = 0.0) {
  benchmark::internal::Benchmark* b =
      benchmark::RegisterBenchmark(
          name.c_str(), [make = std::move(make), frame, prompt](
                            benchmark::State& state) { RunSegment(state, make, *frame, prompt); })
          ->ArgName("threads")
          ->Arg(1)
          ->Arg(2)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime();
  if (min_time_s > 0.0) b->MinTime(min_time_s);
}

/// Registers every case; false (after printing why) when the stubs cannot be made.
bool RegisterAll() {
  Result<fs::path> stubs = StubDir();
  if (!stubs.ok()) {
    std::fprintf(stderr, "bench_zsl: %s\n", stubs.status().ToString().c_str());
    return false;
  }
  const auto stub_frame = std::make_shared<const RgbdFrame>(FrameOf(StubImage()));
  Register("BM_Ywes/stub", YwesFactory(*stubs / "ywes", true, 1024), stub_frame, "a, b, c");
  Register("BM_YwesUncachedText/stub", YwesFactory(*stubs / "ywes", true, 0), stub_frame,
           "a, b, c");
  Register("BM_Lsam/stub", LsamFactory(*stubs / "lsam", true), stub_frame, "tomato, leaf, stem");

  if (std::optional<std::string> real = Env("AVP_ZSL_MODEL_DIR")) {
    ImageRgb8 image = SyntheticImage();
    if (std::optional<std::string> path = Env("AVP_ZSL_TEST_IMAGE")) {
      Result<ImageRgb8> read = io::ReadImageFile(*path);
      if (!read.ok()) {
        std::fprintf(stderr, "bench_zsl: %s\n", read.status().ToString().c_str());
        return false;
      }
      image = std::move(read).value();
    }
    const auto frame = std::make_shared<const RgbdFrame>(FrameOf(std::move(image)));
    const std::string prompt = Env("AVP_ZSL_TEST_PROMPT").value_or("tomato");
    Register("BM_Ywes/real", YwesFactory(*real, false, 1024), frame, prompt, 8.0);
    Register("BM_YwesUncachedText/real", YwesFactory(*real, false, 0), frame, prompt, 8.0);
    // AVP_ZSL_BENCH_BOXES=K[,K...]: BM_Ywes/real_boxes:K, the pipeline with K detections.
    if (std::optional<std::string> list = Env("AVP_ZSL_BENCH_BOXES")) {
      // Each item is a case of at least 2 x 8 s: a few are a sweep, more is a mistake.
      constexpr size_t kMaxBoxCases = 16;
      const std::vector<std::string> items = options_internal::SplitList(*list);
      if (items.size() > kMaxBoxCases) {
        std::fprintf(stderr, "bench_zsl: AVP_ZSL_BENCH_BOXES lists %zu box counts; at most %zu\n",
                     items.size(), kMaxBoxCases);
        return false;
      }
      for (const std::string& item : items) {
        const std::optional<int64_t> k = options_internal::ParseInteger(item);
        if (!k || *k < 1 || *k > 300) {
          std::fprintf(stderr, "bench_zsl: AVP_ZSL_BENCH_BOXES item '%s' must be in [1, 300]\n",
                       item.c_str());
          return false;
        }
        Register(fmt::format("BM_Ywes/real_boxes:{}", *k),
                 YwesFactory(*real, false, 1024, static_cast<int>(*k)), frame, prompt, 8.0);
      }
    }
    Register("BM_Lsam/real", LsamFactory(*real, false), frame, prompt, 8.0);
  } else {
    std::fprintf(stderr,
                 "bench_zsl: AVP_ZSL_MODEL_DIR is not set: stub models only (set it to a model "
                 "directory, docs/zero-shot-models.md, to time real exports)\n");
  }
  return true;
}

/// --serve-clients: see the top of the file.
int ServeClients(double seconds, const std::string& json_path) {
  Result<fs::path> stubs = StubDir(true);
  if (!stubs.ok()) {
    std::fprintf(stderr, "bench_zsl: %s\n", stubs.status().ToString().c_str());
    return 1;
  }
  std::vector<bench::BenchRecord> records;
  std::printf(
      "serve clients: text model of ywes_heavy_text ([1, 77] -> [1, 512], ~0.6 GMAC), 16 gRPC "
      "threads; unbatched: 1 ORT thread per run, runs side by side; batched_RxT: R batches at "
      "once of T ORT threads each; %.0f s each\n",
      seconds);
  // (batched, batches run at once, ORT threads per run): both cores busy either way.
  const std::vector<std::tuple<bool, int, int>> modes = {{false, 0, 1}, {true, 2, 1}, {true, 1, 2}};
  for (const auto& [batched, instances, ort_threads] : modes) {
    ModelServiceOptions o;
    o.server.port = 0;
    o.server.threads = 16;
    o.runtime.intra_op_threads = ort_threads;
    o.runtime.device = Device::kCpu;
    if (batched) {
      o.server.batching.max_batch = 16;
      o.server.batching.max_delay = std::chrono::microseconds(2000);
      o.server.batching.instances = instances;
    }
    Result<ModelService> service = ServeModels(*stubs / "ywes_heavy_text", o);
    if (!service.ok()) {
      std::fprintf(stderr, "bench_zsl: %s\n", service.status().ToString().c_str());
      return 1;
    }
    const std::string mode =
        batched ? fmt::format("batched_{}x{}", instances, ort_threads) : "unbatched";
    std::printf("  %s (%s)\n", mode.c_str(), service->server->batching().at("text").c_str());
    for (const int clients : {1, 4, 16}) {
      const segmentation_service::TensorServerStats before = service->server->stats();
      const std::string address = service->server->address();
      const bench::ClientLoad load = bench::RunClientLoad(clients, seconds, [&](int c) {
        segmentation_service::TensorClientOptions co;
        co.address = address;
        co.model = "text";
        std::shared_ptr<segmentation_service::TensorClient> client;
        if (Result<std::unique_ptr<segmentation_service::TensorClient>> made =
                segmentation_service::TensorClient::Create(co);
            made.ok()) {
          client = std::move(made).value();
        }
        auto state =
            std::make_shared<uint64_t>(0x9E3779B97F4A7C15ull * static_cast<uint64_t>(c + 1));
        return [client, state](std::string& error) {
          if (client == nullptr) {
            error = "no client";
            return false;
          }
          std::vector<int64_t> ids(77, 0);
          for (int64_t& id : ids) {
            *state = *state * 6364136223846793005ull + 1442695040888963407ull;
            id = static_cast<int64_t>((*state >> 33) % 49408);
          }
          segmentation_service::InferRequest request;
          request.inputs.push_back(segmentation_service::MakeTensor<int64_t>(
              "input_ids", segmentation_service::DataType::kInt64, {1, 77},
              std::span<const int64_t>(ids)));
          const Result<segmentation_service::InferResponse> out = client->Infer(std::move(request));
          if (!out.ok()) error = out.status().ToString();
          return out.ok();
        };
      });
      double per_run = 1.0;
      if (batched) {
        const segmentation_service::BatchingStats& b0 = before.batching.at("text");
        const segmentation_service::BatchingStats b1 = service->server->stats().batching.at("text");
        per_run = b1.batches > b0.batches ? static_cast<double>(b1.requests - b0.requests) /
                                                static_cast<double>(b1.batches - b0.batches)
                                          : 0.0;
      }
      std::printf(
          "    %2d clients: %6.1f requests/s, p50 %7.1f ms, p99 %7.1f ms, %.2f requests per "
          "run, %llu errors\n",
          clients, load.requests_per_s, load.p50_ms, load.p99_ms, per_run,
          static_cast<unsigned long long>(load.errors));
      if (!load.first_error.empty()) {
        std::printf("      first error: %s\n", load.first_error.c_str());
      }
      const std::string name = fmt::format("serve/{}/clients/{}", mode, clients);
      for (bench::BenchRecord& r : bench::ClientLoadRecords(name, load)) {
        records.push_back(std::move(r));
      }
      records.push_back(bench::MakeRecord(name + "/requests_per_run", per_run, ""));
    }
    service->server->Shutdown(std::chrono::seconds(2));
  }
  if (!json_path.empty() && !bench::WriteBenchRecords(json_path, records)) return 1;
  return 0;
}

}  // namespace
}  // namespace avp::zsl

int main(int argc, char** argv) {
  bool serve = false;
  double seconds = 5.0;
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--serve-clients") {
      serve = true;
    } else if (arg.rfind("--seconds=", 0) == 0) {
      seconds = std::stod(arg.substr(10));
    } else {
      argv[kept++] = argv[i];
    }
  }
  argc = kept;
  if (serve) {
    const std::string json = avp::bench::TakeJsonPathArgument(argc, argv);
    return avp::zsl::ServeClients(seconds, json);
  }
  if (!avp::zsl::RegisterAll()) return 1;
  // No targets: design §5 gives estimates only (YWES S + L0 ≈ 0.7–1.3 s per image on 2 cores).
  return avp::bench::GoogleBenchmarkMain(argc, argv, {});
}

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
//          the device of AVP_ZSL_DEVICE.
// Cases: BM_Ywes/<models>/threads:N (the text embeddings cached after the first call, as in a
// running system), BM_YwesUncachedText/<models>/threads:N (text model every call), and
// BM_Lsam/<models>/threads:N. Prompts for the stubs: "a, b, c" (three planted boxes) and
// "tomato, leaf, stem".
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <fmt/format.h>
#include <unistd.h>

#include <avp/core/camera.h>
#include <avp/core/rgbd_frame.h>
#include <avp/io/image_codec.h>
#include <avp/segmentation/segmenter.h>
#include <avp/zsl/lsam_segmenter.h>
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
Result<fs::path> StubDir() {
  if (std::optional<std::string> dir = Env("AVP_ZSL_STUB_DIR")) return fs::path(*dir);
  static fs::path temp;
  temp = fs::temp_directory_path() / fmt::format("avp_bench_zsl_{}", ::getpid());
  const std::string command =
      fmt::format("/usr/bin/python3 '{}' '{}' --clip-merges '{}' > /dev/null", AVP_ZSL_MAKE_STUBS,
                  temp.string(), AVP_ZSL_CLIP_MERGES);
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

Factory YwesFactory(const fs::path& dir, bool stub, size_t text_cache) {
  return [dir, stub, text_cache](int threads) -> Result<std::unique_ptr<segmentation::Segmenter>> {
    YwesOptions o;
    o.session.device = BenchDevice(stub);
    o.session.intra_op_threads = threads;
    o.text_cache_capacity = text_cache;
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

void Register(const std::string& name, Factory make, std::shared_ptr<const RgbdFrame> frame,
              std::string prompt) {
  benchmark::RegisterBenchmark(name.c_str(),
                               [make = std::move(make), frame, prompt](benchmark::State& state) {
                                 RunSegment(state, make, *frame, prompt);
                               })
      ->ArgName("threads")
      ->Arg(1)
      ->Arg(2)
      ->Unit(benchmark::kMillisecond)
      ->UseRealTime();
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
    Register("BM_Ywes/real", YwesFactory(*real, false, 1024), frame, prompt);
    Register("BM_YwesUncachedText/real", YwesFactory(*real, false, 0), frame, prompt);
    Register("BM_Lsam/real", LsamFactory(*real, false), frame, prompt);
  } else {
    std::fprintf(stderr,
                 "bench_zsl: AVP_ZSL_MODEL_DIR is not set: stub models only (set it to a model "
                 "directory, docs/zero-shot-models.md, to time real exports)\n");
  }
  return true;
}

}  // namespace
}  // namespace avp::zsl

int main(int argc, char** argv) {
  if (!avp::zsl::RegisterAll()) return 1;
  // No targets: design §5 gives estimates only (YWES S + L0 ≈ 0.7–1.3 s per image on 2 cores).
  return avp::bench::GoogleBenchmarkMain(argc, argv, {});
}

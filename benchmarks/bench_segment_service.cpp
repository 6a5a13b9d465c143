// Round-trip cost of the segmentation service (KServe v2 over gRPC, docs/segmentation-service.md)
// against the same segmenter in-process, on the default scenario's 640 x 480 start view with its
// simulator labels.
//
// Cases (wall-clock time per frame):
//   BM_InProcess/<backend>            Segment() on a segmenter in this process
//   BM_Remote/<backend>/<image>       RemoteSegmenter -> SegmentationServer on 127.0.0.1 (same
//                                     process, real sockets): encode, send, decode, segment,
//                                     encode, send back, decode; image = raw RGB or PNG
// Backends: oracle (reads the labels, which cross the wire too) and color (HSV thresholds).
// The service overhead is BM_Remote - BM_InProcess of the same backend; counters give the
// request and response payload in MB.

#include <memory>
#include <string>

#include <benchmark/benchmark.h>

#include <avp/interop/remote_segmenter.h>
#include <avp/interop/segmentation_codec.h>
#include <avp/interop/segmentation_server.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

#include "bench_report.h"

namespace avp::interop {
namespace {

/// The built-in segmenters the benchmark serves and compares against (never freed: the server
/// outlives the benchmarks).
const segmentation::SegmenterRegistry& Segmenters() {
  static const auto* registry =
      new segmentation::SegmenterRegistry(segmentation::BuiltinSegmenters());
  return *registry;
}

struct Frame {
  RgbdFrame frame;
  SimulatorLabels labels;
};

const Frame& TheFrame() {
  static const Frame* frame = [] {
    auto* f = new Frame;
    Result<sim::Scene> scene = sim::MakeScenario(sim::DefaultScenarioName(), 3);
    if (!scene.ok()) throw Error(scene.status().ToString());
    const sim::RgbdRenderer renderer(*scene);
    sim::RenderedFrame r = renderer.Render(CameraIntrinsics::RealSenseD435(), scene->X_WC_start);
    f->frame = std::move(r.rgbd);
    f->labels.instance_ids = std::move(r.instance_ids);
    f->labels.class_ids = std::move(r.class_ids);
    for (const sim::FruitTruth& fruit : scene->Fruits()) {
      f->labels.fruits.push_back({fruit.instance_id, fruit.center_W, fruit.mean_radius_m()});
    }
    return f;
  }();
  return *frame;
}

segmentation::SegmentationRequest Request(uint64_t index) {
  segmentation::SegmentationRequest r;
  r.frame = &TheFrame().frame;
  r.labels = &TheFrame().labels;
  r.prompt = "tomato";
  r.frame_index = index;
  return r;
}

SegmentationServer& TheServer() {
  static SegmentationServer* server = [] {
    ServerOptions o;
    o.segmenters = &Segmenters();
    o.host = "127.0.0.1";
    o.port = 0;
    o.backends = {"oracle", "color"};
    o.threads = 2;
    Result<std::unique_ptr<SegmentationServer>> s = SegmentationServer::Start(o);
    if (!s.ok()) throw Error(s.status().ToString());
    return s->release();
  }();
  return *server;
}

void BM_InProcess(benchmark::State& state, const std::string& backend) {
  auto seg = Segmenters().Make(backend, 7);
  if (!seg.ok()) {
    state.SkipWithError(seg.status().ToString().c_str());
    return;
  }
  uint64_t i = 0;
  for (auto _ : state) {
    Result<Segmentation> out = (*seg)->Segment(Request(i++ % 8));
    if (!out.ok()) {
      state.SkipWithError(out.status().ToString().c_str());
      return;
    }
    benchmark::DoNotOptimize(out->instances.size());
  }
}

void BM_Remote(benchmark::State& state, const std::string& backend, ImageEncoding image) {
  RemoteOptions o;
  o.host = "127.0.0.1";
  o.port = TheServer().port();
  o.model = backend;
  o.seed = 7;
  o.image = image;
  RemoteSegmenter remote(o);
  // Payload sizes of one request and its answer, as the codec builds them.
  RequestEncodeOptions eo;
  eo.model_name = backend;
  eo.seed = 7;
  eo.image = image;
  Result<InferRequest> req = EncodeSegmentationRequest(Request(0), eo);
  double request_mb = 0.0;
  if (req.ok()) {
    for (const Tensor& t : req->inputs) request_mb += static_cast<double>(t.data.size()) / 1e6;
  }
  uint64_t i = 0;
  size_t response_bytes = 0;
  for (auto _ : state) {
    Result<Segmentation> out = remote.Segment(Request(i++ % 8));
    if (!out.ok()) {
      state.SkipWithError(out.status().ToString().c_str());
      return;
    }
    response_bytes = 0;
    for (const InstanceMask& m : out->instances) response_bytes += m.mask.data().size();
    benchmark::DoNotOptimize(out->instances.size());
  }
  state.counters["request_MB"] = request_mb;
  state.counters["mask_MB"] = static_cast<double>(response_bytes) / 1e6;
}

BENCHMARK_CAPTURE(BM_InProcess, oracle, std::string("oracle"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_InProcess, color, std::string("color"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Remote, oracle / raw, std::string("oracle"), ImageEncoding::kRaw)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Remote, oracle / png, std::string("oracle"), ImageEncoding::kPng)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Remote, color / raw, std::string("color"), ImageEncoding::kRaw)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace avp::interop

int main(int argc, char** argv) { return avp::bench::GoogleBenchmarkMain(argc, argv, {}); }

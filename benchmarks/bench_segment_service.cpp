// Round-trip cost of the segmentation service (KServe v2 over gRPC, docs/segmentation-service.md)
// against the same segmenter in-process, on the default scenario's 640 x 480 start view with its
// simulator labels; and, with --mixed-load, the service under valid and hostile clients at once.
//
// Cases (wall-clock time per frame):
//   BM_InProcess/<backend>            Segment() on a segmenter in this process
//   BM_Remote/<backend>/<image>[/<masks>] RemoteSegmenter -> SegmentationServer on 127.0.0.1
//                                     (same process, real sockets): encode, send, decode,
//                                     segment, encode, send back, decode; image = raw RGB or PNG;
//                                     masks RLE (the client's default), dense or instance_ids
// Backends: oracle (reads the labels, which cross the wire too) and color (HSV thresholds).
// The service overhead is BM_Remote - BM_InProcess of the same backend; counters give the
// request and answer payload in MB (answer_MB: the answer's tensors in that mask format).
//
// --clients [--seconds=S] (instead of the cases above): 1, 4 and 16 concurrent clients against a
// server with 4 workers: requests per second, p50 and p99 latency.
//
// --mixed-load [--seconds=S] (instead of the cases above): a server with its default limits and
// 2 workers; 4 valid clients (one connection each, one request at a time, the oracle on the 320 x
// 240 start view) for S seconds alone ("idle"), then S seconds together with hostile clients:
// requests declaring a 20000 x 20000 image, 100 000-phrase prompts, a flood of 24 threads on one
// connection (far beyond the queue), and clients that leave 5 ms after sending. Reports the valid
// clients' p50 / p99 idle and under attack, each hostile kind's outcomes (gRPC status counts) and
// the process's RSS (server and clients: /proc/self/status VmRSS) over time.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include <benchmark/benchmark.h>
#include <fmt/format.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include <avp/core/limits.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/segmentation_service/remote_segmenter.h>
#include <avp/segmentation_service/segmentation_codec.h>
#include <avp/segmentation_service/segmentation_server.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

#include "bench_report.h"

namespace avp::segmentation_service {
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

/// The default scenario's start view at the D435's intrinsics scaled by `scale`, with its labels.
Frame* RenderStartView(double scale) {
  auto* f = new Frame;
  Result<sim::Scene> scene = sim::MakeScenario(sim::DefaultScenarioName(), 3);
  if (!scene.ok()) throw Error(scene.status().ToString());
  const sim::RgbdRenderer renderer(*scene);
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  sim::RenderedFrame r = renderer.Render(scale == 1.0 ? K : K.Scaled(scale), scene->X_WC_start);
  f->frame = std::move(r.rgbd);
  f->labels.instance_ids = std::move(r.instance_ids);
  f->labels.class_ids = std::move(r.class_ids);
  for (const sim::FruitTruth& fruit : scene->Fruits()) {
    f->labels.fruits.push_back({fruit.instance_id, fruit.center_W, fruit.mean_radius_m()});
  }
  return f;
}

const Frame& TheFrame() {
  static const Frame* frame = RenderStartView(1.0);
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

void BM_Remote(benchmark::State& state, const std::string& backend, ImageEncoding image,
               MaskFormat masks) {
  RemoteOptions o;
  o.host = "127.0.0.1";
  o.port = TheServer().port();
  o.model = backend;
  o.seed = 7;
  o.image = image;
  o.mask_format = masks;
  RemoteSegmenter remote(o);
  // The answer's tensor bytes in this mask format (the same segmentation, encoded as the server
  // does).
  double answer_mb = 0.0;
  if (auto local = Segmenters().Make(backend, 7); local.ok()) {
    if (Result<Segmentation> seg = (*local)->Segment(Request(0)); seg.ok()) {
      if (Result<InferResponse> a = EncodeSegmentation(*seg, masks); a.ok()) {
        for (const Tensor& t : a->outputs) answer_mb += static_cast<double>(t.data.size()) / 1e6;
      }
    }
  }
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
  state.counters["answer_MB"] = answer_mb;
  state.counters["mask_MB"] = static_cast<double>(response_bytes) / 1e6;
}

BENCHMARK_CAPTURE(BM_InProcess, oracle, std::string("oracle"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_InProcess, color, std::string("color"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Remote, oracle / raw, std::string("oracle"), ImageEncoding::kRaw,
                  MaskFormat::kRle)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Remote, oracle / raw / dense_masks, std::string("oracle"), ImageEncoding::kRaw,
                  MaskFormat::kDense)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Remote, oracle / raw / instance_ids, std::string("oracle"),
                  ImageEncoding::kRaw, MaskFormat::kInstanceIds)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Remote, oracle / png, std::string("oracle"), ImageEncoding::kPng,
                  MaskFormat::kRle)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Remote, color / raw, std::string("color"), ImageEncoding::kRaw,
                  MaskFormat::kRle)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// ---- --mixed-load -------------------------------------------------------------------------------

using Clock = std::chrono::steady_clock;

/// VmRSS of this process, MB.
double RssMb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  }
  return 0.0;
}

/// Minimal protobuf writer for hostile ModelInferRequests (no generated code here).
struct ProtoWriter {
  std::string out;
  void Varint(uint64_t v) {
    while (v >= 0x80) {
      out.push_back(static_cast<char>((v & 0x7f) | 0x80));
      v >>= 7;
    }
    out.push_back(static_cast<char>(v));
  }
  void Bytes(int field, std::string_view b) {
    Varint((static_cast<uint64_t>(field) << 3) | 2);
    Varint(b.size());
    out.append(b);
  }
};

/// An InferInputTensor message.
std::string InputTensor(std::string_view name, std::string_view datatype,
                        const std::vector<int64_t>& shape) {
  ProtoWriter w;
  w.Bytes(1, name);
  w.Bytes(2, datatype);
  ProtoWriter dims;
  for (const int64_t d : shape) dims.Varint(static_cast<uint64_t>(d));
  w.Bytes(3, dims.out);
  return w.out;
}

/// A ModelInferRequest for `model` with inputs (name, datatype, shape, raw contents).
std::string InferRequestBytes(
    std::string_view model,
    const std::vector<std::tuple<std::string, std::string, std::vector<int64_t>, std::string>>&
        inputs) {
  ProtoWriter w;
  w.Bytes(1, model);
  for (const auto& [name, datatype, shape, raw] : inputs) {
    w.Bytes(5, InputTensor(name, datatype, shape));
  }
  for (const auto& input : inputs) w.Bytes(7, std::get<3>(input));
  return w.out;
}

std::string BytesElement(std::string_view e) {
  std::string out;
  const auto n = static_cast<uint32_t>(e.size());
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((n >> (8 * i)) & 0xff));
  out.append(e);
  return out;
}

/// A PNG signature and IHDR declaring w x h, no pixels.
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

/// Sends raw request bytes on its own connection and returns the gRPC status code.
class RawClient {
 public:
  explicit RawClient(int port) {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(64 << 20);
    args.SetMaxSendMessageSize(64 << 20);
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    stub_ = std::make_unique<grpc::GenericStub>(grpc::CreateCustomChannel(
        fmt::format("127.0.0.1:{}", port), grpc::InsecureChannelCredentials(), args));
  }
  grpc::StatusCode Call(const std::string& request, double deadline_s = 10.0) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::microseconds(static_cast<int64_t>(deadline_s * 1e6)));
    grpc::Slice slice(request);
    const grpc::ByteBuffer send(&slice, 1);
    grpc::ByteBuffer receive;
    std::mutex m;
    std::condition_variable cv;
    bool done = false;
    grpc::Status status;
    stub_->UnaryCall(&context, "/inference.GRPCInferenceService/ModelInfer", grpc::StubOptions(),
                     &send, &receive, [&](grpc::Status s) {
                       std::lock_guard lock(m);
                       status = std::move(s);
                       done = true;
                       cv.notify_all();
                     });
    std::unique_lock lock(m);
    cv.wait(lock, [&] { return done; });
    return status.error_code();
  }

 private:
  std::unique_ptr<grpc::GenericStub> stub_;
};

/// Outcomes of one hostile kind: gRPC status code -> count.
struct Outcomes {
  std::mutex mutex;
  std::map<std::string, uint64_t> counts;
  void Add(const std::string& code) {
    std::lock_guard lock(mutex);
    ++counts[code];
  }
  std::string Describe() {
    std::lock_guard lock(mutex);
    std::string out;
    for (const auto& [code, n] : counts)
      out += fmt::format("{}{} {}", out.empty() ? "" : ", ", n, code);
    return out;
  }
  uint64_t Total() {
    std::lock_guard lock(mutex);
    uint64_t n = 0;
    for (const auto& [code, c] : counts) n += c;
    return n;
  }
  uint64_t Count(const std::string& code) {
    std::lock_guard lock(mutex);
    return counts.count(code) ? counts[code] : 0;
  }
};

std::string CodeName(grpc::StatusCode c) {
  switch (c) {
    case grpc::StatusCode::OK:
      return "OK";
    case grpc::StatusCode::CANCELLED:
      return "CANCELLED";
    case grpc::StatusCode::INVALID_ARGUMENT:
      return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::UNAVAILABLE:
      return "UNAVAILABLE";
    default:
      return fmt::format("code {}", static_cast<int>(c));
  }
}

using bench::Percentile;

/// The start view at half resolution (320 x 240), for the mixed-load clients.
const Frame& SmallFrame() {
  static const Frame* frame = RenderStartView(0.5);
  return *frame;
}

segmentation::SegmentationRequest SmallRequest(uint64_t index, std::string prompt = "tomato") {
  segmentation::SegmentationRequest r;
  r.frame = &SmallFrame().frame;
  r.labels = &SmallFrame().labels;
  r.prompt = std::move(prompt);
  r.frame_index = index;
  return r;
}

/// The bytes of a ModelInferRequest for `r` (raw contents; no parameters: the server's seed).
std::string EncodedRequestBytes(const segmentation::SegmentationRequest& r) {
  RequestEncodeOptions eo;
  eo.model_name = "oracle";
  Result<InferRequest> req = EncodeSegmentationRequest(r, eo);
  if (!req.ok()) throw Error(req.status().ToString());
  std::vector<std::tuple<std::string, std::string, std::vector<int64_t>, std::string>> inputs;
  for (const Tensor& t : req->inputs) {
    inputs.emplace_back(t.name, std::string(ToString(t.datatype)), t.shape, t.data);
  }
  return InferRequestBytes("oracle", inputs);
}

/// --clients: 1, 4 and 16 clients (one connection each, one request at a time, the oracle on the
/// 640 x 480 start view, RLE masks) against a server with `threads` workers, `seconds` each:
/// requests per second and the p50 / p99 latency.
int Clients(double seconds, const std::string& json_path) {
  const int threads = 4;
  ServerOptions so;
  so.segmenters = &Segmenters();
  so.host = "127.0.0.1";
  so.port = 0;
  so.backends = {"oracle"};
  so.threads = threads;
  so.max_queued_per_client = 4;
  so.max_running_per_client = threads;
  Result<std::unique_ptr<SegmentationServer>> started = SegmentationServer::Start(so);
  if (!started.ok()) {
    std::fprintf(stderr, "%s\n", started.status().ToString().c_str());
    return 1;
  }
  (void)TheFrame();
  std::vector<bench::BenchRecord> records;
  std::printf(
      "clients: the oracle on the 640 x 480 start view, RLE masks, %d server workers, %.0f s "
      "each\n",
      threads, seconds);
  for (const int clients : {1, 4, 16}) {
    const bench::ClientLoad load = bench::RunClientLoad(clients, seconds, [&](int c) {
      RemoteOptions o;
      o.host = "127.0.0.1";
      o.port = (*started)->port();
      o.model = "oracle";
      o.seed = 7;
      auto remote = std::make_shared<RemoteSegmenter>(o);
      auto i = std::make_shared<uint64_t>(static_cast<uint64_t>(c));
      return [remote, i](std::string& error) {
        const Result<Segmentation> out = remote->Segment(Request((*i)++ % 8));
        if (!out.ok()) error = out.status().ToString();
        return out.ok();
      };
    });
    std::printf("  %2d clients: %6.1f requests/s, p50 %6.1f ms, p99 %6.1f ms, %llu errors\n",
                clients, load.requests_per_s, load.p50_ms, load.p99_ms,
                static_cast<unsigned long long>(load.errors));
    for (bench::BenchRecord& r :
         bench::ClientLoadRecords(fmt::format("clients/{}", clients), load)) {
      records.push_back(std::move(r));
    }
  }
  (*started)->Shutdown(std::chrono::seconds(2));
  if (!json_path.empty() && !bench::WriteBenchRecords(json_path, records)) return 1;
  return 0;
}

/// What the valid clients of MixedLoad measure: latencies idle and under attack, errors.
struct ValidClients {
  std::atomic<bool> attack{false}, stop{false};
  std::mutex lat_mutex;
  std::vector<double> idle_ms, attack_ms;
  std::atomic<uint64_t> valid_errors{0};
  std::string first_valid_error;
};

/// What the hostile clients of MixedLoad got back.
struct HostileOutcomes {
  Outcomes huge_image, huge_prompt, flood, leaving;
};

/// `count` valid clients, each one request at a time until `v.stop`: the latency of every answer
/// that did not straddle the switch to the attack, as idle or under attack.
std::vector<std::thread> StartValidClients(int port, int count, ValidClients& v) {
  std::vector<std::thread> valid;
  for (int c = 0; c < count; ++c) {
    valid.emplace_back([&v, port, c] {
      RemoteOptions o;
      o.port = port;
      o.seed = 7;
      o.deadline_s = 30;
      RemoteSegmenter client(o);
      uint64_t i = static_cast<uint64_t>(c) * 1000;
      while (!v.stop.load()) {
        const bool under_attack = v.attack.load();
        const Clock::time_point a = Clock::now();
        Result<Segmentation> r = client.Segment(SmallRequest(i++ % 8));
        const double ms = std::chrono::duration<double, std::milli>(Clock::now() - a).count();
        if (!r.ok()) {
          if (v.valid_errors.fetch_add(1) == 0) {
            std::lock_guard lock(v.lat_mutex);
            v.first_valid_error = r.status().ToString();
          }
          continue;
        }
        if (under_attack != v.attack.load()) continue;  // straddles the switch: not counted
        std::lock_guard lock(v.lat_mutex);
        (under_attack ? v.attack_ms : v.idle_ms).push_back(ms);
      }
    });
  }
  return valid;
}

/// The attack, until `stop`: requests declaring 20000 x 20000 pixels (a PNG header alone, and a
/// raw rgb shape alone); 100 000-phrase prompts (800 KB each) with the real frame; a flood of 24
/// threads on one connection, each sending again as soon as it has an answer (10 ms after a
/// refusal); clients that leave 5 ms after sending (their requests are queued or running when
/// they go). Requests are encoded once: the clients' own encoding is not what is measured.
std::vector<std::thread> StartHostileClients(int port, const std::atomic<bool>& stop,
                                             HostileOutcomes& out) {
  std::vector<std::thread> hostile;
  for (int k = 0; k < 2; ++k) {
    hostile.emplace_back([&stop, &out, port, k] {
      RawClient client(port);
      const std::string prompt = BytesElement("tomato");
      const std::string request =
          k == 0 ? InferRequestBytes(
                       "oracle", {{"image", "BYTES", {1}, BytesElement(PngHeader(20000, 20000))},
                                  {"prompt", "BYTES", {1}, prompt}})
                 : InferRequestBytes("oracle", {{"rgb", "UINT8", {20000, 20000, 3}, ""},
                                                {"prompt", "BYTES", {1}, prompt}});
      while (!stop.load()) {
        out.huge_image.Add(CodeName(client.Call(request)));
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
    });
  }
  std::string phrases = "tomato";
  for (int i = 1; i < 100000; ++i) phrases += ", tomato";
  auto prompt_request = std::make_shared<const std::string>([&] {
    // The client would refuse it (SplitPrompt's limits): encode it past them, for the server to
    // refuse.
    const ScopedLimit bytes(segmentation::MaxPromptBytes(), 1u << 20);
    const ScopedLimit count(segmentation::MaxPromptPhrases(), 1u << 20);
    return EncodedRequestBytes(SmallRequest(0, phrases));
  }());
  auto valid_request = std::make_shared<const std::string>(EncodedRequestBytes(SmallRequest(1)));
  hostile.emplace_back([&stop, &out, port, prompt_request] {
    RawClient client(port);
    while (!stop.load()) {
      out.huge_prompt.Add(CodeName(client.Call(*prompt_request)));
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  auto flood_client = std::make_shared<RawClient>(port);
  for (int t = 0; t < 24; ++t) {
    hostile.emplace_back([&stop, &out, flood_client, valid_request] {
      while (!stop.load()) {
        const grpc::StatusCode code = flood_client->Call(*valid_request);
        out.flood.Add(CodeName(code));
        if (code != grpc::StatusCode::OK)
          std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
    });
  }
  for (int t = 0; t < 2; ++t) {
    hostile.emplace_back([&stop, &out, port, valid_request] {
      RawClient client(port);
      while (!stop.load()) {
        out.leaving.Add(CodeName(client.Call(*valid_request, 0.005)));
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
    });
  }
  return hostile;
}

/// RSS in MB over the run: (seconds since the start, MB) samples, their maxima idle and under
/// attack, and the values at the end of each phase.
struct RssTrace {
  std::vector<std::pair<double, double>> samples;
  double idle_end = 0.0, attack_end = 0.0, idle_max = 0.0, attack_max = 0.0;
};

void PrintMixedLoad(double seconds, ValidClients& v, HostileOutcomes& h, const RssTrace& rss,
                    const ServerStats& stats) {
  const double p50_idle = Percentile(v.idle_ms, 0.50), p99_idle = Percentile(v.idle_ms, 0.99);
  const double p50_attack = Percentile(v.attack_ms, 0.50);
  const double p99_attack = Percentile(v.attack_ms, 0.99);
  std::printf(
      "mixed load: 4 valid clients (oracle, 320 x 240, one request at a time), %.0f s idle "
      "then %.0f s under attack; server: 2 workers, default limits\n",
      seconds, seconds);
  std::printf("  valid, idle:         %zu requests, p50 %.1f ms, p99 %.1f ms\n", v.idle_ms.size(),
              p50_idle, p99_idle);
  std::printf("  valid, under attack: %zu requests, p50 %.1f ms, p99 %.1f ms (p99 %.2fx idle)\n",
              v.attack_ms.size(), p50_attack, p99_attack, p99_attack / std::max(p99_idle, 1e-9));
  std::printf("  valid errors: %llu%s%s\n", static_cast<unsigned long long>(v.valid_errors.load()),
              v.first_valid_error.empty() ? "" : ", first: ", v.first_valid_error.c_str());
  std::printf("  hostile, 20000 x 20000 declared: %s\n", h.huge_image.Describe().c_str());
  std::printf("  hostile, 100000-phrase prompt:   %s\n", h.huge_prompt.Describe().c_str());
  std::printf("  hostile, flood (24 in flight):   %s\n", h.flood.Describe().c_str());
  std::printf("  hostile, leave after 5 ms:       %s\n", h.leaving.Describe().c_str());
  std::printf(
      "  server: %llu answered, %llu refused (%llu over budget, %llu queue full, %llu "
      "expired in the queue, %llu stopped while running)\n",
      static_cast<unsigned long long>(stats.infer_ok),
      static_cast<unsigned long long>(stats.infer_failed),
      static_cast<unsigned long long>(stats.infer_over_budget),
      static_cast<unsigned long long>(stats.infer_queue_full),
      static_cast<unsigned long long>(stats.infer_expired),
      static_cast<unsigned long long>(stats.infer_interrupted));
  std::printf(
      "  RSS: %.0f MB at the end of idle (max %.0f), max %.0f MB under attack, %.0f MB "
      "at its end\n",
      rss.idle_end, rss.idle_max, rss.attack_max, rss.attack_end);
  std::printf("  RSS over time (s: MB):");
  for (size_t i = 0; i < rss.samples.size(); i += 10)
    std::printf(" %.0f:%.0f", rss.samples[i].first, rss.samples[i].second);
  std::printf("\n");
}

std::vector<bench::BenchRecord> MixedLoadRecords(ValidClients& v, HostileOutcomes& h,
                                                 const RssTrace& rss) {
  const double p50_idle = Percentile(v.idle_ms, 0.50), p99_idle = Percentile(v.idle_ms, 0.99);
  const double p50_attack = Percentile(v.attack_ms, 0.50);
  const double p99_attack = Percentile(v.attack_ms, 0.99);
  std::vector<bench::BenchRecord> records;
  records.push_back(bench::MakeRecord("mixed/valid_p50_idle", p50_idle, "ms"));
  records.push_back(bench::MakeRecord("mixed/valid_p99_idle", p99_idle, "ms"));
  records.push_back(bench::MakeRecord("mixed/valid_p50_attack", p50_attack, "ms", "idle", p50_idle,
                                      p50_idle / std::max(p50_attack, 1e-9)));
  records.push_back(bench::MakeRecord("mixed/valid_p99_attack", p99_attack, "ms", "idle", p99_idle,
                                      p99_idle / std::max(p99_attack, 1e-9), ">=0.5x"));
  records.push_back(bench::MakeRecord("mixed/valid_errors", static_cast<double>(v.valid_errors),
                                      "requests", std::nullopt, std::nullopt, std::nullopt, "<=0"));
  const auto refused_pct = [](Outcomes& o) {
    const uint64_t total = o.Total();
    return total == 0 ? 0.0
                      : 100.0 * static_cast<double>(o.Count("RESOURCE_EXHAUSTED")) /
                            static_cast<double>(total);
  };
  records.push_back(bench::MakeRecord("mixed/huge_image_refused", refused_pct(h.huge_image), "%",
                                      std::nullopt, std::nullopt, std::nullopt, ">=100"));
  records.push_back(bench::MakeRecord("mixed/huge_prompt_refused", refused_pct(h.huge_prompt), "%",
                                      std::nullopt, std::nullopt, std::nullopt, ">=100"));
  records.push_back(bench::MakeRecord("mixed/flood_refused", refused_pct(h.flood), "%"));
  records.push_back(bench::MakeRecord("mixed/rss_max_idle", rss.idle_max, "MB"));
  records.push_back(bench::MakeRecord("mixed/rss_max_attack", rss.attack_max, "MB", "idle",
                                      rss.idle_max, rss.idle_max / std::max(rss.attack_max, 1e-9),
                                      ">=0.5x"));
  return records;
}

/// --mixed: 4 valid clients against a server of 2 workers, `seconds` idle, then `seconds` under
/// the attack of StartHostileClients: the valid clients' latency, what the hostile ones got, the
/// server's counters and its RSS over time.
int MixedLoad(double seconds, const std::string& json_path) {
  ServerOptions so;
  so.segmenters = &Segmenters();
  so.host = "127.0.0.1";
  so.port = 0;
  so.backends = {"oracle"};
  so.threads = 2;
  Result<std::unique_ptr<SegmentationServer>> started = SegmentationServer::Start(so);
  if (!started.ok()) {
    std::fprintf(stderr, "%s\n", started.status().ToString().c_str());
    return 1;
  }
  SegmentationServer& server = **started;
  const int port = server.port();
  (void)SmallFrame();

  ValidClients v;
  RssTrace rss;
  // RSS every 100 ms.
  const Clock::time_point t0 = Clock::now();
  std::thread sampler([&] {
    while (!v.stop.load()) {
      rss.samples.emplace_back(std::chrono::duration<double>(Clock::now() - t0).count(), RssMb());
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  });
  std::vector<std::thread> valid = StartValidClients(port, 4, v);
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  rss.idle_end = RssMb();

  v.attack = true;
  std::atomic<bool> attack_stop{false};
  HostileOutcomes h;
  std::vector<std::thread> hostile = StartHostileClients(port, attack_stop, h);
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  attack_stop = true;
  for (std::thread& t : hostile) t.join();
  rss.attack_end = RssMb();
  v.stop = true;
  for (std::thread& t : valid) t.join();
  sampler.join();
  const ServerStats stats = server.stats();
  server.Shutdown();

  for (const auto& [t, mb] : rss.samples) {
    double& max = t <= seconds ? rss.idle_max : rss.attack_max;
    max = std::max(max, mb);
  }
  PrintMixedLoad(seconds, v, h, rss, stats);
  const std::vector<bench::BenchRecord> records = MixedLoadRecords(v, h, rss);
  if (!json_path.empty() && !bench::WriteBenchRecords(json_path, records)) return 1;
  return 0;
}

}  // namespace
}  // namespace avp::segmentation_service

int main(int argc, char** argv) {
  bool mixed = false, clients = false;
  double seconds = 10.0;
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--mixed-load") {
      mixed = true;
    } else if (arg == "--clients") {
      clients = true;
    } else if (arg.rfind("--seconds=", 0) == 0) {
      seconds = std::stod(arg.substr(10));
    } else {
      argv[kept++] = argv[i];
    }
  }
  argc = kept;
  if (!mixed && !clients) return avp::bench::GoogleBenchmarkMain(argc, argv, {});
  const std::string json = avp::bench::TakeJsonPathArgument(argc, argv);
  if (clients) return avp::segmentation_service::Clients(seconds, json);
  return avp::segmentation_service::MixedLoad(seconds, json);
}

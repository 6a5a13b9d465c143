// Replay speed of `avp replay` (issue 17): frames per second over a recorded episode.
//
// The recording: `avp run --record` of the built-in scenario tomato-multiple-clusters, seed 3,
// with the settings of `avp run` (avp-nbv, oracle segmenter, 640x480 camera, 2 threads), kViews
// views, written once into the temporary folder. Each iteration reads the MCAP file and replays
// it into a run folder (record.json, metrics.csv, map.avpmap, map.ot, PLY, SVG, report.html), as
// the command does:
//   BM_ReadBag                 reading only (ros::bag::ReadBag: decode every view)
//   BM_Replay/recorded         read + the recorded masks + integrate + evaluate + write the folder
//   BM_Replay/oracle           the same with the oracle segmenter rerun on the recorded labels
//   BM_Replay/robot_bag        the file read as a robot's bag (images, CameraInfo, TF) + oracle
//   BM_ReplayRobotBag/W/H      a 90-frame RealSense bag (W x H, 30 Hz) replayed frame by frame
//                              with the colour segmenter; peak resident memory
// Counters: fps (views per second of wall time, the whole replay), ms_per_view, and for the
// replays the original episode's ms per view (episode_ms_per_view: capture, segment, integrate,
// evaluate, plan, move), speedup = episode_ms_per_view / ms_per_view, and the replay's own
// integrate_ms and segment_ms per view (the rest: reading, evaluating, writing the folder).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>

#include <benchmark/benchmark.h>
#include <fmt/format.h>

#include <avp/experiment/replay.h>
#include <avp/experiment/run_folder.h>
#include <avp/ros/bag/bag_reader.h>

#include "bench_report.h"
#include "robot_bag_writer.h"

namespace avp {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr int kViews = 6;

void Die(const Status& s) {
  std::fprintf(stderr, "bench_replay: %s\n", s.ToString().c_str());
  std::abort();
}

struct Fixture {
  experiment::Registries registries = experiment::BuiltinRegistries();
  fs::path dir = fs::temp_directory_path() / "avp_bench_replay";
  fs::path bag;
  double episode_ms_per_view = 0.0;
  Fixture() {
    fs::remove_all(dir);
    experiment::RunConfig config;
    config.scenario = "tomato-multiple-clusters";
    config.seed = 3;
    config.episode.views = kViews;
    config.threads = 2;
    experiment::RunFolderOptions o;
    o.out_dir = dir / "run";
    o.record = true;
    Result<experiment::RunSummary> run =
        experiment::RunToFolder(experiment::CheckedRunConfig::Check(config, registries).value(), o);
    if (!run.ok()) Die(run.status());
    bag = o.out_dir / "episode.mcap";
    episode_ms_per_view = run->result.episode.total_ms / run->result.episode.views_fused();
    std::printf("bench_replay: recorded %d views (%.1f MB), %.1f ms per view in the episode\n",
                run->result.episode.views_fused(), static_cast<double>(fs::file_size(bag)) / 1e6,
                episode_ms_per_view);
  }
  ~Fixture() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
};

Fixture& TheFixture() {
  static Fixture* f = new Fixture();
  return *f;
}

double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

void BM_ReadBag(benchmark::State& state) {
  Fixture& f = TheFixture();
  double seconds = 0.0;
  size_t views = 0;
  for (auto _ : state) {
    const auto t0 = Clock::now();
    Result<ros::bag::Bag> bag = ros::bag::ReadBag(f.bag);
    if (!bag.ok()) Die(bag.status());
    seconds += Seconds(t0);
    views += bag->views.size();
  }
  state.counters["fps"] = static_cast<double>(views) / seconds;
  state.counters["ms_per_view"] = 1e3 * seconds / static_cast<double>(views);
  state.counters["MB_per_s"] = static_cast<double>(fs::file_size(f.bag)) *
                               static_cast<double>(state.iterations()) / seconds / 1e6;
}
BENCHMARK(BM_ReadBag)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

/// mode 0: recorded masks; 1: the oracle; 2: the file read as a robot's bag, oracle.
void BM_Replay(benchmark::State& state, int mode) {
  Fixture& f = TheFixture();
  ros::bag::BagReadOptions read;
  if (mode == 2) read.as_robot_bag = true;
  double seconds = 0.0, integrate_ms = 0.0, segment_ms = 0.0;
  size_t views = 0;
  for (auto _ : state) {
    const auto t0 = Clock::now();
    Result<std::unique_ptr<ros::bag::BagReader>> bag = ros::bag::BagReader::Open(f.bag, read);
    if (!bag.ok()) Die(bag.status());
    Result<experiment::RunConfig> config = experiment::BagRunConfig(**bag);
    if (!config.ok()) Die(config.status());
    if (mode == 2) config->replay.fps = 0.0;
    experiment::ReplayOptions o;
    o.segmenter = mode == 0 ? "recorded" : "oracle";
    o.folder.out_dir = f.dir / "replay";
    o.folder.force = true;
    Result<experiment::ReplaySummary> r =
        experiment::ReplayToFolder(**bag, *config, f.registries, o);
    if (!r.ok()) Die(r.status());
    seconds += Seconds(t0);
    views += r->views;
    for (const pipeline::StepRecord& s : r->run.result.episode.steps) {
      integrate_ms += s.times.integrate_ms;
      segment_ms += s.times.segment_ms;
    }
    if (mode != 2 && r->metrics_differ != 0) {
      std::fprintf(stderr, "bench_replay: the replay's metrics differ: %s\n",
                   r->first_difference.c_str());
      std::abort();
    }
  }
  const double ms = 1e3 * seconds / static_cast<double>(views);
  state.counters["fps"] = static_cast<double>(views) / seconds;
  state.counters["ms_per_view"] = ms;
  state.counters["episode_ms_per_view"] = f.episode_ms_per_view;
  state.counters["speedup"] = f.episode_ms_per_view / ms;
  state.counters["integrate_ms"] = integrate_ms / static_cast<double>(views);
  state.counters["segment_ms"] = segment_ms / static_cast<double>(views);
}
BENCHMARK_CAPTURE(BM_Replay, recorded, 0)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Replay, oracle, 1)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Replay, robot_bag, 2)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3)
    ->UseRealTime();

/// The process's peak resident memory (VmHWM), MB, or NaN when /proc does not say.
double PeakRssMb() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  }
  return std::nan("");
}

/// Resets VmHWM to the current RSS (Linux >= 4.0: clear_refs 5), so that PeakRssMb measures what
/// follows.
void ResetPeakRss() { std::ofstream("/proc/self/clear_refs") << "5"; }

/// A RealSense robot's bag (ros/bag/test/robot_bag_writer.h) of 3 s at 30 Hz, width x height:
/// rgb8 colour, 16UC1 depth of a wall 0.6 m ahead with a red disc, CameraInfo, /tf at 100 Hz.
fs::path RobotBag(int width, int height) {
  const fs::path path = TheFixture().dir / fmt::format("robot_{}x{}.mcap", width, height);
  if (fs::exists(path)) return path;
  using Writer = ros::bag::testing::RobotBagWriter;
  auto w = Writer::Open(path).value();
  const int64_t t0 = 1'700'000'000'000'000'000;
  const RigidTransform optical =
      RigidTransform::LookAt({0, 0, 0}, {1, 0, 0}, Eigen::Vector3d::UnitZ());
  if (!w->Tf({Writer::Edge("igus_rebel_base_link", "link",
                           RigidTransform(Eigen::Vector3d(0, 0, 0.4)), t0),
              Writer::Edge("link", "camera_color_optical_frame", optical, t0)},
             t0, true)
           .ok()) {
    Die(InternalError("tf"));
  }
  const CameraIntrinsics K = ros::bag::testing::SyntheticIntrinsics(width, height);
  ImageRgb8 rgb(width, height);
  DepthImage depth(width, height);
  ros::bag::testing::DrawWallAndDisc(rgb, depth);
  for (int i = 0; i < 90; ++i) {
    const int64_t t = t0 + i * int64_t{33'333'333};
    if (!w->Frame(t, rgb, depth, ros::msg::ToCameraInfo(K, {}), "camera_color_optical_frame")
             .ok()) {
      Die(InternalError("frame"));
    }
  }
  if (Status st = w->Close(); !st.ok()) Die(st);
  return path;
}

/// A robot's bag replayed frame by frame (replay.fps = 0: all 90 frames) with the colour
/// segmenter into a run folder, at 640 x 480 and 1280 x 720: fps (views per second of wall
/// time), MB_per_s of bag read, and peak_rss_MB (the process's resident memory at its highest
/// during the replay) with rss_growth_MB over the memory before it.
void BM_ReplayRobotBag(benchmark::State& state) {
  Fixture& f = TheFixture();
  const fs::path bag = RobotBag(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  double seconds = 0.0, peak = 0.0, growth = 0.0;
  size_t views = 0;
  for (auto _ : state) {
    const double before = [] {
      std::ifstream status("/proc/self/status");
      std::string line;
      while (std::getline(status, line)) {
        if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
      }
      return std::nan("");
    }();
    ResetPeakRss();
    const auto t0 = Clock::now();
    auto reader = ros::bag::BagReader::Open(bag).value();
    experiment::RunConfig config = experiment::BagRunConfig(*reader).value();
    config.replay.fps = 0.0;
    experiment::ReplayOptions o;
    o.segmenter = "color";
    o.folder.out_dir = f.dir / "replay_robot";
    o.folder.force = true;
    Result<experiment::ReplaySummary> r =
        experiment::ReplayToFolder(*reader, config, f.registries, o);
    if (!r.ok()) Die(r.status());
    seconds += Seconds(t0);
    views += r->views;
    peak = std::max(peak, PeakRssMb());
    growth = std::max(growth, PeakRssMb() - before);
  }
  state.counters["fps"] = static_cast<double>(views) / seconds;
  state.counters["ms_per_view"] = 1e3 * seconds / static_cast<double>(views);
  state.counters["MB_per_s"] = static_cast<double>(fs::file_size(bag)) *
                               static_cast<double>(state.iterations()) / seconds / 1e6;
  state.counters["peak_rss_MB"] = peak;
  state.counters["rss_growth_MB"] = growth;
}
BENCHMARK(BM_ReplayRobotBag)
    ->Args({640, 480})
    ->Args({1280, 720})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(2)
    ->UseRealTime();

}  // namespace
}  // namespace avp

int main(int argc, char** argv) { return avp::bench::GoogleBenchmarkMain(argc, argv, {}); }

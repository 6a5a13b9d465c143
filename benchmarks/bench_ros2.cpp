// ROS 2 on the wire (docs/ros2.md, docs/benchmarks.md): a plain program writing records.
//
//   ros2_rgbd_pair_latency_{median,p99}  publish → both images of a 640 x 480 rgb8 + 16UC1 pair
//                                         taken and decoded in another process, over loopback,
//                                         reliable QoS, 30 Hz for 10 s (ms; target median <= 5)
//   ros2_rgbd_pairs_lost                  pairs published but not received (target < 1)
//   ros2_rgbd_pair_to_frame               the live source's conversion of a pair (ms)
//   live_step_cpu / run_step_cpu          CPU seconds per step of an avp live episode against
//                                         avp sim ros2 in a second process (both processes'
//                                         CPU), and of avp run in one process, same scenario,
//                                         seed and components; ratio = run / live
//
// Usage: bench_ros2 [--avp_json=PATH] [--quick]
#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <avp/experiment/episode_runner.h>
#include <avp/experiment/registries.h>
#include <avp/robot/arm_model.h>
#include <avp/ros/dds/node.h>
#include <avp/ros/live/ros2_arm.h>
#include <avp/ros/live/ros2_rgbd_source.h>
#include <avp/ros/live/tf_listener.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/simrobot/sim_ros2_robot.h>

#include "bench_report.h"

namespace avp {
namespace {

using Clock = std::chrono::steady_clock;

std::string g_self;  ///< this program, re-executed for the second process

/// Starts this program again as `mode` with `args` (fork + exec at once: the parent's DDS threads
/// are never inherited).
pid_t SpawnSelf(const std::string& mode, const std::vector<std::string>& args) {
  std::vector<std::string> all = {g_self, mode};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    execv(g_self.c_str(), argv.data());
    _exit(127);
  }
  return pid;
}

double CpuSeconds(int who) {
  rusage u{};
  getrusage(who, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
}

ros::dds::NodeOptions Loopback(const std::string& name, int domain) {
  ros::dds::NodeOptions o;
  o.name = name;
  o.domain_id = domain;
  o.loopback = true;
  return o;
}

ros::msg::Image Pattern(const std::string& encoding, int bpp) {
  ros::msg::Image m;
  m.header.frame_id = "camera_color_optical_frame";
  m.width = 640;
  m.height = 480;
  m.encoding = encoding;
  m.step = static_cast<uint32_t>(640 * bpp);
  m.data.resize(static_cast<size_t>(m.step) * m.height);
  for (size_t i = 0; i < m.data.size(); ++i) m.data[i] = static_cast<uint8_t>(i * 7);
  return m;
}

/// Child: publishes `frames` pairs at 30 Hz once the reader matched, then exits.
[[noreturn]] void PublishPairs(int domain, int frames) {
  auto node = ros::dds::Node::Create(Loopback("bench_camera", domain));
  if (!node.ok()) _exit(2);
  auto color =
      (*node)->CreatePublisher<ros::msg::Image>("/bench/color", ros::dds::QosProfile::Default());
  auto depth =
      (*node)->CreatePublisher<ros::msg::Image>("/bench/depth", ros::dds::QosProfile::Default());
  if (!color.ok() || !depth.ok()) _exit(3);
  const auto deadline = Clock::now() + std::chrono::seconds(20);
  while (((*color)->matched_subscriptions() == 0 || (*depth)->matched_subscriptions() == 0) &&
         Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ros::msg::Image c = Pattern("rgb8", 3);
  ros::msg::Image d = Pattern("16UC1", 2);
  auto next = Clock::now();
  for (int i = 0; i < frames; ++i) {
    const ros::msg::Time stamp = ros::msg::Time::FromNanoseconds(ros::live::NowNs());
    c.header.stamp = d.header.stamp = stamp;
    (void)(*color)->Publish(c);
    (void)(*depth)->Publish(d);
    next += std::chrono::microseconds(33333);
    std::this_thread::sleep_until(next);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  _exit(0);
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t i =
      std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5));
  return v[i];
}

void TransportLatency(int domain, int frames, std::vector<bench::BenchRecord>& records) {
  std::mutex mutex;
  std::map<int64_t, std::pair<int64_t, int64_t>> arrivals;  // stamp -> (colour, depth) receipt
  auto node = ros::dds::Node::Create(Loopback("bench_loop", domain));
  if (!node.ok()) throw Error(node.status().ToString());
  auto on = [&](bool is_color) {
    return [&, is_color](ros::msg::Image&& m, const ros::dds::SampleInfo&) {
      const int64_t now = ros::live::NowNs();
      // What the loop does with a pair: decode (done) and convert.
      std::lock_guard lock(mutex);
      auto& a = arrivals[m.header.stamp.ToNanoseconds()];
      (is_color ? a.first : a.second) = now;
    };
  };
  auto color = (*node)->CreateSubscription<ros::msg::Image>(
      "/bench/color", ros::dds::QosProfile::Default(), on(true));
  auto depth = (*node)->CreateSubscription<ros::msg::Image>(
      "/bench/depth", ros::dds::QosProfile::Default(), on(false));
  if (!color.ok() || !depth.ok()) throw Error("subscriptions failed");
  const pid_t child = SpawnSelf("--child-camera", {std::to_string(domain), std::to_string(frames)});
  int status = 0;
  waitpid(child, &status, 0);
  std::vector<double> latency_ms;
  {
    std::lock_guard lock(mutex);
    for (const auto& [stamp, a] : arrivals) {
      if (a.first > 0 && a.second > 0) {
        latency_ms.push_back(static_cast<double>(std::max(a.first, a.second) - stamp) / 1e6);
      }
    }
  }
  const double lost = static_cast<double>(frames) - static_cast<double>(latency_ms.size());
  records.push_back(bench::MakeRecord("ros2_rgbd_pair_latency_median", Percentile(latency_ms, 0.5),
                                      "ms", std::nullopt, std::nullopt, std::nullopt, "<=5"));
  records.push_back(
      bench::MakeRecord("ros2_rgbd_pair_latency_p99", Percentile(latency_ms, 0.99), "ms"));
  records.push_back(bench::MakeRecord("ros2_rgbd_pairs_lost", lost, "pairs", std::nullopt,
                                      std::nullopt, std::nullopt, "<1"));
  std::printf("transport: %zu of %d pairs, median %.2f ms, p99 %.2f ms (child exit %d)\n",
              latency_ms.size(), frames, Percentile(latency_ms, 0.5), Percentile(latency_ms, 0.99),
              WEXITSTATUS(status));
  // The conversion the live source does per pair.
  const ros::msg::Image c = Pattern("rgb8", 3);
  const ros::msg::Image d = Pattern("16UC1", 2);
  std::vector<double> convert_ms;
  for (int i = 0; i < 50; ++i) {
    const auto t0 = Clock::now();
    auto rgb = ros::msg::ColorFromImage(c, "/bench/color");
    auto z = ros::msg::DepthFromImage(d, "/bench/depth");
    if (!rgb.ok() || !z.ok()) throw Error("conversion failed");
    convert_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  records.push_back(
      bench::MakeRecord("ros2_rgbd_pair_to_frame", Percentile(convert_ms, 0.5), "ms"));
}

/// Child: avp sim ros2 on the scenario of LiveOverhead until killed.
[[noreturn]] void PlaySim(int domain, int views) {
  const experiment::Registries registries = experiment::BuiltinRegistries();
  experiment::RunConfig config;
  config.scenario = "tomato-single-cluster";
  config.seed = 3;
  auto scene = experiment::LoadScene(config, registries);
  auto model = robot::LoadDefaultArm();
  if (!scene.ok() || !model.ok()) _exit(2);
  auto node = ros::dds::Node::Create(Loopback("bench_sim", domain));
  if (!node.ok()) _exit(2);
  ros::simrobot::SimRobotOptions o;
  o.time_scale = 0.0;
  o.camera_rate_hz = 15.0;
  auto robot = ros::simrobot::SimRos2Robot::Create(
      **node, *scene, *model, experiment::StartJoints(*scene, *model), config.camera,
      config.depth_noise, config.seed, o);
  if (!robot.ok()) _exit(3);
  std::stop_source stop;
  (void)(*robot)->Run(stop.get_token(), 30.0 + 15.0 * views);
  _exit(0);
}

/// CPU per step of avp run (one process) and of avp live against avp sim ros2 (two processes).
void LiveOverhead(int domain, int views, std::vector<bench::BenchRecord>& records) {
  const experiment::Registries registries = experiment::BuiltinRegistries();
  experiment::RunConfig config;
  config.scenario = "tomato-single-cluster";
  config.seed = 3;
  config.episode.views = views;
  config.threads = 2;
  auto scene = experiment::LoadScene(config, registries);
  if (!scene.ok()) throw Error(scene.status().ToString());
  auto gt = experiment::GroundTruthFor(config, *scene);
  if (!gt.ok()) throw Error(gt.status().ToString());

  double cpu0 = CpuSeconds(RUSAGE_SELF);
  auto run = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(config, registries).value(), *scene, *gt);
  if (!run.ok()) throw Error(run.status().ToString());
  const double run_cpu = (CpuSeconds(RUSAGE_SELF) - cpu0) / views;

  auto model = robot::LoadDefaultArm();
  if (!model.ok()) throw Error(model.status().ToString());
  const double children_before = CpuSeconds(RUSAGE_CHILDREN);
  const pid_t child = SpawnSelf("--child-sim", {std::to_string(domain), std::to_string(views)});
  cpu0 = CpuSeconds(RUSAGE_SELF);
  double live_cpu = 0.0;
  {
    auto node = ros::dds::Node::Create(Loopback("bench_live", domain));
    if (!node.ok()) throw Error(node.status().ToString());
    ros::msg::TfBuffer tf;
    auto listener = ros::live::TfListener::Create(**node, tf);
    ros::live::ArmTopicsOptions arm_options;
    arm_options.min_duration_s = 0.0;
    arm_options.max_joint_speed_rad_s = 100.0;
    arm_options.state_timeout_s = 20.0;
    ros::live::CameraTopicsOptions camera_options;
    camera_options.labels_prefix = std::string(ros::msg::kSimLabelsPrefix);
    camera_options.frame_timeout_s = 20.0;
    auto arm = ros::live::Ros2Arm::Create(**node, tf, *model, arm_options);
    if (!arm.ok()) throw Error(arm.status().ToString());
    auto source = ros::live::Ros2RgbdSource::Create(**node, tf, camera_options, config.camera);
    if (!source.ok()) throw Error(source.status().ToString());
    cpu0 = CpuSeconds(RUSAGE_SELF);
    auto live = experiment::RunEpisodeWithRobot(
        experiment::CheckedRunConfig::Check(config, registries).value(),
        {source->get(), arm->get(), {}}, scene->plant_bounds.Inflated(config.roi_margin_m),
        {&*scene, &*gt});
    if (!live.ok()) throw Error(live.status().ToString());
    live_cpu = CpuSeconds(RUSAGE_SELF) - cpu0;
    for (const pipeline::StepRecord& step : live->episode.steps) {
      if (!step.capture_status.ok()) {
        std::printf("live view %d: %s\n", step.view + 1, step.capture_status.ToString().c_str());
      }
    }
    std::printf("live: %d views, end %s, F1 %.4f (run %.4f)\n", live->episode.views_fused(),
                std::string(pipeline::ToString(live->episode.end)).c_str(),
                live->final_metrics.exact.f1, run->final_metrics.exact.f1);
  }
  kill(child, SIGTERM);
  int status = 0;
  waitpid(child, &status, 0);
  // The simulated robot's CPU (rendering, publishing) over its whole life: an upper bound of its
  // share in the episode, which replaces avp run's own rendering.
  const double sim_per_step = (CpuSeconds(RUSAGE_CHILDREN) - children_before) / views;
  const double live_per_step = live_cpu / views;
  std::printf("CPU per step: avp run %.3f s; avp live %.3f s + avp sim ros2 %.3f s (whole life)\n",
              run_cpu, live_per_step, sim_per_step);
  records.push_back(bench::MakeRecord("run_step_cpu", run_cpu, "s"));
  records.push_back(bench::MakeRecord("live_step_cpu", live_per_step, "s", "avp run, same episode",
                                      run_cpu, run_cpu / live_per_step));
  records.push_back(bench::MakeRecord("live_and_sim_step_cpu", live_per_step + sim_per_step, "s",
                                      "avp run, same episode", run_cpu,
                                      run_cpu / (live_per_step + sim_per_step)));
}

}  // namespace
}  // namespace avp

int main(int argc, char** argv) {
  avp::g_self = "/proc/self/exe";
  char self[4096];
  const ssize_t n = readlink("/proc/self/exe", self, sizeof(self) - 1);
  if (n > 0) avp::g_self.assign(self, static_cast<size_t>(n));
  setenv("AVP_ROS2_LOOPBACK", "1", 1);
  if (argc == 4 && std::strcmp(argv[1], "--child-camera") == 0) {
    avp::PublishPairs(std::atoi(argv[2]), std::atoi(argv[3]));
  }
  if (argc == 4 && std::strcmp(argv[1], "--child-sim") == 0) {
    avp::PlaySim(std::atoi(argv[2]), std::atoi(argv[3]));
  }
  const std::string json = avp::bench::TakeJsonPathArgument(argc, argv);
  bool quick = false;
  for (int i = 1; i < argc; ++i) quick = quick || std::strcmp(argv[i], "--quick") == 0;
  const int domain = 200 + static_cast<int>(getpid() % 30);
  std::vector<avp::bench::BenchRecord> records;
  try {
    avp::TransportLatency(domain, quick ? 60 : 300, records);
    avp::LiveOverhead(domain, quick ? 2 : 4, records);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_ros2: %s\n", e.what());
    return 1;
  }
  if (!json.empty() && !avp::bench::WriteBenchRecords(json, records)) return 1;
  return 0;
}

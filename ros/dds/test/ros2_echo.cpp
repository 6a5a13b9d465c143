// avp_ros2_echo: a second process for avp_ros2_test. Echoes every sample received on
// <in>/t<n> to <out>/t<n> as raw bytes, for each DDS type name given, on a loopback node.
//   avp_ros2_echo <domain> <seconds> <in-prefix> <out-prefix> <dds type> [<dds type> ...]
// Topic n is the type's index among the arguments ("/avp_test/in/t0"). Exits after <seconds>
// (a bound: the test kills it earlier). Reliable transient-local keep-last 10 both ways, so that
// samples sent before the other side has matched (discovery is not symmetric in time) still
// arrive.

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <unistd.h>

#include <avp/ros/dds/node.h>

int main(int argc, char** argv) {
  using namespace avp::ros::dds;
  if (argc < 6) {
    std::fprintf(stderr, "usage: %s DOMAIN SECONDS IN_PREFIX OUT_PREFIX TYPE...\n", argv[0]);
    return 2;
  }
  NodeOptions options;
  options.name = "avp_echo";
  options.domain_id = std::atoi(argv[1]);
  options.loopback = true;
  const int seconds = std::atoi(argv[2]);
  const std::string in = argv[3];
  const std::string out = argv[4];
  auto node = Node::Create(options);
  if (!node.ok()) {
    std::fprintf(stderr, "avp_ros2_echo: %s\n", node.status().ToString().c_str());
    return 1;
  }
  std::vector<std::unique_ptr<RawPublisher>> pubs;
  std::vector<std::unique_ptr<RawSubscription>> subs;
  for (int i = 5; i < argc; ++i) {
    const TypeInfo type{argv[i], argv[i], ""};
    const int n = i - 5;
    auto pub =
        (*node)->CreateRawPublisher(fmt::format("{}/t{}", out, n), type, QosProfile::Latched(10));
    if (!pub.ok()) {
      std::fprintf(stderr, "avp_ros2_echo: %s\n", pub.status().ToString().c_str());
      return 1;
    }
    RawPublisher* raw_pub = pub->get();
    pubs.push_back(std::move(pub).value());
    auto sub =
        (*node)->CreateRawSubscription(fmt::format("{}/t{}", in, n), type, QosProfile::Latched(10),
                                       [raw_pub](std::span<const uint8_t> cdr, const SampleInfo&) {
                                         return raw_pub->Publish(cdr);
                                       });
    if (!sub.ok()) {
      std::fprintf(stderr, "avp_ros2_echo: %s\n", sub.status().ToString().c_str());
      return 1;
    }
    subs.push_back(std::move(sub).value());
  }
  std::printf("ready\n");
  std::fflush(stdout);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
  while (std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return 0;
}

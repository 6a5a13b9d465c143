// ros2_fastdds_interop: avp (Cyclone DDS) and a Fast DDS 2.9 peer (avp_ros2_fastdds_peer, the
// default RMW's DDS) exchange Image, CameraInfo, TFMessage, PoseStamped and Octomap on loopback
// with ROS's QoS profiles: the peer receives what avp publishes (it reports each sample's size and
// header) and echoes the bytes back, which avp decodes to the messages it sent.

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <avp/ros/dds/node.h>
#include <avp/ros/msg/messages.h>

#include "reference_messages.h"
#include "ros2_test_support.h"

namespace avp::ros::dds {
namespace {

using namespace std::chrono_literals;
using ros::msg::testing::References;
using testing::LoopbackNode;
using testing::TestDomainId;
using testing::WaitFor;

// Runs the peer with its stdout on a pipe, collected line by line; kills it on destruction.
class PeerProcess {
 public:
  explicit PeerProcess(std::vector<std::string> args) {
    int fds[2];
    if (pipe(fds) != 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      dup2(fds[1], STDOUT_FILENO);
      close(fds[0]);
      close(fds[1]);
      std::vector<char*> argv;
      for (auto& s : args) argv.push_back(s.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(fds[1]);
    fd_ = fds[0];
    reader_ = std::thread([this] { Read(); });
  }
  ~PeerProcess() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      int status = 0;
      waitpid(pid_, &status, 0);
    }
    stop_ = true;
    if (reader_.joinable()) reader_.join();
    if (fd_ >= 0) close(fd_);
  }
  bool started() const { return pid_ > 0; }
  /// False once the peer has exited (it then never becomes ready).
  bool alive() {
    if (pid_ <= 0 || exited_) return false;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      exited_ = true;
      pid_ = -1;
    }
    return !exited_;
  }
  std::vector<std::string> lines() {
    std::lock_guard lock(mutex_);
    return lines_;
  }
  /// Whether the peer's reader or writer on `topic` has matched `count` endpoints last.
  bool Matched(const std::string& topic, int count) {
    int last = 0;
    for (const std::string& line : lines()) {
      std::istringstream in(line);
      std::string word, t;
      int n = 0;
      if (in >> word >> t >> n && word == "matched" && t == topic) last = n;
    }
    return last == count;
  }
  /// The "recv <topic> <bytes> <header>" lines for `topic`.
  std::vector<std::pair<size_t, std::string>> Received(const std::string& topic) {
    std::vector<std::pair<size_t, std::string>> out;
    for (const std::string& line : lines()) {
      std::istringstream in(line);
      std::string word, t, header;
      size_t size = 0;
      if (in >> word >> t >> size >> header && word == "recv" && t == topic) {
        out.emplace_back(size, header);
      }
    }
    return out;
  }

 private:
  void Read() {
    std::string partial;
    char buf[4096];
    while (!stop_) {
      pollfd p{fd_, POLLIN, 0};
      if (poll(&p, 1, 50) <= 0) continue;
      const ssize_t n = read(fd_, buf, sizeof(buf));
      if (n <= 0) break;
      partial.append(buf, static_cast<size_t>(n));
      for (size_t pos; (pos = partial.find('\n')) != std::string::npos;) {
        std::lock_guard lock(mutex_);
        lines_.push_back(partial.substr(0, pos));
        partial.erase(0, pos + 1);
      }
    }
  }

  pid_t pid_ = -1;
  bool exited_ = false;
  int fd_ = -1;
  std::atomic<bool> stop_{false};
  std::thread reader_;
  std::mutex mutex_;
  std::vector<std::string> lines_;
};

template <class M>
class Collector {
 public:
  std::function<void(M&&, const SampleInfo&)> Callback() {
    return [this](M&& m, const SampleInfo&) {
      std::lock_guard lock(mutex_);
      got_.push_back(ros::msg::Encode(m));
    };
  }
  std::vector<std::vector<uint8_t>> got() {
    std::lock_guard lock(mutex_);
    return got_;
  }

 private:
  std::mutex mutex_;
  std::vector<std::vector<uint8_t>> got_;
};

std::string PeerArg(std::string_view dds_type, const std::string& name, std::string_view qos) {
  return fmt::format("{},/avp_test/{},/avp_test/echo/{},{}", dds_type, name, name, qos);
}

// One type's round: avp publishes `messages` on /avp_test/<name>, the peer reports and echoes
// them on /avp_test/echo/<name>; avp's subscription there (created after the peer received, for
// a transient-local round: a late joiner) must decode them to the same messages.
template <class M>
void Round(Node& node, PeerProcess& peer, const std::string& name, const QosProfile& qos,
           const std::vector<M>& messages) {
  SCOPED_TRACE(name);
  const std::string topic = "/avp_test/" + name;
  const std::string echo_topic = "/avp_test/echo/" + name;
  const bool latched = qos.durability == Durability::kTransientLocal;
  auto pub = node.CreatePublisher<M>(topic, qos).value();
  Collector<M> collector;
  std::unique_ptr<Subscription<M>> sub;
  if (!latched) {
    sub = node.CreateSubscription<M>(echo_topic, qos, collector.Callback()).value();
  }
  // Both sides must have matched: each learns of the other at its own pace.
  ASSERT_TRUE(
      WaitFor([&] { return pub->matched_subscriptions() == 1 && peer.Matched(topic, 1); }, 15s))
      << "the Fast DDS reader of " << topic << " and avp's writer never matched";
  if (sub != nullptr) {
    ASSERT_TRUE(
        WaitFor([&] { return sub->matched_publishers() == 1 && peer.Matched(echo_topic, 1); }, 15s))
        << "avp's reader of " << echo_topic << " and the Fast DDS writer never matched";
  }
  for (const M& m : messages) ASSERT_TRUE(pub->Publish(m).ok());
  ASSERT_TRUE(WaitFor([&] { return peer.Received(topic).size() == messages.size(); }, 10s))
      << "the Fast DDS peer received " << peer.Received(topic).size() << " of " << messages.size()
      << " samples on " << topic;
  const auto received = peer.Received(topic);
  for (size_t i = 0; i < messages.size(); ++i) {
    const size_t size = ros::msg::Encode(messages[i]).size();
    EXPECT_GE(received[i].first, size);
    EXPECT_LE(received[i].first, size + 3);  // RTPS pads payloads to a multiple of 4
    EXPECT_EQ(received[i].second, "00010000");
  }
  if (latched) {
    sub = node.CreateSubscription<M>(echo_topic, qos, collector.Callback()).value();
  }
  std::vector<std::vector<uint8_t>> expected;
  for (const M& m : messages) expected.push_back(ros::msg::Encode(m));
  ASSERT_TRUE(WaitFor([&] { return collector.got().size() == expected.size(); }, 10s))
      << "avp got " << collector.got().size() << " of " << expected.size()
      << " echoed samples on /avp_test/echo/" << name;
  EXPECT_EQ(collector.got(), expected);
  EXPECT_EQ(sub->malformed(), 0u) << sub->last_error().ToString();
}

TEST(FastDdsInterop, ExchangesEveryTypeBothWays) {
  const int domain = TestDomainId();
  using ros::msg::MessageTraits;
  PeerProcess peer(
      {AVP_ROS2_FASTDDS_PEER, std::to_string(domain), "40",
       PeerArg(MessageTraits<ros::msg::Image>::kDdsName, "image", "sensor"),
       PeerArg(MessageTraits<ros::msg::CameraInfo>::kDdsName, "camera_info", "default"),
       PeerArg(MessageTraits<ros::msg::TFMessage>::kDdsName, "tf", "default"),
       PeerArg(MessageTraits<ros::msg::TFMessage>::kDdsName, "tf_static", "latched"),
       PeerArg(MessageTraits<ros::msg::PoseStamped>::kDdsName, "pose", "default"),
       PeerArg(MessageTraits<ros::msg::Octomap>::kDdsName, "octomap", "default")});
  ASSERT_TRUE(peer.started());
  ASSERT_TRUE(WaitFor(
      [&] {
        for (const auto& l : peer.lines()) {
          if (l == "ready") return true;
        }
        return !peer.alive();
      },
      15s))
      << "the Fast DDS peer did not start";
  ASSERT_TRUE(peer.alive()) << "the Fast DDS peer exited (see its stderr above)";
  auto node = Node::Create(LoopbackNode("avp_interop", domain)).value();
  Round(*node, peer, "image", QosProfile::SensorData(), References<ros::msg::Image>());
  Round(*node, peer, "camera_info", QosProfile::Default(), References<ros::msg::CameraInfo>());
  Round(*node, peer, "tf", QosProfile::Default(), References<ros::msg::TFMessage>());
  // keep-last 1: one latched sample, which the late-joining echo reader still gets.
  Round(*node, peer, "tf_static", QosProfile::TfStatic(),
        std::vector<ros::msg::TFMessage>{References<ros::msg::TFMessage>().back()});
  Round(*node, peer, "pose", QosProfile::Default(), References<ros::msg::PoseStamped>());
  Round(*node, peer, "octomap", QosProfile::Default(), References<ros::msg::Octomap>());
}

}  // namespace
}  // namespace avp::ros::dds

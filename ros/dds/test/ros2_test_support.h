#pragma once

// Helpers for the ros2 tests: a DDS domain per test (so that tests running in parallel never see
// each other), loopback-only nodes, bounded waits.

#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <thread>

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/file.h>
#include <unistd.h>

#include <avp/ros/dds/node.h>

namespace avp::ros::dds::testing {

/// A DDS domain in 100..199 that no other process of this machine is using for a test, so that
/// tests running in parallel (ctest -j, one process per test) never read each other's messages.
/// Each domain is claimed with an exclusive lock on /tmp/avp-test-dds-domain-<d>.lock, held until
/// this process exits or its next test asks (a test's domains are released when another test of
/// the same process starts). The search starts at a hash of the test's name and this process's
/// id; `offset` gives a test further domains of its own. When all 100 are taken, the hashed one
/// is used without a lock (as before; domains above ~230 would push Cyclone's ports past 65535).
inline int TestDomainId(int offset = 0) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::string key = info != nullptr
                              ? std::string(info->test_suite_name()) + "." + info->name()
                              : std::string("none");
  uint64_t h = 1469598103934665603ull;  // FNV-1a
  for (const char c : key) h = (h ^ static_cast<uint8_t>(c)) * 1099511628211ull;
  h ^= static_cast<uint64_t>(::getpid()) * 2654435761ull;
  const int start = static_cast<int>((h + static_cast<uint64_t>(offset)) % 100);

  static std::mutex mu;
  static std::string held_for;     // the test whose domains are held
  static std::map<int, int> held;  // offset -> domain
  static std::map<int, int> fds;   // domain -> locked descriptor
  const std::lock_guard<std::mutex> lock(mu);
  if (held_for != key) {  // a new test: the previous one's domains are free again
    for (const auto& [domain, fd] : fds) ::close(fd);
    fds.clear();
    held.clear();
    held_for = key;
  }
  if (const auto it = held.find(offset); it != held.end()) return it->second;
  for (int i = 0; i < 100; ++i) {
    const int domain = 100 + (start + i) % 100;
    if (fds.contains(domain)) continue;
    const std::string path = "/tmp/avp-test-dds-domain-" + std::to_string(domain) + ".lock";
    // Read-only: flock needs no write access, so a file another user created works too.
    const int fd = ::open(path.c_str(), O_CREAT | O_RDONLY | O_CLOEXEC, 0666);
    if (fd < 0) continue;
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      ::close(fd);
      continue;
    }
    fds[domain] = fd;
    held[offset] = domain;
    return domain;
  }
  return 100 + start;
}

inline NodeOptions LoopbackNode(std::string name, int domain_id,
                                ros::msg::RosDistro distro = ros::msg::RosDistro::kHumble) {
  NodeOptions options;
  options.name = std::move(name);
  options.domain_id = domain_id;
  options.distro = distro;
  options.loopback = true;
  return options;
}

/// Polls `pred` every 5 ms until it holds or `timeout` passes; returns whether it held.
template <class Pred>
bool WaitFor(Pred pred, std::chrono::milliseconds timeout = std::chrono::seconds(5)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

}  // namespace avp::ros::dds::testing

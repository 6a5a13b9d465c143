#pragma once

// Helpers for the ros2 tests: a DDS domain per test (so that tests running in parallel never see
// each other), loopback-only nodes, bounded waits.

#include <chrono>
#include <cstdint>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <unistd.h>

#include <avp/ros2/node.h>

namespace avp::ros2::testing {

/// A domain in 100..199 from the running test's name and this process's id (domains above ~230
/// would push Cyclone's ports past 65535).
inline int TestDomainId(int offset = 0) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string key = info != nullptr ? std::string(info->test_suite_name()) + "." + info->name()
                                    : std::string("none");
  uint64_t h = 1469598103934665603ull;  // FNV-1a
  for (const char c : key) h = (h ^ static_cast<uint8_t>(c)) * 1099511628211ull;
  h ^= static_cast<uint64_t>(::getpid()) * 2654435761ull;
  return 100 + static_cast<int>((h + static_cast<uint64_t>(offset)) % 100);
}

inline NodeOptions LoopbackNode(std::string name, int domain_id,
                                rosmsg::RosDistro distro = rosmsg::RosDistro::kHumble) {
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

}  // namespace avp::ros2::testing

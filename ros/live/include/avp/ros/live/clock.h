#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace avp::ros::live {

/// The system clock in nanoseconds (ROS time without /clock): image and transform stamps.
int64_t NowNs();

/// `s` seconds as a steady-clock duration (deadlines of the bounded waits).
inline std::chrono::steady_clock::duration Seconds(double s) {
  return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(s));
}

}  // namespace avp::ros::live

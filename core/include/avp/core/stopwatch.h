#pragma once

// Wall time of a stage, as the step records and the timings of every module report it.

#include <chrono>

namespace avp {

using SteadyClock = std::chrono::steady_clock;

/// Milliseconds from `t0` to now on the steady clock.
inline double MsSince(SteadyClock::time_point t0) {
  return std::chrono::duration<double, std::milli>(SteadyClock::now() - t0).count();
}

}  // namespace avp

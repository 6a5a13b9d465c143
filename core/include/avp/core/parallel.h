#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

namespace avp {

/// Runs fn(i) for every i in [0, n) on `threads` threads (0 = the hardware's), handing indices out
/// dynamically. Each index is handled exactly once; when every fn(i) writes only its own result
/// (and draws randomness from its own stream), the output does not depend on the thread count.
template <typename Fn>
void ParallelFor(size_t n, int threads, Fn&& fn) {
  size_t t = threads > 0 ? static_cast<size_t>(threads)
                         : std::max<size_t>(1, std::thread::hardware_concurrency());
  t = std::min(t, n);
  if (t <= 1) {
    for (size_t i = 0; i < n; ++i) fn(i);
    return;
  }
  std::atomic<size_t> next{0};
  auto worker = [&] {
    for (size_t i = next.fetch_add(1); i < n; i = next.fetch_add(1)) fn(i);
  };
  std::vector<std::thread> pool;
  pool.reserve(t - 1);
  for (size_t k = 1; k < t; ++k) pool.emplace_back(worker);
  worker();
  for (std::thread& th : pool) th.join();
}

}  // namespace avp

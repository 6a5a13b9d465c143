#pragma once

// avp's one parallelism setting. How many threads the parallel loops may use is set once, at the
// door of a run (`--threads`, RunConfig::threads, a bench job's share), with a ThreadScope on the
// thread that runs it; every ParallelFor beneath it reads it: the planners' candidate scoring, the
// integrator, the renderer, the ground truth. No options struct carries a thread count. Inside a
// ParallelFor's workers the setting is 1, so a loop nested in another runs serially on its worker
// (the outer loop already uses the threads). Results never depend on the setting: every fn(i)
// writes only its own result and draws randomness from its own stream.

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

namespace avp {

namespace internal {
/// The calling thread's setting: 0 = the hardware's threads.
inline thread_local int t_thread_setting = 0;
}  // namespace internal

/// The threads a parallel loop started on this thread may use (>= 1): the innermost ThreadScope's
/// count, or the hardware's when it is 0 or no scope is open.
inline int Threads() {
  const int set = internal::t_thread_setting;
  if (set > 0) return set;
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

/// Sets the calling thread's thread count (0 = the hardware's) until the scope ends, when the
/// previous one returns. Negative counts are taken as 0.
class ThreadScope {
 public:
  explicit ThreadScope(int threads) : previous_(internal::t_thread_setting) {
    internal::t_thread_setting = std::max(0, threads);
  }
  ~ThreadScope() { internal::t_thread_setting = previous_; }
  ThreadScope(const ThreadScope&) = delete;
  ThreadScope& operator=(const ThreadScope&) = delete;

 private:
  int previous_;
};

/// Runs `worker` on min(Threads(), max_workers) threads: the calling thread and the others it
/// starts, each with the setting 1 while it runs (nested loops run serially), and waits for all.
/// On one thread, `worker` runs on the caller with the caller's setting.
template <typename Worker>
void RunWorkers(size_t max_workers, Worker&& worker) {
  const size_t t = std::min(static_cast<size_t>(Threads()), max_workers);
  if (t <= 1) {
    worker();
    return;
  }
  auto run = [&] {
    const ThreadScope serial(1);
    worker();
  };
  std::vector<std::thread> pool;
  pool.reserve(t - 1);
  for (size_t k = 1; k < t; ++k) pool.emplace_back(run);
  run();
  for (std::thread& th : pool) th.join();
}

/// Runs fn(i) for every i in [0, n) on Threads() threads, handing indices out dynamically. Each
/// index is handled exactly once.
template <typename Fn>
void ParallelFor(size_t n, Fn&& fn) {
  if (n == 0) return;
  std::atomic<size_t> next{0};
  RunWorkers(n, [&] {
    for (size_t i = next.fetch_add(1); i < n; i = next.fetch_add(1)) fn(i);
  });
}

}  // namespace avp

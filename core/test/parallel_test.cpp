#include "avp/core/parallel.h"

#include <atomic>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace avp {
namespace {

TEST(ParallelTest, ThreadScopeSetsAndRestoresTheCallingThreadsCount) {
  const int hardware = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  EXPECT_EQ(Threads(), hardware);  // no scope: the hardware's
  {
    const ThreadScope three(3);
    EXPECT_EQ(Threads(), 3);
    {
      const ThreadScope zero(0);
      EXPECT_EQ(Threads(), hardware);
      const ThreadScope negative(-4);  // taken as 0
      EXPECT_EQ(Threads(), hardware);
    }
    EXPECT_EQ(Threads(), 3);
    // Another thread does not see this thread's scope.
    int seen = -1;
    std::thread([&] { seen = Threads(); }).join();
    EXPECT_EQ(seen, hardware);
  }
  EXPECT_EQ(Threads(), hardware);
}

TEST(ParallelTest, ParallelForVisitsEveryIndexOnceOnTheScopesThreads) {
  for (const int threads : {1, 2, 3, 8}) {
    SCOPED_TRACE(threads);
    const ThreadScope scope(threads);
    std::vector<std::atomic<int>> visits(1000);
    std::mutex mu;
    std::set<std::thread::id> workers;
    ParallelFor(visits.size(), [&](size_t i) {
      visits[i].fetch_add(1);
      const std::lock_guard<std::mutex> lock(mu);
      workers.insert(std::this_thread::get_id());
    });
    for (const std::atomic<int>& v : visits) ASSERT_EQ(v.load(), 1);
    EXPECT_LE(workers.size(), static_cast<size_t>(threads));
    EXPECT_EQ(Threads(), threads);  // restored on the caller after the loop
  }
  ParallelFor(0, [](size_t) { FAIL() << "no index to visit"; });
}

TEST(ParallelTest, LoopsNestedInAWorkerRunSerially) {
  const ThreadScope four(4);
  std::vector<int> inner(8, 0);
  ParallelFor(inner.size(), [&](size_t i) { inner[i] = Threads(); });
  EXPECT_THAT(inner, ::testing::Each(1));
  // One index: it runs on the caller, whose setting stays.
  int single = 0;
  ParallelFor(1, [&](size_t) { single = Threads(); });
  EXPECT_EQ(single, 4);
}

TEST(ParallelTest, RunWorkersStartsAtMostTheScopesThreads) {
  const ThreadScope three(3);
  std::atomic<int> started{0};
  RunWorkers(100, [&] { started.fetch_add(1); });
  EXPECT_EQ(started.load(), 3);
  started = 0;
  RunWorkers(2, [&] { started.fetch_add(1); });
  EXPECT_EQ(started.load(), 2);
}

}  // namespace
}  // namespace avp

#include "lru_cache.h"

#include <atomic>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace avp::zsl {
namespace {

TEST(LruCacheTest, MissOnEmptyCache) {
  LruCache<int, int> cache(2);
  EXPECT_EQ(cache.Get(1), std::nullopt);
  EXPECT_EQ(cache.hits(), 0u);
  EXPECT_EQ(cache.misses(), 1u);
  EXPECT_EQ(cache.size(), 0u);
  EXPECT_EQ(cache.capacity(), 2u);
}

TEST(LruCacheTest, EvictsTheLeastRecentlyUsedEntry) {
  LruCache<std::string, int> cache(2);
  cache.Put("tomato", 1);
  cache.Put("leaf", 2);
  EXPECT_EQ(cache.Get("tomato"), 1);  // "leaf" is now the least recently used
  cache.Put("stem", 3);
  EXPECT_EQ(cache.size(), 2u);
  EXPECT_EQ(cache.evictions(), 1u);
  EXPECT_FALSE(cache.Contains("leaf"));
  EXPECT_EQ(cache.Get("leaf"), std::nullopt);
  EXPECT_EQ(cache.Get("tomato"), 1);
  EXPECT_EQ(cache.Get("stem"), 3);
  EXPECT_EQ(cache.hits(), 3u);
  EXPECT_EQ(cache.misses(), 1u);
}

TEST(LruCacheTest, PutReplacesTheValueAndRefreshesTheEntry) {
  LruCache<std::string, int> cache(2);
  cache.Put("a", 1);
  cache.Put("b", 2);
  cache.Put("a", 10);  // "b" is now the least recently used
  EXPECT_EQ(cache.size(), 2u);
  cache.Put("c", 3);
  EXPECT_FALSE(cache.Contains("b"));
  EXPECT_EQ(cache.Get("a"), 10);
  EXPECT_EQ(cache.Get("c"), 3);
  EXPECT_EQ(cache.evictions(), 1u);
}

TEST(LruCacheTest, ContainsDoesNotCountOrReorder) {
  LruCache<int, int> cache(2);
  cache.Put(1, 1);
  cache.Put(2, 2);
  EXPECT_TRUE(cache.Contains(1));  // does not make 1 the most recently used
  cache.Put(3, 3);
  EXPECT_FALSE(cache.Contains(1));
  EXPECT_TRUE(cache.Contains(2));
  EXPECT_EQ(cache.hits() + cache.misses(), 0u);
}

TEST(LruCacheTest, ZeroCapacityStoresNothing) {
  LruCache<int, int> cache(0);
  cache.Put(1, 1);
  EXPECT_EQ(cache.size(), 0u);
  EXPECT_EQ(cache.Get(1), std::nullopt);
  EXPECT_EQ(cache.misses(), 1u);
}

TEST(LruCacheTest, ClearKeepsTheCounters) {
  LruCache<int, int> cache(4);
  cache.Put(1, 1);
  EXPECT_EQ(cache.Get(1), 1);
  cache.Clear();
  EXPECT_EQ(cache.size(), 0u);
  EXPECT_EQ(cache.Get(1), std::nullopt);
  EXPECT_EQ(cache.hits(), 1u);
  EXPECT_EQ(cache.misses(), 1u);
}

TEST(LruCacheTest, HoldsEmbeddingVectors) {
  LruCache<std::string, std::vector<float>> cache(8);
  cache.Put("tomato", {0.5f, -0.25f});
  const auto hit = cache.Get("tomato");
  ASSERT_TRUE(hit.has_value());
  EXPECT_EQ(*hit, (std::vector<float>{0.5f, -0.25f}));
}

TEST(LruCacheTest, ConcurrentUseKeepsItsInvariants) {
  constexpr int kThreads = 4;
  constexpr int kOpsPerThread = 5000;
  LruCache<int, int> cache(16);
  std::atomic<int> wrong_values{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < kOpsPerThread; ++i) {
        const int key = (i * 7 + t * 13) % 32;
        if (const auto value = cache.Get(key)) {
          if (*value != 3 * key) ++wrong_values;
        } else {
          cache.Put(key, 3 * key);
        }
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(wrong_values.load(), 0);
  EXPECT_EQ(cache.hits() + cache.misses(), static_cast<uint64_t>(kThreads * kOpsPerThread));
  EXPECT_LE(cache.size(), 16u);
  EXPECT_EQ(cache.size(), 16u);  // 32 keys were put, so the cache filled up
}

}  // namespace
}  // namespace avp::zsl

#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <list>
#include <mutex>
#include <optional>
#include <unordered_map>
#include <utility>

namespace avp::zsl {

/// A fixed-capacity least-recently-used map, safe to share between threads (one mutex guards every
/// call). The text-embedding cache of the zero-shot segmenters uses it, keyed by the normalised
/// class name, since `Segment` may run on several threads at once.
///
/// `Get` returns a copy of the value (so no reference escapes the lock) and marks the entry as the
/// most recently used; `Put` inserts or replaces and evicts the least recently used entry when the
/// cache is full. A capacity of 0 stores nothing (every `Get` is a miss). `K` needs `std::hash<K>`
/// and `operator==`; `V` must be copyable.
///
/// The cache holds a mutex, so it can be neither copied nor moved; hold it by value in an object
/// that is itself not moved, or behind a `std::unique_ptr`.
template <class K, class V>
class LruCache {
 public:
  explicit LruCache(size_t capacity) : capacity_(capacity) {}

  LruCache(const LruCache&) = delete;
  LruCache& operator=(const LruCache&) = delete;

  /// The value stored for `key` (now the most recently used), or nullopt. Counts a hit or a miss.
  std::optional<V> Get(const K& key) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = index_.find(key);
    if (it == index_.end()) {
      ++misses_;
      return std::nullopt;
    }
    ++hits_;
    entries_.splice(entries_.begin(), entries_, it->second);
    return it->second->second;
  }

  /// Stores `value` for `key` as the most recently used entry, replacing an earlier value; evicts
  /// the least recently used entry when the cache would exceed its capacity.
  void Put(K key, V value) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (capacity_ == 0) return;
    const auto it = index_.find(key);
    if (it != index_.end()) {
      it->second->second = std::move(value);
      entries_.splice(entries_.begin(), entries_, it->second);
      return;
    }
    if (entries_.size() == capacity_) {
      index_.erase(entries_.back().first);
      entries_.pop_back();
      ++evictions_;
    }
    entries_.emplace_front(std::move(key), std::move(value));
    index_.emplace(entries_.front().first, entries_.begin());
  }

  /// True when `key` is stored; neither counts as a hit or miss nor changes the order.
  bool Contains(const K& key) const {
    std::lock_guard<std::mutex> lock(mutex_);
    return index_.count(key) > 0;
  }

  /// Removes every entry; the counters are kept.
  void Clear() {
    std::lock_guard<std::mutex> lock(mutex_);
    index_.clear();
    entries_.clear();
  }

  size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return entries_.size();
  }
  size_t capacity() const { return capacity_; }
  /// Number of `Get` calls that found / did not find their key, and of entries evicted by `Put`.
  uint64_t hits() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return hits_;
  }
  uint64_t misses() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return misses_;
  }
  uint64_t evictions() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return evictions_;
  }

 private:
  using Entry = std::pair<K, V>;

  const size_t capacity_;
  mutable std::mutex mutex_;
  std::list<Entry> entries_;  // most recently used first
  std::unordered_map<K, typename std::list<Entry>::iterator> index_;
  uint64_t hits_ = 0;
  uint64_t misses_ = 0;
  uint64_t evictions_ = 0;
};

}  // namespace avp::zsl

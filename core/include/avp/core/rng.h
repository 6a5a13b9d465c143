#pragma once

#include <cstdint>
#include <random>
#include <string_view>

namespace avp {

/// The one source of randomness in avp, always passed explicitly and seeded from the run's seed.
///
/// The engine is std::mt19937_64, whose output sequence the C++ standard fixes; the distributions
/// are implemented here rather than taken from <random> (whose algorithms differ between standard
/// libraries), so the same seed gives the same numbers with any compiler on any machine.
class Rng {
 public:
  explicit Rng(uint64_t seed) : seed_(seed), engine_(seed) {}

  uint64_t seed() const { return seed_; }

  /// A new generator for an independent sub-stream, e.g. `rng.Fork("leaves")` or `Fork(step)`.
  /// Deterministic in (this generator's seed, stream) and does not advance this generator.
  Rng Fork(uint64_t stream) const;
  Rng Fork(std::string_view stream_name) const;

  uint64_t NextU64() { return engine_(); }
  /// Uniform in [0, 1) with 53 random bits.
  double Uniform01() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  /// Uniform in [lo, hi).
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform01(); }
  /// Uniform integer in [lo, hi] (inclusive), unbiased.
  int64_t UniformInt(int64_t lo, int64_t hi);
  /// Standard normal via Box-Muller (both values used).
  double Normal();
  double Normal(double mean, double stddev) { return mean + stddev * Normal(); }
  bool Bernoulli(double p) { return Uniform01() < p; }

 private:
  uint64_t seed_;
  std::mt19937_64 engine_;
  bool has_spare_normal_ = false;
  double spare_normal_ = 0.0;
};

/// SplitMix64 finaliser: a good 64-bit mixing function for deriving seeds.
uint64_t MixSeed(uint64_t x);

}  // namespace avp

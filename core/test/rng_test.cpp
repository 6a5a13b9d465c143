#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <set>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>

namespace avp {
namespace {

using ::testing::HasSubstr;

// ---- Golden values: a change here changes every seeded run; do it on purpose or not at all. ----

TEST(RngTest, EngineIsTheStandardMt19937_64) {
  // [rand.predef]: the 10000th consecutive output of a default-constructed std::mt19937_64
  // (seed 5489) shall be 9981545732273789042.
  Rng rng(5489);
  for (int i = 0; i < 9999; ++i) (void)rng.NextU64();
  EXPECT_EQ(rng.NextU64(), 9981545732273789042ULL);
}

TEST(RngTest, GoldenNextU64ForSeed42) {
  Rng rng(42);
  EXPECT_EQ(rng.seed(), 42u);
  EXPECT_EQ(rng.NextU64(), 13930160852258120406ULL);
  EXPECT_EQ(rng.NextU64(), 11788048577503494824ULL);
  EXPECT_EQ(rng.NextU64(), 13874630024467741450ULL);
  EXPECT_EQ(rng.NextU64(), 2513787319205155662ULL);
  EXPECT_EQ(rng.NextU64(), 16662371453428439381ULL);
}

TEST(RngTest, GoldenUniform01ForSeed42) {
  // The top 53 bits of each engine output over 2^53: exact in binary, so compared exactly.
  Rng rng(42);
  EXPECT_EQ(rng.Uniform01(), 0.75515553295453897);
  EXPECT_EQ(rng.Uniform01(), 0.63903139385469743);
  EXPECT_EQ(rng.Uniform01(), 0.7521452007480266);
  EXPECT_EQ(rng.Uniform01(), 0.13627268363243705);
  // Same as computing it from the engine words by hand.
  Rng words(42);
  Rng uniform(42);
  for (int i = 0; i < 100; ++i) {
    EXPECT_EQ(uniform.Uniform01(), std::ldexp(static_cast<double>(words.NextU64() >> 11), -53));
  }
}

TEST(RngTest, GoldenNormalForSeed42) {
  // Box-Muller on the uniforms above: r = sqrt(-2 ln 0.75515553), theta = 2 pi 0.63903139;
  // r cos(theta) then r sin(theta). libm may differ in the last bit between platforms, so these
  // are compared to 4 ulps (any algorithm change moves them by far more).
  Rng rng(42);
  EXPECT_DOUBLE_EQ(rng.Normal(), -0.48121769980184498);
  EXPECT_DOUBLE_EQ(rng.Normal(), -0.57453687389830577);
  EXPECT_DOUBLE_EQ(rng.Normal(), 0.49458385623521361);
  EXPECT_DOUBLE_EQ(rng.Normal(), 0.57012155220737415);
  Rng scaled(42);
  EXPECT_DOUBLE_EQ(scaled.Normal(10.0, 2.0), 10.0 + 2.0 * -0.48121769980184498);
}

TEST(RngTest, GoldenUniformIntForSeed42) {
  Rng rng(42);
  const std::array<int64_t, 6> expected = {1, 3, 5, 1, 6, 3};
  for (const int64_t e : expected) EXPECT_EQ(rng.UniformInt(1, 6), e);
}

TEST(RngTest, MixSeedIsSplitMix64) {
  // Reference outputs of SplitMix64 started at state 0 (the first two outputs).
  EXPECT_EQ(MixSeed(0), 0xe220a8397b1dcdafULL);
  EXPECT_EQ(MixSeed(0x9e3779b97f4a7c15ULL), 0x6e789e6aa1b965f4ULL);
}

// ---- Determinism ------------------------------------------------------------------------------

TEST(RngTest, SameSeedSameSequence) {
  Rng a(123456789);
  Rng b(123456789);
  for (int i = 0; i < 1000; ++i) {
    ASSERT_EQ(a.NextU64(), b.NextU64());
    ASSERT_EQ(a.Uniform01(), b.Uniform01());
    ASSERT_EQ(a.Normal(), b.Normal());
    ASSERT_EQ(a.UniformInt(-7, 1000), b.UniformInt(-7, 1000));
  }
  // Copies continue the same stream.
  Rng c = a;
  EXPECT_EQ(c.NextU64(), a.NextU64());
}

TEST(RngTest, DifferentSeedsDiffer) {
  for (uint64_t seed = 0; seed < 20; ++seed) {
    Rng a(seed);
    Rng b(seed + 1);
    int equal = 0;
    for (int i = 0; i < 100; ++i) equal += a.NextU64() == b.NextU64() ? 1 : 0;
    EXPECT_EQ(equal, 0) << "seeds " << seed << " and " << seed + 1;
  }
}

// ---- Fork --------------------------------------------------------------------------------------

TEST(RngTest, ForkIsDeterministicAndDoesNotAdvanceTheParent) {
  Rng parent(42);
  const Rng untouched(42);
  Rng child_a = parent.Fork(3);
  Rng child_b = parent.Fork(3);
  Rng named_a = parent.Fork("leaves");
  Rng named_b = parent.Fork("leaves");
  for (int i = 0; i < 100; ++i) {
    ASSERT_EQ(child_a.NextU64(), child_b.NextU64());
    ASSERT_EQ(named_a.NextU64(), named_b.NextU64());
  }
  // The parent still produces the seed-42 sequence.
  Rng reference = untouched;
  for (int i = 0; i < 100; ++i) ASSERT_EQ(parent.NextU64(), reference.NextU64());
  // Forking depends on (seed, stream), not on how far the parent has advanced.
  EXPECT_EQ(parent.Fork(3).NextU64(), Rng(42).Fork(3).NextU64());
  EXPECT_EQ(parent.Fork(3).seed(), Rng(42).Fork(3).seed());
}

TEST(RngTest, ForkedStreamsDifferFromEachOtherAndFromTheParent) {
  const Rng parent(42);
  std::vector<Rng> streams = {parent,
                              parent.Fork(uint64_t{0}),
                              parent.Fork(1),
                              parent.Fork(2),
                              parent.Fork("leaves"),
                              parent.Fork("fruit"),
                              parent.Fork(""),
                              parent.Fork(uint64_t{0}).Fork(uint64_t{0})};
  std::set<uint64_t> first_outputs;
  for (Rng& s : streams) first_outputs.insert(s.NextU64());
  EXPECT_EQ(first_outputs.size(), streams.size());
}

TEST(RngTest, ForkSeedsDoNotCollideAcrossSeedsAndStreams) {
  // Every (seed, stream) pair over small seeds and small streams -- the common case, e.g. seeds
  // 0..N of an experiment and Fork(step) -- must give a different child. A symmetric combination
  // of seed and stream would make Rng(a).Fork(b) equal Rng(b + 1).Fork(a - 1).
  std::set<uint64_t> child_seeds;
  std::set<uint64_t> first_outputs;
  constexpr int kN = 64;
  for (uint64_t seed = 0; seed < kN; ++seed) {
    for (uint64_t stream = 0; stream < kN; ++stream) {
      Rng child = Rng(seed).Fork(stream);
      child_seeds.insert(child.seed());
      first_outputs.insert(child.NextU64());
    }
  }
  EXPECT_EQ(child_seeds.size(), static_cast<size_t>(kN * kN));
  EXPECT_EQ(first_outputs.size(), static_cast<size_t>(kN * kN));
  EXPECT_NE(Rng(1).Fork(uint64_t{0}).NextU64(), Rng(2).Fork(1).NextU64());
  EXPECT_NE(Rng(5).Fork(9).NextU64(), Rng(10).Fork(4).NextU64());
}

TEST(RngTest, ForkedStreamsAreUncorrelated) {
  const Rng parent(7);
  Rng a = parent.Fork(uint64_t{0});
  Rng b = parent.Fork(1);
  Rng c = parent;
  constexpr int kN = 20000;
  double sab = 0;
  double sac = 0;
  for (int i = 0; i < kN; ++i) {
    const double x = a.Uniform01() - 0.5;
    sab += x * (b.Uniform01() - 0.5);
    sac += x * (c.Uniform01() - 0.5);
  }
  // Correlation coefficient = mean(xy) / var, var = 1/12; its sd is ~1/sqrt(N) = 0.007.
  EXPECT_LT(std::abs(sab / kN * 12), 0.035);
  EXPECT_LT(std::abs(sac / kN * 12), 0.035);
}

TEST(RngTest, GoldenFork) {
  // Pinned so that a change of the derivation shows up as a deliberate golden update.
  const Rng parent(42);
  EXPECT_EQ(parent.Fork(uint64_t{0}).seed(), 6785915167558037768ULL);
  EXPECT_EQ(parent.Fork(uint64_t{0}).NextU64(), 9182676265018412158ULL);
  EXPECT_EQ(parent.Fork("render-noise").seed(), 18093880141842341902ULL);
  EXPECT_EQ(parent.Fork("render-noise").NextU64(), 2656705170108034038ULL);
  // A child is a plain generator seeded with its derived seed.
  EXPECT_EQ(parent.Fork(5).NextU64(), std::mt19937_64(parent.Fork(5).seed())());
  // Named streams hash the name with 64-bit FNV-1a (reference vectors: "" -> offset basis,
  // "a" -> 0xaf63dc4c8601ec8c).
  EXPECT_EQ(parent.Fork("").seed(), parent.Fork(0xcbf29ce484222325ULL).seed());
  EXPECT_EQ(parent.Fork("a").seed(), parent.Fork(0xaf63dc4c8601ec8cULL).seed());
}

// ---- Distributions -----------------------------------------------------------------------------

TEST(RngTest, Uniform01IsInHalfOpenUnitIntervalWithMeanOneHalf) {
  Rng rng(1);
  constexpr int kN = 100000;
  double sum = 0;
  double sum_sq = 0;
  double lo = 1;
  double hi = 0;
  for (int i = 0; i < kN; ++i) {
    const double x = rng.Uniform01();
    ASSERT_GE(x, 0.0);
    ASSERT_LT(x, 1.0);
    sum += x;
    sum_sq += x * x;
    lo = std::min(lo, x);
    hi = std::max(hi, x);
  }
  const double mean = sum / kN;
  // sd of the mean = sqrt(1/12 / N) = 0.0009; 5 sd.
  EXPECT_NEAR(mean, 0.5, 0.0046);
  EXPECT_NEAR(sum_sq / kN - mean * mean, 1.0 / 12.0, 0.002);
  EXPECT_LT(lo, 1e-3);
  EXPECT_GT(hi, 1 - 1e-3);
}

TEST(RngTest, UniformRange) {
  Rng rng(2);
  double sum = 0;
  for (int i = 0; i < 10000; ++i) {
    const double x = rng.Uniform(-3.0, 5.0);
    ASSERT_GE(x, -3.0);
    ASSERT_LT(x, 5.0);
    sum += x;
  }
  EXPECT_NEAR(sum / 10000, 1.0, 0.12);  // sd of the mean = 8 / sqrt(12 * 1e4) = 0.023
}

TEST(RngTest, NormalMomentsAndShape) {
  Rng rng(3);
  constexpr int kN = 100000;
  double sum = 0;
  double sum_sq = 0;
  int within_one_sigma = 0;
  for (int i = 0; i < kN; ++i) {
    const double x = rng.Normal();
    ASSERT_TRUE(std::isfinite(x));
    sum += x;
    sum_sq += x * x;
    within_one_sigma += std::abs(x) < 1.0 ? 1 : 0;
  }
  const double mean = sum / kN;
  const double sd = std::sqrt(sum_sq / kN - mean * mean);
  EXPECT_NEAR(mean, 0.0, 0.016);  // 5 / sqrt(N)
  EXPECT_NEAR(sd, 1.0, 0.012);    // 5 / sqrt(2N)
  // P(|x| < 1) = 0.682689; sd of the fraction = 0.0015.
  EXPECT_NEAR(static_cast<double>(within_one_sigma) / kN, 0.682689, 0.0075);
}

TEST(RngTest, NormalWithMeanAndStddev) {
  Rng rng(4);
  constexpr int kN = 50000;
  double sum = 0;
  double sum_sq = 0;
  for (int i = 0; i < kN; ++i) {
    const double x = rng.Normal(3.0, 0.5);
    sum += x;
    sum_sq += x * x;
  }
  const double mean = sum / kN;
  EXPECT_NEAR(mean, 3.0, 5 * 0.5 / std::sqrt(kN));
  EXPECT_NEAR(std::sqrt(sum_sq / kN - mean * mean), 0.5, 5 * 0.5 / std::sqrt(2.0 * kN));
}

TEST(RngTest, UniformIntHitsBothBoundsAndIsRoughlyUniform) {
  Rng rng(5);
  constexpr int64_t kLo = -3;
  constexpr int64_t kHi = 3;
  constexpr int kBins = 7;
  constexpr int kN = 70000;
  std::array<int, kBins> counts{};
  for (int i = 0; i < kN; ++i) {
    const int64_t x = rng.UniformInt(kLo, kHi);
    ASSERT_GE(x, kLo);
    ASSERT_LE(x, kHi);
    ++counts[static_cast<size_t>(x - kLo)];
  }
  double chi_square = 0;
  const double expected = static_cast<double>(kN) / kBins;
  for (const int c : counts) {
    EXPECT_GT(c, 0);
    chi_square += (c - expected) * (c - expected) / expected;
  }
  // 6 degrees of freedom: P(chi^2 > 22.46) = 0.001.
  EXPECT_LT(chi_square, 22.46);
}

TEST(RngTest, UniformIntEdgeRanges) {
  Rng rng(6);
  for (int i = 0; i < 10; ++i) EXPECT_EQ(rng.UniformInt(5, 5), 5);
  constexpr int64_t kMin = std::numeric_limits<int64_t>::min();
  constexpr int64_t kMax = std::numeric_limits<int64_t>::max();
  bool negative = false;
  bool positive = false;
  for (int i = 0; i < 100; ++i) {
    const int64_t x = rng.UniformInt(kMin, kMax);
    negative |= x < 0;
    positive |= x > 0;
  }
  EXPECT_TRUE(negative && positive);
  // Ranges wider than INT64_MAX but not the full range: the offset from lo no longer fits an
  // int64_t (sanitizer builds check the arithmetic).
  for (int i = 0; i < 100; ++i) {
    const int64_t x = rng.UniformInt(kMin, kMax - 1);
    ASSERT_LT(x, kMax);
    const int64_t y = rng.UniformInt(kMin + 1, kMax);
    ASSERT_GT(y, kMin);
  }
  for (int i = 0; i < 1000; ++i) {
    const int64_t x = rng.UniformInt(-2, kMax);
    ASSERT_GE(x, -2);
    const int64_t y = rng.UniformInt(kMin, 2);
    ASSERT_LE(y, 2);
  }
  // Two values: both come up about equally often.
  int ones = 0;
  for (int i = 0; i < 10000; ++i) ones += static_cast<int>(rng.UniformInt(0, 1));
  EXPECT_NEAR(ones, 5000, 250);
}

TEST(RngTest, UniformIntRejectsEmptyRange) {
  Rng rng(7);
  try {
    (void)rng.UniformInt(3, 2);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("lo = 3, hi = 2"));
  }
}

TEST(RngTest, Bernoulli) {
  Rng rng(8);
  int heads = 0;
  for (int i = 0; i < 20000; ++i) heads += rng.Bernoulli(0.3) ? 1 : 0;
  EXPECT_NEAR(heads / 20000.0, 0.3, 0.017);  // sd 0.0032
  for (int i = 0; i < 1000; ++i) {
    ASSERT_FALSE(rng.Bernoulli(0.0));
    ASSERT_TRUE(rng.Bernoulli(1.0));
  }
}

}  // namespace
}  // namespace avp

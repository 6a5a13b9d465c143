#include <cmath>
#include <string_view>

#include <avp/core/error.h>
#include <avp/core/rng.h>

namespace avp {

uint64_t MixSeed(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

Rng Rng::Fork(uint64_t stream) const {
  // Seed and stream go through different hashes: the symmetric MixSeed(seed) ^ MixSeed(stream + 1)
  // made Rng(a).Fork(b) equal Rng(b + 1).Fork(a - 1), e.g. Rng(1).Fork(0) == Rng(2).Fork(1).
  return Rng(MixSeed(MixSeed(seed_) + MixSeed(MixSeed(stream))));
}

Rng Rng::Fork(std::string_view stream_name) const {
  // FNV-1a over the name: stable across platforms.
  uint64_t h = 0xcbf29ce484222325ULL;
  for (char c : stream_name) {
    h ^= static_cast<uint8_t>(c);
    h *= 0x100000001b3ULL;
  }
  return Fork(h);
}

int64_t Rng::UniformInt(int64_t lo, int64_t hi) {
  AVP_THROW_UNLESS(lo <= hi, lo, hi);
  const uint64_t range = static_cast<uint64_t>(hi) - static_cast<uint64_t>(lo);
  if (range == UINT64_MAX) return static_cast<int64_t>(engine_());
  const uint64_t n = range + 1;
  const uint64_t limit = UINT64_MAX - (UINT64_MAX % n);  // reject the biased tail
  uint64_t x;
  do {
    x = engine_();
  } while (x >= limit);
  // In unsigned arithmetic: lo + offset overflows int64_t for ranges wider than INT64_MAX.
  return static_cast<int64_t>(static_cast<uint64_t>(lo) + x % n);
}

double Rng::Normal() {
  if (has_spare_normal_) {
    has_spare_normal_ = false;
    return spare_normal_;
  }
  double u1 = Uniform01();
  while (u1 <= 0.0) u1 = Uniform01();
  const double u2 = Uniform01();
  const double r = std::sqrt(-2.0 * std::log(u1));
  const double theta = 2.0 * M_PI * u2;
  spare_normal_ = r * std::sin(theta);
  has_spare_normal_ = true;
  return r * std::cos(theta);
}

}  // namespace avp

#pragma once

#include <algorithm>
#include <cmath>

namespace avp {

/// H_b(p) = -p log2 p - (1 - p) log2(1 - p) in bits: 0 at p = 0 and p = 1 (the limit) and for p
/// outside [0, 1]; NaN for NaN.
inline double BinaryEntropyBits(double p) {
  if (std::isnan(p)) return p;
  if (p <= 0.0 || p >= 1.0) return 0.0;
  return -p * std::log2(p) - (1.0 - p) * std::log2(1.0 - p);
}

/// H_b of p clamped to [1e-6, 1 - 1e-6], NaN counted as 0.5: never NaN, never exactly 0 (the
/// reference system logged NaN for confidences of 0 and 1).
inline double ClampedBinaryEntropyBits(double p) {
  constexpr double kEps = 1e-6;
  return BinaryEntropyBits(std::isnan(p) ? 0.5 : std::clamp(p, kEps, 1.0 - kEps));
}

}  // namespace avp

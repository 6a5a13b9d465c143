#pragma once

#include <cmath>
#include <cstdint>
#include <functional>

#include <Eigen/Core>

namespace avp {

/// Integer voxel coordinates on a grid of edge `voxel_size_m` anchored at the world origin:
/// voxel k covers [k * s, (k + 1) * s) on each axis, its centre is (k + 0.5) * s. This is the same
/// lattice as OctoMap's keys (key = k + 32768), so our voxels and OctoMap's coincide.
struct VoxelKey {
  int32_t x = 0;
  int32_t y = 0;
  int32_t z = 0;

  static VoxelKey FromPoint(const Eigen::Vector3d& p, double voxel_size_m) {
    const double inv = 1.0 / voxel_size_m;
    return {Floor(p.x() * inv), Floor(p.y() * inv), Floor(p.z() * inv)};
  }
  /// floor(v) as a key coordinate, without a libm call (baseline x86-64 has no rounding
  /// instruction): the same value as static_cast<int32_t>(std::floor(v)) wherever that is defined.
  static int32_t Floor(double v) {
    const auto t = static_cast<int64_t>(v);  // truncates toward zero
    return static_cast<int32_t>(t - static_cast<int64_t>(v < static_cast<double>(t)));
  }
  Eigen::Vector3d Center(double voxel_size_m) const {
    return {(x + 0.5) * voxel_size_m, (y + 0.5) * voxel_size_m, (z + 0.5) * voxel_size_m};
  }

  friend bool operator==(const VoxelKey&, const VoxelKey&) = default;
  friend auto operator<=>(const VoxelKey&, const VoxelKey&) = default;
};

struct VoxelKeyHash {
  size_t operator()(const VoxelKey& k) const {
    // Large primes (Teschner et al. 2003), mixed into 64 bits.
    const uint64_t h = static_cast<uint64_t>(static_cast<uint32_t>(k.x)) * 73856093ULL ^
                       static_cast<uint64_t>(static_cast<uint32_t>(k.y)) * 19349663ULL ^
                       static_cast<uint64_t>(static_cast<uint32_t>(k.z)) * 83492791ULL;
    return static_cast<size_t>(h ^ (h >> 29));
  }
};

}  // namespace avp

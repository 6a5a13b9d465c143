#pragma once

#include <unordered_map>
#include <vector>

#include <avp/core/voxel_key.h>
#include <avp/sim/scene.h>

namespace avp::sim {

/// The fruit surface voxelised at `voxel_size_m`: every voxel (on the VoxelKey lattice) that the
/// surface of a fruit object passes through, mapped to that fruit's instance id (the smaller id
/// where two fruits share a voxel).
struct FruitVoxels {
  double voxel_size_m = 0.0;
  std::unordered_map<VoxelKey, uint16_t, VoxelKeyHash> voxels;

  /// Keys in ascending (x, y, z) order; handy for deterministic output.
  std::vector<VoxelKey> SortedKeys() const;
};

/// @throws avp::Error if voxel_size_m is not finite and > 0.
FruitVoxels VoxelizeFruitSurfaces(const Scene& scene, double voxel_size_m);

/// Every voxel (on the VoxelKey lattice) that the surface of a solid object passes through: every
/// object but the background and the ground (the motion planner's ground is a declared plane),
/// ascending, each once. What the arm must not touch, as only a simulator knows it
/// (RunConfig::oracle_motion). @throws avp::Error as VoxelizeFruitSurfaces.
std::vector<VoxelKey> VoxelizeObstacleSurfaces(const Scene& scene, double voxel_size_m);

}  // namespace avp::sim

// Fuzz target: the OctoMap import (mapping/octomap_io.h) of a .bt or .ot file with any contents,
// through ImportOctomapOccupiedBytes (the reader of ImportOctomapOccupied, on bytes in memory).
// Property: an import that succeeds returns sorted, unique keys and a positive resolution; the
// same bytes read as a map (ImportOctomapMapBytes, the OctoMap half of mapping::LoadAnyMap) hold
// exactly as many occupied voxels whenever both succeed.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>

#include <avp/mapping/octomap_io.h>

#include "fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  avp::Result<avp::mapping::VoxelSet> set =
      avp::mapping::ImportOctomapOccupiedBytes(bytes, "fuzz-input.ot");
  if (!set.ok()) return 0;
  const auto& keys = set->keys;
  const auto less = [](const avp::VoxelKey& a, const avp::VoxelKey& b) {
    return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
  };
  if (!std::is_sorted(keys.begin(), keys.end(), less) ||
      std::adjacent_find(keys.begin(), keys.end()) != keys.end()) {
    avp::fuzz::Fail("ImportOctomapOccupiedBytes returned keys that are not sorted and unique");
  }
  if (!(set->resolution_m > 0.0)) avp::fuzz::Fail("ImportOctomapOccupiedBytes: resolution <= 0");
  // Small enough that a crafted pruned leaf cannot make the map reader allocate much.
  const avp::Result<avp::mapping::OctomapMapImport> map =
      avp::mapping::ImportOctomapMapBytes(bytes, "fuzz-input.ot", size_t{1} << 20);
  if (map.ok() && map->map.grid().CountOccupiedVoxels() != keys.size()) {
    avp::fuzz::Fail(
        "ImportOctomapMapBytes and ImportOctomapOccupiedBytes disagree on the occupied "
        "voxels");
  }
  return 0;
}

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

namespace {
// Both readers expand coarse leaves to finest voxels, bounded by max_voxels (2^27 by default:
// a 97-byte file with one occupied leaf at depth 8 already expands to 2^24 voxels, 100 s under
// ASan). The bound itself is tested in mapping/test; here it only has to be small enough that
// every input runs in well under libFuzzer's per-input timeout.
constexpr size_t kMaxVoxels = size_t{1} << 16;
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  avp::Result<avp::mapping::VoxelSet> set =
      avp::mapping::ImportOctomapOccupiedBytes(bytes, "fuzz-input.ot", kMaxVoxels);
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
  const avp::Result<avp::mapping::OctomapMapImport> map =
      avp::mapping::ImportOctomapMapBytes(bytes, "fuzz-input.ot", kMaxVoxels);
  if (map.ok() && map->map.grid().CountOccupiedVoxels() != keys.size()) {
    avp::fuzz::Fail(
        "ImportOctomapMapBytes and ImportOctomapOccupiedBytes disagree on the occupied "
        "voxels");
  }
  return 0;
}

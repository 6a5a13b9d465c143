// Fuzz target: the OctoMap import (mapping/octomap_io.h ImportOctomapOccupied) of a .bt or .ot
// file with any contents (the reader takes a path: the bytes go to a scratch file first).
// Property: an import that succeeds returns sorted, unique keys.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include <avp/mapping/octomap_io.h>

#include "fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = avp::fuzz::ScratchDir() / "input.ot";
  avp::fuzz::WriteFile(path, std::string_view(reinterpret_cast<const char*>(data), size));
  avp::Result<avp::mapping::VoxelSet> set = avp::mapping::ImportOctomapOccupied(path);
  if (!set.ok()) return 0;
  const auto& keys = set->keys;
  const auto less = [](const avp::VoxelKey& a, const avp::VoxelKey& b) {
    return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
  };
  if (!std::is_sorted(keys.begin(), keys.end(), less) ||
      std::adjacent_find(keys.begin(), keys.end()) != keys.end()) {
    avp::fuzz::Fail("ImportOctomapOccupied returned keys that are not sorted and unique");
  }
  if (!(set->resolution_m > 0.0)) avp::fuzz::Fail("ImportOctomapOccupied: resolution <= 0");
  return 0;
}

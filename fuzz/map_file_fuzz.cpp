// Fuzz target: the .avpmap reader (mapping/map_file.h DeserializeMap) on any bytes.
//
// Each input is read twice: as it is (the magic, version, size and checksum checks), and, when it
// is long enough, with its declared size (u64 at byte 16) and its trailing CRC-32 made right
// (docs/map-format.md), so that mutations reach the parser behind the checksum.
// Property: a map that loads serializes, that file loads again, and serializing it once more
// gives the same bytes (SerializeMap is deterministic and loading loses nothing it writes).

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <avp/mapping/map_file.h>

#include "fuzz_target.h"

namespace {

void Load(std::span<const uint8_t> input) {
  using namespace avp::mapping;
  MapFileInfo info;
  avp::Result<SemanticMap> map = DeserializeMap(input, &info);
  if (!map.ok()) return;
  MapSaveOptions save;
  save.note = info.note;
  avp::Result<std::vector<uint8_t>> bytes = SerializeMap(*map, save);
  if (!bytes.ok()) avp::fuzz::Fail("a loaded map does not serialize: " + bytes.status().ToString());
  avp::Result<SemanticMap> again = DeserializeMap(*bytes);
  if (!again.ok()) {
    avp::fuzz::Fail("a serialized map does not load: " + again.status().ToString());
  }
  avp::Result<std::vector<uint8_t>> bytes2 = SerializeMap(*again, save);
  if (!bytes2.ok() || *bytes2 != *bytes) avp::fuzz::Fail("save -> load -> save changed the bytes");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::span<const uint8_t> input(data, size);
  Load(input);
  if (size >= 28) {
    std::vector<uint8_t> fixed(data, data + size);
    for (int i = 0; i < 8; ++i) fixed[16 + i] = static_cast<uint8_t>(uint64_t{size} >> (8 * i));
    const uint32_t crc = avp::mapping::Crc32(std::span<const uint8_t>(fixed).first(size - 4));
    for (int i = 0; i < 4; ++i) fixed[size - 4 + i] = static_cast<uint8_t>(crc >> (8 * i));
    if (fixed != std::vector<uint8_t>(data, data + size)) Load(fixed);
  }
  return 0;
}

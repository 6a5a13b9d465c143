#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include <avp/core/limits.h>
#include <avp/core/status.h>
#include <avp/mapping/semantic_map.h>

namespace avp::mapping {

/// avp's own map file (`.avpmap`): a versioned, explicitly little-endian binary format that keeps
/// everything a SemanticMap holds (options, every known voxel's log-odds, every semantic cell) and
/// ends with a CRC-32 of all preceding bytes. Byte layout: docs/map-format.md.
///
/// Loading never trusts the file: the magic, the version, the declared size and the checksum are
/// checked before anything is parsed, every size is bounded by the bytes that remain before
/// anything is allocated, and every value is validated; errors name what is wrong ("bad magic",
/// "unsupported version 7", "checksum mismatch", "truncated at byte 1234 ...").

/// The 8 bytes every map file starts with: 0x89 'A' 'V' 'P' 'M' 'A' 'P' '\n'.
inline constexpr char kMapFileMagic[8] = {'\x89', 'A', 'V', 'P', 'M', 'A', 'P', '\n'};
/// The version this build writes: its header names the map's options as MapOptionTable does
/// ("grid.voxel_size_m" = "0.005", ...), so a new option needs no new format. This build also
/// reads version 1, whose header had fixed option fields.
inline constexpr uint32_t kMapFileVersion = 2;
/// Longest free-form note stored in a file, bytes.
inline constexpr size_t kMaxMapNoteBytes = 65535;

/// What a file says about itself (filled by LoadMap / DeserializeMap).
struct MapFileInfo {
  uint32_t version = 0;
  uint64_t file_bytes = 0;
  uint32_t crc32 = 0;
  uint64_t num_blocks = 0;
  uint64_t known_voxels = 0;
  uint64_t occupied_voxels = 0;
  /// Semantic cells with any evidence (labelled or not) stored in the file.
  uint64_t semantic_cells = 0;
  /// Cells with a semantic label.
  uint64_t labelled_voxels = 0;
  /// Free-form note written with the map (how it was made), may be empty.
  std::string note;
};

struct MapSaveOptions {
  /// Free-form UTF-8 note stored in the header (at most kMaxMapNoteBytes), e.g. the command line
  /// that built the map.
  std::string note;
};

/// max_map_blocks: 8^3-voxel blocks of one map read from a file, 2^21 (2097152, about 4.8 GB in
/// memory) by default; checked on the header's count before any block is allocated.
const Limit& MaxMapBlocks();

/// The file's bytes for `map`. Deterministic: the same voxels give the same bytes. Blocks are
/// written sorted by key, and blocks with no known voxel and no semantic payload (allocated but
/// never reached) are left out, so neither the order in which blocks were allocated nor the
/// number of threads that integrated the map changes the file.
/// Errors: InvalidArgument when the note is too long.
Result<std::vector<uint8_t>> SerializeMap(const SemanticMap& map,
                                          const MapSaveOptions& options = {});

/// Parses SerializeMap's bytes. The returned map has its semantic bookkeeping restored
/// (SemanticFusion::ResetFromGrid) and no pending changes. `info` (optional) receives the header.
/// Errors: ParseError naming what is wrong; never crashes on any input.
Result<SemanticMap> DeserializeMap(std::span<const uint8_t> bytes, MapFileInfo* info = nullptr);

/// Writes the map atomically (a temporary file beside `path`, then rename); creates parent folders.
Status SaveMap(const SemanticMap& map, const std::filesystem::path& path,
               const MapSaveOptions& options = {});

/// Reads a map file; errors name the path and what is wrong with it: NotFound, InvalidArgument (a
/// folder), ResourceExhausted (max_file_bytes, max_map_blocks), IoError, ParseError.
Result<SemanticMap> LoadMap(const std::filesystem::path& path, MapFileInfo* info = nullptr);

/// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320, as zlib's crc32 and PNG): `crc` is the
/// value so far (0 to start), so Crc32(b, Crc32(a)) == Crc32(a ++ b).
uint32_t Crc32(std::span<const uint8_t> bytes, uint32_t crc = 0);

}  // namespace avp::mapping

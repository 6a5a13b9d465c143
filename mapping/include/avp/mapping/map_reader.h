#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/semantic_map.h>

namespace avp::mapping {

// ---- One map reader ----------------------------------------------------------------------------
//
// LoadAnyMap reads every map file avp knows as a SemanticMap: avp's own map file (.avpmap, all of
// it) and OctoMap trees (.bt: occupancy; .ot: OcTree log-odds, ColorOcTree log-odds and colours,
// avp's class colours read back as classes). The format comes from the file's first bytes (its
// magic or header line), never from its name. docs/map-format.md, "Reading any map file".

enum class MapFileFormat {
  kAvpMap,         ///< avp's map file: magic 0x89 "AVPMAP\n"
  kOctomapBinary,  ///< "# Octomap OcTree binary file" (.bt)
  kOctomapTree,    ///< "# Octomap OcTree file" (.ot)
};
/// "avpmap", "bt", "ot".
std::string_view ToString(MapFileFormat format);
/// The usual extension of the format, with the dot: ".avpmap", ".bt", ".ot".
std::string_view MapFileExtension(MapFileFormat format);

/// The format a file's first bytes announce; nullopt when none.
std::optional<MapFileFormat> DetectMapFileFormat(std::string_view first_bytes);

/// Where a map came from and what reading it kept and lost.
struct MapSource {
  std::filesystem::path path;
  MapFileFormat format = MapFileFormat::kAvpMap;
  uint64_t file_bytes = 0;
  double resolution_m = 0.0;
  /// .avpmap: its header.
  MapFileInfo avpmap;
  /// OctoMap: the tree (leaves, colours, free space dropped ...).
  std::string tree_type;  ///< "OcTree", "ColorOcTree"; empty for .avpmap
  uint64_t tree_nodes = 0;
  size_t occupied_leaves = 0;
  size_t free_leaves = 0;
  size_t coarse_leaves = 0;
  bool free_space_dropped = false;
  size_t labelled_by_colour = 0;
  size_t unlabelled_grey = 0;
  size_t foreign_colour = 0;
  /// The file carries semantic labels (an .avpmap with labelled voxels, a ColorOcTree with voxels
  /// in class colours).
  bool has_labels = false;
  /// What the file cannot hold or reading it did not keep, one sentence each (empty for .avpmap).
  std::vector<std::string> lost;
  /// The extension names another format than the content (e.g. an .ot file holding a .bt tree);
  /// empty otherwise.
  std::string extension_note;
};

struct LoadedMap {
  SemanticMap map;
  MapSource source;
};

struct LoadAnyMapOptions {
  /// OctoMap: the most finest-resolution voxels the occupied leaves may expand to (OutOfRange
  /// above), and the free leaves (free space is dropped above).
  size_t max_voxels = size_t{1} << 27;
};

/// Reads a map file of any supported format (see above). The file is checked as LoadMap and
/// ImportOctomapMapBytes check it (max_file_bytes, headers, checksums, max_map_blocks,
/// max_octomap_nodes, the tree walked before OctoMap reads it); every error names the file.
/// Errors: NotFound, InvalidArgument (a folder), ResourceExhausted, IoError, ParseError (neither
/// format: names the first bytes; broken content: names what and where), OutOfRange.
Result<LoadedMap> LoadAnyMap(const std::filesystem::path& path,
                             const LoadAnyMapOptions& options = {});
/// The same on bytes already in memory; `path` names them in errors.
Result<LoadedMap> LoadAnyMapBytes(const std::string& bytes, const std::filesystem::path& path,
                                  const LoadAnyMapOptions& options = {});

/// The ground-truth voxels a loaded map stands for: its occupied voxels labelled `cls` when the
/// file carries labels (MapSource::has_labels), otherwise all its occupied voxels (a .bt or an
/// unlabelled tree is a set of ground-truth voxels). `used_labels` (optional) says which.
VoxelSet GroundTruthVoxels(const LoadedMap& loaded, SemanticClass cls, bool* used_labels = nullptr);
/// The same for a map in memory and where it came from.
VoxelSet GroundTruthVoxels(const SemanticMap& map, const MapSource& source, SemanticClass cls,
                           bool* used_labels = nullptr);

}  // namespace avp::mapping

#pragma once

// What `avp map info / export / compare` do, for any map file LoadAnyMap reads (.avpmap, .bt,
// .ot): describe it, convert it, and score it against a ground-truth file (docs/mapping.md,
// docs/map-format.md).

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include <avp/core/box.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/voxel_key.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/map_reader.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/ply_export.h>
#include <avp/mapping/semantics.h>

namespace avp::mapping {

// ---- Info ---------------------------------------------------------------------------------------

/// Any map file LoadAnyMap reads (.avpmap, .bt, .ot): `file` is the .avpmap header (empty for
/// OctoMap files), `source` says what the file was and what reading it kept.
struct MapInfo {
  std::filesystem::path path;
  MapFileInfo file;
  MapSource source;
  MapOptions options;
  size_t blocks = 0;
  size_t semantic_blocks = 0;
  size_t known_voxels = 0;
  size_t free_voxels = 0;
  size_t occupied_voxels = 0;
  size_t labelled_voxels = 0;
  /// Labelled voxels per class (all / occupied only), indexed by SemanticClass value.
  std::array<size_t, kNumSemanticClasses> labelled_by_class{};
  std::array<size_t, kNumSemanticClasses> occupied_by_class{};
  std::vector<InstanceInfo> instances;
  Box3 known_bounds;
  size_t memory_bytes = 0;
};

/// Errors: an unreadable file, LoadAnyMap's (a corrupt or unknown map file), naming the file.
Result<MapInfo> ReadMapInfo(const std::filesystem::path& path);
/// The report `avp map info` prints (docs/map-format.md shows one).
std::string FormatMapInfo(const MapInfo& info);

// ---- Export -------------------------------------------------------------------------------------

enum class MapExportFormat { kBt, kOt, kPly, kAvpMap };
/// "bt", "ot", "ply", "avpmap"; nullopt otherwise.
std::optional<MapExportFormat> MapExportFormatFromString(std::string_view name);

/// The input may be any map file LoadAnyMap reads (.avpmap, .bt, .ot): e.g. .ot -> .avpmap.
struct MapExportOptions {
  std::filesystem::path map;
  /// Empty: taken from the extension of `out`.
  std::string format;
  std::filesystem::path out;
  bool ply_ascii = false;
  /// PLY: which voxels (`--voxels`; `--all-labelled` is kAllLabelled). Any other format refuses
  /// a value other than the default kLabelled.
  PlyVoxels ply_voxels = PlyVoxels::kLabelled;
};
struct MapExportSummary {
  MapExportFormat format = MapExportFormat::kBt;
  std::filesystem::path out;
  size_t occupied_voxels = 0;  ///< bt / ot / avpmap; ply: occupied vertices
  size_t free_voxels = 0;      ///< bt / ot / avpmap
  /// ot: coloured by class; ply: labelled vertices (class colour); avpmap: labelled.
  size_t labelled_voxels = 0;
  /// ply, --voxels occupied: vertices of occupied voxels without a label (grey, class 0).
  size_t unlabelled_voxels = 0;
  /// ply, --voxels all-labelled: labelled vertices of voxels that are not occupied.
  size_t not_occupied_voxels = 0;
  PlyVoxels ply_voxels = PlyVoxels::kLabelled;  ///< ply: which voxels were written
  uint64_t file_bytes = 0;
  MapSource source;  ///< what was read
};
/// Errors: an unknown format, an output that is the input, the reader's and the writer's.
Result<MapExportSummary> ExportMapFile(const MapExportOptions& options);
/// The same for a map in memory (`options.map` is not read; the output may not be
/// `source.path`, the file the map came from, when it has one).
Result<MapExportSummary> ExportMap(const SemanticMap& map, const MapSource& source,
                                   const MapExportOptions& options);

// ---- Compare ------------------------------------------------------------------------------------

/// Both files may be any map file LoadAnyMap reads. The ground truth is the GT file's occupied
/// voxels labelled `semantic_class` when it carries labels (an .avpmap, a ColorOcTree in class
/// colours), otherwise all its occupied voxels (.bt, OcTree).
struct MapCompareOptions {
  std::filesystem::path map;
  std::filesystem::path gt;
  /// Results are given exactly (0) and, when > 0, with this Chebyshev tolerance in map voxels.
  int tolerance_voxels = 1;
  SemanticClass semantic_class = SemanticClass::kFruit;
  /// Also write the result as JSON here (empty: no file).
  std::filesystem::path json_out;
};
struct MapCompareSummary {
  std::filesystem::path map;
  std::filesystem::path gt;
  SemanticClass semantic_class = SemanticClass::kFruit;
  size_t gt_occupied_leaves = 0;
  size_t gt_coarse_leaves = 0;
  MapSource map_source;
  MapSource gt_source;
  /// The GT file carried labels and only its voxels of `semantic_class` were taken.
  bool gt_used_labels = false;
  /// Exact first, then the tolerance (when > 0).
  std::vector<GroundTruthComparison> results;
  /// Lattice check: the exact F1 after moving every predicted voxel by the one-voxel shift
  /// (each component in {-1, 0, 1}, not all 0) that raises it most; a large gain over the
  /// unshifted exact F1 means the two sides' surfaces sit a voxel apart (a frame or lattice
  /// offset, or a different surface definition), not that the map is wrong.
  VoxelKey best_shift;
  double best_shift_f1 = 0.0;
};
/// Errors: a tolerance out of range, unreadable or corrupt files, a JSON output that is an input.
Result<MapCompareSummary> CompareMapFiles(const MapCompareOptions& options);
/// The same for maps in memory (`map`, where it came from, and a ground truth read: options.map,
/// gt and json_out are not read; the summary's map and gt name options.map and options.gt).
Result<MapCompareSummary> CompareMaps(const SemanticMap& map, const MapSource& source,
                                      const SemanticMap& gt, const MapSource& gt_source,
                                      const MapCompareOptions& options);
std::string FormatMapCompare(const MapCompareSummary& summary);
nlohmann::json ToJson(const MapCompareSummary& summary);

/// "1.5 KiB", "3.2 MiB": a byte count for people.
std::string HumanBytes(uint64_t bytes);

}  // namespace avp::mapping

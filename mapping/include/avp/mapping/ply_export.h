#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string_view>

#include <avp/core/status.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::mapping {

/// Which voxels ExportSemanticPly writes (`avp map export --voxels`).
enum class PlyVoxels : uint8_t {
  /// Labelled voxels that are occupied (the default, and a run's fruit_voxels.ply).
  kLabelled,
  /// Every labelled voxel, occupied or not (`--all-labelled`).
  kAllLabelled,
  /// Every occupied voxel: the whole reconstructed plant. Labelled ones in their class colour,
  /// unlabelled ones in avp's unlabelled grey (kUnlabelledOccupiedColor, octomap_io.h: the .ot
  /// export's, so a voxel looks the same in MeshLab and octovis); labelled voxels that are not
  /// occupied are left out.
  kOccupied,
};
/// "labelled", "all-labelled", "occupied".
std::string_view ToString(PlyVoxels voxels);
/// Inverse of ToString; nullopt for any other name.
std::optional<PlyVoxels> PlyVoxelsFromString(std::string_view name);

struct PlyExportOptions {
  /// binary_little_endian 1.0 (default) or ascii 1.0.
  bool binary = true;
  PlyVoxels voxels = PlyVoxels::kLabelled;
};

struct PlyExportStats {
  size_t vertices = 0;    ///< voxels written: labelled + unlabelled
  size_t labelled = 0;    ///< written with a semantic label (class colour)
  size_t unlabelled = 0;  ///< written without one (kOccupied only; grey, class 0)
  /// Labelled voxels written although not occupied (kAllLabelled only; part of `labelled`).
  size_t not_occupied = 0;
  /// Labelled voxels left out because they are not occupied (kLabelled, kOccupied).
  size_t skipped_not_occupied = 0;
  size_t file_bytes = 0;
};

/// Visits the voxels `voxels` selects, in ExportSemanticPly's order (below), each with its
/// semantic cell (null for an unlabelled voxel, kOccupied only) and whether it is occupied (always
/// for kLabelled and kOccupied). Returns how many labelled voxels were left out because they are
/// not occupied (kLabelled, kOccupied). What the PLY file and avp's Python module
/// (`avp.Map.voxels`) hold, from this one place.
size_t ForEachExportedVoxel(
    const OccupancyGrid& grid, PlyVoxels voxels,
    const std::function<void(const VoxelKey&, const SemanticCell*, bool occupied)>& fn);

/// Writes the map's voxels chosen by `options.voxels` as a PLY point cloud, one vertex per voxel,
/// in the grid's deterministic order (labelled voxels: semantic blocks in allocation order;
/// kOccupied: every block in allocation order), with the properties
///   float x, y, z            voxel centre, metres, world frame
///   uchar red, green, blue   class colour (io::ClassColor: fruit red, leaf green, ...);
///                            kUnlabelledOccupiedColor (grey) for an unlabelled voxel
///   uchar class              SemanticClass value (0, kBackground, for an unlabelled voxel)
///   float confidence         SemanticCell::confidence (0 for an unlabelled voxel)
///   ushort instance          instance id (0 = none, as for an unlabelled voxel)
///   ushort observations      frames in which a mask covered the voxel (0 for an unlabelled one)
/// The header carries `comment voxel_size_m <s>`. Readable by MeshLab, CloudCompare, Open3D.
/// Written atomically and durably (io::WriteFileAtomic): `path` holds the old file or the whole new
/// one, never a truncated one. Errors: IoError naming the path.
Result<PlyExportStats> ExportSemanticPly(const OccupancyGrid& grid,
                                         const std::filesystem::path& path,
                                         const PlyExportOptions& options = {});

}  // namespace avp::mapping

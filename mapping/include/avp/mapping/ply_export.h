#pragma once

#include <cstddef>
#include <filesystem>

#include <avp/core/status.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::mapping {

struct PlyExportOptions {
  /// binary_little_endian 1.0 (default) or ascii 1.0.
  bool binary = true;
  /// Only labelled voxels that are also occupied (default); false: every labelled voxel.
  bool occupied_only = true;
};

struct PlyExportStats {
  size_t vertices = 0;  ///< voxels written
  size_t skipped_not_occupied = 0;
  size_t file_bytes = 0;
};

/// Writes the labelled (semantic) voxels as a PLY point cloud, one vertex per voxel, in the grid's
/// deterministic order, with the properties
///   float x, y, z            voxel centre, metres, world frame
///   uchar red, green, blue   class colour (io::ClassColor: fruit red, leaf green, ...)
///   uchar class              SemanticClass value
///   float confidence         SemanticCell::confidence
///   ushort instance          instance id (0 = none)
///   ushort observations      frames in which a mask covered the voxel
/// The header carries `comment voxel_size_m <s>`. Readable by MeshLab, CloudCompare, Open3D.
/// Written atomically and durably (io::WriteFileAtomic): `path` holds the old file or the whole new
/// one, never a truncated one. Errors: IoError naming the path.
Result<PlyExportStats> ExportSemanticPly(const OccupancyGrid& grid,
                                         const std::filesystem::path& path,
                                         const PlyExportOptions& options = {});

}  // namespace avp::mapping

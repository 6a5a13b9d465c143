#include <array>
#include <bit>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/io/file.h>
#include <avp/io/label_preview.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/ply_export.h>

namespace avp::mapping {

namespace {

void PutU16(std::string& out, uint16_t v) {
  out.push_back(static_cast<char>(v & 0xFF));
  out.push_back(static_cast<char>(v >> 8));
}
void PutU32(std::string& out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
void PutF32(std::string& out, float v) { PutU32(out, std::bit_cast<uint32_t>(v)); }

/// Appends one vertex: the centre of voxel `k`, the colour `rgb` and the semantic fields of `c`
/// (a default SemanticCell, all 0, for an unlabelled voxel).
void AppendVertex(std::string& body, const OccupancyGrid& grid, const VoxelKey& k,
                  const std::array<uint8_t, 3>& rgb, const SemanticCell& c, bool binary) {
  const Eigen::Vector3d p = grid.CenterOf(k);
  if (binary) {
    for (int i = 0; i < 3; ++i) PutF32(body, static_cast<float>(p[i]));
    for (int i = 0; i < 3; ++i) body.push_back(static_cast<char>(rgb[i]));
    body.push_back(static_cast<char>(c.semantic_class));
    PutF32(body, c.confidence);
    PutU16(body, c.instance_id);
    PutU16(body, c.observations);
  } else {
    // Shortest round-trip float formatting ({}), so ASCII and binary carry the same values.
    body += fmt::format("{} {} {} {} {} {} {} {} {} {}\n", static_cast<float>(p.x()),
                        static_cast<float>(p.y()), static_cast<float>(p.z()), rgb[0], rgb[1],
                        rgb[2], c.semantic_class, c.confidence, c.instance_id, c.observations);
  }
}

std::array<uint8_t, 3> ClassRgb(const SemanticCell& c) {
  const auto rgb = io::ClassColor(c.cls());
  return {rgb[0], rgb[1], rgb[2]};
}

/// PlyVoxels::kLabelled and kAllLabelled: the labelled voxels, semantic blocks in allocation order.
void AppendLabelledVoxels(const OccupancyGrid& grid, const PlyExportOptions& options,
                          std::string& body, PlyExportStats& stats) {
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const SemanticCell& c) {
    const bool occupied = grid.State(k) == VoxelState::kOccupied;
    if (!occupied && options.voxels == PlyVoxels::kLabelled) {
      ++stats.skipped_not_occupied;
      return;
    }
    if (!occupied) ++stats.not_occupied;
    ++stats.labelled;
    AppendVertex(body, grid, k, ClassRgb(c), c, options.binary);
  });
}

/// PlyVoxels::kOccupied: every occupied voxel, all blocks in allocation order; labelled ones with
/// their cell, the others grey with class 0.
void AppendOccupiedVoxels(const OccupancyGrid& grid, const PlyExportOptions& options,
                          std::string& body, PlyExportStats& stats) {
  const float occupied = grid.occupied_log_odds();
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    const SemanticCell* cell = grid.Semantic(k);
    const bool labelled = cell != nullptr && cell->has_label();
    if (log_odds < occupied) {
      if (labelled) ++stats.skipped_not_occupied;
      return;
    }
    ++(labelled ? stats.labelled : stats.unlabelled);
    // OctomapVoxelColor: the class colour when labelled, kUnlabelledOccupiedColor otherwise.
    AppendVertex(body, grid, k, OctomapVoxelColor(cell), labelled ? *cell : SemanticCell{},
                 options.binary);
  });
}

}  // namespace

std::string_view ToString(PlyVoxels voxels) {
  switch (voxels) {
    case PlyVoxels::kLabelled:
      return "labelled";
    case PlyVoxels::kAllLabelled:
      return "all-labelled";
    case PlyVoxels::kOccupied:
      return "occupied";
  }
  return "unknown";
}

std::optional<PlyVoxels> PlyVoxelsFromString(std::string_view name) {
  for (PlyVoxels v : {PlyVoxels::kLabelled, PlyVoxels::kAllLabelled, PlyVoxels::kOccupied}) {
    if (name == ToString(v)) return v;
  }
  return std::nullopt;
}

Result<PlyExportStats> ExportSemanticPly(const OccupancyGrid& grid,
                                         const std::filesystem::path& path,
                                         const PlyExportOptions& options) {
  PlyExportStats stats;
  std::string body;
  if (options.voxels == PlyVoxels::kOccupied) {
    AppendOccupiedVoxels(grid, options, body, stats);
  } else {
    AppendLabelledVoxels(grid, options, body, stats);
  }
  stats.vertices = stats.labelled + stats.unlabelled;

  std::string header = "ply\n";
  header += options.binary ? "format binary_little_endian 1.0\n" : "format ascii 1.0\n";
  header += "comment avp semantic voxels (voxel centres, world frame, metres)\n";
  header += fmt::format("comment voxel_size_m {}\n", grid.voxel_size_m());
  header += fmt::format("element vertex {}\n", stats.vertices);
  header +=
      "property float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\n"
      "property uchar class\nproperty float confidence\n"
      "property ushort instance\nproperty ushort observations\n"
      "end_header\n";

  // Atomic and durable (a temporary file, fsync, rename): a kill or a full disk never leaves a
  // truncated PLY behind.
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(path, header + body, "PLY file"));
  stats.file_bytes = header.size() + body.size();
  return stats;
}

}  // namespace avp::mapping

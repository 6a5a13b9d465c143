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

size_t ForEachExportedVoxel(
    const OccupancyGrid& grid, PlyVoxels voxels,
    const std::function<void(const VoxelKey&, const SemanticCell*, bool occupied)>& fn) {
  size_t skipped_not_occupied = 0;
  if (voxels == PlyVoxels::kOccupied) {
    // Every occupied voxel, all blocks in allocation order, each block's semantic cells beside
    // its log-odds (no lookup per voxel: most known voxels are free).
    const float occupied = grid.occupied_log_odds();
    grid.ForEachBlock([&](const OccupancyBlock& b) {
      b.known.ForEachSet([&](int i) {
        const SemanticCell* cell = b.semantics != nullptr ? &(*b.semantics)[i] : nullptr;
        const bool labelled = cell != nullptr && cell->has_label();
        if (b.log_odds[i] < occupied) {
          if (labelled) ++skipped_not_occupied;
          return;
        }
        fn(KeyOf(b.key, i), labelled ? cell : nullptr, true);
      });
    });
    return skipped_not_occupied;
  }
  // The labelled voxels, semantic blocks in allocation order.
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const SemanticCell& c) {
    const bool occupied = grid.State(k) == VoxelState::kOccupied;
    if (!occupied && voxels == PlyVoxels::kLabelled) {
      ++skipped_not_occupied;
      return;
    }
    fn(k, &c, occupied);
  });
  return skipped_not_occupied;
}

Result<PlyExportStats> ExportSemanticPly(const OccupancyGrid& grid,
                                         const std::filesystem::path& path,
                                         const PlyExportOptions& options) {
  PlyExportStats stats;
  std::string body;
  stats.skipped_not_occupied = ForEachExportedVoxel(
      grid, options.voxels, [&](const VoxelKey& k, const SemanticCell* cell, bool occupied) {
        if (cell == nullptr) {
          ++stats.unlabelled;
          // OctomapVoxelColor: kUnlabelledOccupiedColor for an unlabelled voxel.
          AppendVertex(body, grid, k, OctomapVoxelColor(nullptr), SemanticCell{}, options.binary);
          return;
        }
        ++stats.labelled;
        if (!occupied) ++stats.not_occupied;
        AppendVertex(body, grid, k, ClassRgb(*cell), *cell, options.binary);
      });
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

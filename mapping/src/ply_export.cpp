#include <bit>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/io/file.h>
#include <avp/io/label_preview.h>
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

}  // namespace

Result<PlyExportStats> ExportSemanticPly(const OccupancyGrid& grid,
                                         const std::filesystem::path& path,
                                         const PlyExportOptions& options) {
  PlyExportStats stats;
  std::string body;
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const SemanticCell& c) {
    if (options.occupied_only && grid.State(k) != VoxelState::kOccupied) {
      ++stats.skipped_not_occupied;
      return;
    }
    ++stats.vertices;
    const Eigen::Vector3d p = grid.CenterOf(k);
    const auto rgb = io::ClassColor(c.cls());
    if (options.binary) {
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
  });

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

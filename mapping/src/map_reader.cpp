#include <algorithm>
#include <cstring>
#include <span>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/file_kind.h>
#include <avp/mapping/map_reader.h>

namespace avp::mapping {

namespace {

namespace fs = std::filesystem;

constexpr std::string_view kOctomapBinaryLine = "# Octomap OcTree binary file";
constexpr std::string_view kOctomapTreeLine = "# Octomap OcTree file";

}  // namespace

std::string_view ToString(MapFileFormat format) {
  switch (format) {
    case MapFileFormat::kAvpMap:
      return "avpmap";
    case MapFileFormat::kOctomapBinary:
      return "bt";
    case MapFileFormat::kOctomapTree:
      return "ot";
  }
  return "?";
}

std::string_view MapFileExtension(MapFileFormat format) {
  switch (format) {
    case MapFileFormat::kAvpMap:
      return ".avpmap";
    case MapFileFormat::kOctomapBinary:
      return ".bt";
    case MapFileFormat::kOctomapTree:
      return ".ot";
  }
  return "";
}

std::optional<MapFileFormat> DetectMapFileFormat(std::string_view first_bytes) {
  if (first_bytes.size() >= sizeof(kMapFileMagic) &&
      std::memcmp(first_bytes.data(), kMapFileMagic, sizeof(kMapFileMagic)) == 0) {
    return MapFileFormat::kAvpMap;
  }
  // The binary header line starts with the general one: test it first.
  if (first_bytes.starts_with(kOctomapBinaryLine)) return MapFileFormat::kOctomapBinary;
  if (first_bytes.starts_with(kOctomapTreeLine)) return MapFileFormat::kOctomapTree;
  return std::nullopt;
}

Result<LoadedMap> LoadAnyMap(const fs::path& path, const LoadAnyMapOptions& options) {
  // Missing, a folder, over max_file_bytes: told apart before reading.
  AVP_ASSIGN_OR_RETURN(const std::string bytes, io::ReadFileBounded(path, "map file"));
  return LoadAnyMapBytes(bytes, path, options);
}

Result<LoadedMap> LoadAnyMapBytes(const std::string& bytes, const fs::path& path,
                                  const LoadAnyMapOptions& options) {
  const std::optional<MapFileFormat> format = DetectMapFileFormat(bytes);
  if (!format) {
    // Named by what it is where that is known ("a PNG image"), else by its first bytes.
    const std::string kind = io::DescribeFileKind(bytes);
    return ParseError(fmt::format(
        "'{}' is not a map file avp can read: {}; expected avp's map magic (\\x89AVPMAP, "
        ".avpmap), '{}' (.bt) or '{}' (.ot)",
        path.string(),
        !kind.empty()   ? "it is " + kind
        : bytes.empty() ? std::string("it is empty")
                        : "it starts with " + QuoteText(std::string_view(bytes).substr(0, 32), 40),
        kOctomapBinaryLine, kOctomapTreeLine));
  }
  MapSource source;
  source.path = path;
  source.format = *format;
  source.file_bytes = bytes.size();
  const std::string extension = path.extension().string();
  if ((extension == ".avpmap" || extension == ".bt" || extension == ".ot") &&
      extension != MapFileExtension(*format)) {
    source.extension_note = fmt::format("the file is named {} but holds {} content (read as {})",
                                        extension, MapFileExtension(*format), ToString(*format));
  }
  if (*format == MapFileFormat::kAvpMap) {
    Result<SemanticMap> map = DeserializeMap(
        std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
        &source.avpmap);
    if (!map.ok()) return map.status().WithContext(fmt::format("map file '{}'", path.string()));
    source.resolution_m = map->voxel_size_m();
    source.has_labels = source.avpmap.labelled_voxels > 0;
    return LoadedMap{std::move(*map), std::move(source)};
  }
  AVP_ASSIGN_OR_RETURN(OctomapMapImport tree,
                       ImportOctomapMapBytes(bytes, path, options.max_voxels));
  source.resolution_m = tree.map.voxel_size_m();
  source.tree_type = tree.tree_type;
  source.tree_nodes = tree.tree_nodes;
  source.occupied_leaves = tree.occupied_leaves;
  source.free_leaves = tree.free_leaves;
  source.coarse_leaves = tree.coarse_leaves;
  source.free_space_dropped = tree.free_space_dropped;
  source.labelled_by_colour = tree.labelled_by_colour;
  source.unlabelled_grey = tree.unlabelled_grey;
  source.foreign_colour = tree.foreign_colour;
  source.has_labels = tree.labelled_by_colour > 0;
  const bool color = tree.tree_type == "ColorOcTree";
  if (tree.binary) {
    source.lost.push_back(
        "log-odds: a .bt holds one bit per voxel (occupied voxels read as OctoMap's clamping "
        "maximum, p 0.97; free ones as its minimum, p 0.12)");
  }
  if (!color) {
    source.lost.push_back(
        fmt::format("semantics: {} holds occupancy only (no classes, instances or confidences)",
                    tree.binary ? "a .bt file" : "an OcTree"));
  } else {
    source.lost.push_back(
        "instances, confidences and class evidence: a ColorOcTree holds a colour per voxel; "
        "voxels in a class colour are read back as that class with confidence 1");
    if (tree.foreign_colour > 0) {
      source.lost.push_back(fmt::format(
          "{} occupied voxels have colours that are neither a class colour nor avp's unlabelled "
          "grey: read as unlabelled",
          tree.foreign_colour));
    }
  }
  source.lost.push_back(
      "the sensor model and ROI: OctoMap files do not store them (avp's defaults are used; "
      "occupied at p >= 0.5 as OctoMap's default)");
  if (tree.free_space_dropped) {
    source.lost.push_back(fmt::format(
        "free space: its {} free leaves cover more than {} voxels, so only occupied voxels were "
        "kept",
        tree.free_leaves, options.max_voxels));
  }
  return LoadedMap{std::move(tree.map), std::move(source)};
}

VoxelSet GroundTruthVoxels(const LoadedMap& loaded, SemanticClass cls, bool* used_labels) {
  return GroundTruthVoxels(loaded.map, loaded.source, cls, used_labels);
}

VoxelSet GroundTruthVoxels(const SemanticMap& map, const MapSource& source, SemanticClass cls,
                           bool* used_labels) {
  const OccupancyGrid& grid = map.grid();
  VoxelSet set;
  set.resolution_m = grid.voxel_size_m();
  if (source.has_labels) {
    set.keys = OccupiedVoxelsOfClass(grid, cls);
  } else {
    grid.ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
      if (log_odds >= grid.occupied_log_odds()) set.keys.push_back(k);
    });
    std::sort(set.keys.begin(), set.keys.end());
  }
  set.occupied_leaves =
      source.format == MapFileFormat::kAvpMap ? set.keys.size() : source.occupied_leaves;
  set.coarse_leaves = source.coarse_leaves;
  if (used_labels != nullptr) *used_labels = source.has_labels;
  return set;
}

}  // namespace avp::mapping

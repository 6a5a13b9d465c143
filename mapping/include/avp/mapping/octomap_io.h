#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <avp/core/limits.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/voxel_key.h>
#include <avp/mapping/semantic_map.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::mapping {

// ---- OctoMap interop ---------------------------------------------------------------------------
//
// OctoMap and avp share one lattice: avp voxel k covers [k s, (k + 1) s) and OctoMap's finest key
// for the same voxel is k + kOctomapKeyOffset (OcTreeKey = floor(p / s) + 32768). OctoMap keys are
// 16-bit, so only voxels with k in [kOctomapMinKey, kOctomapMaxKey] on every axis can be exported
// (+-163.84 m at 5 mm); exports refuse maps with voxels outside, naming the first one.
//
// OctoMap headers stay in octomap_io.cpp: nothing here needs them.

inline constexpr int32_t kOctomapKeyOffset = 32768;
inline constexpr int32_t kOctomapMinKey = -32768;
inline constexpr int32_t kOctomapMaxKey = 32767;

/// The voxel fits OctoMap's 16-bit key range.
inline bool InOctomapKeyRange(const VoxelKey& k) {
  return k.x >= kOctomapMinKey && k.x <= kOctomapMaxKey && k.y >= kOctomapMinKey &&
         k.y <= kOctomapMaxKey && k.z >= kOctomapMinKey && k.z <= kOctomapMaxKey;
}
/// OctoMap's OcTreeKey components for an avp key (call InOctomapKeyRange first).
inline std::array<uint16_t, 3> ToOctomapKey(const VoxelKey& k) {
  return {static_cast<uint16_t>(k.x + kOctomapKeyOffset),
          static_cast<uint16_t>(k.y + kOctomapKeyOffset),
          static_cast<uint16_t>(k.z + kOctomapKeyOffset)};
}
inline VoxelKey FromOctomapKey(uint16_t x, uint16_t y, uint16_t z) {
  return {int32_t{x} - kOctomapKeyOffset, int32_t{y} - kOctomapKeyOffset,
          int32_t{z} - kOctomapKeyOffset};
}

/// The RGB colour a voxel gets in a ColorOcTree (.ot) export: its class colour
/// (io::ClassColor: fruit red, leaf green, stem brown, ...) when it has a semantic label,
/// kUnlabelledOccupiedColor otherwise.
std::array<uint8_t, 3> OctomapVoxelColor(const SemanticCell* cell);
inline constexpr std::array<uint8_t, 3> kUnlabelledOccupiedColor = {128, 128, 128};

struct OctomapExportStats {
  size_t occupied_voxels = 0;
  size_t free_voxels = 0;
  size_t labelled_voxels = 0;  ///< .ot only: occupied voxels coloured by class
  size_t leaf_nodes = 0;       ///< leaves in the written tree (after pruning)
  size_t file_bytes = 0;
};

/// Both exporters write atomically (io::WriteFileAtomic: a temporary name, flushed, renamed), so a
/// killed run or a full disk never leaves a truncated tree; every write error names the file.
///
/// Writes an OctoMap binary tree (.bt): every known voxel as an occupied or free leaf (maximum
/// likelihood: OctoMap stores one bit per node), pruned. Log-odds and semantics are lost; the
/// occupancy decision (log-odds >= the sensor model's threshold) is kept exactly. Readable by
/// octovis, octomap-tools (convert_octree, compare_octrees, bt2vrml ...) and OcTree::readBinary.
/// Errors: OutOfRange naming the first voxel outside OctoMap's key range; IoError.
Result<OctomapExportStats> ExportOctomapBinary(const OccupancyGrid& grid,
                                               const std::filesystem::path& path);

/// The binary tree of ExportOctomapBinary without the file header, as octomap_msgs/Octomap
/// carries it (binary = true, id "OcTree"; octomap_msgs::binaryMapToMsg): what RViz's
/// octomap_rviz_plugins and octomap_server read. Errors: OutOfRange as ExportOctomapBinary.
struct OctomapBinaryData {
  std::string id;  ///< "OcTree"
  double resolution_m = 0.0;
  std::string data;       ///< OcTree::writeBinaryData
  size_t tree_nodes = 0;  ///< OcTree::size(), the .bt header's "size"
  OctomapExportStats stats;
};
Result<OctomapBinaryData> OctomapBinaryMessageData(const OccupancyGrid& grid);

/// The file an octomap_msgs/Octomap message's tree stands for: the .bt (binary) or .ot text
/// header with the node count the tree holds (walked and checked as a file's tree is, bounded by
/// max_octomap_nodes), then the data: what LoadAnyMapBytes reads (a recording's /avp/map
/// messages as maps). ParseError naming `what`: an id other than OcTree / ColorOcTree, a
/// resolution out of range, a broken tree, bytes after it.
Result<std::string> OctomapMessageFileBytes(std::string_view id, bool binary, double resolution_m,
                                            std::string_view data, std::string_view what);

/// Writes an OctoMap ColorOcTree (.ot, AbstractOcTree::write): every known voxel with its full
/// log-odds (a float, as ours), occupied voxels coloured by OctomapVoxelColor, free voxels white
/// (OctoMap's "no colour"); the tree's sensor parameters are set from the map's sensor model and
/// pruning only merges identical children (lossless). Instances, confidences and the Bayesian
/// class evidence are lost.
Result<OctomapExportStats> ExportOctomapColor(const SemanticMap& map,
                                              const std::filesystem::path& path);

/// A ground-truth (or any) set of occupied voxels on a lattice of edge `resolution_m`.
struct VoxelSet {
  double resolution_m = 0.0;
  /// Sorted (x, then y, then z), unique.
  std::vector<VoxelKey> keys;
  /// Occupied leaves read from the tree and how many were coarser than one voxel (pruned).
  size_t occupied_leaves = 0;
  size_t coarse_leaves = 0;
};

/// max_octomap_nodes: nodes of one OctoMap tree read from a file, 2^26 (67108864) by default
/// (OctoMap holds some 40 bytes per node).
const Limit& MaxOctomapNodes();

/// Reads an OctoMap file (.bt, or .ot holding an OcTree or ColorOcTree) and returns its occupied
/// voxels at the finest resolution: pruned (coarse) occupied leaves are expanded to every voxel
/// they cover. Free and unknown space is dropped.
///
/// The file is never trusted: its size is checked (max_file_bytes), its text header is parsed
/// strictly (id, size as a node count, res in [1e-4, 100] m; nothing else), the node count against
/// max_octomap_nodes, and the tree is walked before OctoMap sees it (at most 16 levels, finite
/// log-odds, exactly the declared node count, ending exactly at the end of the file), so a
/// truncated or crafted file is refused instead of read as a different tree. After OctoMap's
/// reader the stream state, the position and the node count are checked again; what OctoMap
/// printed on std::cerr meanwhile is quoted (escaped) in the error.
/// Errors: NotFound, InvalidArgument (a folder), ResourceExhausted (max_file_bytes,
/// max_octomap_nodes), ParseError (not an OctoMap file, a bad header, a broken or truncated tree,
/// an unsupported tree type), OutOfRange when the expansion would exceed `max_voxels` (a huge
/// pruned leaf).
Result<VoxelSet> ImportOctomapOccupied(const std::filesystem::path& path,
                                       size_t max_voxels = size_t{1} << 27);
/// The same on a file's bytes already in memory (fuzzing, tests); `path` only names it in errors.
/// Safe on any bytes.
Result<VoxelSet> ImportOctomapOccupiedBytes(const std::string& bytes,
                                            const std::filesystem::path& path,
                                            size_t max_voxels = size_t{1} << 27);

/// An OctoMap file read as a map (ImportOctomapMap): every leaf, occupied and free, on avp's
/// lattice, with the class of a ColorOcTree voxel whose colour is exactly a class colour.
struct OctomapMapImport {
  SemanticMap map;
  bool binary = false;    ///< .bt (one bit per node) or .ot (full node data)
  std::string tree_type;  ///< the header's id: "OcTree", "ColorOcTree"
  uint64_t tree_nodes = 0;
  size_t occupied_leaves = 0;
  size_t free_leaves = 0;
  size_t coarse_leaves = 0;  ///< leaves coarser than one voxel (pruned), occupied or free
  size_t occupied_voxels = 0;
  size_t free_voxels = 0;  ///< 0 when free space was dropped
  /// Free leaves would expand to more than `max_voxels` voxels: free space was left out (the
  /// occupied voxels are all there).
  bool free_space_dropped = false;
  /// ColorOcTree, occupied voxels: coloured exactly as a class (io::ClassColor, background
  /// excluded) and read back as that class; avp's unlabelled grey (kUnlabelledOccupiedColor);
  /// any other colour (occupied, unlabelled).
  size_t labelled_by_colour = 0;
  size_t unlabelled_grey = 0;
  size_t foreign_colour = 0;
};

/// The class an occupied ColorOcTree voxel of this colour gets: the labelled class whose
/// io::ClassColor is exactly `rgb`, kBackground (unlabelled) otherwise.
SemanticClass ClassOfOctomapColor(const std::array<uint8_t, 3>& rgb);

/// Reads an OctoMap file (.bt, or .ot holding an OcTree or ColorOcTree) as a SemanticMap with the
/// tree's resolution and avp's default sensor model (its occupancy threshold, p >= 0.5, is
/// OctoMap's default; .ot files do not store theirs): every leaf's log-odds (.bt: OctoMap's
/// clamping bounds, as OcTree::readBinary gives them) expanded to the finest voxels; ColorOcTree
/// voxels get the class of their colour (ClassOfOctomapColor) with confidence 1, one observation
/// and no instance. The same checks as ImportOctomapOccupied (size, strict header,
/// max_octomap_nodes, the tree walked before OctoMap reads it, OctoMap's reader checked after);
/// errors name the file. Occupied voxels over `max_voxels`: OutOfRange; free voxels over
/// `max_voxels`: free space is dropped (free_space_dropped). Other tree types: ParseError naming
/// the type. A resolution outside avp's voxel sizes: InvalidArgument naming it.
Result<OctomapMapImport> ImportOctomapMapBytes(const std::string& bytes,
                                               const std::filesystem::path& path,
                                               size_t max_voxels = size_t{1} << 27);

// ---- Comparison against a ground-truth voxel set -----------------------------------------------

struct GroundTruthCompareOptions {
  /// Chebyshev tolerance in map voxels: 0 = the same key, 1 = within the 3x3x3 cube around it.
  int tolerance_voxels = 0;
  /// The class whose occupied, labelled voxels are the prediction.
  SemanticClass semantic_class = SemanticClass::kFruit;
  Status Validate() const;
};

/// Precision / recall of a map's labelled voxels against a ground-truth voxel set, with counts.
///
/// Predicted = voxels that are occupied and labelled `semantic_class`. A predicted voxel is a true
/// positive when a GT voxel lies within the tolerance cube around it (precision side); a GT voxel
/// is found when a predicted voxel lies within the tolerance cube around it (recall side). With
/// tolerance 0 both sides count the same exact matches. precision = tp / predicted,
/// recall = gt_found / ground_truth, f1 = 2 p r / (p + r); each is 0 when its denominator is 0.
///
/// When the GT resolution differs from the map's, every GT voxel centre is mapped onto the map's
/// lattice (duplicates merged) and `resampled` is set.
struct GroundTruthComparison {
  int tolerance_voxels = 0;
  size_t predicted = 0;
  size_t ground_truth = 0;  ///< GT voxels on the map's lattice
  size_t tp = 0;            ///< predicted voxels with a GT voxel within the tolerance
  size_t fp = 0;            ///< predicted - tp
  size_t gt_found = 0;      ///< GT voxels with a predicted voxel within the tolerance
  size_t fn = 0;            ///< ground_truth - gt_found
  double precision = 0.0;
  double recall = 0.0;
  double f1 = 0.0;

  double map_resolution_m = 0.0;
  double gt_resolution_m = 0.0;
  bool resampled = false;
  size_t gt_voxels_original = 0;  ///< GT voxels before resampling
};

/// Sorted, unique keys of the voxels that are occupied and labelled `semantic_class`.
std::vector<VoxelKey> OccupiedVoxelsOfClass(const OccupancyGrid& grid,
                                            SemanticClass semantic_class);

/// Compares the map against `gt`. Errors: InvalidArgument for a bad tolerance or GT resolution.
Result<GroundTruthComparison> CompareToGroundTruth(const OccupancyGrid& grid, const VoxelSet& gt,
                                                   const GroundTruthCompareOptions& options = {});

/// The same on key sets already on one lattice (`predicted` and `gt` need not be sorted).
GroundTruthComparison CompareVoxelSets(const std::vector<VoxelKey>& predicted,
                                       const std::vector<VoxelKey>& gt, int tolerance_voxels);

}  // namespace avp::mapping

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <unordered_set>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>

#include <avp/io/label_preview.h>
#include <avp/mapping/octomap_io.h>

namespace avp::mapping {

namespace {

namespace fs = std::filesystem;

constexpr std::string_view kBinaryHeader = "# Octomap OcTree binary file";
constexpr std::string_view kGeneralHeader = "# Octomap OcTree file";

/// liboctomap (as Debian builds it) reports progress and errors on std::cerr ("Reading binary
/// octree type OcTree", " done."). While alive, this keeps that chatter out of the program's output
/// and collects it, so that a failure can quote it. Not meant for concurrent std::cerr writers.
class OctomapChatter {
 public:
  OctomapChatter() : old_(std::cerr.rdbuf(text_.rdbuf())) {}
  ~OctomapChatter() { std::cerr.rdbuf(old_); }
  OctomapChatter(const OctomapChatter&) = delete;
  OctomapChatter& operator=(const OctomapChatter&) = delete;
  /// " (OctoMap said: ...)" or empty.
  std::string Quote() const {
    std::string t = text_.str();
    while (!t.empty() && (t.back() == '\n' || t.back() == ' ')) t.pop_back();
    for (char& c : t) {
      if (c == '\n') c = ' ';
    }
    return t.empty() ? std::string() : " (OctoMap said: " + t + ")";
  }

 private:
  std::ostringstream text_;
  std::streambuf* old_;
};

octomap::OcTreeKey OcKey(const VoxelKey& k) {
  const auto key = ToOctomapKey(k);
  return octomap::OcTreeKey(key[0], key[1], key[2]);
}

/// Refuses grids with known voxels outside OctoMap's 16-bit key range, naming the first one.
Status CheckOctomapRange(const OccupancyGrid& grid) {
  size_t outside = 0;
  VoxelKey first;
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float) {
    if (InOctomapKeyRange(k)) return;
    if (outside == 0) first = k;
    ++outside;
  });
  if (outside == 0) return Status::Ok();
  const double s = grid.voxel_size_m();
  const Eigen::Vector3d c = grid.CenterOf(first);
  return OutOfRangeError(fmt::format(
      "{} known voxels lie outside OctoMap's key range (voxel keys {} to {} on each axis, i.e. "
      "[{:.2f}, {:.2f}) m at {} m voxels), e.g. voxel ({}, {}, {}) centred at ({:.3f}, {:.3f}, "
      "{:.3f}) m: OctoMap cannot store them",
      outside, kOctomapMinKey, kOctomapMaxKey, kOctomapMinKey * s, (kOctomapMaxKey + 1) * s, s,
      first.x, first.y, first.z, c.x(), c.y(), c.z()));
}

/// The tree's sensor parameters from ours, so its clamping (setNodeValue clamps) and occupancy
/// threshold are the map's exactly (both use log(p / (1 - p)) rounded to float).
void ConfigureTree(octomap::AbstractOccupancyOcTree& tree, const SensorModel& sensor) {
  tree.setProbHit(sensor.hit);
  tree.setProbMiss(sensor.miss);
  tree.setClampingThresMin(sensor.clamp_min);
  tree.setClampingThresMax(sensor.clamp_max);
  tree.setOccupancyThres(sensor.occupied_threshold);
}

Status WriteBytes(const fs::path& path, const std::string& bytes, std::string_view what) {
  std::error_code ec;
  if (path.has_parent_path()) fs::create_directories(path.parent_path(), ec);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return IoError(fmt::format("cannot open '{}' to write the {}", path.string(), what));
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) return IoError(fmt::format("writing the {} to '{}' failed", what, path.string()));
  return Status::Ok();
}

/// Every occupied leaf expanded to the finest voxels it covers; bounded by max_voxels.
template <class Tree>
Result<VoxelSet> CollectOccupied(const Tree& tree, size_t max_voxels, const fs::path& path) {
  VoxelSet set;
  set.resolution_m = tree.getResolution();
  const unsigned tree_depth = tree.getTreeDepth();
  uint64_t total = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const unsigned level = tree_depth - it.getDepth();
    ++set.occupied_leaves;
    if (level > 0) ++set.coarse_leaves;
    total += uint64_t{1} << (3 * level);
    if (total > max_voxels) {
      return OutOfRangeError(fmt::format(
          "'{}': expanding the occupied leaves to {} m voxels needs more than {} voxels (a leaf "
          "of depth {} alone covers {}^3); raise the limit or coarsen the comparison",
          path.string(), set.resolution_m, max_voxels, it.getDepth(), uint64_t{1} << level));
    }
  }
  set.keys.reserve(static_cast<size_t>(total));
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const unsigned level = tree_depth - it.getDepth();
    const octomap::OcTreeKey base = it.getIndexKey();
    const int n = 1 << level;
    for (int dz = 0; dz < n; ++dz) {
      for (int dy = 0; dy < n; ++dy) {
        for (int dx = 0; dx < n; ++dx) {
          set.keys.push_back(FromOctomapKey(static_cast<uint16_t>(base[0] + dx),
                                            static_cast<uint16_t>(base[1] + dy),
                                            static_cast<uint16_t>(base[2] + dz)));
        }
      }
    }
  }
  std::sort(set.keys.begin(), set.keys.end());
  set.keys.erase(std::unique(set.keys.begin(), set.keys.end()), set.keys.end());
  return set;
}

bool SameResolution(double a, double b) { return std::abs(a - b) <= 1e-9 * std::max(a, b); }

}  // namespace

std::array<uint8_t, 3> OctomapVoxelColor(const SemanticCell* cell) {
  if (cell == nullptr || !cell->has_label()) return kUnlabelledOccupiedColor;
  const auto c = io::ClassColor(cell->cls());
  return {c[0], c[1], c[2]};
}

Result<OctomapBinaryData> OctomapBinaryMessageData(const OccupancyGrid& grid) {
  AVP_RETURN_IF_ERROR(CheckOctomapRange(grid));
  OctomapBinaryData out;
  octomap::OcTree tree(grid.voxel_size_m());
  ConfigureTree(tree, grid.sensor_model());
  const float occupied = grid.occupied_log_odds();
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    tree.setNodeValue(OcKey(k), log_odds, /*lazy_eval=*/true);
    if (log_odds >= occupied) {
      ++out.stats.occupied_voxels;
    } else {
      ++out.stats.free_voxels;
    }
  });
  tree.updateInnerOccupancy();
  // What OcTree::writeBinary does (maximum likelihood, prune, data), spelled out so that
  // liboctomap's " done." on stderr stays out of the program's output.
  tree.toMaxLikelihood();
  tree.prune();
  std::ostringstream data(std::ios::binary);
  tree.writeBinaryData(data);
  if (!data.good()) return IoError("OctoMap could not serialize the binary tree");
  out.id = tree.getTreeType();
  out.resolution_m = tree.getResolution();
  out.data = data.str();
  out.tree_nodes = tree.size();
  out.stats.leaf_nodes = tree.getNumLeafNodes();
  out.stats.file_bytes = out.data.size();
  return out;
}

Result<OctomapExportStats> ExportOctomapBinary(const OccupancyGrid& grid, const fs::path& path) {
  AVP_ASSIGN_OR_RETURN(const OctomapBinaryData tree, OctomapBinaryMessageData(grid));
  std::ostringstream out(std::ios::binary);
  out << kBinaryHeader
      << "\n# (feel free to add / change comments, but leave the first line as it is!)\n#\n";
  out << "id " << tree.id << "\n";
  out << "size " << tree.tree_nodes << "\n";
  out << "res " << tree.resolution_m << "\n";
  out << "data\n";
  out << tree.data;
  OctomapExportStats stats = tree.stats;
  const std::string bytes = out.str();
  stats.file_bytes = bytes.size();
  AVP_RETURN_IF_ERROR(WriteBytes(path, bytes, "OctoMap .bt file"));
  return stats;
}

Result<OctomapExportStats> ExportOctomapColor(const SemanticMap& map, const fs::path& path) {
  const OccupancyGrid& grid = map.grid();
  AVP_RETURN_IF_ERROR(CheckOctomapRange(grid));
  OctomapExportStats stats;
  octomap::ColorOcTree tree(grid.voxel_size_m());
  ConfigureTree(tree, grid.sensor_model());
  const float occupied = grid.occupied_log_odds();
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    octomap::ColorOcTreeNode* node = tree.setNodeValue(OcKey(k), log_odds, /*lazy_eval=*/true);
    if (log_odds < occupied) {
      ++stats.free_voxels;
      return;
    }
    ++stats.occupied_voxels;
    const SemanticCell* cell = grid.Semantic(k);
    if (cell != nullptr && cell->has_label()) ++stats.labelled_voxels;
    const auto rgb = OctomapVoxelColor(cell);
    node->setColor(rgb[0], rgb[1], rgb[2]);
  });
  // Inner nodes get their children's maximum occupancy and mean colour. No pruning: ColorOcTree
  // prunes on occupancy alone and would average neighbouring class colours away.
  tree.updateInnerOccupancy();
  stats.leaf_nodes = tree.getNumLeafNodes();
  std::ostringstream out(std::ios::binary);
  {
    OctomapChatter chatter;
    if (!tree.write(out)) {
      return IoError(fmt::format("OctoMap could not serialize the tree for '{}'{}", path.string(),
                                 chatter.Quote()));
    }
  }
  const std::string bytes = out.str();
  stats.file_bytes = bytes.size();
  AVP_RETURN_IF_ERROR(WriteBytes(path, bytes, "OctoMap .ot file"));
  return stats;
}

Result<VoxelSet> ImportOctomapOccupied(const fs::path& path, size_t max_voxels) {
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    return NotFoundError(fmt::format("OctoMap file '{}' does not exist", path.string()));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return IoError(fmt::format("cannot open OctoMap file '{}'", path.string()));
  std::string first_line;
  std::getline(in, first_line);
  if (first_line.size() > 80) first_line = first_line.substr(0, 80) + "...";
  in.clear();
  in.seekg(0);

  if (first_line.rfind(kBinaryHeader, 0) == 0) {
    octomap::OcTree tree(0.1);  // readBinary sets the file's resolution
    OctomapChatter chatter;
    if (!tree.readBinary(in)) {
      return ParseError(fmt::format("'{}' is not a readable OctoMap binary tree (.bt){}",
                                    path.string(), chatter.Quote()));
    }
    return CollectOccupied(tree, max_voxels, path);
  }
  if (first_line.rfind(kGeneralHeader, 0) == 0) {
    OctomapChatter chatter;
    std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(in));
    if (!tree) {
      return ParseError(fmt::format("'{}' is not a readable OctoMap tree (.ot){}", path.string(),
                                    chatter.Quote()));
    }
    if (const auto* t = dynamic_cast<const octomap::OcTree*>(tree.get())) {
      return CollectOccupied(*t, max_voxels, path);
    }
    if (const auto* t = dynamic_cast<const octomap::ColorOcTree*>(tree.get())) {
      return CollectOccupied(*t, max_voxels, path);
    }
    return ParseError(fmt::format(
        "'{}' holds an OctoMap tree of type '{}'; only OcTree and ColorOcTree can be imported",
        path.string(), tree->getTreeType()));
  }
  return ParseError(fmt::format(
      "'{}' is not an OctoMap file: its first line is '{}', expected '{}' (.bt) or '{}' (.ot)",
      path.string(), first_line, kBinaryHeader, kGeneralHeader));
}

// ---- Comparison
// ----------------------------------------------------------------------------------

Status GroundTruthCompareOptions::Validate() const {
  std::vector<std::string> errors;
  if (tolerance_voxels < 0 || tolerance_voxels > 8) {
    errors.push_back(fmt::format("tolerance_voxels ({}) must be in [0, 8]", tolerance_voxels));
  }
  if (semantic_class == SemanticClass::kBackground ||
      static_cast<int>(semantic_class) >= kNumSemanticClasses) {
    errors.push_back(fmt::format("semantic_class ({}) must be a labelled class",
                                 static_cast<int>(semantic_class)));
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError("invalid ground-truth comparison options: " +
                              fmt::format("{}", fmt::join(errors, "; ")));
}

std::vector<VoxelKey> OccupiedVoxelsOfClass(const OccupancyGrid& grid,
                                            SemanticClass semantic_class) {
  std::vector<VoxelKey> keys;
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const SemanticCell& c) {
    if (c.cls() == semantic_class && grid.State(k) == VoxelState::kOccupied) keys.push_back(k);
  });
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  return keys;
}

GroundTruthComparison CompareVoxelSets(const std::vector<VoxelKey>& predicted,
                                       const std::vector<VoxelKey>& gt, int tolerance_voxels) {
  using KeySet = std::unordered_set<VoxelKey, VoxelKeyHash>;
  const KeySet pred_set(predicted.begin(), predicted.end());
  const KeySet gt_set(gt.begin(), gt.end());
  const int t = std::max(tolerance_voxels, 0);
  // How many keys of `from` have a key of `to` within the Chebyshev tolerance.
  const auto count_matched = [t](const KeySet& from, const KeySet& to) {
    size_t matched = 0;
    for (const VoxelKey& k : from) {
      bool found = false;
      for (int dz = -t; dz <= t && !found; ++dz) {
        for (int dy = -t; dy <= t && !found; ++dy) {
          for (int dx = -t; dx <= t && !found; ++dx) {
            found = to.count(VoxelKey{k.x + dx, k.y + dy, k.z + dz}) > 0;
          }
        }
      }
      if (found) ++matched;
    }
    return matched;
  };
  GroundTruthComparison r;
  r.tolerance_voxels = t;
  r.predicted = pred_set.size();
  r.ground_truth = gt_set.size();
  r.tp = count_matched(pred_set, gt_set);
  r.fp = r.predicted - r.tp;
  r.gt_found = count_matched(gt_set, pred_set);
  r.fn = r.ground_truth - r.gt_found;
  r.precision =
      r.predicted > 0 ? static_cast<double>(r.tp) / static_cast<double>(r.predicted) : 0.0;
  r.recall = r.ground_truth > 0
                 ? static_cast<double>(r.gt_found) / static_cast<double>(r.ground_truth)
                 : 0.0;
  r.f1 =
      r.precision + r.recall > 0.0 ? 2.0 * r.precision * r.recall / (r.precision + r.recall) : 0.0;
  return r;
}

Result<GroundTruthComparison> CompareToGroundTruth(const OccupancyGrid& grid, const VoxelSet& gt,
                                                   const GroundTruthCompareOptions& options) {
  AVP_RETURN_IF_ERROR(options.Validate());
  if (!std::isfinite(gt.resolution_m) || gt.resolution_m <= 0.0) {
    return InvalidArgumentError(
        fmt::format("ground-truth resolution ({}) must be finite and > 0", gt.resolution_m));
  }
  const double s = grid.voxel_size_m();
  const bool resampled = !SameResolution(gt.resolution_m, s);
  std::vector<VoxelKey> gt_keys;
  if (resampled) {
    gt_keys.reserve(gt.keys.size());
    for (const VoxelKey& k : gt.keys) gt_keys.push_back(grid.KeyOf(k.Center(gt.resolution_m)));
    std::sort(gt_keys.begin(), gt_keys.end());
    gt_keys.erase(std::unique(gt_keys.begin(), gt_keys.end()), gt_keys.end());
  }
  GroundTruthComparison r =
      CompareVoxelSets(OccupiedVoxelsOfClass(grid, options.semantic_class),
                       resampled ? gt_keys : gt.keys, options.tolerance_voxels);
  r.map_resolution_m = s;
  r.gt_resolution_m = gt.resolution_m;
  r.resampled = resampled;
  r.gt_voxels_original = gt.keys.size();
  return r;
}

}  // namespace avp::mapping

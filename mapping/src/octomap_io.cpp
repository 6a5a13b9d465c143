#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <system_error>
#include <type_traits>
#include <unordered_set>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>
#include <unistd.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/label_preview.h>
#include <avp/mapping/octomap_io.h>

namespace avp::mapping {

namespace {

namespace fs = std::filesystem;

constexpr std::string_view kBinaryHeader = "# Octomap OcTree binary file";
constexpr std::string_view kGeneralHeader = "# Octomap OcTree file";

/// liboctomap reports errors and warnings on std::cerr (OCTOMAP_ERROR_STR, OCTOMAP_WARNING_STR)
/// and on the C stderr (OCTOMAP_ERROR, OCTOMAP_WARNING: printf-style). While alive, this sends
/// both into buffers (std::cerr's rdbuf, and file descriptor 2 into a temporary file), so that the
/// program's output stays clean and a failure can quote what OctoMap said. One at a time (a
/// process-wide mutex): std::cerr and stderr are shared, and what other threads write to them
/// meanwhile is collected too (and shown only if OctoMap's call fails).
class OctomapChatter {
 public:
  OctomapChatter() : lock_(Mutex()), old_(std::cerr.rdbuf(text_.rdbuf())) {
    std::fflush(stderr);
    tmp_ = std::tmpfile();
    saved_fd_ = tmp_ != nullptr ? ::dup(STDERR_FILENO) : -1;
    if (saved_fd_ >= 0 && ::dup2(::fileno(tmp_), STDERR_FILENO) < 0) {
      ::close(saved_fd_);
      saved_fd_ = -1;
    }
  }
  ~OctomapChatter() {
    Restore();
    if (tmp_ != nullptr) std::fclose(tmp_);
    std::cerr.rdbuf(old_);
  }
  OctomapChatter(const OctomapChatter&) = delete;
  OctomapChatter& operator=(const OctomapChatter&) = delete;
  /// What OctoMap printed so far, one line, escaped and shortened (QuoteText); empty when
  /// nothing.
  std::string Text() {
    Restore();
    std::string t = text_.str();
    if (tmp_ != nullptr) {
      std::rewind(tmp_);
      char buffer[4096];
      const size_t n = std::fread(buffer, 1, sizeof(buffer), tmp_);
      t += std::string(buffer, n);
    }
    while (!t.empty() && (t.back() == '\n' || t.back() == ' ')) t.pop_back();
    for (char& c : t) {
      if (c == '\n') c = ' ';
    }
    return t.empty() ? std::string() : QuoteText(t, 300);
  }
  /// " (OctoMap said: '...')" or empty.
  std::string Quote() {
    const std::string t = Text();
    return t.empty() ? std::string() : " (OctoMap said: " + t + ")";
  }

 private:
  /// Puts the C stderr back (idempotent).
  void Restore() {
    if (saved_fd_ < 0) return;
    std::fflush(stderr);
    ::dup2(saved_fd_, STDERR_FILENO);
    ::close(saved_fd_);
    saved_fd_ = -1;
  }
  static std::mutex& Mutex() {
    static std::mutex mutex;
    return mutex;
  }
  std::lock_guard<std::mutex> lock_;
  std::ostringstream text_;
  std::streambuf* old_;
  std::FILE* tmp_ = nullptr;
  int saved_fd_ = -1;
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

/// Writes a whole file atomically (a temporary name beside it, flushed, renamed): a run killed
/// half-way or a full disk never leaves a truncated tree behind.
Status WriteBytes(const fs::path& path, const std::string& bytes, std::string_view what) {
  return io::WriteFileAtomic(path, bytes, what);
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

namespace {

/// What an OctoMap file's text header says (checked strictly before OctoMap reads anything).
struct OctomapHeader {
  bool binary = false;  ///< .bt (maximum-likelihood bits) or .ot (full node data)
  std::string id;
  uint64_t size = 0;  ///< nodes in the tree
  double resolution_m = 0.0;
  size_t data_offset = 0;  ///< first byte of the tree
};

/// The longest header OctoMap writes is a few lines; anything longer is not one.
constexpr size_t kMaxOctomapHeaderBytes = 4096;
/// OctoMap's trees are 16 levels deep: the root at depth 0, the finest voxels at depth 16.
constexpr int kOctomapTreeDepth = 16;
/// Accepted voxel edges of a tree, metres.
constexpr double kMinOctomapResolution = 1e-4;
constexpr double kMaxOctomapResolution = 100.0;

Result<OctomapHeader> ParseOctomapHeader(std::string_view bytes, const fs::path& path) {
  const auto bad = [&](const std::string& what) {
    return ParseError(fmt::format("'{}' is not a readable OctoMap file: {}", path.string(), what));
  };
  OctomapHeader h;
  size_t at = 0;
  size_t line_no = 0;
  bool have_id = false, have_size = false, have_res = false;
  while (true) {
    if (at >= bytes.size()) {
      return bad(fmt::format("its header ends after {} lines without a 'data' line", line_no));
    }
    if (at > kMaxOctomapHeaderBytes) {
      return bad(fmt::format("no 'data' line in its first {} bytes", kMaxOctomapHeaderBytes));
    }
    const size_t end = bytes.find('\n', at);
    if (end == std::string_view::npos) {
      return bad(fmt::format("its header line {} is not terminated", line_no + 1));
    }
    std::string_view line = bytes.substr(at, end - at);
    at = end + 1;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line_no == 1) {
      if (line.starts_with(kBinaryHeader)) {
        h.binary = true;
      } else if (line.starts_with(kGeneralHeader)) {
        h.binary = false;
      } else {
        return ParseError(fmt::format(
            "'{}' is not an OctoMap file: its first line is {}, expected '{}' (.bt) or '{}' (.ot)",
            path.string(), QuoteText(line), kBinaryHeader, kGeneralHeader));
      }
      continue;
    }
    if (line.starts_with("#")) continue;
    const size_t space = line.find(' ');
    const std::string_view key = line.substr(0, space);
    const std::string_view value =
        space == std::string_view::npos ? std::string_view() : line.substr(space + 1);
    if (key == "data" && value.empty()) break;
    if (key == "id") {
      if (value.empty() || value.size() > 64 || value.find(' ') != std::string_view::npos) {
        return bad(fmt::format("header line {}: id {} is not a tree type name", line_no,
                               QuoteText(value)));
      }
      h.id = std::string(value);
      have_id = true;
    } else if (key == "size") {
      const char* first = value.data();
      const char* last = value.data() + value.size();
      const auto [ptr, ec] = std::from_chars(first, last, h.size);
      if (value.empty() || ec != std::errc() || ptr != last ||
          h.size > std::numeric_limits<uint32_t>::max()) {
        return bad(fmt::format("header line {}: size {} must be a node count in [0, {}]", line_no,
                               QuoteText(value), std::numeric_limits<uint32_t>::max()));
      }
      have_size = true;
    } else if (key == "res") {
      const char* first = value.data();
      const char* last = value.data() + value.size();
      const auto [ptr, ec] = std::from_chars(first, last, h.resolution_m);
      if (value.empty() || ec != std::errc() || ptr != last || !std::isfinite(h.resolution_m) ||
          h.resolution_m < kMinOctomapResolution || h.resolution_m > kMaxOctomapResolution) {
        return bad(fmt::format("header line {}: res {} must be a voxel edge in [{}, {}] m", line_no,
                               QuoteText(value), kMinOctomapResolution, kMaxOctomapResolution));
      }
      have_res = true;
    } else {
      return bad(fmt::format("header line {} is {}; expected 'id', 'size', 'res' or 'data'",
                             line_no, QuoteText(line)));
    }
  }
  if (!have_id || !have_size || !have_res) {
    return bad(fmt::format("its header lacks {}", !have_id     ? "'id'"
                                                  : !have_size ? "'size'"
                                                               : "'res'"));
  }
  if (h.id == "1") h.id = "OcTree";  // OctoMap's deprecated id
  h.data_offset = at;
  return h;
}

/// Walks the tree OctoMap would read (without OctoMap, iteratively, never deeper than its 16
/// levels) and checks that it holds exactly the header's node count and ends exactly at the end
/// of the file. .bt: 2 bytes per node (2 bits per child: 01 occupied, 10 free, 11 inner);
/// .ot: the node's data (`value_bytes`: a float log-odds, + 3 colour bytes for a ColorOcTree)
/// and one byte whose bits say which children follow. OK or what is wrong.
Status CheckOctomapTree(std::string_view data, const OctomapHeader& h, size_t value_bytes,
                        const fs::path& path, uint64_t* counted = nullptr) {
  const auto bad = [&](const std::string& what) {
    return ParseError(fmt::format(
        "'{}' holds a broken OctoMap tree (id {}{}): {}", path.string(), QuoteText(h.id),
        counted != nullptr ? std::string() : fmt::format(", {} nodes declared", h.size), what));
  };
  if (h.size == 0) {
    if (!data.empty()) {
      return bad(fmt::format("{} bytes follow a header that declares an empty tree", data.size()));
    }
    return Status::Ok();
  }
  // Each entry: the depth of a node still to read. A node's children are pushed in reverse, so
  // they are read in order (depth first, as OctoMap writes them).
  std::vector<int> pending = {0};
  size_t at = 0;
  uint64_t nodes = 0;
  const size_t node_bytes = h.binary ? 2 : value_bytes + 1;
  while (!pending.empty()) {
    const int depth = pending.back();
    pending.pop_back();
    ++nodes;
    if (nodes > h.size) {
      return bad(
          fmt::format("the tree has more nodes than {} (at byte {})",
                      counted != nullptr ? "max_octomap_nodes allows" : "its header declares",
                      h.data_offset + at));
    }
    if (data.size() - at < node_bytes) {
      return bad(
          fmt::format("the file is truncated: node {} (depth {}) needs {} bytes at byte {}, "
                      "{} remain",
                      nodes, depth, node_bytes, h.data_offset + at, data.size() - at));
    }
    const auto* p = reinterpret_cast<const uint8_t*>(data.data() + at);
    at += node_bytes;
    if (h.binary) {
      // Children 0-3 in the first byte, 4-7 in the second, two bits each (low bit first).
      for (int child = 7; child >= 0; --child) {
        const uint8_t byte = p[child / 4];
        const int bits = (byte >> (2 * (child % 4))) & 3;
        if (bits == 0) continue;
        if (depth + 1 > kOctomapTreeDepth) {
          return bad(fmt::format("a node at byte {} is deeper than OctoMap's {} levels",
                                 h.data_offset + at - node_bytes, kOctomapTreeDepth));
        }
        if (bits == 3) {
          if (depth + 1 == kOctomapTreeDepth) {
            return bad(fmt::format("a node at byte {} has children below OctoMap's {} levels",
                                   h.data_offset + at - node_bytes, kOctomapTreeDepth));
          }
          pending.push_back(depth + 1);
        } else {
          ++nodes;  // a leaf: no bytes of its own
          if (nodes > h.size) {
            return bad(fmt::format("the tree has more nodes than its header declares (at byte {})",
                                   h.data_offset + at - node_bytes));
          }
        }
      }
      // Inner children are read after this node's leaves, in child order: pending holds them in
      // reverse already (pushed from child 7 down).
    } else {
      float log_odds = 0.0f;
      std::memcpy(&log_odds, p, sizeof(float));
      if (!std::isfinite(log_odds)) {
        return bad(fmt::format("node {} at byte {} has a log-odds of {}", nodes,
                               h.data_offset + at - node_bytes, log_odds));
      }
      const uint8_t children = p[value_bytes];
      if (children != 0 && depth + 1 > kOctomapTreeDepth) {
        return bad(fmt::format("node {} at byte {} has children below OctoMap's {} levels", nodes,
                               h.data_offset + at - node_bytes, kOctomapTreeDepth));
      }
      for (int child = 7; child >= 0; --child) {
        if ((children >> child) & 1) pending.push_back(depth + 1);
      }
    }
  }
  if (counted != nullptr) {
    // Counting (a message's tree, no header): the whole data must be the tree.
    *counted = nodes;
    if (at != data.size()) {
      return bad(fmt::format("{} bytes follow the tree's {} nodes", data.size() - at, nodes));
    }
    return Status::Ok();
  }
  if (nodes != h.size) {
    return bad(
        fmt::format("the tree ends at byte {} after {} nodes: the file is truncated or its "
                    "header's size is wrong",
                    h.data_offset + at, nodes));
  }
  if (at != data.size()) {
    return bad(fmt::format("{} unexpected bytes follow the tree (from byte {})", data.size() - at,
                           h.data_offset + at));
  }
  return Status::Ok();
}

/// After OctoMap's reader: the stream must have read the whole tree and nothing more, and the tree
/// must hold the nodes the header declares.
Status CheckOctomapRead(std::istream& in, size_t file_bytes, size_t tree_nodes,
                        const OctomapHeader& h, OctomapChatter& chatter, const fs::path& path) {
  const bool stream_ok = !in.fail();
  const std::streampos pos = stream_ok ? in.tellg() : std::streampos(-1);
  if (stream_ok && pos == static_cast<std::streampos>(file_bytes) && tree_nodes == h.size) {
    return Status::Ok();
  }
  return ParseError(fmt::format(
      "'{}': OctoMap's reader {} (read {} nodes of the {} the header declares){}", path.string(),
      stream_ok ? fmt::format("stopped at byte {} of {}", static_cast<int64_t>(pos), file_bytes)
                : std::string("failed"),
      tree_nodes, h.size, chatter.Quote()));
}

}  // namespace

const Limit& MaxOctomapNodes() {
  static const Limit limit("max_octomap_nodes", uint64_t{1} << 26, "nodes",
                           "nodes of one OctoMap tree read from a file (.bt, .ot)");
  return limit;
}

namespace {
// Registered when the program starts, so `avp --limit max_octomap_nodes=N` knows it.
[[maybe_unused]] const Limit& kRegisterMaxOctomapNodes = MaxOctomapNodes();
}  // namespace

Result<VoxelSet> ImportOctomapOccupied(const fs::path& path, size_t max_voxels) {
  AVP_ASSIGN_OR_RETURN(const std::string bytes, io::ReadFileBounded(path, "OctoMap file"));
  return ImportOctomapOccupiedBytes(bytes, path, max_voxels);
}

namespace {

/// Parses and checks an OctoMap file's bytes, lets OctoMap read the tree, checks what it read and
/// calls fn(header, tree) with the octomap::OcTree or octomap::ColorOcTree; returns fn's result.
template <class R, class Fn>
Result<R> WithCheckedOctomapTree(const std::string& bytes, const fs::path& path, Fn&& fn) {
  AVP_ASSIGN_OR_RETURN(const OctomapHeader h, ParseOctomapHeader(bytes, path));
  AVP_RETURN_IF_ERROR(
      MaxOctomapNodes().Check(fmt::format("OctoMap tree of '{}'", path.string()), h.size));
  const std::string_view data = std::string_view(bytes).substr(h.data_offset);
  const bool color = h.id == "ColorOcTree";
  if (!h.binary && h.id != "OcTree" && !color) {
    // Let OctoMap say whether it knows the type at all (it prints why not).
    std::string known;
    {
      OctomapChatter chatter;
      std::unique_ptr<octomap::AbstractOcTree> tree(
          octomap::AbstractOcTree::createTree(h.id, h.resolution_m));
      if (!tree) {
        return ParseError(fmt::format("'{}' holds an OctoMap tree of unknown type {}{}",
                                      path.string(), QuoteText(h.id), chatter.Quote()));
      }
    }
    return ParseError(fmt::format(
        "'{}' holds an OctoMap tree of type {}; only OcTree and ColorOcTree can be imported",
        path.string(), QuoteText(h.id)));
  }
  const size_t value_bytes = color ? sizeof(float) + 3 : sizeof(float);
  AVP_RETURN_IF_ERROR(CheckOctomapTree(data, h, value_bytes, path));

  // The tree is well formed: OctoMap reads it, and what it read is checked again.
  std::istringstream in(bytes, std::ios::binary);
  in.seekg(static_cast<std::streamoff>(h.data_offset));
  if (h.binary) {
    octomap::OcTree tree(h.resolution_m);
    {
      OctomapChatter chatter;
      if (h.size > 0) tree.readBinaryData(in);
      AVP_RETURN_IF_ERROR(CheckOctomapRead(in, bytes.size(), tree.size(), h, chatter, path));
    }
    return fn(h, tree);
  }
  if (color) {
    octomap::ColorOcTree tree(h.resolution_m);
    {
      OctomapChatter chatter;
      if (h.size > 0) tree.readData(in);
      AVP_RETURN_IF_ERROR(CheckOctomapRead(in, bytes.size(), tree.size(), h, chatter, path));
    }
    return fn(h, tree);
  }
  octomap::OcTree tree(h.resolution_m);
  {
    OctomapChatter chatter;
    if (h.size > 0) tree.readData(in);
    AVP_RETURN_IF_ERROR(CheckOctomapRead(in, bytes.size(), tree.size(), h, chatter, path));
  }
  return fn(h, tree);
}

/// The leaves of `tree` (occupied and free) as a SemanticMap: see ImportOctomapMapBytes.
template <class Tree>
Result<OctomapMapImport> TreeToMap(const OctomapHeader& h, const Tree& tree, size_t max_voxels,
                                   const fs::path& path) {
  constexpr bool kColor = std::is_same_v<Tree, octomap::ColorOcTree>;
  MapOptions options;
  options.grid.voxel_size_m = tree.getResolution();
  if (const Status s = options.Validate(); !s.ok()) {
    return InvalidArgumentError(
        fmt::format("'{}': its OctoMap resolution {} m cannot be an avp map's voxel size: {}",
                    path.string(), tree.getResolution(), s.message()));
  }
  const unsigned tree_depth = tree.getTreeDepth();
  // Pass 1: counts, so that nothing is allocated for a tree that expands too far.
  uint64_t occupied_total = 0, free_total = 0;
  size_t occupied_leaves = 0, free_leaves = 0, coarse = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const unsigned level = tree_depth - it.getDepth();
    const uint64_t n = uint64_t{1} << (3 * level);
    if (level > 0) ++coarse;
    if (tree.isNodeOccupied(*it)) {
      ++occupied_leaves;
      occupied_total += n;
      if (occupied_total > max_voxels) {
        return OutOfRangeError(fmt::format(
            "'{}': expanding the occupied leaves to {} m voxels needs more than {} voxels (a leaf "
            "of depth {} alone covers {}^3)",
            path.string(), tree.getResolution(), max_voxels, it.getDepth(), uint64_t{1} << level));
      }
    } else {
      ++free_leaves;
      free_total = std::min<uint64_t>(free_total + n, uint64_t{1} << 62);
    }
  }
  OctomapMapImport out;
  out.map = SemanticMap(options);
  out.binary = h.binary;
  out.tree_type = h.id;
  out.tree_nodes = h.size;
  out.occupied_leaves = occupied_leaves;
  out.free_leaves = free_leaves;
  out.coarse_leaves = coarse;
  out.free_space_dropped = free_total > max_voxels;
  OccupancyGrid& grid = out.map.grid();
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const bool occupied = tree.isNodeOccupied(*it);
    if (!occupied && out.free_space_dropped) continue;
    const unsigned level = tree_depth - it.getDepth();
    const octomap::OcTreeKey base = it.getIndexKey();
    const int n = 1 << level;
    const float log_odds = it->getLogOdds();
    SemanticClass cls = SemanticClass::kBackground;
    if constexpr (kColor) {
      if (occupied) {
        const octomap::ColorOcTreeNode::Color c = it->getColor();
        const std::array<uint8_t, 3> rgb = {c.r, c.g, c.b};
        cls = ClassOfOctomapColor(rgb);
        const size_t voxels = size_t{1} << (3 * level);
        if (cls != SemanticClass::kBackground) {
          out.labelled_by_colour += voxels;
        } else if (rgb == kUnlabelledOccupiedColor) {
          out.unlabelled_grey += voxels;
        } else {
          out.foreign_colour += voxels;
        }
      }
    }
    for (int dz = 0; dz < n; ++dz) {
      for (int dy = 0; dy < n; ++dy) {
        for (int dx = 0; dx < n; ++dx) {
          const VoxelKey k = FromOctomapKey(static_cast<uint16_t>(base[0] + dx),
                                            static_cast<uint16_t>(base[1] + dy),
                                            static_cast<uint16_t>(base[2] + dz));
          grid.SetLogOdds(k, log_odds);
          if (occupied) {
            ++out.occupied_voxels;
          } else {
            ++out.free_voxels;
          }
          if (cls == SemanticClass::kBackground) continue;
          SemanticCell* cell = grid.MutableSemantic(k);
          if (cell == nullptr) continue;
          cell->semantic_class = static_cast<uint8_t>(cls);
          cell->confidence = 1.0f;
          cell->observations = 1;
        }
      }
    }
  }
  grid.ClearChanges();
  out.map.semantics().ResetFromGrid(grid);
  return out;
}

}  // namespace

Result<VoxelSet> ImportOctomapOccupiedBytes(const std::string& bytes, const fs::path& path,
                                            size_t max_voxels) {
  return WithCheckedOctomapTree<VoxelSet>(
      bytes, path, [&](const OctomapHeader&, const auto& tree) -> Result<VoxelSet> {
        return CollectOccupied(tree, max_voxels, path);
      });
}

SemanticClass ClassOfOctomapColor(const std::array<uint8_t, 3>& rgb) {
  for (SemanticClass c : AllSemanticClasses()) {
    if (c == SemanticClass::kBackground) continue;
    const auto k = io::ClassColor(c);
    if (k[0] == rgb[0] && k[1] == rgb[1] && k[2] == rgb[2]) return c;
  }
  return SemanticClass::kBackground;
}

Result<OctomapMapImport> ImportOctomapMapBytes(const std::string& bytes, const fs::path& path,
                                               size_t max_voxels) {
  return WithCheckedOctomapTree<OctomapMapImport>(
      bytes, path, [&](const OctomapHeader& h, const auto& tree) -> Result<OctomapMapImport> {
        return TreeToMap(h, tree, max_voxels, path);
      });
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

Result<std::string> OctomapMessageFileBytes(std::string_view id, bool binary, double resolution_m,
                                            std::string_view data, std::string_view what) {
  if (id != "OcTree" && id != "ColorOcTree") {
    return ParseError(
        fmt::format("{}: an OctoMap tree of type {}; only OcTree and ColorOcTree "
                    "can be read",
                    what, QuoteText(id)));
  }
  if (binary && id != "OcTree") {
    return ParseError(
        fmt::format("{}: a binary tree must be an OcTree, not {}", what, QuoteText(id)));
  }
  if (!std::isfinite(resolution_m) || resolution_m < kMinOctomapResolution ||
      resolution_m > kMaxOctomapResolution) {
    return ParseError(fmt::format("{}: resolution {} m outside [{}, {}]", what, resolution_m,
                                  kMinOctomapResolution, kMaxOctomapResolution));
  }
  OctomapHeader h;
  h.binary = binary;
  h.id = std::string(id);
  h.size = MaxOctomapNodes().value();
  h.resolution_m = resolution_m;
  uint64_t nodes = 0;
  if (!data.empty()) {
    const size_t value_bytes = id == "ColorOcTree" ? sizeof(float) + 3 : sizeof(float);
    AVP_RETURN_IF_ERROR(CheckOctomapTree(data, h, value_bytes, fs::path(what), &nodes));
  }
  return fmt::format("{}\nid {}\nsize {}\nres {}\ndata\n", binary ? kBinaryHeader : kGeneralHeader,
                     id, nodes, resolution_m) +
         std::string(data);
}

}  // namespace avp::mapping

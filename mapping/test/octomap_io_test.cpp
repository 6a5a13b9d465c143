// OctoMap interop: the shared lattice (avp key + 32768 = OcTreeKey), .bt export read back by
// liboctomap and by octomap-tools' convert_octree, .ot ColorOcTree export with class colours,
// .bt import with pruned leaves expanded, the key-range guard, and the ground-truth comparison.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>
#include <sys/wait.h>

#include <avp/core/rng.h>
#include <avp/io/label_preview.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/semantic_map.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::mapping {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

octomap::OcTreeKey OcKey(const VoxelKey& k) {
  const auto key = ToOctomapKey(k);
  return octomap::OcTreeKey(key[0], key[1], key[2]);
}

/// Occupied, free and in-between voxels around the origin (negative keys included), an aligned
/// 4x4x4 occupied cube (so the .bt export prunes it into coarse leaves), and labelled voxels of
/// several classes.
SemanticMap MakeMap(double voxel_size_m = 0.005) {
  MapOptions options;
  options.grid.voxel_size_m = voxel_size_m;
  SemanticMap map(options);
  OccupancyGrid& grid = map.grid();
  const float hi = grid.clamp_max_log_odds();
  const float lo = grid.clamp_min_log_odds();
  Rng rng(5);
  for (int i = 0; i < 4000; ++i) {
    const VoxelKey k{static_cast<int32_t>(rng.UniformInt(-40, 40)),
                     static_cast<int32_t>(rng.UniformInt(-40, 40)),
                     static_cast<int32_t>(rng.UniformInt(-10, 30))};
    const double u = rng.Uniform01();
    grid.SetLogOdds(k, u < 0.3 ? hi : (u < 0.7 ? lo : static_cast<float>(rng.Uniform(lo, hi))));
  }
  for (int z = 40; z < 44; ++z) {
    for (int y = -8; y < -4; ++y) {
      for (int x = 16; x < 20; ++x) grid.SetLogOdds({x, y, z}, hi);
    }
  }
  const SemanticClass classes[] = {SemanticClass::kFruit, SemanticClass::kLeaf,
                                   SemanticClass::kStem};
  for (int i = 0; i < 30; ++i) {
    const VoxelKey k{i - 15, 50, 50 + i % 3};
    grid.SetLogOdds(k, hi);
    SemanticCell* c = grid.MutableSemantic(k);
    c->semantic_class = static_cast<uint8_t>(classes[i % 3]);
    c->confidence = 0.9f;
    c->instance_id = static_cast<uint16_t>(i % 3 == 0 ? 1 : 0);
  }
  return map;
}

/// Runs a shell command; returns its exit status (or -1 if it did not exit normally).
int RunCommand(const std::string& command) {
  const int status = std::system(command.c_str());
  if (status == -1 || !WIFEXITED(status)) return -1;
  return WEXITSTATUS(status);
}

/// The octomap-tools program `name`, which scripts/setup installs (Debian package octomap-tools).
std::string OctomapTool(const std::string& name) {
  for (const char* dir : {"/usr/bin", "/usr/local/bin"}) {
    const fs::path p = fs::path(dir) / name;
    if (fs::exists(p)) return p.string();
  }
  return {};
}

std::string ReadText(const fs::path& path) { return test::ReadWholeFile(path); }

/// Every voxel covered by an occupied/free leaf of `tree`, expanded to the finest level.
template <class Tree>
void ExpandLeaves(const Tree& tree, std::set<VoxelKey>& occupied, std::set<VoxelKey>& free) {
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const int n = 1 << (tree.getTreeDepth() - it.getDepth());
    const octomap::OcTreeKey base = it.getIndexKey();
    auto& target = tree.isNodeOccupied(*it) ? occupied : free;
    for (int dz = 0; dz < n; ++dz) {
      for (int dy = 0; dy < n; ++dy) {
        for (int dx = 0; dx < n; ++dx) {
          target.insert(FromOctomapKey(static_cast<uint16_t>(base[0] + dx),
                                       static_cast<uint16_t>(base[1] + dy),
                                       static_cast<uint16_t>(base[2] + dz)));
        }
      }
    }
  }
}

/// The tree holds exactly our occupied and free voxels: nothing else is known to it.
template <class Tree>
void ExpectSameOccupancy(const Tree& tree, const OccupancyGrid& grid) {
  std::set<VoxelKey> occupied, free;
  ExpandLeaves(tree, occupied, free);
  size_t ours_occupied = 0, ours_free = 0;
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float) {
    if (grid.State(k) == VoxelState::kOccupied) {
      ++ours_occupied;
      EXPECT_TRUE(occupied.count(k)) << "voxel " << k.x << "," << k.y << "," << k.z;
    } else {
      ++ours_free;
      EXPECT_TRUE(free.count(k)) << "voxel " << k.x << "," << k.y << "," << k.z;
    }
  });
  EXPECT_EQ(occupied.size(), ours_occupied);
  EXPECT_EQ(free.size(), ours_free);
}

class OctomapIoTest : public test::TempDirTest {};

TEST(OctomapLatticeTest, OctomapKeysAreOurKeysPlus32768) {
  for (const double s : {0.002, 0.005, 0.006, 0.01, 0.02}) {
    const octomap::OcTree tree(s);
    Rng rng(11);
    for (int i = 0; i < 20000; ++i) {
      // Points anywhere in +-50 m, and points a hair off voxel boundaries.
      Eigen::Vector3d p(rng.Uniform(-50, 50), rng.Uniform(-50, 50), rng.Uniform(-50, 50));
      if (i % 2 == 1) {
        for (int a = 0; a < 3; ++a) p[a] = std::round(p[a] / s) * s + rng.Uniform(-1e-7, 1e-7);
      }
      const VoxelKey k = VoxelKey::FromPoint(p, s);
      const octomap::OcTreeKey ok = tree.coordToKey(p.x(), p.y(), p.z());  // double overload
      ASSERT_EQ(OcKey(k), ok) << "p = " << p.transpose() << " s = " << s;
      ASSERT_EQ(FromOctomapKey(ok[0], ok[1], ok[2]), k);
      const Eigen::Vector3d c = k.Center(s);
      EXPECT_NEAR(tree.keyToCoord(ok[0]), c.x(), 1e-9);
      EXPECT_NEAR(tree.keyToCoord(ok[1]), c.y(), 1e-9);
      EXPECT_NEAR(tree.keyToCoord(ok[2]), c.z(), 1e-9);
    }
  }
  // The extremes of OctoMap's key range.
  EXPECT_TRUE(InOctomapKeyRange({-32768, 0, 32767}));
  EXPECT_FALSE(InOctomapKeyRange({32768, 0, 0}));
  EXPECT_FALSE(InOctomapKeyRange({0, -32769, 0}));
  EXPECT_EQ(ToOctomapKey({-32768, 0, 32767}), (std::array<uint16_t, 3>{0, 32768, 65535}));
}

TEST_F(OctomapIoTest, BinaryExportReadsBackWithTheSameStates) {
  const SemanticMap map = MakeMap();
  const fs::path path = dir_ / "map.bt";
  const auto stats = ExportOctomapBinary(map.grid(), path);
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  EXPECT_EQ(stats->occupied_voxels, map.grid().CountOccupiedVoxels());
  EXPECT_EQ(stats->occupied_voxels + stats->free_voxels, map.grid().CountKnownVoxels());
  EXPECT_LT(stats->leaf_nodes, map.grid().CountKnownVoxels());  // the cube was pruned
  EXPECT_EQ(stats->file_bytes, fs::file_size(path));

  octomap::OcTree tree(0.1);
  ASSERT_TRUE(tree.readBinary(path.string()));
  EXPECT_DOUBLE_EQ(tree.getResolution(), 0.005);
  ExpectSameOccupancy(tree, map.grid());
  // Byte for byte what liboctomap's own writeBinary writes for that tree.
  std::ostringstream rewritten;
  ASSERT_TRUE(tree.writeBinary(rewritten));
  EXPECT_TRUE(rewritten.str() == ReadText(path)) << "the .bt differs from OcTree::writeBinary's";
  // And a point query through OctoMap's own coordinates lands on our voxel.
  const VoxelKey k{17, -6, 41};
  const Eigen::Vector3d c = map.grid().CenterOf(k);
  const octomap::OcTreeNode* node = tree.search(c.x(), c.y(), c.z());
  ASSERT_NE(node, nullptr);
  EXPECT_TRUE(tree.isNodeOccupied(node));
  EXPECT_EQ(tree.search(10.0, 10.0, 10.0), nullptr);  // unknown stays unknown
}

TEST_F(OctomapIoTest, OctomapToolsReadTheBinaryExport) {
  const std::string convert = OctomapTool("convert_octree");
  ASSERT_FALSE(convert.empty())
      << "octomap-tools' convert_octree was not found in /usr/bin: run scripts/setup (it installs "
         "the Debian package octomap-tools)";
  const SemanticMap map = MakeMap();
  const fs::path bt = dir_ / "map.bt";
  ASSERT_TRUE(ExportOctomapBinary(map.grid(), bt).ok());
  const fs::path ot = dir_ / "converted.ot";
  const fs::path log = dir_ / "convert.log";
  const int rc = RunCommand(
      fmt::format("'{}' '{}' '{}' > '{}' 2>&1", convert, bt.string(), ot.string(), log.string()));
  ASSERT_EQ(rc, 0) << "convert_octree failed:\n" << ReadText(log);
  ASSERT_TRUE(fs::exists(ot)) << ReadText(log);
  std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(ot.string()));
  ASSERT_NE(tree, nullptr);
  const auto* octree = dynamic_cast<const octomap::OcTree*>(tree.get());
  ASSERT_NE(octree, nullptr) << "convert_octree wrote a " << tree->getTreeType();
  ExpectSameOccupancy(*octree, map.grid());

  // bt2vrml writes one box per occupied leaf of the .bt: together they cover exactly our
  // occupied voxels.
  const std::string bt2vrml = OctomapTool("bt2vrml");
  ASSERT_FALSE(bt2vrml.empty())
      << "octomap-tools' bt2vrml was not found in /usr/bin: run scripts/setup";
  const int rc2 = RunCommand(
      fmt::format("cd '{}' && '{}' map.bt > '{}' 2>&1", dir_.string(), bt2vrml, log.string()));
  ASSERT_EQ(rc2, 0) << "bt2vrml failed:\n" << ReadText(log);
  std::ifstream wrl(dir_ / "map.bt.wrl");
  ASSERT_TRUE(wrl.good()) << ReadText(log);
  std::string token;
  std::set<VoxelKey> boxes;
  const double s = map.voxel_size_m();
  size_t transforms = 0;
  while (wrl >> token) {
    if (token != "translation") continue;
    double x, y, z, size;
    ASSERT_TRUE(wrl >> x >> y >> z);
    while (wrl >> token && token != "size") {
    }
    ASSERT_TRUE(wrl >> size);
    ++transforms;
    const auto n = std::lround(size / s);
    const VoxelKey min{static_cast<int32_t>(std::lround((x - size / 2) / s)),
                       static_cast<int32_t>(std::lround((y - size / 2) / s)),
                       static_cast<int32_t>(std::lround((z - size / 2) / s))};
    for (int dz = 0; dz < n; ++dz) {
      for (int dy = 0; dy < n; ++dy) {
        for (int dx = 0; dx < n; ++dx) boxes.insert({min.x + dx, min.y + dy, min.z + dz});
      }
    }
  }
  const auto imported = ImportOctomapOccupied(bt);
  ASSERT_TRUE(imported.ok());
  EXPECT_EQ(transforms, imported->occupied_leaves);
  EXPECT_GT(imported->coarse_leaves, 0u);
  EXPECT_EQ(boxes.size(), map.grid().CountOccupiedVoxels());
  EXPECT_TRUE(std::equal(boxes.begin(), boxes.end(), imported->keys.begin(), imported->keys.end()));
}

TEST_F(OctomapIoTest, ColorExportKeepsLogOddsAndClassColours) {
  const SemanticMap map = MakeMap();
  const fs::path path = dir_ / "map.ot";
  const auto stats = ExportOctomapColor(map, path);
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  EXPECT_EQ(stats->labelled_voxels, 30u);

  std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(path.string()));
  ASSERT_NE(tree, nullptr);
  const auto* color = dynamic_cast<const octomap::ColorOcTree*>(tree.get());
  ASSERT_NE(color, nullptr) << "read a " << tree->getTreeType();
  EXPECT_DOUBLE_EQ(color->getResolution(), 0.005);
  size_t checked = 0;
  map.grid().ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    const octomap::ColorOcTreeNode* node = color->search(OcKey(k));
    ASSERT_NE(node, nullptr);
    EXPECT_EQ(node->getLogOdds(), log_odds);  // full probabilities, bit-exact
    if (map.State(k) != VoxelState::kOccupied) return;
    const SemanticCell* cell = map.Semantic(k);
    const auto expected = cell != nullptr && cell->has_label()
                              ? io::ClassColor(cell->cls())
                              : Eigen::Matrix<uint8_t, 3, 1>(128, 128, 128);
    const auto c = node->getColor();
    EXPECT_EQ(c.r, expected[0]);
    EXPECT_EQ(c.g, expected[1]);
    EXPECT_EQ(c.b, expected[2]);
    ++checked;
  });
  EXPECT_EQ(checked, map.grid().CountOccupiedVoxels());
  // Fruit is red, leaf green.
  const auto* fruit = color->search(OcKey({-15, 50, 50}));
  ASSERT_NE(fruit, nullptr);
  EXPECT_GT(fruit->getColor().r, 200);
  const auto* leaf = color->search(OcKey({-14, 50, 51}));
  ASSERT_NE(leaf, nullptr);
  EXPECT_GT(leaf->getColor().g, leaf->getColor().r);

  // Importing the .ot gives our occupied voxels.
  const auto set = ImportOctomapOccupied(path);
  ASSERT_TRUE(set.ok()) << set.status().ToString();
  EXPECT_EQ(set->keys.size(), map.grid().CountOccupiedVoxels());
}

TEST_F(OctomapIoTest, ExportRefusesVoxelsOutsideOctomapKeyRange) {
  MapOptions options;
  options.grid.voxel_size_m = 0.02;
  SemanticMap map(options);
  ASSERT_TRUE(map.grid().SetLogOdds({-32768, 0, 32767}, 2.0f));  // the extremes: fine
  EXPECT_TRUE(ExportOctomapBinary(map.grid(), dir_ / "edge.bt").ok());
  ASSERT_TRUE(map.grid().SetLogOdds({40000, 1, 2}, 2.0f));
  for (const auto& r : {ExportOctomapBinary(map.grid(), dir_ / "far.bt"),
                        ExportOctomapColor(map, dir_ / "far.ot")}) {
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kOutOfRange);
    EXPECT_THAT(r.status().message(), HasSubstr("(40000, 1, 2)"));
    EXPECT_THAT(r.status().message(), HasSubstr("OctoMap"));
  }
  EXPECT_FALSE(fs::exists(dir_ / "far.bt"));
}

TEST_F(OctomapIoTest, ImportExpandsPrunedLeaves) {
  const double s = 0.006;  // the reference system's ground-truth resolution
  octomap::OcTree tree(s);
  std::set<VoxelKey> expected;
  // An aligned 8^3 cube (pruned into one leaf three levels up) in negative coordinates ...
  for (int z = -16; z < -8; ++z) {
    for (int y = 8; y < 16; ++y) {
      for (int x = -24; x < -16; ++x) {
        tree.updateNode(OcKey({x, y, z}), true);
        expected.insert({x, y, z});
      }
    }
  }
  // ... an aligned 2^3 cube, single voxels, and free voxels (not imported).
  for (int i = 0; i < 8; ++i) {
    const VoxelKey k{100 + (i & 1), 200 + ((i >> 1) & 1), 300 + (i >> 2)};
    tree.updateNode(OcKey(k), true);
    expected.insert(k);
  }
  for (const VoxelKey k : {VoxelKey{1, 2, 3}, VoxelKey{-7, 0, 5}, VoxelKey{0, 0, 0}}) {
    tree.updateNode(OcKey(k), true);
    expected.insert(k);
  }
  for (int x = 50; x < 60; ++x) tree.updateNode(OcKey({x, 0, 0}), false);
  tree.updateInnerOccupancy();
  tree.prune();
  const fs::path path = dir_ / "gt.bt";
  ASSERT_TRUE(tree.writeBinary(path.string()));

  const auto set = ImportOctomapOccupied(path);
  ASSERT_TRUE(set.ok()) << set.status().ToString();
  EXPECT_DOUBLE_EQ(set->resolution_m, s);
  EXPECT_GE(set->coarse_leaves, 2u);
  EXPECT_EQ(set->occupied_leaves, 1u + 1u + 3u);
  ASSERT_EQ(set->keys.size(), expected.size());
  EXPECT_TRUE(std::equal(set->keys.begin(), set->keys.end(), expected.begin()));
  EXPECT_TRUE(std::is_sorted(set->keys.begin(), set->keys.end()));

  // A limit below the expansion is a clear error, not an allocation.
  const auto limited = ImportOctomapOccupied(path, 100);
  ASSERT_FALSE(limited.ok());
  EXPECT_EQ(limited.status().code(), StatusCode::kOutOfRange);
  EXPECT_THAT(limited.status().message(), HasSubstr("more than 100 voxels"));
}

TEST_F(OctomapIoTest, ImportErrorsNameTheFile) {
  auto r = ImportOctomapOccupied(dir_ / "missing.bt");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(r.status().message(), HasSubstr("missing.bt"));

  const fs::path text = Write("notes.bt", "hello\nworld\n");
  r = ImportOctomapOccupied(text);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kParseError);
  EXPECT_THAT(r.status().message(), HasSubstr("not an OctoMap file"));
  EXPECT_THAT(r.status().message(), HasSubstr("'hello'"));

  // A .bt whose data stops half-way: liboctomap's own complaint is quoted.
  octomap::OcTree tree(0.01);
  for (int x = 0; x < 200; ++x) tree.updateNode(OcKey({x, x % 7, x % 5}), true);
  std::ostringstream bt;
  ASSERT_TRUE(tree.writeBinary(bt));
  const std::string full = bt.str();
  const fs::path cut = dir_ / "cut.bt";
  std::ofstream(cut, std::ios::binary) << full.substr(0, full.size() / 2);
  r = ImportOctomapOccupied(cut);
  ASSERT_FALSE(r.ok()) << "a truncated .bt was accepted with " << r->keys.size() << " voxels";
  EXPECT_EQ(r.status().code(), StatusCode::kParseError);
  EXPECT_THAT(r.status().message(), HasSubstr("cut.bt"));
}

TEST(GroundTruthCompareTest, CountsBothWaysWithTolerance) {
  const std::vector<VoxelKey> predicted = {{0, 0, 0}, {1, 0, 0}, {5, 5, 5}};
  const std::vector<VoxelKey> gt = {{0, 0, 0}, {2, 0, 0}, {10, 10, 10}, {0, 0, 0}};
  const GroundTruthComparison exact = CompareVoxelSets(predicted, gt, 0);
  EXPECT_EQ(exact.predicted, 3u);
  EXPECT_EQ(exact.ground_truth, 3u);
  EXPECT_EQ(exact.tp, 1u);
  EXPECT_EQ(exact.fp, 2u);
  EXPECT_EQ(exact.gt_found, 1u);
  EXPECT_EQ(exact.fn, 2u);
  EXPECT_DOUBLE_EQ(exact.precision, 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(exact.recall, 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(exact.f1, 1.0 / 3.0);

  const GroundTruthComparison tol = CompareVoxelSets(predicted, gt, 1);
  EXPECT_EQ(tol.tp, 2u);  // (0,0,0) and (1,0,0) have a GT voxel within 1
  EXPECT_EQ(tol.fp, 1u);
  EXPECT_EQ(tol.gt_found, 2u);  // (0,0,0) and (2,0,0) have a prediction within 1
  EXPECT_EQ(tol.fn, 1u);
  EXPECT_DOUBLE_EQ(tol.precision, 2.0 / 3.0);
  EXPECT_DOUBLE_EQ(tol.recall, 2.0 / 3.0);

  // Asymmetric: one prediction near two GT voxels counts once on each side.
  const GroundTruthComparison asym = CompareVoxelSets({{0, 0, 0}}, {{1, 1, 1}, {-1, 0, 1}}, 1);
  EXPECT_EQ(asym.tp, 1u);
  EXPECT_EQ(asym.gt_found, 2u);
  EXPECT_DOUBLE_EQ(asym.precision, 1.0);
  EXPECT_DOUBLE_EQ(asym.recall, 1.0);

  const GroundTruthComparison empty = CompareVoxelSets({}, {}, 1);
  EXPECT_EQ(empty.precision, 0.0);
  EXPECT_EQ(empty.recall, 0.0);
  EXPECT_EQ(empty.f1, 0.0);
}

TEST(GroundTruthCompareTest, UsesOccupiedVoxelsOfTheClassAndResamples) {
  MapOptions options;
  options.grid.voxel_size_m = 0.006;
  SemanticMap map(options);
  OccupancyGrid& grid = map.grid();
  const auto label = [&](const VoxelKey& k, SemanticClass c, float log_odds) {
    grid.SetLogOdds(k, log_odds);
    grid.MutableSemantic(k)->semantic_class = static_cast<uint8_t>(c);
  };
  const float hi = grid.clamp_max_log_odds();
  label({0, 0, 0}, SemanticClass::kFruit, hi);
  label({1, 0, 0}, SemanticClass::kFruit, hi);
  label({2, 0, 0}, SemanticClass::kFruit, grid.clamp_min_log_odds());  // free: not predicted
  label({3, 0, 0}, SemanticClass::kLeaf, hi);                          // other class
  grid.SetLogOdds({4, 0, 0}, hi);                                      // unlabelled
  EXPECT_EQ(OccupiedVoxelsOfClass(grid, SemanticClass::kFruit),
            (std::vector<VoxelKey>{{0, 0, 0}, {1, 0, 0}}));

  VoxelSet gt{0.006, {{0, 0, 0}, {2, 0, 0}, {3, 0, 0}}, 3, 0};
  auto r = CompareToGroundTruth(grid, gt, {.tolerance_voxels = 0});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(r->resampled);
  EXPECT_EQ(r->tp, 1u);
  EXPECT_EQ(r->fp, 1u);
  EXPECT_EQ(r->fn, 2u);

  // GT at 3 mm: centres of voxels 0..3 (0 - 12 mm) fall into map voxels 0, 0, 1, 1.
  VoxelSet fine{0.003, {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}}, 4, 0};
  r = CompareToGroundTruth(grid, fine, {.tolerance_voxels = 0});
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->resampled);
  EXPECT_EQ(r->gt_voxels_original, 4u);
  EXPECT_EQ(r->ground_truth, 2u);
  EXPECT_EQ(r->tp, 2u);
  EXPECT_DOUBLE_EQ(r->f1, 1.0);

  EXPECT_FALSE(CompareToGroundTruth(grid, gt, {.tolerance_voxels = -1}).ok());
  EXPECT_FALSE(CompareToGroundTruth(grid, VoxelSet{0.0, {}, 0, 0}).ok());
}

}  // namespace
}  // namespace avp::mapping

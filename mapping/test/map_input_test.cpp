// Hostile and broken map inputs (issue 15): OctoMap files are checked before and after OctoMap
// reads them (a truncated .ot given as ground truth used to load as a different tree), what
// OctoMap prints is quoted escaped, and .avpmap block counts are bounded before allocating.

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>

#include <avp/core/limits.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/semantic_map.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::mapping {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

octomap::OcTreeKey OcKey(const VoxelKey& k) {
  const auto key = ToOctomapKey(k);
  return octomap::OcTreeKey(key[0], key[1], key[2]);
}

class MapInputTest : public test::TempDirTest {
 protected:
  std::string ReadBytes(const fs::path& path) { return test::ReadWholeFile(path); }
  fs::path WriteBytes(const std::string& name, const std::string& bytes) {
    const fs::path path = dir_ / name;
    std::ofstream(path, std::ios::binary) << bytes;
    return path;
  }
  /// A ground truth as `avp map gt` would give: 1690 occupied voxels on a sphere shell, written by
  /// OctoMap itself as a ColorOcTree (.ot) or an OcTree (.bt).
  fs::path WriteGroundTruth(const std::string& name, size_t* voxels) {
    octomap::ColorOcTree color(0.006);
    octomap::OcTree plain(0.006);
    size_t n = 0;
    for (int z = -12; z <= 12; ++z) {
      for (int y = -12; y <= 12; ++y) {
        for (int x = -12; x <= 12; ++x) {
          const int r2 = x * x + y * y + z * z;
          if (r2 < 100 || r2 > 130) continue;
          color.updateNode(OcKey({x + 40, y, z + 60}), true)->setColor(200, 20, 20);
          plain.updateNode(OcKey({x + 40, y, z + 60}), true);
          ++n;
        }
      }
    }
    *voxels = n;
    const fs::path path = dir_ / name;
    if (path.extension() == ".bt") {
      EXPECT_TRUE(plain.writeBinary(path.string()));
    } else {
      color.updateInnerOccupancy();
      EXPECT_TRUE(color.write(path.string()));
    }
    return path;
  }
};

TEST_F(MapInputTest, WholeOctomapFilesStillImport) {
  for (const std::string name : {"gt.ot", "gt.bt"}) {
    size_t voxels = 0;
    const fs::path path = WriteGroundTruth(name, &voxels);
    const Result<VoxelSet> set = ImportOctomapOccupied(path);
    ASSERT_TRUE(set.ok()) << set.status().ToString();
    EXPECT_EQ(set->keys.size(), voxels) << name;
    EXPECT_DOUBLE_EQ(set->resolution_m, 0.006);
  }
}

TEST_F(MapInputTest, TruncatedOctomapFilesAreRefusedAtEveryLength) {
  for (const std::string name : {"gt.ot", "gt.bt"}) {
    size_t voxels = 0;
    const std::string bytes = ReadBytes(WriteGroundTruth(name, &voxels));
    ASSERT_GT(bytes.size(), 1000u);
    const size_t header = bytes.find("data\n") + 5;
    for (const size_t length : {size_t{0}, size_t{10}, header - 3, header, header + 1, header + 7,
                                bytes.size() / 2, bytes.size() - 5, bytes.size() - 1}) {
      const fs::path cut =
          WriteBytes("cut" + fs::path(name).extension().string(), bytes.substr(0, length));
      const Result<VoxelSet> set = ImportOctomapOccupied(cut);
      ASSERT_FALSE(set.ok()) << name << " cut to " << length << " of " << bytes.size()
                             << " bytes read as " << set->keys.size() << " voxels";
      EXPECT_EQ(set.status().code(), StatusCode::kParseError) << set.status().ToString();
      EXPECT_THAT(set.status().message(), HasSubstr(cut.string()));
      if (length > header) {
        EXPECT_THAT(set.status().message(), HasSubstr("truncated")) << set.status().ToString();
      }
    }
  }
}

TEST_F(MapInputTest, OctomapTreesMustMatchTheirHeaderExactly) {
  size_t voxels = 0;
  const std::string bytes = ReadBytes(WriteGroundTruth("gt.ot", &voxels));
  // Bytes after the tree.
  Status s = ImportOctomapOccupied(WriteBytes("tail.ot", bytes + "junk")).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), HasSubstr("4 unexpected bytes follow the tree"));
  // A node count that is not the tree's.
  const size_t at = bytes.find("size ");
  const size_t end = bytes.find('\n', at);
  const uint64_t nodes = std::stoull(bytes.substr(at + 5, end - at - 5));
  const std::string more =
      bytes.substr(0, at) + "size " + std::to_string(nodes + 1) + bytes.substr(end);
  s = ImportOctomapOccupied(WriteBytes("more.ot", more)).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), HasSubstr("truncated"));
  const std::string fewer =
      bytes.substr(0, at) + "size " + std::to_string(nodes - 1) + bytes.substr(end);
  s = ImportOctomapOccupied(WriteBytes("fewer.ot", fewer)).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), HasSubstr("more nodes than its header declares"));
  // Header values are parsed strictly and their ranges named.
  for (const auto& [from, to, expect] :
       std::vector<std::tuple<std::string, std::string, std::string>>{
           {"res 0.006", "res nan", "res 'nan' must be a voxel edge in [0.0001, 100] m"},
           {"res 0.006", "res 0.006x", "res '0.006x'"},
           {"size ", "size -", "must be a node count"},
           {"size ", "size 99999999999", "must be a node count in [0, 4294967295]"}}) {
    std::string edited = bytes;
    edited.replace(edited.find(from), from.size(), to);
    s = ImportOctomapOccupied(WriteBytes("edited.ot", edited)).status();
    EXPECT_EQ(s.code(), StatusCode::kParseError) << to;
    EXPECT_THAT(s.message(), HasSubstr(expect)) << s.ToString();
  }
}

TEST_F(MapInputTest, OctomapNodeCountIsBoundedBeforeReading) {
  size_t voxels = 0;
  const fs::path path = WriteGroundTruth("gt.bt", &voxels);
  const ScopedLimit small(MaxOctomapNodes(), 100);
  const Status s = ImportOctomapOccupied(path).status();
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted) << s.ToString();
  EXPECT_THAT(s.message(), HasSubstr("max_octomap_nodes = 100"));
}

TEST_F(MapInputTest, ACraftedDeepTreeIsRefusedWithoutRecursing) {
  // Every node says "child 0 follows": OctoMap's reader would recurse as deep as the file goes.
  std::string tree;
  const int nodes = 100000;
  for (int i = 0; i < nodes; ++i) {
    const float log_odds = 1.0f;
    tree.append(reinterpret_cast<const char*>(&log_odds), sizeof(float));
    tree.push_back(i + 1 < nodes ? '\x01' : '\x00');
  }
  const std::string file = "# Octomap OcTree file\nid OcTree\nsize " + std::to_string(nodes) +
                           "\nres 0.01\ndata\n" + tree;
  const Status s = ImportOctomapOccupied(WriteBytes("deep.ot", file)).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), HasSubstr("below OctoMap's 16 levels"));
}

TEST_F(MapInputTest, WhatOctomapPrintsIsQuotedEscaped) {
  // A tree type OctoMap does not know: it says so on std::cerr, with the file's text.
  const std::string file =
      "# Octomap OcTree file\nid Evil\x1b[2J\x1b]0;x\x07Tree\nsize 0\nres 0.01\ndata\n";
  const Status s = ImportOctomapOccupied(WriteBytes("evil.ot", file)).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), HasSubstr("unknown type 'Evil\\x1b[2J\\x1b]0;x\\x07Tree'"));
  EXPECT_THAT(s.message(), HasSubstr("OctoMap said: 'ERROR: "));
  EXPECT_THAT(s.message(), Not(HasSubstr("\x1b")));
  EXPECT_THAT(s.message(), Not(HasSubstr("\x07")));
  // Its first line is quoted escaped and shortened too.
  const Status first =
      ImportOctomapOccupied(WriteBytes("x.ot", "\x1b[31m" + std::string(500, 'A') + "\n")).status();
  EXPECT_EQ(first.code(), StatusCode::kParseError);
  EXPECT_THAT(first.message(), HasSubstr("'\\x1b[31mAAA"));
  EXPECT_THAT(first.message(), HasSubstr("(505 bytes)"));
  EXPECT_THAT(first.message(), Not(HasSubstr("\x1b")));
}

TEST_F(MapInputTest, OctomapExportsAreAtomic) {
  MapOptions options;
  SemanticMap map(options);
  for (int i = 0; i < 50; ++i) map.grid().SetLogOdds({i, 0, 0}, 2.0f);
  ASSERT_TRUE(ExportOctomapColor(map, dir_ / "sub" / "map.ot").ok());
  ASSERT_TRUE(ExportOctomapBinary(map.grid(), dir_ / "sub" / "map.bt").ok());
  size_t files = 0;
  for (const auto& e : fs::directory_iterator(dir_ / "sub")) files += e.is_regular_file();
  EXPECT_EQ(files, 2u);  // no temporary file left behind
  const Result<VoxelSet> back = ImportOctomapOccupied(dir_ / "sub" / "map.ot");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->keys.size(), 50u);
  // A path that cannot be written: an error naming it.
  std::ofstream(dir_ / "blocker") << "x";
  const auto r = ExportOctomapColor(map, dir_ / "blocker" / "map.ot");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kIoError);
  EXPECT_THAT(r.status().message(), HasSubstr("blocker"));
}

TEST_F(MapInputTest, MapBlockCountIsBoundedBeforeAllocating) {
  MapOptions options;
  SemanticMap map(options);
  for (int i = 0; i < 40; ++i) map.grid().SetLogOdds({8 * i, 0, 0}, 2.0f);  // 40 blocks
  const Result<std::vector<uint8_t>> bytes = SerializeMap(map);
  ASSERT_TRUE(bytes.ok());
  {
    const ScopedLimit small(MaxMapBlocks(), 39);
    const Status s = DeserializeMap(*bytes).status();
    EXPECT_EQ(s.code(), StatusCode::kResourceExhausted) << s.ToString();
    EXPECT_THAT(s.message(), HasSubstr("blocks of the map (40) exceeds the limit max_map_blocks"));
  }
  EXPECT_TRUE(DeserializeMap(*bytes).ok());
}

TEST_F(MapInputTest, MapFilesAreCheckedBeforeReading) {
  Status s = LoadMap(dir_).status();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("is a folder"));
  s = LoadMap(dir_ / "nope.avpmap").status();
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace avp::mapping

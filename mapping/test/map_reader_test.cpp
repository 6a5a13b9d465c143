// One map reader: LoadAnyMap reads .avpmap, .bt and .ot (OcTree, ColorOcTree) by content; avp's
// class colours come back as classes, other colours as unlabelled occupied voxels; broken files
// are refused naming the file and the byte.
#include <fstream>
#include <optional>
#include <sstream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <octomap/ColorOcTree.h>
#include <octomap/OcTree.h>
#include <octomap/OcTreeStamped.h>

#include <avp/io/label_preview.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/map_reader.h>
#include <avp/mapping/octomap_io.h>
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

/// Free voxels, unlabelled occupied voxels, voxels in between, and occupied voxels of three
/// classes (one labelled voxel free: its label is not exported as a colour).
SemanticMap MakeMap() {
  MapOptions options;
  options.grid.voxel_size_m = 0.006;
  SemanticMap map(options);
  OccupancyGrid& grid = map.grid();
  const float hi = grid.clamp_max_log_odds();
  const float lo = grid.clamp_min_log_odds();
  for (int x = -12; x < 12; ++x) {
    for (int y = -3; y < 3; ++y) {
      grid.SetLogOdds({x, y, 0}, lo);
      grid.SetLogOdds({x, y, 1}, x % 3 == 0 ? 0.4f : -0.3f);
      grid.SetLogOdds({x, y, 2}, hi);
    }
  }
  const SemanticClass classes[] = {SemanticClass::kFruit, SemanticClass::kLeaf,
                                   SemanticClass::kStem};
  for (int i = 0; i < 30; ++i) {
    const VoxelKey k{i - 15, 20, -4 + i % 3};
    grid.SetLogOdds(k, i == 7 ? lo : hi);
    SemanticCell* c = grid.MutableSemantic(k);
    c->semantic_class = static_cast<uint8_t>(classes[i % 3]);
    c->confidence = 0.8f;
    c->observations = 3;
  }
  return map;
}

class MapReaderTest : public test::TempDirTest {
 protected:
  fs::path Write(const std::string& name, const std::string& bytes) {
    const fs::path p = dir_ / name;
    std::ofstream(p, std::ios::binary) << bytes;
    return p;
  }
  static std::string Read(const fs::path& p) { return test::ReadWholeFile(p); }
};

TEST(MapFileFormatTest, DetectedFromTheFirstBytes) {
  EXPECT_EQ(DetectMapFileFormat(std::string(kMapFileMagic, 8) + "rest"), MapFileFormat::kAvpMap);
  EXPECT_EQ(DetectMapFileFormat("# Octomap OcTree binary file\n"), MapFileFormat::kOctomapBinary);
  EXPECT_EQ(DetectMapFileFormat("# Octomap OcTree file\n"), MapFileFormat::kOctomapTree);
  EXPECT_EQ(DetectMapFileFormat("ply\n"), std::nullopt);
  EXPECT_EQ(DetectMapFileFormat(""), std::nullopt);
}

TEST_F(MapReaderTest, ColorOcTreeRoundTripKeepsStatesLogOddsAndLabels) {
  const SemanticMap map = MakeMap();
  const fs::path ot = dir_ / "map.ot";
  const auto exported = ExportOctomapColor(map, ot);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();

  const Result<LoadedMap> loaded = LoadAnyMap(ot);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  const MapSource& src = loaded->source;
  EXPECT_EQ(src.format, MapFileFormat::kOctomapTree);
  EXPECT_EQ(src.tree_type, "ColorOcTree");
  EXPECT_DOUBLE_EQ(src.resolution_m, 0.006);
  EXPECT_TRUE(src.has_labels);
  EXPECT_EQ(src.labelled_by_colour, 29u);  // 30 labelled, one of them free
  EXPECT_EQ(src.foreign_colour, 0u);
  EXPECT_TRUE(src.extension_note.empty());
  const OccupancyGrid& a = map.grid();
  const OccupancyGrid& b = loaded->map.grid();
  EXPECT_EQ(b.CountKnownVoxels(), a.CountKnownVoxels());
  EXPECT_EQ(b.CountOccupiedVoxels(), a.CountOccupiedVoxels());
  EXPECT_EQ(src.unlabelled_grey, a.CountOccupiedVoxels() - 29u);
  size_t checked = 0;
  a.ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    EXPECT_EQ(b.State(k), a.State(k)) << k.x << "," << k.y << "," << k.z;
    const std::optional<float> back = b.LogOdds(k);
    ASSERT_TRUE(back.has_value());
    EXPECT_FLOAT_EQ(*back, log_odds);
    ++checked;
  });
  EXPECT_GT(checked, 400u);
  // Occupied labelled voxels keep their class; the free labelled one has none (no colour).
  size_t labelled = 0;
  a.ForEachSemanticVoxel([&](const VoxelKey& k, const SemanticCell& c) {
    const SemanticCell* back = b.Semantic(k);
    if (a.State(k) == VoxelState::kOccupied) {
      ASSERT_NE(back, nullptr);
      EXPECT_EQ(back->cls(), c.cls());
      ++labelled;
    } else {
      EXPECT_TRUE(back == nullptr || !back->has_label());
    }
  });
  EXPECT_EQ(labelled, 29u);
  EXPECT_EQ(b.CountSemanticVoxels(), 29u);
  EXPECT_EQ(OccupiedVoxelsOfClass(b, SemanticClass::kFruit),
            OccupiedVoxelsOfClass(a, SemanticClass::kFruit));

  // As ground truth, a labelled ColorOcTree gives its voxels of the class.
  bool used_labels = false;
  const VoxelSet gt = GroundTruthVoxels(*loaded, SemanticClass::kLeaf, &used_labels);
  EXPECT_TRUE(used_labels);
  EXPECT_EQ(gt.keys, OccupiedVoxelsOfClass(a, SemanticClass::kLeaf));
}

TEST_F(MapReaderTest, ForeignColoursAreUnlabelledOccupied) {
  octomap::ColorOcTree tree(0.005);
  const auto fruit = io::ClassColor(SemanticClass::kFruit);
  for (int x = 0; x < 10; ++x) {
    octomap::ColorOcTreeNode* n = tree.updateNode(OcKey({x, 0, 0}), true);
    if (x < 4) {
      n->setColor(fruit[0], fruit[1], fruit[2]);
    } else if (x < 6) {
      n->setColor(fruit[0], fruit[1], static_cast<uint8_t>(fruit[2] + 1));  // one off: foreign
    } else {
      n->setColor(10, 200, 250);
    }
  }
  tree.updateNode(OcKey({0, 5, 0}), false);
  tree.updateInnerOccupancy();
  std::ostringstream out;
  ASSERT_TRUE(tree.write(out));
  const fs::path path = Write("foreign.ot", out.str());
  const Result<LoadedMap> loaded = LoadAnyMap(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->source.labelled_by_colour, 4u);
  EXPECT_EQ(loaded->source.foreign_colour, 6u);
  EXPECT_EQ(loaded->source.unlabelled_grey, 0u);
  const OccupancyGrid& g = loaded->map.grid();
  EXPECT_EQ(g.CountOccupiedVoxels(), 10u);
  EXPECT_EQ(g.CountKnownVoxels(), 11u);
  EXPECT_EQ(g.CountSemanticVoxels(), 4u);
  for (int x = 0; x < 10; ++x) {
    const SemanticCell* c = g.Semantic({x, 0, 0});
    if (x < 4) {
      ASSERT_NE(c, nullptr);
      EXPECT_EQ(c->cls(), SemanticClass::kFruit);
    } else {
      EXPECT_TRUE(c == nullptr || !c->has_label()) << x;
    }
  }
  bool lost_named = false;
  for (const std::string& l : loaded->source.lost) {
    lost_named = lost_named || l.find("6 occupied voxels have colours") != std::string::npos;
  }
  EXPECT_TRUE(lost_named);
}

TEST_F(MapReaderTest, BinaryTreeAndPlainOcTreeAreOccupancyOnly) {
  const SemanticMap map = MakeMap();
  const fs::path bt = dir_ / "map.bt";
  ASSERT_TRUE(ExportOctomapBinary(map.grid(), bt).ok());
  const Result<LoadedMap> loaded = LoadAnyMap(bt);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->source.format, MapFileFormat::kOctomapBinary);
  EXPECT_EQ(loaded->source.tree_type, "OcTree");
  EXPECT_FALSE(loaded->source.has_labels);
  const OccupancyGrid& g = loaded->map.grid();
  EXPECT_EQ(g.CountKnownVoxels(), map.grid().CountKnownVoxels());
  EXPECT_EQ(g.CountOccupiedVoxels(), map.grid().CountOccupiedVoxels());
  EXPECT_EQ(g.CountSemanticVoxels(), 0u);
  EXPECT_GT(loaded->source.coarse_leaves, 0u);  // the .bt prunes the free slab
  // As ground truth: all its occupied voxels (what ImportOctomapOccupied reads).
  const VoxelSet gt = GroundTruthVoxels(*loaded, SemanticClass::kFruit);
  const auto direct = ImportOctomapOccupied(bt);
  ASSERT_TRUE(direct.ok());
  EXPECT_EQ(gt.keys, direct->keys);

  // An OcTree .ot: log-odds kept, no labels.
  octomap::OcTree tree(0.01);
  tree.setNodeValue(OcKey({1, 2, 3}), 0.7f);
  tree.setNodeValue(OcKey({1, 2, 4}), -1.2f);
  tree.setNodeValue(OcKey({-1, -2, -3}), 0.1f);
  std::ostringstream out;
  ASSERT_TRUE(tree.write(out));
  const Result<LoadedMap> plain = LoadAnyMapBytes(out.str(), "plain.ot");
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_EQ(plain->source.tree_type, "OcTree");
  EXPECT_EQ(plain->map.grid().CountOccupiedVoxels(), 2u);
  EXPECT_EQ(plain->map.grid().State({1, 2, 4}), VoxelState::kFree);
}

TEST_F(MapReaderTest, FormatComesFromTheContentNotTheName) {
  const SemanticMap map = MakeMap();
  ASSERT_TRUE(ExportOctomapColor(map, dir_ / "real.ot").ok());
  const fs::path misnamed = Write("misnamed.bt", Read(dir_ / "real.ot"));
  const Result<LoadedMap> a = LoadAnyMap(misnamed);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->source.format, MapFileFormat::kOctomapTree);
  EXPECT_THAT(a->source.extension_note, HasSubstr("named .bt but holds .ot content"));

  ASSERT_TRUE(SaveMap(map, dir_ / "real.avpmap").ok());
  const fs::path avp_named_ot = Write("avp.ot", Read(dir_ / "real.avpmap"));
  const Result<LoadedMap> b = LoadAnyMap(avp_named_ot);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->source.format, MapFileFormat::kAvpMap);
  EXPECT_EQ(b->map.grid().CountSemanticVoxels(), map.grid().CountSemanticVoxels());
  EXPECT_TRUE(b->source.lost.empty());
}

TEST_F(MapReaderTest, BrokenFilesAreRefusedNamingTheFileAndTheByte) {
  const SemanticMap map = MakeMap();
  ASSERT_TRUE(ExportOctomapColor(map, dir_ / "full.ot").ok());
  const std::string ot = Read(dir_ / "full.ot");
  const fs::path cut = Write("cut.ot", ot.substr(0, ot.size() - 37));
  Result<LoadedMap> r = LoadAnyMap(cut);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kParseError);
  EXPECT_THAT(r.status().message(), HasSubstr("cut.ot"));
  EXPECT_THAT(r.status().message(), HasSubstr("truncated"));
  EXPECT_THAT(r.status().message(), HasSubstr("at byte"));

  ASSERT_TRUE(ExportOctomapBinary(map.grid(), dir_ / "full.bt").ok());
  const std::string bt = Read(dir_ / "full.bt");
  const fs::path cut_bt = Write("cut.bt", bt.substr(0, bt.size() - 3));
  r = LoadAnyMap(cut_bt);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("cut.bt"));
  EXPECT_THAT(r.status().message(), HasSubstr("byte"));

  ASSERT_TRUE(SaveMap(map, dir_ / "full.avpmap").ok());
  const std::string avp = Read(dir_ / "full.avpmap");
  const fs::path cut_avp = Write("cut.avpmap", avp.substr(0, avp.size() / 2));
  r = LoadAnyMap(cut_avp);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("cut.avpmap"));

  const fs::path text = Write("notes.ot", "hello\nworld\n");
  r = LoadAnyMap(text);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kParseError);
  EXPECT_THAT(r.status().message(), HasSubstr("notes.ot"));
  EXPECT_THAT(r.status().message(), HasSubstr("'hello"));
  EXPECT_THAT(r.status().message(), HasSubstr("not a map file avp can read"));

  r = LoadAnyMap(Write("empty.bt", ""));
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("empty.bt"));

  // Another OctoMap tree type: refused naming the type.
  octomap::OcTreeStamped stamped(0.01);
  stamped.updateNode(OcKey({1, 1, 1}), true);
  std::ostringstream out;
  ASSERT_TRUE(stamped.write(out));
  r = LoadAnyMap(Write("stamped.ot", out.str()));
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("stamped.ot"));
  EXPECT_THAT(r.status().message(), HasSubstr("'OcTreeStamped'"));
}

TEST_F(MapReaderTest, HugeFreeLeavesAreDroppedOccupiedOnesRefused) {
  octomap::OcTree tree(0.01);
  // A free 16^3 cube (pruned into one leaf) and two occupied voxels.
  for (int z = 0; z < 16; ++z) {
    for (int y = 0; y < 16; ++y) {
      for (int x = 0; x < 16; ++x) tree.updateNode(OcKey({x, y, z}), false);
    }
  }
  tree.updateNode(OcKey({40, 0, 0}), true);
  tree.updateNode(OcKey({41, 0, 0}), true);
  tree.updateInnerOccupancy();
  tree.prune();
  std::ostringstream out;
  ASSERT_TRUE(tree.writeBinary(out));
  LoadAnyMapOptions options;
  options.max_voxels = 1000;
  const Result<LoadedMap> r = LoadAnyMapBytes(out.str(), "room.bt", options);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->source.free_space_dropped);
  EXPECT_EQ(r->map.grid().CountKnownVoxels(), 2u);
  EXPECT_EQ(r->map.grid().CountOccupiedVoxels(), 2u);
  options.max_voxels = 1;
  const Result<LoadedMap> refused = LoadAnyMapBytes(out.str(), "room.bt", options);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kOutOfRange);
  EXPECT_THAT(refused.status().message(), HasSubstr("room.bt"));
  options.max_voxels = 5000;
  const Result<LoadedMap> all = LoadAnyMapBytes(out.str(), "room.bt", options);
  ASSERT_TRUE(all.ok());
  EXPECT_FALSE(all->source.free_space_dropped);
  EXPECT_EQ(all->map.grid().CountKnownVoxels(), 4096u + 2u);
}

}  // namespace
}  // namespace avp::mapping

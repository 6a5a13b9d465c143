// The .avpmap file: exact round trips, deterministic bytes, and clear errors (never a crash) on
// truncated, corrupted or foreign input. Also the semantic PLY export.
#include <algorithm>
#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/rng.h>
#include <avp/io/label_preview.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/ply_export.h>
#include <avp/mapping/semantic_map.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::mapping {
namespace {

namespace fs = std::filesystem;

using ::testing::AnyOf;
using ::testing::HasSubstr;

MapOptions TestOptions() {
  MapOptions options;
  options.grid.voxel_size_m = 0.01;
  options.grid.roi = Box3(Eigen::Vector3d(-1.0, -1.0, -0.5), Eigen::Vector3d(1.5, 1.0, 2.0));
  options.grid.sensor.hit = 0.72;
  options.grid.sensor.miss = 0.38;
  options.semantics.policy = FusionPolicy::kReferenceMax;
  options.semantics.reference_penalty = 0.85f;
  options.semantics.outlier_min_neighbours = 2;
  options.semantics.remove_outliers_each_frame = true;
  return options;
}

/// A map with occupied, free and intermediate voxels in several blocks (negative keys too),
/// labelled cells of two instances and two classes, an unlabelled cell with evidence and a block
/// whose semantic payload is allocated but empty.
SemanticMap MakeTestMap() {
  SemanticMap map(TestOptions());
  OccupancyGrid& grid = map.grid();
  const float hi = grid.clamp_max_log_odds();
  const float lo = grid.clamp_min_log_odds();
  Rng rng(42);
  for (int i = 0; i < 3000; ++i) {
    const VoxelKey k{static_cast<int32_t>(rng.UniformInt(-60, 90)),
                     static_cast<int32_t>(rng.UniformInt(-40, 40)),
                     static_cast<int32_t>(rng.UniformInt(-20, 60))};
    const double u = rng.Uniform01();
    const float v = u < 0.3 ? hi : (u < 0.6 ? lo : static_cast<float>(rng.Uniform(lo, hi)));
    EXPECT_TRUE(grid.SetLogOdds(k, v));
  }
  // Two fruit instances and a leaf, occupied.
  for (int x = 10; x < 14; ++x) {
    for (int y = -2; y < 2; ++y) {
      for (int z = 30; z < 33; ++z) {
        const VoxelKey k{x, y, z};
        grid.SetLogOdds(k, hi);
        SemanticCell* c = grid.MutableSemantic(k);
        EXPECT_NE(c, nullptr);
        c->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
        c->instance_id = x < 12 ? 1 : 2;
        c->observations = static_cast<uint16_t>(x + z);
        c->confidence = 0.5f + 0.01f * static_cast<float>(x);
        c->class_log_odds[1] = static_cast<int16_t>(100 * x - z);
      }
    }
  }
  for (int x = -30; x < -25; ++x) {
    const VoxelKey k{x, 5, 7};
    grid.SetLogOdds(k, hi);
    SemanticCell* c = grid.MutableSemantic(k);
    c->semantic_class = static_cast<uint8_t>(SemanticClass::kLeaf);
    c->confidence = 0.75f;
    c->observations = 3;
    c->flags = 0x5a;
  }
  // Unlabelled, with negative evidence only (Bayesian state).
  SemanticCell* e = grid.MutableSemantic({0, 0, 0});
  e->misses = 9;
  e->class_log_odds = {0, -300, -1200, 5, 0, 0, 32767};
  // Allocated but empty semantic payload in its own block.
  grid.SetLogOdds({64, 64, 64}, lo);
  EXPECT_NE(grid.MutableSemantic({64, 64, 64}), nullptr);
  return map;
}

/// Every voxel's state, log-odds and semantic cell, options, and instances agree.
void ExpectMapsEqual(const SemanticMap& a, const SemanticMap& b) {
  const OccupancyGrid& ga = a.grid();
  const OccupancyGrid& gb = b.grid();
  EXPECT_EQ(ga.voxel_size_m(), gb.voxel_size_m());
  ASSERT_EQ(ga.options().roi.has_value(), gb.options().roi.has_value());
  if (ga.options().roi) {
    EXPECT_EQ(ga.options().roi->min(), gb.options().roi->min());
    EXPECT_EQ(ga.options().roi->max(), gb.options().roi->max());
  }
  EXPECT_EQ(ga.sensor_model(), gb.sensor_model());
  const SemanticOptions& sa = a.semantics().options();
  const SemanticOptions& sb = b.semantics().options();
  EXPECT_EQ(sa.policy, sb.policy);
  EXPECT_EQ(sa.reference_penalty, sb.reference_penalty);
  EXPECT_EQ(sa.class_log_odds_min, sb.class_log_odds_min);
  EXPECT_EQ(sa.class_log_odds_max, sb.class_log_odds_max);
  EXPECT_EQ(sa.miss_log_odds, sb.miss_log_odds);
  EXPECT_EQ(sa.label_threshold, sb.label_threshold);
  EXPECT_EQ(sa.instance_join_fraction, sb.instance_join_fraction);
  EXPECT_EQ(sa.instance_merge_fraction, sb.instance_merge_fraction);
  EXPECT_EQ(sa.outlier_min_neighbours, sb.outlier_min_neighbours);
  EXPECT_EQ(sa.remove_outliers_each_frame, sb.remove_outliers_each_frame);

  EXPECT_EQ(ga.num_blocks(), gb.num_blocks());
  EXPECT_EQ(ga.num_semantic_blocks(), gb.num_semantic_blocks());
  EXPECT_EQ(ga.CountKnownVoxels(), gb.CountKnownVoxels());
  EXPECT_EQ(ga.CountOccupiedVoxels(), gb.CountOccupiedVoxels());
  EXPECT_EQ(ga.CountSemanticVoxels(), gb.CountSemanticVoxels());
  size_t compared = 0;
  ga.ForEachBlock([&](const OccupancyBlock& block) {
    const OccupancyBlock* other = gb.FindBlock(block.key);
    ASSERT_NE(other, nullptr) << "block " << block.key.x << "," << block.key.y << "," << block.key.z
                              << " missing after loading";
    EXPECT_EQ(block.known.words, other->known.words);
    ASSERT_EQ(block.semantics != nullptr, other->semantics != nullptr);
    for (int i = 0; i < kBlockVoxels; ++i) {
      const VoxelKey k = KeyOf(block.key, i);
      ASSERT_EQ(ga.State(k), gb.State(k));
      ASSERT_EQ(ga.LogOdds(k), gb.LogOdds(k));
      if (block.semantics) {
        ASSERT_EQ((*block.semantics)[static_cast<size_t>(i)],
                  (*other->semantics)[static_cast<size_t>(i)]);
      }
      ++compared;
    }
  });
  EXPECT_EQ(compared, ga.num_blocks() * kBlockVoxels);

  const auto ia = a.Instances();
  const auto ib = b.Instances();
  ASSERT_EQ(ia.size(), ib.size());
  for (size_t i = 0; i < ia.size(); ++i) {
    EXPECT_EQ(ia[i].id, ib[i].id);
    EXPECT_EQ(ia[i].semantic_class, ib[i].semantic_class);
    EXPECT_EQ(ia[i].voxels, ib[i].voxels);
  }
}

class MapFileTest : public test::TempDirTest {};

TEST(Crc32Test, MatchesTheStandardCheckValue) {
  const std::string s = "123456789";
  const std::span<const uint8_t> bytes(reinterpret_cast<const uint8_t*>(s.data()), s.size());
  EXPECT_EQ(Crc32(bytes), 0xCBF43926u);
  EXPECT_EQ(Crc32(bytes.subspan(4), Crc32(bytes.first(4))), 0xCBF43926u);
  EXPECT_EQ(Crc32({}), 0u);
}

TEST_F(MapFileTest, SaveLoadRoundTripKeepsEveryVoxel) {
  const SemanticMap map = MakeTestMap();
  ASSERT_GT(map.grid().CountKnownVoxels(), 2000u);
  ASSERT_GT(map.grid().CountSemanticVoxels(), 50u);
  const auto path = dir_ / "sub" / "map.avpmap";
  ASSERT_TRUE(SaveMap(map, path, {.note = "unit test map"}).ok());
  EXPECT_FALSE(std::filesystem::exists(dir_ / "sub" / "map.avpmap.tmp"));

  MapFileInfo info;
  const Result<SemanticMap> loaded = LoadMap(path, &info);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  ExpectMapsEqual(map, *loaded);
  EXPECT_EQ(info.version, kMapFileVersion);
  EXPECT_EQ(info.file_bytes, std::filesystem::file_size(path));
  EXPECT_EQ(info.num_blocks, map.grid().num_blocks());
  EXPECT_EQ(info.known_voxels, map.grid().CountKnownVoxels());
  EXPECT_EQ(info.occupied_voxels, map.grid().CountOccupiedVoxels());
  EXPECT_EQ(info.labelled_voxels, map.grid().CountSemanticVoxels());
  EXPECT_EQ(info.semantic_cells, info.labelled_voxels + 1);  // + the unlabelled evidence cell
  EXPECT_EQ(info.note, "unit test map");
  // A loaded map has no pending changes.
  EXPECT_TRUE(loaded->grid().DirtyBlocks().empty());
}

TEST_F(MapFileTest, BytesAreDeterministicAndReSavingIsIdentical) {
  const SemanticMap map = MakeTestMap();
  const auto a = SerializeMap(map);
  const auto b = SerializeMap(MakeTestMap());
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(*a, *b);
  const Result<SemanticMap> loaded = DeserializeMap(*a);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(*SerializeMap(*loaded), *a);
  // The header starts with the magic and the version, little-endian.
  EXPECT_EQ(std::memcmp(a->data(), kMapFileMagic, 8), 0);
  EXPECT_EQ((*a)[8], kMapFileVersion);
  EXPECT_EQ((*a)[9] | (*a)[10] | (*a)[11], 0);
}

TEST_F(MapFileTest, EmptyMapRoundTrips) {
  MapOptions options;
  options.grid.voxel_size_m = 0.006;
  const SemanticMap map(options);
  const auto path = dir_ / "empty.avpmap";
  ASSERT_TRUE(SaveMap(map, path).ok());
  const Result<SemanticMap> loaded = LoadMap(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->grid().num_blocks(), 0u);
  EXPECT_EQ(loaded->voxel_size_m(), 0.006);
  EXPECT_FALSE(loaded->grid().options().roi.has_value());
  EXPECT_EQ(loaded->semantics().options().policy, FusionPolicy::kBayesian);
}

TEST_F(MapFileTest, TruncationAtAnyByteIsAClearError) {
  const auto bytes = SerializeMap(MakeTestMap()).value();
  ASSERT_GT(bytes.size(), 1000u);
  for (size_t n = 0; n < bytes.size(); ++n) {
    const std::span<const uint8_t> prefix(bytes.data(), n);
    const Result<SemanticMap> r = DeserializeMap(prefix);
    ASSERT_FALSE(r.ok()) << "a file truncated to " << n << " bytes was accepted";
    EXPECT_EQ(r.status().code(), StatusCode::kParseError);
    ASSERT_THAT(r.status().message(), HasSubstr(fmt::format("truncated at byte {}", n)))
        << "at " << n;
  }
  // Through the file API the message names the path too.
  const auto path = dir_ / "cut.avpmap";
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), 100);
  const Result<SemanticMap> r = LoadMap(path);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr(path.string()));
  EXPECT_THAT(r.status().message(), HasSubstr("truncated at byte 100"));
}

TEST_F(MapFileTest, RandomByteFlipsAreDetected) {
  const auto bytes = SerializeMap(MakeTestMap()).value();
  Rng rng(2024);
  for (int trial = 0; trial < 1000; ++trial) {
    std::vector<uint8_t> corrupt = bytes;
    // 1 to 4 distinct bytes, each XORed with a nonzero value (so the file really changes).
    std::set<size_t> positions;
    const size_t flips = 1 + static_cast<size_t>(rng.UniformInt(0, 3));
    while (positions.size() < flips) {
      positions.insert(
          static_cast<size_t>(rng.UniformInt(0, static_cast<int64_t>(bytes.size()) - 1)));
    }
    for (size_t at : positions) corrupt[at] ^= static_cast<uint8_t>(rng.UniformInt(1, 255));
    const Result<SemanticMap> r = DeserializeMap(corrupt);
    ASSERT_FALSE(r.ok()) << "trial " << trial << ": a corrupted file was accepted";
    EXPECT_EQ(r.status().code(), StatusCode::kParseError);
    ASSERT_THAT(r.status().message(),
                AnyOf(HasSubstr("bad magic"), HasSubstr("unsupported map file version"),
                      HasSubstr("header declares"), HasSubstr("checksum mismatch")))
        << "trial " << trial << ": " << r.status().message();
  }
}

TEST_F(MapFileTest, SpecificCorruptionsNameWhatIsWrong) {
  const auto bytes = SerializeMap(MakeTestMap()).value();
  {
    const std::string text = "ply\nformat ascii 1.0\n";
    const Result<SemanticMap> r =
        DeserializeMap({reinterpret_cast<const uint8_t*>(text.data()), text.size()});
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.status().message(), HasSubstr("bad magic"));
    EXPECT_THAT(r.status().message(), HasSubstr("70 6c 79"));  // "ply"
  }
  {
    auto v = bytes;
    v[8] = 7;
    const Result<SemanticMap> r = DeserializeMap(v);
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.status().message(), HasSubstr("unsupported map file version 7"));
  }
  {
    auto v = bytes;
    v[bytes.size() / 2] ^= 0x10;
    const Result<SemanticMap> r = DeserializeMap(v);
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.status().message(), HasSubstr("checksum mismatch"));
  }
  {
    auto v = bytes;
    v.push_back(0);
    const Result<SemanticMap> r = DeserializeMap(v);
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.status().message(), HasSubstr("1 unexpected bytes at the end"));
  }
  {
    const Result<SemanticMap> r = LoadMap(dir_ / "nope.avpmap");
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
    EXPECT_THAT(r.status().message(), HasSubstr("nope.avpmap"));
  }
}

// Version 2 header offsets (docs/map-format.md).
constexpr size_t kBlockCountOffset = 74;
constexpr size_t kOptionsOffset = 114;

uint16_t U16At(const std::vector<uint8_t>& v, size_t at) {
  return static_cast<uint16_t>(v[at] | (v[at + 1] << 8));
}

/// Offset of the value text of option `key` in the header's option section.
size_t OptionValueOffset(const std::vector<uint8_t>& v, std::string_view key) {
  size_t at = kOptionsOffset + 4;
  const uint32_t count = v[kOptionsOffset] | (v[kOptionsOffset + 1] << 8);
  for (uint32_t i = 0; i < count; ++i) {
    const uint16_t key_bytes = U16At(v, at);
    const std::string name(v.begin() + static_cast<std::ptrdiff_t>(at + 2),
                           v.begin() + static_cast<std::ptrdiff_t>(at + 2 + key_bytes));
    at += 2 + key_bytes;
    if (name == key) return at + 2;
    at += 2 + U16At(v, at);
  }
  return 0;
}

/// Offset of the note length: after the option section.
size_t NoteLengthOffset(const std::vector<uint8_t>& v) {
  size_t at = kOptionsOffset + 4;
  const uint32_t count = v[kOptionsOffset] | (v[kOptionsOffset + 1] << 8);
  for (uint32_t i = 0; i < count; ++i) {
    at += 2 + U16At(v, at);
    at += 2 + U16At(v, at);
  }
  return at;
}

/// Rewrites the checksum so that the parser itself (not the CRC) must cope with the damage.
void FixChecksum(std::vector<uint8_t>& v) {
  const uint32_t crc = Crc32(std::span<const uint8_t>(v.data(), v.size() - 4));
  for (int i = 0; i < 4; ++i) v[v.size() - 4 + i] = static_cast<uint8_t>(crc >> (8 * i));
}

TEST_F(MapFileTest, ParserSurvivesDamageBehindAValidChecksum) {
  const auto bytes = SerializeMap(MakeTestMap()).value();
  Rng rng(7);
  size_t rejected = 0;
  constexpr int kTrials = 600;
  for (int trial = 0; trial < kTrials; ++trial) {
    std::vector<uint8_t> corrupt = bytes;
    const int flips = 1 + static_cast<int>(rng.UniformInt(0, 2));
    for (int f = 0; f < flips; ++f) {
      // Past magic, version, flags and size: the header fields and the blocks.
      const auto at =
          static_cast<size_t>(rng.UniformInt(24, static_cast<int64_t>(bytes.size()) - 5));
      corrupt[at] ^= static_cast<uint8_t>(1u << rng.UniformInt(0, 7));
    }
    FixChecksum(corrupt);
    const Result<SemanticMap> r = DeserializeMap(corrupt);  // must not crash
    if (!r.ok()) {
      ++rejected;
      EXPECT_EQ(r.status().code(), StatusCode::kParseError) << r.status().ToString();
      EXPECT_FALSE(r.status().message().empty());
    }
  }
  // Many flips hit counts, bitsets, keys or classes that the parser checks.
  EXPECT_GT(rejected, static_cast<size_t>(kTrials / 2));

  // Absurd sizes are bounded before anything is allocated.
  auto v = bytes;
  for (int i = 0; i < 8; ++i) v[kBlockCountOffset + i] = 0xFF;
  FixChecksum(v);
  Result<SemanticMap> r = DeserializeMap(v);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("block count 18446744073709551615 cannot fit"));

  v = bytes;
  const size_t note = NoteLengthOffset(v);
  v[note] = 0xFF;  // note length 65535 + ...
  v[note + 1] = 0xFF;
  v[note + 2] = 0x01;
  FixChecksum(v);
  r = DeserializeMap(v);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("note length 131071 exceeds"));

  v = bytes;
  const size_t voxel = OptionValueOffset(v, "grid.voxel_size_m");
  ASSERT_GT(voxel, 0u);
  for (size_t i = voxel; i < voxel + U16At(v, voxel - 2); ++i) v[i] = '9';  // 9999... m voxels
  FixChecksum(v);
  r = DeserializeMap(v);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(),
              HasSubstr("invalid map options in the header: invalid map options: "
                        "grid.voxel_size_m (9999"));
  EXPECT_THAT(r.status().message(), HasSubstr(" m) must be in [0.002, 0.02]"));

  v = bytes;
  const size_t policy = OptionValueOffset(v, "semantics.policy");
  v[policy] = 0x1b;  // an escape character: named, not echoed
  FixChecksum(v);
  r = DeserializeMap(v);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(),
              HasSubstr("map option semantics.policy: '\\x1beference-max' is not one of"));
}

TEST_F(MapFileTest, VersionOneFilesStillLoad) {
  // Written by avp map build at version 1 (fixed option fields): tomato-single-cluster, seed 0,
  // one view, 20 mm voxels, reference-max, ray-cast carving.
  MapFileInfo info;
  const Result<SemanticMap> v1 =
      LoadMap(fs::path(AVP_TEST_DATA_DIR_MAPPING) / "v1_tomato_single_cluster_20mm.avpmap", &info);
  ASSERT_TRUE(v1.ok()) << v1.status().ToString();
  EXPECT_EQ(info.version, 1u);
  EXPECT_EQ(info.num_blocks, 198u);
  EXPECT_EQ(info.known_voxels, 19002u);
  EXPECT_EQ(info.occupied_voxels, 465u);
  EXPECT_EQ(info.labelled_voxels, 75u);
  EXPECT_THAT(info.note, HasSubstr("--policy reference-max --carving raycast"));
  EXPECT_EQ(v1->voxel_size_m(), 0.02);
  EXPECT_EQ(v1->options().semantics.policy, FusionPolicy::kReferenceMax);
  EXPECT_EQ(v1->Instances().size(), 5u);
  // Saved again it is version 2, and it reads back to the same map.
  const auto v2_bytes = SerializeMap(*v1, {info.note}).value();
  EXPECT_EQ(v2_bytes[8], kMapFileVersion);
  const Result<SemanticMap> v2 = DeserializeMap(v2_bytes);
  ASSERT_TRUE(v2.ok()) << v2.status().ToString();
  EXPECT_EQ(SerializeMap(*v2, {info.note}).value(), v2_bytes);
  EXPECT_TRUE(MapOptionTable().Differences(v2->options(), v1->options()).empty());
}

TEST_F(MapFileTest, TooLongNoteIsRejected) {
  const SemanticMap map(TestOptions());
  const auto r = SerializeMap(map, {.note = std::string(kMaxMapNoteBytes + 1, 'x')});
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("65536"));
}

// ---- PLY ----------------------------------------------------------------------------------------

struct PlyFile {
  std::string header;
  std::string body;
};

PlyFile ReadPly(const std::filesystem::path& path) {
  const std::string all = test::ReadWholeFile(path);
  const size_t end = all.find("end_header\n");
  EXPECT_NE(end, std::string::npos);
  return {all.substr(0, end + 11), all.substr(end + 11)};
}

class PlyExportTest : public test::TempDirTest {};

TEST_F(PlyExportTest, BinaryHoldsEveryOccupiedLabelledVoxel) {
  SemanticMap map = MakeTestMap();
  // A labelled voxel that is free: left out by default.
  map.grid().SetLogOdds({-50, 0, 0}, map.grid().clamp_min_log_odds());
  map.grid().MutableSemantic({-50, 0, 0})->semantic_class =
      static_cast<uint8_t>(SemanticClass::kStem);
  const size_t labelled = map.grid().CountSemanticVoxels();

  const auto path = dir_ / "map.ply";
  const auto stats = ExportSemanticPly(map.grid(), path);
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  EXPECT_EQ(stats->vertices, labelled - 1);
  EXPECT_EQ(stats->skipped_not_occupied, 1u);
  const PlyFile ply = ReadPly(path);
  EXPECT_THAT(ply.header, HasSubstr("format binary_little_endian 1.0\n"));
  EXPECT_THAT(ply.header, HasSubstr(fmt::format("element vertex {}\n", labelled - 1)));
  EXPECT_THAT(ply.header, HasSubstr("property uchar class\nproperty float confidence\n"
                                    "property ushort instance\nproperty ushort observations\n"));
  constexpr size_t kVertexBytes = 3 * 4 + 3 + 1 + 4 + 2 + 2;
  ASSERT_EQ(ply.body.size(), (labelled - 1) * kVertexBytes);
  EXPECT_EQ(stats->file_bytes, std::filesystem::file_size(path));

  // Decode every vertex and find its voxel.
  size_t fruit = 0;
  for (size_t v = 0; v < labelled - 1; ++v) {
    const char* p = ply.body.data() + v * kVertexBytes;
    float xyz[3], confidence;
    uint16_t instance, observations;
    std::memcpy(xyz, p, 12);  // the test machine is little-endian like the file
    std::memcpy(&confidence, p + 16, 4);
    std::memcpy(&instance, p + 20, 2);
    std::memcpy(&observations, p + 22, 2);
    const VoxelKey k = map.grid().KeyOf(Eigen::Vector3d(xyz[0], xyz[1], xyz[2]));
    const SemanticCell* c = map.grid().Semantic(k);
    ASSERT_NE(c, nullptr);
    EXPECT_EQ(map.grid().State(k), VoxelState::kOccupied);
    EXPECT_EQ(static_cast<uint8_t>(p[15]), c->semantic_class);
    const auto rgb = io::ClassColor(c->cls());
    EXPECT_EQ(static_cast<uint8_t>(p[12]), rgb[0]);
    EXPECT_EQ(static_cast<uint8_t>(p[13]), rgb[1]);
    EXPECT_EQ(static_cast<uint8_t>(p[14]), rgb[2]);
    EXPECT_EQ(confidence, c->confidence);
    EXPECT_EQ(instance, c->instance_id);
    EXPECT_EQ(observations, c->observations);
    EXPECT_NEAR(xyz[0], map.grid().CenterOf(k).x(), 1e-6);
    if (c->cls() == SemanticClass::kFruit) ++fruit;
  }
  EXPECT_EQ(fruit, 4u * 4u * 3u);
}

TEST_F(PlyExportTest, AsciiWithFreeVoxels) {
  SemanticMap map = MakeTestMap();
  map.grid().SetLogOdds({-50, 0, 0}, map.grid().clamp_min_log_odds());
  map.grid().MutableSemantic({-50, 0, 0})->semantic_class =
      static_cast<uint8_t>(SemanticClass::kStem);
  const auto path = dir_ / "map_ascii.ply";
  const auto stats =
      ExportSemanticPly(map.grid(), path, {.binary = false, .voxels = PlyVoxels::kAllLabelled});
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  EXPECT_EQ(stats->vertices, map.grid().CountSemanticVoxels());
  EXPECT_EQ(stats->labelled, stats->vertices);
  EXPECT_EQ(stats->not_occupied, 1u);
  EXPECT_EQ(stats->unlabelled, 0u);
  EXPECT_EQ(stats->skipped_not_occupied, 0u);
  const PlyFile ply = ReadPly(path);
  EXPECT_THAT(ply.header, HasSubstr("format ascii 1.0\n"));
  std::istringstream body(ply.body);
  std::string line;
  size_t lines = 0;
  bool found_stem = false;
  while (std::getline(body, line)) {
    ++lines;
    std::istringstream fields(line);
    double x, y, z;
    int r, g, b, cls, instance, observations;
    float confidence;
    ASSERT_TRUE(fields >> x >> y >> z >> r >> g >> b >> cls >> confidence >> instance >>
                observations)
        << line;
    if (cls == static_cast<int>(SemanticClass::kStem)) {
      found_stem = true;
      EXPECT_NEAR(x, -0.495, 1e-6);
      EXPECT_EQ(r, io::ClassColor(SemanticClass::kStem)[0]);
    }
  }
  EXPECT_EQ(lines, stats->vertices);
  EXPECT_TRUE(found_stem);
}

/// One vertex of a PLY that ExportSemanticPly wrote.
struct PlyVertex {
  std::array<float, 3> xyz{};
  std::array<int, 3> rgb{};
  int cls = 0;
  float confidence = 0.0f;
  int instance = 0;
  int observations = 0;
};

/// Reads back the vertices of an ExportSemanticPly file, binary or ASCII (from its header), and
/// checks that the header's vertex count is the number of vertices the body holds.
std::vector<PlyVertex> ReadPlyVertices(const std::filesystem::path& path) {
  const PlyFile ply = ReadPly(path);
  const size_t at = ply.header.find("element vertex ");
  EXPECT_NE(at, std::string::npos);
  const size_t count = std::stoul(ply.header.substr(at + 15));
  std::vector<PlyVertex> out;
  if (ply.header.find("format binary_little_endian 1.0\n") != std::string::npos) {
    constexpr size_t kVertexBytes = 3 * 4 + 3 + 1 + 4 + 2 + 2;
    EXPECT_EQ(ply.body.size(), count * kVertexBytes);
    for (size_t off = 0; off + kVertexBytes <= ply.body.size(); off += kVertexBytes) {
      const char* p = ply.body.data() + off;
      PlyVertex v;
      uint16_t instance, observations;
      std::memcpy(v.xyz.data(), p, 12);  // the test machine is little-endian like the file
      for (int i = 0; i < 3; ++i) v.rgb[i] = static_cast<uint8_t>(p[12 + i]);
      v.cls = static_cast<uint8_t>(p[15]);
      std::memcpy(&v.confidence, p + 16, 4);
      std::memcpy(&instance, p + 20, 2);
      std::memcpy(&observations, p + 22, 2);
      v.instance = instance;
      v.observations = observations;
      out.push_back(v);
    }
  } else {
    EXPECT_THAT(ply.header, HasSubstr("format ascii 1.0\n"));
    std::istringstream body(ply.body);
    std::string line;
    while (std::getline(body, line)) {
      std::istringstream fields(line);
      PlyVertex v;
      EXPECT_TRUE(fields >> v.xyz[0] >> v.xyz[1] >> v.xyz[2] >> v.rgb[0] >> v.rgb[1] >> v.rgb[2] >>
                  v.cls >> v.confidence >> v.instance >> v.observations)
          << line;
      out.push_back(v);
    }
  }
  EXPECT_EQ(out.size(), count);
  return out;
}

/// A small map: 12 occupied fruit voxels, 2 occupied leaf voxels, 6 occupied unlabelled voxels
/// (one with a semantic cell that has evidence but no label), a labelled free voxel, 5 free
/// voxels and one just below the occupied threshold.
SemanticMap MakePlantMap() {
  SemanticMap map(TestOptions());
  OccupancyGrid& grid = map.grid();
  const float hi = grid.clamp_max_log_odds();
  const float lo = grid.clamp_min_log_odds();
  const auto label = [&](const VoxelKey& k, SemanticClass cls, uint16_t instance) {
    SemanticCell* c = grid.MutableSemantic(k);
    c->semantic_class = static_cast<uint8_t>(cls);
    c->instance_id = instance;
    c->confidence = 0.875f;
    c->observations = 4;
  };
  for (int x = 0; x < 3; ++x) {
    for (int y = 0; y < 4; ++y) {
      EXPECT_TRUE(grid.SetLogOdds({x, y, 20}, hi));
      label({x, y, 20}, SemanticClass::kFruit, 1);
    }
  }
  for (int x = 0; x < 2; ++x) {
    EXPECT_TRUE(grid.SetLogOdds({x, -5, 10}, hi));
    label({x, -5, 10}, SemanticClass::kLeaf, 0);
  }
  for (int z = 0; z < 6; ++z) EXPECT_TRUE(grid.SetLogOdds({-3, 0, z}, hi));  // the stem, unseen
  grid.MutableSemantic({-3, 0, 2})->observations = 2;                        // evidence, no label
  EXPECT_TRUE(grid.SetLogOdds({5, 5, 5}, lo));
  label({5, 5, 5}, SemanticClass::kStem, 0);  // labelled but free: never in "occupied"
  for (int x = 20; x < 25; ++x) EXPECT_TRUE(grid.SetLogOdds({x, 0, 0}, lo));
  EXPECT_TRUE(grid.SetLogOdds({30, 0, 0}, grid.occupied_log_odds() - 0.01f));
  return map;
}

TEST_F(PlyExportTest, VoxelsNamesRoundTrip) {
  for (PlyVoxels v : {PlyVoxels::kLabelled, PlyVoxels::kAllLabelled, PlyVoxels::kOccupied}) {
    EXPECT_EQ(PlyVoxelsFromString(ToString(v)), v);
  }
  EXPECT_EQ(ToString(PlyVoxels::kAllLabelled), "all-labelled");
  EXPECT_FALSE(PlyVoxelsFromString("all").has_value());
  EXPECT_FALSE(PlyVoxelsFromString("Occupied").has_value());
}

TEST_F(PlyExportTest, OccupiedHoldsTheWholePlantInClassColoursAndGrey) {
  const SemanticMap map = MakePlantMap();
  const OccupancyGrid& grid = map.grid();
  ASSERT_EQ(grid.CountOccupiedVoxels(), 20u);
  const auto fruit_rgb = io::ClassColor(SemanticClass::kFruit);
  const auto leaf_rgb = io::ClassColor(SemanticClass::kLeaf);
  std::vector<std::vector<PlyVertex>> written;
  for (const bool binary : {true, false}) {
    SCOPED_TRACE(binary ? "binary" : "ascii");
    const auto path = dir_ / (binary ? "plant.ply" : "plant_ascii.ply");
    const auto stats =
        ExportSemanticPly(grid, path, {.binary = binary, .voxels = PlyVoxels::kOccupied});
    ASSERT_TRUE(stats.ok()) << stats.status().ToString();
    EXPECT_EQ(stats->vertices, 20u);
    EXPECT_EQ(stats->labelled, 14u);
    EXPECT_EQ(stats->unlabelled, 6u);
    EXPECT_EQ(stats->not_occupied, 0u);
    EXPECT_EQ(stats->skipped_not_occupied, 1u);  // the free stem voxel
    EXPECT_EQ(stats->file_bytes, std::filesystem::file_size(path));
    const std::vector<PlyVertex> vertices = ReadPlyVertices(path);
    ASSERT_EQ(vertices.size(), 20u);
    size_t fruit = 0, leaf = 0, grey = 0;
    std::set<VoxelKey> seen;
    for (const PlyVertex& v : vertices) {
      const VoxelKey k = grid.KeyOf(Eigen::Vector3d(v.xyz[0], v.xyz[1], v.xyz[2]));
      EXPECT_TRUE(seen.insert(k).second) << "voxel written twice";
      EXPECT_EQ(grid.State(k), VoxelState::kOccupied);
      EXPECT_NEAR(v.xyz[2], grid.CenterOf(k).z(), 1e-6);
      const SemanticCell* c = grid.Semantic(k);
      if (c != nullptr && c->has_label()) {
        EXPECT_EQ(v.cls, c->semantic_class);
        EXPECT_EQ(v.confidence, c->confidence);
        EXPECT_EQ(v.instance, c->instance_id);
        EXPECT_EQ(v.observations, c->observations);
      }
      if (v.cls == static_cast<int>(SemanticClass::kFruit)) {
        ++fruit;
        EXPECT_EQ(v.rgb, (std::array<int, 3>{fruit_rgb[0], fruit_rgb[1], fruit_rgb[2]}));
        EXPECT_EQ(v.instance, 1);
      } else if (v.cls == static_cast<int>(SemanticClass::kLeaf)) {
        ++leaf;
        EXPECT_EQ(v.rgb, (std::array<int, 3>{leaf_rgb[0], leaf_rgb[1], leaf_rgb[2]}));
      } else {
        ++grey;
        EXPECT_EQ(v.cls, static_cast<int>(SemanticClass::kBackground));
        EXPECT_EQ(v.rgb,
                  (std::array<int, 3>{kUnlabelledOccupiedColor[0], kUnlabelledOccupiedColor[1],
                                      kUnlabelledOccupiedColor[2]}));
        EXPECT_EQ(v.confidence, 0.0f);
        EXPECT_EQ(v.instance, 0);
        EXPECT_EQ(v.observations, 0);
        EXPECT_EQ(k.x, -3);
      }
    }
    EXPECT_EQ(fruit, 12u);
    EXPECT_EQ(leaf, 2u);
    EXPECT_EQ(grey, 6u);
    written.push_back(vertices);
  }
  // Binary and ASCII hold the same vertices in the same order.
  ASSERT_EQ(written.size(), 2u);
  for (size_t i = 0; i < written[0].size(); ++i) {
    EXPECT_EQ(written[0][i].xyz, written[1][i].xyz) << i;
    EXPECT_EQ(written[0][i].rgb, written[1][i].rgb) << i;
    EXPECT_EQ(written[0][i].cls, written[1][i].cls) << i;
  }
}

TEST_F(PlyExportTest, EachVoxelsChoiceOnTheSameMap) {
  const SemanticMap map = MakePlantMap();
  const auto path = dir_ / "plant.ply";
  // labelled: the 14 occupied labelled voxels; all-labelled: and the free stem voxel.
  auto stats = ExportSemanticPly(map.grid(), path);
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  EXPECT_EQ(stats->vertices, 14u);
  EXPECT_EQ(stats->skipped_not_occupied, 1u);
  EXPECT_EQ(ReadPlyVertices(path).size(), 14u);
  stats = ExportSemanticPly(map.grid(), path, {.voxels = PlyVoxels::kAllLabelled});
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  EXPECT_EQ(stats->vertices, 15u);
  EXPECT_EQ(stats->not_occupied, 1u);
  const std::vector<PlyVertex> all = ReadPlyVertices(path);
  ASSERT_EQ(all.size(), 15u);
  EXPECT_EQ(std::count_if(
                all.begin(), all.end(),
                [](const PlyVertex& v) { return v.cls == static_cast<int>(SemanticClass::kStem); }),
            1);
  // An empty map writes a valid PLY with no vertices.
  stats =
      ExportSemanticPly(SemanticMap(TestOptions()).grid(), path, {.voxels = PlyVoxels::kOccupied});
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  EXPECT_EQ(stats->vertices, 0u);
  EXPECT_TRUE(ReadPlyVertices(path).empty());
}

TEST_F(PlyExportTest, UnwritablePathIsAnError) {
  const SemanticMap map = MakeTestMap();
  const auto blocker = Write("file", "x");
  const auto r = ExportSemanticPly(map.grid(), blocker / "map.ply");
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("map.ply"));
}

}  // namespace
}  // namespace avp::mapping

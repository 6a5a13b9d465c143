#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/io/yaml.h>
#include <avp/test/temp_dir_test.h>

namespace avp::io {
namespace {

namespace fs = std::filesystem;
using ::testing::ElementsAre;
using ::testing::HasSubstr;

constexpr double kPi = std::numbers::pi;

class YamlFileTest : public test::TempDirTest {};

// ---- LoadYamlFile -------------------------------------------------------------------------------

TEST_F(YamlFileTest, LoadsAFile) {
  const fs::path path = Write("scene.yaml", "name: orchard\nseed: 42\nsize: [1, 2, 3]\n");
  const Result<YAML::Node> node = LoadYamlFile(path);
  ASSERT_TRUE(node.ok()) << node.status().ToString();
  EXPECT_EQ((*node)["name"].as<std::string>(), "orchard");
  EXPECT_EQ((*node)["seed"].as<int>(), 42);
  EXPECT_EQ((*node)["size"].size(), 3u);
}

TEST_F(YamlFileTest, MissingFileIsNotFound) {
  const fs::path path = dir_ / "nope.yaml";
  const Status status = LoadYamlFile(path).status();
  EXPECT_EQ(status.code(), StatusCode::kNotFound);
  EXPECT_THAT(status.message(), HasSubstr(path.string()));
}

TEST_F(YamlFileTest, DirectoryIsRejected) {
  const Status status = LoadYamlFile(dir_).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr(dir_.string()));
}

TEST_F(YamlFileTest, MalformedFileReportsFileLineAndColumn) {
  // The flow sequence opened on line 2 is never closed; yaml-cpp notices on line 3.
  const fs::path path = Write("broken.yaml", "a: 1\nb: [1, 2\nc: 3\n");
  const Status status = LoadYamlFile(path).status();
  EXPECT_EQ(status.code(), StatusCode::kParseError);
  EXPECT_THAT(status.message(), HasSubstr(path.string()));
  EXPECT_THAT(status.message(), HasSubstr("line 3, column 2"));
  EXPECT_THAT(status.message(), HasSubstr("end of sequence flow not found"));

  // A mis-indented key: "illegal map value" at line 2, column 3.
  const Status indent = LoadYamlFile(Write("indent.yaml", "a: 1\n b: 2\n")).status();
  EXPECT_EQ(indent.code(), StatusCode::kParseError);
  EXPECT_THAT(indent.message(), HasSubstr("line 2, column 3"));
}

// ---- RejectUnknownKeys --------------------------------------------------------------------------

TEST_F(YamlFileTest, AFileOfAnotherKindIsNamed) {
  // A mesh, an image, a map or a recording given where YAML is expected: named, not parsed.
  const std::vector<std::pair<std::string, std::string>> files = {
      {"photo.png", std::string("\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 16)},
      {"photo.jpg", "\xff\xd8\xff\xe0JFIF"},
      {"episode.mcap", "\x89MCAP0\r\n"},
      {"gt.bt", "# Octomap OcTree binary file\nid OcTree\n"},
      {"plant.obj",
       "# Blender 4.0 https://www.blender.org\nmtllib plant.mtl\no Leaf\n"
       "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
      {"plant.ply", "ply\nformat ascii 1.0\n"},
      {"blob.bin", std::string("ab\0cd", 5)}};
  for (const auto& [name, bytes] : files) {
    const fs::path p = dir_ / name;
    std::ofstream(p, std::ios::binary) << bytes;
    const Result<YAML::Node> r = LoadYamlFile(p);
    ASSERT_FALSE(r.ok()) << name;
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument) << name;
    EXPECT_THAT(r.status().message(), HasSubstr("not a YAML file")) << name;
  }
  EXPECT_THAT(LoadYamlFile(dir_ / "photo.png").status().message(), HasSubstr("is a PNG image"));
  EXPECT_THAT(LoadYamlFile(dir_ / "plant.obj").status().message(),
              HasSubstr("is a Wavefront OBJ mesh"));
  EXPECT_THAT(LoadYamlFile(dir_ / "episode.mcap").status().message(),
              HasSubstr("is an MCAP recording"));
  // YAML that only looks a little like an OBJ is still YAML.
  std::ofstream(dir_ / "ok.yaml") << "# a scene\nv: 1\nf: [1, 2, 3]\n";
  EXPECT_TRUE(LoadYamlFile(dir_ / "ok.yaml").ok());
}

TEST(YamlTest, AKeyGivenTwiceInOneMapIsRefused) {
  // yaml-cpp keeps both and every lookup finds the first: the second value would be ignored.
  Result<YAML::Node> r = ParseYaml("seed: 1\nviews: 8\nseed: 2\n", "'run.yaml'");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(),
              HasSubstr("'run.yaml': key 'seed' is given twice (lines 1 and 3)"));
  r = ParseYaml("episode:\n  views: 8\n  prompt: tomato\n  views: 6\n", "x");
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("key 'views' is given twice (lines 2 and 4)"));
  EXPECT_FALSE(ParseYaml("{a: 1, a: 2}", "x").ok());
  // Text on which yaml-cpp's document loop never ends (a fuzzer's find) comes back: the duplicate
  // check reads the first document only, as YAML::Load does.
  EXPECT_TRUE(ParseYaml(", 1, 1]}\n 99scale:?([]\n", "x").ok());
  // The same key in different maps, in a list of maps, after a nested map, or as a value: fine.
  EXPECT_TRUE(ParseYaml("a: {x: 1}\nb: {x: 2}\nc: [{x: 1}, {x: 2}]\nd: a\ne: a\n", "x").ok());
  EXPECT_TRUE(ParseYaml("base: &b {x: 1}\none: *b\ntwo: *b\n", "x").ok());
}

TEST(YamlTest, RejectUnknownKeysListsUnknownAndAllowedKeys) {
  const YAML::Node node = YAML::Load("class: fruit\ncolour: red\nfile: a.obj\nsize: 3\n");
  const Status status =
      RejectUnknownKeys(node, {"pose", "class", "file", "color"}, "scene.yaml: objects[2]");
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("scene.yaml: objects[2]: unknown keys 'colour', 'size'"));
  EXPECT_THAT(status.message(), HasSubstr("(allowed: class, color, file, pose)"));  // sorted

  const Status one = RejectUnknownKeys(YAML::Load("colour: red"), {"color"}, "obj");
  EXPECT_THAT(one.message(), HasSubstr("obj: unknown key 'colour'"));
  EXPECT_THAT(one.message(), HasSubstr("(allowed: color)"));
}

TEST(YamlTest, RejectUnknownKeysAcceptsKnownOrAbsentMaps) {
  EXPECT_TRUE(
      RejectUnknownKeys(YAML::Load("class: fruit\nfile: a.obj"), {"class", "file", "pose"}, "obj")
          .ok());
  EXPECT_TRUE(RejectUnknownKeys(YAML::Load("{}"), {"a"}, "obj").ok());
  EXPECT_TRUE(RejectUnknownKeys(YAML::Node(), {"a"}, "obj").ok());  // null
  const YAML::Node root = YAML::Load("a: 1");
  EXPECT_TRUE(RejectUnknownKeys(root["missing"], {"a"}, "obj").ok());  // undefined
}

TEST(YamlTest, RejectUnknownKeysRejectsNonMaps) {
  const Status scalar = RejectUnknownKeys(YAML::Load("just text"), {"a"}, "obj");
  EXPECT_EQ(scalar.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(scalar.message(), HasSubstr("obj: expected a map of keys, got 'just text'"));
  const Status sequence = RejectUnknownKeys(YAML::Load("[1, 2]"), {"a"}, "obj");
  EXPECT_THAT(sequence.message(), HasSubstr("got '[1, 2]'"));
}

// ---- Typed readers ------------------------------------------------------------------------------

const YAML::Node& Config() {
  static const YAML::Node node = YAML::Load(
      "fx: 615.5\n"
      "width: 640\n"
      "negative: -7\n"
      "ratio: 3.5\n"
      "word: abc\n"
      "name: orchard\n"
      "enabled: true\n"
      "disabled: false\n"
      "nan: .nan\n"
      "inf: .inf\n"
      "empty:\n"
      "xyz: [1, 2.5, -3]\n"
      "pair: [1, 2]\n"
      "mixed: [1, x, 3]\n"
      "nested: [1, [2], 3]\n"
      "none: []\n"
      "map: {a: 1}\n");
  return node;
}

TEST(YamlTest, ReadDouble) {
  EXPECT_EQ(ReadDouble(Config(), "fx", "camera").value(), 615.5);
  EXPECT_EQ(ReadDouble(Config(), "width", "camera").value(), 640.0);

  const Status word = ReadDouble(Config(), "word", "camera").status();
  EXPECT_EQ(word.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(word.message(), HasSubstr("camera: 'word' must be a finite number, got 'abc'"));
  EXPECT_THAT(word.message(), HasSubstr("(line 5, column 7)"));

  EXPECT_THAT(ReadDouble(Config(), "nan", "camera").status().message(), HasSubstr("got '.nan'"));
  EXPECT_THAT(ReadDouble(Config(), "inf", "camera").status().message(), HasSubstr("got '.inf'"));
  EXPECT_THAT(ReadDouble(Config(), "xyz", "camera").status().message(),
              HasSubstr("got '[1, 2.5, -3]'"));
  EXPECT_THAT(ReadDouble(Config(), "absent", "camera").status().message(),
              HasSubstr("camera: 'absent' is missing"));
  EXPECT_THAT(ReadDouble(Config(), "empty", "camera").status().message(), HasSubstr("is missing"));
}

TEST(YamlTest, ReadInt) {
  EXPECT_EQ(ReadInt(Config(), "width", "camera").value(), 640);
  EXPECT_EQ(ReadInt(Config(), "negative", "camera").value(), -7);
  const Status fraction = ReadInt(Config(), "ratio", "camera").status();
  EXPECT_EQ(fraction.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(fraction.message(), HasSubstr("camera: 'ratio' must be an integer, got '3.5'"));
  EXPECT_THAT(ReadInt(Config(), "word", "camera").status().message(), HasSubstr("got 'abc'"));
  EXPECT_THAT(ReadInt(Config(), "absent", "camera").status().message(), HasSubstr("is missing"));
}

TEST(YamlTest, ReadString) {
  EXPECT_EQ(ReadString(Config(), "name", "scene").value(), "orchard");
  EXPECT_EQ(ReadString(Config(), "width", "scene").value(), "640");  // scalars are text
  EXPECT_THAT(ReadString(Config(), "xyz", "scene").status().message(),
              HasSubstr("scene: 'xyz' must be a string, got '[1, 2.5, -3]'"));
  EXPECT_THAT(ReadString(Config(), "absent", "scene").status().message(),
              HasSubstr("scene: 'absent' is missing"));
}

TEST(YamlTest, ReadBool) {
  EXPECT_TRUE(ReadBool(Config(), "enabled", "run").value());
  EXPECT_FALSE(ReadBool(Config(), "disabled", "run").value());
  const Status status = ReadBool(Config(), "word", "run").status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("run: 'word' must be true or false, got 'abc'"));
}

TEST(YamlTest, ReadDoubles) {
  EXPECT_THAT(ReadDoubles(Config(), "xyz", "obj").value(), ElementsAre(1.0, 2.5, -3.0));
  EXPECT_TRUE(ReadDoubles(Config(), "none", "obj").value().empty());
  const Status mixed = ReadDoubles(Config(), "mixed", "obj").status();
  EXPECT_EQ(mixed.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(mixed.message(), HasSubstr("obj: 'mixed'[1] must be a finite number, got 'x'"));
  EXPECT_THAT(ReadDoubles(Config(), "nested", "obj").status().message(),
              HasSubstr("'nested'[1] must be a finite number, got '[2]'"));
  EXPECT_THAT(ReadDoubles(Config(), "fx", "obj").status().message(),
              HasSubstr("obj: 'fx' must be a list of numbers, got '615.5'"));
}

TEST(YamlTest, ReadVector) {
  const Eigen::VectorXd xyz = ReadVector(Config(), "xyz", 3, "obj").value();
  ASSERT_EQ(xyz.size(), 3);
  EXPECT_EQ(xyz, Eigen::Vector3d(1, 2.5, -3));
  const Status short_vector = ReadVector(Config(), "pair", 3, "obj").status();
  EXPECT_EQ(short_vector.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(short_vector.message(), HasSubstr("obj: 'pair' must have 3 numbers, got 2: [1, 2]"));
  EXPECT_THAT(ReadVector(Config(), "xyz", 2, "obj").status().message(),
              HasSubstr("must have 2 numbers, got 3: [1, 2.5, -3]"));
  EXPECT_THAT(ReadVector(Config(), "mixed", 3, "obj").status().message(), HasSubstr("got 'x'"));
}

TEST(YamlTest, ReadersOnAMissingOrNonMapSectionReturnErrors) {
  // Reading from a section that is absent, or that is a scalar or list instead of a map, must
  // give a status, never a yaml-cpp exception.
  const YAML::Node root = YAML::Load("camera: 5\nlist: [1, 2]\n");
  const YAML::Node missing = root["lens"];  // const lookup: an invalid ("zombie") node
  const Status absent = ReadDouble(missing, "fx", "lens").status();
  EXPECT_EQ(absent.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(absent.message(), HasSubstr("lens: 'fx' is missing"));
  EXPECT_FALSE(ReadPose(missing, "pose", "lens").ok());

  const Status scalar = ReadDouble(root["camera"], "fx", "camera").status();
  EXPECT_EQ(scalar.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(scalar.message(), HasSubstr("camera"));
  EXPECT_THAT(scalar.message(), HasSubstr("'fx'"));
  for (const YAML::Node& section : {root["camera"], root["list"]}) {
    EXPECT_FALSE(ReadInt(section, "k", "s").ok());
    EXPECT_FALSE(ReadString(section, "k", "s").ok());
    EXPECT_FALSE(ReadBool(section, "k", "s").ok());
    EXPECT_FALSE(ReadDoubles(section, "k", "s").ok());
    EXPECT_FALSE(ReadVector(section, "k", 3, "s").ok());
    EXPECT_FALSE(ReadPose(section, "k", "s").ok());
  }
}

// ---- ReadPose -----------------------------------------------------------------------------------

TEST(YamlTest, ReadPoseWithRadians) {
  const YAML::Node node = YAML::Load("pose: {xyz: [1, 2, 3], rpy: [0.1, -0.2, 0.3]}");
  const RigidTransform X = ReadPose(node, "pose", "camera").value();
  EXPECT_TRUE(X.IsNearlyEqualTo(RigidTransform::FromRpy(0.1, -0.2, 0.3, {1, 2, 3}), 0, 1e-15));
}

TEST(YamlTest, ReadPoseWithDegrees) {
  const YAML::Node node = YAML::Load("pose:\n  xyz: [0.5, 0, 1]\n  rpy_deg: [-90, 0, -90]\n");
  const RigidTransform X = ReadPose(node, "pose", "camera").value();
  // The ROS camera optical frame: z = link x, x = link -y, y = link -z.
  Eigen::Matrix3d expected;
  expected << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  EXPECT_LT((X.rotation() - expected).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_EQ(X.translation(), Eigen::Vector3d(0.5, 0, 1));
  const YAML::Node rad = YAML::Load("pose: {rpy: [0, 0, 1.5707963267948966]}");
  const YAML::Node deg = YAML::Load("pose: {rpy_deg: [0, 0, 90]}");
  EXPECT_TRUE(ReadPose(rad, "pose", "c")
                  .value()
                  .IsNearlyEqualTo(ReadPose(deg, "pose", "c").value(), 0, 1e-15));
}

TEST(YamlTest, ReadPoseKeysAreOptional) {
  const RigidTransform only_xyz = ReadPose(YAML::Load("p: {xyz: [1, 2, 3]}"), "p", "c").value();
  EXPECT_EQ(only_xyz.rotation(), Eigen::Matrix3d::Identity());
  EXPECT_EQ(only_xyz.translation(), Eigen::Vector3d(1, 2, 3));
  const RigidTransform only_rpy = ReadPose(YAML::Load("p: {rpy: [0, 0, 0.5]}"), "p", "c").value();
  EXPECT_EQ(only_rpy.translation(), Eigen::Vector3d::Zero());
  EXPECT_NEAR(only_rpy.rpy().z(), 0.5, 1e-15);
  const RigidTransform empty = ReadPose(YAML::Load("p: {}"), "p", "c").value();
  EXPECT_TRUE(empty.IsNearlyEqualTo(RigidTransform(), 0, 0));
}

TEST(YamlTest, ReadPoseErrors) {
  const Status both =
      ReadPose(YAML::Load("pose: {rpy: [0, 0, 1], rpy_deg: [0, 0, 90]}"), "pose", "camera")
          .status();
  EXPECT_EQ(both.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(both.message(), HasSubstr("camera.pose: give either 'rpy' or 'rpy_deg', not both"));

  EXPECT_THAT(ReadPose(YAML::Load("pose: {xyz: [1, 2]}"), "pose", "camera").status().message(),
              HasSubstr("camera.pose: 'xyz' must have 3 numbers, got 2: [1, 2]"));
  EXPECT_THAT(
      ReadPose(YAML::Load("pose: {rpy_deg: [0, ninety, 0]}"), "pose", "camera").status().message(),
      HasSubstr("camera.pose: 'rpy_deg'[1] must be a finite number, got 'ninety'"));
  const Status unknown =
      ReadPose(YAML::Load("pose: {xyz: [0, 0, 0], rot: [0, 0, 0]}"), "pose", "camera").status();
  EXPECT_THAT(unknown.message(), HasSubstr("camera.pose: unknown key 'rot'"));
  EXPECT_THAT(unknown.message(), HasSubstr("(allowed: rpy, rpy_deg, xyz)"));
  EXPECT_THAT(ReadPose(YAML::Load("a: 1"), "pose", "camera").status().message(),
              HasSubstr("camera: 'pose' is missing"));
  EXPECT_THAT(ReadPose(YAML::Load("pose: [1, 2, 3]"), "pose", "camera").status().message(),
              HasSubstr("camera.pose: expected a map of keys, got '[1, 2, 3]'"));
}

}  // namespace
}  // namespace avp::io

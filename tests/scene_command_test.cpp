// `avp scene check FILE`: a generated plant (fruit with calyx fragments, a placeholder grey
// material) described as text and JSON through the library call, and the built avp's exit codes.
#include <cstdio>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <avp/sim/mesh_builder.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>
#include <avp/sim/scene_report.h>
#include <avp/test/run_command.h>
#include <avp/test/temp_dir_test.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

/// An OBJ object (1-based indices continue from `base`).
std::string ObjObject(const std::string& name, const sim::TriangleMesh& mesh, size_t& base) {
  std::string out = "o " + name + "\nusemtl Grey\n";
  for (const Eigen::Vector3f& v : mesh.vertices) {
    out += "v " + std::to_string(v.x()) + " " + std::to_string(v.y()) + " " +
           std::to_string(v.z()) + "\n";
  }
  for (const Eigen::Vector3i& t : mesh.triangles) {
    out += "f " + std::to_string(base + t[0]) + " " + std::to_string(base + t[1]) + " " +
           std::to_string(base + t[2]) + "\n";
  }
  base += mesh.vertices.size();
  return out;
}

class SceneCommandTest : public test::TempDirTest {
 protected:
  /// plant.obj: a stem, a leaf, three fruits (r 25 mm) each with a calyx fragment on top, all
  /// with the grey material "Grey"; plant.yaml merges the calyces by name and has a rule that
  /// matches nothing.
  void SetUp() override {
    TempDirTest::SetUp();
    size_t base = 1;
    std::string obj = "mtllib plant.mtl\n";
    obj += ObjObject("Stem", sim::MakeBox(Box3({0.04, -0.005, 0.0}, {0.05, 0.005, 0.8})), base);
    sim::TriangleMesh leaf = sim::MakeQuad(0.04, 0.02);
    leaf.Transform(RigidTransform(Eigen::Vector3d(0.02, 0.1, 0.3)));
    obj += ObjObject("Leaf1", leaf, base);
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d c(0.0, -0.08 + 0.08 * k, 0.6);
      sim::TriangleMesh fruit = sim::MakeIcosphere(0.025, 1);
      fruit.Transform(RigidTransform(c));
      obj += ObjObject("Fruit" + std::to_string(k + 1), fruit, base);
      const Eigen::Vector3d top = c + Eigen::Vector3d(0, 0, 0.026);
      obj += ObjObject("Fruit" + std::to_string(k + 1) + "_calyx",
                       sim::MakeBox(Box3(top - Eigen::Vector3d(0.004, 0.004, 0.002),
                                         top + Eigen::Vector3d(0.004, 0.004, 0.002))),
                       base);
    }
    Write("plant.obj", obj);
    Write("plant.mtl", "newmtl Grey\nKd 0.6 0.6 0.6\n");
    yaml_ = Write("plant.yaml", R"(version: 1
meshes:
  - file: plant.obj
    pose: {xyz: [0.7, 0, 0]}
    classes:
      - {match: "Fruit*", class: fruit}
      - {match: "Leaf*", class: leaf}
      - {match: "Stem", class: stem}
      - {match: "Flower*", class: other}
    merge: [{match: "Fruit*_calyx", into: "Fruit*"}]
)");
  }
  std::filesystem::path yaml_;
};

TEST_F(SceneCommandTest, TextListsPartsClassesColoursInstancesRulesAndWarnings) {
  const Result<std::string> text = DescribeSceneFile(yaml_, false);
  ASSERT_TRUE(text.ok()) << text.status().ToString();
  const std::string& t = *text;
  EXPECT_THAT(t, HasSubstr("parts (8):"));
  // A part: name, entry and file, class with its rule, colour with its source, size.
  EXPECT_THAT(t, HasSubstr("  plant/Fruit2  [meshes[0] plant.obj]"));
  EXPECT_THAT(t, HasSubstr("class fruit by classes[0] 'Fruit*'; colour [0.550, 0.050, 0.030] from "
                           "placeholder replaced: material 'Grey' [0.600, 0.600, 0.600]"));
  EXPECT_THAT(t, HasSubstr("8.0 x 8.0 x 4.0 mm; merged into plant/Fruit2 (merge[0])"));
  // Classes: parts, instances, colours.
  EXPECT_THAT(t, HasSubstr("fruit      6 parts, 3 instances; colours [0.550, 0.050, 0.030] x3"));
  EXPECT_THAT(t, HasSubstr("leaf       1 parts, 1 instances; colours [0.080, 0.250, 0.050] x1"));
  // Rules with their counts.
  EXPECT_THAT(t, HasSubstr("meshes[0].classes[0] 'Fruit*' -> fruit: 6 parts"));
  EXPECT_THAT(t, HasSubstr("meshes[0].classes[3] 'Flower*' -> other: 0 parts"));
  // Fruit instances with their size and what they hold.
  EXPECT_THAT(t, HasSubstr("fruit instances (3):"));
  EXPECT_THAT(t, HasSubstr("plant/Fruit1  centre [0.700, -0.080,"));
  EXPECT_THAT(t, HasSubstr("holds 1 fragments: plant/Fruit1_calyx"));
  EXPECT_THAT(t, HasSubstr("fragments: 3 merged, 0 dropped"));
  // Warnings: the placeholder (material, class, count) and the rule that matches nothing.
  EXPECT_THAT(t, HasSubstr("material 'Grey' colour [0.6, 0.6, 0.6] looks like a placeholder"));
  EXPECT_THAT(t, HasSubstr("in fruit (6 parts, now [0.55, 0.05, 0.03]), leaf (1 part, now"));
  EXPECT_THAT(t, HasSubstr("classes[3]: rule 'Flower*' (class other) classifies no part"));
}

TEST_F(SceneCommandTest, JsonHoldsTheSameReport) {
  const Result<std::string> text = DescribeSceneFile(yaml_, true);
  ASSERT_TRUE(text.ok()) << text.status().ToString();
  const nlohmann::json j = nlohmann::json::parse(*text);
  ASSERT_EQ(j["parts"].size(), 8u);
  const nlohmann::json& stem = j["parts"][0];
  EXPECT_EQ(stem["name"], "plant/Stem");
  EXPECT_EQ(stem["class"], "stem");
  EXPECT_EQ(stem["rule"], 2);
  EXPECT_EQ(stem["color_source"], "placeholder replaced");
  EXPECT_EQ(stem["triangles"], 12);
  EXPECT_NEAR(stem["bounds"]["size_mm"][2].get<double>(), 800.0, 1e-3);
  EXPECT_EQ(j["classes"]["fruit"]["instances"], 3);
  EXPECT_EQ(j["classes"]["fruit"]["parts"], 6);
  EXPECT_EQ(j["fruits"].size(), 3u);
  EXPECT_EQ(j["fruits"][0]["merged"][0], "plant/Fruit1_calyx");
  EXPECT_EQ(j["fragments"].size(), 3u);
  EXPECT_EQ(j["fragments"][2]["into"], "plant/Fruit3");
  EXPECT_EQ(j["rules"][3]["parts"], 0);
  EXPECT_EQ(j["warnings"].size(), 2u) << j["warnings"].dump(1);
}

using test::Ran;

/// Runs the built avp with `args` through the shell, stdout and stderr together.
Ran Avp(const std::string& args) { return test::RunShell("'" AVP_BINARY "' " + args + " 2>&1"); }

TEST_F(SceneCommandTest, ExitCodeIsZeroWithWarningsAndNonZeroWithTheError) {
  const Ran ok = Avp("scene check '" + yaml_.string() + "'");
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_THAT(ok.output, HasSubstr("warnings (2):"));
  const Ran json = Avp("scene check --json '" + yaml_.string() + "'");
  EXPECT_EQ(json.exit_code, 0) << json.output;
  EXPECT_EQ(nlohmann::json::parse(json.output)["fruits"].size(), 3u);
  const auto bad = Write("bad.yaml", "version: 1\nmeshes: [{file: plant.obj, materials: maybe}]\n");
  const Ran b = Avp("scene check '" + bad.string() + "'");
  EXPECT_NE(b.exit_code, 0);
  EXPECT_THAT(b.output, HasSubstr("meshes[0].materials: must be 'auto', 'use' or 'ignore', got "
                                  "'maybe'"));
}

TEST_F(SceneCommandTest, APlantBelowTheGroundWarnsAboutTheUpAxis) {
  // The same plant read as y-up: turned onto its side (file y becomes world z), its fruit at file
  // y = -0.08 m hang below the ground.
  const auto yaml = Write("sideways.yaml", R"(version: 1
ground: true
meshes:
  - file: plant.obj
    up_axis: y
    pose: {xyz: [0.7, 0, 0]}
    classes: [{match: "Fruit*", class: fruit}]
)");
  const Result<std::string> text = DescribeSceneFile(yaml, false);
  ASSERT_TRUE(text.ok()) << text.status().ToString();
  EXPECT_THAT(*text, HasSubstr("below the ground at z = 0.000 m"));
  EXPECT_THAT(*text, HasSubstr("check the mesh's up axis (up_axis)"));
  // Upright, no such warning.
  const Result<std::string> upright = DescribeSceneFile(yaml_, false);
  ASSERT_TRUE(upright.ok()) << upright.status().ToString();
  EXPECT_THAT(*upright, Not(HasSubstr("below the")));
}

TEST_F(SceneCommandTest, ExportWritesAScenarioAsASceneFileThatLoadsBack) {
  const sim::ScenarioRegistry scenarios = sim::BuiltinScenarios();
  const Result<std::filesystem::path> yaml =
      ExportScene(sim::SceneSource{"tomato-single-cluster", {}, 4, {}}, scenarios, dir_ / "export");
  ASSERT_TRUE(yaml.ok()) << yaml.status().ToString();
  EXPECT_EQ(yaml->filename(), "tomato-single-cluster.yaml");
  const Result<sim::Scene> original = sim::MakeScenario("tomato-single-cluster", 4);
  const Result<sim::Scene> loaded = sim::LoadSceneFile(*yaml);
  ASSERT_TRUE(original.ok() && loaded.ok()) << loaded.status().ToString();
  ASSERT_EQ(loaded->Fruits().size(), original->Fruits().size());
  for (size_t k = 0; k < original->Fruits().size(); ++k) {
    EXPECT_LT((loaded->Fruits()[k].center_W - original->Fruits()[k].center_W).norm(), 1e-3);
  }
  // An arranged scene file is exported with its arrangement baked in, named without '@'.
  const Result<std::filesystem::path> arranged =
      ExportScene(sim::SceneSource{{}, *yaml, 0, "unoriented-start"}, scenarios, dir_ / "arranged");
  ASSERT_TRUE(arranged.ok()) << arranged.status().ToString();
  EXPECT_EQ(arranged->filename(), "tomato-single-cluster-unoriented-start.yaml");
  const Result<sim::Scene> moved = sim::LoadSceneFile(*arranged);
  ASSERT_TRUE(moved.ok()) << moved.status().ToString();
  EXPECT_NEAR(moved->Fruits()[0].center_W.y() - original->Fruits()[0].center_W.y(), 0.4, 1e-3);
  // The files are there: a second export is refused unless forced.
  for (const std::filesystem::path& f : ExportedSceneFiles(*yaml)) {
    EXPECT_TRUE(std::filesystem::exists(f)) << f;
  }
  const Result<std::filesystem::path> again =
      ExportScene(sim::SceneSource{"tomato-single-cluster", {}, 4, {}}, scenarios, dir_ / "export");
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(again.status().message(), HasSubstr("or --force to replace the exported scene"));
  EXPECT_TRUE(ExportScene(sim::SceneSource{"tomato-single-cluster", {}, 4, {}}, scenarios,
                          dir_ / "export", /*force=*/true)
                  .ok());
  // Unknown scenario: the error names it.
  const Result<std::filesystem::path> bad =
      ExportScene(sim::SceneSource{"tomatoe", {}, 0, {}}, scenarios, dir_ / "bad");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("tomatoe"));
}

}  // namespace
}  // namespace avp::sim

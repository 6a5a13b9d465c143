// End-to-end: `avp render` as a library call writes images whose fruit pixels are labelled,
// deterministically, and rejects bad input with messages that name the bad value.
#include <filesystem>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/experiment/output_folder.h>
#include <avp/experiment/render.h>
#include <avp/io/depth.h>
#include <avp/io/json.h>
#include <avp/io/png.h>
#include <avp/sim/scenario.h>

namespace avp::experiment {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

fs::path TempDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("avp_render_test_" + name);
  fs::remove_all(dir);
  return dir;
}

TEST(RenderCommandTest, DefaultScenarioWritesLabelledFruitPixels) {
  RenderOptions options;
  options.scene.scenario = std::string(sim::DefaultScenarioName());
  options.noise = false;  // every fruit pixel has depth (the noise model drops some, by design)
  options.out_dir = TempDir("default");
  const Result<RenderSummary> result = RenderToFolder(options, sim::BuiltinScenarios());
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_GT(result->fruit_pixels, 500u);
  EXPECT_GE(result->visible_fruits, 2u);
  EXPECT_GT(result->total_fruits, 0u);
  EXPECT_EQ(result->joints_deg.size(), 6u);

  for (const char* name : {"rgb.png", "depth.png", "instance.png", "class.png",
                           "labels_preview.png", "camera.json", "fruits.json"}) {
    EXPECT_TRUE(fs::exists(options.out_dir / name)) << name;
  }
  // Read the files back: fruit class pixels have valid depth and a fruit instance id.
  const auto classes = io::ReadPngGray8(options.out_dir / "class.png");
  const auto instances = io::ReadPngGray16(options.out_dir / "instance.png");
  const auto depth_mm = io::ReadPngGray16(options.out_dir / "depth.png");
  ASSERT_TRUE(classes.ok() && instances.ok() && depth_mm.ok());
  const sim::Scene scene = sim::MakeScenario(options.scene.scenario, 0).value();
  size_t fruit = 0;
  for (int v = 0; v < classes->height(); ++v) {
    for (int u = 0; u < classes->width(); ++u) {
      if ((*classes)(u, v) != static_cast<uint8_t>(SemanticClass::kFruit)) continue;
      ++fruit;
      ASSERT_GT((*depth_mm)(u, v), 0) << "fruit pixel without depth at " << u << "," << v;
      const sim::SceneObject* object = scene.FindInstance((*instances)(u, v));
      ASSERT_NE(object, nullptr);
      EXPECT_EQ(object->semantic_class, SemanticClass::kFruit);
    }
  }
  EXPECT_EQ(fruit, result->fruit_pixels);

  const auto camera = io::ReadJsonFile(options.out_dir / "camera.json");
  ASSERT_TRUE(camera.ok());
  const auto X_WC = io::TransformFromJson((*camera)["X_WC"]);
  ASSERT_TRUE(X_WC.ok());
  EXPECT_TRUE(X_WC->IsNearlyEqualTo(result->X_WC, 1e-9, 1e-9));
  EXPECT_TRUE(io::IntrinsicsFromJson((*camera)["intrinsics"]).ok());
}

TEST(RenderCommandTest, SameSeedGivesIdenticalFilesAndOtherSeedsDiffer) {
  auto render = [](uint64_t seed, const std::string& name) {
    RenderOptions options;
    options.scene.scenario = "tomato-multiple-clusters";
    options.scene.seed = seed;
    options.noise = true;
    options.out_dir = TempDir(name);
    EXPECT_TRUE(RenderToFolder(options, sim::BuiltinScenarios()).ok());
    return std::make_pair(io::ReadPngRgb8(options.out_dir / "rgb.png").value(),
                          io::ReadPngGray16(options.out_dir / "depth.png").value());
  };
  const auto a = render(7, "seed7a");
  const auto b = render(7, "seed7b");
  const auto c = render(8, "seed8");
  EXPECT_TRUE(a.first == b.first);
  EXPECT_TRUE(a.second == b.second);
  EXPECT_FALSE(a.second == c.second);
}

TEST(RenderCommandTest, EveryScenarioRendersItsStartView) {
  const sim::ScenarioRegistry scenarios = sim::BuiltinScenarios();
  for (const sim::ScenarioEntry& info : scenarios.entries()) {
    RenderOptions options;
    options.scene.scenario = info.name;
    options.scene.seed = 3;
    options.out_dir = TempDir("all_" + info.name);
    const Result<RenderSummary> result = RenderToFolder(options, sim::BuiltinScenarios());
    ASSERT_TRUE(result.ok()) << info.name << ": " << result.status().ToString();
    EXPECT_GT(result->valid_depth_pixels, 1000u) << info.name;
    EXPECT_GT(result->total_fruits, 0u) << info.name;
  }
}

TEST(RenderCommandTest, BadInputsNameTheBadValue) {
  RenderOptions options;
  options.out_dir = TempDir("bad");
  options.scene.scenario = "tomato-upside-down";
  Result<RenderSummary> r = RenderToFolder(options, sim::BuiltinScenarios());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(r.status().message(), HasSubstr("tomato-upside-down"));

  options.scene.scenario = "tomato-multiple-clusters";
  options.joints_deg = std::vector<double>{0, 10, 20};
  r = RenderToFolder(options, sim::BuiltinScenarios());
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("6"));
  EXPECT_THAT(r.status().message(), HasSubstr("0, 10, 20"));

  options.joints_deg = std::vector<double>{0, -70, 60, 0, 47.5, 500};
  r = RenderToFolder(options, sim::BuiltinScenarios());
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("500"));

  options.joints_deg.reset();
  options.intrinsics.fx = -1;
  r = RenderToFolder(options, sim::BuiltinScenarios());
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("fx (-1)"));

  options.intrinsics = CameraIntrinsics::RealSenseD435();
  options.scene.scenario.clear();
  options.scene.scene_file = "/nonexistent/plant.yaml";
  r = RenderToFolder(options, sim::BuiltinScenarios());
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("/nonexistent/plant.yaml"));
}

TEST(RenderCommandTest, AnEarlierRenderIsReplacedOnlyWithForceAndNoOtherFolderEver) {
  RenderOptions options;
  options.scene.scenario = "tomato-single-cluster";
  options.intrinsics = CameraIntrinsics::RealSenseD435().Scaled(0.25);
  options.out_dir = TempDir("again");
  ASSERT_TRUE(RenderToFolder(options, sim::BuiltinScenarios()).ok());
  EXPECT_EQ(ReadFolderState(options.out_dir)->state, "complete");
  EXPECT_EQ(ReadFolderState(options.out_dir)->kind, "render");
  // The same folder again: refused, saying what it holds and that --force replaces it.
  Result<RenderSummary> again = RenderToFolder(options, sim::BuiltinScenarios());
  ASSERT_FALSE(again.ok());
  EXPECT_THAT(again.status().message(), HasSubstr("the results of a complete avp render"));
  EXPECT_THAT(again.status().message(), HasSubstr("--force to replace it"));
  options.force = true;
  EXPECT_TRUE(RenderToFolder(options, sim::BuiltinScenarios()).ok());
  // A finished run's folder is never written into, with or without --force, and --force is not
  // offered.
  const fs::path run = TempDir("into_run");
  ASSERT_TRUE(PrepareOutputFolder(run, RunFolderKind(), false).ok());
  ASSERT_TRUE(MarkComplete(run, RunFolderKind(), "avp run").ok());
  options.out_dir = run;
  for (const bool force : {false, true}) {
    options.force = force;
    const Result<RenderSummary> r = RenderToFolder(options, sim::BuiltinScenarios());
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.status().message(), HasSubstr("not an avp render folder"));
    EXPECT_FALSE(fs::exists(run / "rgb.png"));
  }
}

TEST(RenderCommandTest, CameraPoseOverridesTheArm) {
  RenderOptions options;
  options.scene.scenario = "tomato-multiple-clusters";
  // Behind the plant looking back at it along -x (yaw 180 deg in the optical convention is
  // expressed through LookAt in the library; here: a pose from the command line).
  options.camera_pose = std::vector<double>{1.3, 0.0, 0.75, -90.0, 0.0, 90.0};
  options.out_dir = TempDir("pose");
  const Result<RenderSummary> r = RenderToFolder(options, sim::BuiltinScenarios());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->joints_deg.empty());
  EXPECT_NEAR(r->X_WC.translation().x(), 1.3, 1e-12);
  // Optical z (forward) should point along world -x for roll -90, yaw 90.
  EXPECT_NEAR(r->X_WC.rotation().col(2).x(), -1.0, 1e-9);
  EXPECT_GT(r->valid_depth_pixels, 1000u);
}

}  // namespace
}  // namespace avp::experiment

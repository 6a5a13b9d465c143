// The worked examples of docs/extending.md, compiled and run: a segmenter backend, a scenario and
// a map fusion rule of one's own, registered (or set) the way a program does, and used by a whole
// episode. (The example planner, farthest-view, is a built-in: planning/.)
#include <algorithm>
#include <memory>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/experiment/episode_runner.h>
#include <avp/experiment/registries.h>
#include <avp/mapping/integrator.h>
#include <avp/segmentation/mask_ops.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

namespace avp {
namespace {

using ::testing::HasSubstr;

// ---- A segmenter backend ------------------------------------------------------------------------

/// Bright blobs: pixels whose every channel reaches `min_level` form 8-connected blobs, and each
/// blob of at least `min_area_px` pixels is an instance of the prompt's fruit (white flowers or
/// fruit lit by a flash, say).
struct BrightBlobOptions {
  int min_level = 200;
  int min_area_px = 30;
  float confidence = 0.7f;
};

const OptionTable<BrightBlobOptions>& BrightBlobOptionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<BrightBlobOptions>("bright-blob option");
    t->Integer("min_level", &BrightBlobOptions::min_level, "", ValueRange::Closed(0, 255),
               "every channel of a blob pixel reaches this");
    t->Integer("min_area_px", &BrightBlobOptions::min_area_px, "px", ValueRange::AtLeast(1),
               "smallest blob kept");
    t->Real("confidence", &BrightBlobOptions::confidence, "", ValueRange::Closed(0, 1),
            "score of every instance");
    return t;
  }();
  return *table;
}

class BrightBlobSegmenter final : public segmentation::Segmenter {
 public:
  explicit BrightBlobSegmenter(BrightBlobOptions options) : options_(options) {}
  std::string_view name() const override { return "bright-blob"; }
  Result<Segmentation> Segment(const segmentation::SegmentationRequest& request) override {
    if (request.frame == nullptr) return InvalidArgumentError("bright-blob: the frame is null");
    AVP_ASSIGN_OR_RETURN(const std::vector<std::string> phrases,
                         segmentation::SplitPrompt(request.prompt));
    const ImageRgb8& rgb = request.frame->rgb;
    MaskImage bright(rgb.width(), rgb.height(), 0);
    for (int v = 0; v < rgb.height(); ++v) {
      for (int u = 0; u < rgb.width(); ++u) {
        const uint8_t lo = std::min({rgb(u, v, 0), rgb(u, v, 1), rgb(u, v, 2)});
        bright(u, v) = lo >= options_.min_level ? 1 : 0;
      }
    }
    const segmentation::Components blobs = segmentation::LabelComponents(bright);
    Segmentation out;
    out.width = rgb.width();
    out.height = rgb.height();
    for (size_t k = 0; k < blobs.count(); ++k) {
      if (blobs.sizes[k] < static_cast<size_t>(options_.min_area_px)) continue;
      InstanceMask m;
      m.mask = MaskImage(rgb.width(), rgb.height(), 0);
      for (int v = 0; v < rgb.height(); ++v) {
        for (int u = 0; u < rgb.width(); ++u) {
          if (blobs.labels(u, v) == static_cast<int32_t>(k + 1)) m.mask(u, v) = 255;
        }
      }
      m.confidence = options_.confidence;
      m.label = phrases.front();
      if (m.confidence >= request.score_threshold) out.instances.push_back(std::move(m));
    }
    return out;
  }

 private:
  BrightBlobOptions options_;
};

segmentation::SegmenterEntry BrightBlobSegmenterEntry() {
  return segmentation::MakeSegmenterEntry<BrightBlobOptions>(
      "bright-blob", "bright blobs as fruit (docs/extending.md)", BrightBlobOptionTable(),
      BrightBlobOptions{},
      [](std::string_view, const BrightBlobOptions& o, const segmentation::SegmenterContext&) {
        return Result<std::unique_ptr<segmentation::Segmenter>>(
            std::make_unique<BrightBlobSegmenter>(o));
      });
}

// ---- A scenario ---------------------------------------------------------------------------------

/// One white fruit on a stem in front of the reference start camera, half behind a leaf.
Result<sim::Scene> LoneFruitScene(uint64_t seed) {
  sim::Scene scene;
  const Eigen::Vector3d fruit(0.62, 0.02 * static_cast<double>(seed % 3), 0.62);
  scene.Add(
      "stem", SemanticClass::kStem, Eigen::Vector3f(0.3f, 0.5f, 0.2f),
      sim::MakeCylinder(Eigen::Vector3d(0.66, 0.0, 0.0), Eigen::Vector3d(0.66, 0.0, 0.8), 0.008));
  sim::Ellipsoid ball;
  ball.center_W = fruit;
  ball.radii = Eigen::Vector3d::Constant(0.035);
  scene.Add("fruit", SemanticClass::kFruit, Eigen::Vector3f(0.95f, 0.95f, 0.95f), ball);
  sim::TriangleMesh leaf = sim::MakeQuad(0.04, 0.03);
  leaf.Transform(
      RigidTransform(Eigen::AngleAxisd(EIGEN_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix(),
                     fruit + Eigen::Vector3d(-0.06, 0.0, 0.02)));
  scene.Add("leaf", SemanticClass::kLeaf, Eigen::Vector3f(0.2f, 0.5f, 0.1f), leaf);
  sim::AddGroundPlane(scene);
  scene.start_joints_rad = sim::ReferenceStartJointsRad();
  scene.X_WC_start = sim::ReferenceStartCameraPose();
  scene.UpdatePlantBounds();
  return scene;
}

// ---- A map fusion rule --------------------------------------------------------------------------

/// Keeps the class of the most confident observation so far, with that confidence.
class MaxConfidenceRule final : public mapping::FusionRule {
 public:
  std::string_view name() const override { return "max-confidence"; }
  void Hit(mapping::SemanticCell& cell, SemanticClass cls, float confidence) const override {
    if (cell.observations < 65535) ++cell.observations;
    if (confidence > cell.confidence) {
      cell.semantic_class = static_cast<uint8_t>(cls);
      cell.confidence = confidence;
    }
  }
};

// ---- The examples at work -----------------------------------------------------------------------

TEST(ExtendingExamplesTest, ASegmenterBackendIsPickedByNameWithItsOptions) {
  segmentation::SegmenterRegistry registry = segmentation::BuiltinSegmenters();
  ASSERT_TRUE(registry.Add(BrightBlobSegmenterEntry()).ok());
  RgbdFrame frame;
  frame.K = CameraIntrinsics::FromHorizontalFov(64, 48, 60.0);
  frame.rgb = ImageRgb8(64, 48, 20);
  frame.depth_m = DepthImage(64, 48, 1.0f);
  for (int v = 10; v < 20; ++v) {
    for (int u = 5; u < 15; ++u) frame.rgb(u, v, 0) = frame.rgb(u, v, 1) = frame.rgb(u, v, 2) = 250;
  }
  for (int v = 30; v < 33; ++v) {
    for (int u = 40; u < 43; ++u)
      frame.rgb(u, v, 0) = frame.rgb(u, v, 1) = frame.rgb(u, v, 2) = 250;
  }
  segmentation::SegmentationRequest request;
  request.frame = &frame;
  request.prompt = "white fruit";
  auto defaults = registry.Make("bright-blob", 0);
  ASSERT_TRUE(defaults.ok()) << defaults.status().ToString();
  const Result<Segmentation> a = (*defaults)->Segment(request);
  ASSERT_TRUE(a.ok());
  ASSERT_EQ(a->instances.size(), 1u);  // the 3 x 3 blob is below min_area_px
  EXPECT_EQ(segmentation::CountPixels(a->instances[0].mask), 100u);
  EXPECT_EQ(a->instances[0].label, "white fruit");
  EXPECT_TRUE(a->ValidateFor(64, 48).ok());
  auto small = registry.Make("bright-blob",
                             *registry.Options("bright-blob", {{"min_area_px", "9"}}), {.seed = 0});
  ASSERT_TRUE(small.ok());
  EXPECT_EQ((*small)->Segment(request)->instances.size(), 2u);
  EXPECT_THAT(registry.Options("bright-blob", {{"min_level", "300"}}).status().message(),
              HasSubstr("min_level (300) must be in [0, 255]"));
}

TEST(ExtendingExamplesTest, AScenarioAndARuleRunAWholeEpisode) {
  experiment::Registries registries = experiment::BuiltinRegistries();
  ASSERT_TRUE(registries.segmenters.Add(BrightBlobSegmenterEntry()).ok());
  ASSERT_TRUE(
      registries.scenarios.Add({"lone-fruit", "one white fruit half behind a leaf", LoneFruitScene})
          .ok());
  experiment::RunConfig c;
  c.scenario = "lone-fruit";
  c.segmenter.name = "bright-blob";
  c.planner.name = "avp-nbv";
  c.episode.views = 3;
  c.threads = 2;
  c.map.semantics.rule = std::make_shared<MaxConfidenceRule>();
  ASSERT_TRUE(c.Validate(registries).ok()) << c.Validate(registries).ToString();
  const Result<sim::Scene> scene = experiment::LoadScene(c, registries);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  EXPECT_EQ(scene->name, "lone-fruit");
  const Result<eval::GroundTruth> gt = experiment::GroundTruthFor(c, *scene);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  std::unique_ptr<mapping::SemanticMap> map;
  const Result<experiment::RunResult> r = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(c, registries).value(), *scene, *gt, {}, &map);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->episode.views_fused(), 3);
  EXPECT_EQ(r->final_metrics.fruits.total, 1u);
  EXPECT_EQ(r->final_metrics.fruits.found, 1u);
  EXPECT_GT(r->final_metrics.exact.tp, 50u);
  // The rule fused the map: every fruit voxel has the segmenter's confidence (max of equals).
  size_t labelled = 0;
  map->grid().ForEachBlock([&](const mapping::OccupancyBlock& b) {
    if (!b.semantics) return;
    for (const mapping::SemanticCell& cell : *b.semantics) {
      if (!cell.has_label()) continue;
      ++labelled;
      EXPECT_EQ(cell.confidence, BrightBlobOptions{}.confidence);
    }
  });
  EXPECT_GT(labelled, 50u);
}

TEST(ExtendingExamplesTest, AFusionRuleDecidesEachVoxelsClass) {
  const MaxConfidenceRule rule;
  mapping::SemanticCell cell;
  rule.Hit(cell, SemanticClass::kFruit, 0.6f);
  rule.Hit(cell, SemanticClass::kLeaf, 0.7f);
  rule.Hit(cell, SemanticClass::kFruit, 0.65f);
  EXPECT_EQ(cell.cls(), SemanticClass::kLeaf);
  EXPECT_EQ(cell.confidence, 0.7f);
  EXPECT_EQ(cell.observations, 3);
}

}  // namespace
}  // namespace avp

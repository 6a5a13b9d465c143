#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/core/segmentation.h>
#include <avp/mapping/integrator.h>
#include <avp/planning/avp_nbv_planner.h>
#include <avp/planning/learned_gain.h>
#include <avp/planning/view_features.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

#include "start_view_world.h"

namespace avp::planning {
namespace {

using ::testing::HasSubstr;

size_t Column(std::string_view name) {
  const auto names = ViewFeatureNames();
  const auto it = std::find(names.begin(), names.end(), name);
  EXPECT_NE(it, names.end()) << name;
  return static_cast<size_t>(it - names.begin());
}

/// The map of a tomato plant after its start view (perfect masks), as the loop has it at step 1.
class ViewFeaturesTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    std::string error;
    world_ = test::MakeStartViewWorld("tomato-multiple-clusters", 2, 0.005, &error).release();
    ASSERT_NE(world_, nullptr) << error;
    map_ = &world_->map;
    X0_ = world_->X0;
  }
  static void TearDownTestSuite() { delete world_; }
  static PlanningRequest Request() { return world_->Request(); }
  /// A candidate at `eye` looking at `target` (reachable, so that it counts in the step-relative
  /// columns).
  static ViewCandidate LookingAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                 const char* source = "roi") {
    ViewCandidate c;
    c.X_WC = RigidTransform::LookAt(eye, target);
    c.reachable = true;
    c.source = source;
    c.cost = 0.5;
    return c;
  }
  static test::StartViewWorld* world_;
  static const mapping::SemanticMap* map_;
  static RigidTransform X0_;
};
test::StartViewWorld* ViewFeaturesTest::world_ = nullptr;
const mapping::SemanticMap* ViewFeaturesTest::map_ = nullptr;
RigidTransform ViewFeaturesTest::X0_;

TEST_F(ViewFeaturesTest, RowsDescribeWhatAViewWouldCrossAndSee) {
  const PlanningRequest r = Request();
  const Result<GainGrid> grid = GainGrid::Build(*r.map, r.target_class, r.roi);
  ASSERT_TRUE(grid.ok());
  const Result<ViewFeatureExtractor> x = ViewFeatureExtractor::Build(r, *grid);
  ASSERT_TRUE(x.ok()) << x.status().ToString();
  const Eigen::Vector3d centre = r.roi.center();
  const std::vector<ViewCandidate> views = {
      // 0: the start view again (everything it sees is known).
      LookingAt(X0_.translation(), X0_.translation() + X0_.rotation().col(2), "fruit-shell"),
      // 1: from behind the plant, where nothing was seen.
      LookingAt(centre + Eigen::Vector3d(0.45, 0.0, 0.0), centre, "frontier"),
      // 2: beside the ROI (its leaves reach about 0.5 m), turned away from the plant.
      LookingAt(Eigen::Vector3d(centre.x(), r.roi.max().y() + 0.2, centre.z()),
                Eigen::Vector3d(centre.x(), r.roi.max().y() + 2.0, centre.z())),
  };
  const std::vector<float> rows = x->Compute(views);
  const size_t f = ViewFeatureCount();
  ASSERT_EQ(rows.size(), views.size() * f);
  for (const float v : rows) ASSERT_TRUE(std::isfinite(v));
  const auto at = [&](size_t view, std::string_view name) { return rows[view * f + Column(name)]; };
  // The plan's own features are the same in every row.
  for (const char* name : {"plan_progress", "roi_known_fraction", "roi_target_log"}) {
    EXPECT_EQ(at(0, name), at(1, name));
    EXPECT_EQ(at(0, name), at(2, name));
  }
  EXPECT_FLOAT_EQ(at(0, "plan_progress"), 1.0f / 8.0f);
  EXPECT_GT(at(0, "roi_known_fraction"), 0.0f);
  EXPECT_LT(at(0, "roi_known_fraction"), 1.0f);
  EXPECT_GT(at(0, "target_instances"), 0.0f);  // the start view sees fruit
  // The start view: its rays hit what it saw, through free space; a repeat is nothing new.
  EXPECT_GT(at(0, "ray_hit_target") + at(0, "ray_hit_other"), 0.3f);
  EXPECT_LT(at(0, "ray_unseen_share"), at(1, "ray_unseen_share"));
  EXPECT_FLOAT_EQ(at(0, "fused_eye_distance"), 0.0f);
  EXPECT_NEAR(at(0, "fused_axis_cos"), 1.0f, 1e-6);
  EXPECT_NEAR(at(0, "side_start_cos"), 1.0f, 1e-6);
  EXPECT_EQ(at(0, "source_fruit"), 1.0f);
  // From behind: the far side is unknown, the view is on the other side of the plant.
  EXPECT_GT(at(1, "ray_unknown_m"), at(0, "ray_unknown_m"));
  EXPECT_NEAR(at(1, "side_start_cos"), -1.0f, 0.05);
  EXPECT_NEAR(at(1, "axis_roi_cos"), 1.0f, 1e-5);
  EXPECT_EQ(at(1, "source_frontier"), 1.0f);
  EXPECT_EQ(at(1, "ray_unknown_relative"), 1.0f);  // the most unknown of the three
  // Turned away: no ray enters the ROI, nothing to gain.
  EXPECT_EQ(at(2, "ray_in_roi"), 0.0f);
  EXPECT_EQ(at(2, "ray_unknown_m"), 0.0f);
  EXPECT_EQ(at(2, "avp_gain_relative"), 0.0f);
  EXPECT_EQ(at(2, "fruit_in_view"), 0.0f);
  EXPECT_LT(at(2, "axis_roi_cos"), 0.5f);
  // One walk per ray gives both the statistics and avp-nbv's gain parts: the parts sum to the
  // gain avp-nbv computes for the same rays.
  AvpNbvOptions o;
  o.ray_stride_px = ViewFeatureSampling{}.ray_stride_px;
  const double rays = static_cast<double>(RayDirections(r.K, o.ray_stride_px).size());
  for (size_t view = 0; view < views.size(); ++view) {
    double parts = 0.0;
    for (const char* name : {"avp_target_entropy", "avp_predicted_target",
                             "avp_unknown_near_target", "avp_unknown_roi"}) {
      parts += at(view, name);
    }
    const double gain = AvpViewGain(*grid, views[view].X_WC, r.K, o);
    EXPECT_NEAR(parts * rays, gain, 1e-5 * std::max(1.0, gain)) << "view " << view;
    if (view == 1) {
      EXPECT_GT(gain, 0.0);  // from behind: unknown space to gain
    }
  }
}

TEST_F(ViewFeaturesTest, RowsDoNotDependOnTheThreadCountOrTheCandidateOrder) {
  const PlanningRequest r = Request();
  const Result<GainGrid> grid = GainGrid::Build(*r.map, r.target_class, r.roi);
  ASSERT_TRUE(grid.ok());
  Rng rng(5);
  const PlanResult plan = AvpNbvPlanner(AvpNbvOptions{}).Plan(r, rng);
  ASSERT_TRUE(plan.status.ok());
  const auto rows = [&](int threads, std::vector<ViewCandidate> c) {
    const ThreadScope scope(threads);
    return ViewFeatureExtractor::Build(r, *grid)->Compute(c);
  };
  const std::vector<float> one = rows(1, plan.ranked), two = rows(2, plan.ranked);
  EXPECT_EQ(one, two);
  std::vector<ViewCandidate> reversed(plan.ranked.rbegin(), plan.ranked.rend());
  const std::vector<float> back = rows(2, reversed);
  const size_t f = ViewFeatureCount(), n = plan.ranked.size();
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = 0; j < f; ++j) ASSERT_EQ(one[i * f + j], back[(n - 1 - i) * f + j]);
  }
  // Every candidate set has a best in each step-relative column.
  float best = 0.0f;
  for (size_t i = 0; i < n; ++i) best = std::max(best, one[i * f + Column("avp_gain_relative")]);
  EXPECT_EQ(best, 1.0f);
}

#if defined(AVP_WITH_ONNX)

std::filesystem::path ModelDir() { return std::filesystem::path(AVP_GAIN_MODEL_DIR); }

TEST_F(ViewFeaturesTest, AvpNbvRanksByALearnedGainAndFallsBackWhenItFails) {
  AvpNbvOptions o;
  o.gain_model = (ModelDir() / "good.onnx").string();
  Rng a(9), b(9), c(9);
  const PlanResult learned = AvpNbvPlanner(o).Plan(Request(), a);
  ASSERT_TRUE(learned.status.ok()) << learned.status.ToString();
  EXPECT_TRUE(learned.warnings.empty());
  // The model's gain is its prediction from each candidate's row.
  const Result<GainGrid> grid = GainGrid::Build(*map_, SemanticClass::kFruit, Request().roi);
  const PlanningRequest r = Request();
  const std::vector<float> rows = ViewFeatureExtractor::Build(r, *grid)->Compute(learned.ranked);
  const auto model = LearnedGainModel::Load(o.gain_model);
  ASSERT_TRUE(model.ok());
  const std::vector<float> predicted = *(*model)->Predict(rows, learned.ranked.size());
  for (size_t i = 0; i < learned.ranked.size(); ++i) {
    EXPECT_FLOAT_EQ(static_cast<float>(learned.ranked[i].gain), predicted[i]);
  }
  // A model that returns NaN: the hand-written gain ranks that step, with a warning.
  o.gain_model = (ModelDir() / "nan.onnx").string();
  const PlanResult fallback = AvpNbvPlanner(o).Plan(Request(), b);
  const PlanResult hand = AvpNbvPlanner(AvpNbvOptions{}).Plan(Request(), c);
  ASSERT_EQ(fallback.warnings.size(), 1u);
  EXPECT_THAT(fallback.warnings[0], HasSubstr("not finite"));
  EXPECT_THAT(fallback.warnings[0], HasSubstr("hand-written gain"));
  ASSERT_EQ(fallback.ranked.size(), hand.ranked.size());
  for (size_t i = 0; i < hand.ranked.size(); ++i) {
    EXPECT_EQ(fallback.ranked[i].gain, hand.ranked[i].gain);
  }
}

TEST(AvpNbvLearnedGainTest, AModelThatDoesNotLoadIsRefusedAtStartUpByName) {
  PlannerRegistry registry;
  ASSERT_TRUE(registry.Add(AvpNbvPlannerEntry()).ok());
  const auto options = registry.Options("avp-nbv", {{"gain_model", "/no/such/model.onnx"}});
  ASSERT_TRUE(options.ok()) << options.status().ToString();
  const auto planner = registry.Make("avp-nbv", *options, PlannerContext{});
  ASSERT_FALSE(planner.ok());
  EXPECT_THAT(planner.status().message(), HasSubstr("/no/such/model.onnx"));
  EXPECT_THROW(AvpNbvPlanner([] {
                 AvpNbvOptions o;
                 o.gain_model = (ModelDir() / "old_version.onnx").string();
                 return o;
               }()),
               Error);
}

#endif

}  // namespace
}  // namespace avp::planning

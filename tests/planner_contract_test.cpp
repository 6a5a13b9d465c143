// Contract suite for every registered ViewPlanner (experiment::BuiltinRegistries(), the diagnostic
// planners with the scene's ground truth as their truth): on the map a real
// episode has after its start view, each planner is deterministic by seed, returns only reachable
// candidates whose joints put the camera where the candidate says, never re-chooses a fused view,
// and answers a bad request with a status, not an exception.
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include <avp/core/segmentation.h>
#include <avp/eval/oracle_planner.h>
#include <avp/experiment/episode_runner.h>
#include <avp/experiment/registries.h>
#include <avp/mapping/integrator.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

namespace avp {
namespace {

struct World {
  std::unique_ptr<robot::ArmModel> arm;
  std::unique_ptr<sim::Scene> scene;
  std::unique_ptr<mapping::SemanticMap> map;
  Eigen::VectorXd q0;
  RigidTransform X0;
};

const experiment::Registries& Registries() {
  static const auto* registries = new experiment::Registries(experiment::BuiltinRegistries());
  return *registries;
}

const World& TheWorld() {
  static const World* world = [] {
    auto* w = new World;
    w->arm = std::make_unique<robot::ArmModel>(robot::LoadDefaultArm().value());
    w->scene =
        std::make_unique<sim::Scene>(sim::MakeScenario("tomato-multiple-clusters", 1).value());
    mapping::MapOptions mo;
    w->map = std::make_unique<mapping::SemanticMap>(mo);
    w->q0 = Eigen::Map<const Eigen::VectorXd>(w->scene->start_joints_rad.data(), 6);
    w->X0 = w->arm->CameraPose(w->q0);
    const sim::RgbdRenderer renderer(*w->scene);
    const sim::RenderedFrame f = renderer.Render(CameraIntrinsics::RealSenseD435(), w->X0, 0);
    const Segmentation seg = Segmentation::FromLabelImages(f.instance_ids, f.class_ids, 0.8f);
    mapping::IntegratorOptions io;
    io.carving = mapping::FreeSpaceCarving::kProjective;
    (void)mapping::Integrator(io).Integrate(f.rgbd, &seg, *w->map).value();
    return w;
  }();
  return *world;
}

planning::PlanningRequest Request(const World& w) {
  planning::PlanningRequest r;
  r.map = w.map.get();
  r.arm = w.arm.get();
  r.q_current = r.q_start = w.q0;
  r.X_WC_current = r.X_WC_start = w.X0;
  r.K = CameraIntrinsics::RealSenseD435();
  r.roi = w.scene->plant_bounds.Inflated(0.05);
  r.view_index = 1;
  r.views_total = 8;
  r.fused_views = {w.X0};
  return r;
}

class PlannerContractTest : public ::testing::TestWithParam<std::string> {
 protected:
  /// The planner with its registered defaults; a diagnostic one gets the world's truth.
  std::unique_ptr<planning::ViewPlanner> Make() const {
    const planning::PlannerEntry* entry = Registries().planners.Find(GetParam());
    EXPECT_NE(entry, nullptr);
    if (entry == nullptr) return nullptr;
    planning::PlannerContext context{.truth = nullptr};
    if (entry->needs_ground_truth) context.truth = &TheTruth();
    auto p = Registries().planners.Make(GetParam(), entry->options, context);
    EXPECT_TRUE(p.ok()) << p.status().ToString();
    return p.ok() ? std::move(*p) : nullptr;
  }

  /// The world's scene and its observable ground truth at the map's voxel size.
  static const eval::PlannerTruth& TheTruth() {
    static const eval::PlannerTruth* truth = [] {
      const World& w = TheWorld();
      experiment::RunConfig c;
      c.scenario = "tomato-multiple-clusters";
      c.seed = 1;
      c.threads = 2;
      auto* gt = new eval::GroundTruth(experiment::GroundTruthFor(c, *w.scene).value());
      return new eval::PlannerTruth(*w.scene, *gt, segmentation::OracleOptions{});
    }();
    return *truth;
  }
};

TEST_P(PlannerContractTest, DeterministicBySeedAndOnlyReachableUnfusedViews) {
  const World& w = TheWorld();
  auto planner = Make();
  ASSERT_NE(planner, nullptr);
  EXPECT_EQ(planner->name(), GetParam().rfind("predefined", 0) == 0 ? "predefined" : GetParam());
  Rng a(21), b(21);
  const planning::PlanResult ra = planner->Plan(Request(w), a);
  const planning::PlanResult rb = planner->Plan(Request(w), b);
  ASSERT_TRUE(ra.status.ok()) << GetParam() << ": " << ra.status.ToString();
  ASSERT_FALSE(ra.ranked.empty());
  EXPECT_GE(ra.generated, ra.reachable);
  EXPECT_GE(ra.reachable, ra.ranked.size());
  ASSERT_EQ(ra.ranked.size(), rb.ranked.size());
  for (size_t i = 0; i < ra.ranked.size(); ++i) {
    const planning::ViewCandidate& v = ra.ranked[i];
    ASSERT_EQ(v.X_WC.translation(), rb.ranked[i].X_WC.translation()) << i;
    ASSERT_EQ(v.utility, rb.ranked[i].utility) << i;
    ASSERT_TRUE(v.reachable) << i;
    ASSERT_TRUE(w.arm->WithinLimits(v.q)) << i;
    const RigidTransform X = w.arm->CameraPose(v.q);
    EXPECT_LT((X.translation() - v.X_WC.translation()).norm(), 2e-3) << i;
    EXPECT_FALSE(planning::IsNearAny(v.X_WC, {w.X0})) << i;
    if (i > 0) {
      EXPECT_LE(v.utility, ra.ranked[i - 1].utility) << i;
    }
  }
}

TEST_P(PlannerContractTest, BadRequestIsAStatus) {
  const World& w = TheWorld();
  auto planner = Make();
  ASSERT_NE(planner, nullptr);
  planning::PlanningRequest r = Request(w);
  r.map = nullptr;
  Rng rng(1);
  planning::PlanResult res;
  EXPECT_NO_THROW(res = planner->Plan(r, rng));
  EXPECT_FALSE(res.status.ok());
  EXPECT_TRUE(res.ranked.empty());
  r = Request(w);
  r.q_current = Eigen::VectorXd::Zero(3);
  EXPECT_NO_THROW(res = planner->Plan(r, rng));
  EXPECT_FALSE(res.status.ok());
}

INSTANTIATE_TEST_SUITE_P(AllPlanners, PlannerContractTest,
                         ::testing::ValuesIn(Registries().planners.Names()),
                         [](const ::testing::TestParamInfo<std::string>& param) {
                           std::string n = param.param;
                           for (char& c : n) {
                             if (c == '-') c = '_';
                           }
                           return n;
                         });

}  // namespace
}  // namespace avp

// Contract suite for every registered ViewPlanner (experiment::BuiltinRegistries(), the diagnostic
// planners with the scene's ground truth as their truth): on the map a real episode has after its
// start view, each planner keeps experiment::PlannerContractViolations's rules (deterministic by
// seed, only reachable candidates whose joints put the camera where the candidate says, never a
// fused view, utilities that do not rise, a bad request answered with a status). Python planners
// are checked by the same function (avp.check_planner, python/tests/test_planners.py).
#include <memory>
#include <string>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/eval/oracle_planner.h>
#include <avp/experiment/episode_runner.h>
#include <avp/experiment/planner_contract.h>
#include <avp/experiment/registries.h>

namespace avp {
namespace {

const experiment::Registries& Registries() {
  static const auto* registries = new experiment::Registries(experiment::BuiltinRegistries());
  return *registries;
}

const experiment::ContractWorld& TheWorld() {
  static const experiment::ContractWorld* world = experiment::MakeContractWorld()->release();
  return *world;
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
      const experiment::ContractWorld& w = TheWorld();
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

TEST_P(PlannerContractTest, KeepsTheContract) {
  auto planner = Make();
  ASSERT_NE(planner, nullptr);
  EXPECT_EQ(planner->name(), GetParam().rfind("predefined", 0) == 0 ? "predefined" : GetParam());
  const std::vector<std::string> violations =
      experiment::PlannerContractViolations(*planner, TheWorld());
  EXPECT_TRUE(violations.empty()) << GetParam() << ":\n  "
                                  << fmt::format("{}", fmt::join(violations, "\n  "));
}

/// The checks catch what they check: a planner that breaks each rule is named for it.
class BrokenPlanner : public planning::ViewPlanner {
 public:
  enum class Fault { kFusedView, kRisingUtility, kThrowsOnBadRequest, kRandom };
  explicit BrokenPlanner(Fault fault) : fault_(fault) {}
  std::string_view name() const override { return "broken"; }
  planning::PlanResult Plan(const planning::PlanningRequest& r, Rng& rng) override {
    if (r.map == nullptr || r.q_current.size() != 6) {
      if (fault_ == Fault::kThrowsOnBadRequest) throw std::runtime_error("no map");
      planning::PlanResult refused;
      refused.status = InvalidArgumentError("bad request");
      return refused;
    }
    planning::PlanResult p;
    for (int i = 0; i < 2; ++i) {
      planning::ViewCandidate c;
      c.q = r.q_current;
      c.q[0] += 0.3 * (i + 1);
      if (fault_ == Fault::kFusedView && i == 0) c.q = r.q_current;
      if (fault_ == Fault::kRandom) c.q[0] += 0.1 * rng.Uniform01() + 0.05 * (++calls_);
      c.X_WC = r.arm->CameraPose(c.q);
      c.reachable = true;
      c.utility = fault_ == Fault::kRisingUtility ? i : -i;
      p.ranked.push_back(c);
    }
    p.generated = p.reachable = p.ranked.size();
    return p;
  }

 private:
  Fault fault_;
  int calls_ = 0;
};

TEST(PlannerContractChecks, NameEachBrokenRule) {
  using Fault = BrokenPlanner::Fault;
  const auto violations = [](Fault f) {
    BrokenPlanner p(f);
    return fmt::format("{}", fmt::join(experiment::PlannerContractViolations(p, TheWorld()), "; "));
  };
  EXPECT_THAT(violations(Fault::kFusedView),
              ::testing::HasSubstr("candidate 0 is the view already fused"));
  EXPECT_THAT(violations(Fault::kRisingUtility),
              ::testing::HasSubstr("utility (1) is above candidate 0's (0)"));
  EXPECT_THAT(violations(Fault::kThrowsOnBadRequest),
              ::testing::HasSubstr("a request without a map threw instead of answering a status"));
  EXPECT_THAT(violations(Fault::kRandom),
              ::testing::HasSubstr("differs between two plans with the same seed"));
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

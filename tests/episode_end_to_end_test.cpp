// A short simulated episode end to end (scene -> oracle segmentation -> map -> avp-nbv -> arm):
// the voxel F1 rises above a stated floor, the same seed gives the same episode, and another
// planner runs through the same code.
#include <algorithm>
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include <avp/experiment/episode_runner.h>
#include <avp/sim/scenario.h>

namespace avp {
namespace {

using experiment::RunConfig;

const experiment::Registries& Registries() {
  static const auto* registries = new experiment::Registries(experiment::BuiltinRegistries());
  return *registries;
}

RunConfig Config(const std::string& planner) {
  RunConfig c;
  c.scenario = "tomato-multiple-clusters";
  c.seed = 4;
  c.planner.name = planner;
  c.segmenter.name = "oracle";
  c.episode.views = 4;
  c.threads = 2;
  return c;
}

/// The scene and ground truth of a config's scenario and seed, and episodes run on them.
struct SceneEpisodes {
  explicit SceneEpisodes(const RunConfig& c)
      : scene(sim::MakeScenario(c.scenario, c.seed).value()),
        gt(experiment::GroundTruthFor(c, scene).value()) {}
  Result<experiment::RunResult> Run(const RunConfig& config) const {
    return experiment::RunEpisodeOnScene(
        experiment::CheckedRunConfig::Check(config, Registries()).value(), scene, gt);
  }
  sim::Scene scene;
  eval::GroundTruth gt;
};

/// Three views of avp-nbv with planned motion on `scenario`, seed 0.
RunConfig PlannedMotionConfig(const std::string& scenario) {
  RunConfig c = Config("avp-nbv");
  c.scenario = scenario;
  c.seed = 0;
  c.episode.views = 3;
  c.motion.enabled = true;
  return c;
}

/// The same episode: the same metrics and the same eye at every step.
void ExpectSameEpisode(const experiment::RunResult& a, const experiment::RunResult& b) {
  ASSERT_EQ(a.episode.steps.size(), b.episode.steps.size());
  for (size_t i = 0; i < a.episode.steps.size(); ++i) {
    EXPECT_EQ(a.episode.steps[i].metrics, b.episode.steps[i].metrics) << i;
    EXPECT_EQ(a.episode.steps[i].X_WC.translation(), b.episode.steps[i].X_WC.translation()) << i;
  }
}

TEST(EpisodeEndToEndTest, AvpNbvRaisesF1AboveTheFloor) {
  const RunConfig c = Config("avp-nbv");
  auto scene = sim::MakeScenario(c.scenario, c.seed);
  ASSERT_TRUE(scene.ok());
  auto gt = experiment::GroundTruthFor(c, *scene);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  ASSERT_GT(gt->voxels.size(), 500u);
  auto r = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(c, Registries()).value(), *scene, *gt);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->episode.views_fused(), 4) << r->episode.end_reason;
  const double f1_first = r->episode.steps.front().Metric("f1");
  const double f1_last = r->episode.steps.back().Metric("f1");
  // Stated floor: after 4 views with the noisy oracle, the exact-voxel F1 is above 0.4 and has
  // grown by at least 0.1 over the start view.
  EXPECT_GT(f1_last, 0.4);
  EXPECT_GT(f1_last, f1_first + 0.1);
  EXPECT_GT(r->final_metrics.fruits.found, 0u);
  EXPECT_EQ(r->final_metrics.exact.f1, f1_last);

  auto again = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(c, Registries()).value(), *scene, *gt);
  ASSERT_TRUE(again.ok());
  ExpectSameEpisode(*again, *r);
}

/// With planned motion the simulator measures the free space assumed around the arm at its start
/// (motion.collision.map.start_clearance_m and the field's rounding, 4.7 cm) against the true
/// scene: in tomato-full-occlusion seed 9 a leaf grows 3 cm from the start camera
/// (docs/motion.md), in the other scene nothing is that close; without planning nothing is
/// assumed and nothing measured.
TEST(EpisodeEndToEndTest, TheSimulatorChecksTheFreeSpaceAssumedAroundTheStart) {
  RunConfig c = Config("avp-nbv");
  c.episode.views = 1;
  c.motion.enabled = true;
  RunConfig leafy = c;
  leafy.scenario = "tomato-full-occlusion";
  leafy.seed = 9;
  auto broken = SceneEpisodes(leafy).Run(leafy);
  ASSERT_TRUE(broken.ok()) << broken.status().ToString();
  ASSERT_TRUE(broken->episode.start_clearance.has_value());
  const auto& start = *broken->episode.start_clearance;
  // 2 cm, and the field's rounding at its 1 cm cells: 1.5 cell diagonals and 1 mm.
  EXPECT_NEAR(start.assumed_m, 0.02 + 1.5 * std::sqrt(3.0) * 0.01 + 0.001, 1e-12);
  ASSERT_TRUE(start.truth.has_value());
  EXPECT_TRUE(start.broken());
  EXPECT_NEAR(start.truth->distance_m, 0.030, 0.001);  // measured: 30.2 mm
  EXPECT_NE(start.truth->nearest.find("leaf 'tomato/leaf_11'"), std::string::npos)
      << start.truth->nearest;

  auto kept = SceneEpisodes(c).Run(c);
  ASSERT_TRUE(kept.ok()) << kept.status().ToString();
  ASSERT_TRUE(kept->episode.start_clearance.has_value());
  EXPECT_FALSE(kept->episode.start_clearance->broken())
      << kept->episode.start_clearance->truth->nearest;

  c.motion.enabled = false;
  auto straight = SceneEpisodes(c).Run(c);
  ASSERT_TRUE(straight.ok()) << straight.status().ToString();
  EXPECT_FALSE(straight->episode.start_clearance.has_value());
}

/// Every move is planned collision-free, executed as a timed trajectory, and checked by the
/// simulator against the true scene (docs/motion.md); the arm returns home at the end. With
/// motion planning off the same counts are kept (today's straight moves), for comparison.
TEST(EpisodeEndToEndTest, EveryMoveIsPlannedAndTheSimulatorCountsItsContacts) {
  RunConfig c = Config("avp-nbv");
  c.motion.enabled = true;
  const SceneEpisodes episodes(c);
  auto r = episodes.Run(c);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_GE(r->episode.views_fused(), 2) << r->episode.end_reason;
  int moves = 0;
  for (const pipeline::StepRecord& s : r->episode.steps) {
    if (s.chosen_rank < 0) continue;
    ++moves;
    EXPECT_TRUE(s.motion.planned);
    EXPECT_GE(s.motion.attempts, 1);
    EXPECT_GT(s.motion.execution_s, 0.0);
    EXPECT_GT(s.motion.path_length_rad, 0.0);
    EXPECT_GE(s.motion.camera_path_W.size(), 2u);
    ASSERT_TRUE(s.motion.contacts.has_value());
    ASSERT_TRUE(s.motion.straight_line_contacts.has_value());
    EXPECT_EQ(s.motion.contacts->total(), 0) << s.motion.contacts->first;
    EXPECT_GE(s.candidates_in_collision, 0u);
  }
  EXPECT_GE(moves, 1);
  ASSERT_TRUE(r->episode.return_home.has_value());
  EXPECT_TRUE(r->episode.return_home_status.ok()) << r->episode.return_home_status.ToString();
  const pipeline::MotionTotals t = pipeline::SumMotion(r->episode);
  EXPECT_EQ(t.moves, moves + 1);  // and the return home
  ASSERT_TRUE(t.contacts.has_value());
  EXPECT_EQ(t.contacts->total(), 0);

  c.motion.enabled = false;
  auto straight = episodes.Run(c);
  ASSERT_TRUE(straight.ok()) << straight.status().ToString();
  const pipeline::MotionTotals u = pipeline::SumMotion(straight->episode);
  EXPECT_FALSE(straight->episode.return_home.has_value());
  ASSERT_TRUE(u.contacts.has_value());
  // Unplanned moves are the straight line: both counts are the same.
  EXPECT_EQ(u.contacts->total(), u.straight_line_contacts->total());
  for (const pipeline::StepRecord& s : straight->episode.steps) EXPECT_FALSE(s.motion.planned);
}

/// oracle_motion: the motion planner knows the true scene. Behind this tomato's leaf layer the
/// map's unknown space holds back almost every candidate; the truth frees those the arm can
/// really reach, and every move stays clear of the plant (docs/motion.md, "What it costs").
TEST(EpisodeEndToEndTest, OracleMotionPlansAgainstTheTrueSceneAndTouchesNothing) {
  RunConfig c = PlannedMotionConfig("tomato-full-occlusion");
  c.motion.step_back_m = 0.0;  // every candidate judged where it is
  const SceneEpisodes episodes(c);
  const auto run = [&](const RunConfig& config) { return episodes.Run(config); };
  auto map = run(c);
  ASSERT_TRUE(map.ok()) << map.status().ToString();
  c.oracle_motion = true;
  auto truth = run(c);
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  ASSERT_EQ(truth->episode.views_fused(), 3) << truth->episode.end_reason;
  const pipeline::StepRecord& first_map = map->episode.steps.front();
  const pipeline::StepRecord& first_truth = truth->episode.steps.front();
  // The same first plan (same view, same candidates), judged against other obstacles.
  EXPECT_EQ(first_truth.candidates_generated, first_map.candidates_generated);
  EXPECT_GT(first_truth.candidates_reachable, 10 * first_map.candidates_reachable);
  const pipeline::MotionTotals t = pipeline::SumMotion(truth->episode);
  EXPECT_EQ(t.moves, 3);  // two views and the return home
  ASSERT_TRUE(t.contacts.has_value());
  EXPECT_EQ(t.contacts->total(), 0) << t.contacts->first;
  ASSERT_TRUE(t.straight_line_contacts.has_value());
  EXPECT_GT(t.straight_line_contacts->total(), 0);  // the straight line would go through it

  c.motion.enabled = false;
  auto refused = run(c);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("oracle_motion"), std::string::npos);
  EXPECT_NE(refused.status().message().find("motion.enabled"), std::string::npos);
}

/// motion.step_back_m: a view whose arm would stand in unseen space is taken from further back
/// along the same optical axis, where the camera stands in space the map has seen free: more
/// candidates survive the collision check, and nothing is touched.
TEST(EpisodeEndToEndTest, CollidingViewsAreSteppedBackIntoSeenSpace) {
  RunConfig c = PlannedMotionConfig("tomato-unoriented-start");
  const SceneEpisodes episodes(c);
  const auto run = [&](const RunConfig& config) { return episodes.Run(config); };
  auto stepped = run(c);
  ASSERT_TRUE(stepped.ok()) << stepped.status().ToString();
  c.motion.step_back_m = 0.0;
  auto dropped = run(c);
  ASSERT_TRUE(dropped.ok()) << dropped.status().ToString();
  const pipeline::StepRecord& a = stepped->episode.steps.front();
  const pipeline::StepRecord& b = dropped->episode.steps.front();
  EXPECT_EQ(a.candidates_generated, b.candidates_generated);
  EXPECT_GT(a.candidates_reachable, b.candidates_reachable);
  EXPECT_LT(a.candidates_in_collision, b.candidates_in_collision);
  for (const auto* r : {&*stepped, &*dropped}) {
    const pipeline::MotionTotals t = pipeline::SumMotion(r->episode);
    ASSERT_TRUE(t.contacts.has_value());
    EXPECT_EQ(t.contacts->total(), 0) << t.contacts->first;
  }
}

TEST(EpisodeEndToEndTest, PredefinedRunsTheSameLoop) {
  RunConfig c = Config("predefined");
  // Straight moves: this tomato's leaves reach the start camera, and with planned motion every
  // zig-zag waypoint after it is in unseen space (docs/motion.md, "What it costs").
  c.motion.enabled = false;
  auto r = SceneEpisodes(c).Run(c);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->episode.views_fused(), 4) << r->episode.end_reason;
  EXPECT_GE(r->episode.steps.back().Metric("f1"), r->episode.steps.front().Metric("f1"));
}

TEST(EpisodeEndToEndTest, OracleDetectKnowsTheTruthAndIsDeterministic) {
  // The diagnostic bound on fruits found: built only with the scene and its ground truth.
  const planning::PlannerEntry* entry = Registries().planners.Find("oracle-detect");
  ASSERT_NE(entry, nullptr);
  EXPECT_TRUE(entry->needs_ground_truth);
  RunConfig c = Config("oracle-detect");
  c.episode.views = 3;
  c.motion.enabled = false;  // the diagnostic's views, as in PredefinedRunsTheSameLoop
  const auto made = Registries().planners.Make("oracle-detect", entry->options, {});
  ASSERT_FALSE(made.ok());
  EXPECT_NE(made.status().message().find("planner 'oracle-detect' needs the true scene"),
            std::string::npos);
  auto scene = sim::MakeScenario(c.scenario, c.seed);
  ASSERT_TRUE(scene.ok());
  auto gt = experiment::GroundTruthFor(c, *scene);
  ASSERT_TRUE(gt.ok());
  auto r = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(c, Registries()).value(), *scene, *gt);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->episode.views_fused(), 3) << r->episode.end_reason;
  EXPECT_GT(r->final_metrics.fruits.found,
            static_cast<size_t>(r->episode.steps.front().Metric("fruits_found")));
  auto again = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(c, Registries()).value(), *scene, *gt);
  ASSERT_TRUE(again.ok());
  ExpectSameEpisode(*again, *r);
}

TEST(EpisodeEndToEndTest, OracleRegretMeasuresEachPlanWithoutChangingTheEpisode) {
  RunConfig c = Config("avp-nbv");
  c.episode.views = 3;
  auto scene = sim::MakeScenario(c.scenario, c.seed);
  ASSERT_TRUE(scene.ok());
  auto gt = experiment::GroundTruthFor(c, *scene);
  ASSERT_TRUE(gt.ok());
  auto plain = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(c, Registries()).value(), *scene, *gt);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_TRUE(plain->regret.empty());
  c.oracle_regret = true;
  // Recording the gain's parts changes no choice either.
  c.planner.options.emplace_back("record_gain_terms", "true");
  auto probed = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(c, Registries()).value(), *scene, *gt);
  ASSERT_TRUE(probed.ok()) << probed.status().ToString();
  ExpectSameEpisode(*probed, *plain);
  size_t plans = 0;
  for (const pipeline::StepRecord& step : plain->episode.steps) plans += step.planned ? 1 : 0;
  ASSERT_EQ(probed->regret.size(), plans);
  ASSERT_GE(plans, 2u);
  for (size_t i = 0; i < probed->regret.size(); ++i) {
    const eval::StepRegret& r = probed->regret[i];
    EXPECT_EQ(r.step, static_cast<int>(i));
    EXPECT_EQ(r.candidates, probed->episode.steps[i].candidates_reachable);
    EXPECT_GT(r.best_true_gain, 0.0);  // fruit is left to see after one or two views
    EXPECT_LE(r.chosen_true_gain, r.best_true_gain);
    EXPECT_NEAR(r.regret, 1.0 - r.chosen_true_gain / r.best_true_gain, 1e-12);
    EXPECT_GE(r.chosen_true_rank, 1u);
    EXPECT_LE(r.chosen_true_rank, r.candidates);
    EXPECT_GE(r.rank_correlation, -1.0);
    EXPECT_LE(r.rank_correlation, 1.0);
    // Every ranked candidate with the truth beside it, the chosen one first.
    ASSERT_EQ(r.scored.size(), r.candidates);
    EXPECT_EQ(r.scored.front().true_gain, r.chosen_true_gain);
    double best = 0.0;
    for (size_t j = 0; j < r.scored.size(); ++j) {
      const eval::ScoredCandidate& sc = r.scored[j];
      best = std::max(best, sc.true_gain);
      if (j > 0) {
        EXPECT_LE(sc.utility, r.scored[j - 1].utility);
      }
      EXPECT_NEAR(sc.forward.norm(), 1.0, 1e-9);
      ASSERT_EQ(sc.gain_terms.size(), 4u);
      EXPECT_EQ(sc.gain_terms[0].first, "target_entropy");
      EXPECT_EQ(sc.gain_terms[3].first, "unknown_roi");
      double sum = 0.0;
      for (const auto& [name, value] : sc.gain_terms) {
        EXPECT_GE(value, 0.0) << name;
        sum += value;
      }
      EXPECT_NEAR(sum, sc.gain, 1e-6 * std::max(1.0, sc.gain));
    }
    EXPECT_EQ(best, r.best_true_gain);
  }
}

TEST(EpisodeEndToEndTest, BadConfigurationsAreErrors) {
  RunConfig c = Config("no-such-planner");
  EXPECT_NE(c.Validate(Registries()).message().find("unknown planner 'no-such-planner'"),
            std::string::npos);
  c = Config("avp-nbv");
  c.segmenter.name = "magic";
  EXPECT_NE(c.Validate(Registries()).message().find("unknown segmenter 'magic'"),
            std::string::npos);
  c = Config("avp-nbv");
  c.episode.views = 0;
  EXPECT_NE(c.Validate(Registries()).message().find("episode.views (0)"), std::string::npos);
}

}  // namespace
}  // namespace avp

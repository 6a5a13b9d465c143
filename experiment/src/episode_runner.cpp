#include <cmath>
#include <memory>

#include <fmt/format.h>

#include <avp/core/rng.h>
#include <avp/experiment/episode_runner.h>
#include <avp/report/metrics_csv.h>
#include <avp/robot/arm_model.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/sim/sim_arm.h>
#include <avp/sim/sim_rgbd_source.h>

namespace avp::experiment {

Eigen::VectorXd StartJoints(const sim::Scene& scene, const robot::ArmModel& arm) {
  if (scene.start_joints_rad.empty()) return arm.home_joints();
  return Eigen::Map<const Eigen::VectorXd>(
      scene.start_joints_rad.data(), static_cast<Eigen::Index>(scene.start_joints_rad.size()));
}

namespace {

/// The detector model the oracle planners expect: the oracle segmenter's own options, or the
/// default noise model for any other segmenter (whose misses they cannot know).
segmentation::OracleOptions DetectorModel(const AnyOptions& segmenter_options) {
  if (segmenter_options.Holds<segmentation::OracleOptions>()) {
    return segmenter_options.As<segmentation::OracleOptions>();
  }
  return segmentation::OracleOptions{};
}

/// The software side of one episode, owned: planner, segmenter, map, and the regret probe.
struct EpisodeParts {
  std::unique_ptr<eval::PlannerTruth> truth;
  std::unique_ptr<planning::ViewPlanner> planner;
  std::unique_ptr<segmentation::Segmenter> segmenter;
  std::unique_ptr<mapping::SemanticMap> map;
  // The regret probe sees the planner's own results (an oracle planner's included).
  std::unique_ptr<eval::OracleNbvPlanner> probe_oracle;
  std::unique_ptr<eval::RegretProbe> probe;
};

Status CheckSceneAndTruth(const RunConfig& config, const sim::Scene& scene,
                          const eval::GroundTruth& gt) {
  if (scene.plant_bounds.IsEmpty()) {
    return InvalidArgumentError(fmt::format("scene '{}' has no plant", scene.name));
  }
  const double voxel_size_m = config.map.grid.voxel_size_m;
  if (std::abs(gt.voxel_size_m - voxel_size_m) > 1e-12) {
    return InvalidArgumentError(fmt::format(
        "the ground truth ({}) has {} m voxels but the map is configured with {} m: give "
        "--voxel-size {}",
        gt.source, gt.voxel_size_m, voxel_size_m, gt.voxel_size_m));
  }
  return Status::Ok();
}

Result<EpisodeParts> BuildParts(const RunConfig& config, const Registries& registries,
                                const EpisodeTruth& truth) {
  EpisodeParts e;
  AVP_ASSIGN_OR_RETURN(const AnyOptions segmenter_options, SegmenterOptions(config, registries));
  AVP_ASSIGN_OR_RETURN(const AnyOptions planner_options, PlannerOptions(config, registries));
  AVP_ASSIGN_OR_RETURN(const planning::PlannerEntry* entry,
                       registries.planners.Get(config.planner.name));
  const bool known_truth = truth.scene != nullptr && truth.gt != nullptr;
  planning::PlannerContext context{.threads = config.threads, .truth = nullptr};
  if (entry->needs_ground_truth) {
    if (!known_truth) {
      return InvalidArgumentError(
          fmt::format("planner '{}' needs the ground truth, and this episode has none (no scene)",
                      config.planner.name));
    }
    e.truth = std::make_unique<eval::PlannerTruth>(*truth.scene, *truth.gt,
                                                   DetectorModel(segmenter_options));
    context.truth = e.truth.get();
  }
  AVP_ASSIGN_OR_RETURN(e.planner,
                       registries.planners.Make(config.planner.name, planner_options, context));
  AVP_ASSIGN_OR_RETURN(e.segmenter, registries.segmenters.Make(
                                        config.segmenter.name, segmenter_options,
                                        {.seed = Rng(config.seed).Fork("segmenter").NextU64()}));
  AVP_RETURN_IF_ERROR(config.map.Validate());
  e.map = std::make_unique<mapping::SemanticMap>(config.map);
  if (config.oracle_regret) {
    if (!known_truth) {
      return InvalidArgumentError(
          "oracle_regret needs the ground truth, and this episode has none");
    }
    eval::OracleNbvOptions o;
    o.num_threads = config.threads;
    e.probe_oracle = std::make_unique<eval::OracleNbvPlanner>(*truth.scene, *truth.gt, o);
    e.probe = std::make_unique<eval::RegretProbe>(*e.planner, *e.probe_oracle, config.threads);
  }
  return e;
}

}  // namespace

Result<sim::Scene> LoadScene(const RunConfig& config, const Registries& registries) {
  return sim::LoadScene({config.scenario, config.scene_file, config.seed}, registries.scenarios);
}

Result<eval::GroundTruth> GroundTruthFor(const RunConfig& config, const sim::Scene& scene) {
  if (!config.ground_truth_file.empty()) {
    return eval::GroundTruthFromOctomapFile(config.ground_truth_file, &scene);
  }
  AVP_ASSIGN_OR_RETURN(const robot::ArmModel arm, robot::LoadDefaultArm());
  eval::GroundTruthOptions o = config.ground_truth;
  o.voxel_size_m = config.map.grid.voxel_size_m;
  o.max_range_m = config.episode.integrator.max_range_m;
  o.seed = Rng(config.seed).Fork("ground-truth").NextU64();
  o.num_threads = config.threads;
  return eval::ObservableGroundTruth(scene, arm, StartJoints(scene, arm), config.camera, o);
}

Result<RunResult> RunEpisodeWithRobot(const RunConfig& config, const Registries& registries,
                                      const RobotSide& robot, const Box3& roi,
                                      const EpisodeTruth& truth,
                                      const std::vector<pipeline::EpisodeObserver*>& observers,
                                      std::unique_ptr<mapping::SemanticMap>* map_out) {
  AVP_RETURN_IF_ERROR(config.Validate(registries));
  if ((truth.scene == nullptr) != (truth.gt == nullptr)) {
    return InvalidArgumentError(
        "RunEpisodeWithRobot: give the scene and its ground truth, or neither");
  }
  if (truth.scene != nullptr)
    AVP_RETURN_IF_ERROR(CheckSceneAndTruth(config, *truth.scene, *truth.gt));
  AVP_ASSIGN_OR_RETURN(EpisodeParts e, BuildParts(config, registries, truth));

  pipeline::EpisodeOptions eo = config.episode;
  eo.roi = roi;
  eo.integrator.num_threads = config.threads;
  eo.seed = config.seed;
  eval::EvalOptions eval_options;
  eval_options.roi = eo.roi;
  eval::MapMetrics last;
  pipeline::MetricsHook hook;
  if (truth.gt != nullptr) {
    hook = [&](const mapping::SemanticMap& m) {
      last = eval::EvaluateMap(m, *truth.gt, eval_options);
      return report::MetricsRow(last);
    };
  }
  planning::ViewPlanner* planner = e.probe ? e.probe.get() : e.planner.get();
  const pipeline::EpisodeComponents components{robot.source, e.segmenter.get(), robot.arm,
                                               planner,      e.map.get(),       robot.stop};
  AVP_ASSIGN_OR_RETURN(pipeline::EpisodeResult episode,
                       pipeline::RunEpisode(components, eo, hook, observers));
  RunResult result;
  result.episode = std::move(episode);
  result.final_metrics = last;
  if (truth.gt != nullptr) {
    result.gt_voxels = truth.gt->voxels.size();
    result.gt_fruits = truth.gt->fruits.size();
  }
  if (e.probe != nullptr) result.regret = e.probe->steps();
  if (map_out != nullptr) *map_out = std::move(e.map);
  return result;
}

Result<RunResult> RunEpisodeOnScene(const RunConfig& config, const Registries& registries,
                                    const sim::Scene& scene, const eval::GroundTruth& gt,
                                    const std::vector<pipeline::EpisodeObserver*>& observers,
                                    std::unique_ptr<mapping::SemanticMap>* map_out,
                                    std::stop_token stop) {
  AVP_RETURN_IF_ERROR(config.Validate(registries));
  AVP_RETURN_IF_ERROR(CheckSceneAndTruth(config, scene, gt));
  AVP_ASSIGN_OR_RETURN(const robot::ArmModel arm_model, robot::LoadDefaultArm());
  const Eigen::VectorXd q0 = StartJoints(scene, arm_model);
  AVP_RETURN_IF_ERROR(arm_model.CheckJoints(q0));
  sim::SimArm arm(arm_model, q0);
  sim::SimRgbdSource source(scene, config.camera, config.depth_noise, config.seed);
  return RunEpisodeWithRobot(config, registries, {&source, &arm, stop},
                             scene.plant_bounds.Inflated(config.roi_margin_m), {&scene, &gt},
                             observers, map_out);
}

}  // namespace avp::experiment

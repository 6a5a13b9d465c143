#include <cmath>
#include <memory>
#include <optional>

#include <fmt/format.h>

#include <avp/core/rng.h>
#include <avp/experiment/episode_runner.h>
#include <avp/report/metrics_csv.h>
#include <avp/robot/arm_model.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/sim/sim_arm.h>
#include <avp/sim/sim_rgbd_source.h>

namespace avp::experiment {

namespace {

/// The scene's start joints, or the arm's home when the scene names none.
Eigen::VectorXd StartJoints(const sim::Scene& scene, const robot::ArmModel& arm) {
  if (scene.start_joints_rad.empty()) return arm.home_joints();
  return Eigen::Map<const Eigen::VectorXd>(
      scene.start_joints_rad.data(), static_cast<Eigen::Index>(scene.start_joints_rad.size()));
}

/// The detector model the oracle planners expect: the oracle segmenter's own options, or the
/// default noise model for any other segmenter (whose misses they cannot know).
segmentation::OracleOptions DetectorModel(const AnyOptions& segmenter_options) {
  if (segmenter_options.Holds<segmentation::OracleOptions>()) {
    return segmenter_options.As<segmentation::OracleOptions>();
  }
  return segmentation::OracleOptions{};
}

/// The components of one simulated episode, owned.
struct SimulatedEpisode {
  std::optional<robot::ArmModel> arm_model;
  std::unique_ptr<sim::SimArm> arm;
  std::unique_ptr<eval::PlannerTruth> truth;
  std::unique_ptr<planning::ViewPlanner> planner;
  std::unique_ptr<segmentation::Segmenter> segmenter;
  std::unique_ptr<sim::SimRgbdSource> source;
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

Result<SimulatedEpisode> BuildEpisode(const RunConfig& config, const Registries& registries,
                                      const sim::Scene& scene, const eval::GroundTruth& gt) {
  SimulatedEpisode e;
  AVP_ASSIGN_OR_RETURN(e.arm_model, robot::LoadDefaultArm());
  const Eigen::VectorXd q0 = StartJoints(scene, *e.arm_model);
  AVP_RETURN_IF_ERROR(e.arm_model->CheckJoints(q0));
  e.arm = std::make_unique<sim::SimArm>(*e.arm_model, q0);

  AVP_ASSIGN_OR_RETURN(const AnyOptions segmenter_options, SegmenterOptions(config, registries));
  AVP_ASSIGN_OR_RETURN(const AnyOptions planner_options, PlannerOptions(config, registries));
  AVP_ASSIGN_OR_RETURN(const planning::PlannerEntry* entry,
                       registries.planners.Get(config.planner.name));
  planning::PlannerContext context{.threads = config.threads, .truth = nullptr};
  if (entry->needs_ground_truth) {
    e.truth = std::make_unique<eval::PlannerTruth>(scene, gt, DetectorModel(segmenter_options));
    context.truth = e.truth.get();
  }
  AVP_ASSIGN_OR_RETURN(e.planner,
                       registries.planners.Make(config.planner.name, planner_options, context));
  AVP_ASSIGN_OR_RETURN(e.segmenter, registries.segmenters.Make(
                                        config.segmenter.name, segmenter_options,
                                        {.seed = Rng(config.seed).Fork("segmenter").NextU64()}));
  e.source =
      std::make_unique<sim::SimRgbdSource>(scene, config.camera, config.depth_noise, config.seed);
  AVP_RETURN_IF_ERROR(config.map.Validate());
  e.map = std::make_unique<mapping::SemanticMap>(config.map);
  if (config.oracle_regret) {
    eval::OracleNbvOptions o;
    o.num_threads = config.threads;
    e.probe_oracle = std::make_unique<eval::OracleNbvPlanner>(scene, gt, o);
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

Result<RunResult> RunEpisodeOnScene(const RunConfig& config, const Registries& registries,
                                    const sim::Scene& scene, const eval::GroundTruth& gt,
                                    const std::vector<pipeline::EpisodeObserver*>& observers,
                                    std::unique_ptr<mapping::SemanticMap>* map_out) {
  AVP_RETURN_IF_ERROR(config.Validate(registries));
  AVP_RETURN_IF_ERROR(CheckSceneAndTruth(config, scene, gt));
  AVP_ASSIGN_OR_RETURN(SimulatedEpisode e, BuildEpisode(config, registries, scene, gt));

  pipeline::EpisodeOptions eo = config.episode;
  eo.roi = scene.plant_bounds.Inflated(config.roi_margin_m);
  eo.integrator.num_threads = config.threads;
  eo.seed = config.seed;
  eval::EvalOptions eval_options;
  eval_options.roi = eo.roi;
  eval::MapMetrics last;
  const pipeline::MetricsHook hook = [&](const mapping::SemanticMap& m) {
    last = eval::EvaluateMap(m, gt, eval_options);
    return report::MetricsRow(last);
  };
  planning::ViewPlanner* planner = e.probe ? e.probe.get() : e.planner.get();
  const pipeline::EpisodeComponents components{e.source.get(), e.segmenter.get(), e.arm.get(),
                                               planner, e.map.get()};
  AVP_ASSIGN_OR_RETURN(pipeline::EpisodeResult episode,
                       pipeline::RunEpisode(components, eo, hook, observers));
  RunResult result;
  result.episode = std::move(episode);
  result.final_metrics = last;
  result.gt_voxels = gt.voxels.size();
  result.gt_fruits = gt.fruits.size();
  if (e.probe != nullptr) result.regret = e.probe->steps();
  if (map_out != nullptr) *map_out = std::move(e.map);
  return result;
}

}  // namespace avp::experiment

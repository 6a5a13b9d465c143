#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <unordered_map>

#include <fmt/format.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/core/semantic_class.h>
#include <avp/experiment/episode_runner.h>
#include <avp/report/metrics_csv.h>
#include <avp/robot/arm_model.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/sim/contact_counter.h>
#include <avp/sim/ground_truth.h>
#include <avp/sim/sim_arm.h>
#include <avp/sim/sim_rgbd_source.h>

namespace avp::experiment {

Eigen::VectorXd StartJoints(const sim::Scene& scene, const robot::ArmModel& arm) {
  if (scene.start_joints_rad.empty()) return arm.home_joints();
  return Eigen::Map<const Eigen::VectorXd>(
      scene.start_joints_rad.data(), static_cast<Eigen::Index>(scene.start_joints_rad.size()));
}

std::unordered_map<uint16_t, double> VisibleFractions(const robot::Observation& obs,
                                                      const std::vector<sim::FruitTruth>& fruits,
                                                      double max_range_m) {
  if (!obs.labels.has_value()) return {};
  std::unordered_map<uint16_t, GroundTruthFruit> truth;
  for (const sim::FruitTruth& f : fruits) {
    truth[f.instance_id] = {f.instance_id, f.center_W, f.mean_radius_m()};
  }
  const SimulatorLabels& labels = *obs.labels;
  const RgbdFrame& frame = obs.frame;
  const CameraIntrinsics& K = frame.K;
  const auto fruit = static_cast<uint8_t>(SemanticClass::kFruit);
  std::unordered_map<uint16_t, size_t> pixels;
  const int w = std::min(labels.instance_ids.width(), frame.depth_m.width());
  const int h = std::min(labels.instance_ids.height(), frame.depth_m.height());
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      if (labels.class_ids.at(u, v) != fruit) continue;
      const uint16_t id = labels.instance_ids.at(u, v);
      if (truth.count(id) == 0) continue;
      const float d = frame.depth_m.at(u, v);
      if (std::isfinite(d) && d > 0.0f) {
        const Eigen::Vector3d p_C((u - K.cx) / K.fx * d, (v - K.cy) / K.fy * d, d);
        if (p_C.norm() > max_range_m) continue;
      }
      ++pixels[id];
    }
  }
  std::unordered_map<uint16_t, double> out;
  for (const auto& [id, n] : pixels) {
    const std::optional<double> area =
        segmentation::ExpectedFruitAreaPx(K, frame.X_WC, truth.at(id));
    out[id] = area ? std::clamp(static_cast<double>(n) / *area, 0.0, 1.0) : 1.0;
  }
  return out;
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

/// Each fruit's visible fraction in the frames an episode captures, from their simulator labels:
/// the fruit's pixels (instance id, class fruit) over segmentation::ExpectedFruitAreaPx at the
/// frame's camera, clamped to [0, 1] (1 when the area is undefined), as
/// eval::GroundTruth::best_visible_fraction counts them: a pixel with a valid depth farther than
/// max_range_m from the camera does not count; one whose depth the sensor model dropped does (the
/// labels are ground truth). Wraps the episode's source; frames without labels (a real camera)
/// give nothing. Counting is one pass over the label image: no rendering.
class VisibilityProbe final : public robot::RgbdSource {
 public:
  VisibilityProbe(robot::RgbdSource& inner, const std::vector<sim::FruitTruth>& fruits,
                  double max_range_m)
      : inner_(inner), truth_(fruits), max_range_m_(max_range_m) {}

  Result<robot::Observation> Capture(const RigidTransform& X_WC, int64_t stamp_ns) override {
    Result<robot::Observation> obs = inner_.Capture(X_WC, stamp_ns);
    if (obs.ok() && obs->labels.has_value()) last_ = Fractions(*obs);
    return obs;
  }
  CameraIntrinsics intrinsics() const override { return inner_.intrinsics(); }
  /// The moving frames are the source's own (their visibility is not counted: the per-fruit
  /// results count the views).
  std::unique_ptr<robot::MoveStream> StreamMove(const robot::MoveStreamRequest& request) override {
    return inner_.StreamMove(request);
  }

  /// The fractions of the frame captured since the last call, if any (then forgotten).
  std::optional<std::unordered_map<uint16_t, double>> Take() {
    std::optional<std::unordered_map<uint16_t, double>> out = std::move(last_);
    last_.reset();
    return out;
  }

 private:
  std::unordered_map<uint16_t, double> Fractions(const robot::Observation& obs) const {
    return VisibleFractions(obs, truth_, max_range_m_);
  }

  robot::RgbdSource& inner_;
  const std::vector<sim::FruitTruth>& truth_;
  double max_range_m_;
  std::optional<std::unordered_map<uint16_t, double>> last_;
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

Result<EpisodeParts> BuildParts(const CheckedRunConfig& checked, const EpisodeTruth& truth) {
  const RunConfig& config = *checked;
  const Registries& registries = checked.registries();
  const AnyOptions& segmenter_options = checked.segmenter_options();
  EpisodeParts e;
  AVP_ASSIGN_OR_RETURN(const planning::PlannerEntry* entry,
                       registries.planners.Get(config.planner.name));
  const bool known_truth = truth.scene != nullptr && truth.gt != nullptr;
  planning::PlannerContext context{.truth = nullptr};
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
  AVP_ASSIGN_OR_RETURN(
      e.planner, registries.planners.Make(config.planner.name, checked.planner_options(), context));
  AVP_ASSIGN_OR_RETURN(e.segmenter, registries.segmenters.Make(
                                        config.segmenter.name, segmenter_options,
                                        {.seed = Rng(config.seed).Fork("segmenter").NextU64()}));
  e.map = std::make_unique<mapping::SemanticMap>(config.map);
  if (config.oracle_regret) {
    if (!known_truth) {
      return InvalidArgumentError(
          "oracle_regret needs the ground truth, and this episode has none");
    }
    e.probe_oracle =
        std::make_unique<eval::OracleNbvPlanner>(*truth.scene, *truth.gt, eval::OracleNbvOptions{});
    e.probe = std::make_unique<eval::RegretProbe>(*e.planner, *e.probe_oracle,
                                                  config.oracle_regret_features);
  }
  return e;
}

/// With RunConfig::oracle_motion: the true scene's surfaces as occupied voxels of a grid of the
/// map's voxel size, for the motion planner (nullopt otherwise). Refused without motion planning
/// or without the scene.
Result<std::optional<mapping::OccupancyGrid>> TrueObstacles(const RunConfig& config,
                                                            const EpisodeTruth& truth) {
  if (!config.oracle_motion) return std::optional<mapping::OccupancyGrid>();
  if (!config.motion.enabled) {
    return InvalidArgumentError(
        "oracle_motion plans motion against the true scene: it needs "
        "motion.enabled: true");
  }
  if (truth.scene == nullptr) {
    return InvalidArgumentError(
        "oracle_motion needs the true scene, and this episode has none (simulation only)");
  }
  std::optional<mapping::OccupancyGrid> grid(std::in_place, config.map.grid);
  for (const VoxelKey& key :
       sim::VoxelizeObstacleSurfaces(*truth.scene, config.map.grid.voxel_size_m)) {
    grid->SetLogOdds(key, grid->clamp_max_log_odds());
  }
  return grid;
}

/// The run's collision options; with oracle_motion unknown space is free (the planner knows
/// where everything is).
motion::CollisionOptions MotionCollisionOptions(const RunConfig& config) {
  motion::CollisionOptions options = config.motion.collision;
  if (config.oracle_motion) options.field.unknown_is_obstacle = false;
  return options;
}

}  // namespace

Status SegmenterFailedEveryView(const RunResult& result) {
  const std::vector<pipeline::StepRecord>& steps = result.episode.steps;
  if (steps.empty()) return Status::Ok();
  for (const pipeline::StepRecord& s : steps) {
    if (s.segment_status.ok()) return Status::Ok();
  }
  return UnavailableError(fmt::format(
      "the segmenter failed at every one of the {} views (view 1: {}); the run folder holds what "
      "was mapped without masks",
      steps.size(), steps.front().segment_status.ToString()));
}

Status SegmenterFailure(const RunResult& result) {
  if (result.episode.end == pipeline::EpisodeEnd::kSegmenterFault) {
    return UnavailableError(fmt::format("segmenter fault: {}", result.episode.end_reason));
  }
  return SegmenterFailedEveryView(result);
}

std::vector<std::string> WhyNothingFound(const RunConfig& config, const RunResult& result) {
  const std::vector<pipeline::StepRecord>& steps = result.episode.steps;
  const eval::FruitScores& fruits = result.final_metrics.fruits;
  std::vector<std::string> why;
  if (steps.empty() || result.gt_fruits == 0 || fruits.found > 0) return why;
  size_t masks = 0, failed = 0, planned = 0, zero_gain = 0;
  for (const pipeline::StepRecord& s : steps) {
    masks += s.masks;
    failed += s.segment_status.ok() ? 0 : 1;
    if (s.planned && s.chosen_rank >= 0) {
      ++planned;
      zero_gain += s.chosen.gain == 0.0 ? 1 : 0;
    }
  }
  if (failed > 0) {
    why.push_back(fmt::format("the segmenter failed at {} of {} views ({})", failed, steps.size(),
                              config.segmenter.name));
  }
  if (masks == 0 && failed < steps.size()) {
    why.push_back(fmt::format(
        "no view returned a mask: the segmenter '{}' found nothing for the prompt '{}' in {} "
        "views",
        config.segmenter.name, config.episode.prompt, steps.size()));
  } else if (masks > 0) {
    why.push_back(fmt::format(
        "{} masks were segmented in {} views, but none made a fruit's voxels (masks without "
        "valid depth, or on something else)",
        masks, steps.size()));
  }
  const double coverage = result.final_metrics.roi_coverage;
  if (coverage < 0.05) {
    why.push_back(fmt::format(
        "the views saw {:.1f} % of the region of interest around the plant (the camera looked "
        "past it)",
        100.0 * coverage));
  }
  if (planned > 0 && zero_gain == planned) {
    why.push_back(fmt::format(
        "every one of the {} views planner '{}' chose had zero gain: it had nothing to aim at "
        "(a planner that scores views by the fruit already seen finds none when the start view "
        "sees none)",
        planned, config.planner.name));
  }
  return why;
}

Result<sim::Scene> LoadScene(const RunConfig& config, const Registries& registries) {
  return sim::LoadScene({config.scenario, config.scene_file, config.seed, config.arrangement},
                        registries.scenarios);
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
  const ThreadScope threads(config.threads);
  return eval::ObservableGroundTruth(scene, arm, StartJoints(scene, arm), config.camera, o);
}

Result<RunResult> RunEpisodeWithRobot(const CheckedRunConfig& checked, const RobotSide& robot,
                                      const Box3& roi, const EpisodeTruth& truth,
                                      const std::vector<pipeline::EpisodeObserver*>& observers,
                                      std::unique_ptr<mapping::SemanticMap>* map_out) {
  const RunConfig& config = *checked;
  const ThreadScope threads(config.threads);
  if ((truth.scene == nullptr) != (truth.gt == nullptr)) {
    return InvalidArgumentError(
        "RunEpisodeWithRobot: give the scene and its ground truth, or neither");
  }
  if (truth.scene != nullptr)
    AVP_RETURN_IF_ERROR(CheckSceneAndTruth(config, *truth.scene, *truth.gt));
  AVP_ASSIGN_OR_RETURN(EpisodeParts e, BuildParts(checked, truth));

  pipeline::EpisodeOptions eo = config.episode;
  eo.roi = roi;
  eo.seed = config.seed;
  eval::EvalOptions eval_options;
  eval_options.roi = eo.roi;
  eval::MapMetrics last;
  pipeline::MetricsHook hook;
  // Per-fruit results: evaluated with the step's metrics (no second evaluation), the views'
  // visible fractions counted from the captured frames' labels.
  std::optional<VisibilityProbe> visibility;
  eval::FruitTracker fruits;
  int view = 0;
  if (truth.gt != nullptr) {
    if (robot.source != nullptr) {
      visibility.emplace(*robot.source, truth.gt->fruits, eo.integrator.max_range_m);
    }
    hook = [&](const mapping::SemanticMap& m) {
      std::vector<eval::FruitResult> now;
      last = eval::EvaluateMap(m, *truth.gt, eval_options, &now);
      fruits.AfterView(view++, std::move(now), visibility ? visibility->Take() : std::nullopt);
      return report::MetricsRow(last);
    };
  }
  planning::ViewPlanner* planner = e.probe ? e.probe.get() : e.planner.get();
  robot::RgbdSource* source = visibility ? &*visibility : robot.source;
  // Collision-free motion (docs/motion.md): the arm's collision model, the declared world, the
  // map as obstacles (updated by the loop after every view).
  std::optional<motion::CollisionChecker> checker;
  std::optional<motion::MotionPlanner> motion_planner;
  if (config.motion.enabled) {
    AVP_ASSIGN_OR_RETURN(motion::RobotGeometry geometry,
                         motion::RobotGeometry::Create(robot.arm->model()));
    for (const std::string& w : geometry.warnings()) fmt::print(stderr, "warning: {}\n", w);
    AVP_ASSIGN_OR_RETURN(
        checker, motion::CollisionChecker::Create(std::move(geometry),
                                                  robot.arm->model().config().collision.world,
                                                  MotionCollisionOptions(config)));
    motion_planner.emplace(*checker, config.motion);
  }
  AVP_ASSIGN_OR_RETURN(const std::optional<mapping::OccupancyGrid> true_obstacles,
                       TrueObstacles(config, truth));
  const pipeline::EpisodeComponents components{source,
                                               e.segmenter.get(),
                                               robot.arm,
                                               planner,
                                               e.map.get(),
                                               robot.stop,
                                               motion_planner ? &*motion_planner : nullptr,
                                               true_obstacles ? &*true_obstacles : nullptr,
                                               &config.motion};
  AVP_ASSIGN_OR_RETURN(pipeline::EpisodeResult episode,
                       pipeline::RunEpisode(components, eo, hook, observers));
  RunResult result;
  result.episode = std::move(episode);
  result.final_metrics = last;
  if (truth.gt != nullptr) {
    result.gt_voxels = truth.gt->voxels.size();
    result.gt_fruits = truth.gt->fruits.size();
  }
  if (truth.gt != nullptr) result.fruits = fruits.Result();
  if (e.probe != nullptr) result.regret = e.probe->steps();
  if (map_out != nullptr) *map_out = std::move(e.map);
  return result;
}

Result<RunResult> RunEpisodeOnScene(const CheckedRunConfig& checked, const sim::Scene& scene,
                                    const eval::GroundTruth& gt,
                                    const std::vector<pipeline::EpisodeObserver*>& observers,
                                    std::unique_ptr<mapping::SemanticMap>* map_out,
                                    std::stop_token stop) {
  const RunConfig& config = *checked;
  AVP_RETURN_IF_ERROR(CheckSceneAndTruth(config, scene, gt));
  AVP_ASSIGN_OR_RETURN(const robot::ArmModel arm_model, robot::LoadDefaultArm());
  const Eigen::VectorXd q0 = StartJoints(scene, arm_model);
  AVP_RETURN_IF_ERROR(arm_model.CheckJoints(q0));
  sim::SimArm arm(arm_model, q0);
  // The simulator checks every move against the true scene (docs/motion.md): contacts along the
  // executed path and along the straight line.
  AVP_ASSIGN_OR_RETURN(motion::RobotGeometry geometry, motion::RobotGeometry::Create(arm_model));
  AVP_ASSIGN_OR_RETURN(sim::ContactCounter counter,
                       sim::ContactCounter::Create(scene, std::move(geometry)));
  arm.SetContactCounter(std::make_shared<const sim::ContactCounter>(std::move(counter)));
  sim::SimRgbdSource source(scene, config.camera, config.depth_noise, config.seed);
  return RunEpisodeWithRobot(checked, {&source, &arm, stop},
                             scene.plant_bounds.Inflated(config.roi_margin_m), {&scene, &gt},
                             observers, map_out);
}

}  // namespace avp::experiment

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include <avp/eval/experiment.h>
#include <avp/eval/oracle_planner.h>
#include <avp/planning/avp_nbv_planner.h>
#include <avp/planning/isler_utilities.h>
#include <avp/planning/predefined_planner.h>
#include <avp/planning/random_planner.h>
#include <avp/planning/reference_nbv_planner.h>
#include <avp/robot/arm.h>
#include <avp/robot/arm_model.h>
#include <avp/segmentation/oracle_segmenter.h>

namespace avp::eval {

namespace {

std::string JoinNames(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

}  // namespace

const std::vector<std::string>& PlannerNames() {
  static const std::vector<std::string> kNames = {
      "avp-nbv",       "predefined", "predefined-wide", "predefined-generic",
      "reference-nbv", "random",     "isler-ae",        "isler-oa",
      "isler-uv",      "isler-rsv",  "isler-rse",       "isler-pc"};
  return kNames;
}

const std::vector<std::string>& SegmenterNames() { return segmentation::SegmenterNames(); }

const std::vector<std::string>& DiagnosticPlannerNames() {
  static const std::vector<std::string> kNames = {"oracle-nbv", "oracle-detect"};
  return kNames;
}

std::vector<std::string> KnownPlannerNames() {
  std::vector<std::string> known = PlannerNames();
  for (const std::string& n : DiagnosticPlannerNames()) known.push_back(n);
  return known;
}

bool IsKnownPlanner(std::string_view name) {
  const std::vector<std::string> known = KnownPlannerNames();
  return std::find(known.begin(), known.end(), name) != known.end();
}

Result<planning::AvpNbvOptions> AvpNbvOptionsFor(const RunConfig& config) {
  planning::AvpNbvOptions o;
  o.num_threads = config.threads;
  o.candidates.num_threads = config.threads;
  for (const auto& [key, value] : config.planner_options) {
    AVP_RETURN_IF_ERROR(planning::AvpNbvOptionTable().Set(o, key, value));
  }
  AVP_RETURN_IF_ERROR(o.Validate());
  return o;
}

Status RunConfig::Validate() const {
  std::vector<std::string> errors;
  if (!scenario.empty() && !scene_file.empty()) {
    errors.push_back(fmt::format("give a scenario ('{}') or a scene file ('{}'), not both",
                                 scenario, scene_file.string()));
  }
  if (views < 1 || views > 100)
    errors.push_back(fmt::format("views ({}) must be in [1, 100]", views));
  if (!(voxel_size_m >= 0.002 && voxel_size_m <= 0.02)) {
    errors.push_back(fmt::format("voxel size ({} m) must be in [0.002, 0.02]", voxel_size_m));
  }
  if (!(max_range_m > 0.0 && max_range_m <= 10.0)) {
    errors.push_back(fmt::format("max range ({} m) must be in (0, 10]", max_range_m));
  }
  if (!(roi_margin_m >= 0.0 && roi_margin_m <= 1.0)) {
    errors.push_back(fmt::format("ROI margin ({} m) must be in [0, 1]", roi_margin_m));
  }
  if (threads < 0) errors.push_back(fmt::format("threads ({}) must be >= 0", threads));
  if (!IsKnownPlanner(planner)) {
    errors.push_back(
        fmt::format("unknown planner '{}' (known: {})", planner, JoinNames(KnownPlannerNames())));
  }
  if (!segmentation::IsKnownSegmenter(segmenter)) {
    errors.push_back(fmt::format("unknown segmenter '{}' (known: {})", segmenter,
                                 JoinNames(segmentation::KnownSegmenterSpecs())));
  }
  if (Status s = K.Validate(); !s.ok()) errors.push_back(s.ToString());
  if (!planner_options.empty()) {
    if (planner != "avp-nbv") {
      errors.push_back(fmt::format("planner options ({} = {}, ...) apply to avp-nbv only, not '{}'",
                                   planner_options.begin()->first, planner_options.begin()->second,
                                   planner));
    } else if (Result<planning::AvpNbvOptions> o = AvpNbvOptionsFor(*this); !o.ok()) {
      errors.push_back(o.status().message());
    }
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError("invalid run configuration: " + JoinNames(errors));
}

Result<std::unique_ptr<planning::ViewPlanner>> MakePlanner(const RunConfig& config) {
  const std::string& name = config.planner;
  if (name == "avp-nbv") {
    AVP_ASSIGN_OR_RETURN(const planning::AvpNbvOptions o, AvpNbvOptionsFor(config));
    return std::unique_ptr<planning::ViewPlanner>(std::make_unique<planning::AvpNbvPlanner>(o));
  }
  if (name == "random") {
    planning::ShellCandidateOptions o;
    o.num_threads = config.threads;
    return std::unique_ptr<planning::ViewPlanner>(std::make_unique<planning::RandomPlanner>(o));
  }
  if (name == "predefined" || name == "predefined-wide" || name == "predefined-generic") {
    planning::PredefinedOptions o;
    o.set = name == "predefined"        ? planning::PredefinedOptions::Set::kNarrow
            : name == "predefined-wide" ? planning::PredefinedOptions::Set::kWide
                                        : planning::PredefinedOptions::Set::kGeneric;
    return std::unique_ptr<planning::ViewPlanner>(std::make_unique<planning::PredefinedPlanner>(o));
  }
  if (name == "reference-nbv") {
    planning::ReferenceNbvOptions o;
    o.num_threads = config.threads;
    return std::unique_ptr<planning::ViewPlanner>(
        std::make_unique<planning::ReferenceNbvPlanner>(o));
  }
  if (name == "oracle-nbv" || name == "oracle-detect") {
    return FailedPreconditionError(
        fmt::format("planner '{}' needs the true scene and its ground truth: it is built by "
                    "RunEpisodeOnScene",
                    name));
  }
  if (name.rfind("isler-", 0) == 0) {
    const auto utility = planning::IslerUtilityFromString(name.substr(6));
    if (utility) {
      planning::IslerPlannerOptions o;
      o.utility = *utility;
      o.num_threads = config.threads;
      o.candidates.num_threads = config.threads;
      return std::unique_ptr<planning::ViewPlanner>(std::make_unique<planning::IslerPlanner>(o));
    }
  }
  return NotFoundError(
      fmt::format("unknown planner '{}' (known: {})", name, JoinNames(PlannerNames())));
}

Result<std::unique_ptr<segmentation::Segmenter>> MakeSegmenter(const RunConfig& config) {
  return segmentation::MakeSegmenter(config.segmenter,
                                     Rng(config.seed).Fork("segmenter").NextU64());
}

std::vector<std::pair<std::string, double>> MetricsRow(const MapMetrics& m) {
  auto d = [](size_t v) { return static_cast<double>(v); };
  return {
      {"f1", m.exact.f1},
      {"precision", m.exact.precision},
      {"recall", m.exact.recall},
      {"tp", d(m.exact.tp)},
      {"fp", d(m.exact.fp)},
      {"fn", d(m.exact.fn)},
      {"f1_tol", m.tolerant.f1},
      {"precision_tol", m.tolerant.precision},
      {"recall_tol", m.tolerant.recall},
      {"tp_tol", d(m.tolerant.tp)},
      {"fp_tol", d(m.tolerant.fp)},
      {"fn_tol", d(m.tolerant.fn)},
      {"fruits_found", d(m.fruits.found)},
      {"fruits_total", d(m.fruits.total)},
      {"fruits_observable", d(m.fruits.observable)},
      {"fruits_found_fraction", m.fruits.found_fraction},
      {"center_error_m", m.fruits.mean_center_error_m},
      {"radius_error_m", m.fruits.mean_radius_error_m},
      {"map_instances", d(m.fruits.map_instances)},
      {"entropy_sum_bits", m.entropy_sum_bits},
      {"entropy_mean_bits", m.entropy_mean_bits},
      {"predicted_voxels", d(m.predicted_voxels)},
      {"roi_coverage", m.roi_coverage},
  };
}

Result<GroundTruth> GroundTruthFor(const RunConfig& config, const sim::Scene& scene) {
  if (!config.gt_file.empty()) return GroundTruthFromOctomapFile(config.gt_file, &scene);
  AVP_ASSIGN_OR_RETURN(const robot::ArmModel arm, robot::LoadDefaultArm());
  Eigen::VectorXd q_start = arm.home_joints();
  if (!scene.start_joints_rad.empty()) {
    q_start = Eigen::Map<const Eigen::VectorXd>(
        scene.start_joints_rad.data(), static_cast<Eigen::Index>(scene.start_joints_rad.size()));
  }
  GroundTruthOptions o;
  o.voxel_size_m = config.voxel_size_m;
  o.max_range_m = config.max_range_m;
  o.seed = Rng(config.seed).Fork("ground-truth").NextU64();
  o.num_threads = config.threads;
  return ObservableGroundTruth(scene, arm, q_start, config.K, o);
}

Result<RunResult> RunEpisodeOnScene(const RunConfig& config, const sim::Scene& scene,
                                    const GroundTruth& gt,
                                    const std::vector<pipeline::EpisodeObserver*>& observers,
                                    std::unique_ptr<mapping::SemanticMap>* map_out) {
  AVP_RETURN_IF_ERROR(config.Validate());
  if (scene.plant_bounds.IsEmpty()) {
    return InvalidArgumentError(fmt::format("scene '{}' has no plant", scene.name));
  }
  if (std::abs(gt.voxel_size_m - config.voxel_size_m) > 1e-12) {
    return InvalidArgumentError(fmt::format(
        "the ground truth ({}) has {} m voxels but the map is configured with {} m: give "
        "--voxel-size {}",
        gt.source, gt.voxel_size_m, config.voxel_size_m, gt.voxel_size_m));
  }
  AVP_ASSIGN_OR_RETURN(robot::ArmModel arm_model, robot::LoadDefaultArm());
  Eigen::VectorXd q0 = arm_model.home_joints();
  if (!scene.start_joints_rad.empty()) {
    q0 = Eigen::Map<const Eigen::VectorXd>(
        scene.start_joints_rad.data(), static_cast<Eigen::Index>(scene.start_joints_rad.size()));
  }
  AVP_RETURN_IF_ERROR(arm_model.CheckJoints(q0));
  robot::SimArm arm(arm_model, q0);
  std::unique_ptr<planning::ViewPlanner> planner;
  if (config.planner == "oracle-nbv" || config.planner == "oracle-detect") {
    OracleNbvOptions o;
    o.num_threads = config.threads;
    o.candidates.num_threads = config.threads;
    if (config.planner == "oracle-detect") {
      o.objective = OracleNbvOptions::Objective::kDetections;
      o.observation_view_candidates = true;
      // The detector it expects: the oracle segmenter's model (perfect for oracle-perfect; the
      // default noise model for any other segmenter, whose misses it cannot know).
      o.detector = config.segmenter == "oracle-perfect" ? segmentation::OracleOptions::Perfect()
                                                        : segmentation::OracleOptions{};
    }
    planner = std::make_unique<OracleNbvPlanner>(scene, gt, o);
  } else {
    AVP_ASSIGN_OR_RETURN(planner, MakePlanner(config));
  }
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<segmentation::Segmenter> segmenter, MakeSegmenter(config));
  sim::DepthNoiseConfig noise;
  noise.enabled = config.depth_noise;
  pipeline::SimRgbdSource source(scene, config.K, noise, config.seed);

  mapping::MapOptions map_options;
  map_options.grid.voxel_size_m = config.voxel_size_m;
  map_options.semantics.policy = config.policy;
  AVP_RETURN_IF_ERROR(map_options.Validate());
  auto map = std::make_unique<mapping::SemanticMap>(map_options);

  pipeline::EpisodeOptions eo;
  eo.views = config.views;
  eo.prompt = config.prompt;
  eo.roi = scene.plant_bounds.Inflated(config.roi_margin_m);
  eo.integrator.carving = config.carving;
  eo.integrator.max_range_m = config.max_range_m;
  eo.integrator.num_threads = config.threads;
  eo.seed = config.seed;
  EvalOptions eval_options;
  eval_options.roi = eo.roi;
  MapMetrics last;
  const pipeline::MetricsHook hook = [&](const mapping::SemanticMap& m) {
    last = EvaluateMap(m, gt, eval_options);
    return MetricsRow(last);
  };
  // The regret probe sees the planner's own results (an oracle planner's included).
  std::unique_ptr<OracleNbvPlanner> probe_oracle;
  std::unique_ptr<RegretProbe> probe;
  planning::ViewPlanner* used = planner.get();
  if (config.oracle_regret) {
    OracleNbvOptions o;
    o.num_threads = config.threads;
    probe_oracle = std::make_unique<OracleNbvPlanner>(scene, gt, o);
    probe = std::make_unique<RegretProbe>(*planner, *probe_oracle, config.threads);
    used = probe.get();
  }
  pipeline::EpisodeComponents components{&source, segmenter.get(), &arm, used, map.get()};
  AVP_ASSIGN_OR_RETURN(pipeline::EpisodeResult episode,
                       pipeline::RunEpisode(components, eo, hook, observers));
  RunResult result;
  result.episode = std::move(episode);
  result.final_metrics = last;
  result.gt_voxels = gt.voxels.size();
  result.gt_fruits = gt.fruits.size();
  if (probe != nullptr) result.regret = probe->steps();
  if (map_out != nullptr) *map_out = std::move(map);
  return result;
}

// ---- metrics.csv

Result<std::unique_ptr<MetricsCsvWriter>> MetricsCsvWriter::Open(
    const std::filesystem::path& path) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) {
    return IoError(fmt::format("cannot write '{}': {}", path.string(), std::strerror(errno)));
  }
  return std::unique_ptr<MetricsCsvWriter>(new MetricsCsvWriter(f, path));
}

MetricsCsvWriter::~MetricsCsvWriter() {
  if (file_ != nullptr) std::fclose(file_);
}

void MetricsCsvWriter::OnStep(const pipeline::StepRecord& s, const mapping::SemanticMap&) {
  if (file_ == nullptr) return;
  if (!header_written_) {
    std::fprintf(file_, "view");
    for (const auto& [name, value] : s.metrics) std::fprintf(file_, ",%s", name.c_str());
    std::fprintf(file_,
                 ",known_voxels,occupied_voxels,target_voxels,instances,masks,capture_ms,"
                 "segment_ms,integrate_ms,metrics_ms,plan_ms,move_ms,step_ms,candidates,"
                 "reachable,chosen_rank,chosen_utility,chosen_gain,joint_path_length,eye_x,"
                 "eye_y,eye_z,status\n");
    header_written_ = true;
  }
  std::fprintf(file_, "%d", s.view + 1);
  for (const auto& [name, value] : s.metrics) std::fprintf(file_, ",%.9g", value);
  const Eigen::Vector3d eye = s.X_WC.translation();
  std::string status = "ok";
  if (!s.capture_status.ok())
    status = "capture-error";
  else if (!s.segment_status.ok())
    status = "segment-error";
  else if (!s.integrate_status.ok())
    status = "integrate-error";
  else if (s.planned && s.chosen_rank < 0)
    status = "no-move";
  std::fprintf(file_,
               ",%zu,%zu,%zu,%zu,%zu,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%zu,%zu,%d,%.6g,%.6g,"
               "%.6g,%.4f,%.4f,%.4f,%s\n",
               s.known_voxels, s.occupied_voxels, s.target_voxels, s.instances, s.masks,
               s.times.capture_ms, s.times.segment_ms, s.times.integrate_ms, s.times.metrics_ms,
               s.times.plan_ms, s.times.move_ms, s.times.total_ms, s.candidates_generated,
               s.candidates_reachable, s.chosen_rank, s.chosen_rank >= 0 ? s.chosen.utility : 0.0,
               s.chosen_rank >= 0 ? s.chosen.gain : 0.0, s.joint_path_length, eye.x(), eye.y(),
               eye.z(), status.c_str());
  std::fflush(file_);
}

}  // namespace avp::eval

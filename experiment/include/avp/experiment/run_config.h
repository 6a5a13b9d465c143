#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include <yaml-cpp/yaml.h>

#include <avp/core/camera.h>
#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/eval/ground_truth.h>
#include <avp/experiment/registries.h>
#include <avp/mapping/semantic_map.h>
#include <avp/motion/motion_planner.h>
#include <avp/pipeline/episode.h>
#include <avp/ros/bag/frame_selection.h>
#include <avp/sim/sensor_noise.h>

namespace avp::experiment {

/// The most threads a run (RunConfig::threads) or a bench (BenchConfig::jobs) asks for.
inline constexpr int kMaxThreads = 1024;

/// A registered component picked by name, with KEY=VALUE settings over its registered defaults
/// (checked against its options table when the configuration is validated).
struct ComponentChoice {
  std::string name;
  OptionValues options;
};

/// What `avp replay` fuses of a robot's bag (docs/recording.md "Replaying a real robot's bag"):
/// which of its colour/depth pairs (ros::bag::FrameSelection: start_s, end_s, at_rest_only,
/// every_nth, fps, max_views, ...) and the region of interest the map keeps.
struct ReplayConfig : ros::bag::FrameSelection {
  /// The map keeps only voxels inside the box [roi_min_m, roi_max_m] (the base frame, metres;
  /// both 3 values, or both empty: no box); the coverage metric and the report use it too.
  std::vector<double> roi_min_m;
  std::vector<double> roi_max_m;
  /// The box, when set.
  std::optional<Box3> Roi() const;
};

/// The fields of ReplayConfig (the run configuration's replay.* keys).
const OptionTable<ReplayConfig>& ReplayConfigTable();

/// One episode's whole configuration (docs/experiments.md, "Configuration"): it nests the
/// modules' own option structs, each with its field table, and writes each default once, where
/// the module declares it. `avp run --print-config` prints it as YAML that `--config` reads back.
struct RunConfig {
  /// A registered scenario (empty: the default one) or a YAML scene file (then scenario is empty).
  std::string scenario;
  std::filesystem::path scene_file;
  /// How the scene file's plant is arranged (sim::ParseArrangement: "full-occlusion",
  /// "plant-y=0.4+start-yaw=20", ...; empty: as the file places it; a scenario takes only
  /// "reference").
  std::string arrangement;
  /// Seed of the plant, the noise and every choice (forked per subsystem).
  uint64_t seed = 0;
  /// Threads inside the planner, the integrator and the ground truth (0 = all). Results do not
  /// depend on it.
  int threads = 0;
  /// The planning ROI is the scene's plant bounds inflated by this.
  double roi_margin_m = 0.05;
  /// Ground truth from an OctoMap .bt instead of the observable fruit surface.
  std::filesystem::path ground_truth_file;
  /// Measure each plan step's regret with the truth (eval::RegretProbe): the episode does not
  /// change, its plan times include the probe's rendering.
  bool oracle_regret = false;
  /// With oracle_regret: each scored candidate also carries its feature row
  /// (planning/view_features.h), the data a learned gain is trained on (docs/planning.md, "A
  /// learned gain").
  bool oracle_regret_features = false;
  /// Simulation only, with motion.enabled: the motion planner avoids the true scene (every
  /// object's surface voxelised at the map's voxel size; unknown space is free) instead of the
  /// map. Collision-free motion's ceiling: what the arm could reach if it knew the plant
  /// (docs/motion.md).
  bool oracle_motion = false;
  /// The camera (its intrinsics and depth range).
  CameraIntrinsics camera = CameraIntrinsics::RealSenseD435();
  /// The simulated camera's depth noise (on by default in episodes).
  sim::DepthNoiseConfig depth_noise{.enabled = true};
  /// The semantic occupancy map.
  mapping::MapOptions map;
  /// The loop: views, prompt, score threshold, integrator.
  pipeline::EpisodeOptions episode;
  /// How the observable ground truth is computed (its voxel size and range are the map's and the
  /// integrator's).
  eval::GroundTruthOptions ground_truth;
  /// `avp replay` of a robot's bag: the frames to fuse and the region of interest.
  ReplayConfig replay;
  /// Collision-free motion (docs/motion.md): margins, what counts as an obstacle, the planner's
  /// budget, the trajectory's speed.
  motion::MotionOptions motion;
  ComponentChoice planner{"avp-nbv", {}};
  ComponentChoice segmenter{"oracle", {}};

  /// Every problem at once, each naming the key and its value: the tables' ranges, an unknown
  /// scenario, planner or segmenter (with the known ones), options a component does not have or
  /// values out of their range. InvalidArgument "invalid run configuration: ...".
  Status Validate(const Registries& registries) const;
};

/// A run configuration checked at the door: validated once (RunConfig::Validate), with the
/// registries it was checked against and its planner's and segmenter's options resolved. Only
/// Check makes one and it cannot be changed afterwards, so the functions that take it (RunToFolder,
/// RunEpisodeOnScene, RunEpisodeWithRobot, RunEpisodeToFolder, RunLiveToFolder) check nothing
/// again. The registries must outlive it.
class CheckedRunConfig {
 public:
  /// InvalidArgument "invalid run configuration: ..." with every problem (RunConfig::Validate).
  static Result<CheckedRunConfig> Check(RunConfig config, const Registries& registries);

  const RunConfig& config() const { return config_; }
  const RunConfig& operator*() const { return config_; }
  const RunConfig* operator->() const { return &config_; }
  const Registries& registries() const { return *registries_; }
  /// The planner's and the segmenter's options: registered defaults + the overrides, valid.
  const AnyOptions& planner_options() const { return planner_options_; }
  const AnyOptions& segmenter_options() const { return segmenter_options_; }

 private:
  CheckedRunConfig(RunConfig config, const Registries& registries, AnyOptions planner,
                   AnyOptions segmenter);
  RunConfig config_;
  const Registries* registries_;
  AnyOptions planner_options_;
  AnyOptions segmenter_options_;
};

/// The fields of RunConfig that do not depend on the registries: everything but `planner` and
/// `segmenter` (camera.*, depth_noise.*, map.*, episode.*, ground_truth.*, ...).
const OptionTable<RunConfig>& RunConfigTable();

/// Sets one key of the configuration tree from text, as a YAML file or `--set KEY=VALUE` names
/// it: a key of RunConfigTable ("map.grid.voxel_size_m"), "planner" or "planner.name",
/// "planner.options.KEY", and the same for "segmenter". Component options are checked by
/// Validate, not here. InvalidArgument naming an unknown key (and the known top-level ones).
Status SetRunConfigKey(RunConfig& config, std::string_view key, std::string_view value);

/// The effective configuration as YAML: every field of RunConfigTable, and the planner's and
/// segmenter's names with every one of their options (registered defaults, then the
/// overrides). Errors: those of Validate for the components.
Result<YAML::Node> RunConfigToYaml(const RunConfig& config, const Registries& registries);

/// Applies a YAML tree (RunConfigToYaml's shape, any subset of it) over `config`: every key it
/// names is set (SetRunConfigKey), in document order. Errors name `context` and the key.
Status ReadRunConfigYaml(const YAML::Node& node, std::string_view context, RunConfig& config);

/// Reads a run configuration file over the defaults (RunConfig{}), then validates it.
Result<RunConfig> LoadRunConfig(const std::filesystem::path& yaml, const Registries& registries);

/// The planner's and the segmenter's options, resolved (registered defaults + overrides,
/// validated).
Result<AnyOptions> PlannerOptions(const RunConfig& config, const Registries& registries);
Result<AnyOptions> SegmenterOptions(const RunConfig& config, const Registries& registries);

}  // namespace avp::experiment

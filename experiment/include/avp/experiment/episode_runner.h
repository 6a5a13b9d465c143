#pragma once

#include <memory>
#include <stop_token>
#include <unordered_map>
#include <vector>

#include <avp/core/box.h>
#include <avp/core/status.h>
#include <avp/eval/ground_truth.h>
#include <avp/eval/metrics.h>
#include <avp/eval/oracle_planner.h>
#include <avp/experiment/registries.h>
#include <avp/experiment/run_config.h>
#include <avp/mapping/semantic_map.h>
#include <avp/pipeline/episode.h>
#include <avp/robot/arm.h>
#include <avp/robot/rgbd_source.h>
#include <avp/sim/scene.h>

namespace avp::experiment {

/// The scene of `config`: its registered scenario (the default one when none is named) or its
/// scene file, seeded with config.seed.
Result<sim::Scene> LoadScene(const RunConfig& config, const Registries& registries);

/// The ground truth for `config` on `scene`: the observable fruit surface (from the arm's
/// reachable views, config.ground_truth at the map's voxel size and the integrator's range), or
/// config.ground_truth_file.
Result<eval::GroundTruth> GroundTruthFor(const RunConfig& config, const sim::Scene& scene);

/// Everything one episode produced.
struct RunResult {
  pipeline::EpisodeResult episode;
  /// Final metrics (the last step's).
  eval::MapMetrics final_metrics;
  size_t gt_voxels = 0;
  size_t gt_fruits = 0;
  double gt_ms = 0.0;
  /// Per plan step, with RunConfig::oracle_regret (empty otherwise).
  std::vector<eval::StepRegret> regret;
  /// Every ground-truth fruit (instance-id order) with the final map's result for it
  /// (eval::EvaluateFruits, the same evaluation as final_metrics) and the episode's: the view
  /// that found it, and how visible it was in the fused views (eval::FruitResult). Empty without
  /// a ground truth or for one without fruits (a file read without a scene).
  std::vector<eval::FruitResult> fruits;
};

/// The robot side of one episode: where frames come from and what moves the camera (the
/// simulator's SimRgbdSource and SimArm, or a live robot's), and the stop token that ends it.
struct RobotSide {
  robot::RgbdSource* source = nullptr;
  robot::Arm* arm = nullptr;
  std::stop_token stop;
};

/// What an episode is scored against, when it is known: the scene and its ground truth (both or
/// neither). Without it the episode has no metrics, and planners that need the truth (oracle-*)
/// and RunConfig::oracle_regret are refused.
struct EpisodeTruth {
  const sim::Scene* scene = nullptr;
  const eval::GroundTruth* gt = nullptr;
};

/// Runs one episode of `config` with `robot` (the registered planner and segmenter with their
/// options, a map of config.map), planning inside `roi`, on config.threads threads (a
/// ThreadScope: core/parallel.h). Observers see every step as it completes; `map_out`, when
/// given, receives the final map.
Result<RunResult> RunEpisodeWithRobot(const CheckedRunConfig& config, const RobotSide& robot,
                                      const Box3& roi, const EpisodeTruth& truth,
                                      const std::vector<pipeline::EpisodeObserver*>& observers = {},
                                      std::unique_ptr<mapping::SemanticMap>* map_out = nullptr);

/// Each fruit's visible fraction in a capture, from its simulator labels: the fruit's pixels
/// (instance id, class fruit) over segmentation::ExpectedFruitAreaPx at the frame's camera,
/// clamped to [0, 1] (1 when the area is undefined), as eval::GroundTruth::best_visible_fraction
/// counts them: a pixel with a valid depth farther than max_range_m from the camera does not
/// count; one whose depth the sensor model dropped does (the labels are ground truth). Empty
/// without labels. What RunEpisodeWithRobot's per-fruit results (and `avp replay`'s) count.
std::unordered_map<uint16_t, double> VisibleFractions(const robot::Observation& obs,
                                                      const std::vector<sim::FruitTruth>& fruits,
                                                      double max_range_m);

/// Why an episode with a ground truth found no fruit, one line per cause its steps show, in a
/// researcher's words: no view returned a mask (the prompt, the segmenter); the segmenter failed;
/// the views saw almost none of the region of interest; every plan's chosen view had zero gain
/// (the planner had nothing to aim at, e.g. the paper's planner, which scores views by the fruit
/// already seen, from a start that sees none); masks without fruit voxels. Empty when a fruit was
/// found or there is no ground truth. `avp run` prints it and record.json holds it
/// ("nothing_found").
std::vector<std::string> WhyNothingFound(const RunConfig& config, const RunResult& result);

/// Unavailable naming the first view's error when the segmenter failed at every fused view (a
/// degenerate scene, a backend that refuses every frame): the run mapped nothing it segmented,
/// and `avp run` ends non-zero, its results saved. OK otherwise (no views: OK).
Status SegmenterFailedEveryView(const RunResult& result);

/// Unavailable when the episode's segmenter failed it: it ended as segmenter-fault (naming the
/// reason), or failed at every view (SegmenterFailedEveryView). The run's results are saved, and
/// `avp run` (and the Python module's avp.run) then fails. OK otherwise.
Status SegmenterFailure(const RunResult& result);

/// The scene's start joints, or the arm's home when the scene names none.
Eigen::VectorXd StartJoints(const sim::Scene& scene, const robot::ArmModel& arm);

/// Runs one episode of `config` on `scene` against `gt` (compute it once per scene with
/// GroundTruthFor and share it between planners and seeds): the simulated camera and arm
/// (sim::SimRgbdSource, sim::SimArm), the registered planner and segmenter with their options.
/// `map_out`, when given, receives the final map. Observers see every step as it completes; a stop
/// requested through `stop` ends the episode as interrupted (a result could not be written).
Result<RunResult> RunEpisodeOnScene(const CheckedRunConfig& config, const sim::Scene& scene,
                                    const eval::GroundTruth& gt,
                                    const std::vector<pipeline::EpisodeObserver*>& observers = {},
                                    std::unique_ptr<mapping::SemanticMap>* map_out = nullptr,
                                    std::stop_token stop = {});

}  // namespace avp::experiment

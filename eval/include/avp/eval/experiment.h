#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/camera.h>
#include <avp/core/status.h>
#include <avp/eval/ground_truth.h>
#include <avp/eval/metrics.h>
#include <avp/eval/oracle_planner.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/semantics.h>
#include <avp/pipeline/episode.h>
#include <avp/planning/avp_nbv_planner.h>
#include <avp/planning/view_planner.h>
#include <avp/segmentation/segmenter.h>
#include <avp/sim/scene.h>

namespace avp::eval {

/// Names accepted by MakePlanner / MakeSegmenter.
const std::vector<std::string>& PlannerNames();
const std::vector<std::string>& SegmenterNames();
/// Planners that need the true scene (built only by RunEpisodeOnScene): "oracle-nbv", the
/// ground-truth upper bound on avp-nbv's candidates (eval/oracle_planner.h).
const std::vector<std::string>& DiagnosticPlannerNames();
/// PlannerNames(), then DiagnosticPlannerNames().
std::vector<std::string> KnownPlannerNames();
/// In KnownPlannerNames().
bool IsKnownPlanner(std::string_view name);

/// One episode's configuration: everything `avp run` resolves and records.
struct RunConfig {
  /// Built-in scenario (empty: the default one) or a YAML scene file (then scenario is empty).
  std::string scenario;
  std::filesystem::path scene_file;
  uint64_t seed = 0;
  std::string planner = "avp-nbv";
  std::string segmenter = "oracle";
  /// Fused views, start view included (the paper's "8 views" = 8 observations).
  int views = 8;
  std::string prompt = "tomato";
  double voxel_size_m = 0.005;
  mapping::FusionPolicy policy = mapping::FusionPolicy::kBayesian;
  mapping::FreeSpaceCarving carving = mapping::FreeSpaceCarving::kProjective;
  double max_range_m = 1.5;
  /// The depth noise model of a D435-like camera.
  bool depth_noise = true;
  CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  /// The planning ROI is the scene's plant bounds inflated by this.
  double roi_margin_m = 0.05;
  /// Threads inside the planner and integrator (0 = all). The bench runs episodes in parallel
  /// with 1 each. Results do not depend on it.
  int threads = 0;
  /// Ground truth from an OctoMap .bt instead of the observable fruit surface.
  std::filesystem::path gt_file;
  /// avp-nbv's options by name (planning::SetAvpNbvOption: "p_unknown" -> "0.1", ...), over its
  /// defaults; only for planner "avp-nbv".
  std::map<std::string, std::string> planner_options;
  /// Measure the planner's regret at every step with the truth (RegretProbe; RunResult::regret):
  /// the episode does not change, its plan times include the probe's rendering.
  bool oracle_regret = false;
  Status Validate() const;
};

/// Planner by name ("avp-nbv", "predefined", "predefined-wide", "predefined-generic",
/// "reference-nbv", "random", "isler-ae", ...). NotFound naming the known names;
/// InvalidArgument for a bad planner option.
Result<std::unique_ptr<planning::ViewPlanner>> MakePlanner(const RunConfig& config);
/// Segmenter by name ("oracle", "oracle-perfect", "color"), seeded from config.seed.
Result<std::unique_ptr<segmentation::Segmenter>> MakeSegmenter(const RunConfig& config);

/// avp-nbv's options for `config`: the defaults, config.threads, then config.planner_options
/// (planning::SetAvpNbvOption), validated.
Result<planning::AvpNbvOptions> AvpNbvOptionsFor(const RunConfig& config);

/// The (name, value) metrics of a map, in a fixed order (the columns of metrics.csv).
std::vector<std::pair<std::string, double>> MetricsRow(const MapMetrics& m);

/// Everything one episode produced.
struct RunResult {
  pipeline::EpisodeResult episode;
  /// Final metrics (the last step's).
  MapMetrics final_metrics;
  size_t gt_voxels = 0;
  size_t gt_fruits = 0;
  double gt_ms = 0.0;
  /// Per plan step, with RunConfig::oracle_regret (empty otherwise).
  std::vector<StepRegret> regret;
};

/// Runs one episode of `config` on `scene` against `gt` (compute it once per scene with
/// ObservableGroundTruth and share it between planners and seeds). `map_out`, when given,
/// receives the final map. Observers see every step as it completes.
Result<RunResult> RunEpisodeOnScene(const RunConfig& config, const sim::Scene& scene,
                                    const GroundTruth& gt,
                                    const std::vector<pipeline::EpisodeObserver*>& observers = {},
                                    std::unique_ptr<mapping::SemanticMap>* map_out = nullptr);

/// The ground truth for `config` on `scene`: the observable fruit surface (from the arm's
/// reachable views), or config.gt_file.
Result<GroundTruth> GroundTruthFor(const RunConfig& config, const sim::Scene& scene);

/// Writes metrics.csv (one row per step, written and flushed as each step completes).
class MetricsCsvWriter final : public pipeline::EpisodeObserver {
 public:
  static Result<std::unique_ptr<MetricsCsvWriter>> Open(const std::filesystem::path& path);
  void OnStep(const pipeline::StepRecord& step, const mapping::SemanticMap& map) override;
  ~MetricsCsvWriter() override;

 private:
  explicit MetricsCsvWriter(std::FILE* f, std::filesystem::path path)
      : file_(f), path_(std::move(path)) {}
  std::FILE* file_ = nullptr;
  std::filesystem::path path_;
  bool header_written_ = false;
};

}  // namespace avp::eval

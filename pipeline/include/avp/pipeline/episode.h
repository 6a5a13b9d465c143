#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <stop_token>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/camera.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/semantic_map.h>
#include <avp/motion/motion_planner.h>
#include <avp/planning/view_planner.h>
#include <avp/robot/arm.h>
#include <avp/robot/rgbd_source.h>
#include <avp/segmentation/segmenter.h>

namespace avp::pipeline {

/// Wall time of each stage of one step, milliseconds.
struct StageTimes {
  double capture_ms = 0.0;
  double segment_ms = 0.0;
  double integrate_ms = 0.0;
  double metrics_ms = 0.0;
  double plan_ms = 0.0;
  double move_ms = 0.0;
  double total_ms = 0.0;
};

/// How one move was planned and executed (StepRecord::motion, EpisodeResult::return_home).
struct MotionRecord {
  /// A motion planner chose the path (EpisodeComponents::motion); false: the arm was sent
  /// straight to the candidate's joints, unchecked.
  bool planned = false;
  /// Candidates given up before the executed one, each "rank R (source): why" (IK failed, the
  /// goal or the start in collision, no collision-free path, the arm refused).
  std::vector<std::string> rejected;
  /// Motion plans attempted (the rejected ones and the executed one).
  int attempts = 0;
  /// Building the obstacle field from the map, and planning summed over the attempts, ms.
  double map_update_ms = 0.0;
  double planning_ms = 0.0;
  /// The executed path is the straight joint-space line (no search was needed).
  bool straight = false;
  /// States the search drew (0 for a straight path).
  int samples = 0;
  /// The executed path's joint-space length (radians) and duration (seconds).
  double path_length_rad = 0.0;
  double execution_s = 0.0;
  /// The camera's positions along the executed trajectory (its points), for the report.
  std::vector<Eigen::Vector3d> camera_path_W;
  /// Contacts with the true world along the executed motion, and along the straight joint line
  /// (what a blind move would have hit): only where the arm sees the truth (a simulator).
  std::optional<robot::MotionContacts> contacts;
  std::optional<robot::MotionContacts> straight_line_contacts;
};

/// Which frames taken while the arm moves get semantics (MotionFusionOptions::semantics): every
/// frame gets its depth fused.
enum class MovingSemantics : uint8_t {
  /// kEveryFrame for a segmenter that keeps up with a camera stream
  /// (segmentation::Segmenter::keeps_up_with_stream: the oracle, the colour filter), else
  /// kWhenFree.
  kAuto,
  kEveryFrame,  ///< each frame is segmented before it is fused (the stream waits for it)
  /// The segmenter takes the newest frame whenever it is free, on a thread of its own; that frame
  /// is fused with its masks when they come, the others with depth only (which frames get masks
  /// then depends on the segmenter's speed).
  kWhenFree,
  kNone,  ///< depth only
};
std::string_view ToString(MovingSemantics semantics);

/// Fusion during motion (docs/sensing.md, "Seeing while moving"): the camera's frames taken
/// between two views, while the arm moves, fused into the map before the next plan.
struct MotionFusionOptions {
  /// Off by default: the paper's protocol counts views, and fuses only them.
  bool enabled = false;
  /// Frames a second along each move (a camera streaming faster is thinned to it).
  double rate_hz = 30.0;
  /// How the moving frames carve free space: end-voxel rays (one exact ray per voxel holding a
  /// return) keep up with a 30 Hz stream on a laptop; the views keep episode.integrator.carving.
  mapping::FreeSpaceCarving carving = mapping::FreeSpaceCarving::kEndVoxelRays;
  /// Every decimation-th pixel of every decimation-th row of a moving frame is fused (the
  /// RealSense decimation filter's subsampling; mapping::IntegratorOptions::pixel_stride): 1
  /// with projective carving.
  int decimation = 2;
  MovingSemantics semantics = MovingSemantics::kAuto;
  /// A live stream keeps at most this many frames waiting for the map; older ones are dropped
  /// and counted (robot::MoveStreamRequest::max_pending).
  int max_pending = 4;
};
const OptionTable<MotionFusionOptions>& MotionFusionOptionTable();

/// The frame index (SegmentationRequest::frame_index) of the k-th frame (k >= 1) taken during the
/// move after view `view`: far above any view's index, and the same in `avp run` and `avp live`.
inline uint64_t MovingFrameIndex(int view, int k) {
  return (uint64_t{1} << 32) + static_cast<uint64_t>(view) * 1'000'000u + static_cast<uint64_t>(k);
}

/// What fusion during motion did along one move (StepRecord::motion_frames).
struct MovingFramesRecord {
  /// Fusion during motion ran for this move (options on, and a source that streams).
  bool streamed = false;
  /// Frames expected along the move at the rate (a simulator renders each).
  int expected = 0;
  /// Frames whose depth was fused, and of those the frames fused with masks.
  int fused = 0;
  int segmented = 0;
  /// Frames the map was too slow for (dropped), thinned above the rate (skipped), that could not
  /// be had or fused (failed), and frames whose segmentation failed (fused with depth only).
  int dropped = 0;
  int skipped = 0;
  int failed = 0;
  int segment_failed = 0;
  /// The move's duration (the trajectory's, seconds).
  double move_s = 0.0;
  /// Summed over the frames: waiting for or rendering them, segmenting, integrating (ms).
  double capture_ms = 0.0;
  double segment_ms = 0.0;
  double integrate_ms = 0.0;
  /// Wall time the map's side spent on the frames (integrating, and segmenting where the stream
  /// waits for it: kEveryFrame), ms; what must stay under the frame period to keep up.
  double busy_ms = 0.0;
  /// Wall time from the move's start until the last frame was fused (ms).
  double wall_ms = 0.0;
  /// What the moving frames added to the map (known voxels; occupied target voxels).
  int64_t known_delta = 0;
  int64_t target_delta = 0;
  /// The first problem met (a frame, a segmentation), for a person.
  std::string first_problem;
  /// Frames a second the map's side sustains: fused / busy time, 0 when none.
  double map_rate_hz() const;
};

/// Everything that happened in one step of the loop: one fused view (sense, segment, integrate),
/// its metrics, and the choice of and move to the next view (absent after the last view).
struct StepRecord {
  /// 0-based index of the fused view; the episode's "N views" are N fused observations (the start
  /// view plus N - 1 moves; no move is made after the last one).
  int view = 0;
  int views_total = 0;
  /// Where the view was taken.
  RigidTransform X_WC;
  Eigen::VectorXd q;

  Status capture_status;
  Status segment_status;  ///< a segmenter error: the frame is fused without semantics
  Status integrate_status;
  size_t masks = 0;  ///< instances the segmenter returned
  /// Of those, masks with no pixel of valid depth (finite, within the camera's depth range):
  /// they add no semantic evidence (a real camera's depth holes, a mask on a far background).
  size_t masks_without_depth = 0;
  mapping::IntegrationStats integration;

  /// The map after this view, and its change from the previous view.
  size_t known_voxels = 0;
  size_t occupied_voxels = 0;
  size_t target_voxels = 0;  ///< occupied voxels labelled with the target class
  size_t instances = 0;      ///< map instances of the target class
  int64_t known_delta = 0;
  int64_t target_delta = 0;

  /// Metrics from the episode's metrics hook (name, value), in the hook's order.
  std::vector<std::pair<std::string, double>> metrics;

  /// Planning of the next view (planned == false after the last view or when the loop stopped).
  bool planned = false;
  Status plan_status;
  size_t candidates_generated = 0;
  size_t candidates_reachable = 0;
  /// Candidates IK reached but the collision check dropped.
  size_t candidates_in_collision = 0;
  /// PlanResult::warnings.
  std::vector<std::string> plan_warnings;
  /// The best candidates as ranked (up to EpisodeOptions::record_top_candidates).
  std::vector<planning::ViewCandidate> top_candidates;
  /// Rank (0 = best) of the candidate the arm moved to; -1 when none.
  int chosen_rank = -1;
  planning::ViewCandidate chosen;
  /// Moves refused before one succeeded (unreachable ranked candidates).
  int refused_moves = 0;
  Status move_status;
  double joint_path_length = 0.0;
  /// How the move was planned and what it touched.
  MotionRecord motion;
  /// The frames fused while the arm moved (EpisodeOptions::motion_fusion).
  MovingFramesRecord motion_frames;

  StageTimes times;

  /// The metric named `name`, or NaN.
  double Metric(std::string_view name) const;
};

struct EpisodeOptions {
  /// Fused views (observations), start view included. >= 1.
  int views = 8;
  std::string prompt = "tomato";
  float score_threshold = 0.0f;
  SemanticClass target_class = SemanticClass::kFruit;
  /// The plant's region of interest (planning); required.
  Box3 roi;
  mapping::IntegratorOptions integrator;
  /// Candidates kept in each StepRecord.
  int record_top_candidates = 5;
  /// Seeds the planner's and the arm's random choices (forked per view).
  uint64_t seed = 0;
  /// Views in a row whose segmentation failed before the episode ends as a segmenter fault, in
  /// [1, 1000] (a segmenter that reports Unavailable, a service that is down, ends it at once).
  int max_segment_failures = 3;
  /// With a motion planner: the arm returns to the episode's first pose at the end (not after an
  /// interruption or a robot fault), along a planned path.
  bool return_home = true;
  /// Frames taken and fused while the arm moves between views (off by default).
  MotionFusionOptions motion_fusion;
  /// The table's ranges, a prompt that names something (within the prompt limits of
  /// segmentation::SplitPrompt), a target class other than background and a finite, non-empty
  /// ROI.
  Status Validate() const;
};

/// The configurable fields of EpisodeOptions: views, prompt, score_threshold,
/// record_top_candidates, max_segment_failures, integrator.* and motion_fusion.* (the ROI, the
/// target class and the seed come from the scene, the prompt and the run).
const OptionTable<EpisodeOptions>& EpisodeOptionTable();

/// How the episode ended.
enum class EpisodeEnd : uint8_t {
  kBudgetReached,     ///< all `views` fused
  kPlannerStopped,    ///< the planner's stopping rule fired
  kNoValidCandidate,  ///< the planner had no candidate
  kNoReachableMove,   ///< every ranked candidate was refused by the arm
  kInterrupted,       ///< a stop was requested (Ctrl-C, a time limit) or a component was cancelled
  kRobotFault,  ///< the arm did not arrive or stopped answering (DeadlineExceeded, Unavailable)
  /// The segmenter is not there (it reported Unavailable: a segmentation service that is down or
  /// unreachable) or failed EpisodeOptions::max_segment_failures views in a row. The steps so
  /// far are kept; end_reason is the segmenter's last error (naming the service's address).
  kSegmenterFault,
  /// The planner threw (a bug in it, or a Python planner's exception: docs/python.md): nothing it
  /// would answer can be trusted. end_reason is the exception's message (a Python traceback).
  kPlannerFault,
};
std::string_view ToString(EpisodeEnd end);

struct EpisodeResult {
  EpisodeEnd end = EpisodeEnd::kBudgetReached;
  /// Why it ended (the planner's or the arm's message when it ended early).
  std::string end_reason;
  std::vector<StepRecord> steps;
  /// The move back to the first pose (EpisodeOptions::return_home), when one was made or tried.
  std::optional<MotionRecord> return_home;
  Status return_home_status;
  /// With collision-free motion: how far around the arm at its start the planner took unknown
  /// space as free (motion::CollisionChecker::StartFreeDistance: start_clearance_m and the
  /// field's rounding), and, where the arm sees the true world (a simulator), the nearest object
  /// within it: one there is an assumption broken (docs/motion.md).
  struct StartClearance {
    double assumed_m = 0.0;
    std::optional<robot::TrueClearance> truth;
    bool broken() const { return truth && truth->distance_m < assumed_m; }
  };
  std::optional<StartClearance> start_clearance;
  double total_ms = 0.0;
  int views_fused() const { return static_cast<int>(steps.size()); }
};

/// An episode's moves summed (the steps' and the return home's).
struct MotionTotals {
  /// Moves executed, and motion plans attempted.
  int moves = 0;
  int attempts = 0;
  /// Candidates given up on the way (MotionRecord::rejected).
  int rejected = 0;
  double execution_s = 0.0;
  double path_length_rad = 0.0;
  /// Planning time of every executed move (ms, attempts summed), in order.
  std::vector<double> planning_ms;
  /// Summed contacts where every move reported them (a simulator), else nullopt.
  std::optional<robot::MotionContacts> contacts;
  std::optional<robot::MotionContacts> straight_line_contacts;
  /// The frames fused while moving, summed over the moves (streamed: any move streamed;
  /// first_problem: the first move's with one).
  MovingFramesRecord moving;
  /// The episode's time on a robot, seconds: the moves between views (execution_s) plus the
  /// views' segmentation, integration and planning, plus the time fusion during motion ran past
  /// the end of a move (the robot waits for the map). The simulator's rendering is left out (a
  /// camera takes its frames for free); so is the return home.
  double robot_s = 0.0;
};
MotionTotals SumMotion(const EpisodeResult& result);
/// Adds one move's moving-frame counts and times to `sum` (nothing when it did not stream).
void AddMovingFrames(const MovingFramesRecord& frames, MovingFramesRecord& sum);

/// What one view saw and what the planner weighed after it, for observers that keep more than
/// the StepRecord (recordings, reports). Non-owning; valid only during the OnView call.
struct StepData {
  /// The capture (the frame with its intrinsics and pose; simulator labels when the source has
  /// them). Null when the capture failed.
  const robot::Observation* observation = nullptr;
  /// The segmenter's answer. Null when the capture or the segmentation failed.
  const Segmentation* segmentation = nullptr;
  /// The plan for the next view: every reachable candidate ranked best first, with its gain, cost
  /// and utility. Null when no plan was made (after the last view, or when the loop stopped).
  const planning::PlanResult* plan = nullptr;
};

/// A frame fused while the arm moved (fusion during motion), for observers that keep frames
/// (recordings). Non-owning; valid only during the OnMovingFrame call.
struct MovingFrameData {
  int view = 0;  ///< the view the move left (0-based)
  int k = 0;     ///< the frame's number along the move, from 1
  const robot::Observation* observation = nullptr;
  /// Its masks, when it was segmented; null for depth only.
  const Segmentation* segmentation = nullptr;
};

/// Receives every step as soon as it is complete (before the next one starts), so a long run
/// writes its results step by step.
class EpisodeObserver {
 public:
  virtual ~EpisodeObserver() = default;
  /// Called for every step, just before OnStep, with what the view saw (recordings, reports).
  virtual void OnView(const StepRecord& /*step*/, const StepData& /*data*/,
                      const mapping::SemanticMap& /*map*/) {}
  virtual void OnStep(const StepRecord& step, const mapping::SemanticMap& map) = 0;
  /// Called for every frame fused while the arm moves, on the fusion thread while the episode's
  /// thread waits for the move (never at the same time as the other calls), before the step the
  /// move belongs to is handed over.
  virtual void OnMovingFrame(const MovingFrameData& /*frame*/,
                             const mapping::SemanticMap& /*map*/) {}
  virtual void OnEnd(const EpisodeResult& /*result*/, const mapping::SemanticMap& /*map*/) {}
};

/// Computes a step's metrics from the map after the view was fused (e.g. eval's F1 against
/// ground truth). May be empty.
using MetricsHook =
    std::function<std::vector<std::pair<std::string, double>>(const mapping::SemanticMap&)>;

/// The components of one episode (non-owning).
struct EpisodeComponents {
  robot::RgbdSource* source = nullptr;
  segmentation::Segmenter* segmenter = nullptr;
  robot::Arm* arm = nullptr;
  planning::ViewPlanner* planner = nullptr;
  mapping::SemanticMap* map = nullptr;
  /// Asked before every view, plan and move: a requested stop ends the episode (kInterrupted)
  /// with the steps so far. Live sources and arms take the same token so that their waits end.
  std::stop_token stop;
  /// Plans every move collision-free against the map (updated after each view), the declared
  /// world objects and the arm itself; planners drop candidates in collision. Null: the arm is
  /// sent straight to each view's joints, unchecked (the paper's IK-only filter).
  motion::MotionPlanner* motion = nullptr;
  /// With `motion`: the grid it avoids instead of the map (a simulator's true obstacles,
  /// RunConfig::oracle_motion), taken in before every plan like the map. Null: the map.
  const mapping::OccupancyGrid* motion_obstacles = nullptr;
  /// The timing of straight moves (no motion planner): velocity and acceleration scaling and
  /// the sample period of the trajectory a straight move follows when frames are fused while
  /// moving, and of the duration recorded for it otherwise. Null: MotionOptions{}'s.
  const motion::MotionOptions* timing = nullptr;
};

/// Occupied voxels of the target class in the grid (StepRecord::target_voxels).
size_t CountTargetVoxels(const mapping::OccupancyGrid& grid, SemanticClass target);
/// Instances of the target class in the map (StepRecord::instances).
size_t CountTargetInstances(const mapping::SemanticMap& map, SemanticClass target);

/// The active-vision loop: for each view, capture at the arm's current pose, segment, integrate,
/// compute metrics and notify the observers; then, unless it was the last view, plan the next
/// view and move there. Failures are outcomes: a capture or segmenter error is recorded and the
/// loop goes on (a segmenter error fuses the depth without semantics; a capture error fuses
/// nothing); an unreachable ranked candidate is skipped for the next one; no valid candidate,
/// every candidate refused, or the planner's stopping rule end the episode with that reason. An arm
/// that reports DeadlineExceeded or Unavailable ends it as a robot fault (no other candidate is
/// tried: where the arm is, is unknown); a segmenter that reports Unavailable, or fails
/// options.max_segment_failures views in a row, ends it as a segmenter fault after that view is
/// fused (depth only) and recorded; a Cancelled status from any component, or a stop requested
/// through components.stop, ends it as interrupted. The segmenter's requests carry an interrupt
/// that reports Cancelled once components.stop is requested. Observers see every step and the
/// end in every case. InvalidArgument for missing components or invalid options.
Result<EpisodeResult> RunEpisode(const EpisodeComponents& components, const EpisodeOptions& options,
                                 const MetricsHook& metrics = {},
                                 const std::vector<EpisodeObserver*>& observers = {});

}  // namespace avp::pipeline

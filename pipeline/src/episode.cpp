#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>

#include <fmt/format.h>

#include <avp/core/stopwatch.h>
#include <avp/core/text.h>
#include <avp/pipeline/episode.h>
#include <avp/pipeline/view_fusion.h>

namespace avp::pipeline {

namespace {

using Clock = SteadyClock;

}  // namespace

size_t CountTargetVoxels(const mapping::OccupancyGrid& grid, SemanticClass target) {
  size_t n = 0;
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const mapping::SemanticCell& cell) {
    if (cell.cls() == target && grid.State(k) == mapping::VoxelState::kOccupied) ++n;
  });
  return n;
}

size_t CountTargetInstances(const mapping::SemanticMap& map, SemanticClass target) {
  size_t n = 0;
  for (const mapping::InstanceInfo& info : map.Instances()) {
    if (info.semantic_class == target) ++n;
  }
  return n;
}

namespace {

// ---- Stages of RunEpisode -----------------------------------------------------------------------

/// Senses at step.X_WC, segments and fuses the view into the map (depth only when segmentation
/// failed; nothing when the capture failed), recording statuses, counts and times in `step` and
/// what was seen in `seen`.
void SenseAndFuse(const EpisodeComponents& c, ViewFusion& fusion, int view, int64_t stamp_ns,
                  StepRecord& step, ViewSeen& seen) {
  const auto t0 = Clock::now();
  Result<robot::Observation> obs = c.source->Capture(step.X_WC, stamp_ns);
  step.times.capture_ms = MsSince(t0);
  if (!obs.ok()) {
    step.capture_status = obs.status();
    fusion.RecordMap(step);
    return;
  }
  fusion.Segment(std::move(*obs), *c.segmenter, static_cast<uint64_t>(view), c.stop, step, seen);
}

/// A status that ends the episode at once: the robot did not do what it was asked (it did not
/// arrive, it stopped answering) or the run was cancelled.
bool IsRobotFault(const Status& status) {
  return status.code() == StatusCode::kDeadlineExceeded ||
         status.code() == StatusCode::kUnavailable || status.code() == StatusCode::kCancelled;
}

/// Whether the view's segmenter error ends the episode (`failures_in_a_row` counts this view):
/// a segmenter that is not there (Unavailable) at once, any other error after
/// max_segment_failures views in a row. Sets the end and its reason.
bool SegmenterFault(const StepRecord& step, int failures_in_a_row, const EpisodeOptions& options,
                    EpisodeResult& result) {
  const Status& s = step.segment_status;
  if (s.ok()) return false;
  if (s.code() == StatusCode::kUnavailable) {
    result.end = EpisodeEnd::kSegmenterFault;
    result.end_reason = s.ToString();
    return true;
  }
  if (failures_in_a_row < options.max_segment_failures) return false;
  result.end = EpisodeEnd::kSegmenterFault;
  result.end_reason =
      fmt::format("the segmenter failed {} views in a row (max_segment_failures): {}",
                  failures_in_a_row, s.ToString());
  return true;
}

/// Ends the episode as interrupted; returns true.
bool Interrupted(EpisodeResult& result, std::string reason) {
  result.end = EpisodeEnd::kInterrupted;
  result.end_reason = std::move(reason);
  return true;
}

/// What choosing and reaching the next view needs besides the step: fixed for the episode.
struct NextViewContext {
  const EpisodeComponents& c;
  const EpisodeOptions& options;
  Rng planner_root;  ///< forked per view
  Rng arm_root;      ///< forked per view
  Eigen::VectorXd q_start;
  RigidTransform X_WC_start;
  /// Fuses the frames taken while moving between views (EpisodeOptions::motion_fusion); null
  /// when off.
  MovingFusion* moving = nullptr;
};

/// A move between views with fusion during motion: who fuses, the view it leaves, the
/// episode's stamp of its start and where its record goes.
struct MovingMove {
  MovingFusion& fusion;
  int view = 0;
  int64_t start_stamp_ns = 0;
  MovingFramesRecord& rec;
};

/// The straight joint line from `q0` to `q1`, timed as the episode's straight moves are
/// (EpisodeComponents::timing).
Result<robot::JointTrajectory> StraightTrajectory(const EpisodeComponents& c,
                                                  const Eigen::VectorXd& q0,
                                                  const Eigen::VectorXd& q1) {
  const motion::MotionOptions defaults;
  const motion::MotionOptions& t = c.timing != nullptr ? *c.timing : defaults;
  return robot::TimeParameterize(c.arm->model(), {q0, q1}, t.velocity_scaling,
                                 t.acceleration_scaling, t.sample_period_s);
}

/// Executes `trajectory` on the arm, fusing the frames taken along it when `moving` is given.
robot::MoveResult Follow(const EpisodeComponents& c, const robot::JointTrajectory& trajectory,
                         const MovingMove* moving) {
  robot::Arm& arm = *c.arm;
  if (moving == nullptr) return arm.FollowTrajectory(trajectory);
  return moving->fusion.Run(
      *c.source, arm.model(), trajectory, moving->view, moving->start_stamp_ns,
      [&] { return arm.FollowTrajectory(trajectory); }, moving->rec);
}

/// The planning request for the view after `view`, taken at the step's pose.
planning::PlanningRequest PlanningRequestAfter(const NextViewContext& next, int view,
                                               const StepRecord& step,
                                               const std::vector<RigidTransform>& fused) {
  planning::PlanningRequest req;
  req.map = next.c.map;
  req.arm = &next.c.arm->model();
  req.q_current = step.q;
  req.X_WC_current = step.X_WC;
  req.q_start = next.q_start;
  req.X_WC_start = next.X_WC_start;
  req.K = next.c.source->intrinsics();
  req.roi = next.options.roi;
  req.view_index = view + 1;
  req.views_total = next.options.views;
  req.fused_views = fused;
  req.target_class = next.options.target_class;
  req.prompt = next.options.prompt;
  if (next.c.motion != nullptr) {
    req.collision = &next.c.motion->checker();
    req.collision_step_back_m = next.c.motion->options().step_back_m;
  }
  return req;
}

/// The planner's answer; a throw becomes an Internal error naming the planner, and `*threw`.
planning::PlanResult PlanOrError(planning::ViewPlanner& planner,
                                 const planning::PlanningRequest& req, Rng& rng, bool* threw) {
  planning::PlanResult plan;
  *threw = false;
  try {
    plan = planner.Plan(req, rng);
  } catch (const std::exception& e) {
    plan = {};
    plan.status = InternalError(fmt::format("planner '{}' threw: {}", planner.name(), e.what()));
    *threw = true;
  }
  return plan;
}

/// A refusal as a MoveResult.
robot::MoveResult NotMoved(Status status) {
  robot::MoveResult move;
  move.status = std::move(status);
  return move;
}

/// Moves the arm to `q_goal` (or, when empty, to joints IK finds for `X_WC`): along a planned
/// collision-free trajectory with a motion planner, else straight (unchecked). A plan that fails
/// comes back as the move's status (not a robot fault: the next candidate is tried); `rec` gets
/// the plan's figures, and the executed trajectory is marked as swept (free) space. With
/// `moving`, the frames taken along the move are fused (a straight move then follows its timed
/// trajectory).
robot::MoveResult MoveTo(const EpisodeComponents& c, const Eigen::VectorXd& q_goal,
                         const RigidTransform& X_WC, Rng& rng, MotionRecord& rec,
                         const MovingMove* moving = nullptr) {
  robot::Arm& arm = *c.arm;
  const int n = arm.model().num_joints();
  const Eigen::VectorXd q_before = arm.CurrentJoints();
  robot::MoveResult move;
  const robot::JointTrajectory* executed = nullptr;
  std::optional<robot::JointTrajectory> timed;
  if (c.motion == nullptr && moving == nullptr) {
    move = q_goal.size() == n ? arm.MoveToJoints(q_goal) : arm.MoveToCameraPose(X_WC, rng);
    rec.path_length_rad = move.joint_path_length;
  } else {
    rec.planned = c.motion != nullptr;
    Eigen::VectorXd goal = q_goal;
    if (goal.size() != n) {
      const robot::IkResult ik = arm.model().SolveCameraIk(X_WC, q_before, rng);
      if (!ik.ok()) return NotMoved(ik.status);
      goal = ik.q;
    }
    if (c.motion == nullptr) {
      Result<robot::JointTrajectory> line = StraightTrajectory(c, q_before, goal);
      if (!line.ok()) return NotMoved(line.status());
      timed = std::move(*line);
      executed = &*timed;
      rec.straight = true;
    } else {
      ++rec.attempts;
      const motion::MotionPlan plan = c.motion->Plan(q_before, goal, rng);
      rec.planning_ms += plan.planning_ms;
      if (!plan.ok()) return NotMoved(plan.status);
      timed = plan.trajectory;
      executed = &*timed;
      rec.straight = plan.straight;
      rec.samples = plan.samples;
      rec.path_length_rad = plan.path_length;
    }
    move = Follow(c, *executed, moving);
    if (!move.ok()) return move;
    if (c.motion == nullptr) rec.path_length_rad = move.joint_path_length;
    for (const robot::TrajectoryPoint& p : executed->points) {
      rec.camera_path_W.push_back(arm.model().CameraPose(p.q).translation());
      if (c.motion != nullptr) c.motion->checker().MarkSwept(p.q);
    }
  }
  if (move.ok()) {
    rec.execution_s = move.execution_s;
    if (rec.execution_s == 0.0 && executed == nullptr) {
      // A straight move the arm did not time: the duration of the same line timed as a straight
      // move with fusion during motion is (episode time, per-second figures).
      if (const Result<robot::JointTrajectory> line = StraightTrajectory(c, q_before, move.q);
          line.ok()) {
        rec.execution_s = line->duration_s();
      }
    }
    rec.contacts = move.contacts;
    rec.straight_line_contacts = move.straight_line_contacts;
  }
  return move;
}

/// Moves the arm to the best ranked candidate it can reach (planned, with a motion planner;
/// at most MotionOptions::max_attempts plans), recording the choice and the refusals in `step`.
/// Returns the refusals' messages (the first ~400 characters) for the episode's end reason.
std::string MoveToBestCandidate(const EpisodeComponents& c,
                                const std::vector<planning::ViewCandidate>& ranked, Rng& arm_rng,
                                MovingFusion* moving, int64_t stamp_ns, StepRecord& step) {
  std::string refusals;
  for (size_t i = 0; i < ranked.size(); ++i) {
    if (c.motion != nullptr && step.motion.attempts >= c.motion->options().max_attempts) {
      refusals += fmt::format("; {} motion plans failed (max_attempts)", step.motion.attempts);
      break;
    }
    const planning::ViewCandidate& cand = ranked[i];
    step.motion_frames = {};  // only the executed move's frames
    std::optional<MovingMove> along;
    if (moving != nullptr)
      along.emplace(MovingMove{*moving, step.view, stamp_ns, step.motion_frames});
    const robot::MoveResult move =
        MoveTo(c, cand.q, cand.X_WC, arm_rng, step.motion, along ? &*along : nullptr);
    if (move.ok()) {
      step.chosen_rank = static_cast<int>(i);
      step.chosen = cand;
      step.move_status = Status::Ok();
      step.joint_path_length = move.joint_path_length;
      break;
    }
    ++step.refused_moves;
    step.motion.rejected.push_back(
        fmt::format("rank {} ({}): {}", i, cand.source, move.status.ToString()));
    if (refusals.size() < 400) refusals += (refusals.empty() ? "" : "; ") + move.status.ToString();
    step.move_status = move.status;
    if (IsRobotFault(move.status)) break;  // where the arm is, is unknown: try nothing else
  }
  return refusals;
}

/// Takes the map into the motion planner's obstacle field (before planning).
Status UpdateMotionMap(const EpisodeComponents& c, const EpisodeOptions& options,
                       MotionRecord& rec) {
  if (c.motion == nullptr) return Status::Ok();
  const auto t0 = Clock::now();
  const Status s = c.motion->checker().SetMap(
      c.motion_obstacles != nullptr ? *c.motion_obstacles : c.map->grid(), options.roi);
  rec.map_update_ms = MsSince(t0);
  return s;
}

/// With a motion planner and EpisodeOptions::return_home: the planned move back to the first
/// pose, unless the episode was interrupted or the robot failed.
void ReturnHome(const NextViewContext& next, EpisodeResult& result) {
  const EpisodeComponents& c = next.c;
  if (c.motion == nullptr || !next.options.return_home || result.end == EpisodeEnd::kInterrupted ||
      result.end == EpisodeEnd::kRobotFault) {
    return;
  }
  MotionRecord& rec = result.return_home.emplace();
  if (Status s = UpdateMotionMap(c, next.options, rec); !s.ok()) {
    result.return_home_status = std::move(s);
    return;
  }
  Rng rng = next.arm_root.Fork("return-home");
  const robot::MoveResult move = MoveTo(c, next.q_start, next.X_WC_start, rng, rec);
  result.return_home_status = move.status;
  if (!move.ok()) rec.rejected.push_back("home: " + move.status.ToString());
}

/// Plans the view after `view` (taken at the episode's stamp `stamp_ns`) and moves there,
/// recording both in `step`. Returns true, with the
/// end and its reason in `result`, when the episode ends here (the planner stopped, no valid
/// candidate, every candidate refused).
bool PlanAndMove(const NextViewContext& next, int view, int64_t stamp_ns,
                 const std::vector<RigidTransform>& fused, StepRecord& step, EpisodeResult& result,
                 ViewSeen& seen) {
  if (next.c.stop.stop_requested()) return Interrupted(result, "stop requested before planning");
  auto t0 = Clock::now();
  if (const Status s = UpdateMotionMap(next.c, next.options, step.motion); !s.ok()) {
    result.end = EpisodeEnd::kNoValidCandidate;
    result.end_reason =
        s.WithContext("the map could not be taken into the motion planner").ToString();
    return true;
  }
  const planning::PlanningRequest req = PlanningRequestAfter(next, view, step, fused);
  Rng planner_rng = next.planner_root.Fork(static_cast<uint64_t>(view + 1));
  bool threw = false;
  const planning::PlanResult& plan =
      seen.plan.emplace(PlanOrError(*next.c.planner, req, planner_rng, &threw));
  step.times.plan_ms = MsSince(t0);
  step.planned = true;
  step.plan_status = plan.status;
  step.candidates_generated = plan.generated;
  step.candidates_reachable = plan.reachable;
  step.candidates_in_collision = plan.in_collision;
  step.plan_warnings = plan.warnings;
  for (size_t i = 0;
       i < plan.ranked.size() && static_cast<int>(i) < next.options.record_top_candidates; ++i) {
    step.top_candidates.push_back(plan.ranked[i]);
  }
  if (threw) {
    result.end = EpisodeEnd::kPlannerFault;
    result.end_reason = plan.status.ToString();
    return true;
  }
  if (plan.stop) {
    result.end = EpisodeEnd::kPlannerStopped;
    result.end_reason = plan.stop_reason;
    return true;
  }
  if (!plan.status.ok() || plan.ranked.empty()) {
    result.end = EpisodeEnd::kNoValidCandidate;
    result.end_reason =
        plan.status.ok() ? "the planner returned no candidate" : plan.status.ToString();
    return true;
  }
  if (next.c.stop.stop_requested()) return Interrupted(result, "stop requested before moving");
  // Move: the best candidate the arm accepts.
  t0 = Clock::now();
  Rng arm_rng = next.arm_root.Fork(static_cast<uint64_t>(view + 1));
  const std::string refusals =
      MoveToBestCandidate(next.c, plan.ranked, arm_rng, next.moving, stamp_ns, step);
  step.times.move_ms = MsSince(t0);
  if (step.chosen_rank >= 0) return false;
  if (step.move_status.code() == StatusCode::kCancelled) {
    return Interrupted(result, step.move_status.ToString());
  }
  if (IsRobotFault(step.move_status)) {
    result.end = EpisodeEnd::kRobotFault;
    result.end_reason = step.move_status.ToString();
    return true;
  }
  result.end = EpisodeEnd::kNoReachableMove;
  result.end_reason =
      fmt::format("the arm refused all {} ranked candidates: {}", plan.ranked.size(), refusals);
  return true;
}

}  // namespace

/// Adds one move's moving-frame counts and times to `sum`.
void AddMovingFrames(const MovingFramesRecord& f, MovingFramesRecord& sum) {
  if (!f.streamed) return;
  sum.streamed = true;
  sum.expected += f.expected;
  sum.fused += f.fused;
  sum.segmented += f.segmented;
  sum.dropped += f.dropped;
  sum.skipped += f.skipped;
  sum.failed += f.failed;
  sum.segment_failed += f.segment_failed;
  sum.move_s += f.move_s;
  sum.capture_ms += f.capture_ms;
  sum.segment_ms += f.segment_ms;
  sum.integrate_ms += f.integrate_ms;
  sum.busy_ms += f.busy_ms;
  sum.wall_ms += f.wall_ms;
  sum.known_delta += f.known_delta;
  sum.target_delta += f.target_delta;
  if (sum.first_problem.empty()) sum.first_problem = f.first_problem;
}

MotionTotals SumMotion(const EpisodeResult& result) {
  MotionTotals t;
  bool all_contacts = true;
  bool all_straight = true;
  robot::MotionContacts contacts;
  robot::MotionContacts straight;
  const auto add = [&](const MotionRecord& m, bool moved) {
    t.attempts += m.attempts;
    t.rejected += static_cast<int>(m.rejected.size());
    if (!moved) return;
    ++t.moves;
    t.execution_s += m.execution_s;
    t.path_length_rad += m.path_length_rad;
    t.planning_ms.push_back(m.planning_ms);
    if (m.contacts) contacts += *m.contacts;
    all_contacts = all_contacts && m.contacts.has_value();
    if (m.straight_line_contacts) straight += *m.straight_line_contacts;
    all_straight = all_straight && m.straight_line_contacts.has_value();
  };
  for (const StepRecord& s : result.steps) {
    add(s.motion, s.chosen_rank >= 0);
    AddMovingFrames(s.motion_frames, t.moving);
    t.robot_s += (s.times.segment_ms + s.times.integrate_ms + s.times.plan_ms) / 1e3;
    if (s.chosen_rank >= 0) t.robot_s += s.motion.execution_s;
    if (s.motion_frames.streamed) {
      t.robot_s += std::max(0.0, (s.motion_frames.busy_ms / 1e3) - s.motion_frames.move_s);
    }
  }
  if (result.return_home) add(*result.return_home, result.return_home_status.ok());
  if (all_contacts && t.moves > 0) t.contacts = contacts;
  if (all_straight && t.moves > 0) t.straight_line_contacts = straight;
  return t;
}

double StepRecord::Metric(std::string_view name) const {
  for (const auto& [key, value] : metrics) {
    if (key == name) return value;
  }
  return std::numeric_limits<double>::quiet_NaN();
}

std::string_view ToString(MovingSemantics semantics) {
  switch (semantics) {
    case MovingSemantics::kAuto:
      return "auto";
    case MovingSemantics::kEveryFrame:
      return "every-frame";
    case MovingSemantics::kWhenFree:
      return "when-free";
    case MovingSemantics::kNone:
      return "none";
  }
  return "unknown";
}

const OptionTable<MotionFusionOptions>& MotionFusionOptionTable() {
  static const auto* table = [] {
    using M = MotionFusionOptions;
    auto* t = new OptionTable<M>("motion fusion option");
    t->Flag("enabled", &M::enabled,
            "fuse the camera's frames taken while the arm moves between views");
    t->Real("rate_hz", &M::rate_hz, "Hz", ValueRange::LeftOpen(0, 120),
            "frames a second along each move");
    t->Choice("carving", &M::carving, mapping::FreeSpaceCarvingChoices(),
              "how the moving frames carve free space (docs/mapping.md)");
    t->Integer("decimation", &M::decimation, "", ValueRange::Closed(1, 8),
               "every n-th pixel of every n-th row of a moving frame is fused (1 with "
               "projective carving)");
    std::vector<std::pair<MovingSemantics, std::string>> semantics;
    for (MovingSemantics m : {MovingSemantics::kAuto, MovingSemantics::kEveryFrame,
                              MovingSemantics::kWhenFree, MovingSemantics::kNone}) {
      semantics.emplace_back(m, std::string(ToString(m)));
    }
    t->Choice("semantics", &M::semantics, semantics,
              "which moving frames are segmented (auto: every frame for a segmenter that keeps "
              "up with a camera, else the newest whenever it is free)");
    t->Integer("max_pending", &M::max_pending, "", ValueRange::Closed(1, 120),
               "a live stream keeps at most this many frames waiting for the map (older ones "
               "are dropped and counted)");
    t->AddRule([](const M& m, std::vector<std::string>& errors) {
      if (m.decimation > 1 && m.carving == mapping::FreeSpaceCarving::kProjective) {
        errors.push_back(fmt::format(
            "motion_fusion.decimation ({}) needs a ray carving (end-voxel, raycast), not "
            "projective",
            m.decimation));
      }
    });
    return t;
  }();
  return *table;
}

const OptionTable<EpisodeOptions>& EpisodeOptionTable() {
  static const auto* table = [] {
    using E = EpisodeOptions;
    auto* t = new OptionTable<E>("episode option");
    t->Integer("views", &E::views, "", ValueRange::Closed(1, 1000),
               "fused views, the start view included");
    t->Text("prompt", &E::prompt, "comma-separated phrases naming what to find");
    t->Real("score_threshold", &E::score_threshold, "", ValueRange::Closed(0, 1),
            "instances scoring below this are dropped");
    t->Integer("record_top_candidates", &E::record_top_candidates, "", ValueRange::Closed(0, 1000),
               "ranked candidates kept in each step's record");
    t->Integer(
        "max_segment_failures", &E::max_segment_failures, "", ValueRange::Closed(1, 1000),
        "views in a row whose segmentation failed before the episode ends (segmenter-fault)");
    t->Flag("return_home", &E::return_home,
            "with motion planning, the arm returns to its first pose at the end of the episode");
    t->Nested("integrator", &E::integrator, mapping::IntegratorOptionTable());
    t->Nested("motion_fusion", &E::motion_fusion, MotionFusionOptionTable());
    t->AddRule([](const E& o, std::vector<std::string>& errors) {
      if (o.prompt.find_first_not_of(" ,\t") == std::string::npos) {
        errors.push_back(fmt::format("prompt ({}) names no class", QuoteText(o.prompt)));
      } else if (Result<std::vector<std::string>> phrases = segmentation::SplitPrompt(o.prompt);
                 !phrases.ok()) {
        errors.push_back(phrases.status().message());
      }
    });
    return t;
  }();
  return *table;
}

Status EpisodeOptions::Validate() const {
  std::vector<std::string> errors = EpisodeOptionTable().Problems(*this);
  if (target_class == SemanticClass::kBackground) errors.push_back("target class is background");
  if (roi.IsEmpty() || !roi.min().allFinite() || !roi.max().allFinite()) {
    errors.push_back(fmt::format("ROI ({}) must be finite and non-empty", roi.ToString()));
  }
  if (errors.empty()) return Status::Ok();
  std::string joined;
  for (const std::string& e : errors) joined += (joined.empty() ? "" : "; ") + e;
  return InvalidArgumentError("invalid episode options: " + joined);
}

std::string_view ToString(EpisodeEnd end) {
  switch (end) {
    case EpisodeEnd::kBudgetReached:
      return "budget-reached";
    case EpisodeEnd::kPlannerStopped:
      return "planner-stopped";
    case EpisodeEnd::kNoValidCandidate:
      return "no-valid-candidate";
    case EpisodeEnd::kNoReachableMove:
      return "no-reachable-move";
    case EpisodeEnd::kInterrupted:
      return "interrupted";
    case EpisodeEnd::kRobotFault:
      return "robot-fault";
    case EpisodeEnd::kSegmenterFault:
      return "segmenter-fault";
    case EpisodeEnd::kPlannerFault:
      return "planner-fault";
  }
  return "unknown";
}

Result<EpisodeResult> RunEpisode(const EpisodeComponents& c, const EpisodeOptions& options,
                                 const MetricsHook& metrics,
                                 const std::vector<EpisodeObserver*>& observers) {
  if (c.source == nullptr || c.segmenter == nullptr || c.arm == nullptr || c.planner == nullptr ||
      c.map == nullptr) {
    return InvalidArgumentError(fmt::format("RunEpisode: missing component(s):{}{}{}{}{}",
                                            c.source ? "" : " source",
                                            c.segmenter ? "" : " segmenter", c.arm ? "" : " arm",
                                            c.planner ? "" : " planner", c.map ? "" : " map"));
  }
  AVP_RETURN_IF_ERROR(options.Validate());
  mapping::SemanticMap& map = *c.map;
  ViewFusion fusion(map, options);
  robot::Arm& arm = *c.arm;
  const Rng root(options.seed);

  EpisodeResult result;
  const auto t_episode = Clock::now();
  std::optional<MovingFusion> moving;
  if (options.motion_fusion.enabled) {
    moving.emplace(fusion, *c.segmenter, options, c.stop, observers);
  }
  const NextViewContext next{c,
                             options,
                             root.Fork("planner"),
                             root.Fork("arm"),
                             arm.CurrentJoints(),
                             arm.CurrentCameraPose(),
                             moving ? &*moving : nullptr};
  std::vector<RigidTransform> fused;
  if (c.motion != nullptr) {
    // A new episode: no map yet; where the arm stands is free.
    c.motion->checker().ClearMap();
    c.motion->checker().MarkStart(next.q_start);
    c.motion->checker().SetStartView(next.X_WC_start, options.roi);
    const double assumed = c.motion->checker().StartFreeDistance();
    result.start_clearance = {assumed, arm.TrueClearanceNow(assumed)};
  }

  int segment_failures_in_a_row = 0;
  // The episode's clock (frame stamps): view v at v seconds, plus the moves' durations when
  // frames are taken while moving (those frames are stamped along the move).
  int64_t moved_ns = 0;
  for (int view = 0; view < options.views; ++view) {
    if (c.stop.stop_requested()) {
      Interrupted(result, fmt::format("stop requested before view {}", view));
      break;
    }
    const auto t_step = Clock::now();
    StepRecord step;
    step.view = view;
    step.views_total = options.views;
    step.q = arm.CurrentJoints();
    step.X_WC = arm.CurrentCameraPose();
    ViewSeen seen;
    const int64_t stamp_ns = static_cast<int64_t>(view) * 1'000'000'000 + moved_ns;
    SenseAndFuse(c, fusion, view, stamp_ns, step, seen);
    fused.push_back(step.X_WC);
    if (metrics) {
      const auto t0 = Clock::now();
      step.metrics = metrics(map);
      step.times.metrics_ms = MsSince(t0);
    }
    // Plan and move, unless this was the last view, the capture or the segmentation was
    // cancelled, or the segmenter is gone.
    segment_failures_in_a_row = step.segment_status.ok() ? 0 : segment_failures_in_a_row + 1;
    const bool cancelled = step.capture_status.code() == StatusCode::kCancelled ||
                           step.segment_status.code() == StatusCode::kCancelled;
    if (cancelled) {
      Interrupted(result, step.capture_status.code() == StatusCode::kCancelled
                              ? step.capture_status.ToString()
                              : step.segment_status.ToString());
    }
    const bool stop =
        cancelled || SegmenterFault(step, segment_failures_in_a_row, options, result) ||
        (view + 1 < options.views && PlanAndMove(next, view, stamp_ns, fused, step, result, seen));
    if (step.motion_frames.streamed) moved_ns += std::llround(step.motion_frames.move_s * 1e9);
    step.times.total_ms = MsSince(t_step);
    result.steps.push_back(step);
    NotifyStep(observers, result.steps.back(), seen.Data(), map);
    if (stop) break;
  }
  ReturnHome(next, result);
  result.total_ms = MsSince(t_episode);
  NotifyEnd(observers, result, map);
  return result;
}

}  // namespace avp::pipeline

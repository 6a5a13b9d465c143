#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include <avp/core/options.h>
#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/motion/collision_checker.h>
#include <avp/robot/arm.h>

namespace avp::motion {

/// How moves are planned and timed (the run config's `motion.*`).
struct MotionOptions {
  /// Plan every move collision-free (avp live's default: a real arm). Off (the default in
  /// simulation: in the tomato scenarios most views are reachable only through space the camera
  /// has not seen, docs/motion.md "What it costs"): the arm is sent straight to each view's
  /// joints, unchecked (the paper's loop, where IK is the only filter); the simulator still
  /// counts what those moves touch.
  bool enabled = false;
  CollisionOptions collision;
  /// OMPL's RRT-Connect: stop after this many samples (deterministic: the same seed gives the
  /// same path on any machine), or after this wall time, a safety net far above what max_samples
  /// takes (a plan of 1000 samples takes about 0.15 s on one core): a plan it cuts is reported as
  /// a timeout, and the run no longer reproduces on another machine.
  int max_samples = 5000;
  double timeout_s = 5.0;
  /// RRT-Connect's step (joint space, radians); 0: OMPL's default (0.2 of the space's extent).
  double range_rad = 0.0;
  /// After the greedy vertex shortcuts, this many tries at a partial shortcut: two points drawn
  /// along the path (from the run's generator), joined straight when that segment is free
  /// (MoveIt's and OMPL's shortcutting, made reproducible). 0 (the default): vertex shortcuts
  /// only. At 100 the planned episodes' motion time falls 16-31 %, but one of 210 planned
  /// episodes touched a leaf 3 cm from the start camera, inside the free space assumed around
  /// the start (start_clearance_m and the field's rounding; docs/motion.md, "Shorter paths ...").
  int shortcut_tries = 0;
  /// Fractions of the joints' velocity (URDF) and acceleration (arm config) limits the
  /// trajectory uses.
  double velocity_scaling = 0.5;
  double acceleration_scaling = 0.5;
  /// Spacing of the trajectory's points in time (seconds); every vertex of the path is a point too.
  double sample_period_s = 0.1;
  /// An episode plans at most this many moves to ranked candidates after a view before it gives
  /// up (MoveIt's planning attempts): each failed plan costs up to timeout_s.
  int max_attempts = 5;
  /// A candidate view whose joints collide is moved back along its optical axis up to this far,
  /// to where its arm is free and its camera stands in seen free space
  /// (planning::PlanningRequest::collision_step_back_m); 0: dropped at once.
  double step_back_m = 0.3;

  Status Validate() const;
};
const OptionTable<MotionOptions>& MotionOptionTable();

/// A planned move.
struct MotionPlan {
  /// OK; InvalidArgument (a start or goal in collision, naming what it touches; joints outside
  /// the limits); DeadlineExceeded (no path within max_samples / timeout_s).
  Status status;
  /// Vertices of the collision-free joint path, start and goal included.
  std::vector<Eigen::VectorXd> path;
  robot::JointTrajectory trajectory;
  /// The straight joint line was free (no search was needed).
  bool straight = false;
  /// The straight line's verdict (what it would have hit).
  SegmentCheck straight_check;
  double planning_ms = 0.0;
  /// Σ |Δq| along the path (radians; metres for prismatic joints).
  double path_length = 0.0;
  /// Samples the search drew (0 when straight).
  int samples = 0;

  bool ok() const { return status.ok(); }
};

/// Plans collision-free joint motion: the straight joint-space line when it is free (checked at
/// the checker's max_step_m), else OMPL's RRT-Connect in the joint limits with a state sampler
/// drawing from the caller's generator (same seed, same path, on any machine), shortcut
/// deterministically and re-checked densely, then timed rest-to-rest per segment within the
/// velocity and acceleration limits (robot::TimeParameterize).
class MotionPlanner {
 public:
  /// `checker` must outlive the planner; the episode updates its map through checker().
  MotionPlanner(CollisionChecker& checker, MotionOptions options)
      : checker_(&checker), options_(std::move(options)) {}

  MotionPlan Plan(const Eigen::VectorXd& q_start, const Eigen::VectorXd& q_goal, Rng& rng) const;

  const MotionOptions& options() const { return options_; }
  CollisionChecker& checker() const { return *checker_; }

 private:
  CollisionChecker* checker_;
  MotionOptions options_;
};

}  // namespace avp::motion

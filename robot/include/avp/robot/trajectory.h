#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include <avp/core/status.h>
#include <avp/robot/arm_model.h>

namespace avp::robot {

/// One point of a joint trajectory (trajectory_msgs/JointTrajectoryPoint's fields avp uses).
struct TrajectoryPoint {
  Eigen::VectorXd q;   ///< positions, URDF convention (radians; metres for prismatic joints)
  Eigen::VectorXd qd;  ///< velocities (rad/s; m/s)
  double t_s = 0.0;    ///< time from the trajectory's start, seconds
};

/// A timed joint path: what an arm executes for one move (trajectory_msgs/JointTrajectory).
struct JointTrajectory {
  std::vector<std::string> joint_names;
  std::vector<TrajectoryPoint> points;

  bool empty() const { return points.empty(); }
  double duration_s() const { return points.empty() ? 0.0 : points.back().t_s; }
  /// Every point's time in whole nanoseconds, as trajectory_msgs carries it (TimeNs).
  std::vector<int64_t> times_ns() const;
  /// OK, or InvalidArgument naming the first bad point and value: at least two points for the
  /// model's joints (names and sizes), finite values within the limits, times starting at 0 and
  /// strictly increasing, speeds within the URDF's velocity limits (+1 %) where it has them.
  Status Validate(const ArmModel& arm) const;
};

/// A point's time from the start in whole nanoseconds, truncated as a JointTrajectoryPoint's
/// time_from_start carries it: what an arm receiving the trajectory over ROS 2 follows.
int64_t TimeNs(const TrajectoryPoint& point);

/// The joints `at_ns` after the start of a trajectory with points `q` at times `t_ns` (whole
/// nanoseconds, non-decreasing, t_ns[0] the first point's): linear between consecutive points
/// in time, as a joint trajectory controller interpolates; the first point's joints before it,
/// the last point's after it. @pre q and t_ns are non-empty and of the same size.
Eigen::VectorXd JointsAt(std::span<const Eigen::VectorXd> q, std::span<const int64_t> t_ns,
                         int64_t at_ns);

/// One frame a camera streaming at a fixed rate takes while the arm follows a trajectory.
struct FrameAlong {
  int index = 0;      ///< k >= 1: the k-th frame of the move
  int64_t t_ns = 0;   ///< round(k / rate) in nanoseconds from the move's start
  Eigen::VectorXd q;  ///< the joints then (JointsAt)
};

/// The times of the frames a camera streaming at `rate_hz` takes during a move of
/// `duration_ns`: t_k = round(k / rate_hz) in whole nanoseconds for k = 1, 2, ... while t_k is
/// before `duration_ns` (the move's start and its arrival are the views' own frames). The one
/// rule for FramesAlong and for `avp sim ros2`'s published frames, so that both see the same
/// poses. Empty for a rate <= 0 or not finite.
std::vector<int64_t> FrameTimesNs(int64_t duration_ns, double rate_hz);

/// The frames a camera streaming at `rate_hz` takes while the arm follows `trajectory`, in time
/// order: t_k = k / rate_hz (rounded to whole nanoseconds) for k = 1, 2, ... while t_k is
/// before the trajectory's last time (its start and its arrival are the views' own frames).
/// Fusion during motion (pipeline/motion_fusion.h) renders the simulator's frames there, and
/// `avp sim ros2` publishes its frames at the same times, so both see the same poses. Empty for
/// a rate <= 0 or not finite, or a trajectory of fewer than two points.
std::vector<FrameAlong> FramesAlong(const JointTrajectory& trajectory, double rate_hz);

/// Times the joint path `path` (vertices, start first) rest to rest: along each segment the
/// joints move together on a trapezoidal (or triangular) speed profile whose peak velocity and
/// acceleration keep every joint within velocity_scaling × its URDF velocity limit and
/// acceleration_scaling × arm.config().joint_acceleration_limit, stopping at each vertex, so the
/// trajectory never leaves the (collision-checked) polyline. Points every `sample_period_s`
/// plus every vertex. InvalidArgument for fewer than one vertex, wrong sizes, non-finite values,
/// scalings outside (0, 1], a period <= 0, or a moving joint without a velocity limit (naming
/// it). A single vertex (or repeated vertices) gives a trajectory of two points at t = 0 and a
/// tiny positive time.
Result<JointTrajectory> TimeParameterize(const ArmModel& arm,
                                         const std::vector<Eigen::VectorXd>& path,
                                         double velocity_scaling, double acceleration_scaling,
                                         double sample_period_s);

}  // namespace avp::robot

#pragma once

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
  /// OK, or InvalidArgument naming the first bad point and value: at least two points for the
  /// model's joints (names and sizes), finite values within the limits, times starting at 0 and
  /// strictly increasing, speeds within the URDF's velocity limits (+1 %) where it has them.
  Status Validate(const ArmModel& arm) const;
};

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

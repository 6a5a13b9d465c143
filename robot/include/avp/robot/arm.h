#pragma once

#include <utility>

#include <Eigen/Core>

#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/robot/arm_model.h>

namespace avp::robot {

/// Outcome of one motion request.
struct MoveResult {
  /// OK, or why the arm did not move (its state is then unchanged): InvalidArgument for a NaN or
  /// wrongly sized joint vector, OutOfRange for joints outside the limits, Unreachable when IK
  /// found no joints for a pose; implementations may add their own (a real arm: IoError, ...).
  Status status;
  /// Euclidean joint-space length |q_after − q_before| of this move (radians, metres for prismatic
  /// joints); 0 when refused.
  double joint_path_length = 0.0;
  /// The joints after the request (unchanged ones when refused).
  Eigen::VectorXd q;

  bool ok() const { return status.ok(); }
};

/// A robot arm carrying the camera: where it is and how to move it. Public methods validate and
/// are non-virtual; implementations override the protected Do* methods (NVI), which are only
/// called with validated, in-limit requests.
///
/// Implementations: sim::SimArm (teleports; tests and simulation). A real arm (ROS 2 / MoveIt)
/// is ros::live::Ros2Arm (ros/live/).
class Arm {
 public:
  virtual ~Arm() = default;
  Arm(const Arm&) = delete;
  Arm& operator=(const Arm&) = delete;

  /// The kinematic model (URDF chain, limits, camera mount, IK).
  const ArmModel& model() const { return model_; }

  /// Current joints, URDF convention.
  Eigen::VectorXd CurrentJoints() const { return DoCurrentJoints(); }
  /// Current camera optical frame pose X_WC (forward kinematics of CurrentJoints()).
  RigidTransform CurrentCameraPose() const { return model_.CameraPose(DoCurrentJoints()); }

  /// Moves to joint vector `q`. Refuses (status, state unchanged) a vector of the wrong size,
  /// with a NaN or infinite entry, or outside the limits; the status names the value.
  MoveResult MoveToJoints(const Eigen::VectorXd& q);
  /// Moves the camera to X_WC: IK seeded with the current joints (restarts drawn from `rng`), then
  /// MoveToJoints. Unreachable poses are refused with the IK status.
  MoveResult MoveToCameraPose(const RigidTransform& X_WC, Rng& rng);

  /// Statistics over this arm's lifetime: successful moves, their summed joint-space path length
  /// (radians; metres for prismatic joints), and refused requests.
  int num_moves() const { return num_moves_; }
  double total_joint_path_length() const { return total_joint_path_length_; }
  int num_refused_moves() const { return num_refused_moves_; }

 protected:
  explicit Arm(ArmModel model) : model_(std::move(model)) {}

  virtual Eigen::VectorXd DoCurrentJoints() const = 0;
  /// @pre `q` is within the limits. Returns the result of the motion (path length, final joints).
  virtual MoveResult DoMoveToJoints(const Eigen::VectorXd& q) = 0;

 private:
  MoveResult Record(MoveResult result);

  ArmModel model_;
  int num_moves_ = 0;
  double total_joint_path_length_ = 0.0;
  int num_refused_moves_ = 0;
};

}  // namespace avp::robot

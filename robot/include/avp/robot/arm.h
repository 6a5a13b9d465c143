#pragma once

#include <limits>
#include <optional>
#include <string>
#include <utility>

#include <Eigen/Core>

#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/robot/arm_model.h>
#include <avp/robot/trajectory.h>

namespace avp::robot {

/// Contacts between the arm (camera included) and the true world along one motion, as only a
/// simulator can count them. A contact is one interval of consecutive sampled states in which
/// one body of the arm touches one object; counts are by what was touched.
struct MotionContacts {
  int plant = 0;  ///< leaves and stems
  int fruit = 0;
  int support = 0;  ///< stakes, posts, wires, walls
  int ground = 0;
  int self = 0;  ///< two of the arm's own bodies (not in the allowed list)
  /// The first contact, for a person: "link_7 – leaf 'plant/leaf_3' at 42 % of the move".
  std::string first;

  int total() const { return plant + fruit + support + ground + self; }
  MotionContacts& operator+=(const MotionContacts& other);
};

/// How close the arm's moving bodies are to the true world at one state, as only a simulator
/// can measure (the start-clearance check, docs/motion.md).
struct TrueClearance {
  /// The smallest distance between a moving body and a scene object, metres (0 when they touch);
  /// +infinity when nothing is within the distance that was asked for.
  double distance_m = std::numeric_limits<double>::infinity();
  /// "flange/d435 – leaf 'tomato/leaf_11'" when distance_m is finite.
  std::string nearest;
};

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
  /// How long the motion took (seconds; a trajectory's duration); 0 when refused or unknown.
  double execution_s = 0.0;
  /// Contacts along the executed motion, where the arm can see the true world (a simulator).
  std::optional<MotionContacts> contacts;
  /// Contacts the straight joint-space line from the start to the end would have made (what a
  /// blind straight move hits), where the arm can see the true world.
  std::optional<MotionContacts> straight_line_contacts;

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
  /// Executes a timed joint path (from motion planning). Refuses (status, state unchanged) a
  /// trajectory that fails JointTrajectory::Validate or does not start within 1e-3 rad (or m) of
  /// the current joints, naming the value.
  MoveResult FollowTrajectory(const JointTrajectory& trajectory);
  /// Where the arm can see the true world (a simulator): how close its moving bodies are to it
  /// now, looking as far as `up_to_m`; nullopt where it cannot (a real arm).
  std::optional<TrueClearance> TrueClearanceNow(double up_to_m) const {
    return DoTrueClearanceNow(up_to_m);
  }

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
  /// @pre `trajectory` is valid and starts at the current joints. The default moves to its last
  /// point (DoMoveToJoints), for arms that cannot follow a trajectory; the path length is then
  /// the trajectory's and the execution time its duration.
  virtual MoveResult DoFollowTrajectory(const JointTrajectory& trajectory);
  /// The default: the true world is unknown.
  virtual std::optional<TrueClearance> DoTrueClearanceNow(double /*up_to_m*/) const {
    return std::nullopt;
  }

 private:
  MoveResult Record(MoveResult result);

  ArmModel model_;
  int num_moves_ = 0;
  double total_joint_path_length_ = 0.0;
  int num_refused_moves_ = 0;
};

}  // namespace avp::robot

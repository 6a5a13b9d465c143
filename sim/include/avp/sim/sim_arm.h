#pragma once

#include <memory>
#include <optional>

#include <Eigen/Core>

#include <avp/robot/arm.h>
#include <avp/robot/arm_model.h>
#include <avp/robot/trajectory.h>

namespace avp::sim {

class ContactCounter;

/// A kinematic arm that teleports: a move to any in-limit target succeeds at once, and its path
/// length is the straight joint-space distance.
///
/// With a contact counter (SetContactCounter), every move also reports the contacts the arm's
/// collision geometry made with the true scene (MoveResult::contacts): MoveToJoints moves along
/// the straight joint line, so both `contacts` and `straight_line_contacts` are those of that
/// line; FollowTrajectory moves along the trajectory's points (`contacts`: the polyline through
/// them; `straight_line_contacts`: the straight line from the start to its last point, what a
/// blind straight move would have hit). Contacts never stop a move: the simulator only counts
/// them. Without a counter both stay empty.
class SimArm final : public robot::Arm {
 public:
  /// Starts at model.home_joints().
  explicit SimArm(robot::ArmModel model);
  /// Starts at `q_initial`. @throws avp::Error if it is not valid for the model (the message
  /// names the bad joint and value).
  SimArm(robot::ArmModel model, const Eigen::VectorXd& q_initial);

  /// Counts contacts along every following move with `counter` (shared; a null pointer stops
  /// counting). The counter's robot must be this arm's (same joints): @throws avp::Error naming
  /// both joint counts otherwise.
  void SetContactCounter(std::shared_ptr<const ContactCounter> counter);
  const std::shared_ptr<const ContactCounter>& contact_counter() const { return counter_; }

 protected:
  Eigen::VectorXd DoCurrentJoints() const override { return q_; }
  robot::MoveResult DoMoveToJoints(const Eigen::VectorXd& q) override;
  /// Moves to the trajectory's last point at once; the path length is the summed |Δq| over its
  /// points and the execution time its duration (as robot::Arm's default), plus the contacts.
  robot::MoveResult DoFollowTrajectory(const robot::JointTrajectory& trajectory) override;
  /// With a contact counter: ContactCounter::NearestAt at the current joints.
  std::optional<robot::TrueClearance> DoTrueClearanceNow(double up_to_m) const override;

 private:
  Eigen::VectorXd q_;
  std::shared_ptr<const ContactCounter> counter_;
};

}  // namespace avp::sim

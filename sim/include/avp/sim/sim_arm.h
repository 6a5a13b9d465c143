#pragma once

#include <Eigen/Core>

#include <avp/robot/arm.h>
#include <avp/robot/arm_model.h>

namespace avp::sim {

/// A kinematic arm that teleports: a move to any in-limit target succeeds at once, and its path
/// length is the straight joint-space distance.
class SimArm final : public robot::Arm {
 public:
  /// Starts at model.home_joints().
  explicit SimArm(robot::ArmModel model);
  /// Starts at `q_initial`. @throws avp::Error if it is not valid for the model (the message
  /// names the bad joint and value).
  SimArm(robot::ArmModel model, const Eigen::VectorXd& q_initial);

 protected:
  Eigen::VectorXd DoCurrentJoints() const override { return q_; }
  robot::MoveResult DoMoveToJoints(const Eigen::VectorXd& q) override;

 private:
  Eigen::VectorXd q_;
};

}  // namespace avp::sim

#include <utility>

#include <avp/core/error.h>
#include <avp/sim/sim_arm.h>

namespace avp::sim {

SimArm::SimArm(robot::ArmModel model) : SimArm(model, model.home_joints()) {}

SimArm::SimArm(robot::ArmModel model, const Eigen::VectorXd& q_initial) : Arm(std::move(model)) {
  const Status s = this->model().CheckJoints(q_initial);
  AVP_THROW_UNLESS(s.ok(), s.message());
  q_ = q_initial;
}

robot::MoveResult SimArm::DoMoveToJoints(const Eigen::VectorXd& q) {
  robot::MoveResult result;
  result.joint_path_length = (q - q_).norm();
  q_ = q;
  result.q = q_;
  return result;
}

}  // namespace avp::sim

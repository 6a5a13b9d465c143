#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/sim/contact_counter.h>
#include <avp/sim/sim_arm.h>

namespace avp::sim {

SimArm::SimArm(robot::ArmModel model) : SimArm(model, model.home_joints()) {}

SimArm::SimArm(robot::ArmModel model, const Eigen::VectorXd& q_initial) : Arm(std::move(model)) {
  const Status s = this->model().CheckJoints(q_initial);
  AVP_THROW_UNLESS(s.ok(), s.message());
  q_ = q_initial;
}

void SimArm::SetContactCounter(std::shared_ptr<const ContactCounter> counter) {
  if (counter != nullptr) {
    const int counter_joints = counter->robot().arm().num_joints();
    if (counter_joints != model().num_joints()) {
      throw Error(
          fmt::format("SimArm::SetContactCounter: the counter's robot has {} joints, this arm {}",
                      counter_joints, model().num_joints()));
    }
  }
  counter_ = std::move(counter);
}

robot::MoveResult SimArm::DoMoveToJoints(const Eigen::VectorXd& q) {
  robot::MoveResult result;
  result.joint_path_length = (q - q_).norm();
  if (counter_ != nullptr) {
    result.contacts = counter_->CountAlong({q_, q});
    result.straight_line_contacts = result.contacts;
  }
  q_ = q;
  result.q = q_;
  return result;
}

std::optional<robot::TrueClearance> SimArm::DoTrueClearanceNow(double up_to_m) const {
  if (counter_ == nullptr) return std::nullopt;
  return counter_->NearestAt(q_, up_to_m);
}

robot::MoveResult SimArm::DoFollowTrajectory(const robot::JointTrajectory& trajectory) {
  robot::MoveResult result;
  const Eigen::VectorXd& q_end = trajectory.points.back().q;
  std::vector<Eigen::VectorXd> path;
  path.reserve(trajectory.points.size());
  for (size_t i = 0; i < trajectory.points.size(); ++i) {
    path.push_back(trajectory.points[i].q);
    if (i > 0) result.joint_path_length += (path[i] - path[i - 1]).norm();
  }
  result.execution_s = trajectory.duration_s();
  if (counter_ != nullptr) {
    result.contacts = counter_->CountAlong(path);
    result.straight_line_contacts = counter_->CountAlong({q_, q_end});
  }
  q_ = q_end;
  result.q = q_;
  return result;
}

}  // namespace avp::sim

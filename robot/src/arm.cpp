#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/robot/arm.h>

namespace avp::robot {

MotionContacts& MotionContacts::operator+=(const MotionContacts& other) {
  if (first.empty() && !other.first.empty()) first = other.first;
  plant += other.plant;
  fruit += other.fruit;
  support += other.support;
  ground += other.ground;
  self += other.self;
  return *this;
}

namespace {

MoveResult Refused(Status status) {
  MoveResult result;
  result.status = std::move(status);
  return result;
}

}  // namespace

MoveResult Arm::Record(MoveResult result) {
  if (result.ok()) {
    ++num_moves_;
    total_joint_path_length_ += result.joint_path_length;
  } else {
    ++num_refused_moves_;
    result.joint_path_length = 0.0;
    result.q = DoCurrentJoints();
  }
  return result;
}

MoveResult Arm::MoveToJoints(const Eigen::VectorXd& q) {
  if (const Status s = model_.CheckJoints(q); !s.ok()) {
    return Record(Refused(s.WithContext("MoveToJoints refused")));
  }
  return Record(DoMoveToJoints(q));
}

MoveResult Arm::MoveToCameraPose(const RigidTransform& X_WC, Rng& rng) {
  const IkResult ik = model_.SolveCameraIk(X_WC, DoCurrentJoints(), rng);
  if (!ik.ok()) {
    return Record(Refused(ik.status.WithContext("MoveToCameraPose refused")));
  }
  return MoveToJoints(ik.q);
}

MoveResult Arm::FollowTrajectory(const JointTrajectory& trajectory) {
  if (const Status s = trajectory.Validate(model_); !s.ok()) {
    return Record(Refused(s.WithContext("FollowTrajectory refused")));
  }
  const Eigen::VectorXd q = DoCurrentJoints();
  const Eigen::VectorXd& q0 = trajectory.points.front().q;
  const double offset = (q0 - q).cwiseAbs().maxCoeff();
  if (!(offset <= 1e-3)) {
    return Record(Refused(InvalidArgumentError(fmt::format(
        "FollowTrajectory refused: the trajectory starts {:.4g} rad from the current joints "
        "(at most 1e-3): starts at [{:.4f}], the arm is at [{:.4f}]",
        offset, fmt::join(q0, ", "), fmt::join(q, ", ")))));
  }
  return Record(DoFollowTrajectory(trajectory));
}

MoveResult Arm::DoFollowTrajectory(const JointTrajectory& trajectory) {
  MoveResult result = DoMoveToJoints(trajectory.points.back().q);
  if (!result.ok()) return result;
  double length = 0.0;
  for (size_t i = 1; i < trajectory.points.size(); ++i) {
    length += (trajectory.points[i].q - trajectory.points[i - 1].q).norm();
  }
  result.joint_path_length = length;
  result.execution_s = trajectory.duration_s();
  return result;
}

}  // namespace avp::robot

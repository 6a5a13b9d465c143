#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/robot/arm.h>

namespace avp::robot {

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
    return Record(MoveResult{s.WithContext("MoveToJoints refused"), 0.0, {}});
  }
  return Record(DoMoveToJoints(q));
}

MoveResult Arm::MoveToCameraPose(const RigidTransform& X_WC, Rng& rng) {
  const IkResult ik = model_.SolveCameraIk(X_WC, DoCurrentJoints(), rng);
  if (!ik.ok()) {
    return Record(MoveResult{ik.status.WithContext("MoveToCameraPose refused"), 0.0, {}});
  }
  return MoveToJoints(ik.q);
}

}  // namespace avp::robot

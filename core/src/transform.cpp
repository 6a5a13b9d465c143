#include <algorithm>
#include <cmath>
#include <ostream>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/core/transform.h>

namespace avp {

bool IsRotationMatrix(const Eigen::Matrix3d& R, double tolerance) {
  if (!R.allFinite()) return false;
  const double orthogonality =
      (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  return orthogonality <= tolerance && std::abs(R.determinant() - 1.0) <= tolerance;
}

RigidTransform::RigidTransform(const Eigen::Matrix3d& R, const Eigen::Vector3d& p) : R_(R), p_(p) {
  AVP_THROW_UNLESS(IsRotationMatrix(R, 1e-6), R.determinant(), R.row(0), R.row(1), R.row(2));
  AVP_THROW_UNLESS(p.allFinite(), p.transpose());
}

RigidTransform::RigidTransform(const Eigen::Quaterniond& q, const Eigen::Vector3d& p) : p_(p) {
  AVP_THROW_UNLESS(std::isfinite(q.norm()) && q.norm() > 1e-9, q.coeffs().transpose());
  AVP_THROW_UNLESS(p.allFinite(), p.transpose());
  R_ = q.normalized().toRotationMatrix();
}

RigidTransform RigidTransform::FromRpy(double roll, double pitch, double yaw,
                                       const Eigen::Vector3d& p) {
  AVP_THROW_UNLESS(std::isfinite(roll) && std::isfinite(pitch) && std::isfinite(yaw), roll, pitch,
                   yaw);
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  return RigidTransform(R, p);
}

RigidTransform RigidTransform::FromMatrix4(const Eigen::Matrix4d& X) {
  const Eigen::RowVector4d last = X.row(3);
  AVP_THROW_UNLESS(last.isApprox(Eigen::RowVector4d(0, 0, 0, 1), 1e-9), last);
  return RigidTransform(Eigen::Matrix3d(X.topLeftCorner<3, 3>()),
                        Eigen::Vector3d(X.topRightCorner<3, 1>()));
}

RigidTransform RigidTransform::LookAt(const Eigen::Vector3d& p_WEye,
                                      const Eigen::Vector3d& p_WTarget,
                                      const Eigen::Vector3d& up_W) {
  const Eigen::Vector3d forward = p_WTarget - p_WEye;
  const double distance = forward.norm();
  AVP_THROW_UNLESS(distance > 1e-9, p_WEye.transpose(), p_WTarget.transpose());
  const Eigen::Vector3d z = forward / distance;
  Eigen::Vector3d x = z.cross(up_W);  // image right = forward x up (= down x forward)
  const double x_norm = x.norm();
  AVP_THROW_UNLESS(x_norm > 1e-9, z.transpose(), up_W.transpose());
  x /= x_norm;
  const Eigen::Vector3d y = z.cross(x);  // image down
  Eigen::Matrix3d R;
  R.col(0) = x;
  R.col(1) = y;
  R.col(2) = z;
  return RigidTransform(R, p_WEye);
}

Eigen::Vector3d RigidTransform::rpy() const {
  // Inverse of R = Rz(yaw) Ry(pitch) Rx(roll). Roll from the last row, then yaw from
  // N = R Rx(-roll) = Rz(yaw) Ry(pitch): every atan2 sees O(1) arguments, so FromRpy(rpy())
  // reproduces R to rounding error even at and near gimbal lock (asin(-R20) and a cos(pitch)
  // threshold lost up to ~1e-8 rad there). At exact gimbal lock roll is 0 and yaw takes the rest.
  const double c_pitch = std::hypot(R_(2, 1), R_(2, 2));
  const double roll = c_pitch > 0.0 ? std::atan2(R_(2, 1), R_(2, 2)) : 0.0;
  const double pitch = std::atan2(-R_(2, 0), c_pitch);
  const double c = std::cos(roll);
  const double s = std::sin(roll);
  const double yaw = std::atan2(-(R_(0, 1) * c - R_(0, 2) * s), R_(1, 1) * c - R_(1, 2) * s);
  return {roll, pitch, yaw};
}

Eigen::Matrix4d RigidTransform::ToMatrix4() const {
  Eigen::Matrix4d X = Eigen::Matrix4d::Identity();
  X.topLeftCorner<3, 3>() = R_;
  X.topRightCorner<3, 1>() = p_;
  return X;
}

Eigen::Isometry3d RigidTransform::ToIsometry() const {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = R_;
  X.translation() = p_;
  return X;
}

double RigidTransform::AngleTo(const RigidTransform& other) const {
  // atan2(sin, cos) keeps full precision near 0 and pi, where acos((trace - 1) / 2) alone
  // resolves only ~1e-8 rad.
  const Eigen::Matrix3d R_rel = R_.transpose() * other.R_;
  const Eigen::Vector3d two_sin_axis(R_rel(2, 1) - R_rel(1, 2), R_rel(0, 2) - R_rel(2, 0),
                                     R_rel(1, 0) - R_rel(0, 1));
  return std::atan2(0.5 * two_sin_axis.norm(), 0.5 * (R_rel.trace() - 1.0));
}

std::string RigidTransform::ToString() const {
  // Adding 0.0 prints -0 as 0.
  const Eigen::Vector3d e = rpy().array() + 0.0;
  const Eigen::Vector3d p = p_.array() + 0.0;
  return fmt::format("xyz [{:.6g}, {:.6g}, {:.6g}] m, rpy [{:.6g}, {:.6g}, {:.6g}] rad", p.x(),
                     p.y(), p.z(), e.x(), e.y(), e.z());
}

std::ostream& operator<<(std::ostream& os, const RigidTransform& X) { return os << X.ToString(); }

}  // namespace avp

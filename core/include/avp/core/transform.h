#pragma once

#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace avp {

/// A rigid transform (rotation + translation), named after the frames it relates, as in Drake:
/// `X_WC` is the pose of frame C measured in frame W, so `p_W = X_WC * p_C` and
/// `X_WB = X_WA * X_AB`. Units: metres and radians.
class RigidTransform {
 public:
  /// Identity.
  RigidTransform() : R_(Eigen::Matrix3d::Identity()), p_(Eigen::Vector3d::Zero()) {}
  /// @pre `R` is a rotation matrix (orthonormal, det = +1); checked with AVP_THROW_UNLESS.
  RigidTransform(const Eigen::Matrix3d& R, const Eigen::Vector3d& p);
  RigidTransform(const Eigen::Quaterniond& q, const Eigen::Vector3d& p);
  explicit RigidTransform(const Eigen::Vector3d& p) : R_(Eigen::Matrix3d::Identity()), p_(p) {}

  static RigidTransform Identity() { return {}; }
  /// From roll-pitch-yaw (URDF convention: R = Rz(yaw) * Ry(pitch) * Rx(roll)) and a translation.
  static RigidTransform FromRpy(double roll, double pitch, double yaw, const Eigen::Vector3d& p);
  static RigidTransform FromRpy(const Eigen::Vector3d& rpy, const Eigen::Vector3d& p) {
    return FromRpy(rpy.x(), rpy.y(), rpy.z(), p);
  }
  /// @pre `X` is a homogeneous rigid transform (last row 0 0 0 1, orthonormal rotation).
  static RigidTransform FromMatrix4(const Eigen::Matrix4d& X);

  /// The pose of a camera optical frame (z forward, x right, y down) at `p_WEye` looking at
  /// `p_WTarget`, with the image "up" (−y) as close as possible to `up_W`.
  /// @throws avp::Error if eye and target coincide or the view direction is parallel to `up_W`.
  static RigidTransform LookAt(const Eigen::Vector3d& p_WEye, const Eigen::Vector3d& p_WTarget,
                               const Eigen::Vector3d& up_W = Eigen::Vector3d::UnitZ());

  const Eigen::Matrix3d& rotation() const { return R_; }
  const Eigen::Vector3d& translation() const { return p_; }
  Eigen::Quaterniond quaternion() const { return Eigen::Quaterniond(R_); }
  /// Roll, pitch, yaw with the URDF convention of FromRpy.
  Eigen::Vector3d rpy() const;
  Eigen::Matrix4d ToMatrix4() const;
  Eigen::Isometry3d ToIsometry() const;

  RigidTransform inverse() const { return {R_.transpose(), -(R_.transpose() * p_), Unchecked{}}; }

  RigidTransform operator*(const RigidTransform& other) const {
    return {R_ * other.R_, R_ * other.p_ + p_, Unchecked{}};
  }
  Eigen::Vector3d operator*(const Eigen::Vector3d& p) const { return R_ * p + p_; }

  /// Translation distance in metres.
  double TranslationDistanceTo(const RigidTransform& other) const { return (p_ - other.p_).norm(); }
  /// Angle in radians of the relative rotation R_this^T R_other, in [0, pi].
  double AngleTo(const RigidTransform& other) const;

  bool IsNearlyEqualTo(const RigidTransform& other, double tolerance_m,
                       double tolerance_rad) const {
    return TranslationDistanceTo(other) <= tolerance_m && AngleTo(other) <= tolerance_rad;
  }

  /// "xyz [0.1, 0.2, 0.3] m, rpy [0, 0, 1.5708] rad"
  std::string ToString() const;

 private:
  struct Unchecked {};
  RigidTransform(const Eigen::Matrix3d& R, const Eigen::Vector3d& p, Unchecked) : R_(R), p_(p) {}

  Eigen::Matrix3d R_;
  Eigen::Vector3d p_;
};

std::ostream& operator<<(std::ostream& os, const RigidTransform& X);

/// True when `R` is orthonormal with determinant +1 within `tolerance`.
bool IsRotationMatrix(const Eigen::Matrix3d& R, double tolerance = 1e-6);

inline double DegToRad(double deg) { return deg * (EIGEN_PI / 180.0); }
inline double RadToDeg(double rad) { return rad * (180.0 / EIGEN_PI); }

}  // namespace avp

#include "avp/ros/msg/convert.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <fmt/format.h>

namespace avp::ros::msg {
namespace {

Result<RigidTransform> FromParts(const Point& p, const Quaternion& q, std::string_view what) {
  const double values[] = {p.x, p.y, p.z, q.x, q.y, q.z, q.w};
  for (const double v : values) {
    if (!std::isfinite(v)) {
      return InvalidArgumentError(fmt::format(
          "{} has a non-finite value: position ({}, {}, {}), quaternion (x {}, y {}, z {}, w {})",
          what, p.x, p.y, p.z, q.x, q.y, q.z, q.w));
    }
  }
  Eigen::Quaterniond eq(q.w, q.x, q.y, q.z);
  const double norm = eq.norm();
  if (norm < 1e-6) {
    return InvalidArgumentError(
        fmt::format("{} has a quaternion of norm {} (x {}, y {}, z {}, w {}); it must not be zero",
                    what, norm, q.x, q.y, q.z, q.w));
  }
  eq.coeffs() /= norm;
  return RigidTransform(eq.toRotationMatrix(), Eigen::Vector3d(p.x, p.y, p.z));
}

}  // namespace

Quaternion ToQuaternionMsg(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  return Quaternion{q.x(), q.y(), q.z(), q.w()};
}

Pose ToPoseMsg(const RigidTransform& X_AB) {
  return Pose{ToPointMsg(X_AB.translation()), ToQuaternionMsg(X_AB.rotation())};
}

Transform ToTransformMsg(const RigidTransform& X_AB) {
  return Transform{ToVector3Msg(X_AB.translation()), ToQuaternionMsg(X_AB.rotation())};
}

Result<RigidTransform> FromPoseMsg(const Pose& pose) {
  return FromParts(pose.position, pose.orientation, "geometry_msgs/msg/Pose");
}

Result<RigidTransform> FromTransformMsg(const Transform& transform) {
  const Point p{transform.translation.x, transform.translation.y, transform.translation.z};
  return FromParts(p, transform.rotation, "geometry_msgs/msg/Transform");
}

Point ToPointMsg(const Eigen::Vector3d& p) { return Point{p.x(), p.y(), p.z()}; }
Eigen::Vector3d FromPointMsg(const Point& p) { return {p.x, p.y, p.z}; }
Vector3 ToVector3Msg(const Eigen::Vector3d& v) { return Vector3{v.x(), v.y(), v.z()}; }
Eigen::Vector3d FromVector3Msg(const Vector3& v) { return {v.x, v.y, v.z}; }

std::string FormatStamp(int64_t ns) {
  int64_t s = ns / 1'000'000'000;
  int64_t rest = ns % 1'000'000'000;
  if (rest < 0) {
    --s;
    rest += 1'000'000'000;
  }
  return fmt::format("{}.{:09d}", s, rest);
}

ColorRGBA Rgba(double r, double g, double b, double a) {
  return {static_cast<float>(r), static_cast<float>(g), static_cast<float>(b),
          static_cast<float>(a)};
}

ColorRGBA Viridis(double t) {
  static constexpr std::array<std::array<double, 3>, 5> kStops = {{{0.267, 0.005, 0.329},
                                                                   {0.229, 0.322, 0.546},
                                                                   {0.128, 0.567, 0.551},
                                                                   {0.369, 0.789, 0.383},
                                                                   {0.993, 0.906, 0.144}}};
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0) * 4.0;
  const size_t i = std::min<size_t>(static_cast<size_t>(t), 3);
  const double f = t - static_cast<double>(i);
  const auto& a = kStops[i];
  const auto& b = kStops[i + 1];
  return Rgba(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]));
}

}  // namespace avp::ros::msg

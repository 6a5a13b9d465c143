#pragma once

// Conversions between avp's core types and ROS 2 messages.

#include <cstdint>
#include <string>

#include <Eigen/Core>

#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::msg {

/// X_AB as a Pose (position = p_AB, orientation = R_AB), the quaternion unit length with w >= 0.
Pose ToPoseMsg(const RigidTransform& X_AB);
/// X_AB as a Transform (translation = p_AB, rotation = R_AB), the quaternion as in ToPoseMsg.
Transform ToTransformMsg(const RigidTransform& X_AB);

/// A Pose / Transform from a peer as a RigidTransform. The quaternion is normalised;
/// InvalidArgument when a value is not finite or the quaternion's norm is below 1e-6 (an all-zero
/// quaternion, which some publishers send for "unset").
Result<RigidTransform> FromPoseMsg(const Pose& pose);
Result<RigidTransform> FromTransformMsg(const Transform& transform);

Point ToPointMsg(const Eigen::Vector3d& p);
Eigen::Vector3d FromPointMsg(const Point& p);
Vector3 ToVector3Msg(const Eigen::Vector3d& v);
Eigen::Vector3d FromVector3Msg(const Vector3& v);
/// Unit quaternion with w >= 0.
Quaternion ToQuaternionMsg(const Eigen::Matrix3d& R);

/// A stamp in nanoseconds since the epoch (avp's clocks) as a Time, and back
/// (Time::FromNanoseconds / ToNanoseconds).
inline Time ToTimeMsg(int64_t stamp_ns) { return Time::FromNanoseconds(stamp_ns); }
inline int64_t FromTimeMsg(const Time& t) { return t.ToNanoseconds(); }
/// A stamp as "sec.nanosec" for messages: the seconds floored, the nanoseconds in [0, 1e9) (1 ns
/// before the epoch is "-1.999999999").
std::string FormatStamp(int64_t stamp_ns);

/// A marker colour from doubles in [0, 1].
ColorRGBA Rgba(double r, double g, double b, double a = 1.0);
/// Viridis at t in [0, 1] (five-stop piecewise-linear approximation; NaN reads 0, t is clamped):
/// the colour scale of utilities and confidences in RViz markers and recordings.
ColorRGBA Viridis(double t);

}  // namespace avp::ros::msg

#pragma once

#include <limits>

#include <Eigen/Core>

namespace avp {

/// A ray p(t) = origin + t * direction for t in [t_min, t_max]. `direction` is unit length when
/// built with Ray::Between or Ray::FromDirection, so t is then a distance in metres.
struct Ray {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();
  double t_min = 0.0;
  double t_max = std::numeric_limits<double>::infinity();

  Eigen::Vector3d At(double t) const { return origin + t * direction; }

  /// The segment from `from` to `to` (t in [0, |to - from|]).
  static Ray Between(const Eigen::Vector3d& from, const Eigen::Vector3d& to);
  /// A ray along the normalised `direction`, up to `max_distance` metres.
  static Ray FromDirection(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                           double max_distance = std::numeric_limits<double>::infinity());
};

}  // namespace avp

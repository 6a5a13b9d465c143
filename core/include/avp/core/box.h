#pragma once

#include <limits>
#include <optional>
#include <string>

#include <Eigen/Core>

#include <avp/core/ray.h>

namespace avp {

/// An axis-aligned box [min, max] in metres. A default-constructed box is empty.
class Box3 {
 public:
  Box3()
      : min_(Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity())),
        max_(Eigen::Vector3d::Constant(-std::numeric_limits<double>::infinity())) {}
  /// @pre min <= max component-wise (checked).
  Box3(const Eigen::Vector3d& min, const Eigen::Vector3d& max);
  static Box3 FromCenterAndHalfSize(const Eigen::Vector3d& center, const Eigen::Vector3d& half);

  const Eigen::Vector3d& min() const { return min_; }
  const Eigen::Vector3d& max() const { return max_; }
  bool IsEmpty() const { return (min_.array() > max_.array()).any(); }
  Eigen::Vector3d center() const { return 0.5 * (min_ + max_); }
  Eigen::Vector3d size() const {
    return IsEmpty() ? Eigen::Vector3d::Zero() : Eigen::Vector3d(max_ - min_);
  }
  double Volume() const { return size().prod(); }

  bool Contains(const Eigen::Vector3d& p) const {
    return (p.array() >= min_.array()).all() && (p.array() <= max_.array()).all();
  }
  bool Intersects(const Box3& other) const {
    return !IsEmpty() && !other.IsEmpty() && (min_.array() <= other.max_.array()).all() &&
           (other.min_.array() <= max_.array()).all();
  }
  void Extend(const Eigen::Vector3d& p) {
    min_ = min_.cwiseMin(p);
    max_ = max_.cwiseMax(p);
  }
  void Extend(const Box3& other) {
    if (other.IsEmpty()) return;
    Extend(other.min_);
    Extend(other.max_);
  }
  /// Grown by `margin` on every side (shrunk if negative; may become empty).
  Box3 Inflated(double margin) const;
  Box3 Intersection(const Box3& other) const;

  /// Slab test: the parameter interval [t_enter, t_exit] of `ray` inside the box, clipped to
  /// [ray.t_min, ray.t_max]; nullopt if the ray misses.
  std::optional<std::pair<double, double>> Intersect(const Ray& ray) const;

  std::string ToString() const;

 private:
  Eigen::Vector3d min_;
  Eigen::Vector3d max_;
};

}  // namespace avp

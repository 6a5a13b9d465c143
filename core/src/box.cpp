#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include <avp/core/box.h>
#include <avp/core/error.h>

namespace avp {

Box3::Box3(const Eigen::Vector3d& min, const Eigen::Vector3d& max) : min_(min), max_(max) {
  AVP_THROW_UNLESS(min.allFinite() && max.allFinite(), min.transpose(), max.transpose());
  AVP_THROW_UNLESS((min.array() <= max.array()).all(), min.transpose(), max.transpose());
}

Box3 Box3::FromCenterAndHalfSize(const Eigen::Vector3d& center, const Eigen::Vector3d& half) {
  AVP_THROW_UNLESS((half.array() >= 0.0).all(), half.transpose());
  return {center - half, center + half};
}

Box3 Box3::Inflated(double margin) const {
  if (IsEmpty()) return *this;
  Box3 out;
  out.min_ = min_.array() - margin;
  out.max_ = max_.array() + margin;
  return out;
}

Box3 Box3::Intersection(const Box3& other) const {
  Box3 out;
  out.min_ = min_.cwiseMax(other.min_);
  out.max_ = max_.cwiseMin(other.max_);
  return out;
}

std::optional<std::pair<double, double>> Box3::Intersect(const Ray& ray) const {
  if (IsEmpty()) return std::nullopt;
  double t0 = ray.t_min;
  double t1 = ray.t_max;
  for (int k = 0; k < 3; ++k) {
    const double d = ray.direction[k];
    const double o = ray.origin[k];
    if (std::abs(d) < 1e-300) {
      if (o < min_[k] || o > max_[k]) return std::nullopt;
      continue;
    }
    double ta = (min_[k] - o) / d;
    double tb = (max_[k] - o) / d;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return std::nullopt;
  }
  return std::make_pair(t0, t1);
}

std::string Box3::ToString() const {
  if (IsEmpty()) return "[empty box]";
  return fmt::format("[({:.4g}, {:.4g}, {:.4g}) .. ({:.4g}, {:.4g}, {:.4g})] m", min_.x(), min_.y(),
                     min_.z(), max_.x(), max_.y(), max_.z());
}

Ray Ray::Between(const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  const Eigen::Vector3d d = to - from;
  const double length = d.norm();
  AVP_THROW_UNLESS(length > 0.0 && std::isfinite(length), from.transpose(), to.transpose());
  return Ray{from, d / length, 0.0, length};
}

Ray Ray::FromDirection(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                       double max_distance) {
  const double n = direction.norm();
  AVP_THROW_UNLESS(n > 0.0 && std::isfinite(n), direction.transpose());
  AVP_THROW_UNLESS(origin.allFinite(), origin.transpose());
  AVP_THROW_UNLESS(max_distance > 0.0, max_distance);
  return Ray{origin, direction / n, 0.0, max_distance};
}

}  // namespace avp

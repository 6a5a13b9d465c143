#pragma once

#include <array>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/camera.h>
#include <avp/core/transform.h>

namespace avp {

/// The viewing volume of a pinhole camera between its min and max depth, in the world frame:
/// six inward-facing planes n . p + d >= 0 (near, far, left, right, top, bottom).
class Frustum {
 public:
  Frustum(const CameraIntrinsics& K, const RigidTransform& X_WC);

  /// True if p_W is inside (or on) all six planes.
  bool Contains(const Eigen::Vector3d& p_W) const;
  /// Conservative box test: false only if the box lies entirely outside one plane.
  bool MayIntersect(const Box3& box_W) const;
  /// The eight corners in the world frame: near (tl, tr, br, bl), then far (tl, tr, br, bl).
  const std::array<Eigen::Vector3d, 8>& corners() const { return corners_W_; }
  Box3 BoundingBox() const;

 private:
  std::array<Eigen::Vector4d, 6> planes_W_;
  std::array<Eigen::Vector3d, 8> corners_W_;
};

}  // namespace avp

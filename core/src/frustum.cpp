#include <avp/core/error.h>
#include <avp/core/frustum.h>

namespace avp {

Frustum::Frustum(const CameraIntrinsics& K, const RigidTransform& X_WC) {
  const Status status = K.Validate();
  AVP_THROW_UNLESS(status.ok(), status.message());
  const std::array<Eigen::Vector2d, 4> image_corners = {
      Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(K.width - 0.5, -0.5),
      Eigen::Vector2d(K.width - 0.5, K.height - 0.5), Eigen::Vector2d(-0.5, K.height - 0.5)};
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector3d dir_C = K.RayDirection(image_corners[i]);
    corners_W_[i] = X_WC * (dir_C * K.min_depth_m);
    corners_W_[i + 4] = X_WC * (dir_C * K.max_depth_m);
  }
  const Eigen::Vector3d origin = X_WC.translation();
  const Eigen::Vector3d forward = X_WC.rotation().col(2);
  auto plane = [](const Eigen::Vector3d& n, const Eigen::Vector3d& p) {
    const Eigen::Vector3d unit = n.normalized();
    return Eigen::Vector4d(unit.x(), unit.y(), unit.z(), -unit.dot(p));
  };
  planes_W_[0] = plane(forward, corners_W_[0]);
  planes_W_[1] = plane(-forward, corners_W_[4]);
  // Side planes through the optical centre; the normal points inside (towards the optical axis).
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector3d a = corners_W_[4 + i] - origin;
    const Eigen::Vector3d b = corners_W_[4 + (i + 1) % 4] - origin;
    const Eigen::Vector3d axis_point =
        X_WC * Eigen::Vector3d(0, 0, 0.5 * (K.min_depth_m + K.max_depth_m));
    Eigen::Vector4d pl = plane(a.cross(b), origin);
    if (pl.head<3>().dot(axis_point) + pl.w() < 0.0) pl = -pl;  // normal points inside
    planes_W_[2 + i] = pl;
  }
}

bool Frustum::Contains(const Eigen::Vector3d& p_W) const {
  for (const Eigen::Vector4d& pl : planes_W_) {
    if (pl.head<3>().dot(p_W) + pl.w() < -1e-12) return false;
  }
  return true;
}

bool Frustum::MayIntersect(const Box3& box_W) const {
  if (box_W.IsEmpty()) return false;
  for (const Eigen::Vector4d& pl : planes_W_) {
    // The box corner furthest along the plane normal.
    Eigen::Vector3d p;
    for (int k = 0; k < 3; ++k) p[k] = pl[k] >= 0.0 ? box_W.max()[k] : box_W.min()[k];
    if (pl.head<3>().dot(p) + pl.w() < 0.0) return false;
  }
  return true;
}

Box3 Frustum::BoundingBox() const {
  Box3 box;
  for (const Eigen::Vector3d& c : corners_W_) box.Extend(c);
  return box;
}

}  // namespace avp

#include <cmath>
#include <vector>

#include <fmt/format.h>

#include <avp/core/camera.h>
#include <avp/core/error.h>

namespace avp {

CameraIntrinsics CameraIntrinsics::FromHorizontalFov(int width, int height, double fov_x_deg,
                                                     double min_depth_m, double max_depth_m) {
  AVP_THROW_UNLESS(width > 0 && height > 0, width, height);
  AVP_THROW_UNLESS(fov_x_deg > 0.0 && fov_x_deg < 180.0, fov_x_deg);
  CameraIntrinsics K;
  K.width = width;
  K.height = height;
  K.fx = K.fy = 0.5 * width / std::tan(0.5 * fov_x_deg * EIGEN_PI / 180.0);
  K.cx = 0.5 * (width - 1);
  K.cy = 0.5 * (height - 1);
  K.min_depth_m = min_depth_m;
  K.max_depth_m = max_depth_m;
  return K;
}

CameraIntrinsics CameraIntrinsics::RealSenseD435() {
  CameraIntrinsics K;
  K.width = 640;
  K.height = 480;
  K.fx = K.fy = 615.0;
  K.cx = 319.5;
  K.cy = 239.5;
  K.min_depth_m = 0.1;
  K.max_depth_m = 3.0;
  return K;
}

Status CameraIntrinsics::Validate() const {
  std::vector<std::string> errors;
  auto require = [&](bool ok, std::string message) {
    if (!ok) errors.push_back(std::move(message));
  };
  require(width > 0, fmt::format("width ({}) must be > 0", width));
  require(height > 0, fmt::format("height ({}) must be > 0", height));
  require(std::isfinite(fx) && fx > 0, fmt::format("fx ({}) must be finite and > 0", fx));
  require(std::isfinite(fy) && fy > 0, fmt::format("fy ({}) must be finite and > 0", fy));
  require(std::isfinite(cx), fmt::format("cx ({}) must be finite", cx));
  require(std::isfinite(cy), fmt::format("cy ({}) must be finite", cy));
  require(std::isfinite(min_depth_m) && min_depth_m >= 0,
          fmt::format("min_depth_m ({}) must be finite and >= 0", min_depth_m));
  require(std::isfinite(max_depth_m) && max_depth_m > min_depth_m,
          fmt::format("max_depth_m ({}) must be finite and > min_depth_m ({})", max_depth_m,
                      min_depth_m));
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError("invalid camera intrinsics: " +
                              fmt::format("{}", fmt::join(errors, "; ")));
}

double CameraIntrinsics::fov_x_deg() const {
  return 2.0 * std::atan(0.5 * width / fx) * 180.0 / EIGEN_PI;
}
double CameraIntrinsics::fov_y_deg() const {
  return 2.0 * std::atan(0.5 * height / fy) * 180.0 / EIGEN_PI;
}

std::optional<Eigen::Vector2d> CameraIntrinsics::Project(const Eigen::Vector3d& p_C) const {
  if (!(p_C.z() > 0.0)) return std::nullopt;
  return Eigen::Vector2d(fx * p_C.x() / p_C.z() + cx, fy * p_C.y() / p_C.z() + cy);
}

bool CameraIntrinsics::IsInImage(const Eigen::Vector2d& uv) const {
  return uv.x() >= -0.5 && uv.x() < width - 0.5 && uv.y() >= -0.5 && uv.y() < height - 0.5;
}

Eigen::Vector3d CameraIntrinsics::BackProject(const Eigen::Vector2d& uv, double depth_m) const {
  return RayDirection(uv) * depth_m;
}

Eigen::Vector3d CameraIntrinsics::RayDirection(const Eigen::Vector2d& uv) const {
  return {(uv.x() - cx) / fx, (uv.y() - cy) / fy, 1.0};
}

Eigen::Matrix3d CameraIntrinsics::K() const {
  Eigen::Matrix3d K;
  K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return K;
}

CameraIntrinsics CameraIntrinsics::Scaled(double factor) const {
  AVP_THROW_UNLESS(std::isfinite(factor) && factor > 0.0, factor);
  CameraIntrinsics out = *this;
  out.width = static_cast<int>(std::lround(width * factor));
  out.height = static_cast<int>(std::lround(height * factor));
  out.fx = fx * factor;
  out.fy = fy * factor;
  // Pixel centres at integers: the image edge -0.5 maps to -0.5.
  out.cx = (cx + 0.5) * factor - 0.5;
  out.cy = (cy + 0.5) * factor - 0.5;
  return out;
}

std::string ToString(const CameraIntrinsics& K) {
  return fmt::format("{}x{} fx={:.3f} fy={:.3f} cx={:.3f} cy={:.3f} range=[{}, {}] m", K.width,
                     K.height, K.fx, K.fy, K.cx, K.cy, K.min_depth_m, K.max_depth_m);
}

}  // namespace avp

#include <cmath>
#include <utility>
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

namespace {
/// Focal lengths and principal points a camera can have, in pixels.
constexpr double kMinFocalPx = 1e-2;
constexpr double kMaxFocalPx = 1e6;
constexpr double kMaxPrincipalPx = 1e6;
}  // namespace

const OptionTable<CameraIntrinsics>& CameraIntrinsicsTable() {
  static const auto* table = [] {
    using K = CameraIntrinsics;
    auto* t = new OptionTable<K>("camera intrinsic");
    t->Integer("width", &K::width, "", ValueRange::Above(0), "image width");
    t->Integer("height", &K::height, "", ValueRange::Above(0), "image height");
    t->Real("fx", &K::fx, "", ValueRange::Above(0), "focal length along x");
    t->Real("fy", &K::fy, "", ValueRange::Above(0), "focal length along y");
    t->Real("cx", &K::cx, "", ValueRange::Any(), "principal point x (pixel centres)");
    t->Real("cy", &K::cy, "", ValueRange::Any(), "principal point y");
    t->Real("min_depth_m", &K::min_depth_m, "m", ValueRange::AtLeast(0), "nearest valid depth");
    t->Real("max_depth_m", &K::max_depth_m, "m", ValueRange::Any(),
            "farthest valid depth (> min_depth_m)");
    t->AddRule([](const K& k, std::vector<std::string>& errors) {
      // Finite values past bounds no camera reaches (a crop's principal point may lie outside its
      // window, so they are absolute): past them a value is a unit or field mix-up that would make
      // every ray degenerate or overflow.
      for (const auto& [name, f] : {std::pair{"fx", k.fx}, std::pair{"fy", k.fy}}) {
        if (std::isfinite(f) && f > 0 && !(f >= kMinFocalPx && f <= kMaxFocalPx)) {
          errors.push_back(fmt::format("{} ({:.6g} px) must be in [{:g}, {:g}] px", name, f,
                                       kMinFocalPx, kMaxFocalPx));
        }
      }
      for (const auto& [name, c] : {std::pair{"cx", k.cx}, std::pair{"cy", k.cy}}) {
        if (std::isfinite(c) && std::abs(c) > kMaxPrincipalPx) {
          errors.push_back(fmt::format("{} ({:.6g} px) must be in [-{:g}, {:g}] px", name, c,
                                       kMaxPrincipalPx, kMaxPrincipalPx));
        }
      }
      if (!(std::isfinite(k.max_depth_m) && k.max_depth_m > k.min_depth_m)) {
        errors.push_back(fmt::format("max_depth_m ({}) must be finite and > min_depth_m ({})",
                                     k.max_depth_m, k.min_depth_m));
      }
    });
    return t;
  }();
  return *table;
}

Status CameraIntrinsics::Validate() const { return CameraIntrinsicsTable().Validate(*this); }

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

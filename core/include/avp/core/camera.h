#pragma once

#include <optional>
#include <string>

#include <Eigen/Core>

#include <avp/core/options.h>
#include <avp/core/status.h>

namespace avp {

/// Pinhole intrinsics of an undistorted camera (depth aligned to colour).
///
/// Pixel convention (OpenCV / ROS `CameraInfo`): pixel (u, v) is column u, row v, counted from the
/// top-left; its *centre* has continuous coordinates (u, v), so the image spans [-0.5, width - 0.5]
/// and a centred principal point is cx = (width - 1) / 2. A point p_C = (x, y, z) in the camera
/// optical frame (x right, y down, z forward) projects to (fx x / z + cx, fy y / z + cy).
struct CameraIntrinsics {
  int width = 640;
  int height = 480;
  double fx = 0.0;
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  /// Valid depth range; returns outside it are reported as invalid (0) by sensors.
  double min_depth_m = 0.1;
  double max_depth_m = 3.0;

  /// Square pixels, centred principal point, horizontal field of view in degrees.
  static CameraIntrinsics FromHorizontalFov(int width, int height, double fov_x_deg,
                                            double min_depth_m = 0.1, double max_depth_m = 3.0);
  /// RealSense D435-like colour-aligned depth at 640x480: fx = fy = 615 px (55.0 deg x 42.6 deg:
  /// the colour sensor's 69 deg width is at 16:9; 4:3 crops it), range 0.1 - 3 m.
  static CameraIntrinsics RealSenseD435();

  /// Every bad field at once: "invalid camera intrinsics: width (-13) must be > 0; fx (inf) ...".
  Status Validate() const;

  double fov_x_deg() const;
  double fov_y_deg() const;

  /// Projects p_C to continuous pixel coordinates; nullopt when z <= 0.
  std::optional<Eigen::Vector2d> Project(const Eigen::Vector3d& p_C) const;
  /// True when continuous pixel coordinates fall on the image: u in [-0.5, width - 0.5), etc.
  bool IsInImage(const Eigen::Vector2d& uv) const;
  /// The point at z-depth `depth_m` (not ray length) behind pixel coordinates `uv`.
  Eigen::Vector3d BackProject(const Eigen::Vector2d& uv, double depth_m) const;
  /// Ray direction in the optical frame through `uv`, with z component 1 (not normalised).
  Eigen::Vector3d RayDirection(const Eigen::Vector2d& uv) const;

  /// The 3x3 matrix K.
  Eigen::Matrix3d K() const;

  /// Same field of view and principal point scaled to a new size (e.g. for a downsampled view).
  CameraIntrinsics Scaled(double factor) const;

  bool operator==(const CameraIntrinsics&) const = default;
};

std::string ToString(const CameraIntrinsics& K);

/// The fields of CameraIntrinsics (configs name a camera by them: camera.fx, ...).
const OptionTable<CameraIntrinsics>& CameraIntrinsicsTable();

}  // namespace avp

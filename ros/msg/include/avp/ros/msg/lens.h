#pragma once

// Camera lens models from sensor_msgs/CameraInfo, and the rectification of raw images through
// them: the one home of distortion that `avp replay` (ros::bag) and `avp live` (ros::live) share.
// avp's mapping is pinhole (core/camera.h): a raw image from a camera with lens distortion
// (Kinect, RealSense colour, fisheye) is remapped once to the rectified camera and fused as that.
//
// The models are those of ROS's image_geometry (sensor_msgs/distortion_models.hpp), on OpenCV:
//   plumb_bob            k1 k2 p1 p2 [k3]                            (4 or 5 coefficients)
//   rational_polynomial  k1 k2 p1 p2 k3 k4 k5 k6 [s1..s4 [tx ty]]    (8, 12 or 14)
//   equidistant          k1 k2 k3 k4: OpenCV's fisheye model          (4)
//   "" or "none"         no coefficients (or all zero)
// All-zero coefficients (any number of them) are no distortion, whatever the model's name: a
// rectified topic (image_rect) costs nothing. The rectified camera is P's left 3x3 (P's
// translation column is a stereo baseline, not used for the image), rotated by R against the raw
// camera (R = I for a monocular camera; an all-zero R or P is taken as unset).
//
// Pixel convention: OpenCV's and avp's (core/camera.h): pixel (u, v)'s centre is at (u, v).

#include <memory>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/camera.h>
#include <avp/core/image.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/status.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::msg {

/// The distortion models accepted, as the errors list them.
inline constexpr std::string_view kLensModels =
    "plumb_bob (4 or 5 coefficients), rational_polynomial (8, 12 or 14), equidistant (4), "
    "or \"\" / none (no coefficients)";

/// A camera's lens: its distortion, its raw intrinsics and those of its rectified image.
struct LensModel {
  enum class Kind {
    kNone,  ///< no distortion: the model is empty or "none", or every coefficient is 0
    kPlumbBob,
    kRationalPolynomial,
    kEquidistant,
  };
  Kind kind = Kind::kNone;
  /// The coefficients as CameraInfo gives them; empty for kNone.
  std::vector<double> d;
  /// The raw camera (CameraInfo's K).
  CameraIntrinsics K;
  /// The rectified camera: P's fx' = P[0], fy' = P[5], cx' = P[2], cy' = P[6] when P is set, else
  /// K; same size and depth range as K.
  CameraIntrinsics rectified;
  /// The rectified camera's orientation against the raw one (CameraInfo's R): a point p in the
  /// raw camera's optical frame is R p in the rectified one.
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();

  /// True when the rectified image is the raw one: no distortion, R = I, rectified == K.
  bool IsIdentity() const;
  /// The same lens: kind, coefficients, R, and K's and the rectified camera's size and
  /// intrinsics (not their depth ranges). A Rectifier built for one serves the other.
  bool SameLensAs(const LensModel& other) const;
};

/// The name of a kind as CameraInfo writes it ("plumb_bob", ...; "none" for kNone).
std::string_view ToString(LensModel::Kind kind);

/// The lens model of a CameraInfo, with the depth range given (a CameraInfo carries none). K and
/// its checks are FromCameraInfo's (images.h). InvalidArgument naming the frame and the values:
/// a model not accepted (listing kLensModels), a number of coefficients the model does not take
/// or a non-finite coefficient (naming the model, the count and the values), an R that is not a
/// rotation, a P whose rectified intrinsics do not validate.
Result<LensModel> LensModelFromCameraInfo(const CameraInfo& info, double min_depth_m,
                                          double max_depth_m);

/// Where a rectified pixel's point appears in the raw image (continuous coordinates; may lie
/// outside it; NaN when the ray points behind the raw camera): the forward lens model, in closed
/// form (OpenCV's formulas; tens of ns; OpenCV itself for a tilted sensor's 14 coefficients).
Eigen::Vector2d RawPixelOf(const LensModel& model, const Eigen::Vector2d& rectified_uv);

/// Remaps raw images to the rectified camera of one lens model. Built once per model: the maps
/// (a few ms at 640x480) are cached and shared by copies. Colour is interpolated bilinearly,
/// depth taken from the nearest raw pixel (no depth is invented by mixing a foreground and a
/// background: every rectified depth is a raw pixel's value, 0 = no return stays 0, a NaN stays
/// on the pixels that take it); rectified pixels whose raw position falls outside the raw image
/// get colour 0 and depth 0 (no return).
class Rectifier {
 public:
  /// The identity rectifier (no model).
  Rectifier();
  /// @pre `model` comes from LensModelFromCameraInfo (or is as valid: intrinsics that validate,
  /// a coefficient count its kind takes, R a rotation).
  explicit Rectifier(LensModel model);

  const LensModel& model() const { return model_; }
  /// True when Rectify changes nothing (LensModel::IsIdentity): it then copies nothing.
  bool identity() const { return maps_ == nullptr; }

  /// Replaces the raw frame's images by the rectified ones and its K by the rectified intrinsics
  /// (keeping the frame's depth range); with R != I, X_WC becomes the rectified camera's pose
  /// (X_WC · R^T). InvalidArgument when the frame's images or K are not the raw camera's.
  Status Rectify(RgbdFrame& frame) const;
  /// The rectified colour / depth image alone. InvalidArgument when its size is not the raw's.
  Result<ImageRgb8> RectifyColor(const ImageRgb8& raw) const;
  Result<DepthImage> RectifyDepth(const DepthImage& raw) const;

 private:
  struct Maps;
  LensModel model_;
  std::shared_ptr<const Maps> maps_;
};

/// The inverse of Rectify, for simulation and tests (not the live path; it costs an iterative
/// undistortion per pixel): the raw image a camera with this lens would see, given the rectified
/// frame (K = model.rectified, pose of the rectified camera). Each raw pixel samples the rectified
/// image where its undistorted position falls: colour bilinearly, depth from the nearest pixel;
/// raw pixels whose position falls outside the rectified image get colour 0 and depth 0. The
/// result has K = model.K (the frame's depth range kept) and, with R != I, X_WC · R.
/// InvalidArgument when the frame's size or intrinsics are not model.rectified's.
Result<RgbdFrame> Distort(const RgbdFrame& rectified, const LensModel& model);

}  // namespace avp::ros::msg

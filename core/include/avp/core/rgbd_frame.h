#pragma once

#include <cstdint>
#include <string>

#include <avp/core/camera.h>
#include <avp/core/image.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>

namespace avp {

/// One aligned RGB-D observation: colour and z-depth share the intrinsics `K`, and `X_WC` is the
/// pose of the camera optical frame in the world frame at capture time.
struct RgbdFrame {
  ImageRgb8 rgb;
  DepthImage depth_m;
  CameraIntrinsics K;
  RigidTransform X_WC;
  int64_t stamp_ns = 0;
  std::string frame_id = "camera_color_optical_frame";

  /// Sizes agree with K and with each other, K is valid.
  Status Validate() const;
};

}  // namespace avp

#pragma once

#include <cstdint>
#include <memory>

#include <avp/core/camera.h>
#include <avp/core/image.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/transform.h>
#include <avp/sim/scene.h>

namespace avp::sim {

/// A rendered RGB-D frame plus the simulator's per-pixel ground truth labels.
struct RenderedFrame {
  RgbdFrame rgbd;              ///< rgb + z-depth in metres (0 = no return)
  InstanceImage instance_ids;  ///< SceneObject::instance_id per pixel, 0 = background
  ClassImage class_ids;        ///< SemanticClass per pixel, 0 = background
};

struct RendererOptions {
  /// Colour of pixels with no return, linear RGB in [0, 1].
  Eigen::Vector3f background_rgb = Eigen::Vector3f(0.80f, 0.86f, 0.93f);
  /// Rays traced together: 1 (rtcIntersect1), 4 (2x2 pixels), 8 (4x2) or 16 (4x4 pixels).
  /// Results do not depend on it beyond float rounding; speed does (see bench_render).
  int ray_packet_size = 8;
};

/// CPU ray-cast RGB-D + label camera over a static scene (Embree). Building it copies the scene's
/// geometry into a BVH; Render() is const and may be called from several threads.
class RgbdRenderer {
 public:
  /// @throws avp::Error if the scene fails Scene::Validate() or the options are invalid
  /// (ray_packet_size not 1/4/8/16, background colour not finite). A frame is rendered on
  /// avp::Threads() threads (core/parallel.h).
  explicit RgbdRenderer(const Scene& scene, RendererOptions options = {});
  ~RgbdRenderer();
  RgbdRenderer(RgbdRenderer&&) noexcept;
  RgbdRenderer& operator=(RgbdRenderer&&) noexcept;

  /// Largest image Render() accepts (width x height), a guard against absurd intrinsics.
  static constexpr int64_t kMaxPixels = int64_t{1} << 26;

  /// One pinhole ray per pixel centre. Depth is z along the optical axis in metres; returns
  /// closer than K.min_depth_m or further than K.max_depth_m read 0 and label background.
  /// A surface closer than K.min_depth_m still occludes what lies behind it (the pixel reads
  /// "no return", as on a stereo camera), and pixels without a return get
  /// RendererOptions::background_rgb.
  /// @throws avp::Error if K is invalid (the message names the bad field), the image has more
  /// than kMaxPixels pixels, or X_WC is not finite.
  RenderedFrame Render(const CameraIntrinsics& K, const RigidTransform& X_WC,
                       int64_t stamp_ns = 0) const;

  /// Triangles in the BVH (ellipsoids count as 0; see num_ellipsoids()).
  size_t num_triangles() const;
  size_t num_ellipsoids() const;
  /// RendererOptions::ray_packet_size.
  int ray_packet_size() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace avp::sim

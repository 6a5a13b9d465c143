#pragma once

#include <cstdint>
#include <vector>

#include <avp/core/camera.h>
#include <avp/core/rng.h>
#include <avp/core/simulator_labels.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/robot/rgbd_source.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scene.h>
#include <avp/sim/sensor_noise.h>

namespace avp::sim {

/// Renders the scene with RgbdRenderer, optionally through the depth noise model (seeded per
/// frame from `seed` and the frame's index, so frame k is the same whatever came before).
class SimRgbdSource final : public robot::RgbdSource {
 public:
  /// @throws avp::Error if the scene or intrinsics are invalid.
  SimRgbdSource(const Scene& scene, const CameraIntrinsics& K, const DepthNoiseConfig& noise,
                uint64_t seed);
  Result<robot::Observation> Capture(const RigidTransform& X_WC, int64_t stamp_ns) override;
  /// A frame taken while the arm moves (fusion during motion): as Capture, with the noise drawn
  /// from a stream of its own (moving frame k uses draw k), so that the frames at rest are the
  /// same whether or not frames are taken while moving.
  Result<robot::Observation> CaptureMoving(const RigidTransform& X_WC, int64_t stamp_ns);
  /// Renders request.poses (CaptureMoving, stamped request.start_stamp_ns + t_ns) one by one
  /// from Next(), once End(true) was called; End(false): none. Never drops a frame: the
  /// simulation waits for the map.
  std::unique_ptr<robot::MoveStream> StreamMove(const robot::MoveStreamRequest& request) override;

  CameraIntrinsics intrinsics() const override { return K_; }
  int frames_captured() const { return frames_; }
  int moving_frames_captured() const { return moving_frames_; }

 private:
  const Scene* scene_;
  RgbdRenderer renderer_;
  CameraIntrinsics K_;
  DepthNoiseConfig noise_;
  Rng noise_rng_;
  std::vector<GroundTruthFruit> fruits_;
  int frames_ = 0;
  int moving_frames_ = 0;

  Result<robot::Observation> Render(const RigidTransform& X_WC, int64_t stamp_ns, Rng noise);
};

}  // namespace avp::sim

#pragma once

#include <cstdint>
#include <optional>

#include <avp/core/camera.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/segmentation/segmenter.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scene.h>
#include <avp/sim/sensor_noise.h>

namespace avp::pipeline {

/// One capture: the RGB-D frame and, from a simulator, its labels (for the oracle segmenter and
/// for reports).
struct Observation {
  RgbdFrame frame;
  std::optional<segmentation::SimulatorLabels> labels;
};

/// Where frames come from: a simulated camera, a recording, or a real camera (interop/).
class RgbdSource {
 public:
  virtual ~RgbdSource() = default;
  /// A frame taken with the camera at `X_WC` (the pose the arm reports after its move). A real
  /// source waits for the first frame stamped after the arm stopped; errors are statuses.
  virtual Result<Observation> Capture(const RigidTransform& X_WC, int64_t stamp_ns) = 0;
  /// The camera's intrinsics (the planner casts rays with its true field of view).
  virtual CameraIntrinsics intrinsics() const = 0;
};

/// Renders the scene with sim::RgbdRenderer, optionally through the depth noise model (seeded per
/// frame from `seed` and the frame's index, so frame k is the same whatever came before).
class SimRgbdSource final : public RgbdSource {
 public:
  /// @throws avp::Error if the scene or intrinsics are invalid.
  SimRgbdSource(const sim::Scene& scene, const CameraIntrinsics& K,
                const sim::DepthNoiseConfig& noise, uint64_t seed);
  Result<Observation> Capture(const RigidTransform& X_WC, int64_t stamp_ns) override;

  CameraIntrinsics intrinsics() const override { return K_; }
  int frames_captured() const { return frames_; }

 private:
  const sim::Scene* scene_;
  sim::RgbdRenderer renderer_;
  CameraIntrinsics K_;
  sim::DepthNoiseConfig noise_;
  Rng noise_rng_;
  std::vector<segmentation::GroundTruthFruit> fruits_;
  int frames_ = 0;
};

}  // namespace avp::pipeline

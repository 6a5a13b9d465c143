#pragma once

#include <cstdint>
#include <optional>

#include <avp/core/camera.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/simulator_labels.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>

namespace avp::robot {

/// One capture: the RGB-D frame and, from a simulator, its labels (for the oracle segmenter and
/// for reports).
struct Observation {
  RgbdFrame frame;
  std::optional<SimulatorLabels> labels;
};

/// Where frames come from: a simulated camera (sim::SimRgbdSource), a recording, or a real
/// camera (ros/live/).
class RgbdSource {
 public:
  virtual ~RgbdSource() = default;
  /// A frame taken with the camera at `X_WC` (the pose the arm reports after its move). A real
  /// source waits for the first frame stamped after the arm stopped; errors are statuses.
  virtual Result<Observation> Capture(const RigidTransform& X_WC, int64_t stamp_ns) = 0;
  /// The camera's intrinsics (the planner casts rays with its true field of view).
  virtual CameraIntrinsics intrinsics() const = 0;
};

}  // namespace avp::robot

#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

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

/// A camera pose at a time of a move: where a frame of the stream is expected (FramesAlong).
struct TimedCameraPose {
  int64_t t_ns = 0;  ///< from the move's start
  RigidTransform X_WC;
};

/// What a source is asked to stream while the arm moves (fusion during motion).
struct MoveStreamRequest {
  /// The episode's stamp of the move's start: a simulator stamps frame k start_stamp_ns + t_k.
  int64_t start_stamp_ns = 0;
  /// At most this many frames a second (a camera streaming faster is thinned to it).
  double rate_hz = 30.0;
  /// Where the camera will be at each frame time (the trajectory the arm is about to execute): a
  /// simulator renders there; a real camera takes its poses from TF and only uses the count.
  std::vector<TimedCameraPose> poses;
  /// The camera at the move's start and at its goal: a live camera's frames taken there (before
  /// the arm starts, after it arrived: the views' own poses) are not the move's.
  RigidTransform X_WC_from;
  RigidTransform X_WC_to;
  /// A live stream keeps at most this many frames waiting for the map: when the consumer falls
  /// further behind, the oldest are dropped (counted), so memory stays bounded.
  int max_pending = 4;
};

/// Counts of one move's stream (StepRecord::motion_frames).
struct MoveStreamCounters {
  int delivered = 0;  ///< frames Next() returned
  int dropped = 0;    ///< frames the consumer was too slow for (max_pending exceeded)
  int skipped = 0;    ///< frames above rate_hz, or taken at rest at the start or the goal
  int failed = 0;     ///< frames that could not be assembled (each an error from Next())
};

/// The frames a camera takes while the arm moves, one move at a time. Used from one consumer
/// thread (Next) and the thread that moves the arm (End).
class MoveStream {
 public:
  virtual ~MoveStream() = default;
  /// The next frame of the move, in stamp order, or nullopt when the move's frames are all
  /// returned (or dropped) after End(). Blocks while the move goes on and the next frame is not
  /// there yet. An error is one frame that could not be had (counted); the stream goes on.
  virtual Result<std::optional<Observation>> Next() = 0;
  /// The move ended: `moved` false when the arm refused or failed it (a simulator then renders
  /// nothing; a real camera's frames so far stay valid, their poses came from TF). Frames
  /// stamped after the arm arrived belong to the next view, not to this move.
  virtual void End(bool moved) = 0;
  virtual MoveStreamCounters counters() const = 0;
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
  /// Starts streaming the frames taken during the move the arm is about to make (fusion during
  /// motion), before the arm is told to move; null when this source cannot (the default: a
  /// recording, a camera that only captures at rest). A simulator renders at request.poses once
  /// End(true) is called; a live camera hands over the frames it receives until End().
  virtual std::unique_ptr<MoveStream> StreamMove(const MoveStreamRequest& /*request*/) {
    return nullptr;
  }
};

}  // namespace avp::robot

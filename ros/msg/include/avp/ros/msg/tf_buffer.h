#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::msg {

/// A transform tree as tf2 keeps it: the /tf and /tf_static edges (parent → child, X_PC), a
/// history per dynamic edge, and lookups between any two frames of one tree at a time,
/// interpolated (linear in translation, slerp in rotation) between the samples that bracket it.
/// The one TF buffer of `avp live` (filled by ros::live::TfListener as messages arrive) and of
/// `avp replay` (ros::bag::ReadBag, filled from a whole bag's /tf and /tf_static).
/// Frame names are kept without a leading '/' (as tf2 does), in Add and in Lookup.
/// Thread-safe: subscription callbacks add while the loop looks up.
class TfBuffer {
 public:
  struct Options {
    /// History kept per dynamic edge, seconds (tf2's default cache time is 10 s); 0: every
    /// sample is kept (a bag read whole).
    double cache_s = 10.0;
    /// A lookup up to this much outside an edge's samples (after its newest, or before its
    /// oldest) uses that nearest sample (a robot that stands still may publish /tf slowly);
    /// seconds.
    double extrapolation_s = 0.0;
  };
  TfBuffer() : TfBuffer(Options{}) {}
  explicit TfBuffer(Options options) : options_(options) {}

  /// Adds X_PC of `child` in `parent` at `stamp_ns`. A static edge holds at every time. Refuses
  /// (InvalidArgument naming the frames) an empty frame, parent == child, a non-finite
  /// transform, a child that already has another parent, an edge that would close a loop, and
  /// (OutOfRange) a sample older than the edge's history.
  Status Add(std::string_view parent, std::string_view child, const RigidTransform& X_PC,
             int64_t stamp_ns, bool is_static);
  /// Adds a TransformStamped of /tf or /tf_static as tf2 takes it: as above, refusing also a
  /// quaternion whose norm is not within 1e-3 of 1 (tf2's "denormalized quaternion"); the error
  /// names the frames, the stamp and the values.
  Status Add(const TransformStamped& t, bool is_static);

  /// X_TS: the pose of frame `source` in frame `target` at `stamp_ns`. NotFound naming the
  /// frame (and the known frames) when one is unknown or the two are in different trees;
  /// DeadlineExceeded ("not available yet") when an edge's newest sample is older than the stamp
  /// (beyond extrapolation_s): live callers may wait; OutOfRange when the stamp is older than an
  /// edge's oldest sample (beyond extrapolation_s).
  Result<RigidTransform> Lookup(std::string_view target, std::string_view source,
                                int64_t stamp_ns) const;

  /// The newest stamp at which Lookup(target, source) can be answered (the minimum over the
  /// chain's dynamic edges of their newest samples; INT64_MAX for a static chain), or NotFound.
  Result<int64_t> LatestCommonTime(std::string_view target, std::string_view source) const;

  /// Known frames, sorted.
  std::vector<std::string> Frames() const;
  /// True while no transform has been added.
  bool empty() const;

 private:
  struct Sample {
    int64_t stamp_ns;
    RigidTransform X_PC;
  };
  struct Edge {
    std::string parent;
    bool is_static = false;
    std::vector<Sample> samples;  ///< by stamp; one for a static edge
  };
  /// The chain from `frame` up to its root: (child, edge) pairs.
  std::vector<std::pair<std::string, const Edge*>> ChainToRoot(const std::string& frame) const;
  std::vector<std::string> FramesLocked() const;
  Result<RigidTransform> EdgeAt(const std::string& child, const Edge& edge, int64_t stamp_ns) const;

  Options options_;
  mutable std::mutex mutex_;
  std::map<std::string, Edge, std::less<>> edges_;  ///< by child frame
};

}  // namespace avp::ros::msg

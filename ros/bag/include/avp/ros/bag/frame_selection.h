#pragma once

// Which frames of a robot's bag `avp replay` fuses: the run configuration's replay.* keys
// (docs/recording.md "Replaying a real robot's bag"). Light on purpose: the run configuration
// includes it.

#include <concepts>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/core/options.h>

namespace avp::ros::bag {

/// Which frames of a real robot's bag are fused (`avp replay`; the run configuration's replay.*
/// keys). A colour/depth pair is fused when it passes each of these in turn; each pair left out
/// is counted under its first reason. avp's own recordings fuse every step (max_views applies).
struct FrameSelection {
  /// Seconds since the first colour image: only pairs stamped in [start_s, end_s] (end_s = 0:
  /// to the end).
  double start_s = 0.0;
  double end_s = 0.0;
  /// Only the pairs taken while the camera stands still (from TF: it moved less than
  /// at_rest_m_s and at_rest_deg_s over the at_rest_window_s before the image).
  bool at_rest_only = false;
  double at_rest_m_s = 0.01;
  double at_rest_deg_s = 2.0;
  double at_rest_window_s = 0.2;
  /// Every Nth pair (of those in the window and at rest).
  int every_nth = 1;
  /// At most this many per second of bag time (the first pair, then each first pair at least
  /// 1 / fps later); 0 = no limit.
  double fps = 1.0;
  /// At most this many views (0: all); reading stops there.
  int max_views = 0;
};

/// Adds FrameSelection's keys (start_s, end_s, at_rest_only, at_rest_m_s, at_rest_deg_s,
/// at_rest_window_s, every_nth, fps, max_views) to the table of a struct that derives from it.
template <std::derived_from<FrameSelection> O>
void AddFrameSelectionOptions(OptionTable<O>& t) {
  t.Real("start_s", &O::start_s, "s", ValueRange::AtLeast(0),
         "robot bags: fuse pairs stamped at least this long after the first colour image");
  t.Real("end_s", &O::end_s, "s", ValueRange::AtLeast(0),
         "robot bags: ... and at most this long after it (0: to the end)");
  t.Flag("at_rest_only", &O::at_rest_only,
         "robot bags: fuse only pairs taken while the camera stands still (from TF)");
  t.Real("at_rest_m_s", &O::at_rest_m_s, "m/s", ValueRange::Above(0),
         "at rest: the camera moves slower than this");
  t.Real("at_rest_deg_s", &O::at_rest_deg_s, "deg/s", ValueRange::Above(0),
         "at rest: the camera turns slower than this");
  t.Real("at_rest_window_s", &O::at_rest_window_s, "s", ValueRange::Closed(0.001, 10),
         "at rest: measured over this long before the image");
  t.Integer("every_nth", &O::every_nth, "", ValueRange::Closed(1, 1000000),
            "robot bags: fuse every Nth colour/depth pair");
  t.Real("fps", &O::fps, "Hz", ValueRange::Closed(0, 1000),
         "robot bags: fuse at most this many pairs per second of bag time (0: no limit)");
  t.Integer("max_views", &O::max_views, "", ValueRange::Closed(0, 1000000),
            "fuse at most this many views (0: all)");
  t.AddRule([](const O& o, std::vector<std::string>& errors) {
    if (o.end_s > 0.0 && o.end_s <= o.start_s) {
      errors.push_back(fmt::format("end_s = {} must be after start_s = {} (or 0: to the end)",
                                   o.end_s, o.start_s));
    }
  });
}

/// FrameSelection's own table (its keys and rules, as AddFrameSelectionOptions gives them).
const OptionTable<FrameSelection>& FrameSelectionTable();

}  // namespace avp::ros::bag

#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/image.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/segmentation.h>
#include <avp/core/simulator_labels.h>
#include <avp/core/status.h>

namespace avp::segmentation {

/// One segmentation request: an RGB-D frame and a text prompt.
struct SegmentationRequest {
  /// The frame to segment (rgb, depth, intrinsics, pose). Required.
  const RgbdFrame* frame = nullptr;
  /// Comma-separated class phrases, e.g. "tomato" or "tomato, green apple". Segmenters that map
  /// phrases to classes report each instance's phrase in InstanceMask::label.
  std::string prompt = "tomato";
  /// Instances scoring below this are dropped.
  float score_threshold = 0.0f;
  /// Simulator labels of the frame, or nullptr (a real camera).
  const SimulatorLabels* labels = nullptr;
  /// Index of the frame in its episode: seeds per-frame randomness (noise models), so results do
  /// not depend on the order or the thread frames are segmented in.
  uint64_t frame_index = 0;
};

/// Turns an image and a prompt into instance masks. Implementations: OracleSegmenter (simulator
/// labels through a zero-shot-like error model), ColorSegmenter (HSV thresholds); the network
/// backends come with their own module. Programs pick them by name from a SegmenterRegistry
/// (segmenter_registry.h). Expected failures (bad input, missing labels) are
/// statuses naming the bad value, never exceptions.
class Segmenter {
 public:
  virtual ~Segmenter() = default;
  /// Short name: "oracle", "color", ...
  virtual std::string_view name() const = 0;
  /// The masks of `request.frame`, all of the frame's size, each with a class and a calibrated
  /// confidence in [0, 1] (Segmentation::ValidateFor passes on success).
  virtual Result<Segmentation> Segment(const SegmentationRequest& request) = 0;
};

/// Splits a prompt on commas into trimmed, non-empty phrases ("tomato, green apple" -> {"tomato",
/// "green apple"}). InvalidArgument when nothing is left.
Result<std::vector<std::string>> SplitPrompt(std::string_view prompt);

}  // namespace avp::segmentation

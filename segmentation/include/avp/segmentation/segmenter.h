#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/image.h>
#include <avp/core/limits.h>
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
  /// Asked by segmenters between units of work (phrases, rows, stages): a non-OK status stops
  /// the work and Segment() returns it. Cancelled: the caller no longer wants the answer (its
  /// client left, Ctrl-C); DeadlineExceeded: its deadline passed. Empty: never stops. The
  /// segmentation service sets it, so that a worker is free again soon after its client leaves.
  /// Called from the thread running Segment(); must be cheap (it is asked often).
  std::function<Status()> interrupt;
};

/// request.interrupt's answer, or OK when it has none.
inline Status CheckInterrupt(const SegmentationRequest& request) {
  return request.interrupt ? request.interrupt() : Status::Ok();
}

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
  /// Whether it segments a frame well within a 30 Hz camera's period on a laptop's CPU, so that
  /// fusion during motion segments every frame (pipeline::MovingSemantics::kAuto); false (the
  /// default, a network): it takes the newest frame whenever it is free.
  virtual bool keeps_up_with_stream() const { return false; }
};

/// Process-wide limits of a prompt (core/limits.h; `avp limits`, `avp --limit NAME=N`), checked by
/// SplitPrompt before it splits: bytes of the prompt text (default 4096) and phrases in it
/// (default 64; counted before duplicates are dropped).
const Limit& MaxPromptBytes();
const Limit& MaxPromptPhrases();

/// Splits a prompt on commas into trimmed, non-empty phrases ("tomato, green apple" -> {"tomato",
/// "green apple"}), each phrase once (the first occurrence kept, in prompt order: "tomato,
/// tomato" -> {"tomato"}). InvalidArgument when nothing is left (the prompt quoted, escaped);
/// ResourceExhausted naming max_prompt_bytes or max_prompt_phrases when the prompt is larger,
/// before any phrase is copied.
Result<std::vector<std::string>> SplitPrompt(std::string_view prompt);

}  // namespace avp::segmentation

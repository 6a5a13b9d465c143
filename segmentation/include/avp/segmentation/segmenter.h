#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/image.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>

namespace avp::segmentation {

/// One ground-truth fruit as a simulator knows it (for segmenters that imitate a detector).
struct GroundTruthFruit {
  uint16_t instance_id = 0;
  Eigen::Vector3d center_W = Eigen::Vector3d::Zero();
  double radius_m = 0.0;
};

/// What a simulator knows about a frame: its label images and fruits. Only simulation segmenters
/// (oracle) read it; real segmenters ignore it.
struct SimulatorLabels {
  InstanceImage instance_ids;  ///< object instance id per pixel, 0 = background
  ClassImage class_ids;        ///< SemanticClass per pixel, 0 = background
  std::vector<GroundTruthFruit> fruits;
};

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
/// backends come with their own module. Expected failures (bad input, missing labels) are
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

/// The names MakeSegmenter accepts, in a stable order: "oracle", "oracle-perfect", "color".
const std::vector<std::string>& SegmenterNames();

/// Builds a segmenter from its spec (the name, or for a scheme the whole "remote://host:port").
using SegmenterFactory =
    std::function<Result<std::unique_ptr<Segmenter>>(std::string_view spec, uint64_t seed)>;

/// Makes `name` known to MakeSegmenter: modules above this one (the network backends, the remote
/// client) register themselves so that every command and config accepts them unchanged. A name
/// ending in "://" is a scheme and matches every spec that starts with it. Registering a name
/// again replaces its factory. Thread-safe.
void RegisterSegmenterFactory(std::string name, SegmenterFactory factory);

/// The registered names and schemes (RegisterSegmenterFactory), sorted.
std::vector<std::string> RegisteredSegmenterNames();

/// True when MakeSegmenter knows `spec`: a built-in name, a registered name, or a spec starting
/// with a registered scheme. (Whether it then builds, e.g. reaches its server, is another matter.)
bool IsKnownSegmenter(std::string_view spec);

/// What error messages list as known: SegmenterNames(), then the registered names, schemes
/// written as "remote://...".
std::vector<std::string> KnownSegmenterSpecs();

/// A segmenter by spec: "oracle" (OracleSegmenter with OracleOptions{}), "oracle-perfect"
/// (OracleSegmenter with OracleOptions::Perfect()), "color" (ColorSegmenter with ColorOptions{};
/// ignores the seed), or a registered name or scheme. NotFound naming the unknown spec and listing
/// the known ones.
Result<std::unique_ptr<Segmenter>> MakeSegmenter(std::string_view name, uint64_t seed);

}  // namespace avp::segmentation

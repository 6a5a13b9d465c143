#pragma once

// `avp segment`: one photo through any registered segmenter, with an overlay and a JSON of the
// instances (docs/zero-shot-models.md).

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <avp/core/options.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/segmentation/segmenter_registry.h>

namespace avp::segmentation {

/// `avp segment`: one image through a segmenter, with a debug overlay and a JSON of the instances.
struct SegmentOptions {
  /// JPEG or PNG (anything OpenCV reads), as 8-bit RGB.
  std::filesystem::path image;
  /// Comma-separated phrases, e.g. "tomato, green apple".
  std::string prompt = "tomato";
  /// A segmenter spec the registry knows: "ywes", "lsam" (their models from AVP_ZSL_MODEL_DIR
  /// or `models`), "ywes://DIR", "color", "oracle", "remote://host:port", ...
  std::string backend = "ywes";
  /// The model directory of "ywes" / "lsam" (turns the spec into "<backend>://<models>");
  /// empty = AVP_ZSL_MODEL_DIR. Only for those two backends.
  std::filesystem::path models;
  /// Instances scoring below this are dropped (SegmentationRequest::score_threshold), in [0, 1].
  float threshold = 0.0f;
  /// Where overlay.png and instances.json go (created when missing).
  std::filesystem::path out_dir = "out/segment";
  /// The segmenter's seed (only noisy segmenters use it).
  uint64_t seed = 0;
  /// Options of the segmenter over its registered defaults (--segmenter-option).
  OptionValues segmenter_options;

  /// OK, or InvalidArgument listing every bad field.
  Status Validate() const;
};

struct SegmentResult {
  std::string spec;     ///< the spec the segmenter was made from
  std::string backend;  ///< its name() ("ywes", "color", ...)
  std::filesystem::path image;
  int width = 0;
  int height = 0;
  Segmentation segmentation;
  double total_ms = 0.0;  ///< wall time of Segment
  std::vector<std::filesystem::path> files;
};

/// The spec `options` name: `backend`, or "<backend>://<models>" when `models` is given.
/// InvalidArgument when `models` is given for a backend other than "ywes" / "lsam" or together
/// with a spec that already names a directory.
Result<std::string> SegmenterSpecFor(const SegmentOptions& options);

/// One frame through the segmenter `spec` of `segmenters` (its registered defaults with
/// `segmenter_options` over them, seeded with `seed`): the segmentation, checked against the
/// frame's size, and how long it took (SegmentResult without `image`). What `avp segment` and the
/// Python module's avp.segment share. Errors name the spec: an unknown one, bad options, the
/// segmenter's own error, a result of the wrong size.
Result<SegmentResult> SegmentWith(const SegmenterRegistry& segmenters, const std::string& spec,
                                  const OptionValues& segmenter_options, uint64_t seed,
                                  const SegmentationRequest& request);

/// Reads the image, builds an RgbdFrame around it (a nominal 60-degree pinhole camera and zero
/// depth: the segmenters in scope use only the colour image), runs the segmenter on the prompt,
/// and writes out_dir/overlay.png (zsl::DrawSegmentationOverlay) and out_dir/instances.json
/// (SegmentationJson). Errors name the bad value: unreadable image, unknown or unusable backend
/// (the segmenter's own error, e.g. a missing model directory), bad prompt, unwritable folder.
Result<SegmentResult> SegmentImageToFolder(const SegmentOptions& options,
                                           const SegmenterRegistry& segmenters);

/// instances.json: {"backend", "spec", "prompt", "threshold", "image": {"path", "width",
/// "height"}, "total_ms", "timings": [{"stage", "ms"}], "instances": [{"index", "label",
/// "class", "score", "mask_score" (null when the segmenter has none), "box": [x0, y0, x1, y1]
/// (null when none), "area" (mask pixels), "rle": {"size": [height, width], "counts": [...]}
/// (COCO uncompressed, column-major), "polygons": [[[x, y], ...], ...]}]}.
std::string SegmentationJson(const SegmentResult& result, const SegmentOptions& options);

/// The console report: one line per instance ("#0 tomato  score 0.912  mask 0.875  box (12, 40)
/// -(80, 96)  area 2810 px"), then one line of stage timings and the total.
std::string FormatSegmentSummary(const SegmentResult& result);

}  // namespace avp::segmentation

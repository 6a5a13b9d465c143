#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation/segmenter_registry.h>

namespace avp::segmentation {

/// An 8-bit HSV colour with OpenCV's ranges: hue 0-179 (degrees / 2), saturation and value 0-255.
struct Hsv8 {
  uint8_t h = 0;
  uint8_t s = 0;
  uint8_t v = 0;
  bool operator==(const Hsv8&) const = default;
};

/// OpenCV's cvtColor(COLOR_RGB2HSV) for 8-bit pixels, rounded to nearest: V = max(R, G, B),
/// S = 255 (V - min) / V (0 when V = 0), H = 60° (G - B) / (V - min) when V = R, 120° + ... when
/// V = G, 240° + ... when V = B, then halved and wrapped into [0, 180) (0 for greys).
Hsv8 RgbToHsv(uint8_t r, uint8_t g, uint8_t b);

/// An inclusive hue interval in OpenCV units, 0 <= min_hue <= max_hue <= 179.
struct HueRange {
  int min_hue = 0;
  int max_hue = 0;
  bool Contains(int hue) const { return hue >= min_hue && hue <= max_hue; }
};

/// Which colour a prompt phrase asks for.
enum class ColorFilter : uint8_t {
  kRed = 0,
  kGreen = 1,
  kRedGreen = 2,  ///< pixels passing either filter (the reference's "red-green")
};
/// "red", "green" or "red-green".
std::string_view ToString(ColorFilter filter);
/// Inverse of ToString; nullopt otherwise.
std::optional<ColorFilter> ColorFilterFromString(std::string_view name);

struct ColorOptions {
  /// Red hues. The reference used 1-10 only; red wraps around hue 0, so 170-179 and 0 belong too.
  std::vector<HueRange> red_hues = {{0, 10}, {170, 179}};
  /// Green hues (the reference's 25-45).
  std::vector<HueRange> green_hues = {{25, 45}};
  /// Pixels below these saturations / values are grey, white or dark and never pass (the
  /// reference had no limit). In [0, 255].
  int min_saturation = 80;
  int min_value = 40;
  /// 8-connected components with fewer pixels are dropped (>= 1).
  int min_area_px = 30;
  /// Confidence of every instance, in [0, 1].
  float confidence = 0.8f;
  /// Default colour of a phrase that names no colour, by its last word (or that word's singular),
  /// lower case. "fruit" is red, as the reference system's default filter.
  std::map<std::string, ColorFilter> fruit_colors = {
      {"tomato", ColorFilter::kRed},     {"strawberry", ColorFilter::kRed},
      {"apple", ColorFilter::kRed},      {"cherry", ColorFilter::kRed},
      {"pepper", ColorFilter::kRed},     {"raspberry", ColorFilter::kRed},
      {"fruit", ColorFilter::kRed},      {"lime", ColorFilter::kGreen},
      {"cucumber", ColorFilter::kGreen}, {"grape", ColorFilter::kGreen},
  };

  /// Every bad field at once: "invalid color options: red_hues[1] (170-190) must satisfy 0 <=
  /// min <= max <= 179; ...".
  Status Validate() const;
};

/// OpenCV-free HSV thresholding of the RGB image (the reference system's colour filter, with its
/// bugs fixed: docs/segmentation.md). Each prompt phrase picks a ColorFilter (FilterForPhrase);
/// the pixels passing it form 8-connected components, and each component of at least
/// min_area_px pixels becomes one fruit instance with the fixed confidence and the phrase as
/// label. Instances are ordered by phrase, then by each component's first pixel in raster order.
/// Deterministic: the seed, frame_index and simulator labels are ignored. Phrases that name no
/// known colour or fruit give no instances.
///
/// Errors: InvalidArgument for a null or invalid frame, an empty prompt or a score threshold
/// outside [0, 1].
/// The scalar fields of ColorOptions: min_saturation, min_value, min_area_px, confidence (the hue
/// ranges and the word -> colour map are set in code; a rule checks them).
const OptionTable<ColorOptions>& ColorOptionTable();

/// "color": the reference's HSV colour filter.
SegmenterEntry ColorSegmenterEntry();

class ColorSegmenter : public Segmenter {
 public:
  /// @throws avp::Error if options.Validate() fails (the message names the bad fields).
  explicit ColorSegmenter(ColorOptions options = {});

  std::string_view name() const override { return "color"; }
  Result<Segmentation> Segment(const SegmentationRequest& request) override;
  bool keeps_up_with_stream() const override { return true; }

  const ColorOptions& options() const { return options_; }

  /// The filter a phrase asks for: "red-green" anywhere -> kRedGreen; otherwise the colour words
  /// "red" and "green" (both -> kRedGreen: "red and green tomatoes"); otherwise the last word's
  /// entry in fruit_colors ("cherry tomatoes" -> red); otherwise nullopt. Case-insensitive.
  std::optional<ColorFilter> FilterForPhrase(std::string_view phrase) const;

  /// Whether a pixel passes `filter`: its hue is in one of the filter's ranges and its saturation
  /// and value reach the minimums.
  bool Passes(const Hsv8& hsv, ColorFilter filter) const;

 private:
  ColorOptions options_;
};

}  // namespace avp::segmentation

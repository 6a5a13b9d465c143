#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/segmentation/color_segmenter.h>
#include <avp/segmentation/mask_ops.h>

#include "phrase.h"

namespace avp::segmentation {

namespace {

/// floor(a / b) for b > 0.
int FloorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

Hsv8 RgbToHsv(uint8_t r, uint8_t g, uint8_t b) {
  const int vmax = std::max({r, g, b});
  const int vmin = std::min({r, g, b});
  const int diff = vmax - vmin;
  Hsv8 out;
  out.v = static_cast<uint8_t>(vmax);
  out.s = vmax == 0 ? 0 : static_cast<uint8_t>((255 * diff + vmax / 2) / vmax);
  if (diff == 0) return out;
  int raw = 0;  // hue in units of diff / 60 degrees
  if (vmax == r) {
    raw = g - b;
  } else if (vmax == g) {
    raw = 2 * diff + b - r;
  } else {
    raw = 4 * diff + r - g;
  }
  // Hue / 2 = 30 raw / diff, rounded to nearest (half up), wrapped into [0, 180).
  int h = FloorDiv(60 * raw + diff, 2 * diff);
  if (h < 0) h += 180;
  if (h >= 180) h -= 180;
  out.h = static_cast<uint8_t>(h);
  return out;
}

std::string_view ToString(ColorFilter filter) {
  switch (filter) {
    case ColorFilter::kRed:
      return "red";
    case ColorFilter::kGreen:
      return "green";
    case ColorFilter::kRedGreen:
      return "red-green";
  }
  return "invalid";
}

std::optional<ColorFilter> ColorFilterFromString(std::string_view name) {
  for (auto f : {ColorFilter::kRed, ColorFilter::kGreen, ColorFilter::kRedGreen}) {
    if (ToString(f) == name) return f;
  }
  return std::nullopt;
}

const OptionTable<ColorOptions>& ColorOptionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<ColorOptions>("color option");
    t->Integer("min_saturation", &ColorOptions::min_saturation, "", ValueRange::Closed(0, 255),
               "HSV saturation a pixel needs");
    t->Integer("min_value", &ColorOptions::min_value, "", ValueRange::Closed(0, 255),
               "HSV value a pixel needs");
    t->Integer("min_area_px", &ColorOptions::min_area_px, "px", ValueRange::AtLeast(1),
               "smallest blob kept");
    t->Real("confidence", &ColorOptions::confidence, "", ValueRange::Closed(0, 1),
            "score of every instance");
    t->AddRule([](const ColorOptions& o, std::vector<std::string>& errors) {
      const auto check_hues = [&](const std::vector<HueRange>& hues, std::string_view name) {
        if (hues.empty()) errors.push_back(fmt::format("{} must not be empty", name));
        for (size_t i = 0; i < hues.size(); ++i) {
          const HueRange& r = hues[i];
          if (!(r.min_hue >= 0 && r.min_hue <= r.max_hue && r.max_hue <= 179)) {
            errors.push_back(
                fmt::format("{}[{}] ({}-{}) must satisfy 0 <= min_hue <= max_hue <= 179", name, i,
                            r.min_hue, r.max_hue));
          }
        }
      };
      check_hues(o.red_hues, "red_hues");
      check_hues(o.green_hues, "green_hues");
      for (const auto& [word, filter] : o.fruit_colors) {
        if (!internal::IsVocabularyWord(word)) {
          errors.push_back(
              fmt::format("fruit_colors key \"{}\" must be a non-empty lower-case word", word));
        }
        if (ToString(filter) == "invalid") {
          errors.push_back(fmt::format("fruit_colors[\"{}\"] ({}) is not a colour filter", word,
                                       static_cast<int>(filter)));
        }
      }
    });
    return t;
  }();
  return *table;
}

Status ColorOptions::Validate() const { return ColorOptionTable().Validate(*this); }

SegmenterEntry ColorSegmenterEntry() {
  return MakeSegmenterEntry<ColorOptions>(
      "color", "the reference's HSV colour filter (red or green by prompt word)",
      ColorOptionTable(), ColorOptions{},
      [](std::string_view, const ColorOptions& o, const SegmenterContext&) {
        return Result<std::unique_ptr<Segmenter>>(std::make_unique<ColorSegmenter>(o));
      });
}

ColorSegmenter::ColorSegmenter(ColorOptions options) : options_(std::move(options)) {
  const Status status = options_.Validate();
  AVP_THROW_UNLESS(status.ok(), status.message());
}

std::optional<ColorFilter> ColorSegmenter::FilterForPhrase(std::string_view phrase) const {
  const std::vector<std::string> words = internal::PhraseWords(phrase);
  if (words.empty()) return std::nullopt;
  bool red = false;
  bool green = false;
  for (const std::string& word : words) {
    if (word == "red-green" || word == "green-red") return ColorFilter::kRedGreen;
    red = red || word == "red";
    green = green || word == "green";
  }
  if (red && green) return ColorFilter::kRedGreen;
  if (red) return ColorFilter::kRed;
  if (green) return ColorFilter::kGreen;
  for (const std::string& candidate : internal::SingularCandidates(words.back())) {
    if (const auto it = options_.fruit_colors.find(candidate); it != options_.fruit_colors.end()) {
      return it->second;
    }
  }
  return std::nullopt;
}

bool ColorSegmenter::Passes(const Hsv8& hsv, ColorFilter filter) const {
  if (hsv.s < options_.min_saturation || hsv.v < options_.min_value) return false;
  const auto in_any = [&](const std::vector<HueRange>& hues) {
    return std::any_of(hues.begin(), hues.end(),
                       [&](const HueRange& r) { return r.Contains(hsv.h); });
  };
  switch (filter) {
    case ColorFilter::kRed:
      return in_any(options_.red_hues);
    case ColorFilter::kGreen:
      return in_any(options_.green_hues);
    case ColorFilter::kRedGreen:
      return in_any(options_.red_hues) || in_any(options_.green_hues);
  }
  return false;
}

Result<Segmentation> ColorSegmenter::Segment(const SegmentationRequest& request) {
  if (request.frame == nullptr) {
    return InvalidArgumentError("color segmenter: request.frame is null");
  }
  const RgbdFrame& frame = *request.frame;
  AVP_RETURN_IF_ERROR(frame.Validate().WithContext("color segmenter"));
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> phrases, SplitPrompt(request.prompt));
  if (!std::isfinite(request.score_threshold) || request.score_threshold < 0.0f ||
      request.score_threshold > 1.0f) {
    return InvalidArgumentError(fmt::format(
        "color segmenter: score_threshold ({}) must be in [0, 1]", request.score_threshold));
  }
  const int w = frame.rgb.width();
  const int h = frame.rgb.height();
  Segmentation out;
  out.width = w;
  out.height = h;
  if (options_.confidence < request.score_threshold) return out;

  // HSV once per frame, then one pass per phrase.
  std::vector<Hsv8> hsv(frame.rgb.num_pixels());
  for (int v = 0; v < h; ++v) {
    if (v % 64 == 0) AVP_RETURN_IF_ERROR(CheckInterrupt(request));
    for (int u = 0; u < w; ++u) {
      const auto p = frame.rgb.pixel(u, v);
      hsv[static_cast<size_t>(v) * w + u] = RgbToHsv(p[0], p[1], p[2]);
    }
  }
  for (const std::string& phrase : phrases) {
    AVP_RETURN_IF_ERROR(CheckInterrupt(request));
    const std::optional<ColorFilter> filter = FilterForPhrase(phrase);
    if (!filter) continue;
    MaskImage passing(w, h, 0);
    for (size_t i = 0; i < hsv.size(); ++i) {
      if (Passes(hsv[i], *filter)) passing.data()[i] = 1;
    }
    const Components components = LabelComponents(passing, /*eight_connected=*/true);
    std::vector<int32_t> instance_of(components.count() + 1, -1);
    const size_t first = out.instances.size();
    for (size_t k = 0; k < components.count(); ++k) {
      if (components.sizes[k] < static_cast<size_t>(options_.min_area_px)) continue;
      instance_of[k + 1] = static_cast<int32_t>(out.instances.size() - first);
      InstanceMask m;
      m.mask = MaskImage(w, h, 0);
      m.semantic_class = SemanticClass::kFruit;
      m.confidence = options_.confidence;
      m.label = phrase;
      out.instances.push_back(std::move(m));
    }
    for (size_t i = 0; i < hsv.size(); ++i) {
      const int32_t label = components.labels.data()[i];
      if (label == 0 || instance_of[label] < 0) continue;
      out.instances[first + static_cast<size_t>(instance_of[label])].mask.data()[i] = 1;
    }
  }
  return out;
}

}  // namespace avp::segmentation

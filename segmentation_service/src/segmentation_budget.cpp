// A segmentation request's size against the server's budget (RequestBudget), read from the
// shapes and length prefixes before anything is decoded or allocated: image pixels (raw, or
// declared in a PNG's or JPEG's header), fruit rows, prompt bytes and phrases, and the counts of
// inputs, outputs and parameters.

#include <algorithm>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

#include <fmt/format.h>

#include <avp/core/limits.h>
#include <avp/core/text.h>
#include <avp/segmentation_service/segmentation_codec.h>

#include "segmentation_codec_internal.h"

namespace avp::segmentation_service {

namespace {

using codec::ExpectTensor;
using codec::JoinNames;
using codec::ReadU32LeAt;

uint32_t ReadU32Be(const unsigned char* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | uint32_t{p[3]};
}

/// The elements' lengths of a BYTES tensor's contents, without copying them; nullopt when the
/// length prefixes do not parse (CheckTensor names that later).
std::optional<std::vector<uint32_t>> BytesElementLengths(std::string_view d, uint64_t max_count) {
  std::vector<uint32_t> lengths;
  size_t pos = 0;
  while (pos < d.size()) {
    if (d.size() - pos < 4 || lengths.size() >= max_count) return std::nullopt;
    const uint32_t len = ReadU32LeAt(d, pos);
    pos += 4;
    if (len > d.size() - pos) return std::nullopt;
    lengths.push_back(len);
    pos += len;
  }
  return lengths;
}

/// H x W of an [H, W] or [H, W, 3] or [1, H, W, 3] shape (negative dimensions count as 0: the
/// shape checks name them later), saturating instead of overflowing.
uint64_t ImagePixels(int64_t h, int64_t w) {
  const uint64_t uh = h > 0 ? static_cast<uint64_t>(h) : 0;
  const uint64_t uw = w > 0 ? static_cast<uint64_t>(w) : 0;
  if (uw != 0 && uh > std::numeric_limits<uint64_t>::max() / uw)
    return std::numeric_limits<uint64_t>::max();
  return uh * uw;
}

constexpr std::string_view kRaisePixels =
    "raise it with `avp serve segmentation --max-image-pixels N` (docs/segmentation-service.md)";
constexpr std::string_view kRaisePromptBytes =
    "raise it with `avp serve segmentation --max-prompt-bytes N` (docs/segmentation-service.md)";
constexpr std::string_view kRaisePromptPhrases =
    "raise it with `avp serve segmentation --max-prompt-phrases N` (docs/segmentation-service.md)";

/// The counts of inputs, outputs and parameters, and each parameter's size.
Status CheckRequestCounts(const InferRequest& request) {
  if (request.inputs.size() > kMaxRequestInputs) {
    return InvalidArgumentError(fmt::format(
        "the request has {} inputs: a segmentation request has at most {} (one of each: {})",
        request.inputs.size(), kMaxRequestInputs, JoinNames(SegmentationInputs())));
  }
  if (request.requested_outputs.size() > kMaxRequestedOutputs) {
    return InvalidArgumentError(fmt::format("the request asks for {} outputs: there are {} ({})",
                                            request.requested_outputs.size(), kMaxRequestedOutputs,
                                            JoinNames(SegmentationOutputs())));
  }
  if (request.parameters.size() > kMaxRequestParameters) {
    return InvalidArgumentError(
        fmt::format("the request has {} parameters: at most {} are accepted",
                    request.parameters.size(), kMaxRequestParameters));
  }
  for (const auto& [key, value] : request.parameters) {
    const auto* text = std::get_if<std::string>(&value);
    if (key.size() > kMaxStringParameterBytes ||
        (text != nullptr && text->size() > kMaxStringParameterBytes)) {
      return InvalidArgumentError(fmt::format(
          "parameter {} is {} bytes long (name and value): at most {} bytes each are accepted",
          QuoteText(key), key.size() + (text != nullptr ? text->size() : 0),
          kMaxStringParameterBytes));
    }
  }
  return Status::Ok();
}

/// Input 'image': one BYTES element whose PNG or JPEG header declares at most max_image_pixels.
Status CheckEncodedImageBudget(const Tensor& t, const RequestBudget& budget) {
  AVP_RETURN_IF_ERROR(ExpectTensor(t, "input", DataType::kBytes, {1}, "[1]", "(a PNG or JPEG)"));
  const std::string_view data(t.data);
  if (data.size() < 4 || ReadU32LeAt(data, 0) != data.size() - 4) {
    return InvalidArgumentError(fmt::format(
        "input 'image': its {} bytes are not one BYTES element (a 4-byte length, then the "
        "PNG or JPEG)",
        data.size()));
  }
  const std::optional<std::pair<uint32_t, uint32_t>> size = EncodedImageSize(data.substr(4));
  if (!size) {
    return InvalidArgumentError(
        fmt::format("input 'image': the {} bytes are not a PNG or JPEG image OpenCV can decode",
                    data.size() - 4));
  }
  return CheckLimit(
      fmt::format("input 'image' declaring {} x {} pixels", size->first, size->second),
      uint64_t{size->first} * size->second, "max_image_pixels", budget.max_image_pixels,
      kRaisePixels);
}

/// Phrases within the elements: each comma-separated non-empty piece counts.
uint64_t CountPhrases(const std::string& data, const std::vector<uint32_t>& lengths) {
  uint64_t phrases = 0;
  size_t pos = 0;
  for (const uint32_t len : lengths) {
    const std::string_view e(data.data() + pos + 4, len);
    pos += 4 + len;
    bool in_phrase = false;
    for (const char c : e) {
      if (c == ',') {
        in_phrase = false;
      } else if (!in_phrase && c != ' ' && c != '\t' && c != '\n' && c != '\r' && c != '\f' &&
                 c != '\v') {
        in_phrase = true;
        ++phrases;
      }
    }
  }
  return phrases;
}

/// Input 'prompt': its elements, bytes (joined) and phrases.
Status CheckPromptBudget(const Tensor& t, const RequestBudget& budget) {
  const std::vector<int64_t>& d = t.shape;
  if (d.size() == 1) {
    AVP_RETURN_IF_ERROR(CheckLimit("phrases (elements) of input 'prompt'",
                                   d[0] > 0 ? static_cast<uint64_t>(d[0]) : 0, "max_prompt_phrases",
                                   budget.max_prompt_phrases, kRaisePromptPhrases));
  }
  if (t.datatype != DataType::kBytes) return Status::Ok();  // named by the shape checks later
  // The budget covers the element contents; their 4-byte prefixes are the format's.
  const std::optional<std::vector<uint32_t>> lengths =
      BytesElementLengths(t.data, budget.max_prompt_phrases);
  if (!lengths) {
    AVP_RETURN_IF_ERROR(CheckLimit("input 'prompt'", t.data.size(), "max_prompt_bytes",
                                   budget.max_prompt_bytes + 4 * budget.max_prompt_phrases,
                                   kRaisePromptBytes));
    return Status::Ok();  // malformed: CheckTensor names it
  }
  uint64_t bytes = 0;
  for (const uint32_t len : *lengths) bytes += len;
  if (lengths->size() > 1) bytes += 2 * (lengths->size() - 1);  // joined with ", "
  AVP_RETURN_IF_ERROR(CheckLimit("input 'prompt'", bytes, "max_prompt_bytes",
                                 budget.max_prompt_bytes, kRaisePromptBytes));
  return CheckLimit("phrases in input 'prompt'", CountPhrases(t.data, *lengths),
                    "max_prompt_phrases", budget.max_prompt_phrases, kRaisePromptPhrases);
}

/// One known input against the budget.
Status CheckInputBudget(const Tensor& t, const RequestBudget& budget) {
  const std::vector<int64_t>& d = t.shape;
  if (t.name == names::kRgb && (d.size() == 3 || d.size() == 4)) {
    const size_t o = d.size() - 3;
    return CheckLimit(fmt::format("input 'rgb' of {} x {} pixels", d[o + 1], d[o]),
                      ImagePixels(d[o], d[o + 1]), "max_image_pixels", budget.max_image_pixels,
                      kRaisePixels);
  }
  if (t.name == names::kImage) return CheckEncodedImageBudget(t, budget);
  if ((t.name == names::kDepth || t.name == names::kInstanceIds || t.name == names::kClassIds) &&
      d.size() == 2) {
    return CheckLimit(fmt::format("input '{}' of {} x {} pixels", t.name, d[1], d[0]),
                      ImagePixels(d[0], d[1]), "max_image_pixels", budget.max_image_pixels,
                      kRaisePixels);
  }
  if (t.name == names::kFruits && !d.empty() && d[0] > kMaxFruits) {
    return InvalidArgumentError(fmt::format(
        "input 'fruits' has {} rows: at most {} (one per UINT16 instance id)", d[0], kMaxFruits));
  }
  if (t.name == names::kPrompt) return CheckPromptBudget(t, budget);
  return Status::Ok();
}

}  // namespace

std::optional<std::pair<uint32_t, uint32_t>> EncodedImageSize(std::string_view bytes) {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  const size_t n = bytes.size();
  static constexpr unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n >= 8 && std::equal(kPng, kPng + 8, p)) {
    // The first chunk must be IHDR: length (13), "IHDR", width, height (big-endian).
    if (n < 24 || std::string_view(bytes.data() + 12, 4) != "IHDR") return std::nullopt;
    return std::make_pair(ReadU32Be(p + 16), ReadU32Be(p + 20));
  }
  if (n >= 3 && p[0] == 0xff && p[1] == 0xd8 && p[2] == 0xff) {
    size_t pos = 2;
    while (pos + 4 <= n) {
      if (p[pos] != 0xff) return std::nullopt;
      const unsigned char marker = p[pos + 1];
      if (marker == 0xff) {  // fill byte
        ++pos;
        continue;
      }
      if (marker == 0x01 || (marker >= 0xd0 && marker <= 0xd7)) {  // no length
        pos += 2;
        continue;
      }
      if (marker == 0xd9 || marker == 0xda) return std::nullopt;  // end, or scan before a frame
      const size_t len = (size_t{p[pos + 2]} << 8) | p[pos + 3];
      const bool sof =
          marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc;
      if (sof) {
        // length (2), precision (1), height (2), width (2)
        if (len < 7 || pos + 9 > n) return std::nullopt;
        const uint32_t h = (uint32_t{p[pos + 5]} << 8) | p[pos + 6];
        const uint32_t w = (uint32_t{p[pos + 7]} << 8) | p[pos + 8];
        return std::make_pair(w, h);
      }
      if (len < 2) return std::nullopt;
      pos += 2 + len;
    }
  }
  return std::nullopt;
}

Status CheckRequestBudget(const InferRequest& request, const RequestBudget& budget) {
  AVP_RETURN_IF_ERROR(CheckRequestCounts(request));
  if (request.FindInput(names::kRgb) != nullptr && request.FindInput(names::kImage) != nullptr) {
    return InvalidArgumentError(codec::kBothImages);
  }
  const std::vector<TensorSpec>& specs = SegmentationInputs();
  for (const Tensor& t : request.inputs) {
    if (std::none_of(specs.begin(), specs.end(),
                     [&](const TensorSpec& spec) { return spec.name == t.name; })) {
      return InvalidArgumentError(fmt::format("unknown input {} {} {}; known inputs: {}",
                                              QuoteText(t.name), ToString(t.datatype),
                                              ShapeToString(t.shape), JoinNames(specs)));
    }
    AVP_RETURN_IF_ERROR(CheckInputBudget(t, budget));
  }
  return Status::Ok();
}

}  // namespace avp::segmentation_service

#include <algorithm>
#include <cstdint>
#include <limits>
#include <span>
#include <string>

#include <fmt/format.h>

#include <avp/io/image_limits.h>

namespace avp::io {

const Limit& MaxImagePixels() {
  static const Limit limit("max_image_pixels", uint64_t{64} << 20, "pixels",
                           "pixels of one decoded image (colour, depth, mask)");
  return limit;
}

namespace {

// Registered when the program starts, so `avp --limit max_image_pixels=N` knows it before the
// first image is read.
[[maybe_unused]] const Limit& kRegisterMaxImagePixels = MaxImagePixels();

uint32_t Be16(std::span<const uint8_t> b, size_t at) {
  return (uint32_t{b[at]} << 8) | uint32_t{b[at + 1]};
}
uint32_t Be32(std::span<const uint8_t> b, size_t at) {
  return (uint32_t{b[at]} << 24) | (uint32_t{b[at + 1]} << 16) | (uint32_t{b[at + 2]} << 8) |
         uint32_t{b[at + 3]};
}
uint32_t Le16(std::span<const uint8_t> b, size_t at) {
  return uint32_t{b[at]} | (uint32_t{b[at + 1]} << 8);
}
uint32_t Le32(std::span<const uint8_t> b, size_t at) {
  return uint32_t{b[at]} | (uint32_t{b[at + 1]} << 8) | (uint32_t{b[at + 2]} << 16) |
         (uint32_t{b[at + 3]} << 24);
}

constexpr uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

Result<ImageHeader> PngHeader(std::span<const uint8_t> b) {
  // Signature, IHDR length (13), "IHDR", width, height.
  if (b.size() < 24) {
    return ParseError(fmt::format("PNG header truncated ({} bytes, its IHDR needs 24)", b.size()));
  }
  if (Be32(b, 8) != 13 || b[12] != 'I' || b[13] != 'H' || b[14] != 'D' || b[15] != 'R') {
    return ParseError("PNG does not start with an IHDR chunk of 13 bytes");
  }
  return ImageHeader{"PNG", Be32(b, 16), Be32(b, 20)};
}

Result<ImageHeader> JpegHeader(std::span<const uint8_t> b) {
  size_t at = 2;  // after SOI
  while (true) {
    // Markers: 0xFF, any number of 0xFF fill bytes, the marker code.
    if (at >= b.size() || b[at] != 0xFF) {
      return ParseError(fmt::format("JPEG header: no marker at byte {} before a frame header", at));
    }
    while (at < b.size() && b[at] == 0xFF) ++at;
    if (at >= b.size()) return ParseError("JPEG header truncated before a frame header");
    const uint8_t marker = b[at++];
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD8)) continue;  // no length
    if (marker == 0xD9 || marker == 0xDA) {
      return ParseError(fmt::format("JPEG has no frame header (SOF) before its {}",
                                    marker == 0xD9 ? "end (EOI)" : "scan (SOS)"));
    }
    if (at + 2 > b.size()) return ParseError("JPEG header truncated in a segment length");
    const uint32_t length = Be16(b, at);
    if (length < 2) {
      return ParseError(
          fmt::format("JPEG segment 0xFF{:02X} at byte {} has length {}", marker, at, length));
    }
    const bool sof =
        marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (sof) {
      if (length < 8 || at + 7 > b.size()) {
        return ParseError("JPEG frame header (SOF) truncated");
      }
      const uint32_t height = Be16(b, at + 3);
      const uint32_t width = Be16(b, at + 5);
      return ImageHeader{"JPEG", width, height};
    }
    at += length;
  }
}

Result<ImageHeader> BmpHeader(std::span<const uint8_t> b) {
  if (b.size() < 26) {
    return ParseError(fmt::format("BMP header truncated ({} bytes)", b.size()));
  }
  const uint32_t dib = Le32(b, 14);
  if (dib == 12) return ImageHeader{"BMP", Le16(b, 18), Le16(b, 20)};
  if (dib < 40) return ParseError(fmt::format("BMP header of unknown size {}", dib));
  const auto width = static_cast<int32_t>(Le32(b, 18));
  const auto height = static_cast<int32_t>(Le32(b, 22));
  // A negative height is a top-down image.
  if (width <= 0 || height == std::numeric_limits<int32_t>::min()) {
    return ParseError(fmt::format("BMP header declares {} x {} pixels", width, height));
  }
  return ImageHeader{"BMP", static_cast<uint64_t>(width),
                     static_cast<uint64_t>(height < 0 ? -int64_t{height} : int64_t{height})};
}

bool StartsWith(std::span<const uint8_t> b, std::string_view prefix) {
  if (b.size() < prefix.size()) return false;
  for (size_t i = 0; i < prefix.size(); ++i) {
    if (b[i] != static_cast<uint8_t>(prefix[i])) return false;
  }
  return true;
}

/// PNM (P1..P6): "P6", then width and height as decimal text, separated by whitespace and
/// "#" comments (to the end of the line), read exactly as OpenCV's PxM decoder reads them (a
/// header read otherwise would check another size than the one OpenCV allocates). Safe on any
/// bytes: at most 10 digits per number.
Result<ImageHeader> PnmHeader(std::span<const uint8_t> b) {
  size_t at = 2;
  uint64_t sides[2] = {0, 0};
  for (uint64_t& side : sides) {
    while (at < b.size()) {
      if (b[at] == '#') {
        while (at < b.size() && b[at] != '\n' && b[at] != '\r') ++at;
      } else if (b[at] == ' ' || b[at] == '\t' || b[at] == '\n' || b[at] == '\r' || b[at] == '\v' ||
                 b[at] == '\f') {
        ++at;
      } else {
        break;
      }
    }
    size_t digits = 0;
    while (at < b.size() && b[at] >= '0' && b[at] <= '9') {
      if (++digits > 10) return ParseError("PNM header: a side of more than 10 digits");
      side = side * 10 + static_cast<uint64_t>(b[at] - '0');
      ++at;
    }
    if (digits == 0) return ParseError("PNM header: truncated or malformed width/height");
    // As OpenCV's reader does, the byte that ends a number is consumed with it, whatever it is:
    // in "100000#10500 ..." the '#' starts no comment and the height is 10500.
    if (at < b.size()) ++at;
  }
  return ImageHeader{"PNM", sides[0], sides[1]};
}

/// Formats OpenCV would decode but DecodeImage does not accept, by signature.
std::string_view OtherFormat(std::span<const uint8_t> b) {
  if (StartsWith(b, "II*\0") || StartsWith(b, std::string_view("MM\0*", 4))) return "TIFF";
  if (StartsWith(b, "RIFF") && b.size() >= 12 && b[8] == 'W' && b[9] == 'E' && b[10] == 'B' &&
      b[11] == 'P') {
    return "WebP";
  }
  if (StartsWith(b, "\x76\x2f\x31\x01")) return "OpenEXR";
  if (StartsWith(b, "#?RADIANCE") || StartsWith(b, "#?RGBE")) return "Radiance HDR";
  if (StartsWith(b, std::string_view("\0\0\0\x0cjP  ", 8)) || StartsWith(b, "\xff\x4f\xff\x51")) {
    return "JPEG 2000";
  }
  if (b.size() >= 2 && b[0] == 'P' && b[1] == '7') return "PAM";
  if (b.size() >= 2 && b[0] == 'P' && (b[1] == 'F' || b[1] == 'f')) return "PFM";
  if (StartsWith(b, "\x59\xa6\x6a\x95")) return "Sun raster";
  if (StartsWith(b, "GIF8")) return "GIF";
  return {};
}

}  // namespace

Status CheckJpegScans(std::span<const uint8_t> b, std::string_view what) {
  if (b.size() < 2 || b[0] != 0xFF || b[1] != 0xD8) return Status::Ok();
  size_t at = 2;
  size_t scans = 0;
  bool ended = false;  // the end-of-image marker was seen
  while (at + 4 <= b.size()) {
    if (b[at] != 0xFF) break;  // not a marker: the decoder says what is wrong
    while (at < b.size() && b[at] == 0xFF) ++at;
    if (at >= b.size()) break;
    const uint8_t marker = b[at++];
    if (marker == 0xD9) {  // EOI
      ended = true;
      break;
    }
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD8)) continue;
    if (at + 2 > b.size()) break;
    const uint32_t length = Be16(b, at);
    if (length < 2) break;
    at += length;
    if (marker != 0xDA) continue;
    if (++scans > kMaxJpegScans) {
      return ResourceExhaustedError(fmt::format(
          "JPEG {} has more than {} scans (each one a pass over the whole image): refused", what,
          kMaxJpegScans));
    }
    // The entropy-coded data: up to a marker that is neither a stuffed 0xFF00 nor a restart.
    while (at + 1 < b.size() &&
           !(b[at] == 0xFF && b[at + 1] != 0x00 && !(b[at + 1] >= 0xD0 && b[at + 1] <= 0xD7))) {
      ++at;
    }
  }
  // A file cut short (a partial download or copy) loses its end-of-image marker: libjpeg decodes
  // it anyway, grey below the cut, with only a warning. Refused, as a truncated PNG is.
  for (size_t i = std::min(at, b.size()); !ended && i + 1 < b.size(); ++i) {
    ended = b[i] == 0xFF && b[i + 1] == 0xD9;
  }
  if (scans > 0 && !ended) {
    return InvalidArgumentError(fmt::format(
        "JPEG {} is truncated: its {} bytes end before the end-of-image marker (a partial "
        "download or copy?)",
        what, b.size()));
  }
  return Status::Ok();
}

Status CheckImageSize(uint64_t width, uint64_t height, std::string_view what) {
  if (width == 0 || height == 0) {
    return InvalidArgumentError(fmt::format(
        "{} declares {} x {} pixels: an image needs at least one", what, width, height));
  }
  constexpr uint64_t kMaxInt = static_cast<uint64_t>(std::numeric_limits<int>::max());
  if (width > kMaxInt || height > kMaxInt) {
    return InvalidArgumentError(fmt::format(
        "{} declares {} x {} pixels: a side of more than {} pixels", what, width, height, kMaxInt));
  }
  return MaxImagePixels().Check(fmt::format("{} of {} x {} pixels", what, width, height),
                                width * height);
}

Result<ImageHeader> ReadImageHeader(std::span<const uint8_t> encoded) {
  const std::span<const uint8_t> b = encoded;
  if (b.size() >= 8 && std::equal(kPngSignature, kPngSignature + 8, b.begin())) {
    return PngHeader(b);
  }
  if (b.size() >= 3 && b[0] == 0xFF && b[1] == 0xD8 && b[2] == 0xFF) return JpegHeader(b);
  if (StartsWith(b, "BM")) return BmpHeader(b);
  if (b.size() >= 2 && b[0] == 'P' && b[1] >= '1' && b[1] <= '6') return PnmHeader(b);
  if (const std::string_view other = OtherFormat(b); !other.empty()) {
    return ParseError(
        fmt::format("{} images are not accepted (only PNG, JPEG, BMP and PNM are)", other));
  }
  return ParseError("not a PNG, JPEG, BMP or PNM image");
}

}  // namespace avp::io

#pragma once

// Budgets for decoding images (docs/limits.md): the size an image declares is read from its
// header and checked before any pixel is decoded, so a small file that declares 20000 x 20000
// pixels is refused with ResourceExhausted instead of allocating gigabytes.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include <avp/core/limits.h>
#include <avp/core/status.h>

namespace avp::io {

/// max_image_pixels: pixels of one decoded image (colour, depth, mask), 64 Mi (67108864, e.g.
/// 8192 x 8192) by default. Raise it with `avp --limit max_image_pixels=N`.
const Limit& MaxImagePixels();

/// OK when an image of `width` x `height` pixels may be decoded: both >= 1, both fit an int and
/// width * height <= MaxImagePixels(). InvalidArgument for a zero or oversized side,
/// ResourceExhausted naming max_image_pixels otherwise; `what` names the image in the message
/// ("PNG image 'a.png'").
Status CheckImageSize(uint64_t width, uint64_t height, std::string_view what);

/// Most scans a JPEG may have: a progressive JPEG decodes every scan over the whole image, so a
/// small file of thousands of tiny scans costs minutes of CPU (real encoders write about 10).
inline constexpr size_t kMaxJpegScans = 256;

/// OK unless `encoded` is a JPEG with more than kMaxJpegScans scans (ResourceExhausted naming
/// `what`); a walk over its markers, no decoding. Safe on any bytes.
Status CheckJpegScans(std::span<const uint8_t> encoded, std::string_view what);

/// What an encoded image says about itself in its header.
struct ImageHeader {
  std::string format;  ///< "PNG", "JPEG", "BMP" or "PNM"
  uint64_t width = 0;
  uint64_t height = 0;
};

/// The format and size an encoded image declares, read from its header without decoding a pixel:
/// PNG (IHDR), JPEG (the first SOF marker), BMP (the DIB header), PNM P1..P6 (its text header).
/// ParseError for anything else
/// (other formats OpenCV could decode, such as TIFF or WebP, are not accepted: their headers are
/// not checked) and for a truncated or malformed header. Safe on any bytes.
Result<ImageHeader> ReadImageHeader(std::span<const uint8_t> encoded);

}  // namespace avp::io

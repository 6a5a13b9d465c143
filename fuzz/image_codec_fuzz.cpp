// Fuzz target: the image decoder (io/image_codec.h DecodeImage: PNG, JPEG and whatever else
// OpenCV's imgcodecs reads) on any bytes. Property: a decoded image is non-empty and holds
// width x height x 3 bytes, and PNG-encoding it decodes to the same image.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <avp/io/image_codec.h>

#include "fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  avp::Result<avp::ImageRgb8> image = avp::io::DecodeImage(std::span<const uint8_t>(data, size));
  if (!image.ok()) return 0;
  const size_t w = static_cast<size_t>(image->width());
  const size_t h = static_cast<size_t>(image->height());
  if (w == 0 || h == 0 || image->data().size() != w * h * 3) {
    avp::fuzz::Fail("DecodeImage returned an image whose size and data disagree");
  }
  // Re-encoding is as costly as decoding: only for small images, to keep the fuzzer fast.
  if (w * h <= 64 * 64) {
    avp::Result<std::vector<uint8_t>> png = avp::io::EncodePng(*image);
    if (!png.ok()) avp::fuzz::Fail("EncodePng failed on a decoded image");
    avp::Result<avp::ImageRgb8> back = avp::io::DecodeImage(*png);
    if (!back.ok() || back->width() != image->width() || back->height() != image->height() ||
        !std::equal(back->data().begin(), back->data().end(), image->data().begin())) {
      avp::fuzz::Fail("PNG round trip of a decoded image changed it");
    }
  }
  return 0;
}

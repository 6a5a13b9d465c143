#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

#include <avp/core/image.h>
#include <avp/core/status.h>

// Encoded images (JPEG, PNG, anything OpenCV's imgcodecs reads) in memory and in files, for
// photos given to the segmenters and images sent to the segmentation service. (Plain PNG files of
// known formats: png.h.)
namespace avp::io {

/// Reads a JPEG or PNG (anything OpenCV's imgcodecs decodes) as 8-bit RGB: grey images are
/// expanded, alpha is dropped, 16-bit samples are reduced, and the EXIF orientation is applied
/// (as cv2.imread in the reference).
/// @return NotFound when the file does not exist, IoError when it cannot be read, ParseError
///   when it is empty or undecodable; every message names the file.
Result<ImageRgb8> ReadImageFile(const std::filesystem::path& path);

/// Decodes an encoded image held in memory, as ReadImageFile.
/// @return ParseError "undecodable image (N bytes)" when the bytes are empty or not an image.
Result<ImageRgb8> DecodeImage(std::span<const uint8_t> encoded);

/// Encodes an RGB image as PNG bytes (lossless, so DecodeImage gives the image back).
/// @return InvalidArgument for an empty image; Internal when the encoder fails.
Result<std::vector<uint8_t>> EncodePng(const ImageRgb8& image);

/// Encodes an RGB image as JPEG bytes at `quality` (0 - 100; lossy).
/// @return InvalidArgument for an empty image or a quality outside [0, 100]; Internal when the
///   encoder fails.
Result<std::vector<uint8_t>> EncodeJpeg(const ImageRgb8& image, int quality = 95);

/// Writes an RGB image to `path` as PNG; the parent folder must exist.
/// @return EncodePng's errors, or IoError naming the file when it cannot be written.
Status WritePngFile(const ImageRgb8& image, const std::filesystem::path& path);

}  // namespace avp::io

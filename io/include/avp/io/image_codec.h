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

/// Reads a PNG, JPEG, BMP or PNM through OpenCV's imgcodecs as 8-bit RGB: grey images are expanded,
/// alpha is dropped, 16-bit samples are reduced, and the EXIF orientation is applied (as
/// cv2.imread in the reference). The size the header declares is checked (io/image_limits.h:
/// max_image_pixels) before any pixel is decoded, and the decoded size against the header.
/// @return NotFound when the file does not exist, InvalidArgument for a folder, ResourceExhausted
///   for a file over max_file_bytes or an image over max_image_pixels, IoError when it cannot be
///   read, ParseError when it is empty, of another format (TIFF, WebP, ...) or undecodable; every
///   message names the file.
Result<ImageRgb8> ReadImageFile(const std::filesystem::path& path);

/// Decodes an encoded image held in memory, as ReadImageFile. Safe on any bytes.
/// @return ParseError "undecodable image (N bytes)[: reason]" when the bytes are empty, not a
///   PNG, JPEG, BMP or PNM, or undecodable; ResourceExhausted (max_image_pixels) for an image whose
///   header declares too many pixels, before decoding.
Result<ImageRgb8> DecodeImage(std::span<const uint8_t> encoded);

/// Encodes an RGB image as PNG bytes (lossless, so DecodeImage gives the image back).
/// @return InvalidArgument for an empty image; Internal when the encoder fails.
Result<std::vector<uint8_t>> EncodePng(const ImageRgb8& image);

/// Encodes an RGB image as JPEG bytes at `quality` (0 - 100; lossy).
/// @return InvalidArgument for an empty image or a quality outside [0, 100]; Internal when the
///   encoder fails.
Result<std::vector<uint8_t>> EncodeJpeg(const ImageRgb8& image, int quality = 95);

/// Writes an RGB image to `path` as PNG, atomically (io::WriteFileAtomic: a temporary name,
/// flushed, renamed; parent folders created).
/// @return EncodePng's errors, or IoError naming the file when it cannot be written.
Status WritePngFile(const ImageRgb8& image, const std::filesystem::path& path);

}  // namespace avp::io

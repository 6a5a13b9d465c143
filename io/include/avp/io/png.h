#pragma once

#include <cstdint>
#include <filesystem>

#include <avp/core/image.h>
#include <avp/core/status.h>

namespace avp::io {

/// PNG files through libpng. Writers encode in memory and write atomically (io::WriteFileAtomic:
/// a temporary name, flushed, renamed; parent folders created). Readers check the file
/// (io::CheckReadableFile: NotFound, a folder, max_file_bytes) and the size in the header
/// (max_image_pixels, io/image_limits.h: ResourceExhausted) before any row is allocated; every
/// failure is a Status naming the file (never a crash on a corrupt or truncated file).
Status WritePngRgb8(const std::filesystem::path& path, const ImageRgb8& image);
Status WritePngGray8(const std::filesystem::path& path, const Image<uint8_t>& image);
/// 16-bit greyscale, big-endian on disk as PNG requires.
Status WritePngGray16(const std::filesystem::path& path, const Image<uint16_t>& image);

/// Reads an 8-bit RGB PNG (greyscale, palette and alpha are converted; 16-bit is reduced).
Result<ImageRgb8> ReadPngRgb8(const std::filesystem::path& path);
/// Reads a single-channel PNG of exactly 8 bits.
Result<Image<uint8_t>> ReadPngGray8(const std::filesystem::path& path);
/// Reads a single-channel PNG of exactly 16 bits.
Result<Image<uint16_t>> ReadPngGray16(const std::filesystem::path& path);

}  // namespace avp::io

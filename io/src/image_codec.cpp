#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <optional>
#include <system_error>
#include <vector>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <avp/io/image_codec.h>

namespace avp::io {

namespace {

// Decodes to 8-bit RGB; an empty result when OpenCV cannot decode the bytes.
std::optional<ImageRgb8> DecodeToRgb(std::span<const uint8_t> encoded) {
  if (encoded.empty() || encoded.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
    return std::nullopt;
  }
  cv::Mat bgr;
  try {
    const cv::Mat buffer(1, static_cast<int>(encoded.size()), CV_8UC1,
                         const_cast<uint8_t*>(encoded.data()));
    bgr = cv::imdecode(buffer, cv::IMREAD_COLOR);
  } catch (const cv::Exception&) {
    return std::nullopt;
  }
  if (bgr.empty() || bgr.type() != CV_8UC3) return std::nullopt;
  ImageRgb8 rgb(bgr.cols, bgr.rows);
  cv::Mat out(bgr.rows, bgr.cols, CV_8UC3, rgb.data().data());
  cv::cvtColor(bgr, out, cv::COLOR_BGR2RGB);
  return rgb;
}

}  // namespace

Result<ImageRgb8> ReadImageFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return NotFoundError(fmt::format("image file {} does not exist", path.string()));
  }
  if (!std::filesystem::is_regular_file(path, ec)) {
    return IoError(fmt::format("image file {} is not a regular file", path.string()));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return IoError(fmt::format("cannot open image file {}", path.string()));
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                   std::istreambuf_iterator<char>());
  if (in.bad()) return IoError(fmt::format("cannot read image file {}", path.string()));
  if (bytes.empty()) return ParseError(fmt::format("image file {} is empty", path.string()));
  std::optional<ImageRgb8> rgb = DecodeToRgb(bytes);
  if (!rgb) {
    return ParseError(fmt::format("image file {} is not a decodable image ({} bytes)",
                                  path.string(), bytes.size()));
  }
  return std::move(*rgb);
}

Result<ImageRgb8> DecodeImage(std::span<const uint8_t> encoded) {
  std::optional<ImageRgb8> rgb = DecodeToRgb(encoded);
  if (!rgb) return ParseError(fmt::format("undecodable image ({} bytes)", encoded.size()));
  return std::move(*rgb);
}

namespace {

// `ext` ".png" or ".jpg"; `name` for the messages ("PNG", "JPEG").
Result<std::vector<uint8_t>> Encode(const ImageRgb8& image, const char* ext, const char* name,
                                    const std::vector<int>& params) {
  if (image.empty()) {
    return InvalidArgumentError(fmt::format("cannot encode an empty image ({} x {}) as {}",
                                            image.width(), image.height(), name));
  }
  const cv::Mat rgb(image.height(), image.width(), CV_8UC3,
                    const_cast<uint8_t*>(image.data().data()));
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  std::vector<uint8_t> bytes;
  bool ok = false;
  try {
    ok = cv::imencode(ext, bgr, bytes, params);
  } catch (const cv::Exception& e) {
    return InternalError(fmt::format("{} encoding of a {} x {} image failed: {}", name,
                                     image.width(), image.height(), e.what()));
  }
  if (!ok) {
    return InternalError(
        fmt::format("{} encoding of a {} x {} image failed", name, image.width(), image.height()));
  }
  return bytes;
}

}  // namespace

Result<std::vector<uint8_t>> EncodePng(const ImageRgb8& image) {
  return Encode(image, ".png", "PNG", {});
}

Result<std::vector<uint8_t>> EncodeJpeg(const ImageRgb8& image, int quality) {
  if (quality < 0 || quality > 100) {
    return InvalidArgumentError(fmt::format("JPEG quality ({}) must be in [0, 100]", quality));
  }
  return Encode(image, ".jpg", "JPEG", {cv::IMWRITE_JPEG_QUALITY, quality});
}

Status WritePngFile(const ImageRgb8& image, const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(const std::vector<uint8_t> bytes, EncodePng(image));
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return IoError(fmt::format("cannot open {} for writing", path.string()));
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) return IoError(fmt::format("cannot write PNG file {}", path.string()));
  return Status::Ok();
}

}  // namespace avp::io

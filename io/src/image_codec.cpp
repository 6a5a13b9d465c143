#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <avp/io/file.h>
#include <avp/io/file_kind.h>
#include <avp/io/image_codec.h>
#include <avp/io/image_limits.h>

namespace avp::io {

namespace {

// Decodes to 8-bit RGB after checking the size the header declares (ReadImageHeader,
// CheckImageSize) and before any pixel is decoded; the decoded size is checked against the header.
// `what` names the image in errors ("image file 'a.png'", "image"): ParseError
// "undecodable <what> (N bytes)[: reason]", ResourceExhausted from CheckImageSize.
Result<ImageRgb8> DecodeToRgb(std::span<const uint8_t> encoded, std::string_view what) {
  const auto undecodable = [&](std::string_view reason) {
    return ParseError(fmt::format("undecodable {} ({} bytes){}{}", what, encoded.size(),
                                  reason.empty() ? "" : ": ", reason));
  };
  if (encoded.empty()) return undecodable("");
  if (encoded.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
    return ResourceExhaustedError(
        fmt::format("{} of {} bytes is larger than an encoded image may be ({} bytes)", what,
                    encoded.size(), std::numeric_limits<int>::max()));
  }
  Result<ImageHeader> header = ReadImageHeader(encoded);
  if (!header.ok()) {
    // Another kind of file where an image was expected is named ("an MCAP recording").
    const std::string kind = DescribeFileKind(
        std::string_view(reinterpret_cast<const char*>(encoded.data()), encoded.size()));
    return undecodable(kind.empty() || kind == "a binary file"
                           ? header.status().message()
                           : fmt::format("{} (it is {})", header.status().message(), kind));
  }
  AVP_RETURN_IF_ERROR(
      CheckImageSize(header->width, header->height, fmt::format("{} {}", header->format, what)));
  if (header->format == "JPEG") AVP_RETURN_IF_ERROR(CheckJpegScans(encoded, what));
  cv::Mat bgr;
  try {
    const cv::Mat buffer(1, static_cast<int>(encoded.size()), CV_8UC1,
                         const_cast<uint8_t*>(encoded.data()));
    bgr = cv::imdecode(buffer, cv::IMREAD_COLOR);
  } catch (const cv::Exception&) {
    return undecodable("");
  }
  if (bgr.empty()) return undecodable("");
  // What OpenCV returns must be what the header declared (EXIF orientation may swap the sides).
  const auto w = static_cast<uint64_t>(bgr.cols);
  const auto h = static_cast<uint64_t>(bgr.rows);
  const bool same =
      (w == header->width && h == header->height) || (w == header->height && h == header->width);
  if (bgr.type() != CV_8UC3 || !same) {
    return undecodable(
        fmt::format("the {} header declares {} x {} pixels, OpenCV decoded {} x {} of type {}",
                    header->format, header->width, header->height, w, h, bgr.type()));
  }
  ImageRgb8 rgb(bgr.cols, bgr.rows);
  cv::Mat out(bgr.rows, bgr.cols, CV_8UC3, rgb.data().data());
  cv::cvtColor(bgr, out, cv::COLOR_BGR2RGB);
  return rgb;
}

}  // namespace

Result<ImageRgb8> ReadImageFile(const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(const std::string bytes, ReadFileBounded(path, "image file"));
  if (bytes.empty()) return ParseError(fmt::format("image file {} is empty", path.string()));
  return DecodeToRgb(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
      fmt::format("image file {}", path.string()));
}

Result<ImageRgb8> DecodeImage(std::span<const uint8_t> encoded) {
  return DecodeToRgb(encoded, "image");
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
  return WriteFileAtomic(
      path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()),
      "PNG file");
}

}  // namespace avp::io

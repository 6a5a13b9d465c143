#include "avp/ros/msg/images.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/ros/msg/convert.h>

namespace avp::ros::msg {
namespace {

uint16_t LoadU16(const uint8_t* p, bool big) {
  return big ? static_cast<uint16_t>((p[0] << 8) | p[1])
             : static_cast<uint16_t>(p[0] | (p[1] << 8));
}

float LoadF32(const uint8_t* p, bool big) {
  uint8_t b[4];
  std::memcpy(b, p, 4);
  if (big) {
    std::swap(b[0], b[3]);
    std::swap(b[1], b[2]);
  }
  float z;
  std::memcpy(&z, b, 4);
  return z;
}

bool IsMillimetres(const Image& msg) { return msg.encoding == "16UC1" || msg.encoding == "mono16"; }

/// The depth rule for one 32FC1 value: the depth, 0 for no return, or an error.
Status DepthValue(float& z, const Image& msg, std::string_view topic, uint32_t u, uint32_t v) {
  if (!std::isfinite(z) || z == 0.0f) {
    z = 0.0f;  // NaN, +-inf, +-0: no return
    return Status::Ok();
  }
  if (z < 0.0f || !std::isnormal(z)) {
    return InvalidArgumentError(fmt::format(
        "{}: depth {} m at pixel ({}, {}) (stamp {}): a 32FC1 depth must be positive, or NaN, "
        "inf or 0 for no return",
        topic, z, u, v, FormatStamp(msg.header.stamp.ToNanoseconds())));
  }
  return Status::Ok();
}

/// The encoding's bytes per pixel and channel order (r, g, b offsets), or an error.
struct ColorLayout {
  int bpp = 0;
  int r = 0, g = 1, b = 2;
};
Result<ColorLayout> ColorLayoutOf(const Image& msg, std::string_view topic) {
  const std::string& e = msg.encoding;
  if (e == "rgb8") return ColorLayout{3, 0, 1, 2};
  if (e == "bgr8") return ColorLayout{3, 2, 1, 0};
  if (e == "rgba8") return ColorLayout{4, 0, 1, 2};
  if (e == "bgra8") return ColorLayout{4, 2, 1, 0};
  if (e == "mono8") return ColorLayout{1, 0, 0, 0};
  return InvalidArgumentError(fmt::format("{}: colour encoding {} is not supported ({})", topic,
                                          QuoteText(e), kColorEncodings));
}

Status CheckDepthEncoding(const Image& msg, std::string_view topic) {
  if (!IsMillimetres(msg) && msg.encoding != "32FC1") {
    return InvalidArgumentError(fmt::format("{}: depth encoding {} is not supported ({})", topic,
                                            QuoteText(msg.encoding), kDepthEncodings));
  }
  return CheckImageLayout(msg, topic, IsMillimetres(msg) ? 2 : 4);
}

template <class T>
Image RawImage(const ::avp::Image<T, 1>& image, std::string_view encoding, const Header& header) {
  Image m;
  m.header = header;
  m.height = static_cast<uint32_t>(image.height());
  m.width = static_cast<uint32_t>(image.width());
  m.encoding = std::string(encoding);
  m.is_bigendian = 0;
  m.step = static_cast<uint32_t>(image.width() * static_cast<int>(sizeof(T)));
  const auto data = image.data();
  m.data.resize(data.size_bytes());
  // avp runs on little-endian hosts (as the CDR writer): the values' bytes as they are.
  static_assert(std::endian::native == std::endian::little);
  std::memcpy(m.data.data(), data.data(), data.size_bytes());
  return m;
}

}  // namespace

Status CheckImageLayout(const Image& msg, std::string_view topic, int bytes_per_pixel) {
  if (msg.width == 0 || msg.height == 0 || msg.width > kMaxImageSide ||
      msg.height > kMaxImageSide) {
    return InvalidArgumentError(fmt::format("{}: image size {}x{} is out of range (1..{})", topic,
                                            msg.width, msg.height, kMaxImageSide));
  }
  const uint64_t row = uint64_t{msg.width} * static_cast<uint64_t>(bytes_per_pixel);
  if (msg.step < row) {
    return InvalidArgumentError(
        fmt::format("{}: step {} is shorter than a row of {} {} pixels ({} bytes)", topic, msg.step,
                    msg.width, QuoteText(msg.encoding), row));
  }
  const uint64_t expected = uint64_t{msg.step} * msg.height;
  if (msg.data.size() != expected) {
    return InvalidArgumentError(fmt::format("{}: data holds {} bytes, but step {} x height {} = {}",
                                            topic, msg.data.size(), msg.step, msg.height,
                                            expected));
  }
  return Status::Ok();
}

Status CheckColorImage(const Image& msg, std::string_view topic) {
  AVP_ASSIGN_OR_RETURN(const ColorLayout layout, ColorLayoutOf(msg, topic));
  return CheckImageLayout(msg, topic, layout.bpp);
}

Status CheckDepthImage(const Image& msg, std::string_view topic) {
  AVP_RETURN_IF_ERROR(CheckDepthEncoding(msg, topic));
  if (IsMillimetres(msg)) return Status::Ok();  // every uint16 is a depth or 0
  const bool big = msg.is_bigendian != 0;
  for (uint32_t v = 0; v < msg.height; ++v) {
    const uint8_t* row = msg.data.data() + static_cast<size_t>(v) * msg.step;
    for (uint32_t u = 0; u < msg.width; ++u) {
      float z = LoadF32(row + 4 * static_cast<size_t>(u), big);
      AVP_RETURN_IF_ERROR(DepthValue(z, msg, topic, u, v));
    }
  }
  return Status::Ok();
}

Result<ImageRgb8> ColorFromImage(const Image& msg, std::string_view topic) {
  AVP_ASSIGN_OR_RETURN(const ColorLayout layout, ColorLayoutOf(msg, topic));
  AVP_RETURN_IF_ERROR(CheckImageLayout(msg, topic, layout.bpp));
  const int w = static_cast<int>(msg.width);
  const int h = static_cast<int>(msg.height);
  ImageRgb8 out(w, h);
  for (int v = 0; v < h; ++v) {
    const uint8_t* row = msg.data.data() + static_cast<size_t>(v) * msg.step;
    for (int u = 0; u < w; ++u) {
      const uint8_t* p = row + static_cast<size_t>(layout.bpp) * static_cast<size_t>(u);
      out.at(u, v, 0) = p[layout.r];
      out.at(u, v, 1) = p[layout.g];
      out.at(u, v, 2) = p[layout.b];
    }
  }
  return out;
}

Result<DepthImage> DepthFromImage(const Image& msg, std::string_view topic) {
  AVP_RETURN_IF_ERROR(CheckDepthEncoding(msg, topic));
  const bool mm = IsMillimetres(msg);
  const bool big = msg.is_bigendian != 0;
  const int w = static_cast<int>(msg.width);
  const int h = static_cast<int>(msg.height);
  DepthImage out(w, h);
  for (int v = 0; v < h; ++v) {
    const uint8_t* row = msg.data.data() + static_cast<size_t>(v) * msg.step;
    for (int u = 0; u < w; ++u) {
      if (mm) {
        out.at(u, v) = static_cast<float>(LoadU16(row + 2 * static_cast<size_t>(u), big)) * 0.001f;
        continue;
      }
      float z = LoadF32(row + 4 * static_cast<size_t>(u), big);
      AVP_RETURN_IF_ERROR(
          DepthValue(z, msg, topic, static_cast<uint32_t>(u), static_cast<uint32_t>(v)));
      out.at(u, v) = z;
    }
  }
  return out;
}

Result<InstanceImage> InstanceIdsFromImage(const Image& msg, std::string_view topic) {
  if (!IsMillimetres(msg)) {
    return InvalidArgumentError(fmt::format("{}: encoding {} (16UC1 or mono16 instance ids)", topic,
                                            QuoteText(msg.encoding)));
  }
  AVP_RETURN_IF_ERROR(CheckImageLayout(msg, topic, 2));
  const bool big = msg.is_bigendian != 0;
  InstanceImage out(static_cast<int>(msg.width), static_cast<int>(msg.height));
  for (int v = 0; v < out.height(); ++v) {
    const uint8_t* row = msg.data.data() + static_cast<size_t>(v) * msg.step;
    for (int u = 0; u < out.width(); ++u) {
      out.at(u, v) = LoadU16(row + 2 * static_cast<size_t>(u), big);
    }
  }
  return out;
}

Result<ClassImage> ClassIdsFromImage(const Image& msg, std::string_view topic) {
  if (msg.encoding != "mono8" && msg.encoding != "8UC1") {
    return InvalidArgumentError(
        fmt::format("{}: encoding {} (mono8 or 8UC1 classes)", topic, QuoteText(msg.encoding)));
  }
  AVP_RETURN_IF_ERROR(CheckImageLayout(msg, topic, 1));
  ClassImage out(static_cast<int>(msg.width), static_cast<int>(msg.height));
  for (int v = 0; v < out.height(); ++v) {
    const uint8_t* row = msg.data.data() + static_cast<size_t>(v) * msg.step;
    for (int u = 0; u < out.width(); ++u) out.at(u, v) = row[u];
  }
  return out;
}

Result<SimulatorLabels> LabelsFromImages(const Image& instance, const Image& classes, int width,
                                         int height, std::string_view prefix) {
  SimulatorLabels labels;
  AVP_ASSIGN_OR_RETURN(labels.instance_ids,
                       InstanceIdsFromImage(instance, fmt::format("{}/instance", prefix)));
  AVP_ASSIGN_OR_RETURN(labels.class_ids,
                       ClassIdsFromImage(classes, fmt::format("{}/class", prefix)));
  if (!labels.instance_ids.SameSizeAs(width, height) ||
      !labels.class_ids.SameSizeAs(width, height)) {
    return InvalidArgumentError(
        fmt::format("{}: label images {}x{} and {}x{} do not match the {}x{} colour image", prefix,
                    instance.width, instance.height, classes.width, classes.height, width, height));
  }
  return labels;
}

Image ToColorImage(const ImageRgb8& rgb, const Header& header) {
  Image m;
  m.header = header;
  m.height = static_cast<uint32_t>(rgb.height());
  m.width = static_cast<uint32_t>(rgb.width());
  m.encoding = "rgb8";
  m.step = static_cast<uint32_t>(rgb.width() * 3);
  m.data.assign(rgb.data().begin(), rgb.data().end());
  return m;
}

Image ToDepthImage(const DepthImage& depth_m, const Header& header, DepthEncoding encoding) {
  if (encoding == DepthEncoding::k32FC1) return RawImage(depth_m, "32FC1", header);
  InstanceImage mm(depth_m.width(), depth_m.height());
  const auto in = depth_m.data();
  auto out = mm.data();
  for (size_t i = 0; i < in.size(); ++i) {
    const float z = in[i];
    const double r =
        std::isfinite(z) && z > 0.0f ? std::round(static_cast<double>(z) * 1000.0) : 0.0;
    out[i] = static_cast<uint16_t>(std::min(r, 65535.0));
  }
  return RawImage(mm, "16UC1", header);
}

Image ToInstanceIdImage(const InstanceImage& ids, std::string_view encoding, const Header& header) {
  return RawImage(ids, encoding, header);
}

Image ToClassIdImage(const ClassImage& classes, const Header& header) {
  return RawImage(classes, "mono8", header);
}

CameraInfo ToCameraInfo(const CameraIntrinsics& K, const Header& header) {
  CameraInfo m;
  m.header = header;
  m.width = static_cast<uint32_t>(K.width);
  m.height = static_cast<uint32_t>(K.height);
  m.distortion_model = "plumb_bob";
  m.d = {0.0, 0.0, 0.0, 0.0, 0.0};
  m.k = {K.fx, 0.0, K.cx, 0.0, K.fy, K.cy, 0.0, 0.0, 1.0};
  m.r = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  m.p = {K.fx, 0.0, K.cx, 0.0, 0.0, K.fy, K.cy, 0.0, 0.0, 0.0, 1.0, 0.0};
  return m;
}

Result<CameraIntrinsics> FromCameraInfo(const CameraInfo& info, double min_depth_m,
                                        double max_depth_m) {
  if (info.width == 0 || info.height == 0 || info.width > kMaxImageSide ||
      info.height > kMaxImageSide) {
    return InvalidArgumentError(
        fmt::format("CameraInfo (frame {}): size {}x{} is out of range (1..{})",
                    QuoteText(info.header.frame_id), info.width, info.height, kMaxImageSide));
  }
  CameraIntrinsics K;
  K.width = static_cast<int>(info.width);
  K.height = static_cast<int>(info.height);
  K.fx = info.k[0];
  K.fy = info.k[4];
  K.cx = info.k[2];
  K.cy = info.k[5];
  K.min_depth_m = min_depth_m;
  K.max_depth_m = max_depth_m;
  if (Status s = K.Validate(); !s.ok()) {
    return InvalidArgumentError(fmt::format("CameraInfo (frame {}) gives invalid intrinsics: {}",
                                            QuoteText(info.header.frame_id), s.message()));
  }
  if (info.binning_x > 1 || info.binning_y > 1 || info.roi.width != 0 || info.roi.height != 0) {
    return InvalidArgumentError(fmt::format(
        "CameraInfo (frame {}): binning {}x{} or a region of interest {}x{} is not supported",
        QuoteText(info.header.frame_id), info.binning_x, info.binning_y, info.roi.width,
        info.roi.height));
  }
  return K;
}

}  // namespace avp::ros::msg

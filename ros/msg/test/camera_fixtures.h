#pragma once

// Camera frames as real drivers publish them, each with the frame avp must read from it: the one
// set of fixtures fed through `avp live`'s path (live/test/same_frames_test.cpp: DDS on loopback
// into ros::live::Ros2RgbdSource) and through `avp replay`'s path
// (ros/bag/test/bag_reader_test.cpp: an MCAP written with ros::mcap::Writer, read with
// ros::bag::ReadBag), so that both read every encoding alike (ros/msg/images.h: the depth rule).
// Header-only; ros/msg and core only.

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <avp/core/camera.h>
#include <avp/core/image.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::msg::testing {

inline constexpr int kFixtureWidth = 8;
inline constexpr int kFixtureHeight = 6;

struct CameraFixture {
  std::string name;
  /// As the camera publishes them; the caller sets the stamps (and frame ids, if it wants).
  Image color;
  Image depth;
  /// What avp must read: the colour as rgb, the depth in metres by the depth rule.
  ImageRgb8 rgb;
  DepthImage depth_m;
  /// Non-empty: the depth image must be refused, the error containing this.
  std::string depth_error;
};

/// The fixtures' CameraInfo (8 x 6, fx = fy = 50, plumb_bob without distortion).
inline CameraInfo FixtureCameraInfo() {
  CameraIntrinsics K;
  K.width = kFixtureWidth;
  K.height = kFixtureHeight;
  K.fx = K.fy = 50.0;
  K.cx = (kFixtureWidth - 1) / 2.0;
  K.cy = (kFixtureHeight - 1) / 2.0;
  Header header;
  header.frame_id = "camera_color_optical_frame";
  return ToCameraInfo(K, header);
}

namespace detail {

inline uint8_t R(int u, int v) { return static_cast<uint8_t>(10 * u + v + 1); }
inline uint8_t G(int u, int v) { return static_cast<uint8_t>(20 * v + u + 2); }
inline uint8_t B(int u, int v) { return static_cast<uint8_t>(7 * u + 5 * v + 3); }
inline uint8_t Grey(int u, int v) { return static_cast<uint8_t>(11 * u + 17 * v + 4); }

/// A colour image in `encoding` (rgb8, bgr8, rgba8, bgra8, mono8) with `pad` bytes after each
/// row, and the rgb avp must read from it.
inline std::pair<Image, ImageRgb8> Color(const std::string& encoding, uint32_t pad) {
  const int bpp = encoding == "mono8" ? 1 : (encoding == "rgba8" || encoding == "bgra8") ? 4 : 3;
  const bool bgr = encoding == "bgr8" || encoding == "bgra8";
  Image m;
  m.header.frame_id = "camera_color_optical_frame";
  m.width = kFixtureWidth;
  m.height = kFixtureHeight;
  m.encoding = encoding;
  m.step = static_cast<uint32_t>(kFixtureWidth * bpp) + pad;
  m.data.assign(static_cast<size_t>(m.step) * m.height, 0xEE);  // padding: garbage
  ImageRgb8 rgb(kFixtureWidth, kFixtureHeight);
  for (int v = 0; v < kFixtureHeight; ++v) {
    for (int u = 0; u < kFixtureWidth; ++u) {
      uint8_t* p = m.data.data() + static_cast<size_t>(v) * m.step + static_cast<size_t>(bpp * u);
      if (bpp == 1) {
        p[0] = Grey(u, v);
        rgb.at(u, v, 0) = rgb.at(u, v, 1) = rgb.at(u, v, 2) = Grey(u, v);
        continue;
      }
      p[0] = bgr ? B(u, v) : R(u, v);
      p[1] = G(u, v);
      p[2] = bgr ? R(u, v) : B(u, v);
      if (bpp == 4) p[3] = static_cast<uint8_t>(255 - 9 * u);  // alpha: dropped
      rgb.at(u, v, 0) = R(u, v);
      rgb.at(u, v, 1) = G(u, v);
      rgb.at(u, v, 2) = B(u, v);
    }
  }
  return {std::move(m), std::move(rgb)};
}

/// A 32FC1 depth image (metres) of `values` (row-major), in either byte order.
inline Image Depth32(const std::vector<float>& values, bool big_endian) {
  Image m;
  m.header.frame_id = "camera_color_optical_frame";
  m.width = kFixtureWidth;
  m.height = kFixtureHeight;
  m.encoding = "32FC1";
  m.is_bigendian = big_endian ? 1 : 0;
  m.step = 4 * kFixtureWidth;
  m.data.resize(4 * values.size());
  for (size_t i = 0; i < values.size(); ++i) {
    uint8_t b[4];
    std::memcpy(b, &values[i], 4);  // little-endian hosts
    for (int k = 0; k < 4; ++k) m.data[4 * i + static_cast<size_t>(k)] = b[big_endian ? 3 - k : k];
  }
  return m;
}

/// A 16UC1 (or mono16) depth image (millimetres) of `mm` (row-major), in either byte order.
inline Image Depth16(const std::vector<uint16_t>& mm, const std::string& encoding,
                     bool big_endian) {
  Image m;
  m.header.frame_id = "camera_color_optical_frame";
  m.width = kFixtureWidth;
  m.height = kFixtureHeight;
  m.encoding = encoding;
  m.is_bigendian = big_endian ? 1 : 0;
  m.step = 2 * kFixtureWidth;
  for (const uint16_t x : mm) {
    const auto lo = static_cast<uint8_t>(x & 0xff);
    const auto hi = static_cast<uint8_t>(x >> 8);
    m.data.insert(m.data.end(), big_endian ? std::initializer_list<uint8_t>{hi, lo}
                                           : std::initializer_list<uint8_t>{lo, hi});
  }
  return m;
}

/// Metres: a slanted plane, with the pixels of row 0 from u = 1 on replaced by `specials`.
inline std::vector<float> Metres(const std::vector<float>& specials) {
  std::vector<float> z(static_cast<size_t>(kFixtureWidth * kFixtureHeight));
  for (int v = 0; v < kFixtureHeight; ++v) {
    for (int u = 0; u < kFixtureWidth; ++u) {
      z[static_cast<size_t>(v * kFixtureWidth + u)] =
          0.5f + 0.0125f * static_cast<float>(u) + 0.1f * static_cast<float>(v);
    }
  }
  for (size_t i = 0; i < specials.size(); ++i) z[1 + i] = specials[i];
  return z;
}

/// The depth avp reads from metres: NaN, +-inf and +-0 are no return (0); the rest as is.
inline DepthImage ReadMetres(const std::vector<float>& z) {
  DepthImage d(kFixtureWidth, kFixtureHeight);
  for (size_t i = 0; i < z.size(); ++i) {
    d.data()[i] = std::isfinite(z[i]) && z[i] != 0.0f ? z[i] : 0.0f;
  }
  return d;
}

inline std::vector<uint16_t> Millimetres() {
  std::vector<uint16_t> mm(static_cast<size_t>(kFixtureWidth * kFixtureHeight));
  for (size_t i = 0; i < mm.size(); ++i) mm[i] = static_cast<uint16_t>(400 + 37 * i);
  mm[1] = 0;      // no return
  mm[2] = 65535;  // the farthest a 16UC1 holds
  return mm;
}

inline DepthImage ReadMillimetres(const std::vector<uint16_t>& mm) {
  DepthImage d(kFixtureWidth, kFixtureHeight);
  for (size_t i = 0; i < mm.size(); ++i) d.data()[i] = static_cast<float>(mm[i]) * 0.001f;
  return d;
}

}  // namespace detail

/// Every colour encoding and both depth encodings in both byte orders, padded rows, the depth
/// rule's special values, and one frame whose depth must be refused (a negative depth).
inline std::vector<CameraFixture> CameraFixtures() {
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  constexpr float kInf = std::numeric_limits<float>::infinity();
  std::vector<CameraFixture> out;
  const auto add = [&](std::string name, const std::string& color_encoding, uint32_t pad,
                       Image depth, DepthImage depth_m, std::string depth_error = {}) {
    auto [color, rgb] = detail::Color(color_encoding, pad);
    out.push_back({std::move(name), std::move(color), std::move(depth), std::move(rgb),
                   std::move(depth_m), std::move(depth_error)});
  };
  // A camera that publishes RGBA colour and float depth with REP 118's special values.
  const std::vector<float> z = detail::Metres({kNaN, 0.0f, kInf, -kInf, -0.0f});
  add("rgba8 + 32FC1 (NaN, 0, inf, -inf, -0)", "rgba8", 0, detail::Depth32(z, false),
      detail::ReadMetres(z));
  // A RealSense-like 16UC1 with a BGRA colour stream whose rows are padded.
  const std::vector<uint16_t> mm = detail::Millimetres();
  add("bgra8 (padded rows) + 16UC1", "bgra8", 12, detail::Depth16(mm, "16UC1", false),
      detail::ReadMillimetres(mm));
  add("rgb8 + 32FC1 big-endian", "rgb8", 0, detail::Depth32(z, true), detail::ReadMetres(z));
  add("bgr8 (padded rows) + 16UC1 big-endian", "bgr8", 3, detail::Depth16(mm, "16UC1", true),
      detail::ReadMillimetres(mm));
  add("mono8 + mono16", "mono8", 0, detail::Depth16(mm, "mono16", false),
      detail::ReadMillimetres(mm));
  // A negative depth: no camera sends one; the frame is refused, naming the pixel.
  std::vector<float> bad = detail::Metres({});
  bad[static_cast<size_t>(5 * kFixtureWidth + 6)] = -0.25f;
  add("rgb8 + 32FC1 with a negative depth", "rgb8", 0, detail::Depth32(bad, false), DepthImage(),
      "depth -0.25 m at pixel (6, 5)");
  return out;
}

}  // namespace avp::ros::msg::testing

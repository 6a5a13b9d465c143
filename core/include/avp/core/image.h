#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <avp/core/error.h>

namespace avp {

/// A dense row-major image with `kChannels` interleaved channels of type T.
/// Pixel (u, v) is column u, row v from the top-left (see docs/conventions.md).
template <typename T, int kChannels = 1>
class Image {
 public:
  using value_type = T;
  static constexpr int channels = kChannels;

  Image() = default;
  /// @throws avp::Error if width or height is negative.
  Image(int width, int height, T fill = T{}) : width_(width), height_(height) {
    AVP_THROW_UNLESS(width >= 0 && height >= 0, width, height);
    data_.assign(static_cast<size_t>(width) * height * kChannels, fill);
  }

  int width() const { return width_; }
  int height() const { return height_; }
  bool empty() const { return data_.empty(); }
  size_t num_pixels() const { return static_cast<size_t>(width_) * height_; }
  bool SameSizeAs(int width, int height) const { return width_ == width && height_ == height; }
  template <typename U, int C>
  bool SameSizeAs(const Image<U, C>& other) const {
    return width_ == other.width() && height_ == other.height();
  }
  bool Contains(int u, int v) const { return u >= 0 && v >= 0 && u < width_ && v < height_; }

  /// Unchecked access (debug builds assert).
  T& at(int u, int v, int c = 0) { return data_[Index(u, v, c)]; }
  const T& at(int u, int v, int c = 0) const { return data_[Index(u, v, c)]; }
  /// Bounds-checked access in every build: throws avp::Error naming (u, v, c) and the size.
  T& AtChecked(int u, int v, int c = 0) {
    CheckBounds(u, v, c);
    return data_[(static_cast<size_t>(v) * width_ + u) * kChannels + c];
  }
  const T& AtChecked(int u, int v, int c = 0) const {
    CheckBounds(u, v, c);
    return data_[(static_cast<size_t>(v) * width_ + u) * kChannels + c];
  }
  T& operator()(int u, int v, int c = 0) { return at(u, v, c); }
  const T& operator()(int u, int v, int c = 0) const { return at(u, v, c); }

  std::span<T> data() { return data_; }
  std::span<const T> data() const { return data_; }
  /// Channels of one pixel.
  std::span<T, kChannels> pixel(int u, int v) {
    return std::span<T, kChannels>(data_.data() + Index(u, v, 0), kChannels);
  }
  std::span<const T, kChannels> pixel(int u, int v) const {
    return std::span<const T, kChannels>(data_.data() + Index(u, v, 0), kChannels);
  }

  void Fill(T value) { std::fill(data_.begin(), data_.end(), value); }

  bool operator==(const Image&) const = default;

 private:
  void CheckBounds(int u, int v, int c) const {
    AVP_THROW_UNLESS(Contains(u, v) && c >= 0 && c < kChannels, u, v, c, width_, height_);
  }
  size_t Index(int u, int v, int c) const {
#ifndef NDEBUG
    CheckBounds(u, v, c);
#endif
    return (static_cast<size_t>(v) * width_ + u) * kChannels + c;
  }

  int width_ = 0;
  int height_ = 0;
  std::vector<T> data_;
};

/// 8-bit RGB, channels in R, G, B order.
using ImageRgb8 = Image<uint8_t, 3>;
/// z-depth (along the optical axis, not ray length) in metres; 0 or NaN = no valid return.
using DepthImage = Image<float, 1>;
/// Per-pixel instance id; 0 = background / no instance.
using InstanceImage = Image<uint16_t, 1>;
/// Per-pixel semantic class id (see SemanticClass); 0 = background.
using ClassImage = Image<uint8_t, 1>;

/// True for a usable depth: finite and > 0.
inline bool IsValidDepth(float depth_m) {
  return depth_m > 0.0f && depth_m == depth_m && depth_m < 1e30f;
}

}  // namespace avp

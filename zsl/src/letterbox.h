#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <vector>

#include <avp/core/image.h>
#include <avp/core/segmentation.h>

namespace avp::zsl {

/// The YOLO letterbox of design/zero-shot-models.md §4.1 (the Ultralytics `LetterBox` with
/// `auto=False, scaleup=True, center=True`): the source image is scaled by
/// r = min(dst_h / src_h, dst_w / src_w) to (round(src_w·r), round(src_h·r)) and centre-padded to
/// dst_w x dst_h. With d pixels of padding on an axis, left/top = round(d/2 − 0.1) and
/// right/bottom = round(d/2 + 0.1), so an odd d puts the extra pixel right/bottom.
///
/// `round` is Python's round(), half to even (Ultralytics computes the sizes with it): a source
/// 256x5 into 640x640 has r = 2.5 and a resized height round(12.5) = 12, not 13. The ±0.1 keeps
/// the pad split off exact halves. All sizes are in pixels; coordinates are continuous pixel
/// coordinates (pixel column u covers [u, u+1)).
struct Letterbox {
  int src_w = 0;  ///< source image width, pixels
  int src_h = 0;  ///< source image height, pixels
  int dst_w = 0;  ///< network input width, pixels (640)
  int dst_h = 0;  ///< network input height, pixels (640)
  /// r: letterboxed pixels per source pixel, the same on both axes.
  double scale = 1.0;
  int resized_w = 0;  ///< round(src_w·r), at least 1
  int resized_h = 0;  ///< round(src_h·r), at least 1
  int pad_left = 0;
  int pad_top = 0;
  int pad_right = 0;
  int pad_bottom = 0;

  /// The letterbox of a src_w x src_h image into dst_w x dst_h.
  /// @throws avp::Error unless all four sizes are > 0.
  static Letterbox Compute(int src_w, int src_h, int dst_w = 640, int dst_h = 640);

  /// Letterboxed (network) coordinates → source image coordinates: subtracts the left/top pad,
  /// divides by `scale` and clips to [0, src_w] x [0, src_h] (as Ultralytics `scale_boxes`,
  /// except that the pad is this struct's integer pad, the one actually applied to the image).
  PixelBox ToSource(const PixelBox& letterboxed) const;

  /// Source image coordinates → letterboxed coordinates: multiplies by `scale` and adds the
  /// left/top pad. Not clipped; ToSource(ToLetterboxed(b)) == b for a box inside the source.
  PixelBox ToLetterboxed(const PixelBox& source) const;
};

/// The network input for `rgb` under `lb`: a CHW float32 tensor [3, dst_h, dst_w] in R, G, B
/// channel order (element (c, y, x) at index (c·dst_h + y)·dst_w + x). The image is resized to
/// resized_w x resized_h with bilinear interpolation (cv::INTER_LINEAR on the 8-bit image, as
/// cv2.resize in the reference), placed at (pad_left, pad_top), and every element is the 8-bit
/// value times `value_scale`; padding has the value `pad_value · value_scale` (114/255).
/// @throws avp::Error unless rgb is lb.src_w x lb.src_h.
std::vector<float> LetterboxTensor(const ImageRgb8& rgb, const Letterbox& lb,
                                   float pad_value = 114.f, float value_scale = 1.f / 255.f);

}  // namespace avp::zsl

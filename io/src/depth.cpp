#include <cmath>

#include <avp/io/depth.h>

namespace avp::io {

Image<uint16_t> DepthToMillimetres(const DepthImage& depth_m) {
  Image<uint16_t> out(depth_m.width(), depth_m.height(), 0);
  auto src = depth_m.data();
  auto dst = out.data();
  for (size_t i = 0; i < src.size(); ++i) {
    const float d = src[i];
    if (!IsValidDepth(d)) continue;
    const double mm = std::round(static_cast<double>(d) * 1000.0);
    dst[i] = mm >= 65535.0 ? uint16_t{65535} : static_cast<uint16_t>(mm);
  }
  return out;
}

DepthImage DepthFromMillimetres(const Image<uint16_t>& depth_mm) {
  DepthImage out(depth_mm.width(), depth_mm.height(), 0.0f);
  auto src = depth_mm.data();
  auto dst = out.data();
  for (size_t i = 0; i < src.size(); ++i) dst[i] = static_cast<float>(src[i]) * 0.001f;
  return out;
}

}  // namespace avp::io

#pragma once

#include <cstdint>

#include <avp/core/image.h>

namespace avp::io {

/// Metres (float, 0/NaN = invalid) to the RealSense Z16 convention: uint16 millimetres, rounded to
/// nearest, 0 = invalid; depths >= 65.535 m saturate to 65535.
Image<uint16_t> DepthToMillimetres(const DepthImage& depth_m);
/// Inverse of DepthToMillimetres (0 stays 0 = invalid).
DepthImage DepthFromMillimetres(const Image<uint16_t>& depth_mm);

}  // namespace avp::io

#pragma once

#include <cstdint>

#include <Eigen/Core>

#include <avp/core/image.h>
#include <avp/core/semantic_class.h>

namespace avp::io {

/// A fixed colour per semantic class (sRGB 8-bit): fruit red, leaf green, stem brown, ...
Eigen::Matrix<uint8_t, 3, 1> ClassColor(SemanticClass c);
/// A distinct colour per instance id (golden-angle hue steps, full saturation); black for 0.
Eigen::Matrix<uint8_t, 3, 1> InstanceColor(uint16_t instance_id);

/// A picture of the labels for people: fruit pixels in per-instance colours, other classes in
/// their class colours, background black; `underlay` (same size, may be empty) is blended in at
/// `underlay_weight` so the scene stays readable. Instance boundaries are drawn darker.
/// @throws avp::Error if the label images (or a non-empty underlay) differ in size.
ImageRgb8 ColorizeLabels(const InstanceImage& instance_ids, const ClassImage& class_ids,
                         const ImageRgb8& underlay = {}, double underlay_weight = 0.35);

}  // namespace avp::io

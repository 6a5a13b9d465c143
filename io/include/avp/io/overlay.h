#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/image.h>
#include <avp/core/segmentation.h>

namespace avp::io {

/// The key an instance is coloured by: its label, or the name of its semantic class when the
/// label is empty.
std::string OverlayKey(const InstanceMask& instance);

/// The preferred overlay colour (R, G, B) of a key: a fixed palette entry chosen by a hash
/// (FNV-1a) of the key, so the same label has the same colour in every image and every run.
std::array<uint8_t, 3> PreferredOverlayColor(std::string_view key);

/// The colour of each instance of `seg` in DrawSegmentationOverlay, in instance order. Instances
/// with the same key share a colour; distinct keys get distinct colours while the palette
/// lasts: keys take their preferred colour in sorted order, and a key whose colour is taken moves
/// to the next free palette entry.
std::vector<std::array<uint8_t, 3>> OverlayColors(const Segmentation& seg);

/// A debug picture of a segmentation over its image, drawn in this order for all instances:
/// each mask blended at 50 % with its colour (each channel (image + colour + 1) / 2, rounded),
/// then each mask's outline (one pixel wide, in full colour, on the mask's boundary pixels) and
/// its detector box when present (on the pixels round(x0) .. round(x1) − 1), then a text tag
/// "label 0.87" (key and confidence) on a filled patch of its colour, above the box's or the
/// mask's top-left corner (inside it when there is no room above). An instance with an empty mask
/// and no box gets no tag. Pixels away from every mask, outline, box and tag are unchanged.
/// @throws avp::Error unless seg and every mask have the image's size.
ImageRgb8 DrawSegmentationOverlay(const ImageRgb8& image, const Segmentation& seg);

}  // namespace avp::io

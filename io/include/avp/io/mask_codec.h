#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <avp/core/segmentation.h>
#include <avp/core/status.h>

namespace avp::io {

/// COCO-style uncompressed run-length encoding of a binary mask (nonzero = foreground): the
/// pixels in column-major order (down column 0, then column 1, ...; pycocotools' Fortran order),
/// as alternating run lengths starting with background, so the first count is 0 when pixel
/// (0, 0) is foreground. The counts sum to width·height; an empty (0 x 0) mask gives {0}.
std::vector<uint32_t> MaskToRle(const MaskImage& mask);

/// The inverse of MaskToRle for a width x height mask: foreground pixels are 255, background 0.
/// @return InvalidArgument when width or height is negative or when the counts do not sum to
///   width·height (the message names the sum and the size); ResourceExhausted when width·height
///   exceeds max_image_pixels (io/image_limits.h), checked before the mask is allocated.
Result<MaskImage> RleToMask(std::span<const uint32_t> counts, int width, int height);

/// The outer contours of a binary mask's 8-connected components (cv::findContours,
/// RETR_EXTERNAL, CHAIN_APPROX_SIMPLE), one polygon per component, holes ignored. Vertices are
/// {column, row} of boundary pixels (pixel indices, so a rectangle over columns 10..19 has
/// vertices at x = 10 and x = 19), listed from the component's top-most then left-most pixel.
/// Polygons are ordered by that first vertex (row, then column). A one-pixel component is a
/// one-vertex polygon; an empty mask gives none.
std::vector<std::vector<std::array<int, 2>>> MaskToPolygons(const MaskImage& mask);

}  // namespace avp::io

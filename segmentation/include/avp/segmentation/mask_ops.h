#pragma once

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include <avp/core/image.h>
#include <avp/core/segmentation.h>

namespace avp::segmentation {

/// Pixels of `mask` that are set (nonzero).
size_t CountPixels(const MaskImage& mask);

/// The offsets (dx, dy) of the digital disk of radius `radius_px`: dx² + dy² <= radius_px², in
/// raster order. Radius 0 is the single offset (0, 0); radius 1 the 4-neighbour cross.
/// @throws avp::Error if radius_px < 0.
std::vector<std::pair<int, int>> DiskOffsets(int radius_px);

/// Morphological dilation by the disk of radius `radius_px` (see DiskOffsets), clipped to the
/// image: a pixel is set when some set pixel lies within the disk around it. Output values are 0/1.
/// @throws avp::Error if radius_px < 0.
MaskImage Dilate(const MaskImage& mask, int radius_px);

/// Morphological erosion by the disk of radius `radius_px`: a set pixel stays set when every pixel
/// within the disk around it *that lies inside the image* is set, so the image border does not
/// erode a mask (a fruit cut by the border keeps its cut edge). Output values are 0/1.
/// @throws avp::Error if radius_px < 0.
MaskImage Erode(const MaskImage& mask, int radius_px);

/// Dilate(mask, r) for r > 0, Erode(mask, -r) for r < 0, the mask as 0/1 for r = 0.
MaskImage AdjustBoundary(const MaskImage& mask, int radius_px);

/// Connected components of a binary mask.
struct Components {
  /// Per pixel: 0 outside the mask, else the component's label 1..count. Labels are assigned in
  /// raster order of each component's first (top-most, then left-most) pixel.
  Image<int32_t, 1> labels;
  /// sizes[k - 1] = pixels of component k.
  std::vector<size_t> sizes;
  size_t count() const { return sizes.size(); }
};

/// Labels the connected components of the set pixels of `mask`, with 8-connectivity (pixels
/// touching at a corner connect) or 4-connectivity (edges only).
Components LabelComponents(const MaskImage& mask, bool eight_connected = true);

}  // namespace avp::segmentation

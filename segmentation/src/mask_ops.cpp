#include <algorithm>
#include <utility>
#include <vector>

#include <avp/core/error.h>
#include <avp/segmentation/mask_ops.h>

namespace avp::segmentation {

namespace {

/// Bounding box [u0, u1) x [v0, v1) of the set pixels; empty (u0 >= u1) when none is set.
struct Bounds {
  int u0 = 0, v0 = 0, u1 = 0, v1 = 0;
};

Bounds SetBounds(const MaskImage& mask) {
  Bounds b{mask.width(), mask.height(), 0, 0};
  for (int v = 0; v < mask.height(); ++v) {
    const uint8_t* row = mask.data().data() + static_cast<size_t>(v) * mask.width();
    int first = -1;
    int last = -1;
    for (int u = 0; u < mask.width(); ++u) {
      if (row[u] == 0) continue;
      if (first < 0) first = u;
      last = u;
    }
    if (first < 0) continue;
    b.u0 = std::min(b.u0, first);
    b.u1 = std::max(b.u1, last + 1);
    b.v0 = std::min(b.v0, v);
    b.v1 = v + 1;
  }
  return b;
}

}  // namespace

size_t CountPixels(const MaskImage& mask) {
  size_t n = 0;
  for (uint8_t value : mask.data()) n += value != 0 ? 1 : 0;
  return n;
}

std::vector<std::pair<int, int>> DiskOffsets(int radius_px) {
  AVP_THROW_UNLESS(radius_px >= 0, radius_px);
  std::vector<std::pair<int, int>> offsets;
  const int r2 = radius_px * radius_px;
  for (int dy = -radius_px; dy <= radius_px; ++dy) {
    for (int dx = -radius_px; dx <= radius_px; ++dx) {
      if (dx * dx + dy * dy <= r2) offsets.emplace_back(dx, dy);
    }
  }
  return offsets;
}

MaskImage Dilate(const MaskImage& mask, int radius_px) {
  const auto offsets = DiskOffsets(radius_px);
  const int w = mask.width();
  const int h = mask.height();
  MaskImage out(w, h, 0);
  const Bounds b = SetBounds(mask);
  for (int v = b.v0; v < b.v1; ++v) {
    for (int u = b.u0; u < b.u1; ++u) {
      if (mask.at(u, v) == 0) continue;
      for (const auto& [dx, dy] : offsets) {
        const int x = u + dx;
        const int y = v + dy;
        if (x >= 0 && y >= 0 && x < w && y < h) out.at(x, y) = 1;
      }
    }
  }
  return out;
}

MaskImage Erode(const MaskImage& mask, int radius_px) {
  const auto offsets = DiskOffsets(radius_px);
  const int w = mask.width();
  const int h = mask.height();
  MaskImage out(w, h, 0);
  const Bounds b = SetBounds(mask);
  for (int v = b.v0; v < b.v1; ++v) {
    for (int u = b.u0; u < b.u1; ++u) {
      if (mask.at(u, v) == 0) continue;
      bool keep = true;
      for (const auto& [dx, dy] : offsets) {
        const int x = u + dx;
        const int y = v + dy;
        if (x >= 0 && y >= 0 && x < w && y < h && mask.at(x, y) == 0) {
          keep = false;
          break;
        }
      }
      if (keep) out.at(u, v) = 1;
    }
  }
  return out;
}

MaskImage AdjustBoundary(const MaskImage& mask, int radius_px) {
  if (radius_px > 0) return Dilate(mask, radius_px);
  if (radius_px < 0) return Erode(mask, -radius_px);
  return Dilate(mask, 0);
}

Components LabelComponents(const MaskImage& mask, bool eight_connected) {
  const int w = mask.width();
  const int h = mask.height();
  Components out;
  out.labels = Image<int32_t, 1>(w, h, 0);
  std::vector<std::pair<int, int>> neighbours = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
  if (eight_connected) {
    neighbours.insert(neighbours.end(), {{1, 1}, {1, -1}, {-1, 1}, {-1, -1}});
  }
  std::vector<std::pair<int, int>> stack;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      if (mask.at(u, v) == 0 || out.labels.at(u, v) != 0) continue;
      const auto label = static_cast<int32_t>(out.sizes.size() + 1);
      size_t size = 0;
      out.labels.at(u, v) = label;
      stack.assign(1, {u, v});
      while (!stack.empty()) {
        const auto [x, y] = stack.back();
        stack.pop_back();
        ++size;
        for (const auto& [dx, dy] : neighbours) {
          const int nx = x + dx;
          const int ny = y + dy;
          if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
          if (mask.at(nx, ny) == 0 || out.labels.at(nx, ny) != 0) continue;
          out.labels.at(nx, ny) = label;
          stack.emplace_back(nx, ny);
        }
      }
      out.sizes.push_back(size);
    }
  }
  return out;
}

}  // namespace avp::segmentation

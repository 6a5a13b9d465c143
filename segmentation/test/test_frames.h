#pragma once

// Hand-built frames and simulator labels for the segmentation tests (no renderer needed).

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>

#include <Eigen/Core>

#include <avp/core/camera.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/segmentation.h>
#include <avp/core/semantic_class.h>
#include <avp/core/transform.h>
#include <avp/segmentation/segmenter.h>

namespace avp::segmentation::test {

using Rgb = std::array<uint8_t, 3>;

/// A w x h pinhole camera with fx = fy = f and a centred principal point.
inline CameraIntrinsics TestCamera(int w, int h, double f) {
  CameraIntrinsics K;
  K.width = w;
  K.height = h;
  K.fx = f;
  K.fy = f;
  K.cx = (w - 1) / 2.0;
  K.cy = (h - 1) / 2.0;
  return K;
}

/// A frame plus matching simulator labels that tests paint into. The camera sits at the world
/// origin looking along +z (X_WC = identity), every pixel at depth `depth_m`.
struct TestScene {
  RgbdFrame frame;
  SimulatorLabels labels;
  double depth_m = 1.0;

  TestScene(int w, int h, double f, const Rgb& background = {128, 128, 128}, double depth = 1.0)
      : depth_m(depth) {
    frame.K = TestCamera(w, h, f);
    frame.X_WC = RigidTransform::Identity();
    frame.rgb = ImageRgb8(w, h, 0);
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        for (int c = 0; c < 3; ++c) frame.rgb.at(u, v, c) = background[c];
      }
    }
    frame.depth_m = DepthImage(w, h, static_cast<float>(depth));
    labels.instance_ids = InstanceImage(w, h, 0);
    labels.class_ids = ClassImage(w, h, 0);
  }

  int width() const { return frame.rgb.width(); }
  int height() const { return frame.rgb.height(); }

  /// Paints every pixel where inside(u, v) holds with the colour, instance id and class (later
  /// paint covers earlier paint, as a nearer object would). Returns the pixels painted.
  int Paint(const std::function<bool(int, int)>& inside, uint16_t id, SemanticClass cls,
            const Rgb& rgb) {
    int n = 0;
    for (int v = 0; v < height(); ++v) {
      for (int u = 0; u < width(); ++u) {
        if (!inside(u, v)) continue;
        for (int c = 0; c < 3; ++c) frame.rgb.at(u, v, c) = rgb[c];
        labels.instance_ids.at(u, v) = id;
        labels.class_ids.at(u, v) = static_cast<uint8_t>(cls);
        ++n;
      }
    }
    return n;
  }

  /// A digital disc: pixels with (u - cu)² + (v - cv)² <= r².
  int PaintDisc(double cu, double cv, double r_px, uint16_t id, SemanticClass cls, const Rgb& rgb) {
    return Paint(
        [&](int u, int v) { return (u - cu) * (u - cu) + (v - cv) * (v - cv) <= r_px * r_px; }, id,
        cls, rgb);
  }

  /// The rectangle [u0, u1) x [v0, v1).
  int PaintRect(int u0, int v0, int u1, int v1, uint16_t id, SemanticClass cls, const Rgb& rgb) {
    return Paint([&](int u, int v) { return u >= u0 && u < u1 && v >= v0 && v < v1; }, id, cls,
                 rgb);
  }

  /// A fruit disc of radius r_px around pixel (cu, cv), recorded as a ground-truth sphere at
  /// depth_m whose unoccluded projection has radius r_px (expected area π r_px²).
  int PaintFruit(double cu, double cv, double r_px, uint16_t id, const Rgb& rgb = {200, 30, 20}) {
    const double f = frame.K.fx;
    GroundTruthFruit fruit;
    fruit.instance_id = id;
    fruit.center_W =
        Eigen::Vector3d((cu - frame.K.cx) * depth_m / f, (cv - frame.K.cy) * depth_m / f, depth_m);
    fruit.radius_m = r_px * depth_m / f;
    labels.fruits.push_back(fruit);
    return PaintDisc(cu, cv, r_px, id, SemanticClass::kFruit, rgb);
  }

  /// The pixels of instance `id` as a mask.
  MaskImage MaskOf(uint16_t id) const {
    MaskImage m(width(), height(), 0);
    for (int v = 0; v < height(); ++v) {
      for (int u = 0; u < width(); ++u) m.at(u, v) = labels.instance_ids.at(u, v) == id ? 1 : 0;
    }
    return m;
  }

  SegmentationRequest Request(std::string prompt = "tomato", uint64_t frame_index = 0) const {
    SegmentationRequest r;
    r.frame = &frame;
    r.labels = &labels;
    r.prompt = std::move(prompt);
    r.frame_index = frame_index;
    return r;
  }
};

/// Every field of two segmentations is equal.
inline bool SameSegmentation(const Segmentation& a, const Segmentation& b) {
  if (a.width != b.width || a.height != b.height) return false;
  if (a.instances.size() != b.instances.size()) return false;
  for (size_t i = 0; i < a.instances.size(); ++i) {
    const InstanceMask& x = a.instances[i];
    const InstanceMask& y = b.instances[i];
    if (!(x.mask == y.mask) || x.semantic_class != y.semantic_class ||
        x.confidence != y.confidence || x.label != y.label) {
      return false;
    }
  }
  return true;
}

/// Mean pixel position (u, v) of a mask; (-1, -1) when empty.
inline Eigen::Vector2d Centroid(const MaskImage& m) {
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  double n = 0.0;
  for (int v = 0; v < m.height(); ++v) {
    for (int u = 0; u < m.width(); ++u) {
      if (m.at(u, v) == 0) continue;
      sum += Eigen::Vector2d(u, v);
      n += 1.0;
    }
  }
  return n > 0.0 ? Eigen::Vector2d(sum / n) : Eigen::Vector2d(-1.0, -1.0);
}

}  // namespace avp::segmentation::test

#include <algorithm>
#include <cmath>

#include <avp/core/error.h>
#include <avp/io/label_preview.h>

namespace avp::io {

namespace {

using Rgb = Eigen::Matrix<uint8_t, 3, 1>;

Rgb HsvToRgb(double h_deg, double s, double v) {
  const double c = v * s;
  const double hp = std::fmod(h_deg, 360.0) / 60.0;
  const double x = c * (1.0 - std::abs(std::fmod(hp, 2.0) - 1.0));
  double r = 0, g = 0, b = 0;
  if (hp < 1) {
    r = c, g = x;
  } else if (hp < 2) {
    r = x, g = c;
  } else if (hp < 3) {
    g = c, b = x;
  } else if (hp < 4) {
    g = x, b = c;
  } else if (hp < 5) {
    r = x, b = c;
  } else {
    r = c, b = x;
  }
  const double m = v - c;
  auto to8 = [](double f) {
    return static_cast<uint8_t>(std::lround(std::clamp(f, 0.0, 1.0) * 255.0));
  };
  return Rgb(to8(r + m), to8(g + m), to8(b + m));
}

}  // namespace

Rgb ClassColor(SemanticClass c) {
  switch (c) {
    case SemanticClass::kBackground:
      return Rgb(0, 0, 0);
    case SemanticClass::kFruit:
      return Rgb(230, 40, 40);
    case SemanticClass::kLeaf:
      return Rgb(60, 170, 60);
    case SemanticClass::kStem:
      return Rgb(140, 100, 50);
    case SemanticClass::kSupport:
      return Rgb(150, 150, 200);
    case SemanticClass::kGround:
      return Rgb(90, 80, 70);
    case SemanticClass::kOther:
      return Rgb(200, 200, 200);
  }
  return Rgb(255, 0, 255);
}

Rgb InstanceColor(uint16_t instance_id) {
  if (instance_id == 0) return Rgb(0, 0, 0);
  return HsvToRgb(137.508 * instance_id, 0.85, 1.0);
}

ImageRgb8 ColorizeLabels(const InstanceImage& instance_ids, const ClassImage& class_ids,
                         const ImageRgb8& underlay, double underlay_weight) {
  AVP_THROW_UNLESS(instance_ids.SameSizeAs(class_ids), instance_ids.width(), instance_ids.height(),
                   class_ids.width(), class_ids.height());
  AVP_THROW_UNLESS(underlay.empty() || underlay.SameSizeAs(class_ids), underlay.width(),
                   underlay.height(), class_ids.width(), class_ids.height());
  AVP_THROW_UNLESS(underlay_weight >= 0.0 && underlay_weight <= 1.0, underlay_weight);
  const int w = class_ids.width();
  const int h = class_ids.height();
  ImageRgb8 out(w, h);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const auto cls = static_cast<SemanticClass>(class_ids(u, v));
      const uint16_t id = instance_ids(u, v);
      Rgb color = cls == SemanticClass::kFruit ? InstanceColor(id) : ClassColor(cls);
      const bool boundary = (u + 1 < w && instance_ids(u + 1, v) != id) ||
                            (v + 1 < h && instance_ids(u, v + 1) != id);
      double weight = underlay.empty() ? 0.0 : underlay_weight;
      for (int c = 0; c < 3; ++c) {
        double value = color[c] * (boundary ? 0.45 : 1.0);
        if (weight > 0.0) value = (1.0 - weight) * value + weight * underlay(u, v, c);
        out(u, v, c) = static_cast<uint8_t>(std::lround(std::clamp(value, 0.0, 255.0)));
      }
    }
  }
  return out;
}

}  // namespace avp::io

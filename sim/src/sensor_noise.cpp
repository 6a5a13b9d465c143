// Seeded RealSense-D435-like depth noise. Effects, applied per pixel in row-major order so the
// result depends only on (config, input frame, rng state):
//   1. edge dropout: a valid pixel is an edge pixel when a 4-neighbour differs by more than
//      edge_jump_m or has no valid depth (no return = far away); edges are found on the input
//      depth before anything is dropped, and each edge pixel is dropped with
//      edge_dropout_probability (both sides of a discontinuity are candidates);
//   2. random holes: every remaining valid pixel is dropped with invalid_pixel_probability;
//   3. axial noise: z += N(0, sigma_z), sigma_z = z^2 * disparity_sigma_px / (K.fx * baseline_m)
//      (the stereo law: depth z = f B / d, so dz = z^2 / (f B) * dd);
//   4. quantisation: z = round(z / quantization_m) * quantization_m (Z16 in 1 mm units).
// A pixel whose noisy depth is <= 0 is dropped. Pixels that had no valid depth are left as they
// were. Labels are never touched.

#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/sim/sensor_noise.h>

namespace avp::sim {

const OptionTable<DepthNoiseConfig>& DepthNoiseTable() {
  static const auto* table = [] {
    using N = DepthNoiseConfig;
    auto* t = new OptionTable<N>("depth noise option");
    const ValueRange probability = ValueRange::Closed(0, 1);
    t->Flag("enabled", &N::enabled, "apply the noise model");
    t->Real("baseline_m", &N::baseline_m, "m", ValueRange::Above(0), "stereo baseline");
    t->Real("disparity_sigma_px", &N::disparity_sigma_px, "px", ValueRange::AtLeast(0),
            "disparity noise (axial sigma = z^2 sigma / (f b))");
    t->Real("edge_jump_m", &N::edge_jump_m, "m", ValueRange::Above(0),
            "a 4-neighbour depth jump above this makes an edge pixel");
    t->Real("edge_dropout_probability", &N::edge_dropout_probability, "", probability,
            "an edge pixel is dropped with this probability");
    t->Real("invalid_pixel_probability", &N::invalid_pixel_probability, "", probability,
            "independent random holes");
    t->Real("quantization_m", &N::quantization_m, "m", ValueRange::AtLeast(0),
            "quantisation step of the reported depth (0: none)");
    return t;
  }();
  return *table;
}

Status DepthNoiseConfig::Validate() const { return DepthNoiseTable().Validate(*this); }

void ApplyDepthNoise(const DepthNoiseConfig& config, RenderedFrame& frame, Rng& rng) {
  if (!config.enabled) return;
  const Status valid = config.Validate();
  if (!valid.ok()) throw Error("ApplyDepthNoise: " + valid.message());
  const double fx = frame.rgbd.K.fx;
  if (config.disparity_sigma_px > 0.0) {
    AVP_THROW_UNLESS(std::isfinite(fx) && fx > 0.0, fx, frame.rgbd.K.width);
  }

  DepthImage& depth = frame.rgbd.depth_m;
  const int width = depth.width();
  const int height = depth.height();
  std::span<float> z = depth.data();

  // 1. Edge pixels of the input depth.
  std::vector<uint8_t> edge;
  if (config.edge_dropout_probability > 0.0) {
    edge.assign(z.size(), 0);
    const float jump = static_cast<float>(config.edge_jump_m);
    auto differs = [&](float a, float b) { return !IsValidDepth(b) || std::abs(a - b) > jump; };
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        const size_t i = static_cast<size_t>(v) * width + u;
        const float zi = z[i];
        if (!IsValidDepth(zi)) continue;
        edge[i] = (u > 0 && differs(zi, z[i - 1])) || (u + 1 < width && differs(zi, z[i + 1])) ||
                  (v > 0 && differs(zi, z[i - width])) ||
                  (v + 1 < height && differs(zi, z[i + width]));
      }
    }
  }

  const double sigma_per_z2 = config.disparity_sigma_px / (fx * config.baseline_m);
  const double q = config.quantization_m;
  for (size_t i = 0; i < z.size(); ++i) {
    if (!IsValidDepth(z[i])) continue;
    if (!edge.empty() && edge[i] && rng.Bernoulli(config.edge_dropout_probability)) {
      z[i] = 0.0f;
      continue;
    }
    if (config.invalid_pixel_probability > 0.0 && rng.Bernoulli(config.invalid_pixel_probability)) {
      z[i] = 0.0f;
      continue;
    }
    double zn = z[i];
    if (sigma_per_z2 > 0.0) zn += zn * zn * sigma_per_z2 * rng.Normal();
    if (q > 0.0) zn = std::round(zn / q) * q;
    z[i] = zn > 0.0 ? static_cast<float>(zn) : 0.0f;
  }
}

}  // namespace avp::sim

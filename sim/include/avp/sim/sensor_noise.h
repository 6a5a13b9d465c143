#pragma once

#include <avp/core/options.h>
#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/sim/rgbd_renderer.h>

namespace avp::sim {

/// A seeded depth-noise model in the spirit of an active-stereo RealSense D435 (see
/// docs/conventions.md). Every effect can be switched off by setting its parameter to 0.
struct DepthNoiseConfig {
  bool enabled = false;
  /// Stereo axial noise sigma_z = z^2 * disparity_sigma_px / (focal_px * baseline_m).
  double baseline_m = 0.05;
  double disparity_sigma_px = 0.08;
  /// Pixels whose 4-neighbour depth jump exceeds this are dropped with edge_dropout_probability.
  double edge_jump_m = 0.03;
  double edge_dropout_probability = 0.5;
  /// Independent random holes.
  double invalid_pixel_probability = 0.002;
  /// Quantisation step of the reported depth (Z16 at 1 mm); 0 = none.
  double quantization_m = 0.001;

  Status Validate() const;
};

/// The fields of DepthNoiseConfig.
const OptionTable<DepthNoiseConfig>& DepthNoiseTable();

/// Applies the model in place to `frame.rgbd.depth_m` (dropped pixels become 0; their labels are
/// kept, since labels are ground truth). Deterministic in `rng`.
void ApplyDepthNoise(const DepthNoiseConfig& config, RenderedFrame& frame, Rng& rng);

}  // namespace avp::sim

#include <avp/core/error.h>
#include <avp/sim/sim_rgbd_source.h>

namespace avp::sim {

SimRgbdSource::SimRgbdSource(const Scene& scene, const CameraIntrinsics& K,
                             const DepthNoiseConfig& noise, uint64_t seed)
    : scene_(&scene),
      renderer_(scene),
      K_(K),
      noise_(noise),
      noise_rng_(Rng(seed).Fork("depth-noise")) {
  if (const Status k_status = K.Validate(); !k_status.ok()) {
    throw Error("SimRgbdSource: " + k_status.ToString());
  }
  for (const FruitTruth& f : scene.Fruits()) {
    fruits_.push_back({f.instance_id, f.center_W, f.mean_radius_m()});
  }
}

Result<robot::Observation> SimRgbdSource::Capture(const RigidTransform& X_WC, int64_t stamp_ns) {
  if (!X_WC.translation().allFinite() || !X_WC.rotation().allFinite()) {
    return InvalidArgumentError("SimRgbdSource: camera pose " + X_WC.ToString() + " is not finite");
  }
  RenderedFrame rendered = renderer_.Render(K_, X_WC, stamp_ns);
  if (noise_.enabled) {
    Rng rng = noise_rng_.Fork(static_cast<uint64_t>(frames_));
    ApplyDepthNoise(noise_, rendered, rng);
  }
  ++frames_;
  robot::Observation obs;
  obs.frame = std::move(rendered.rgbd);
  SimulatorLabels labels;
  labels.instance_ids = std::move(rendered.instance_ids);
  labels.class_ids = std::move(rendered.class_ids);
  labels.fruits = fruits_;
  obs.labels = std::move(labels);
  return obs;
}

}  // namespace avp::sim

#include <condition_variable>
#include <mutex>

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
  return Render(X_WC, stamp_ns, noise_rng_.Fork(static_cast<uint64_t>(frames_++)));
}

Result<robot::Observation> SimRgbdSource::CaptureMoving(const RigidTransform& X_WC,
                                                        int64_t stamp_ns) {
  return Render(X_WC, stamp_ns,
                noise_rng_.Fork("moving").Fork(static_cast<uint64_t>(moving_frames_++)));
}

Result<robot::Observation> SimRgbdSource::Render(const RigidTransform& X_WC, int64_t stamp_ns,
                                                 Rng noise) {
  if (!X_WC.translation().allFinite() || !X_WC.rotation().allFinite()) {
    return InvalidArgumentError("SimRgbdSource: camera pose " + X_WC.ToString() + " is not finite");
  }
  RenderedFrame rendered = renderer_.Render(K_, X_WC, stamp_ns);
  if (noise_.enabled) ApplyDepthNoise(noise_, rendered, noise);
  robot::Observation obs;
  obs.frame = std::move(rendered.rgbd);
  SimulatorLabels labels;
  labels.instance_ids = std::move(rendered.instance_ids);
  labels.class_ids = std::move(rendered.class_ids);
  labels.fruits = fruits_;
  obs.labels = std::move(labels);
  return obs;
}

namespace {

/// SimRgbdSource's stream: renders each pose of the request once the arm has moved.
class SimMoveStream final : public robot::MoveStream {
 public:
  SimMoveStream(SimRgbdSource& source, robot::MoveStreamRequest request)
      : source_(source), request_(std::move(request)) {}

  Result<std::optional<robot::Observation>> Next() override {
    {
      std::unique_lock lock(mutex_);
      ended_.wait(lock, [&] { return end_.has_value(); });
      if (!*end_ || next_ >= request_.poses.size()) return std::optional<robot::Observation>();
    }
    const robot::TimedCameraPose& p = request_.poses[next_++];
    Result<robot::Observation> obs =
        source_.CaptureMoving(p.X_WC, request_.start_stamp_ns + p.t_ns);
    if (!obs.ok()) {
      ++counters_.failed;
      return obs.status();
    }
    ++counters_.delivered;
    return std::optional<robot::Observation>(std::move(*obs));
  }

  void End(bool moved) override {
    std::lock_guard lock(mutex_);
    end_ = moved;
    ended_.notify_all();
  }

  robot::MoveStreamCounters counters() const override { return counters_; }

 private:
  SimRgbdSource& source_;
  robot::MoveStreamRequest request_;
  std::mutex mutex_;
  std::condition_variable ended_;
  std::optional<bool> end_;
  size_t next_ = 0;
  robot::MoveStreamCounters counters_;
};

}  // namespace

std::unique_ptr<robot::MoveStream> SimRgbdSource::StreamMove(
    const robot::MoveStreamRequest& request) {
  return std::make_unique<SimMoveStream>(*this, request);
}

}  // namespace avp::sim

#include <chrono>
#include <cmath>
#include <exception>
#include <utility>

#include <fmt/format.h>

#include <avp/core/stopwatch.h>
#include <avp/pipeline/view_fusion.h>

namespace avp::pipeline {

Result<Segmentation> SegmentObservation(segmentation::Segmenter& segmenter,
                                        const robot::Observation& obs,
                                        const EpisodeOptions& options, uint64_t frame_index,
                                        const std::stop_token& stop) {
  segmentation::SegmentationRequest request;
  if (stop.stop_possible()) {
    request.interrupt = [stop]() -> Status {
      return stop.stop_requested() ? CancelledError("stop requested while segmenting")
                                   : Status::Ok();
    };
  }
  request.frame = &obs.frame;
  request.prompt = options.prompt;
  request.score_threshold = options.score_threshold;
  request.labels = obs.labels ? &*obs.labels : nullptr;
  request.frame_index = frame_index;
  Result<Segmentation> seg = InternalError("segmenter not called");
  try {
    seg = segmenter.Segment(request);
  } catch (const std::exception& e) {
    seg = InternalError(fmt::format("segmenter '{}' threw: {}", segmenter.name(), e.what()));
  }
  if (seg.ok()) {
    if (Status v = seg->ValidateFor(obs.frame.depth_m.width(), obs.frame.depth_m.height());
        !v.ok()) {
      seg = InternalError(fmt::format("segmenter '{}' returned an invalid segmentation: {}",
                                      segmenter.name(), v.ToString()));
    }
  }
  return seg;
}

ViewFusion::ViewFusion(mapping::SemanticMap& map, const EpisodeOptions& options)
    : map_(map),
      options_(options),
      integrator_(options.integrator),
      known_before_(map.grid().CountKnownVoxels()),
      target_before_(CountTargetVoxels(map.grid(), options.target_class)) {}

void ViewFusion::Segment(robot::Observation obs, segmentation::Segmenter& segmenter,
                         uint64_t frame_index, const std::stop_token& stop, StepRecord& step,
                         ViewSeen& seen) {
  const auto t0 = SteadyClock::now();
  Result<Segmentation> seg = SegmentObservation(segmenter, obs, options_, frame_index, stop);
  step.times.segment_ms = MsSince(t0);
  std::optional<Segmentation> masks;
  if (seg.ok()) {
    masks = std::move(*seg);
  } else {
    step.segment_status = seg.status();
  }
  Fuse(std::move(obs), std::move(masks), step, seen);
}

size_t CountMasksWithoutDepth(const Segmentation& segmentation, const RgbdFrame& frame) {
  const DepthImage& depth = frame.depth_m;
  size_t n = 0;
  for (const InstanceMask& m : segmentation.instances) {
    if (!m.mask.SameSizeAs(depth)) continue;  // Integrate names the mismatch
    bool any = false;
    for (int v = 0; v < depth.height() && !any; ++v) {
      for (int u = 0; u < depth.width(); ++u) {
        const float d = depth(u, v);
        if (m.mask(u, v) != 0 && std::isfinite(d) && d >= frame.K.min_depth_m &&
            d <= frame.K.max_depth_m) {
          any = true;
          break;
        }
      }
    }
    if (!any) ++n;
  }
  return n;
}

void ViewFusion::Fuse(robot::Observation obs, std::optional<Segmentation> segmentation,
                      StepRecord& step, ViewSeen& seen) {
  seen.observation = std::move(obs);
  seen.segmentation = std::move(segmentation);
  if (seen.segmentation) {
    step.masks = seen.segmentation->instances.size();
    step.masks_without_depth = CountMasksWithoutDepth(*seen.segmentation, seen.observation->frame);
  }
  Integrate(step, seen);
  RecordMap(step);
}

void ViewFusion::Integrate(StepRecord& step, ViewSeen& seen) {
  const auto t0 = SteadyClock::now();
  Result<mapping::IntegrationStats> stats = integrator_.Integrate(
      seen.observation->frame, seen.segmentation ? &*seen.segmentation : nullptr, map_);
  step.times.integrate_ms = MsSince(t0);
  if (stats.ok()) {
    step.integration = *stats;
  } else {
    step.integrate_status = stats.status();
  }
}

void ViewFusion::RecordMap(StepRecord& step) {
  step.known_voxels = map_.grid().CountKnownVoxels();
  step.occupied_voxels = map_.grid().CountOccupiedVoxels();
  step.target_voxels = CountTargetVoxels(map_.grid(), options_.target_class);
  step.instances = CountTargetInstances(map_, options_.target_class);
  step.known_delta = static_cast<int64_t>(step.known_voxels) - static_cast<int64_t>(known_before_);
  step.target_delta =
      static_cast<int64_t>(step.target_voxels) - static_cast<int64_t>(target_before_);
  known_before_ = step.known_voxels;
  target_before_ = step.target_voxels;
}

void NotifyStep(const std::vector<EpisodeObserver*>& observers, const StepRecord& step,
                const StepData& data, const mapping::SemanticMap& map) {
  for (EpisodeObserver* o : observers) {
    if (o == nullptr) continue;
    o->OnView(step, data, map);
    o->OnStep(step, map);
  }
}

void NotifyEnd(const std::vector<EpisodeObserver*>& observers, const EpisodeResult& result,
               const mapping::SemanticMap& map) {
  for (EpisodeObserver* o : observers) {
    if (o != nullptr) o->OnEnd(result, map);
  }
}

}  // namespace avp::pipeline

#include <chrono>
#include <cmath>
#include <exception>
#include <future>
#include <thread>
#include <utility>

#include <fmt/format.h>

#include <avp/core/parallel.h>
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

namespace {

/// The moving frames' integrator: their carving, the views' range, updating the planning ROI
/// only (the map's part the planner and the metrics read; IntegratorOptions::clip_box).
mapping::IntegratorOptions MovingIntegratorOptions(const EpisodeOptions& o) {
  mapping::IntegratorOptions m{.max_range_m = o.integrator.max_range_m,
                               .carving = o.motion_fusion.carving,
                               .clip_box = std::nullopt,
                               .pixel_stride = o.motion_fusion.decimation};
  if (!o.roi.IsEmpty() && o.roi.min().allFinite() && o.roi.max().allFinite()) m.clip_box = o.roi;
  return m;
}

}  // namespace

ViewFusion::ViewFusion(mapping::SemanticMap& map, const EpisodeOptions& options)
    : map_(map),
      options_(options),
      integrator_(options.integrator),
      moving_integrator_(MovingIntegratorOptions(options)),
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

namespace {

/// Keeps the first problem of a move for a person.
void NoteProblem(MovingFramesRecord& rec, const Status& status) {
  if (rec.first_problem.empty()) rec.first_problem = status.ToString();
}

}  // namespace

void ViewFusion::FuseMoving(const robot::Observation& obs, const Segmentation* segmentation,
                            MovingFramesRecord& rec) {
  const auto t0 = SteadyClock::now();
  const Result<mapping::IntegrationStats> stats =
      moving_integrator_.Integrate(obs.frame, segmentation, map_);
  rec.integrate_ms += MsSince(t0);
  if (!stats.ok()) {
    ++rec.failed;
    NoteProblem(rec, stats.status());
    return;
  }
  ++rec.fused;
  if (segmentation != nullptr) ++rec.segmented;
}

void ViewFusion::RecordMoving(MovingFramesRecord& rec) {
  const size_t known = map_.grid().CountKnownVoxels();
  const size_t target = CountTargetVoxels(map_.grid(), options_.target_class);
  rec.known_delta = static_cast<int64_t>(known) - static_cast<int64_t>(known_before_);
  rec.target_delta = static_cast<int64_t>(target) - static_cast<int64_t>(target_before_);
  known_before_ = known;
  target_before_ = target;
}

double MovingFramesRecord::map_rate_hz() const {
  const double busy_s = busy_ms / 1000.0;
  return fused > 0 && busy_s > 0.0 ? fused / busy_s : 0.0;
}

MovingFusion::MovingFusion(ViewFusion& fusion, segmentation::Segmenter& segmenter,
                           const EpisodeOptions& options, std::stop_token stop,
                           std::vector<EpisodeObserver*> observers)
    : fusion_(fusion),
      segmenter_(segmenter),
      options_(options),
      semantics_(options.motion_fusion.semantics),
      stop_(std::move(stop)),
      observers_(std::move(observers)) {
  if (semantics_ == MovingSemantics::kAuto) {
    semantics_ = segmenter.keeps_up_with_stream() ? MovingSemantics::kEveryFrame
                                                  : MovingSemantics::kWhenFree;
  }
}

robot::MoveResult MovingFusion::Run(robot::RgbdSource& source, const robot::ArmModel& arm,
                                    const robot::JointTrajectory& trajectory, int view,
                                    int64_t start_stamp_ns,
                                    const std::function<robot::MoveResult()>& move,
                                    MovingFramesRecord& rec) {
  rec.move_s = trajectory.duration_s();
  const MotionFusionOptions& o = options_.motion_fusion;
  robot::MoveStreamRequest request;
  request.start_stamp_ns = start_stamp_ns;
  request.rate_hz = o.rate_hz;
  request.max_pending = o.max_pending;
  for (const robot::FrameAlong& f : robot::FramesAlong(trajectory, o.rate_hz)) {
    request.poses.push_back({f.t_ns, arm.CameraPose(f.q)});
  }
  if (!trajectory.points.empty()) {
    request.X_WC_from = arm.CameraPose(trajectory.points.front().q);
    request.X_WC_to = arm.CameraPose(trajectory.points.back().q);
  }
  rec.expected = static_cast<int>(request.poses.size());
  const std::unique_ptr<robot::MoveStream> stream = source.StreamMove(request);
  if (stream == nullptr) return move();
  rec.streamed = true;
  const auto t0 = SteadyClock::now();
  const int threads = Threads();
  robot::MoveResult result;
  {
    std::jthread worker([&] {
      const ThreadScope scope(threads);
      Consume(*stream, view, rec);
    });
    try {
      result = move();
    } catch (...) {
      stream->End(false);
      throw;
    }
    stream->End(result.ok());
  }
  rec.wall_ms = MsSince(t0);
  const robot::MoveStreamCounters counters = stream->counters();
  rec.dropped = counters.dropped;
  rec.skipped = counters.skipped;
  rec.failed += counters.failed;
  fusion_.RecordMoving(rec);
  return result;
}

void MovingFusion::Consume(robot::MoveStream& stream, int view, MovingFramesRecord& rec) {
  // kWhenFree: the frame the segmenter works on, fused with its masks once they come.
  std::optional<robot::Observation> held;
  int held_k = 0;
  std::future<Result<Segmentation>> pending;
  auto held_since = SteadyClock::now();
  // Fuses one frame and hands it to the observers.
  const auto fuse = [&](const robot::Observation& obs, const Segmentation* seg, int k) {
    const int fused_before = rec.fused;
    fusion_.FuseMoving(obs, seg, rec);
    if (rec.fused == fused_before) return;  // failed: counted and named
    const MovingFrameData data{view, k, &obs, seg};
    for (EpisodeObserver* o : observers_) {
      if (o != nullptr) o->OnMovingFrame(data, fusion_.map());
    }
  };
  const auto fuse_segmented = [&](const robot::Observation& obs, Result<Segmentation> seg, int k) {
    if (seg.ok()) {
      fuse(obs, &*seg, k);
    } else {
      ++rec.segment_failed;
      NoteProblem(rec, seg.status());
      fuse(obs, nullptr, k);
    }
  };
  const auto finish_held = [&](bool wait) {
    if (!pending.valid()) return;
    if (!wait && pending.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return;
    Result<Segmentation> seg = pending.get();
    rec.segment_ms += MsSince(held_since);
    fuse_segmented(*held, std::move(seg), held_k);
    held.reset();
  };
  int k = 0;
  while (!stop_.stop_requested()) {
    const auto t0 = SteadyClock::now();
    Result<std::optional<robot::Observation>> next = stream.Next();
    rec.capture_ms += MsSince(t0);
    ++k;
    if (!next.ok()) {
      NoteProblem(rec, next.status());  // counted by the stream
      continue;
    }
    if (!next->has_value()) break;
    robot::Observation& obs = **next;
    const uint64_t index = MovingFrameIndex(view, k);
    const auto t_busy = SteadyClock::now();
    finish_held(false);
    switch (semantics_) {
      case MovingSemantics::kEveryFrame: {
        const auto t1 = SteadyClock::now();
        Result<Segmentation> seg = SegmentObservation(segmenter_, obs, options_, index, stop_);
        rec.segment_ms += MsSince(t1);
        fuse_segmented(obs, std::move(seg), k);
        break;
      }
      case MovingSemantics::kWhenFree:
        if (pending.valid()) {
          fuse(obs, nullptr, k);
        } else {
          held = std::move(obs);
          held_k = k;
          held_since = SteadyClock::now();
          pending = std::async(std::launch::async, [this, &held, index] {
            return SegmentObservation(segmenter_, *held, options_, index, stop_);
          });
        }
        break;
      case MovingSemantics::kAuto:  // resolved in the constructor
      case MovingSemantics::kNone:
        fuse(obs, nullptr, k);
        break;
    }
    rec.busy_ms += MsSince(t_busy);
  }
  finish_held(true);
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

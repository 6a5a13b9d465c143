#pragma once

// The one place a view is fused into a semantic map: the segmenter's answer checked, the frame
// integrated, the map's counts and their change recorded in the step. The episode loop
// (RunEpisode), `avp replay` (a recording's views) and `avp map build` (views on an arc) all fuse
// through it; tests/architecture_test.cpp fails if any other library or command integrates.

#include <cstddef>
#include <functional>
#include <optional>
#include <stop_token>
#include <vector>

#include <avp/core/segmentation.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/semantic_map.h>
#include <avp/pipeline/episode.h>
#include <avp/robot/arm_model.h>
#include <avp/robot/rgbd_source.h>
#include <avp/robot/trajectory.h>
#include <avp/segmentation/segmenter.h>

namespace avp::pipeline {

/// What one view saw, kept for the observers (StepData): the capture, the segmentation and the
/// plan made after it, each absent when that stage did not happen or failed.
struct ViewSeen {
  std::optional<robot::Observation> observation;
  std::optional<Segmentation> segmentation;
  std::optional<planning::PlanResult> plan;

  StepData Data() const {
    return StepData{observation ? &*observation : nullptr, segmentation ? &*segmentation : nullptr,
                    plan ? &*plan : nullptr};
  }
};

/// The segmenter's answer for one observation (prompt and score threshold of `options`, the
/// observation's simulator labels, `frame_index`); a throw or a segmentation that does not fit
/// the frame becomes an Internal error naming the segmenter. A requested `stop` makes the request
/// report Cancelled.
Result<Segmentation> SegmentObservation(segmentation::Segmenter& segmenter,
                                        const robot::Observation& obs,
                                        const EpisodeOptions& options, uint64_t frame_index,
                                        const std::stop_token& stop = {});

/// The instance masks of `segmentation` with no pixel of valid depth in `frame` (finite, within
/// frame.K's depth range): StepRecord::masks_without_depth.
size_t CountMasksWithoutDepth(const Segmentation& segmentation, const RgbdFrame& frame);

/// Fuses views into one map, step after step, and records in each StepRecord what the fusion did
/// (segment_status, masks, integration, integrate_status, segment_ms, integrate_ms) and the map
/// after it (known, occupied and target voxels, target instances, and the change since the
/// previous view fused through this object, or since the map as it was at construction).
/// Not thread-safe; the map must outlive it.
class ViewFusion {
 public:
  /// Uses options.integrator, options.target_class, and for Segment(), options.prompt and
  /// options.score_threshold. The options are not validated here (RunEpisode and the callers
  /// validate theirs once).
  ViewFusion(mapping::SemanticMap& map, const EpisodeOptions& options);

  /// Segments `obs` with `segmenter` (SegmentObservation) and fuses it: with the masks, or depth
  /// only when the segmentation failed (its status in step.segment_status). The observation and
  /// the segmentation are kept in `seen`.
  void Segment(robot::Observation obs, segmentation::Segmenter& segmenter, uint64_t frame_index,
               const std::stop_token& stop, StepRecord& step, ViewSeen& seen);

  /// Fuses `obs` with masks that are already known (a recording's, the simulator's labels), or
  /// depth only when `segmentation` is empty. step.segment_ms is left as it is.
  void Fuse(robot::Observation obs, std::optional<Segmentation> segmentation, StepRecord& step,
            ViewSeen& seen);

  /// Records the map as it is now in `step` (counts and change) without fusing anything: a view
  /// whose capture failed.
  void RecordMap(StepRecord& step);

  /// Fuses a frame taken while the arm moved (options.motion_fusion.carving), with `segmentation`
  /// or depth only, adding its times and counts to `rec` (a failed integration counts as failed,
  /// named in rec.first_problem).
  void FuseMoving(const robot::Observation& obs, const Segmentation* segmentation,
                  MovingFramesRecord& rec);
  /// Records in `rec` what the moving frames since the last view (or RecordMoving) added, and
  /// takes the map as it is now as the next view's baseline.
  void RecordMoving(MovingFramesRecord& rec);

  const mapping::SemanticMap& map() const { return map_; }

 private:
  void Integrate(StepRecord& step, ViewSeen& seen);

  mapping::SemanticMap& map_;
  EpisodeOptions options_;
  mapping::Integrator integrator_;
  mapping::Integrator moving_integrator_;
  size_t known_before_ = 0;
  size_t target_before_ = 0;
};

/// Fuses the frames a source streams while the arm moves (EpisodeOptions::motion_fusion), on a
/// thread of its own while the arm executes the move, through a ViewFusion; which frames are
/// segmented follows motion_fusion.semantics. Not thread-safe; one move at a time.
class MovingFusion {
 public:
  /// `observers` see every frame fused (OnMovingFrame).
  MovingFusion(ViewFusion& fusion, segmentation::Segmenter& segmenter,
               const EpisodeOptions& options, std::stop_token stop,
               std::vector<EpisodeObserver*> observers = {});

  /// Streams the frames `source` takes while `move` executes `trajectory` (whose camera poses
  /// come from `arm`) and fuses them as they come; returns `move`'s result once every frame of
  /// the move was fused or dropped. `view`: the view the move leaves (frame indices);
  /// `start_stamp_ns`: the episode's stamp of the move's start. A source that does not stream:
  /// the move alone (rec.streamed false).
  robot::MoveResult Run(robot::RgbdSource& source, const robot::ArmModel& arm,
                        const robot::JointTrajectory& trajectory, int view, int64_t start_stamp_ns,
                        const std::function<robot::MoveResult()>& move, MovingFramesRecord& rec);

 private:
  void Consume(robot::MoveStream& stream, int view, MovingFramesRecord& rec);

  ViewFusion& fusion_;
  segmentation::Segmenter& segmenter_;
  EpisodeOptions options_;
  MovingSemantics semantics_;
  std::stop_token stop_;
  std::vector<EpisodeObserver*> observers_;
};

/// Hands a completed step to every observer (OnView with what it saw, then OnStep); null
/// observers are skipped.
void NotifyStep(const std::vector<EpisodeObserver*>& observers, const StepRecord& step,
                const StepData& data, const mapping::SemanticMap& map);

/// Hands the episode's end to every observer.
void NotifyEnd(const std::vector<EpisodeObserver*>& observers, const EpisodeResult& result,
               const mapping::SemanticMap& map);

}  // namespace avp::pipeline

#pragma once

// `avp replay BAG`: segmentation, mapping and (with a ground truth) evaluation over the views of
// an MCAP recording, into a run folder like `avp run`'s (docs/recording.md "Replay").

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/experiment/registries.h>
#include <avp/experiment/run_config.h>
#include <avp/experiment/run_folder.h>
#include <avp/pipeline/episode.h>
#include <avp/ros/bag/bag_reader.h>

namespace avp::experiment {

/// The segmenter name that replays the recording's own masks.
inline constexpr std::string_view kRecordedSegmenter = "recorded";

/// The run configuration a bag was recorded with: its "avp" metadata's run_config (the resolved
/// YAML `avp run --print-config` prints) over the defaults, or the defaults when the bag has
/// none (a robot's bag). Not validated (the caller applies its own --config / --set first).
/// InvalidArgument naming the bag and the key when run_config does not read back.
Result<RunConfig> BagRunConfig(const ros::bag::BagReader& bag);

struct ReplayOptions {
  /// "recorded": the recording's masks (every view must have them); a registered segmenter name
  /// (run with the configuration's options when it is the configuration's segmenter, else its
  /// defaults); empty: "recorded" when every view has masks, else the configuration's segmenter.
  /// The oracle segmenters need the simulator labels (/avp/sim/instance and /avp/sim/class).
  std::string segmenter;
  /// Where the folder goes, --force, per-step callback (progress).
  RunFolderOptions folder;
};

struct ReplaySummary {
  RunSummary run;
  /// The segmenter that made the masks: "recorded" or a registered name.
  std::string segmenter;
  size_t views = 0;
  /// Per fused view: its index in the bag, its masks and those with no valid depth.
  struct ViewMasks {
    int index = 0;
    size_t masks = 0;
    size_t masks_without_depth = 0;
  };
  std::vector<ViewMasks> view_masks;
  /// avp recordings made with fusion during motion: the frames fused while moving (between the
  /// views, as the episode fused them), summed.
  pipeline::MovingFramesRecord moving;
  /// Over every view.
  size_t masks() const;
  size_t masks_without_depth() const;
  /// avp recordings: views whose recomputed metrics were compared with the recorded /avp/step
  /// metrics, and those that differ (the first difference described).
  size_t metrics_compared = 0;
  size_t metrics_differ = 0;
  std::string first_difference;
  /// What the replay left out or could not do (a ground truth of another voxel size, no ROI ...).
  std::vector<std::string> notes;
};

/// Replays `bag` with `config` into options.folder.out_dir, reading it view by view (bounded
/// memory: ros::bag::BagReader): each view segmented (the recorded masks or the segmenter),
/// integrated into a map of config.map with config.episode.integrator (exactly as the episode
/// did; config.replay's region of interest, when set, bounds the map), and, when the bag has a
/// ground truth of the map's voxel size, evaluated after every view as `avp run` does. The frames
/// fused are config.replay's (ros::bag::FrameSelection). Writes record.json (with a "replay"
/// section: the bag, its format and files, the segmenter, what became of each frame, damage, the
/// comparison with the recorded metrics), metrics.csv, map.avpmap, map.ot, fruit_voxels.ply,
/// metrics.svg (RunEpisodeToFolder). A damaged bag replays its intact views and the episode ends
/// "interrupted" naming the damage. Errors (before anything is written): invalid configuration,
/// "recorded" without masks, an oracle segmenter without labels, a robot's bag without a
/// segmenter, a bag with nothing to fuse, a bad ground_truth.json; then the folder's.
Result<ReplaySummary> ReplayToFolder(ros::bag::BagReader& bag, RunConfig config,
                                     const Registries& registries, const ReplayOptions& options);

}  // namespace avp::experiment

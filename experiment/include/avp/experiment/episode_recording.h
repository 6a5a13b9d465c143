#pragma once

// `--record` of avp run / live / bench: an MCAP recording of the episode (docs/recording.md).

#include <filesystem>
#include <memory>
#include <string>

#include <avp/core/status.h>
#include <avp/eval/ground_truth.h>
#include <avp/experiment/registries.h>
#include <avp/experiment/run_config.h>
#include <avp/ros/bag/mcap_recorder.h>

namespace avp::experiment {

/// What a recording says about its run besides the configuration.
struct RecordingInfo {
  std::string command = "avp run";  ///< "avp run", "avp live", "avp bench"
  std::string scene;                ///< the scene's name
  std::string base_frame = "igus_rebel_base_link";
  /// The chunks' compression: "" (none), "zstd" or "lz4" (`--record-compression`).
  std::string compression = "";
  const eval::GroundTruth* gt = nullptr;  ///< attached as ground_truth.json when set
};

/// Opens `path` for an episode of `config`: the Metadata record "avp" (command, revision, scene,
/// seed, planner, segmenter, prompt, views, base_frame, run_config = RunConfigToYaml's text),
/// the ground truth as the attachment ground_truth.json (eval::GroundTruthToJson), the default
/// arm's joint names. Errors name the file.
Result<std::unique_ptr<ros::bag::McapRecorder>> OpenEpisodeRecording(
    const std::filesystem::path& path, const RunConfig& config, const Registries& registries,
    const RecordingInfo& info);

}  // namespace avp::experiment

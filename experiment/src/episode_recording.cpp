#include "avp/experiment/episode_recording.h"

#include <chrono>

#include <fmt/format.h>

#include <avp/eval/ground_truth_io.h>
#include <avp/io/options_yaml.h>
#include <avp/report/provenance.h>
#include <avp/robot/arm_model.h>
#include <avp/ros/bag/layout.h>

namespace avp::experiment {

Result<std::unique_ptr<ros::bag::McapRecorder>> OpenEpisodeRecording(
    const std::filesystem::path& path, const RunConfig& config, const Registries& registries,
    const RecordingInfo& info) {
  ros::bag::RecorderOptions options;
  options.base_frame = info.base_frame;
  options.compression = info.compression;
  AVP_ASSIGN_OR_RETURN(const robot::ArmModel arm, robot::LoadDefaultArm());
  options.joint_names = arm.joint_names();
  AVP_ASSIGN_OR_RETURN(const YAML::Node yaml, RunConfigToYaml(config, registries));
  options.metadata = {{"command", info.command},
                      {"revision", report::SourceRevision()},
                      {"scene", info.scene},
                      {"seed", std::to_string(config.seed)},
                      {"planner", config.planner.name},
                      {"segmenter", config.segmenter.name},
                      {"prompt", config.episode.prompt},
                      {"views", std::to_string(config.episode.views)},
                      {"run_config", io::YamlText(yaml)}};
  if (info.gt != nullptr) {
    const auto now = static_cast<uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                               std::chrono::system_clock::now().time_since_epoch())
                                               .count());
    options.attachments.push_back({.log_time = 0,
                                   .create_time = now,
                                   .name = std::string(ros::bag::kGroundTruthAttachment),
                                   .media_type = std::string(ros::bag::kGroundTruthMediaType),
                                   .data = eval::GroundTruthToJson(*info.gt).dump()});
  }
  return ros::bag::McapRecorder::Open(path, std::move(options));
}

}  // namespace avp::experiment

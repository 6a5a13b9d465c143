#pragma once

// McapRecorder: an episode observer that writes every fused view into an MCAP file in the `ros2`
// profile (the layout of layout.h; docs/recording.md), chunk by chunk, so that a run that is
// killed leaves its finished steps readable (ros::mcap::ReadStreaming).

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <stop_token>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/pipeline/episode.h>
#include <avp/ros/bag/layout.h>
#include <avp/ros/mcap/mcap.h>

namespace avp::ros::bag {

struct RecorderOptions {
  /// The frame of the TF (parent of the camera frame), the markers and the map.
  std::string base_frame = std::string(kDefaultBaseFrame);
  /// Names of the arm's joints for /joint_states (the model's); missing ones are "joint_<i+1>".
  std::vector<std::string> joint_names;
  /// The Metadata record "avp" (layout.h lists the keys); base_frame is added.
  std::map<std::string, std::string> metadata;
  /// Attachments written after the metadata (ground_truth.json).
  std::vector<ros::mcap::Attachment> attachments;
  /// Chunks are written after every view anyway; a view larger than this is split.
  uint64_t chunk_size = 64u << 20;
  /// The chunks' compression: "" (none), "zstd" or "lz4" (mcap::WriterOptions::compression).
  std::string compression = "";
};

class McapRecorder final : public pipeline::EpisodeObserver {
 public:
  /// Creates `path` (truncating it), writes the header, the schemas and channels of every topic,
  /// the metadata and the attachments. Errors name the file.
  static Result<std::unique_ptr<McapRecorder>> Open(const std::filesystem::path& path,
                                                    RecorderOptions options = {});
  ~McapRecorder() override;

  /// A write error requests a stop on `stop` (the episode's stop source).
  void StopOnError(std::stop_source stop) { stop_ = std::move(stop); }

  /// Writes every topic of the view and flushes its chunk to the file.
  void OnView(const pipeline::StepRecord& step, const pipeline::StepData& data,
              const mapping::SemanticMap& map) override;
  void OnStep(const pipeline::StepRecord&, const mapping::SemanticMap&) override {}
  /// Writes a frame fused while the arm moved: the camera topics (and the masks, when it was
  /// segmented) at its stamp, and kMovingFrameTopic; one chunk per frame.
  void OnMovingFrame(const pipeline::MovingFrameData& frame,
                     const mapping::SemanticMap& map) override;

  /// OK, or the first write error (naming the file).
  const Status& status() const { return status_; }
  /// Writes the summary and closes the file: the first error, if any.
  Status Close();

  const std::filesystem::path& path() const { return writer_->path(); }
  /// Views written, and frames fused while moving written.
  int views() const { return views_; }
  int moving_frames() const { return moving_frames_; }
  /// Messages written per topic.
  const ros::mcap::Statistics& statistics() const { return writer_->statistics(); }

 private:
  McapRecorder(std::unique_ptr<ros::mcap::Writer> writer, RecorderOptions options);
  Status AddChannels();
  /// A channel for `topic` (its schema added once per type), as rosbag2 writes them.
  Status AddChannel(std::string_view topic, std::string_view type, std::string_view schema);
  Status WriteView(const pipeline::StepRecord& step, const pipeline::StepData& data,
                   const mapping::SemanticMap& map);
  /// The camera topics of one frame (colour, depth, CameraInfo, TF, simulator labels, masks).
  Status WriteFrame(const robot::Observation& observation, const Segmentation* segmentation,
                    int64_t stamp);
  Status WriteMovingFrame(const pipeline::MovingFrameData& frame);
  template <class T>
  Status Publish(uint16_t channel, uint64_t time_ns, const T& msg);

  std::unique_ptr<ros::mcap::Writer> writer_;
  RecorderOptions options_;
  std::map<std::string, uint16_t, std::less<>> channels_;
  std::map<std::string, uint16_t, std::less<>> schemas_;
  std::map<uint16_t, uint32_t> sequences_;
  std::stop_source stop_{std::nostopstate};
  Status status_;
  int views_ = 0;
  int moving_frames_ = 0;
  int64_t last_stamp_ns_ = -1;
  bool closed_ = false;
};

}  // namespace avp::ros::bag

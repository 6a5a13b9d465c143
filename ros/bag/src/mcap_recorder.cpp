#include "avp/ros/bag/mcap_recorder.h"

#include <fmt/format.h>

#include <avp/ros/bag/encode.h>
#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::bag {
namespace {

struct TopicInfo {
  std::string_view topic;
  std::string_view type;
  std::string_view schema;
};

template <class T>
TopicInfo Topic(std::string_view topic) {
  return {topic, ros::msg::MessageTraits<T>::kRosName, ros::msg::Definition<T>()};
}

}  // namespace

McapRecorder::McapRecorder(std::unique_ptr<ros::mcap::Writer> writer, RecorderOptions options)
    : writer_(std::move(writer)), options_(std::move(options)) {}

McapRecorder::~McapRecorder() {
  if (!closed_) (void)Close();
}

Result<std::unique_ptr<McapRecorder>> McapRecorder::Open(const std::filesystem::path& path,
                                                         RecorderOptions options) {
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<ros::mcap::Writer> writer,
                       ros::mcap::Writer::Open(path, {.chunk_size = options.chunk_size,
                                                      .compression = options.compression}));
  std::unique_ptr<McapRecorder> r(new McapRecorder(std::move(writer), std::move(options)));
  AVP_RETURN_IF_ERROR(r->AddChannels());
  std::map<std::string, std::string> metadata = r->options_.metadata;
  metadata["base_frame"] = r->options_.base_frame;
  AVP_RETURN_IF_ERROR(r->writer_->WriteMetadata({std::string(kMetadataName), metadata}));
  for (const ros::mcap::Attachment& a : r->options_.attachments) {
    AVP_RETURN_IF_ERROR(r->writer_->WriteAttachment(a));
  }
  AVP_RETURN_IF_ERROR(r->writer_->Flush());
  return r;
}

Status McapRecorder::AddChannels() {
  const TopicInfo topics[] = {
      Topic<ros::msg::Image>(kColorTopic),
      Topic<ros::msg::Image>(kDepthTopic),
      Topic<ros::msg::CameraInfo>(kCameraInfoTopic),
      Topic<ros::msg::TFMessage>(kTfTopic),
      Topic<ros::msg::JointState>(kJointStatesTopic),
      Topic<ros::msg::Image>(kInstanceImageTopic),
      Topic<ros::msg::String>(kInstancesTopic),
      Topic<ros::msg::Image>(kSimInstanceTopic),
      Topic<ros::msg::Image>(kSimClassTopic),
      Topic<ros::msg::MarkerArray>(kCandidatesTopic),
      Topic<ros::msg::Octomap>(kMapTopic),
      Topic<ros::msg::String>(kStepTopic),
  };
  for (const TopicInfo& t : topics) AVP_RETURN_IF_ERROR(AddChannel(t.topic, t.type, t.schema));
  return Status::Ok();
}

Status McapRecorder::AddChannel(std::string_view topic, std::string_view type,
                                std::string_view schema) {
  auto it = schemas_.find(type);
  if (it == schemas_.end()) {
    AVP_ASSIGN_OR_RETURN(const uint16_t id, writer_->AddSchema(type, "ros2msg", schema));
    it = schemas_.emplace(std::string(type), id).first;
  }
  // As rosbag2 (Jazzy) writes them: the QoS offered and the type's REP-2011 hash.
  const std::string qos =
      ros::mcap::OfferedQosProfiles(/*reliable=*/true, /*transient_local=*/false);
  AVP_ASSIGN_OR_RETURN(const std::string hash, ros::msg::TypeHashOf(type));
  AVP_ASSIGN_OR_RETURN(const uint16_t channel, writer_->AddChannel(it->second, topic, "cdr",
                                                                   {{"offered_qos_profiles", qos},
                                                                    {"topic_type_hash", hash}}));
  channels_.emplace(std::string(topic), channel);
  return Status::Ok();
}

template <class T>
Status McapRecorder::Publish(uint16_t channel, uint64_t time_ns, const T& msg) {
  const std::vector<uint8_t> bytes = ros::msg::Encode(msg);
  return writer_->Write(channel, sequences_[channel]++, time_ns, time_ns, bytes);
}

void McapRecorder::OnView(const pipeline::StepRecord& step, const pipeline::StepData& data,
                          const mapping::SemanticMap& map) {
  if (!status_.ok() || closed_) return;
  status_ = WriteView(step, data, map);
  if (!status_.ok() && stop_.stop_possible()) stop_.request_stop();
}

Status McapRecorder::WriteView(const pipeline::StepRecord& step, const pipeline::StepData& data,
                               const mapping::SemanticMap& map) {
  const robot::Observation* obs = data.observation;
  // The capture's stamp; a view without a capture takes the one after the previous view's.
  int64_t stamp = obs != nullptr ? obs->frame.stamp_ns : last_stamp_ns_ + 1;
  if (stamp < 0) stamp = 0;
  last_stamp_ns_ = stamp;
  const auto t = static_cast<uint64_t>(stamp);
  auto channel = [&](std::string_view topic) { return channels_.find(topic)->second; };

  ros::msg::Header base{ros::msg::ToTimeMsg(stamp), options_.base_frame};
  if (obs != nullptr) AVP_RETURN_IF_ERROR(WriteFrame(*obs, data.segmentation, stamp));
  ros::msg::JointState joints;
  joints.header = ros::msg::Header{ros::msg::ToTimeMsg(stamp), ""};
  for (Eigen::Index i = 0; i < step.q.size(); ++i) {
    const auto k = static_cast<size_t>(i);
    joints.name.push_back(k < options_.joint_names.size() ? options_.joint_names[k]
                                                          : fmt::format("joint_{}", k + 1));
    joints.position.push_back(step.q[i]);
  }
  AVP_RETURN_IF_ERROR(Publish(channel(kJointStatesTopic), t, joints));

  const std::vector<planning::ViewCandidate>& ranked =
      data.plan != nullptr ? data.plan->ranked : step.top_candidates;
  AVP_RETURN_IF_ERROR(Publish(channel(kCandidatesTopic), t,
                              CandidateMarkers(ranked, step.chosen_rank, step.view, base)));

  // liboctomap's bytes, built straight from the grid (OctomapBinaryTree: several times faster).
  AVP_ASSIGN_OR_RETURN(const std::string tree, OctomapBinaryTree(map.grid()));
  ros::msg::Octomap octomap;
  octomap.header = base;
  octomap.binary = true;
  octomap.id = "OcTree";
  octomap.resolution = map.grid().voxel_size_m();
  octomap.data.assign(tree.begin(), tree.end());
  AVP_RETURN_IF_ERROR(Publish(channel(kMapTopic), t, octomap));

  AVP_RETURN_IF_ERROR(
      Publish(channel(kStepTopic), t, ros::msg::String{StepToJson(step, data.plan, stamp).dump()}));
  // The view's chunk goes to the file now: a run killed later leaves this step readable.
  AVP_RETURN_IF_ERROR(writer_->Flush());
  ++views_;
  return Status::Ok();
}

Status McapRecorder::WriteFrame(const robot::Observation& observation,
                                const Segmentation* segmentation, int64_t stamp) {
  const robot::Observation* obs = &observation;
  const auto t = static_cast<uint64_t>(stamp);
  auto channel = [&](std::string_view topic) { return channels_.find(topic)->second; };
  ros::msg::Header base{ros::msg::ToTimeMsg(stamp), options_.base_frame};
  const RgbdFrame& f = obs->frame;
  const ros::msg::Header cam{ros::msg::ToTimeMsg(stamp), f.frame_id};
  AVP_RETURN_IF_ERROR(Publish(channel(kColorTopic), t, ros::msg::ToColorImage(f.rgb, cam)));
  AVP_RETURN_IF_ERROR(Publish(channel(kDepthTopic), t, ros::msg::ToDepthImage(f.depth_m, cam)));
  AVP_RETURN_IF_ERROR(Publish(channel(kCameraInfoTopic), t, ros::msg::ToCameraInfo(f.K, cam)));
  ros::msg::TFMessage tf;
  tf.transforms.resize(1);
  tf.transforms[0].header = base;
  tf.transforms[0].child_frame_id = f.frame_id;
  tf.transforms[0].transform = ros::msg::ToTransformMsg(f.X_WC);
  AVP_RETURN_IF_ERROR(Publish(channel(kTfTopic), t, tf));
  if (obs->labels) {
    AVP_RETURN_IF_ERROR(
        Publish(channel(kSimInstanceTopic), t,
                ros::msg::ToInstanceIdImage(obs->labels->instance_ids, kSimInstanceEncoding, cam)));
    AVP_RETURN_IF_ERROR(
        Publish(channel(kSimClassTopic), t, ros::msg::ToClassIdImage(obs->labels->class_ids, cam)));
  }
  if (segmentation != nullptr) {
    AVP_RETURN_IF_ERROR(Publish(
        channel(kInstanceImageTopic), t,
        ros::msg::ToInstanceIdImage(InstanceIdImage(*segmentation), kInstanceImageEncoding, cam)));
    AVP_RETURN_IF_ERROR(Publish(channel(kInstancesTopic), t,
                                ros::msg::String{InstancesToJson(*segmentation).dump()}));
  }
  return Status::Ok();
}

void McapRecorder::OnMovingFrame(const pipeline::MovingFrameData& frame,
                                 const mapping::SemanticMap&) {
  if (!status_.ok() || closed_ || frame.observation == nullptr) return;
  status_ = WriteMovingFrame(frame);
  if (!status_.ok() && stop_.stop_possible()) stop_.request_stop();
}

Status McapRecorder::WriteMovingFrame(const pipeline::MovingFrameData& frame) {
  const int64_t stamp = std::max<int64_t>(0, frame.observation->frame.stamp_ns);
  if (!channels_.contains(kMovingFrameTopic)) {
    // Added with the first moving frame: a recording without fusion during motion has the
    // channels it always had.
    const TopicInfo t = Topic<ros::msg::String>(kMovingFrameTopic);
    AVP_RETURN_IF_ERROR(AddChannel(t.topic, t.type, t.schema));
  }
  AVP_RETURN_IF_ERROR(WriteFrame(*frame.observation, frame.segmentation, stamp));
  const nlohmann::json marker{{"view", frame.view + 1},
                              {"k", frame.k},
                              {"stamp_ns", stamp},
                              {"segmented", frame.segmentation != nullptr},
                              {"X_WC", PoseToJson(frame.observation->frame.X_WC)}};
  AVP_RETURN_IF_ERROR(Publish(channels_.find(kMovingFrameTopic)->second,
                              static_cast<uint64_t>(stamp), ros::msg::String{marker.dump()}));
  // One chunk per frame: a move's frames (~2.5 MB each) are never held together.
  AVP_RETURN_IF_ERROR(writer_->Flush());
  ++moving_frames_;
  return Status::Ok();
}

Status McapRecorder::Close() {
  if (closed_) return status_;
  closed_ = true;
  const Status closed = writer_->Close();
  if (status_.ok()) status_ = closed;
  return status_;
}

}  // namespace avp::ros::bag

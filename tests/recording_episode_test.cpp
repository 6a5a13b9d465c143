// avp's MCAP recordings of real simulated episodes: every topic of the layout (ros/bag/layout.h)
// read back with ros::mcap::ReadIndexed and decoded with ros/msg equals what the episode saw
// (frames, labels, masks, poses, joints, maps, steps: exactly), one message per view and topic; the
// metadata and the ground-truth attachment are there; a recording cut off after its last flushed
// view keeps every view; a write error (a full disk) stops the episode and names the file.
#include <csignal>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <avp/eval/ground_truth_io.h>
#include <avp/experiment/bench.h>
#include <avp/experiment/episode_recording.h>
#include <avp/experiment/episode_runner.h>
#include <avp/experiment/run_folder.h>
#include <avp/mapping/octomap_io.h>
#include <avp/ros/bag/encode.h>
#include <avp/ros/bag/layout.h>
#include <avp/ros/bag/mcap_recorder.h>
#include <avp/ros/mcap/mcap.h>
#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/messages.h>
#include <avp/sim/scenario.h>
#include <avp/test/temp_dir_test.h>

namespace avp {
namespace {

namespace fs = std::filesystem;
namespace rec = ros::bag;
using ::testing::HasSubstr;

const experiment::Registries& Registries() {
  static const auto* registries = new experiment::Registries(experiment::BuiltinRegistries());
  return *registries;
}

experiment::RunConfig Config() {
  experiment::RunConfig c;
  c.scenario = "tomato-multiple-clusters";
  c.seed = 3;
  c.planner.name = "avp-nbv";
  c.segmenter.name = "oracle";
  c.episode.views = 3;
  c.threads = 2;
  return c;
}

/// Deep copies of what each view saw (StepData is valid only during OnView).
struct Seen {
  pipeline::StepRecord step;
  std::optional<robot::Observation> obs;
  std::optional<Segmentation> seg;
  std::vector<planning::ViewCandidate> ranked;
  std::string octree;
};
class Keeper final : public pipeline::EpisodeObserver {
 public:
  std::vector<Seen> seen;
  void OnView(const pipeline::StepRecord& s, const pipeline::StepData& d,
              const mapping::SemanticMap& map) override {
    Seen v;
    v.step = s;
    if (d.observation != nullptr) v.obs = *d.observation;
    if (d.segmentation != nullptr) v.seg = *d.segmentation;
    if (d.plan != nullptr) v.ranked = d.plan->ranked;
    v.octree = mapping::OctomapBinaryMessageData(map.grid()).value().data;
    seen.push_back(std::move(v));
  }
  void OnStep(const pipeline::StepRecord&, const mapping::SemanticMap&) override {}
};

/// Messages of `topic`, in log-time order.
std::vector<const ros::mcap::Message*> On(const ros::mcap::File& f, std::string_view topic) {
  uint16_t id = 0xFFFF;
  for (const ros::mcap::Channel& c : f.channels) {
    if (c.topic == topic) id = c.id;
  }
  std::vector<const ros::mcap::Message*> out;
  for (const ros::mcap::Message& m : f.messages) {
    if (m.channel_id == id) out.push_back(&m);
  }
  return out;
}

template <class T>
T Decoded(const ros::mcap::Message* m) {
  Result<T> r = ros::msg::Decode<T>(m->data);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  return r.ok() ? *r : T{};
}

class RecordingTest : public test::TempDirTest {};

/// Every topic once per view, with its type, QoS, type hash and schema.
void ExpectEveryTopicOncePerView(const ros::mcap::File& f, size_t views) {
  // The oracle's source has simulator labels.
  const std::pair<std::string_view, std::string_view> topics[] = {
      {rec::kColorTopic, "sensor_msgs/msg/Image"},
      {rec::kDepthTopic, "sensor_msgs/msg/Image"},
      {rec::kCameraInfoTopic, "sensor_msgs/msg/CameraInfo"},
      {rec::kTfTopic, "tf2_msgs/msg/TFMessage"},
      {rec::kJointStatesTopic, "sensor_msgs/msg/JointState"},
      {rec::kInstanceImageTopic, "sensor_msgs/msg/Image"},
      {rec::kInstancesTopic, "std_msgs/msg/String"},
      {rec::kSimInstanceTopic, "sensor_msgs/msg/Image"},
      {rec::kSimClassTopic, "sensor_msgs/msg/Image"},
      {rec::kCandidatesTopic, "visualization_msgs/msg/MarkerArray"},
      {rec::kMapTopic, "octomap_msgs/msg/Octomap"},
      {rec::kStepTopic, "std_msgs/msg/String"}};
  ASSERT_EQ(f.channels.size(), std::size(topics));
  for (const auto& [topic, type] : topics) {
    SCOPED_TRACE(std::string(topic));
    EXPECT_EQ(On(f, topic).size(), views);
    const auto ch = std::find_if(f.channels.begin(), f.channels.end(),
                                 [&](const ros::mcap::Channel& x) { return x.topic == topic; });
    ASSERT_NE(ch, f.channels.end());
    EXPECT_EQ(ch->message_encoding, "cdr");
    EXPECT_THAT(ch->metadata.at("offered_qos_profiles"), HasSubstr("reliability: 1"));
    EXPECT_EQ(ch->metadata.at("topic_type_hash"), ros::msg::TypeHashOf(type).value());
    EXPECT_EQ(f.schemas.at(ch->schema_id - 1).name, type);
    EXPECT_EQ(f.schemas.at(ch->schema_id - 1).encoding, "ros2msg");
    EXPECT_EQ(f.statistics.channel_message_counts.at(ch->id), views);
  }
  EXPECT_EQ(f.statistics.message_count, views * std::size(topics));
}

/// The "avp" metadata and the ground truth attachment, exact.
void ExpectMetadataAndGroundTruth(const ros::mcap::File& f, const sim::Scene& scene,
                                  const eval::GroundTruth& gt) {
  ASSERT_EQ(f.metadata.size(), 1u);
  EXPECT_EQ(f.metadata[0].name, "avp");
  const auto& md = f.metadata[0].metadata;
  EXPECT_EQ(md.at("command"), "avp run");
  EXPECT_EQ(md.at("scene"), scene.name);
  EXPECT_EQ(md.at("seed"), "3");
  EXPECT_EQ(md.at("planner"), "avp-nbv");
  EXPECT_EQ(md.at("segmenter"), "oracle");
  EXPECT_EQ(md.at("base_frame"), "igus_rebel_base_link");
  EXPECT_THAT(md.at("run_config"), HasSubstr("planner:"));
  ASSERT_EQ(f.attachments.size(), 1u);
  EXPECT_EQ(f.attachments[0].name, "ground_truth.json");
  EXPECT_EQ(f.attachments[0].media_type, "application/json");
  EXPECT_EQ(f.attachments[0].data, eval::GroundTruthToJson(gt).dump());
}

/// View v's camera topics: colour, depth, CameraInfo, TF and joints, as the episode saw them.
void ExpectCameraTopics(const ros::mcap::File& f, size_t v, const Seen& s) {
  const RgbdFrame& frame = s.obs->frame;
  const uint64_t t = static_cast<uint64_t>(frame.stamp_ns);
  EXPECT_EQ(On(f, rec::kColorTopic)[v]->log_time, t);
  EXPECT_EQ(On(f, rec::kStepTopic)[v]->publish_time, t);

  const auto color = Decoded<ros::msg::Image>(On(f, rec::kColorTopic)[v]);
  EXPECT_EQ(color.header.frame_id, frame.frame_id);
  EXPECT_EQ(color.header.stamp.ToNanoseconds(), frame.stamp_ns);
  EXPECT_EQ(ros::msg::ColorFromImage(color, rec::kColorTopic).value(), frame.rgb);
  const auto depth = Decoded<ros::msg::Image>(On(f, rec::kDepthTopic)[v]);
  EXPECT_EQ(depth.encoding, "32FC1");
  EXPECT_EQ(ros::msg::DepthFromImage(depth, rec::kDepthTopic).value(),
            frame.depth_m);  // bit-exact floats
  const auto info = Decoded<ros::msg::CameraInfo>(On(f, rec::kCameraInfoTopic)[v]);
  EXPECT_EQ(info.k[0], frame.K.fx);
  EXPECT_EQ(info.k[5], frame.K.cy);
  EXPECT_EQ(info.width, static_cast<uint32_t>(frame.K.width));

  const auto tf = Decoded<ros::msg::TFMessage>(On(f, rec::kTfTopic)[v]);
  ASSERT_EQ(tf.transforms.size(), 1u);
  EXPECT_EQ(tf.transforms[0].header.frame_id, "igus_rebel_base_link");
  EXPECT_EQ(tf.transforms[0].child_frame_id, frame.frame_id);
  EXPECT_EQ(tf.transforms[0].transform.translation.x, frame.X_WC.translation().x());
  const RigidTransform tf_pose = ros::msg::FromTransformMsg(tf.transforms[0].transform).value();
  EXPECT_TRUE(tf_pose.rotation().isApprox(frame.X_WC.rotation(), 1e-12));

  const auto joints = Decoded<ros::msg::JointState>(On(f, rec::kJointStatesTopic)[v]);
  ASSERT_EQ(joints.position.size(), static_cast<size_t>(s.step.q.size()));
  for (size_t k = 0; k < joints.position.size(); ++k) {
    EXPECT_EQ(joints.position[k], s.step.q[static_cast<Eigen::Index>(k)]);
    EXPECT_FALSE(joints.name[k].empty());
  }
}

/// View v's masks: the instance image, the instances JSON and the simulator's labels.
void ExpectSegmentationTopics(const ros::mcap::File& f, size_t v, const Seen& s) {
  const auto ids = Decoded<ros::msg::Image>(On(f, rec::kInstanceImageTopic)[v]);
  EXPECT_EQ(ids.encoding, "mono16");
  EXPECT_EQ(ros::msg::InstanceIdsFromImage(ids, rec::kInstanceImageTopic).value(),
            rec::InstanceIdImage(*s.seg));
  const Segmentation masks =
      rec::InstancesFromJson(
          nlohmann::json::parse(Decoded<ros::msg::String>(On(f, rec::kInstancesTopic)[v]).data))
          .value();
  ASSERT_EQ(masks.instances.size(), s.seg->instances.size());
  EXPECT_GT(masks.instances.size(), 0u);
  for (size_t i = 0; i < masks.instances.size(); ++i) {
    const InstanceMask& a = s.seg->instances[i];
    const InstanceMask& b = masks.instances[i];
    EXPECT_EQ(b.confidence, a.confidence);
    EXPECT_EQ(b.semantic_class, a.semantic_class);
    ASSERT_TRUE(b.mask.SameSizeAs(a.mask));
    for (size_t p = 0; p < a.mask.data().size(); ++p) {
      ASSERT_EQ(b.mask.data()[p] != 0, a.mask.data()[p] != 0) << "instance " << i;
    }
  }
  ASSERT_TRUE(s.obs->labels.has_value());
  EXPECT_EQ(
      ros::msg::InstanceIdsFromImage(Decoded<ros::msg::Image>(On(f, rec::kSimInstanceTopic)[v]),
                                     rec::kInstanceImageTopic)
          .value(),
      s.obs->labels->instance_ids);
  EXPECT_EQ(ros::msg::ClassIdsFromImage(Decoded<ros::msg::Image>(On(f, rec::kSimClassTopic)[v]),
                                        rec::kSimClassTopic)
                .value(),
            s.obs->labels->class_ids);
}

/// View v's map, candidates and step record.
void ExpectMapAndStepTopics(const ros::mcap::File& f, size_t v, size_t views, const Seen& s,
                            const experiment::RunConfig& c) {
  const auto octomap = Decoded<ros::msg::Octomap>(On(f, rec::kMapTopic)[v]);
  EXPECT_TRUE(octomap.binary);
  EXPECT_EQ(octomap.id, "OcTree");
  EXPECT_EQ(octomap.resolution, c.map.grid.voxel_size_m);
  EXPECT_EQ(std::string(octomap.data.begin(), octomap.data.end()), s.octree);

  const auto markers = Decoded<ros::msg::MarkerArray>(On(f, rec::kCandidatesTopic)[v]);
  const nlohmann::json step =
      nlohmann::json::parse(Decoded<ros::msg::String>(On(f, rec::kStepTopic)[v]).data);
  EXPECT_EQ(step["view"], static_cast<int>(v));
  const RigidTransform X = rec::PoseFromJson(step["X_WC"]).value();
  EXPECT_EQ(X.rotation(), s.step.X_WC.rotation());  // exact
  EXPECT_EQ(X.translation(), s.step.X_WC.translation());
  EXPECT_EQ(step["known_voxels"], s.step.known_voxels);
  EXPECT_EQ(step["chosen_rank"], s.step.chosen_rank);
  ASSERT_EQ(step["metrics"].size(), s.step.metrics.size());
  for (size_t k = 0; k < s.step.metrics.size(); ++k) {
    EXPECT_EQ(step["metrics"][k][0], s.step.metrics[k].first);
    EXPECT_EQ(step["metrics"][k][1].get<double>(), s.step.metrics[k].second);
  }
  ASSERT_EQ(step["candidates"].size(), s.ranked.size());
  if (v + 1 < views) {
    ASSERT_GT(s.ranked.size(), 0u);
    EXPECT_EQ(step["candidates"][0]["utility"].get<double>(), s.ranked[0].utility);
    const RigidTransform best = rec::PoseFromJson(step["candidates"][0]["X_WC"]).value();
    EXPECT_EQ(best.translation(), s.ranked[0].X_WC.translation());
    // DELETEALL, one arrow per ranked candidate, the chosen one's text.
    EXPECT_EQ(markers.markers.size(), s.ranked.size() + 2);
    EXPECT_GE(s.step.chosen_rank, 0);
  } else {
    EXPECT_EQ(markers.markers.size(), 1u);  // after the last view: no plan
  }
}

TEST_F(RecordingTest, EveryTopicEqualsWhatTheEpisodeSaw) {
  const experiment::RunConfig c = Config();
  const sim::Scene scene = sim::MakeScenario(c.scenario, c.seed).value();
  const eval::GroundTruth gt = experiment::GroundTruthFor(c, scene).value();
  const fs::path path = dir_ / "episode.mcap";
  auto recorder = experiment::OpenEpisodeRecording(
                      path, c, Registries(), {.command = "avp run", .scene = scene.name, .gt = &gt})
                      .value();
  Keeper keeper;
  const experiment::RunResult result =
      experiment::RunEpisodeOnScene(experiment::CheckedRunConfig::Check(c, Registries()).value(),
                                    scene, gt, {&keeper, recorder.get()})
          .value();
  ASSERT_TRUE(recorder->Close().ok()) << recorder->status().ToString();
  const size_t views = static_cast<size_t>(result.episode.views_fused());
  ASSERT_EQ(views, 3u);
  ASSERT_EQ(keeper.seen.size(), views);
  EXPECT_EQ(recorder->views(), 3);

  const ros::mcap::File f = ros::mcap::ReadIndexed(path).value();
  EXPECT_EQ(f.profile, "ros2");
  ExpectEveryTopicOncePerView(f, views);
  ExpectMetadataAndGroundTruth(f, scene, gt);
  for (size_t v = 0; v < views; ++v) {
    SCOPED_TRACE("view " + std::to_string(v));
    const Seen& s = keeper.seen[v];
    ASSERT_TRUE(s.obs.has_value());
    ASSERT_TRUE(s.seg.has_value());
    ExpectCameraTopics(f, v, s);
    ExpectSegmentationTopics(f, v, s);
    ExpectMapAndStepTopics(f, v, views, s, c);
  }
  // The streaming reader finds the same.
  const ros::mcap::StreamResult streamed = ros::mcap::ReadStreaming(path);
  ASSERT_TRUE(streamed.status.ok()) << streamed.status.ToString();
  EXPECT_EQ(streamed.file.messages.size(), f.messages.size());
  EXPECT_EQ(streamed.file.attachments, f.attachments);
  EXPECT_EQ(streamed.file.metadata, f.metadata);
}

TEST_F(RecordingTest, AKilledRunKeepsItsFinishedViews) {
  const experiment::RunConfig c = Config();
  const sim::Scene scene = sim::MakeScenario(c.scenario, c.seed).value();
  const eval::GroundTruth gt = experiment::GroundTruthFor(c, scene).value();
  const fs::path path = dir_ / "live.mcap";
  auto recorder =
      experiment::OpenEpisodeRecording(path, c, Registries(), {.scene = scene.name}).value();
  ASSERT_TRUE(
      experiment::RunEpisodeOnScene(experiment::CheckedRunConfig::Check(c, Registries()).value(),
                                    scene, gt, {recorder.get()})
          .ok());
  // The process dies here (the recorder is never closed): the file as it is on disk.
  const fs::path cut = dir_ / "cut.mcap";
  fs::copy_file(path, cut);
  const ros::mcap::StreamResult s = ros::mcap::ReadStreaming(cut);
  EXPECT_THAT(s.status.message(), HasSubstr("without a Data End record"));
  EXPECT_EQ(s.file.messages.size(), 3u * 12u);  // every view, every topic
  EXPECT_EQ(s.file.metadata.size(), 1u);
  EXPECT_TRUE(s.file.attachments.empty());  // no ground truth given
  EXPECT_THAT(ros::mcap::ReadIndexed(cut).status().message(), HasSubstr("no closing magic"));
  ASSERT_TRUE(recorder->Close().ok());
}

TEST_F(RecordingTest, RunFolderRecordsAndAWriteErrorStopsTheRunNamingTheFile) {
  experiment::RunConfig c = Config();
  c.episode.views = 2;
  experiment::RunFolderOptions options;
  options.out_dir = dir_ / "run";
  options.record = true;
  const auto summary = experiment::RunToFolder(
      experiment::CheckedRunConfig::Check(c, Registries()).value(), options);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  const fs::path mcap_path = options.out_dir / "episode.mcap";
  EXPECT_NE(std::find(summary->files.begin(), summary->files.end(), mcap_path),
            summary->files.end());
  const ros::mcap::File f = ros::mcap::ReadIndexed(mcap_path).value();
  EXPECT_EQ(On(f, rec::kStepTopic).size(), 2u);
  ASSERT_EQ(f.attachments.size(), 1u);  // the run's ground truth
  EXPECT_EQ(
      eval::GroundTruthFromJson(nlohmann::json::parse(f.attachments[0].data)).value().voxels.size(),
      summary->result.final_metrics.exact.ground_truth);

  // A file that cannot be created or written is an error naming it.
  EXPECT_THAT(rec::McapRecorder::Open(dir_ / "no" / "such" / "e.mcap").status().message(),
              HasSubstr("e.mcap: cannot create"));
  if (fs::exists("/dev/full")) {
    EXPECT_THAT(rec::McapRecorder::Open("/dev/full").status().message(),
                HasSubstr("/dev/full: write failed at offset"));
  }

  // A disk that fills up during the episode (files limited to 6 MB: a view records ~3.7 MB):
  // the recorder's error stops the episode after the view it failed on, and is the run's error.
  options.out_dir = dir_ / "full";
  c.episode.views = 5;
  struct rlimit old {};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  std::signal(SIGXFSZ, SIG_IGN);  // a write past the limit then fails with EFBIG
  struct rlimit small = old;
  small.rlim_cur = 6'000'000;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  const auto failed = experiment::RunToFolder(
      experiment::CheckedRunConfig::Check(c, Registries()).value(), options);
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &old), 0);
  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.status().code(), StatusCode::kIoError);
  EXPECT_THAT(failed.status().message(), HasSubstr((options.out_dir / "episode.mcap").string()));
  EXPECT_THAT(failed.status().message(), HasSubstr("failed"));
  // The episode stopped: metrics.csv has a header and at most 2 of the 5 views.
  std::ifstream csv(options.out_dir / "metrics.csv");
  size_t lines = 0;
  for (std::string line; std::getline(csv, line);) ++lines;
  EXPECT_GE(lines, 2u);
  EXPECT_LE(lines, 3u);
  // What was flushed before the failure is readable.
  const ros::mcap::StreamResult cut = ros::mcap::ReadStreaming(options.out_dir / "episode.mcap");
  EXPECT_FALSE(cut.status.ok());
  EXPECT_EQ(cut.file.metadata.size(), 1u);
}

TEST_F(RecordingTest, BenchRecordsEveryEpisodeInItsRunFolder) {
  experiment::BenchConfig bench;
  bench.scenarios = {"tomato-single-cluster"};
  bench.planners = {"predefined", "random"};
  bench.seeds = {5};
  bench.base.episode.views = 2;
  bench.jobs = 2;
  bench.progress = false;
  bench.record = true;
  bench.out_dir = dir_ / "bench";
  const auto summary = experiment::RunBench(bench, Registries());
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  for (const std::string planner : {"predefined", "random"}) {
    SCOPED_TRACE(planner);
    const fs::path path =
        bench.out_dir / "runs" / "tomato-single-cluster" / planner / "seed-5" / "episode.mcap";
    const ros::mcap::File f = ros::mcap::ReadIndexed(path).value();
    EXPECT_EQ(On(f, rec::kStepTopic).size(), 2u);
    EXPECT_EQ(On(f, rec::kColorTopic).size(), 2u);
    ASSERT_EQ(f.metadata.size(), 1u);
    EXPECT_EQ(f.metadata[0].metadata.at("command"), "avp bench");
    EXPECT_EQ(f.metadata[0].metadata.at("planner"), planner);
    EXPECT_EQ(f.metadata[0].metadata.at("seed"), "5");
    ASSERT_EQ(f.attachments.size(), 1u);
    EXPECT_EQ(f.attachments[0].name, "ground_truth.json");
  }
}

}  // namespace
}  // namespace avp

// avp replay: a recorded `avp run` replayed equals the original (every metric of every view, the
// per-fruit results, the map voxel for voxel: map.ot byte for byte, map.avpmap byte for byte but
// its note); the oracle segmenter rerun on the recorded labels gives the same masks; the recording
// read as a robot's bag (images, CameraInfo, TF only); truncated and corrupt recordings replay
// their intact views and name the offset; the avp replay command end to end.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <avp/core/transform.h>
#include <avp/experiment/replay.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/json.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/map_file.h>
#include <avp/report/run_html.h>
#include <avp/ros/bag/bag_reader.h>
#include <avp/ros/bag/layout.h>
#include <avp/ros/mcap/mcap.h>
#include <avp/ros/msg/lens.h>
#include <avp/ros/msg/messages.h>
#include <avp/test/read_file.h>
#include <avp/test/run_command.h>

#include "robot_bag_writer.h"

namespace avp {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using ::testing::HasSubstr;

const experiment::Registries& Registries() {
  static const auto* registries = new experiment::Registries(experiment::BuiltinRegistries());
  return *registries;
}

/// metrics.csv without the time columns (capture_ms ... step_ms): what a replay must reproduce.
std::vector<std::string> CsvWithoutTimes(const fs::path& p) {
  std::istringstream in(test::ReadWholeFile(p));
  std::vector<std::string> rows;
  std::vector<size_t> drop;
  for (std::string line; std::getline(in, line);) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    if (rows.empty()) {
      for (size_t i = 0; i < cells.size(); ++i) {
        if (cells[i].ends_with("_ms")) drop.push_back(i);
      }
      EXPECT_EQ(drop.size(), 7u) << line;
    }
    std::string kept;
    for (size_t i = 0; i < cells.size(); ++i) {
      if (std::find(drop.begin(), drop.end(), i) == drop.end()) kept += cells[i] + ",";
    }
    rows.push_back(kept);
  }
  return rows;
}

/// The map file's bytes once saved with a fixed note (the note names the command).
std::string MapBytes(const fs::path& avpmap, const fs::path& scratch) {
  Result<mapping::SemanticMap> map = mapping::LoadMap(avpmap);
  EXPECT_TRUE(map.ok()) << map.status().ToString();
  if (!map.ok()) return {};
  EXPECT_TRUE(mapping::SaveMap(*map, scratch, {.note = "same"}).ok());
  return test::ReadWholeFile(scratch);
}

class ReplayTest : public ::testing::Test {
 protected:
  /// One recorded episode for the suite: tomato-multiple-clusters, avp-nbv, oracle, 3 views.
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::path(::testing::TempDir()) /
                        ("avp_replay_test_" + std::to_string(::getpid())));
    fs::remove_all(*dir_);
    Result<experiment::RunSummary> run = RecordRun(SuiteRunConfig(), *dir_ / "run");
    ASSERT_TRUE(run.ok()) << run.status().ToString();
    ASSERT_EQ(run->result.episode.views_fused(), 3);
  }
  /// The suite's episode: tomato-multiple-clusters, seed 5, 3 views.
  static experiment::RunConfig SuiteRunConfig() {
    experiment::RunConfig c;
    c.scenario = "tomato-multiple-clusters";
    c.seed = 5;
    c.episode.views = 3;
    c.threads = 2;
    return c;
  }
  /// Runs `c` into `out_dir`, recorded as MCAP.
  static Result<experiment::RunSummary> RecordRun(const experiment::RunConfig& c,
                                                  const fs::path& out_dir) {
    experiment::RunFolderOptions o;
    o.out_dir = out_dir;
    o.record = true;
    return experiment::RunToFolder(experiment::CheckedRunConfig::Check(c, Registries()).value(), o);
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    fs::remove_all(*dir_, ec);
    delete dir_;
  }
  static fs::path Run() { return *dir_ / "run"; }

  /// The suite's episode with fusion during motion (3 frames a second, to keep the file small),
  /// recorded once into dir_/moving-run. Returns its moving totals.
  static const pipeline::MotionTotals& MovingRun() {
    static const pipeline::MotionTotals totals = [] {
      experiment::RunConfig c = SuiteRunConfig();
      c.episode.motion_fusion.enabled = true;
      c.episode.motion_fusion.rate_hz = 3.0;
      Result<experiment::RunSummary> run = RecordRun(c, *dir_ / "moving-run");
      EXPECT_TRUE(run.ok()) << run.status().ToString();
      return run.ok() ? pipeline::SumMotion(run->result.episode) : pipeline::MotionTotals{};
    }();
    return totals;
  }

  /// `file` written to `path` with the message of `channel` logged at `log_time` replaced by a
  /// std_msgs/String of `text`.
  static void RewriteMessage(const ros::mcap::File& file, uint16_t channel, uint64_t log_time,
                             const std::string& text, const fs::path& path) {
    auto w = ros::mcap::Writer::Open(path).value();
    for (const ros::mcap::Schema& s : file.schemas) {
      ASSERT_TRUE(w->AddSchema(s.name, s.encoding, s.data).ok());
    }
    for (const ros::mcap::Channel& ch : file.channels) {
      ASSERT_TRUE(w->AddChannel(ch.schema_id, ch.topic, ch.message_encoding, ch.metadata).ok());
    }
    for (const ros::mcap::Attachment& a : file.attachments) ASSERT_TRUE(w->WriteAttachment(a).ok());
    for (const ros::mcap::Metadata& m : file.metadata) ASSERT_TRUE(w->WriteMetadata(m).ok());
    for (ros::mcap::Message m : file.messages) {
      if (m.channel_id == channel && m.log_time == log_time) {
        m.data = ros::msg::Encode(ros::msg::String{text});
      }
      ASSERT_TRUE(w->Write(m).ok());
    }
    ASSERT_TRUE(w->Close().ok());
  }
  static fs::path Bag() { return Run() / "episode.mcap"; }

  /// Replays `bag` (read with `bag_options`) into dir_/name.
  /// `fps`: replay.fps when >= 0.
  static Result<experiment::ReplaySummary> Replay(const fs::path& bag, const std::string& name,
                                                  const std::string& segmenter = {},
                                                  ros::bag::BagReadOptions bag_options = {},
                                                  double fps = -1.0) {
    AVP_ASSIGN_OR_RETURN(std::unique_ptr<ros::bag::BagReader> b,
                         ros::bag::BagReader::Open(bag, bag_options));
    AVP_ASSIGN_OR_RETURN(experiment::RunConfig config, experiment::BagRunConfig(*b));
    if (fps >= 0.0) config.replay.fps = fps;
    experiment::ReplayOptions o;
    o.segmenter = segmenter;
    o.folder.out_dir = *dir_ / name;
    return experiment::ReplayToFolder(*b, config, Registries(), o);
  }

  /// The replay folder `name` equals the recorded run: metrics, fruits, map.
  static void ExpectSameAsRun(const std::string& name) {
    const fs::path out = *dir_ / name;
    const json a = io::ReadJsonFile(Run() / "record.json").value();
    const json b = io::ReadJsonFile(out / "record.json").value();
    EXPECT_EQ(b["avp"], "avp replay");
    EXPECT_EQ(a["final_metrics"], b["final_metrics"]);
    EXPECT_EQ(a["fruits"], b["fruits"]);
    EXPECT_EQ(a["config"], b["config"]);
    ASSERT_EQ(a["steps"].size(), b["steps"].size());
    for (size_t i = 0; i < a["steps"].size(); ++i) {
      for (const char* key : {"metrics", "known_voxels", "occupied_voxels", "target_voxels",
                              "instances", "masks", "integration", "chosen_rank", "candidates"}) {
        if (a["steps"][i].contains(key)) {
          EXPECT_EQ(a["steps"][i][key], b["steps"][i][key]) << "step " << i << " " << key;
        }
      }
    }
    EXPECT_EQ(CsvWithoutTimes(Run() / "metrics.csv"), CsvWithoutTimes(out / "metrics.csv"));
    EXPECT_EQ(test::ReadWholeFile(Run() / "map.ot"), test::ReadWholeFile(out / "map.ot"));
    const std::string original = MapBytes(Run() / "map.avpmap", *dir_ / (name + "_a.avpmap"));
    EXPECT_GT(original.size(), 100000u);
    EXPECT_TRUE(original == MapBytes(out / "map.avpmap", *dir_ / (name + "_b.avpmap")));
  }

  static fs::path* dir_;
};
fs::path* ReplayTest::dir_ = nullptr;

TEST_F(ReplayTest, RecordedMasksRebuildTheSameMapAndMetrics) {
  Result<experiment::ReplaySummary> r = Replay(Bag(), "replay");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->segmenter, "recorded");
  EXPECT_EQ(r->views, 3u);
  EXPECT_EQ(r->metrics_compared, 3u);
  EXPECT_EQ(r->metrics_differ, 0u) << r->first_difference;
  EXPECT_TRUE(r->notes.empty());
  EXPECT_EQ(r->run.result.episode.end, pipeline::EpisodeEnd::kBudgetReached);
  EXPECT_GT(r->run.result.final_metrics.exact.f1, 0.2);
  ExpectSameAsRun("replay");
  const json record = io::ReadJsonFile(*dir_ / "replay" / "record.json").value();
  EXPECT_EQ(record["replay"]["segmenter"], "recorded");
  EXPECT_EQ(record["replay"]["damage"], nullptr);
  EXPECT_EQ(record["replay"]["recorded_with"]["planner"], "avp-nbv");
}

TEST_F(ReplayTest, FramesFusedWhileMovingAreRecordedAndReplayedBetweenTheViews) {
  // The same episode with fusion during motion: every moving frame is in the recording, and the
  // replay fuses it between the views as the episode did, so the metrics and the map come out
  // the same.
  const pipeline::MotionTotals& totals = MovingRun();
  ASSERT_GE(totals.moving.fused, 4);
  const fs::path run_dir = *dir_ / "moving-run";
  Result<experiment::ReplaySummary> r = Replay(run_dir / "episode.mcap", "moving-replay");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->views, 3u);
  EXPECT_EQ(r->moving.fused, totals.moving.fused);
  EXPECT_EQ(r->moving.segmented, totals.moving.segmented);
  EXPECT_EQ(r->moving.known_delta, totals.moving.known_delta);
  EXPECT_EQ(r->metrics_compared, 3u);
  EXPECT_EQ(r->metrics_differ, 0u) << r->first_difference;
  const json a = io::ReadJsonFile(run_dir / "record.json").value();
  const json b = io::ReadJsonFile(*dir_ / "moving-replay" / "record.json").value();
  EXPECT_EQ(a["final_metrics"], b["final_metrics"]);
  for (size_t i = 0; i < a["steps"].size(); ++i) {
    EXPECT_EQ(a["steps"][i]["known_voxels"], b["steps"][i]["known_voxels"]) << i;
  }
  EXPECT_EQ(b["replay"]["moving_frames"]["fused"], totals.moving.fused);
  EXPECT_TRUE(test::ReadWholeFile(run_dir / "map.ot") ==
              test::ReadWholeFile(*dir_ / "moving-replay" / "map.ot"));
}

TEST_F(ReplayTest, BadMovingFrameIsSkippedNamingTheValue) {
  // A /avp/moving_frame message that is not JSON, or lacks whole numbers view >= 1 and k >= 1:
  // that frame is skipped with its reason, the views and the other frames are read.
  const pipeline::MotionTotals& totals = MovingRun();
  ASSERT_GE(totals.moving.fused, 4);
  const fs::path recording = *dir_ / "moving-run" / "episode.mcap";
  const ros::mcap::File file = ros::mcap::ReadIndexed(recording).value();
  uint16_t channel = 0;
  for (const ros::mcap::Channel& c : file.channels) {
    if (c.topic == ros::bag::kMovingFrameTopic) channel = c.id;
  }
  ASSERT_NE(channel, 0);
  uint64_t first = 0;
  for (const ros::mcap::Message& m : file.messages) {
    if (m.channel_id == channel) {
      first = m.log_time;
      break;
    }
  }
  ASSERT_GT(first, 0u);
  const std::string needs = "/avp/moving_frame: needs whole numbers view >= 1 and k >= 1";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"{not json", "/avp/moving_frame: malformed JSON"},
      {R"({"view": 0, "k": 1})", needs},
      {R"({"view": 1})", needs},
      {R"({"view": 1, "k": 1.5})", needs},
      {R"({"view": 1, "k": -3})", needs},
      {"[1, 2]", needs},
  };
  for (const auto& [text, expected] : cases) {
    const fs::path path = *dir_ / "bad_moving_frame.mcap";
    RewriteMessage(file, channel, first, text, path);
    Result<ros::bag::Bag> bag = ros::bag::ReadBag(path);
    ASSERT_TRUE(bag.ok()) << bag.status().ToString();
    const auto moving = static_cast<size_t>(std::count_if(
        bag->views.begin(), bag->views.end(), [](const ros::bag::BagView& v) { return v.moving; }));
    EXPECT_EQ(bag->views.size() - moving, 3u) << text;
    EXPECT_EQ(moving, static_cast<size_t>(totals.moving.fused) - 1) << text;
    EXPECT_EQ(bag->account.moving_frames, moving) << text;
    ASSERT_EQ(bag->account.skipped_count(), 1u) << text;
    EXPECT_THAT(bag->account.skipped[0], HasSubstr(expected)) << text;
  }
}

TEST_F(ReplayTest, TheOracleRerunOnTheRecordedLabelsGivesTheSameMasks) {
  Result<experiment::ReplaySummary> r = Replay(Bag(), "oracle", "oracle");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->segmenter, "oracle");
  EXPECT_EQ(r->metrics_differ, 0u) << r->first_difference;
  ExpectSameAsRun("oracle");
}

TEST_F(ReplayTest, ReadAsARobotBagThePosesComeFromTf) {
  ros::bag::BagReadOptions o;
  o.as_robot_bag = true;
  Result<experiment::ReplaySummary> r = Replay(Bag(), "robot", "oracle", o, /*fps=*/0.0);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->views, 3u);
  EXPECT_EQ(r->metrics_compared, 0u);  // a robot's bag has no recorded metrics
  // TF's quaternion rounds the pose in its last bits: the map is the same within a few voxels.
  const json a = io::ReadJsonFile(Run() / "record.json").value();
  const json b = io::ReadJsonFile(*dir_ / "robot" / "record.json").value();
  EXPECT_NEAR(a["final_metrics"]["f1"].get<double>(), b["final_metrics"]["f1"].get<double>(), 0.01);
  EXPECT_EQ(a["final_metrics"]["fruits_found"], b["final_metrics"]["fruits_found"]);
  EXPECT_NEAR(a["steps"][2]["occupied_voxels"].get<double>(),
              b["steps"][2]["occupied_voxels"].get<double>(),
              0.01 * a["steps"][2]["occupied_voxels"].get<double>());
}

TEST_F(ReplayTest, TheOracleNeedsLabels) {
  ros::bag::BagReadOptions o;
  o.labels_prefix = "";  // as a real robot's bag: no label images
  Result<experiment::ReplaySummary> r = Replay(Bag(), "nolabels", "oracle", o);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(),
              HasSubstr("the 'oracle' segmenter needs the simulator's label images "
                        "(/avp/sim/instance, /avp/sim/class), and the bag has none"));
  ros::bag::BagReadOptions robot;
  robot.as_robot_bag = true;
  r = Replay(Bag(), "recorded-robot", "recorded", robot);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("the bag has no recorded masks"));
  EXPECT_FALSE(fs::exists(*dir_ / "recorded-robot"));  // refused before anything is written
}

TEST_F(ReplayTest, TruncatedRecordingReplaysItsIntactViewsAndNamesTheOffset) {
  const fs::path cut = *dir_ / "cut.mcap";
  fs::copy_file(Bag(), cut, fs::copy_options::overwrite_existing);
  const auto size = fs::file_size(cut);
  fs::resize_file(cut, size * 75 / 100);
  Result<ros::bag::Bag> bag = ros::bag::ReadBag(cut);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  EXPECT_FALSE(bag->damage.ok());
  EXPECT_THAT(bag->damage.message(), HasSubstr("offset"));
  ASSERT_GE(bag->views.size(), 1u);
  ASSERT_LT(bag->views.size(), 3u);
  Result<experiment::ReplaySummary> r = Replay(cut, "cut");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->run.result.episode.end, pipeline::EpisodeEnd::kInterrupted);
  EXPECT_THAT(r->run.result.episode.end_reason, HasSubstr("the recording is damaged"));
  EXPECT_THAT(r->run.result.episode.end_reason, HasSubstr("offset"));
  EXPECT_EQ(r->metrics_differ, 0u) << r->first_difference;
  // The intact views' rows equal the original's first rows.
  const auto original = CsvWithoutTimes(Run() / "metrics.csv");
  const auto replayed = CsvWithoutTimes(*dir_ / "cut" / "metrics.csv");
  ASSERT_EQ(replayed.size(), bag->views.size() + 1);
  for (size_t i = 0; i < replayed.size(); ++i) EXPECT_EQ(replayed[i], original[i]) << i;
}

TEST_F(ReplayTest, CorruptChunkReplaysTheViewsBeforeIt) {
  const fs::path bad = *dir_ / "corrupt.mcap";
  fs::copy_file(Bag(), bad, fs::copy_options::overwrite_existing);
  std::string bytes = test::ReadWholeFile(bad);
  // A byte in the middle of the file (inside a later view's chunk: the recorder writes a chunk
  // per view).
  bytes[bytes.size() * 70 / 100] ^= 0x5a;
  std::ofstream(bad, std::ios::binary) << bytes;
  Result<ros::bag::Bag> bag = ros::bag::ReadBag(bad);
  ASSERT_TRUE(bag.ok()) << bag.status().ToString();
  EXPECT_THAT(bag->damage.message(), HasSubstr("CRC mismatch"));
  EXPECT_THAT(bag->damage.message(), HasSubstr("offset"));
  EXPECT_LT(bag->views.size(), 3u);
}

TEST_F(ReplayTest, BadStepOrMasksSkipTheViewNamingTheValue) {
  const ros::mcap::File file = ros::mcap::ReadIndexed(Bag()).value();
  uint16_t step_channel = 0, instances_channel = 0;
  for (const ros::mcap::Channel& c : file.channels) {
    if (c.topic == ros::bag::kStepTopic) step_channel = c.id;
    if (c.topic == ros::bag::kInstancesTopic) instances_channel = c.id;
  }
  const uint64_t view1 = 1'000'000'000;  // simulation stamps: view x 1 s
  struct Case {
    uint16_t channel;
    std::string text;
    std::string expected;
  };
  const json step1 = [&] {
    for (const ros::mcap::Message& m : file.messages) {
      if (m.channel_id == step_channel && m.log_time == view1) {
        return json::parse(ros::msg::Decode<ros::msg::String>(m.data).value().data);
      }
    }
    return json();
  }();
  ASSERT_TRUE(step1.is_object());
  json bad_pose = step1;
  bad_pose["X_WC"][0] = 3.0;
  json short_pose = step1;
  short_pose["X_WC"].erase(0);
  const std::vector<Case> cases = {
      {step_channel, "{not json", "/avp/step: malformed JSON"},
      {step_channel, bad_pose.dump(), "/avp/step: X_WC"},
      {step_channel, short_pose.dump(), "/avp/step: X_WC"},
      {instances_channel, R"({"width": 640, "height": 480, "instances": [{"class": "fruit"}]})",
       "/avp/segmentation/instances"},
      {instances_channel, R"({"width": 1, "height": 1, "instances": []})",
       "/avp/segmentation/instances"},
  };
  for (const Case& c : cases) {
    const fs::path path = *dir_ / "bad_step.mcap";
    RewriteMessage(file, c.channel, view1, c.text, path);
    Result<ros::bag::Bag> bag = ros::bag::ReadBag(path);
    ASSERT_TRUE(bag.ok()) << bag.status().ToString();
    ASSERT_EQ(bag->views.size(), 2u) << c.text;
    EXPECT_EQ(bag->views[1].index, 2);
    ASSERT_EQ(bag->account.skipped_count(), 1u);
    EXPECT_THAT(bag->account.skipped[0], HasSubstr("stamp 1.000000000: " + c.expected)) << c.text;
  }
}

TEST_F(ReplayTest, NotAnMcapFileIsAClearError) {
  const fs::path junk = *dir_ / "junk.mcap";
  std::ofstream(junk) << "not an mcap file at all";
  Result<ros::bag::Bag> bag = ros::bag::ReadBag(junk);
  ASSERT_FALSE(bag.ok());
  EXPECT_THAT(bag.status().message(), HasSubstr("junk.mcap"));
  EXPECT_FALSE(ros::bag::ReadBag(*dir_ / "missing.mcap").ok());
}

/// A robot's bag as the RealSense driver and a robot write it: 3 s at 30 Hz of 64 x 48 bgr8
/// colour (a red disc on green) and 16UC1 depth (a wall 0.6 m in front of the camera), CameraInfo,
/// /tf_static base -> mount and link -> optical frame, /tf mount -> link at 100 Hz (the arm
/// turning slowly). Returns the path.
fs::path WriteRobotBag(const fs::path& path) {
  auto w = ros::mcap::Writer::Open(path).value();
  auto channel = [&](std::string_view type, std::string_view def, const std::string& topic) {
    const uint16_t schema = w->AddSchema(type, "ros2msg", def).value();
    return w
        ->AddChannel(schema, topic, "cdr",
                     {{"offered_qos_profiles", ros::mcap::OfferedQosProfiles()}})
        .value();
  };
  using ros::msg::Image, ros::msg::CameraInfo, ros::msg::TFMessage;
  const uint16_t color = channel(ros::msg::MessageTraits<Image>::kRosName,
                                 ros::msg::Definition<Image>(), "/camera/camera/color/image_raw");
  const uint16_t depth =
      channel(ros::msg::MessageTraits<Image>::kRosName, ros::msg::Definition<Image>(),
              "/camera/camera/aligned_depth_to_color/image_raw");
  const uint16_t info =
      channel(ros::msg::MessageTraits<CameraInfo>::kRosName, ros::msg::Definition<CameraInfo>(),
              "/camera/camera/color/camera_info");
  const uint16_t tf = channel(ros::msg::MessageTraits<TFMessage>::kRosName,
                              ros::msg::Definition<TFMessage>(), "/tf");
  const uint16_t tf_static = channel(ros::msg::MessageTraits<TFMessage>::kRosName,
                                     ros::msg::Definition<TFMessage>(), "/tf_static");
  const int64_t t0 = 1'700'000'000'000'000'000;
  uint32_t seq = 0;
  auto put = [&](uint16_t ch, int64_t t, const std::vector<uint8_t>& bytes) {
    ASSERT_TRUE(
        w->Write(ch, seq++, static_cast<uint64_t>(t), static_cast<uint64_t>(t), bytes).ok());
  };
  const auto edge = &ros::bag::testing::RobotBagWriter::Edge;
  // The optical frame looks along +x of the link (z forward, x right, y down).
  const RigidTransform link_to_optical =
      RigidTransform::LookAt({0, 0, 0}, {1, 0, 0}, Eigen::Vector3d::UnitZ());
  put(tf_static, t0,
      ros::msg::Encode(TFMessage{
          {edge("igus_rebel_base_link", "mount", RigidTransform(Eigen::Vector3d(0, 0, 0.4)), t0),
           edge("link", "camera_color_optical_frame", link_to_optical, t0)}}));
  for (int64_t t = t0 - 20'000'000; t <= t0 + 3'100'000'000; t += 10'000'000) {
    const double s = static_cast<double>(t - t0) * 1e-9;
    put(tf, t,
        ros::msg::Encode(TFMessage{
            {edge("mount", "link", RigidTransform::FromRpy(0, 0, 0.05 * s, {0, 0, 0}), t)}}));
  }
  constexpr int kW = 64, kH = 48;
  for (int64_t i = 0; i < 90; ++i) {
    const int64_t t = t0 + i * int64_t{33'333'333};
    Image c;
    c.header = {ros::msg::Time::FromNanoseconds(t), "camera_color_optical_frame"};
    c.width = kW;
    c.height = kH;
    c.encoding = "bgr8";
    c.step = 3 * kW;
    Image d = c;
    d.encoding = "16UC1";
    d.step = 2 * kW;
    for (int v = 0; v < kH; ++v) {
      for (int u = 0; u < kW; ++u) {
        const bool disc = (u - 32) * (u - 32) + (v - 24) * (v - 24) < 100;
        c.data.insert(c.data.end(),
                      {static_cast<uint8_t>(disc ? 30 : 40), static_cast<uint8_t>(disc ? 20 : 160),
                       static_cast<uint8_t>(disc ? 210 : 40)});
        d.data.insert(d.data.end(),
                      {static_cast<uint8_t>(600 & 0xff), static_cast<uint8_t>(600 >> 8)});
      }
    }
    CameraInfo k;
    k.header = c.header;
    k.width = kW;
    k.height = kH;
    k.k = {50.0, 0, 31.5, 0, 50.0, 23.5, 0, 0, 1};
    put(color, t, ros::msg::Encode(c));
    put(depth, t, ros::msg::Encode(d));
    put(info, t, ros::msg::Encode(k));
  }
  EXPECT_TRUE(w->Close().ok());
  return path;
}

/// The occupied voxels of the map that `views` (a bag's, read with `options`) build.
std::unordered_set<VoxelKey, VoxelKeyHash> OccupiedOf(const fs::path& bag,
                                                      const ros::bag::BagReadOptions& options) {
  ros::bag::FrameSelection every;
  every.fps = 0.0;
  const ros::bag::Bag b = ros::bag::ReadBag(bag, options, every).value();
  mapping::SemanticMap map;
  const mapping::Integrator integrator;
  for (const ros::bag::BagView& v : b.views) {
    EXPECT_TRUE(integrator.Integrate(v.observation.frame, nullptr, map).ok());
  }
  std::unordered_set<VoxelKey, VoxelKeyHash> out;
  map.grid().ForEachKnownVoxel([&](const VoxelKey& k, float) {
    if (map.State(k) == mapping::VoxelState::kOccupied) out.insert(k);
  });
  return out;
}

/// The fraction of `a`'s voxels with one of `b`'s within a voxel (26-neighbourhood).
double NearFraction(const std::unordered_set<VoxelKey, VoxelKeyHash>& a,
                    const std::unordered_set<VoxelKey, VoxelKeyHash>& b) {
  size_t near = 0;
  for (const VoxelKey& k : a) {
    bool found = false;
    for (int dx = -1; dx <= 1 && !found; ++dx)
      for (int dy = -1; dy <= 1 && !found; ++dy)
        for (int dz = -1; dz <= 1 && !found; ++dz)
          found = b.contains({k.x + dx, k.y + dy, k.z + dz});
    near += found ? 1 : 0;
  }
  return a.empty() ? 0.0 : static_cast<double>(near) / static_cast<double>(a.size());
}

TEST_F(ReplayTest, ADistortedCameraReplaysToTheUndistortedMapWithinAVoxel) {
  // The recorded episode's rendered 640 x 480 views, seen through a plumb_bob lens (OpenCV's
  // model, 25-30 px at the corners) and written as a RealSense bag with that CameraInfo.
  const ros::bag::Bag recording = ros::bag::ReadBag(Bag()).value();
  ASSERT_EQ(recording.views.size(), 3u);
  ros::msg::CameraInfo info =
      ros::msg::ToCameraInfo(recording.views[0].observation.frame.K, ros::msg::Header{});
  const ros::msg::CameraInfo pinhole = info;
  info.d = {-0.2, 0.05, 0.001, -0.001, 0.0};
  const ros::msg::LensModel lens = ros::msg::LensModelFromCameraInfo(info, 0.1, 10.0).value();
  auto write = [&](const fs::path& path, bool distort) {
    auto w = ros::bag::testing::RobotBagWriter::Open(path).value();
    const int64_t t0 = 1'700'000'000'000'000'000;
    for (size_t i = 0; i < recording.views.size(); ++i) {
      RgbdFrame f = recording.views[i].observation.frame;
      if (distort) f = ros::msg::Distort(f, lens).value();
      const int64_t t = t0 + static_cast<int64_t>(i) * 1'000'000'000;
      for (const int64_t dt : {-10'000'000, 10'000'000}) {
        ASSERT_TRUE(w->Tf({w->Edge("igus_rebel_base_link", "camera_color_optical_frame",
                                   recording.views[i].observation.frame.X_WC, t + dt)},
                          t + dt, false)
                        .ok());
      }
      ASSERT_TRUE(
          w->Frame(t, f.rgb, f.depth_m, distort ? info : pinhole, "camera_color_optical_frame")
              .ok());
    }
    ASSERT_TRUE(w->Close().ok());
  };
  const fs::path plain = *dir_ / "pinhole.mcap", raw = *dir_ / "distorted.mcap";
  write(plain, false);
  write(raw, true);
  const auto reference = OccupiedOf(plain, {});
  const auto rectified = OccupiedOf(raw, {});
  ros::bag::BagReadOptions ignore;
  ignore.distortion = "ignore";
  const auto ignored = OccupiedOf(raw, ignore);
  ASSERT_GT(reference.size(), 1000u);
  const double rect_a = NearFraction(rectified, reference),
               rect_b = NearFraction(reference, rectified);
  const double ign_a = NearFraction(ignored, reference);
  std::printf(
      "[ distortion ] occupied voxels: pinhole %zu, rectified %zu (%.3f / %.3f within a "
      "voxel), ignored %zu (%.3f within a voxel)\n",
      reference.size(), rectified.size(), rect_a, rect_b, ignored.size(), ign_a);
  // Rectified: every voxel within a voxel of the pinhole map's, both ways (measured: all of
  // them). Fused as if rectified: measurably off (measured: 4.4 % of the voxels more than a
  // voxel away, up to 5 voxels at the image's border, where the lens moves pixels 25-30 px).
  EXPECT_GT(rect_a, 0.997);
  EXPECT_GT(rect_b, 0.99);
  EXPECT_GT(1.0 - ign_a, 0.02);

  // An unknown lens model is refused by name; every frame is then skipped.
  info.distortion_model = "kannala_brandt";
  write(*dir_ / "unknown_lens.mcap", true);
  Result<ros::bag::Bag> unknown = ros::bag::ReadBag(*dir_ / "unknown_lens.mcap");
  ASSERT_FALSE(unknown.ok());
  EXPECT_THAT(unknown.status().message(), HasSubstr("kannala_brandt"));
}

TEST_F(ReplayTest, ARobotsBagIntoARunFolder) {
  const fs::path bag = WriteRobotBag(*dir_ / "robot.mcap");
  Result<ros::bag::Bag> b = ros::bag::ReadBag(bag);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_FALSE(b->avp_recording);
  EXPECT_EQ(b->account.pairs, 90u);
  ASSERT_EQ(b->views.size(), 3u);  // 1 frame per second of bag time
  auto reader = ros::bag::BagReader::Open(bag).value();
  experiment::RunConfig config = experiment::BagRunConfig(*reader).value();
  experiment::ReplayOptions o;
  o.folder.out_dir = *dir_ / "robot_default";
  // No segmenter given and the configuration's default, the oracle, needs labels: refused.
  Result<experiment::ReplaySummary> r =
      experiment::ReplayToFolder(*reader, config, Registries(), o);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(),
              HasSubstr("a robot's bag has neither avp's masks nor the simulator's labels, so it "
                        "needs a segmenter: give --segmenter NAME: color, ywes://MODEL_DIR"));
  EXPECT_FALSE(fs::exists(o.folder.out_dir));
  o.segmenter = "color";
  o.folder.out_dir = *dir_ / "robot_color";
  reader = ros::bag::BagReader::Open(bag).value();
  r = experiment::ReplayToFolder(*reader, config, Registries(), o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->segmenter, "color");
  EXPECT_EQ(r->metrics_compared, 0u);
  const json record = io::ReadJsonFile(o.folder.out_dir / "record.json").value();
  EXPECT_EQ(record["final_metrics"], nullptr);  // no ground truth
  EXPECT_EQ(record["replay"]["pairs"], 90);
  EXPECT_EQ(record["replay"]["left_out"]["fps"], 87);
  ASSERT_EQ(record["replay"]["frames"].size(), 3u);  // the fused ones (none was skipped)
  EXPECT_EQ(record["replay"]["frames"][1]["index"], 30);
  EXPECT_EQ(record["replay"]["frames"][1]["what"], "fused");
  EXPECT_GE(record["replay"]["frames"][1]["masks"].get<int>(), 1);
  EXPECT_EQ(record["replay"]["frames"][1]["masks_without_depth"], 0);
  ASSERT_EQ(record["steps"].size(), 3u);
  for (const json& step : record["steps"]) {
    EXPECT_GT(step["occupied_voxels"].get<int>(), 100) << step.dump();  // the wall
    EXPECT_GE(step["masks"].get<int>(), 1) << step.dump();              // the red disc
  }
  // The wall is 0.6 m along the camera's axis, which turns about the mount (0.4 m up) at
  // 0.05 rad/s: at t = 2 s the camera looks 0.1 rad to the left.
  Result<mapping::SemanticMap> map = mapping::LoadMap(o.folder.out_dir / "map.avpmap");
  ASSERT_TRUE(map.ok()) << map.status().ToString();
  EXPECT_GT(map->grid().CountOccupiedVoxels(), 300u);

  // A region of interest (replay.roi_min_m / roi_max_m): the map keeps only what is inside it.
  config.replay.roi_min_m = {0.5, -0.05, 0.35};
  config.replay.roi_max_m = {0.7, 0.05, 0.45};
  o.folder.out_dir = *dir_ / "robot_roi";
  reader = ros::bag::BagReader::Open(bag).value();
  r = experiment::ReplayToFolder(*reader, config, Registries(), o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  Result<mapping::SemanticMap> cropped = mapping::LoadMap(o.folder.out_dir / "map.avpmap");
  ASSERT_TRUE(cropped.ok()) << cropped.status().ToString();
  size_t inside = 0, outside = 0;
  const double h = cropped->voxel_size_m() / 2;
  cropped->grid().ForEachKnownVoxel([&](const VoxelKey& k, float) {
    const Eigen::Vector3d c =
        (Eigen::Vector3d(k.x, k.y, k.z).array() + 0.5).matrix() * cropped->voxel_size_m();
    const bool in = c.x() > 0.5 - h && c.x() < 0.7 + h && c.y() > -0.05 - h && c.y() < 0.05 + h &&
                    c.z() > 0.35 - h && c.z() < 0.45 + h;
    (in ? inside : outside) += 1;
  });
  EXPECT_EQ(outside, 0u);
  EXPECT_GT(inside, 100u);
  EXPECT_LT(cropped->grid().CountOccupiedVoxels(), map->grid().CountOccupiedVoxels());
  config.replay.roi_max_m = {0.7, 0.05};
  reader = ros::bag::BagReader::Open(bag).value();
  r = experiment::ReplayToFolder(*reader, config, Registries(), o);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("roi_min_m (3 values) and roi_max_m (2 values)"));
}

#ifdef AVP_BINARY
TEST_F(ReplayTest, CommandEndToEnd) {
  const std::string avp = AVP_BINARY;
  const fs::path out = *dir_ / "cli";
  test::Ran r =
      test::RunShell(avp + " replay " + Bag().string() + " --out " + out.string() + " 2>&1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("avp recording (MCAP (indexed, uncompressed chunks)"));
  EXPECT_THAT(r.output, HasSubstr("frames: 3 steps, 3 fused, 0 left out, 0 skipped; masks: "));
  EXPECT_THAT(r.output, HasSubstr("replayed 3 view(s) with recorded masks"));
  EXPECT_THAT(r.output, HasSubstr("metrics identical to the recording's at all 3 views"));
  // Progress off a terminal: one plain line per view.
  EXPECT_THAT(r.output, HasSubstr("views 3/3 (100 %)"));
  ExpectSameAsRun("cli");
  // The page says it is a replay, which planned nothing (not "avp-nbv, 3 of 8").
  const auto page = report::ReadRunReportData(out / "report.html");
  ASSERT_TRUE(page.ok()) << page.status().ToString();
  EXPECT_THAT(page->dump(), HasSubstr("replay of a recording"));
  EXPECT_THAT(page->dump(), HasSubstr("none (a replay: the recording's camera poses)"));
  EXPECT_THAT(page->dump(), HasSubstr("3 (the recording's)"));

  // A damaged recording: exit code 1, the offset named, the intact views written.
  const fs::path cut = *dir_ / "cli_cut.mcap";
  fs::copy_file(Bag(), cut, fs::copy_options::overwrite_existing);
  fs::resize_file(cut, fs::file_size(cut) * 75 / 100);
  r = test::RunShell(avp + " replay " + cut.string() + " --out " + (*dir_ / "cli_cut").string() +
                     " 2>&1");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("offset"));
  EXPECT_THAT(r.output, HasSubstr("intact view(s) were replayed"));
  EXPECT_TRUE(fs::exists(*dir_ / "cli_cut" / "map.avpmap"));

  // Unknown topic: the error lists the bag's topics.
  // A robot's bag with the RealSense names: --segmenter color.
  const fs::path robot = WriteRobotBag(*dir_ / "cli_robot.mcap");
  r = test::RunShell(avp + " replay " + robot.string() + " --segmenter color --fps 2 --out " +
                     (*dir_ / "cli_robot").string() + " 2>&1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("robot bag (MCAP (indexed, uncompressed chunks)"));
  EXPECT_THAT(r.output, HasSubstr("frames: 90 colour/depth pairs, 6 fused, 84 left out (84 fps), "
                                  "0 skipped; masks: 6, 0 with no valid depth"));
  // Each view's line: its masks, those without depth, the map; the count (the total is not
  // known while a bag streams).
  EXPECT_THAT(r.output, HasSubstr("views 6 "));
  EXPECT_THAT(r.output, HasSubstr("view 6: 1 masks (0 without depth), "));
  EXPECT_THAT(r.output, HasSubstr("replayed 6 view(s) with color masks"));
  EXPECT_TRUE(fs::exists(*dir_ / "cli_robot" / "map.ot"));

  r = test::RunShell(avp + " replay " + Bag().string() + " --out " + (*dir_ / "x").string() +
                     " --color-topic /nope 2>&1");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("no messages on '/nope' (the bag's topics: "));
}
#endif

}  // namespace
}  // namespace avp

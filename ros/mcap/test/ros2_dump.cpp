// Writes an MCAP file of real ROS 2 messages (avp::ros::msg's encoders and ros2msg schemas) with
// avp::ros::mcap::Writer, and a JSON sidecar of what it holds, for test/readback.mjs to check with
// npm's
// @mcap/core and @foxglove/rosmsg2-serialization.
// Usage: mcap_ros2_dump OUT_DIR  ->  OUT_DIR/ros2.mcap, OUT_DIR/expected.json

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include <avp/ros/mcap/mcap.h>
#include <avp/ros/msg/messages.h>

namespace {

using nlohmann::json;
namespace rm = avp::ros::msg;

json ToJson(const rm::Time& t) { return {{"sec", t.sec}, {"nanosec", t.nanosec}}; }
json ToJson(const rm::Header& h) { return {{"stamp", ToJson(h.stamp)}, {"frame_id", h.frame_id}}; }

json ToJson(const rm::Image& m) {
  return {{"header", ToJson(m.header)},
          {"height", m.height},
          {"width", m.width},
          {"encoding", m.encoding},
          {"is_bigendian", m.is_bigendian},
          {"step", m.step},
          {"data", m.data}};
}
json ToJson(const rm::CameraInfo& m) {
  return {{"header", ToJson(m.header)},
          {"height", m.height},
          {"width", m.width},
          {"distortion_model", m.distortion_model},
          {"d", m.d},
          {"k", m.k},
          {"r", m.r},
          {"p", m.p},
          {"binning_x", m.binning_x},
          {"binning_y", m.binning_y},
          {"roi",
           {{"x_offset", m.roi.x_offset},
            {"y_offset", m.roi.y_offset},
            {"height", m.roi.height},
            {"width", m.roi.width},
            {"do_rectify", m.roi.do_rectify}}}};
}
json ToJson(const rm::TFMessage& m) {
  json transforms = json::array();
  for (const auto& t : m.transforms) {
    const auto& tr = t.transform;
    transforms.push_back(
        {{"header", ToJson(t.header)},
         {"child_frame_id", t.child_frame_id},
         {"transform",
          {{"translation",
            {{"x", tr.translation.x}, {"y", tr.translation.y}, {"z", tr.translation.z}}},
           {"rotation",
            {{"x", tr.rotation.x},
             {"y", tr.rotation.y},
             {"z", tr.rotation.z},
             {"w", tr.rotation.w}}}}}});
  }
  return {{"transforms", transforms}};
}
json ToJson(const rm::JointState& m) {
  return {{"header", ToJson(m.header)},
          {"name", m.name},
          {"position", m.position},
          {"velocity", m.velocity},
          {"effort", m.effort}};
}

struct Out {
  avp::ros::mcap::Writer& writer;
  json& expected;
  uint32_t sequence = 0;

  template <typename T>
  uint16_t Channel(const std::string& topic, bool transient_local = false) {
    const std::string name(rm::MessageTraits<T>::kRosName);
    uint16_t schema = 0;
    for (size_t i = 0; i < expected["schemas"].size(); ++i) {
      if (expected["schemas"][i]["name"] == name) schema = static_cast<uint16_t>(i + 1);
    }
    if (schema == 0) {
      const std::string text(rm::Definition<T>());
      schema = writer.AddSchema(name, "ros2msg", text).value();
      expected["schemas"].push_back({{"name", name}, {"encoding", "ros2msg"}, {"data", text}});
    }
    const std::string qos = avp::ros::mcap::OfferedQosProfiles(true, transient_local);
    const uint16_t id =
        writer.AddChannel(schema, topic, "cdr", {{"offered_qos_profiles", qos}}).value();
    expected["channels"].push_back({{"id", id},
                                    {"topic", topic},
                                    {"schema_name", name},
                                    {"message_encoding", "cdr"},
                                    {"offered_qos_profiles", qos}});
    return id;
  }

  template <typename T>
  void Write(uint16_t channel, uint64_t t_ns, const T& msg) {
    const std::vector<uint8_t> bytes = rm::Encode(msg, rm::RosDistro::kJazzy);
    const avp::Status s = writer.Write(channel, sequence, t_ns, t_ns - 1000, bytes);
    if (!s.ok()) throw std::runtime_error(s.ToString());
    expected["messages"].push_back({{"channel_id", channel},
                                    {"sequence", sequence},
                                    {"log_time", std::to_string(t_ns)},
                                    {"publish_time", std::to_string(t_ns - 1000)},
                                    {"value", ToJson(msg)}});
    ++sequence;
  }
};

/// The channels of a robot's bag the dump writes every step.
struct RobotChannels {
  uint16_t image = 0;
  uint16_t info = 0;
  uint16_t tf = 0;
  uint16_t joints = 0;
};

/// Step `step`'s colour image, CameraInfo, moving transform and joint states.
void WriteRobotStep(Out& out, const RobotChannels& ch, uint32_t step) {
  const uint64_t t = 1'700'000'000'000'000'000ull + 200'000'000ull * step + 1;
  const rm::Time stamp = rm::Time::FromNanoseconds(static_cast<int64_t>(t));
  rm::Image img;
  img.header = {stamp, "camera_color_optical_frame"};
  img.height = 6;
  img.width = 8;
  img.encoding = "rgb8";
  img.step = 24;
  img.data.resize(6 * 24);
  for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = static_cast<uint8_t>(i * 7 + step);
  out.Write(ch.image, t, img);

  rm::CameraInfo ci;
  ci.header = img.header;
  ci.height = 6;
  ci.width = 8;
  ci.distortion_model = "plumb_bob";
  ci.d = {0.1, -0.05, 0.001, 0.0, 0.0};
  ci.k = {5.5, 0, 4, 0, 5.5, 3, 0, 0, 1};
  ci.r = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  ci.p = {5.5, 0, 4, 0, 0, 5.5, 3, 0, 0, 0, 1, 0};
  out.Write(ch.info, t, ci);

  rm::TFMessage moving;
  moving.transforms.resize(1);
  moving.transforms[0].header = {stamp, "base_link"};
  moving.transforms[0].child_frame_id = "tool0";
  moving.transforms[0].transform.translation = {0.3 + 0.01 * step, 0.1, 0.6};
  out.Write(ch.tf, t, moving);

  rm::JointState js;
  js.header = {stamp, ""};
  js.name = {"joint_1", "joint_2", "joint_3"};
  js.position = {0.1 * step, -0.25, 1.5 + 0.125 * step};
  out.Write(ch.joints, t, js);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: mcap_ros2_dump OUT_DIR\n");
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  std::filesystem::create_directories(dir);
  const auto path = dir / "ros2.mcap";
  auto writer = avp::ros::mcap::Writer::Open(path, {.chunk_size = 2048, .compression = ""}).value();
  json expected = {{"profile", "ros2"},
                   {"schemas", json::array()},
                   {"channels", json::array()},
                   {"messages", json::array()}};
  Out out{*writer, expected};
  // One Metadata record and one Attachment (as an avp recording has: "avp" and ground_truth.json).
  const avp::ros::mcap::Metadata metadata{
      "avp", {{"command", "avp run"}, {"scene", "tomato_plant"}, {"seed", "7"}, {"note", ""}}};
  if (const avp::Status s = writer->WriteMetadata(metadata); !s.ok()) {
    std::fprintf(stderr, "%s\n", s.ToString().c_str());
    return 1;
  }
  expected["metadata"] = json::array({{{"name", metadata.name}, {"metadata", metadata.metadata}}});
  const avp::ros::mcap::Attachment attachment{
      1'700'000'000'000'000'000ull, 1'700'000'000'000'000'002ull, "ground_truth.json",
      "application/json", R"({"fruits": [{"id": 1, "voxels": 42}]})"};
  if (const avp::Status s = writer->WriteAttachment(attachment); !s.ok()) {
    std::fprintf(stderr, "%s\n", s.ToString().c_str());
    return 1;
  }
  expected["attachments"] = json::array({{{"name", attachment.name},
                                          {"media_type", attachment.media_type},
                                          {"log_time", std::to_string(attachment.log_time)},
                                          {"create_time", std::to_string(attachment.create_time)},
                                          {"data", attachment.data}}});
  RobotChannels channels;
  channels.image = out.Channel<rm::Image>("/camera/camera/color/image_raw");
  channels.info = out.Channel<rm::CameraInfo>("/camera/camera/color/camera_info");
  channels.tf = out.Channel<rm::TFMessage>("/tf");
  const uint16_t tf_static = out.Channel<rm::TFMessage>("/tf_static", true);
  channels.joints = out.Channel<rm::JointState>("/joint_states");

  rm::TFMessage fixed;
  fixed.transforms.resize(1);
  fixed.transforms[0].header.frame_id = "tool0";
  fixed.transforms[0].child_frame_id = "camera_color_optical_frame";
  fixed.transforms[0].transform.translation = {0.01, -0.02, 0.05};
  fixed.transforms[0].transform.rotation = {-0.5, 0.5, -0.5, 0.5};
  out.Write(tf_static, 1'700'000'000'000'000'000ull, fixed);

  for (uint32_t step = 0; step < 6; ++step) WriteRobotStep(out, channels, step);
  const avp::Status closed = writer->Close();
  if (!closed.ok()) {
    std::fprintf(stderr, "%s\n", closed.ToString().c_str());
    return 1;
  }
  const auto& st = writer->statistics();
  expected["statistics"] = {{"message_count", st.message_count},
                            {"chunk_count", st.chunk_count},
                            {"attachment_count", st.attachment_count},
                            {"metadata_count", st.metadata_count},
                            {"message_start_time", std::to_string(st.message_start_time)},
                            {"message_end_time", std::to_string(st.message_end_time)}};
  std::ofstream(dir / "expected.json") << expected.dump(1) << "\n";
  std::printf("%s\n", path.c_str());
  return 0;
}

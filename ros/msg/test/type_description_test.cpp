#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/ros/msg/messages.h>

namespace avp::ros::msg {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

// ros2-interop.md §1.6 and the hashes Jazzy's rosidl generates for these types.
TEST(RosmsgTypeHashTest, MatchesJazzy) {
  EXPECT_EQ(TypeHash<Time>(),
            "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197");
  EXPECT_EQ(TypeHash<Point>(),
            "RIHS01_6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881");
  EXPECT_EQ(TypeHash<Quaternion>(),
            "RIHS01_8a765f66778c8ff7c8ab94afcc590a2ed5325a1d9a076ffff38fbce36f458684");
  EXPECT_EQ(TypeHash<String>(),
            "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18");
  // With referenced types (sorted by name) and fixed-size arrays:
  EXPECT_EQ(TypeHash<Header>(),
            "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01");
  EXPECT_EQ(TypeHash<Pose>(),
            "RIHS01_d501954e9476cea2996984e812054b68026ae0bfae789d9a10b23daf35cc90fa");
  EXPECT_EQ(TypeHash<Image>(),
            "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47");
  EXPECT_EQ(TypeHash<CameraInfo>(),
            "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275");
}

TEST(RosmsgTypeHashTest, EveryTypeHasOne) {
  for (const MessageInfo& info : AllMessages()) {
    const Result<std::string> hash = TypeHashOf(info.ros_name);
    ASSERT_TRUE(hash.ok()) << hash.status().ToString();
    EXPECT_THAT(*hash, ::testing::MatchesRegex("RIHS01_[0-9a-f]{64}")) << info.ros_name;
  }
  EXPECT_EQ(TypeHashOf("std_msgs/msg/Nope").status().code(), StatusCode::kNotFound);
}

TEST(RosmsgTypeHashTest, CanonicalJson) {
  EXPECT_EQ(TypeDescriptionJsonOf("builtin_interfaces/msg/Time").value(),
            "{\"type_description\": {\"type_name\": \"builtin_interfaces/msg/Time\", \"fields\": "
            "[{\"name\": \"sec\", \"type\": {\"type_id\": 6, \"capacity\": 0, \"string_capacity\": "
            "0, \"nested_type_name\": \"\"}}, {\"name\": \"nanosec\", \"type\": {\"type_id\": 7, "
            "\"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"\"}}]}, "
            "\"referenced_type_descriptions\": []}");
  const std::string node = TypeDescriptionJsonOf("rmw_dds_common/msg/NodeEntitiesInfo").value();
  // string<=256: BOUNDED_STRING (21); Gid[]: NESTED_TYPE unbounded sequence (1 + 144);
  // char[16]: UINT8 array (3 + 48).
  EXPECT_THAT(node, HasSubstr("{\"name\": \"node_name\", \"type\": {\"type_id\": 21, "
                              "\"capacity\": 0, \"string_capacity\": 256"));
  EXPECT_THAT(node, HasSubstr("\"type_id\": 145, \"capacity\": 0, \"string_capacity\": 0, "
                              "\"nested_type_name\": \"rmw_dds_common/msg/Gid\""));
  EXPECT_THAT(node, HasSubstr("{\"name\": \"data\", \"type\": {\"type_id\": 51, \"capacity\": 16"));
}

TEST(RosmsgDefinitionTest, Ros2MsgShape) {
  const std::string_view image = Definition<Image>();
  EXPECT_THAT(std::string(image), StartsWith(std::string(MessageTraits<Image>::kMsg)));
  const std::string separator = std::string(80, '=');
  EXPECT_THAT(std::string(image), HasSubstr("\n" + separator + "\nMSG: std_msgs/Header\n"));
  EXPECT_THAT(std::string(image), HasSubstr("\n" + separator + "\nMSG: builtin_interfaces/Time\n"));
  EXPECT_THAT(std::string(image), ::testing::Not(HasSubstr("MSG: std_msgs/msg/")));
  // Every line of '=' is exactly 80 long, and each dependency appears once.
  size_t separators = 0;
  size_t start = 0;
  const std::string text(Definition<MarkerArray>());
  while (start < text.size()) {
    const size_t end = text.find('\n', start);
    const std::string line = text.substr(start, end - start);
    if (!line.empty() && line[0] == '=') {
      EXPECT_EQ(line, separator);
      ++separators;
    }
    start = end == std::string::npos ? text.size() : end + 1;
  }
  // MarkerArray: Marker, Header, Time, Pose, Point, Quaternion, Vector3, ColorRGBA, Duration,
  // CompressedImage, UVCoordinate, MeshFile.
  EXPECT_EQ(separators, 12u);
  EXPECT_EQ(text.find("MSG: geometry_msgs/Point\n"), text.rfind("MSG: geometry_msgs/Point\n"));
  EXPECT_EQ(Definition<Time>(), "int32 sec\nuint32 nanosec\n");
}

TEST(RosmsgDefinitionTest, DistroDifferences) {
  EXPECT_THAT(std::string(Definition<Marker>(RosDistro::kJazzy)), HasSubstr("ARROW_STRIP = 12"));
  EXPECT_THAT(std::string(Definition<Marker>(RosDistro::kHumble)),
              ::testing::Not(HasSubstr("ARROW_STRIP")));
  EXPECT_THAT(std::string(Definition<ParticipantEntitiesInfo>(RosDistro::kHumble)),
              HasSubstr("MSG: rmw_dds_common/Gid\nchar[24] data\n"));
  EXPECT_THAT(std::string(Definition<ParticipantEntitiesInfo>(RosDistro::kJazzy)),
              HasSubstr("MSG: rmw_dds_common/Gid\nchar[16] data\n"));
  EXPECT_EQ(DefinitionOf("nope/msg/Nope").status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace avp::ros::msg

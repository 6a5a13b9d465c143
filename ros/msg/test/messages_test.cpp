#include "avp/ros/msg/messages.h"

#include <algorithm>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "reference_messages.h"

namespace avp::ros::msg {
namespace {

template <class T>
std::vector<RosDistro> DistrosOf() {
  if constexpr (kDistroDependent<T>) return {RosDistro::kHumble, RosDistro::kJazzy};
  return {RosDistro::kJazzy};
}

/// Records the field names VisitFields reports.
class NameVisitor {
 public:
  RosDistro distro() const { return RosDistro::kJazzy; }
  template <class F>
  void operator()(std::string_view name, const F&) {
    names.emplace_back(name);
  }
  void FixedBytes(std::string_view name, const std::array<uint8_t, 24>&, size_t) {
    names.emplace_back(name);
  }
  void BoundedString(std::string_view name, const std::string&, size_t) {
    names.emplace_back(name);
  }
  std::vector<std::string> names;
};

template <class T>
class RosmsgMessageTypeTest : public ::testing::Test {};

#define AVP_ROSMSG_TYPE_COMMA(T) T,
using Types = ::testing::Types<AVP_ROSMSG_FOR_EACH_TYPE(AVP_ROSMSG_TYPE_COMMA) char>;
#undef AVP_ROSMSG_TYPE_COMMA
// `char` closes the list; the tests skip it.
TYPED_TEST_SUITE(RosmsgMessageTypeTest, Types);

TYPED_TEST(RosmsgMessageTypeTest, RoundTripsEveryReferenceMessage) {
  using T = TypeParam;
  if constexpr (RosMessage<T>) {
    for (const RosDistro distro : DistrosOf<T>()) {
      for (const T& msg : testing::References<T>()) {
        const std::vector<uint8_t> bytes = Encode(msg, distro);
        ASSERT_GE(bytes.size(), 5u);
        EXPECT_EQ(bytes[0], 0x00);
        EXPECT_EQ(bytes[1], 0x01);
        const Result<T> back = Decode<T>(bytes, distro);
        ASSERT_TRUE(back.ok()) << back.status().ToString();
        EXPECT_TRUE(*back == msg) << MessageTraits<T>::kRosName;
        const Result<T> be = Decode<T>(Encode(msg, distro, Endianness::kBig), distro);
        ASSERT_TRUE(be.ok()) << be.status().ToString();
        EXPECT_TRUE(*be == msg) << MessageTraits<T>::kRosName << " big-endian";
      }
    }
  }
}

TYPED_TEST(RosmsgMessageTypeTest, EveryTruncationIsRefusedWithoutCrashing) {
  using T = TypeParam;
  if constexpr (RosMessage<T>) {
    for (const RosDistro distro : DistrosOf<T>()) {
      for (const T& msg : testing::References<T>()) {
        const std::vector<uint8_t> bytes = Encode(msg, distro);
        for (size_t n = 0; n < bytes.size(); ++n) {
          // An exact-size copy, so that a sanitizer sees any read past the end.
          const std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + n);
          const Result<T> r = Decode<T>(prefix, distro);
          ASSERT_FALSE(r.ok()) << MessageTraits<T>::kRosName << " truncated to " << n << " of "
                               << bytes.size() << " bytes decoded";
          EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
          EXPECT_THAT(r.status().message(),
                      ::testing::StartsWith(std::string(MessageTraits<T>::kRosName) + ": "));
        }
      }
    }
  }
}

TYPED_TEST(RosmsgMessageTypeTest, CorruptedSamplesNeverCrash) {
  using T = TypeParam;
  if constexpr (RosMessage<T>) {
    std::mt19937 rng(14);
    for (const RosDistro distro : DistrosOf<T>()) {
      for (const T& msg : testing::References<T>()) {
        const std::vector<uint8_t> bytes = Encode(msg, distro);
        for (int trial = 0; trial < 200; ++trial) {
          std::vector<uint8_t> bad = bytes;
          const int flips = 1 + static_cast<int>(rng() % 4);
          for (int f = 0; f < flips; ++f) {
            const size_t i = 4 + rng() % (bad.size() - 4);
            bad[i] = static_cast<uint8_t>(rng());
          }
          const Result<T> r = Decode<T>(bad, distro);
          if (r.ok()) {
            EXPECT_FALSE(Encode(*r, distro).empty());  // what decodes re-encodes
          }
        }
      }
    }
  }
}

TYPED_TEST(RosmsgMessageTypeTest, NamesAndFieldsAgreeWithTheMsgText) {
  using T = TypeParam;
  if constexpr (RosMessage<T>) {
    const std::string_view ros = MessageTraits<T>::kRosName;
    const std::string_view dds = MessageTraits<T>::kDdsName;
    const size_t slash = ros.find('/');
    const std::string pkg(ros.substr(0, slash));
    const std::string type(ros.substr(ros.rfind('/') + 1));
    EXPECT_EQ(ros, pkg + "/msg/" + type);
    EXPECT_EQ(dds, pkg + "::msg::dds_::" + type + "_");
    // The fields VisitFields walks are the fields of the .msg text, in order.
    NameVisitor names;
    const T msg{};
    MessageTraits<T>::VisitFields(names, msg);
    const std::string json = TypeDescriptionJsonOf(ros).value();
    const std::string top = json.substr(0, json.find("referenced_type_descriptions"));
    size_t at = 0;
    for (const std::string& name : names.names) {
      const size_t found = top.find("{\"name\": \"" + name + "\"", at);
      ASSERT_NE(found, std::string::npos)
          << ros << ": field " << name << " missing or out of order";
      at = found;
    }
    EXPECT_EQ(static_cast<size_t>(std::count(top.begin(), top.end(), '{')) - 2,
              2 * names.names.size())
        << ros << ": the .msg text has fields VisitFields does not visit";
  }
}

TEST(RosmsgMessagesTest, GidIs24BytesInHumbleAnd16FromIronOn) {
  const Gid gid = testing::Gid24();
  EXPECT_EQ(Encode(gid, RosDistro::kHumble).size(), 4u + 24u);
  EXPECT_EQ(Encode(gid, RosDistro::kJazzy).size(), 4u + 16u);
  EXPECT_EQ(Decode<Gid>(Encode(gid, RosDistro::kHumble), RosDistro::kHumble).value(), gid);
  Gid first16 = gid;
  for (size_t i = 16; i < 24; ++i) first16.data[i] = 0;
  EXPECT_EQ(Decode<Gid>(Encode(gid, RosDistro::kJazzy), RosDistro::kJazzy).value(), first16);
  // A Humble sample read as Jazzy misreads GID bytes 17..20 as the node count and is refused.
  ParticipantEntitiesInfo info = testing::References<ParticipantEntitiesInfo>()[1];
  info.gid = gid;
  EXPECT_FALSE(
      Decode<ParticipantEntitiesInfo>(Encode(info, RosDistro::kHumble), RosDistro::kJazzy).ok());
}

TEST(RosmsgMessagesTest, TimeFromNanoseconds) {
  EXPECT_EQ(Time::FromNanoseconds(0), (Time{0, 0}));
  EXPECT_EQ(Time::FromNanoseconds(1'500'000'001), (Time{1, 500'000'001}));
  EXPECT_EQ(Time::FromNanoseconds(-1), (Time{-1, 999'999'999}));
  EXPECT_EQ(Time::FromNanoseconds(-1'700'000'000), (Time{-2, 300'000'000}));
  EXPECT_EQ(Time::FromNanoseconds(std::numeric_limits<int64_t>::max()),
            (Time{std::numeric_limits<int32_t>::max(), 999'999'999}));
  EXPECT_EQ(Time::FromNanoseconds(std::numeric_limits<int64_t>::min()),
            (Time{std::numeric_limits<int32_t>::min(), 0}));
  for (const int64_t ns : {int64_t{0}, int64_t{-1}, int64_t{1'700'000'000'123'456'789},
                           int64_t{-2'000'000'000'000'000'000}}) {
    EXPECT_EQ(Time::FromNanoseconds(ns).ToNanoseconds(), ns);
    EXPECT_EQ(Duration::FromNanoseconds(ns).ToNanoseconds(), ns);
  }
  EXPECT_EQ(Duration::FromNanoseconds(-1'700'000'000), (Duration{-2, 300'000'000}));
}

TEST(RosmsgMessagesTest, AllMessagesListsEveryTypeOnce) {
  std::set<std::string_view> names;
  for (const MessageInfo& info : AllMessages()) EXPECT_TRUE(names.insert(info.ros_name).second);
  EXPECT_EQ(names.size(), 31u);
  EXPECT_TRUE(names.count("std_msgs/msg/String"));
  EXPECT_TRUE(names.count("octomap_msgs/msg/Octomap"));
}

}  // namespace
}  // namespace avp::ros::msg

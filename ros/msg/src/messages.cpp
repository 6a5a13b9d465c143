#include "avp/ros/msg/messages.h"

#include <limits>

#include "serde.h"

namespace avp::ros::msg {
namespace {

constexpr int64_t kNsPerSecond = 1'000'000'000;

template <class T>
T StampFromNanoseconds(int64_t ns) {
  int64_t sec = ns / kNsPerSecond;
  int64_t rem = ns % kNsPerSecond;
  if (rem < 0) {
    sec -= 1;
    rem += kNsPerSecond;
  }
  if (sec > std::numeric_limits<int32_t>::max()) {
    return T{std::numeric_limits<int32_t>::max(), static_cast<uint32_t>(kNsPerSecond - 1)};
  }
  if (sec < std::numeric_limits<int32_t>::min()) {
    return T{std::numeric_limits<int32_t>::min(), 0};
  }
  return T{static_cast<int32_t>(sec), static_cast<uint32_t>(rem)};
}

}  // namespace

std::string_view ToString(RosDistro distro) {
  return distro == RosDistro::kHumble ? "humble" : "jazzy";
}

Time Time::FromNanoseconds(int64_t ns) { return StampFromNanoseconds<Time>(ns); }
int64_t Time::ToNanoseconds() const { return int64_t{sec} * kNsPerSecond + int64_t{nanosec}; }
Duration Duration::FromNanoseconds(int64_t ns) { return StampFromNanoseconds<Duration>(ns); }
int64_t Duration::ToNanoseconds() const { return int64_t{sec} * kNsPerSecond + int64_t{nanosec}; }

template <RosMessage T>
std::vector<uint8_t> Encode(const T& msg, RosDistro distro, Endianness endianness) {
  CdrWriter writer(endianness);
  internal::EncodeVisitor visitor(writer, distro);
  MessageTraits<T>::VisitFields(visitor, msg);
  return std::move(writer).Finish();
}

template <RosMessage T>
Result<T> Decode(std::span<const uint8_t> bytes, RosDistro distro) {
  Result<CdrReader> reader = CdrReader::Open(bytes);
  if (!reader.ok()) return reader.status().WithContext(MessageTraits<T>::kRosName);
  T msg;
  internal::DecodeVisitor visitor(*reader, distro, MessageTraits<T>::kRosName);
  MessageTraits<T>::VisitFields(visitor, msg);
  if (!visitor.status().ok()) return visitor.status();
  return msg;
}

#define AVP_ROSMSG_INSTANTIATE(T)                                           \
  template std::vector<uint8_t> Encode<T>(const T&, RosDistro, Endianness); \
  template Result<T> Decode<T>(std::span<const uint8_t>, RosDistro);
AVP_ROSMSG_FOR_EACH_TYPE(AVP_ROSMSG_INSTANTIATE)
#undef AVP_ROSMSG_INSTANTIATE

namespace {

template <class T>
MessageInfo InfoOf() {
  using Traits = MessageTraits<T>;
  MessageInfo info;
  info.ros_name = Traits::kRosName;
  info.dds_name = Traits::kDdsName;
  info.msg_jazzy = Traits::kMsg;
  if constexpr (requires { Traits::kMsgHumble; }) {
    info.msg_humble = Traits::kMsgHumble;
  } else {
    info.msg_humble = Traits::kMsg;
  }
  info.distro_dependent = Traits::kDistroDependent;
  return info;
}

}  // namespace

std::span<const MessageInfo> AllMessages() {
#define AVP_ROSMSG_INFO(T) InfoOf<T>(),
  static const std::vector<MessageInfo> kAll = {AVP_ROSMSG_FOR_EACH_TYPE(AVP_ROSMSG_INFO)};
#undef AVP_ROSMSG_INFO
  return kAll;
}

template <RosMessage T>
std::string_view Definition(RosDistro distro) {
  static const std::string kJazzy =
      DefinitionOf(MessageTraits<T>::kRosName, RosDistro::kJazzy).value();
  static const std::string kHumble =
      DefinitionOf(MessageTraits<T>::kRosName, RosDistro::kHumble).value();
  return distro == RosDistro::kHumble ? kHumble : kJazzy;
}

#define AVP_ROSMSG_INSTANTIATE(T) template std::string_view Definition<T>(RosDistro);
AVP_ROSMSG_FOR_EACH_TYPE(AVP_ROSMSG_INSTANTIATE)
#undef AVP_ROSMSG_INSTANTIATE

}  // namespace avp::ros::msg

// Writes avp's encodings of the reference messages (reference_messages.h) as JSON for
// ros/msg/test/golden.mjs:
//   {"definitions": {"<ros name>": {"humble": "...", "jazzy": "..."}},
//    "samples": [{"type": "<ros name>", "distro": "humble" | "jazzy" | "any", "value": {...},
//                 "hex": "0001..."}]}
// Values use the field names and shapes of @foxglove/rosmsg2-serialization (time as
// {sec, nanosec}, byte arrays as arrays of numbers).

#include <iostream>
#include <string>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <avp/ros/msg/messages.h>

#include "reference_messages.h"

namespace avp::ros::msg {
namespace {

using nlohmann::json;

class JsonVisitor {
 public:
  explicit JsonVisitor(RosDistro distro) : distro_(distro) {}
  RosDistro distro() const { return distro_; }
  json& out() { return out_; }

  template <class F>
  void operator()(std::string_view name, const F& field) {
    out_[std::string(name)] = ToJson(field);
  }
  void FixedBytes(std::string_view name, const std::array<uint8_t, 24>& data, size_t n) {
    json a = json::array();
    for (size_t i = 0; i < n; ++i) a.push_back(data[i]);
    out_[std::string(name)] = a;
  }
  void BoundedString(std::string_view name, const std::string& s, size_t /*bound*/) {
    out_[std::string(name)] = s;
  }

  template <RosMessage M>
  json Message(const M& msg) const {
    JsonVisitor nested(distro_);
    MessageTraits<M>::VisitFields(nested, msg);
    return nested.out_.is_null() ? json::object() : nested.out_;
  }

 private:
  template <class P>
  requires std::is_arithmetic_v<P> json ToJson(P v)
  const { return v; }
  json ToJson(const std::string& s) const { return s; }
  template <class E>
  json ToJson(const std::vector<E>& values) const {
    json a = json::array();
    for (const E& e : values) a.push_back(ToJson(e));
    return a;
  }
  template <class E, size_t N>
  json ToJson(const std::array<E, N>& values) const {
    json a = json::array();
    for (const E& e : values) a.push_back(ToJson(e));
    return a;
  }
  template <RosMessage M>
  json ToJson(const M& msg) const {
    return Message(msg);
  }

  RosDistro distro_;
  json out_;
};

std::string Hex(const std::vector<uint8_t>& bytes) {
  std::string out;
  out.reserve(bytes.size() * 2);
  for (const uint8_t b : bytes) out += fmt::format("{:02x}", b);
  return out;
}

template <class T>
void Dump(json& definitions, json& samples) {
  const std::string name(MessageTraits<T>::kRosName);
  definitions[name] = {{"humble", std::string(Definition<T>(RosDistro::kHumble))},
                       {"jazzy", std::string(Definition<T>(RosDistro::kJazzy))}};
  std::vector<RosDistro> distros = {RosDistro::kJazzy};
  if constexpr (kDistroDependent<T>) distros = {RosDistro::kHumble, RosDistro::kJazzy};
  std::vector<T> messages = testing::References<T>();
  if constexpr (std::is_same_v<T, Gid>) messages.push_back(testing::Gid24());
  for (const RosDistro distro : distros) {
    for (const T& msg : messages) {
      samples.push_back({{"type", name},
                         {"distro", kDistroDependent<T> ? std::string(ToString(distro)) : "any"},
                         {"value", JsonVisitor(distro).Message(msg)},
                         {"hex", Hex(Encode(msg, distro))}});
    }
  }
}

}  // namespace
}  // namespace avp::ros::msg

int main() {
  using namespace avp::ros::msg;
  nlohmann::json definitions = nlohmann::json::object();
  nlohmann::json samples = nlohmann::json::array();
#define AVP_ROSMSG_DUMP(T) Dump<T>(definitions, samples);
  AVP_ROSMSG_FOR_EACH_TYPE(AVP_ROSMSG_DUMP)
#undef AVP_ROSMSG_DUMP
  std::cout << nlohmann::json{{"definitions", definitions}, {"samples", samples}}.dump() << "\n";
  return 0;
}

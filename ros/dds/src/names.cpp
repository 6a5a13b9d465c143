#include "names.h"

#include <cctype>
#include <cstdlib>
#include <string>
#include <string_view>

#include <fmt/format.h>

#include <avp/ros/dds/node.h>

namespace avp::ros::dds {
namespace {

bool IsTokenChar(char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_'; }

// Checks a '/'-separated path of tokens: [A-Za-z0-9_]+, no token starting with a digit, no empty
// token. `what` names the thing for the message ("topic name '1abc'").
Status CheckTokens(std::string_view path, std::string_view what) {
  if (path.empty()) return Status::Ok();
  size_t start = 0;
  while (start <= path.size()) {
    const size_t end = std::min(path.find('/', start), path.size());
    const std::string_view token = path.substr(start, end - start);
    if (token.empty()) {
      return InvalidArgumentError(fmt::format("{} must not contain '//' or end with '/'", what));
    }
    if (std::isdigit(static_cast<unsigned char>(token.front())) != 0) {
      return InvalidArgumentError(
          fmt::format("{}: the token '{}' must not start with a digit", what, token));
    }
    for (const char c : token) {
      if (!IsTokenChar(c)) {
        return InvalidArgumentError(fmt::format(
            "{}: character '{}' is not allowed (only letters, digits, '_', '/' and a leading '~')",
            what, c));
      }
    }
    start = end + 1;
  }
  return Status::Ok();
}

}  // namespace

Status ValidateNodeName(std::string_view name) {
  const std::string what = fmt::format("node name '{}'", name);
  if (name.empty()) return InvalidArgumentError("node name must not be empty");
  if (name.size() > 255) return InvalidArgumentError(what + " is longer than 255 characters");
  if (std::isdigit(static_cast<unsigned char>(name.front())) != 0) {
    return InvalidArgumentError(what + " must not start with a digit");
  }
  for (const char c : name) {
    if (!IsTokenChar(c)) {
      return InvalidArgumentError(
          fmt::format("{}: character '{}' is not allowed (only letters, digits and '_')", what, c));
    }
  }
  return Status::Ok();
}

Result<std::string> NormalizeNamespace(std::string_view ns) {
  // fmt::format rather than operator+: GCC 12 warns falsely (-Wrestrict) on "/" + std::string.
  std::string out = ns.empty() || ns.front() != '/' ? fmt::format("/{}", ns) : std::string(ns);
  if (out == "/") return out;
  AVP_RETURN_IF_ERROR(
      CheckTokens(std::string_view(out).substr(1), fmt::format("node namespace '{}'", ns)));
  return out;
}

Result<std::string> ExpandTopicName(std::string_view topic, std::string_view node_name,
                                    std::string_view node_namespace) {
  const std::string what = fmt::format("topic name '{}'", topic);
  if (topic.empty()) return InvalidArgumentError("topic name must not be empty");
  if (topic.find('{') != std::string_view::npos || topic.find('}') != std::string_view::npos) {
    return InvalidArgumentError(what + ": substitutions ({...}) are not supported");
  }
  const std::string_view ns = node_namespace.empty() ? std::string_view("/") : node_namespace;
  const std::string ns_prefix = ns == "/" ? std::string("/") : fmt::format("{}/", ns);
  std::string full;
  if (topic.front() == '~') {
    if (topic.size() > 1 && topic[1] != '/') {
      return InvalidArgumentError(what + ": '~' must be followed by '/' or end the name");
    }
    full = fmt::format("{}{}{}", ns_prefix, node_name, topic.substr(1));
  } else if (topic.front() == '/') {
    full = std::string(topic);
  } else {
    full = fmt::format("{}{}", ns_prefix, topic);
  }
  if (full.size() < 2) return InvalidArgumentError(what + " names no topic");
  AVP_RETURN_IF_ERROR(CheckTokens(std::string_view(full).substr(1), what));
  // rmw: DDS topic names are limited to 256 characters, "rt" included.
  if (full.size() + 2 > 256) {
    return InvalidArgumentError(
        fmt::format("{}: expands to '{}', longer than 254 characters", what, full));
  }
  return full;
}

Result<int> ResolveDomainId(int requested) {
  constexpr int kMaxDomainId = 232;  // ROS 2's limit (DDS ports stay below 65535)
  if (requested >= 0) {
    if (requested > kMaxDomainId) {
      return InvalidArgumentError(
          fmt::format("domain id ({}) must be in 0..{}", requested, kMaxDomainId));
    }
    return requested;
  }
  if (requested != -1) {
    return InvalidArgumentError(fmt::format(
        "domain id ({}) must be in 0..{}, or -1 for ROS_DOMAIN_ID", requested, kMaxDomainId));
  }
  const char* env = std::getenv("ROS_DOMAIN_ID");
  if (env == nullptr || *env == '\0') return 0;
  const std::string_view text(env);
  bool digits = text.size() <= 3;
  for (const char c : text) digits = digits && std::isdigit(static_cast<unsigned char>(c)) != 0;
  const int value = digits ? std::atoi(env) : -1;
  if (!digits || value > kMaxDomainId) {
    return InvalidArgumentError(
        fmt::format("ROS_DOMAIN_ID ('{}') must be an integer in 0..{}", text, kMaxDomainId));
  }
  return value;
}

}  // namespace avp::ros::dds

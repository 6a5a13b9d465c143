#pragma once

// What `avp live` and `avp sim ros2` share: their config section's options (a `live:` or `sim:`
// section of --config, then --<name>-option items) and Ctrl-C as a stop request.
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <functional>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/io/options_yaml.h>

namespace avp::apps {

/// The options of a command's own config section: the defaults, `section` (from --config, named
/// `context` in errors), then the KEY=VALUE `items`; checked against the table's ranges and rules.
template <class T>
Result<T> ResolveSectionOptions(const OptionTable<T>& table, const YAML::Node& section,
                                const std::vector<std::string>& items, const std::string& context,
                                std::string_view what) {
  T o;
  if (section) AVP_RETURN_IF_ERROR(io::ReadOptionsYaml(table, o, section, context));
  AVP_ASSIGN_OR_RETURN(const OptionValues values, ParseKeyValues(items, what));
  for (const auto& [key, value] : values) AVP_RETURN_IF_ERROR(table.Set(o, key, value));
  AVP_RETURN_IF_ERROR(table.Validate(o));
  return o;
}

/// While it lives, SIGINT and SIGTERM (and `timeout_s` > 0 passing) request a stop of `stop`,
/// after printing `message` (or the time limit's); `tick` (may be empty) runs every 50 ms on the
/// watcher thread (progress lines). Restores the previous handlers when it goes.
class StopOnSignal {
 public:
  StopOnSignal(std::stop_source& stop, double timeout_s, std::string message,
               std::function<void()> tick = {});
  ~StopOnSignal();
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;

 private:
  void (*old_int_)(int) = SIG_DFL;
  void (*old_term_)(int) = SIG_DFL;
  std::jthread watcher_;
};

}  // namespace avp::apps

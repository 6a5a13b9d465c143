// Helpers the command files share (internal to apps/).
#pragma once

#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>

#include <avp/apps/commands.h>
#include <avp/core/options.h>
#include <avp/core/status.h>

namespace avp::apps {

/// Runs `command` and stores its exit code in `context`: avp::Error (a violated precondition) is
/// reported and gives 1, any other exception 2.
void RunGuarded(CommandContext& context, const std::function<int()>& command);

/// Logs "<command> failed: <status>" and returns 1.
int Failed(std::string_view command, const Status& status);

/// "a, b, c" split on commas, items trimmed, empty ones dropped.
std::vector<std::string> SplitCommaList(std::string_view text);

/// Repeatable "--<name> KEY=VALUE" option bound to `values`.
CLI::Option* AddKeyValueOption(CLI::App& cmd, const std::string& name,
                               std::vector<std::string>& values, const std::string& description);

/// The registered components (planners or segmenters) with their descriptions and options, for
/// `--planner help` / `--segmenter help`: "name  description" then one line per option.
template <typename Entry>
std::string DescribeComponents(std::string_view what, const std::vector<Entry>& entries) {
  std::string out = std::string(what) + ":\n";
  for (const Entry& e : entries) {
    out += "  " + e.name + "  " + e.description + "\n";
    const std::vector<OptionInfo> info = e.options.Info();
    if (info.empty()) {
      out += "      (no options)\n";
    } else {
      out += FormatOptionHelp(info, "      ");
    }
  }
  return out;
}

}  // namespace avp::apps

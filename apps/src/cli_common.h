// Helpers the command files share (internal to apps/).
#pragma once

#include <algorithm>
#include <cstdio>
#include <functional>
#include <limits>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/core/text.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene.h>

#include "commands.h"

namespace avp::apps {

/// Runs `command` and stores its exit code in `context`: avp::Error (a violated precondition) is
/// reported and gives 1, any other exception 2.
void RunGuarded(CommandContext& context, const std::function<int()>& command);

/// Logs "<command> failed: <status>" and returns 1.
int Failed(std::string_view command, const Status& status);

/// "a, b, c" split on commas, items trimmed, empty ones dropped.
std::vector<std::string> SplitCommaList(std::string_view text);

/// A list given explicitly on the command line ("--scenarios a,b"): split on commas, items
/// trimmed. InvalidArgument naming `option` for an empty list ("--scenarios ''": never "the
/// defaults") or an empty item ("a,,b"), and for more than `max_items` items.
Result<std::vector<std::string>> ParseCliList(std::string_view option, std::string_view text,
                                              size_t max_items = 100000);

/// Strict numbers of the command line: the whole text is the number (no trailing text, no
/// leading space or '+', no hex or octal), an unsigned option takes no sign (never "-1" wrapped to
/// 2^64 - 1), a real is finite, and the value lies in [min, max]. The error names the option, the
/// range and the text (QuoteText: a 300-digit number is not echoed whole).
Result<uint64_t> ParseCliUnsigned(std::string_view option, std::string_view text, uint64_t min,
                                  uint64_t max);
Result<int64_t> ParseCliInteger(std::string_view option, std::string_view text, int64_t min,
                                int64_t max);
Result<double> ParseCliReal(std::string_view option, std::string_view text, double min, double max);

/// A number option of `cmd` parsed with ParseCli* into `value` (left as it is when the option is
/// not given; `value`'s current value is shown as the default). A bad value is a command-line
/// error (CLI::ValidationError, exit code 105) with ParseCli*'s message.
template <typename T>
CLI::Option* AddNumberOption(CLI::App& cmd, const std::string& name, T& value, T min, T max,
                             const std::string& description) {
  static_assert(std::is_arithmetic_v<T> && !std::is_same_v<T, bool>);
  CLI::Option* option = cmd.add_option_function<std::string>(
      name,
      [&value, name, min, max](const std::string& text) {
        if constexpr (std::is_floating_point_v<T>) {
          const Result<double> v =
              ParseCliReal(name, text, static_cast<double>(min), static_cast<double>(max));
          if (!v.ok()) throw CLI::ValidationError(v.status().message());
          value = static_cast<T>(*v);
        } else if constexpr (std::is_unsigned_v<T>) {
          const Result<uint64_t> v = ParseCliUnsigned(name, text, min, max);
          if (!v.ok()) throw CLI::ValidationError(v.status().message());
          value = static_cast<T>(*v);
        } else {
          const Result<int64_t> v = ParseCliInteger(name, text, min, max);
          if (!v.ok()) throw CLI::ValidationError(v.status().message());
          value = static_cast<T>(*v);
        }
      },
      description);
  option->type_name(std::is_floating_point_v<T> ? "REAL" : std::is_unsigned_v<T> ? "UINT" : "INT");
  if constexpr (std::is_floating_point_v<T>) {
    option->default_str(options_internal::FormatReal(static_cast<double>(value)));
  } else {
    option->default_str(std::to_string(value));
  }
  return option;
}

/// The largest value of T (for AddNumberOption's max).
template <typename T>
constexpr T MaxOf() {
  return std::numeric_limits<T>::max();
}

/// "--arrangement SPEC" bound to `value`: how a scene file's plant is arranged
/// (sim::ParseArrangement; checked when the scene is loaded).
CLI::Option* AddArrangementOption(CLI::App& cmd, std::string& value);

/// The flags of every command that loads a scene: --scenario, --scene, --arrangement, --seed.
struct SceneFlags {
  std::string scenario;
  std::string scene_file;
  std::string arrangement;
  uint64_t seed = 0;
  /// The scene they name (what sim::LoadScene reads).
  sim::SceneSource Source() const { return {scenario, scene_file, seed, arrangement}; }
};

/// `avp scenes`: the registered scenarios, one line each (also `--scenario help`,
/// `--scenarios help`). Returns 0.
int ListScenes(const sim::ScenarioRegistry& scenarios);

/// `help` where a name is expected (`--scenario help`, `--planner(s) help`, `--segmenter help`):
/// prints the scenario list or the planners' or segmenters' names and descriptions;
/// `help:NAME` (`--planner help:avp-nbv`) prints that one's description and options. True when it
/// printed (the command then ends: `*exit_code` is 0, or 2 for an unknown NAME).
bool PrintHelpForNames(const experiment::Registries& registries, std::string_view scenario,
                       std::string_view planner, std::string_view segmenter, int* exit_code);

/// Adds --scenario, --scene, --arrangement and --seed to `cmd`, bound to `flags`; `seed_doc`
/// says what the seed seeds; `scenario_names` are the scenario option's names (CLI11's
/// "--scenario,--scenarios" for an alias).
void AddSceneFlags(CLI::App& cmd, SceneFlags& flags, const std::string& seed_doc,
                   const std::string& scenario_names = "--scenario");

/// "--voxel-size M" bound to `value` (set to the map's default first): the map option
/// grid.voxel_size_m, whose default mapping::GridOptions holds (the one voxel size of every
/// command).
CLI::Option* AddVoxelSizeOption(CLI::App& cmd, double& value);

/// Logs each of the scene's warnings (sim::Scene::warnings) with spdlog::warn, for the commands
/// that load a scene.
void LogSceneWarnings(const sim::Scene& scene);

/// "--record-compression none|zstd|lz4" bound to `value` ("" for none), only with `record` (the
/// --record option or flag): how the MCAP recording's chunks are stored (docs/recording.md).
CLI::Option* AddRecordCompressionOption(CLI::App& cmd, std::string& value, CLI::Option* record);

/// Repeatable "--<name> KEY=VALUE" option bound to `values`.
CLI::Option* AddKeyValueOption(CLI::App& cmd, const std::string& name,
                               std::vector<std::string>& values, const std::string& description);

/// The registered components (planners or segmenters) for `--planner help` / `--segmenter help`:
/// one aligned line each, "name  description", and how to see one's options.
template <typename Entry>
std::string ListComponents(std::string_view what, std::string_view flag,
                           const std::vector<Entry>& entries) {
  size_t width = 0;
  for (const Entry& e : entries) width = std::max(width, e.name.size());
  std::string out = std::string(what) + ":\n";
  for (const Entry& e : entries) out += fmt::format("  {:<{}}  {}\n", e.name, width, e.description);
  out += fmt::format("`{} help:NAME` lists one's options with their defaults and ranges.\n", flag);
  return out;
}

/// One component for `--planner help:NAME`: its name, description and options (an unknown name is
/// named, with the nearest one). Returns the exit code (0, or 2 for an unknown name).
template <typename Entry>
int DescribeComponent(std::string_view what, std::string_view name,
                      const std::vector<Entry>& entries) {
  std::vector<std::string> names;
  for (const Entry& e : entries) {
    names.push_back(e.name);
    if (e.name != name) continue;
    std::string out = e.name + "  " + e.description + "\n";
    const std::vector<OptionInfo> info = e.options.Info();
    out += info.empty()
               ? "  (no options)\n"
               : "options (KEY=DEFAULT  [unit, range]  meaning):\n" + FormatOptionHelp(info, "  ");
    std::fputs(out.c_str(), stdout);
    return 0;
  }
  std::fprintf(stderr, "unknown %s %s (%s)%s\n", std::string(what).c_str(), QuoteText(name).c_str(),
               fmt::format("{}", fmt::join(names, ", ")).c_str(), DidYouMean(name, names).c_str());
  return 2;
}

}  // namespace avp::apps

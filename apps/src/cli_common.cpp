#include "cli_common.h"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <exception>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/core/error.h>
#include <avp/core/text.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::apps {

void RunGuarded(CommandContext& context, const std::function<int()>& command) {
  try {
    context.exit_code = command();
  } catch (const Error& e) {
    spdlog::error("{}", e.what());
    context.exit_code = 1;
  } catch (const std::exception& e) {
    spdlog::error("unexpected error: {}", e.what());
    context.exit_code = 2;
  }
}

int Failed(std::string_view command, const Status& status) {
  spdlog::error("{} failed: {}", command, status.ToString());
  return 1;
}

std::vector<std::string> SplitCommaList(std::string_view text) {
  return options_internal::SplitList(text);
}

Result<std::vector<std::string>> ParseCliList(std::string_view option, std::string_view text,
                                              size_t max_items) {
  std::vector<std::string> items;
  size_t start = 0;
  size_t index = 0;
  while (start <= text.size()) {
    size_t end = text.find(',', start);
    if (end == std::string_view::npos) end = text.size();
    std::string_view item = text.substr(start, end - start);
    while (!item.empty() && (item.front() == ' ' || item.front() == '\t')) item.remove_prefix(1);
    while (!item.empty() && (item.back() == ' ' || item.back() == '\t')) item.remove_suffix(1);
    ++index;
    if (item.empty()) {
      if (text.find_first_not_of(" \t") == std::string_view::npos) {
        return InvalidArgumentError(fmt::format(
            "{} {} is empty: give at least one item (leave the option out for the defaults)",
            option, QuoteText(text)));
      }
      return InvalidArgumentError(
          fmt::format("{} {}: item {} is empty", option, QuoteText(text), index));
    }
    if (items.size() == max_items) {
      return InvalidArgumentError(fmt::format("{} has more than {} items", option, max_items));
    }
    items.emplace_back(item);
    start = end + 1;
  }
  return items;
}

namespace {

Status NotInRange(std::string_view option, std::string_view text, std::string_view kind,
                  const std::string& min, const std::string& max) {
  return InvalidArgumentError(
      fmt::format("{} {} must be {} in [{}, {}]", option, QuoteText(text), kind, min, max));
}

}  // namespace

Result<uint64_t> ParseCliUnsigned(std::string_view option, std::string_view text, uint64_t min,
                                  uint64_t max) {
  const auto bad = [&] {
    return NotInRange(option, text, "a whole number", std::to_string(min), std::to_string(max));
  };
  if (text.empty() || text.find_first_not_of("0123456789") != std::string_view::npos) {
    return bad();
  }
  uint64_t v = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || ptr != text.data() + text.size() || v < min || v > max) return bad();
  return v;
}

Result<int64_t> ParseCliInteger(std::string_view option, std::string_view text, int64_t min,
                                int64_t max) {
  const auto bad = [&] {
    return NotInRange(option, text, "a whole number", std::to_string(min), std::to_string(max));
  };
  const std::string_view digits = !text.empty() && text.front() == '-' ? text.substr(1) : text;
  if (digits.empty() || digits.find_first_not_of("0123456789") != std::string_view::npos) {
    return bad();
  }
  int64_t v = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || ptr != text.data() + text.size() || v < min || v > max) return bad();
  return v;
}

Result<double> ParseCliReal(std::string_view option, std::string_view text, double min,
                            double max) {
  const auto bad = [&] {
    return NotInRange(option, text, "a number", options_internal::FormatReal(min),
                      options_internal::FormatReal(max));
  };
  // Decimal only: no leading space or '+', no hex floats, no inf or nan.
  if (text.empty() || text.size() > 400 ||
      text.find_first_not_of("0123456789.-eE") != std::string_view::npos) {
    return bad();
  }
  const std::string t(text);
  char* end = nullptr;
  const double v = std::strtod(t.c_str(), &end);
  // An underflow ("1e-320", ERANGE) is the nearest double; an overflow is infinite, refused.
  if (end != t.c_str() + t.size() || !std::isfinite(v) || v < min || v > max) {
    return bad();
  }
  return v;
}

CLI::Option* AddArrangementOption(CLI::App& cmd, std::string& value) {
  return cmd
      .add_option("--arrangement", value,
                  "How the scene file's plant is arranged: reference, full-occlusion, "
                  "single-cluster, unoriented-start, or KEY=VALUE items joined by '+' "
                  "(plant-x/y/z=M, plant-yaw=DEG, start-yaw=DEG, cluster-gap=M; "
                  "docs/scene-format.md, Arrangements)")
      ->type_name("SPEC");
}

void AddSceneFlags(CLI::App& cmd, SceneFlags& flags, const std::string& seed_doc,
                   const std::string& scenario_names) {
  cmd.add_option(
      scenario_names, flags.scenario,
      fmt::format("Built-in scenario (see `avp scenes`); default: {}", sim::DefaultScenarioName()));
  cmd.add_option("--scene", flags.scene_file,
                 "YAML scene file instead of a scenario (docs/scene-format.md)");
  AddArrangementOption(cmd, flags.arrangement);
  AddNumberOption(cmd, "--seed", flags.seed, uint64_t{0}, MaxOf<uint64_t>(), seed_doc);
}

CLI::Option* AddVoxelSizeOption(CLI::App& cmd, double& value) {
  value = mapping::GridOptions{}.voxel_size_m;
  return AddNumberOption(cmd, "--voxel-size", value, 0.0, 1e6,
                         "Voxel edge in metres (map option grid.voxel_size_m)");
}

void LogSceneWarnings(const sim::Scene& scene) {
  for (const std::string& w : scene.warnings) spdlog::warn("scene '{}': {}", scene.name, w);
}

CLI::Option* AddRecordCompressionOption(CLI::App& cmd, std::string& value, CLI::Option* record) {
  return cmd
      .add_option_function<std::string>(
          "--record-compression",
          [&value](const std::string& name) { value = name == "none" ? "" : name; },
          "How the recording's chunks are stored: none, zstd or lz4 (zstd: about 15 times "
          "smaller; every MCAP reader reads all three)")
      ->check(CLI::IsMember({"none", "zstd", "lz4"}))
      ->type_name("NAME")
      ->needs(record);
}

CLI::Option* AddKeyValueOption(CLI::App& cmd, const std::string& name,
                               std::vector<std::string>& values, const std::string& description) {
  return cmd.add_option(name, values, description)->type_name("KEY=VALUE");
}

}  // namespace avp::apps

// avp limits, `avp --limit NAME=VALUE ...` and AVP_LIMITS: the process-wide limits on what input
// controls (core/limits.h, docs/limits.md).
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/core/limits.h>
#include <avp/core/text.h>
#include <avp/experiment/bench.h>
#include <avp/io/file.h>
#include <avp/io/image_limits.h>
#include <avp/io/yaml.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/octomap_io.h>
#include <avp/segmentation/segmenter.h>
#include <avp/sim/scene_file.h>

#include "cli_common.h"
#include "limits_cli.h"

namespace avp::apps {

void RegisterKnownLimits() {
  // A limit registers itself when its accessor first runs: every accessor is called here, before
  // --limit and AVP_LIMITS are applied and before `avp limits` lists them. A new limit adds its
  // accessor to this list (docs/limits.md).
  (void)io::MaxFileBytes();
  (void)io::MaxImagePixels();
  (void)io::MaxYamlBytes();
  (void)io::MaxYamlDepth();
  (void)mapping::MaxMapBlocks();
  (void)mapping::MaxOctomapNodes();
  (void)segmentation::MaxPromptBytes();
  (void)segmentation::MaxPromptPhrases();
  (void)sim::MaxMeshVertices();
  (void)sim::MaxMeshFaces();
  (void)sim::MaxMeshFileBytes();
  (void)sim::MaxSceneTexturePixels();
  (void)experiment::MaxBenchEpisodes();
}

Status ApplyLimitsFromEnvironment() {
  const char* env = std::getenv("AVP_LIMITS");
  if (env == nullptr) return Status::Ok();
  const Status s = SetLimits(env);
  if (s.ok()) return s;
  return Status(s.code(), fmt::format("AVP_LIMITS={}: {}", QuoteText(env), s.message()));
}

std::string LimitsTable(const std::vector<LimitInfo>& limits) {
  size_t name_w = 5, value_w = 5, default_w = 7, unit_w = 4;
  for (const LimitInfo& l : limits) {
    name_w = std::max(name_w, l.name.size());
    value_w = std::max(value_w, std::to_string(l.value).size());
    default_w = std::max(default_w, std::to_string(l.default_value).size());
    unit_w = std::max(unit_w, l.unit.size());
  }
  std::string out = fmt::format("{:<{}}  {:>{}}  {:>{}}  {:<{}}  {}\n", "limit", name_w, "value",
                                value_w, "default", default_w, "unit", unit_w, "what it bounds");
  for (const LimitInfo& l : limits) {
    out += fmt::format("{:<{}}  {:>{}}  {:>{}}  {:<{}}  {}{}\n", l.name, name_w, l.value, value_w,
                       l.default_value, default_w, l.unit, unit_w, l.doc,
                       l.value != l.default_value ? " (changed)" : "");
  }
  return out;
}

void AddLimitOption(CLI::App& app) {
  app.add_option_function<std::vector<std::string>>(
         "--limit",
         [](const std::vector<std::string>& items) {
           for (const std::string& item : items) {
             if (item.find('=') == std::string::npos || item.find(',') != std::string::npos) {
               throw CLI::ValidationError(fmt::format(
                   "--limit {} must be one NAME=VALUE (e.g. --limit max_file_bytes=4294967296; "
                   "`avp limits` lists them)",
                   QuoteText(item)));
             }
             const Status s = SetLimits(item);
             if (!s.ok()) throw CLI::ValidationError("--limit: " + s.message());
           }
         },
         "Raise (or lower) a limit on what input controls, before the command runs (repeatable; "
         "`avp limits` lists them, AVP_LIMITS=NAME=VALUE,... sets them too)")
      ->type_name("NAME=VALUE")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
}

void AddLimitsCommand(CLI::App& app, CommandContext& context) {
  CLI::App* cmd = app.add_subcommand(
      "limits",
      "List the limits on what input controls (name, value, default, unit); raise one with "
      "`avp --limit NAME=VALUE <command>` or AVP_LIMITS (docs/limits.md)");
  cmd->callback([&context] {
    RunGuarded(context, [] {
      std::fputs(LimitsTable(RegisteredLimits()).c_str(), stdout);
      std::fputs(
          "\nRaise one for a command with `avp --limit NAME=VALUE <command> ...` (repeatable) or "
          "the environment AVP_LIMITS=NAME=VALUE,NAME=VALUE.\n",
          stdout);
      return 0;
    });
  });
}

}  // namespace avp::apps

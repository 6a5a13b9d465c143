// avp scenes: the registered scenarios, one line each.
#include <algorithm>
#include <cstdio>

#include <avp/experiment/registries.h>
#include <avp/sim/scenario.h>

#include "cli_common.h"

namespace avp::apps {

int ListScenes(const sim::ScenarioRegistry& scenarios) {
  size_t width = 0;
  for (const sim::ScenarioEntry& s : scenarios.entries()) width = std::max(width, s.name.size());
  std::printf("Built-in scenarios (default: %s):\n",
              std::string(sim::DefaultScenarioName()).c_str());
  for (const sim::ScenarioEntry& s : scenarios.entries()) {
    std::printf("  %-*s  %s\n", static_cast<int>(width), s.name.c_str(), s.description.c_str());
  }
  std::printf(
      "Any seed gives a different plant of the same kind: avp render --scenario NAME --seed N\n");
  return 0;
}

bool PrintHelpForNames(const experiment::Registries& registries, std::string_view scenario,
                       std::string_view planner, std::string_view segmenter, int* exit_code) {
  constexpr std::string_view kOne = "help:";
  *exit_code = 0;
  if (scenario == "help") {
    ListScenes(registries.scenarios);
  } else if (planner == "help") {
    std::fputs(ListComponents("planners", "--planner", registries.planners.entries()).c_str(),
               stdout);
  } else if (planner.starts_with(kOne)) {
    *exit_code =
        DescribeComponent("planner", planner.substr(kOne.size()), registries.planners.entries());
  } else if (segmenter == "help") {
    std::fputs(ListComponents("segmenters", "--segmenter", registries.segmenters.entries()).c_str(),
               stdout);
  } else if (segmenter.starts_with(kOne)) {
    *exit_code = DescribeComponent("segmenter", segmenter.substr(kOne.size()),
                                   registries.segmenters.entries());
  } else {
    return false;
  }
  return true;
}

void AddScenesCommand(CLI::App& app, CommandContext& context) {
  CLI::App* cmd =
      app.add_subcommand("scenes", "List the built-in scenarios with one-line descriptions");
  cmd->callback([&context] {
    RunGuarded(context, [&] { return ListScenes(context.registries->scenarios); });
  });
}

}  // namespace avp::apps

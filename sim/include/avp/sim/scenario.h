#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>
#include <avp/sim/scene.h>

namespace avp::sim {

/// A named, seeded scene generator mirroring one of the paper's experiments.
struct ScenarioInfo {
  std::string name;         ///< e.g. "tomato-full-occlusion"
  std::string description;  ///< one line, shown by `avp scenes`
};

/// Every built-in scenario, in a stable order. The first is the default.
const std::vector<ScenarioInfo>& ListScenarios();
/// The scenario used when none is named ("tomato-multiple-clusters").
std::string_view DefaultScenarioName();

/// Builds the scenario's scene for `seed`: the same (name, seed) gives an identical scene on any
/// machine, and different seeds give different plants of the same kind.
/// Errors: NotFound naming the unknown scenario and listing the known ones.
Result<Scene> MakeScenario(std::string_view name, uint64_t seed);

}  // namespace avp::sim

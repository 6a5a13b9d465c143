#include <fmt/format.h>

#include <avp/apps/scene_source.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>

namespace avp::apps {

Result<sim::Scene> LoadScene(const SceneSource& source) {
  if (!source.scenario.empty() && !source.scene_file.empty()) {
    return InvalidArgumentError(
        fmt::format("give either a scenario ('{}') or a scene file ('{}'), not both",
                    source.scenario, source.scene_file.string()));
  }
  if (!source.scene_file.empty()) return sim::LoadSceneFile(source.scene_file);
  const std::string name =
      source.scenario.empty() ? std::string(sim::DefaultScenarioName()) : source.scenario;
  return sim::MakeScenario(name, source.seed);
}

}  // namespace avp::apps

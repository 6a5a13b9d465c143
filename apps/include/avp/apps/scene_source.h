#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include <avp/core/status.h>
#include <avp/sim/scene.h>

namespace avp::apps {

/// Where a command's scene comes from: a built-in scenario (seeded) or a YAML scene file.
struct SceneSource {
  std::string scenario;              ///< empty: use scene_file, or the default scenario
  std::filesystem::path scene_file;  ///< a YAML scene (docs/scene-format.md)
  uint64_t seed = 0;
};

/// Builds the scene; errors name the bad scenario or file. Giving both is an error.
Result<sim::Scene> LoadScene(const SceneSource& source);

}  // namespace avp::apps

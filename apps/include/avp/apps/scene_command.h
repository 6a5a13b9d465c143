#pragma once

#include <filesystem>
#include <string>

#include <avp/core/status.h>
#include <avp/sim/scene.h>

namespace avp::apps {

/// `avp scene check FILE`: loads a scene file (sim::LoadSceneFile with its report) and describes
/// it: every part (name, file, class, the rule that gave it, colour and where the colour came
/// from, triangles, bounding-box size in mm, what became of it), per class the parts, colours and
/// instances, the fruit instances with their size and the fragments merged into them, the
/// fragments dropped, every class rule with the parts it classified, and the warnings.
/// `json`: the same as one JSON document. Errors: LoadSceneFile's (the file cannot be loaded).
Result<std::string> DescribeSceneFile(const std::filesystem::path& file, bool json);

/// Logs each of the scene's warnings (sim::Scene::warnings) with spdlog::warn, for the commands
/// that load a scene.
void LogSceneWarnings(const sim::Scene& scene);

}  // namespace avp::apps

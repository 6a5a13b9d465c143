#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene.h>

namespace avp::sim {

/// `avp scene check FILE`: loads a scene file (LoadSceneFile with its report) and describes
/// it: every part (name, file, class, the rule that gave it, colour and where the colour came
/// from, triangles, bounding-box size in mm, what became of it), per class the parts, colours and
/// instances, the fruit instances with their size and the fragments merged into them, the
/// fragments dropped, every class rule with the parts it classified, and the warnings.
/// `json`: the same as one JSON document. Errors: LoadSceneFile's (the file cannot be loaded).
Result<std::string> DescribeSceneFile(const std::filesystem::path& file, bool json);

/// avp scene export: the scene of `source` (a scenario, or a scene file with its arrangement baked
/// in) written by SaveSceneFiles into `out_dir` as <name>.yaml, .obj and .mtl; returns the YAML
/// file's path (the others are beside it, ExportedSceneFiles). Refuses an output folder that is
/// the input scene file, and (FailedPrecondition, naming it) a file of the three that is there
/// already unless `force`. `on_scene`, when given, sees the loaded scene (e.g. to print its
/// warnings).
Result<std::filesystem::path> ExportScene(const SceneSource& source,
                                          const ScenarioRegistry& scenarios,
                                          const std::filesystem::path& out_dir, bool force = false,
                                          const std::function<void(const Scene&)>& on_scene = {});

/// The files ExportScene writes for its YAML file `yaml`: it, and the .obj and .mtl beside it.
std::vector<std::filesystem::path> ExportedSceneFiles(const std::filesystem::path& yaml);

}  // namespace avp::sim

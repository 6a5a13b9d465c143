#pragma once

#include <filesystem>
#include <string_view>

#include <avp/core/status.h>
#include <avp/sim/scene.h>

/// Scenes from files: a versioned YAML file that places mesh files (OBJ, PLY, COLLADA, glTF 2 and
/// anything else assimp reads) in the world with semantic classes. The format is documented in
/// docs/scene-format.md; configs/scenes/example_plant.yaml is a complete example.
namespace avp::sim {

/// The scene file version this build reads and writes.
inline constexpr int kSceneFileVersion = 1;

/// Loads a scene file. Mesh paths are relative to the YAML file. Node hierarchies are traversed
/// with their transforms; COLLADA units are applied; each node's mesh becomes one SceneObject
/// (fruit meshes optionally split into connected components, one fruit instance each).
/// Errors (each naming the file, the YAML path and the bad value): NotFound for a missing YAML or
/// mesh file (with its resolved path); ParseError for malformed YAML (line and column) or a mesh
/// assimp cannot import (assimp's message); InvalidArgument for an unknown key, an unsupported
/// version, an unknown class name or any other bad value.
Result<Scene> LoadSceneFile(const std::filesystem::path& yaml);

/// Writes `scene` as `<dir>/<name>.yaml` + `<dir>/<name>.obj` + `<dir>/<name>.mtl` (name: the
/// scene name made file-safe, "scene" if empty) that LoadSceneFile reads back: one OBJ object per
/// SceneObject named "<class>__<instance id>__<name>" with its albedo as material, ellipsoids
/// tessellated (icosphere, 1280 triangles, vertices on the surface), world coordinates, and the
/// start configuration. Creates `dir` if needed.
/// Errors: IoError naming the path that could not be written; InvalidArgument if the scene fails
/// Scene::Validate().
Status SaveSceneFiles(const Scene& scene, const std::filesystem::path& dir);

/// Shell-style glob: '*' matches any run of characters (including none), '?' one character,
/// everything else itself (case-sensitive). Used for the class rules of scene files.
bool GlobMatch(std::string_view pattern, std::string_view text);

}  // namespace avp::sim

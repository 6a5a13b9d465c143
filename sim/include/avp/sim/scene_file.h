#pragma once

#include <filesystem>
#include <string_view>

#include <avp/core/limits.h>
#include <avp/core/status.h>
#include <avp/sim/scene.h>

/// Scenes from files: a versioned YAML file that places mesh files (OBJ, PLY, COLLADA, glTF 2 and
/// anything else assimp reads) in the world with semantic classes. The format is documented in
/// docs/scene-format.md; configs/scenes/example_plant.yaml is a complete example.
namespace avp::sim {

/// The scene file version this build reads and writes.
inline constexpr int kSceneFileVersion = 1;

/// Budgets of scene files (docs/limits.md), checked before assimp reads a mesh (the file's size, a
/// PLY header's element counts) and after (what it read), per mesh file and for all meshes of a
/// scene together: max_mesh_vertices (2^24), max_mesh_faces (2^25), max_mesh_file_bytes (1 GiB).
const Limit& MaxMeshVertices();
const Limit& MaxMeshFaces();
const Limit& MaxMeshFileBytes();

/// Loads a scene file. Mesh paths are relative to the YAML file. Node hierarchies are traversed
/// with their transforms; COLLADA units are applied; each node's mesh becomes one SceneObject
/// (fruit meshes optionally split into connected components, one fruit instance each).
/// Errors (each naming the file, the YAML path and the bad value): NotFound for a missing YAML or
/// mesh file (with its resolved path); ParseError for malformed YAML (line and column) or a mesh
/// assimp cannot import (assimp's message and what it logged, escaped), a PLY header whose counts
/// the file cannot hold, non-finite vertices; ResourceExhausted for a YAML file over
/// max_yaml_bytes / max_yaml_depth, a mesh over the limits above, or more than 65535 objects;
/// InvalidArgument for an unknown key, an unsupported version, an unknown class name or any
/// other bad value. Text from the files is shown escaped and shortened (QuoteText).
Result<Scene> LoadSceneFile(const std::filesystem::path& yaml);

/// Writes `scene` as `<dir>/<name>.yaml` + `<dir>/<name>.obj` + `<dir>/<name>.mtl` (name: the
/// scene name made file-safe, "scene" if empty) that LoadSceneFile reads back: one OBJ object per
/// SceneObject named "<class>__<instance id>__<name>" with its albedo as material, ellipsoids
/// tessellated (icosphere, 1280 triangles, vertices on the surface), world coordinates, and the
/// start configuration. Creates `dir` if needed.
/// Each file is written atomically (io::WriteFileAtomic: a temporary name, flushed, renamed), the
/// YAML last, so a killed export never leaves a scene file that names a half-written mesh.
/// Errors: IoError naming the path that could not be written; InvalidArgument if the scene fails
/// Scene::Validate().
Status SaveSceneFiles(const Scene& scene, const std::filesystem::path& dir);

/// Shell-style glob: '*' matches any run of characters (including none), '?' one character,
/// everything else itself (case-sensitive). Used for the class rules of scene files.
bool GlobMatch(std::string_view pattern, std::string_view text);

}  // namespace avp::sim

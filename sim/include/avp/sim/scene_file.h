#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

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
/// Texture pixels one mesh file keeps decoded, over all its images ("max_scene_texture_pixels",
/// 256 Mi by default, ~768 MB of RGB); each image is also bounded by io::MaxImagePixels(). An
/// image past it is not used (a warning names it; its parts keep their material colour).
const Limit& MaxSceneTexturePixels();

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

/// Where a part's colour came from (docs/scene-format.md, "Colours and materials"), first that
/// applies: its class rule's `color`, its mesh entry's `color`, the material's texture, the
/// material's diffuse colour, the class default; kPlaceholder: the material's colour was a
/// placeholder
/// (`materials: auto`) and the class default replaced it.
enum class ColorSource : uint8_t {
  kRule,
  kEntry,
  kTexture,
  kMaterial,
  kClassDefault,
  kPlaceholder,
};
/// "rule", "entry", "texture", "material", "class default", "placeholder replaced".
std::string_view ToString(ColorSource source);

/// One (node, mesh) pair of a mesh file, as the loader classified it.
struct ScenePartReport {
  std::string name;       ///< "<file stem>/<node>[/<mesh>]"
  size_t mesh_entry = 0;  ///< index in `meshes`
  std::string file;       ///< the mesh file as given in the YAML
  std::string material;   ///< the material's name ("" when it has none)
  SemanticClass semantic_class = SemanticClass::kOther;
  /// Index of the class rule that gave the class, -1: the entry's default_class.
  int rule = -1;
  std::string rule_match;                           ///< that rule's `match` ("" for default_class)
  Eigen::Vector3f color = Eigen::Vector3f::Zero();  ///< linear RGB
  ColorSource color_source = ColorSource::kClassDefault;
  /// The material's own colour when color_source is kPlaceholder (what was replaced).
  Eigen::Vector3f material_color = Eigen::Vector3f::Zero();
  size_t vertices = 0;
  size_t triangles = 0;
  Box3 bounds;  ///< world frame, metres
  /// What became of it: "object", "merged into <name> (merge[i])", "merged into <name> (small,
  /// D mm away)", "dropped (small)", "dropped (small, no fruit within R mm)"; a part split into
  /// components has one entry per component, "<name>#k: <what became of it>".
  std::vector<std::string> fate;
};

/// One class rule of one mesh entry and the parts it gave their class (first matching rule wins).
struct SceneRuleReport {
  size_t mesh_entry = 0;
  size_t index = 0;
  std::string match;
  SemanticClass semantic_class = SemanticClass::kOther;
  size_t parts = 0;     ///< parts this rule classified
  size_t shadowed = 0;  ///< parts it matches that an earlier rule took
};

/// A fragment joined to a fruit or dropped.
struct SceneFragmentReport {
  std::string name;
  std::string into;    ///< the fruit it joined ("" when dropped)
  std::string reason;  ///< "merge[0] 'Fruit*_calyx'", "small", "small, no fruit within reach"
  size_t vertices = 0;
  double volume_cm3 = 0.0;  ///< bounding-box volume
  double gap_mm = 0.0;      ///< distance between its bounding box and the fruit's (merged)
};

/// One fruit instance of the loaded scene (a SceneObject of class fruit).
struct SceneFruitReport {
  uint16_t instance_id = 0;
  std::string name;
  size_t vertices = 0;
  size_t triangles = 0;
  Box3 bounds;                      ///< world frame, metres
  double volume_cm3 = 0.0;          ///< bounding-box volume
  std::vector<std::string> merged;  ///< names of the fragments it holds besides its own mesh
};

/// What LoadSceneFile found: every part with its class, rule, colour and its colour's source;
/// every rule with its counts; the fruit instances with what was merged into them; the fragments
/// merged and dropped; the warnings (as Scene::warnings).
struct SceneFileReport {
  std::vector<ScenePartReport> parts;
  std::vector<SceneRuleReport> rules;
  std::vector<SceneFruitReport> fruits;
  std::vector<SceneFragmentReport> fragments;
  std::vector<std::string> warnings;
};

/// As above, and fills `report` (when not null) with what was loaded and why.
Result<Scene> LoadSceneFile(const std::filesystem::path& yaml, SceneFileReport* report);

/// The linear-RGB saturation below which a material colour counts as achromatic (grey, white,
/// black) for the placeholder test of `materials: auto`: (max - min) / max < 0.1, or max < 0.01.
inline constexpr float kAchromaticSaturation = 0.1f;
bool IsAchromatic(const Eigen::Vector3f& rgb);

/// Default colour of a class (linear RGB) when no rule, entry, texture or material gives one.
Eigen::Vector3f DefaultClassColor(SemanticClass semantic_class);

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

/// GlobMatch that also returns the text each '*' matched, in pattern order (each '*' takes the
/// shortest text that lets the rest match). False (captures cleared) when it does not match.
bool GlobCapture(std::string_view pattern, std::string_view text,
                 std::vector<std::string>* captures);

}  // namespace avp::sim

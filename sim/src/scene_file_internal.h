#pragma once

// Private to sim/: what the translation units of the scene-file loader share. LoadSceneFile
// (scene_file.cpp) reads a scene file in named stages, one concept per file:
//   scene_schema.cpp     the YAML: the scene's settings and each mesh entry, checked
//   mesh_checks.cpp      a mesh file's declared counts (PLY header, OBJ/STL lines) before assimp
//   mesh_import.cpp      a mesh file through assimp into parts (class, colour, world mesh)
//   scene_colors.cpp     placeholder material colours and the warnings about the whole scene
//   scene_fragments.cpp  parts into pieces: merge rules, fruit components, small fragments
//   scene_file_save.cpp  SaveSceneFiles (OBJ + MTL + YAML)
// docs/scene-format.md describes the format.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <yaml-cpp/yaml.h>

#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/sim/scene.h>
#include <avp/sim/scene_file.h>

namespace avp::sim::internal {

enum class UpAxis { kAuto, kY, kZ };
enum class FruitInstances { kObjects, kComponents };
/// `materials:` use: material colours (and textures) win over class defaults; ignore: class
/// defaults; auto: as use, except placeholder colours (docs/scene-format.md).
enum class MaterialMode { kAuto, kUse, kIgnore };
enum class SmallParts { kMerge, kDrop };

/// `merge: [{match: "Fruit*_calyx", into: "Fruit*"}]`: a part whose node or mesh name matches
/// `match` joins the part named `into`, with each '*' of `into` replaced by what the
/// corresponding '*' of `match` matched.
struct MergeRule {
  std::string match;
  std::string into;
};

struct ClassRule {
  std::string pattern;
  SemanticClass semantic_class = SemanticClass::kOther;
  std::optional<Eigen::Vector3f> color;
};

struct MeshEntry {
  std::filesystem::path file;  // resolved
  std::string file_text;
  RigidTransform X_WM;
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
  UpAxis up_axis = UpAxis::kAuto;
  SemanticClass default_class = SemanticClass::kOther;
  std::optional<Eigen::Vector3f> color;
  FruitInstances fruit_instances = FruitInstances::kObjects;
  std::vector<ClassRule> rules;
  MaterialMode materials = MaterialMode::kAuto;
  /// A fruit instance whose bounding box is under this volume, or that has fewer vertices, is a
  /// fragment: it joins its nearest fruit within fruit_merge_reach_mm (merge) or is dropped.
  double fruit_min_volume_cm3 = 0.0;
  int64_t fruit_min_vertices = 0;
  SmallParts fruit_small_parts = SmallParts::kMerge;
  double fruit_merge_reach_mm = 10.0;
  std::vector<MergeRule> merge;
};

/// Everything one mesh file contributes, before it is added to the scene.
struct ImportedPart {
  std::string name;
  std::string node_name;
  std::string mesh_name;
  std::string material;  // the material's name, "" when none
  SemanticClass semantic_class = SemanticClass::kOther;
  int rule = -1;  // the class rule that gave the class, -1: default_class
  Eigen::Vector3f albedo;
  ColorSource color_source = ColorSource::kClassDefault;
  Eigen::Vector3f material_color = Eigen::Vector3f::Zero();  // when kPlaceholder
  TriangleMesh mesh;
};

/// One future scene object of a mesh entry: a part, or one connected component of a fruit part.
struct Piece {
  TriangleMesh mesh;
  size_t part = 0;
  std::string name;
  std::vector<std::string> merged;  // fragments joined to it
  std::string fate = "object";
  bool removed = false;  // merged into another piece or dropped
};

// --- scene_schema.cpp -------------------------------------------------------------------------

/// The scene file's top level but its meshes: the keys and version checked, then name,
/// description, start joints and camera, and the ground plane. `file`: the YAML's file name (the
/// errors' context); `yaml`: its path (the default name is its stem).
Result<Scene> ReadSceneSettings(const YAML::Node& root, const std::filesystem::path& yaml);

/// One entry of `meshes:`, every key checked; `file` resolved against `base_dir` and present.
Result<MeshEntry> ReadMeshEntry(const YAML::Node& node, const std::filesystem::path& base_dir,
                                const std::string& context);

// --- mesh_checks.cpp --------------------------------------------------------------------------

/// A PLY file's header, read and checked before assimp sees the file: every element's count
/// against what the rest of the file can hold (each element needs at least its fixed-size
/// properties and list counts in a binary file, two characters per property in an ASCII one), the
/// vertex count against max_mesh_vertices and the face count against max_mesh_faces. A header
/// that declares 10^9 vertices in a small file is refused here instead of making assimp reserve
/// for them.
Status CheckPlyHeader(const std::filesystem::path& file, uint64_t file_bytes,
                      const std::string& context);

/// OBJ and STL files declare no counts: before assimp reads one, its vertex and face lines are
/// counted in one streaming pass (OBJ "v" and "f" lines, ASCII STL "facet" lines; a binary STL's
/// triangle count against the file's size), and checked against max_mesh_vertices /
/// max_mesh_faces, so a file of 100 million short lines is refused before assimp holds them.
Status CheckObjOrStlCounts(const std::filesystem::path& file, uint64_t file_bytes,
                           const std::string& ext, const std::string& context);

// --- mesh_import.cpp --------------------------------------------------------------------------

/// The parts of one mesh entry's file (its size and declared counts checked first), each with
/// its class, colour and mesh in the world frame. Texture warnings are appended to `warnings`.
Result<std::vector<ImportedPart>> ImportMesh(const MeshEntry& entry, const std::string& context,
                                             std::vector<std::string>& warnings);

// --- scene_colors.cpp -------------------------------------------------------------------------

/// "[r, g, b]" with three significant digits.
std::string FormatColor(const Eigen::Vector3f& c);

/// Equal within half an 8-bit step.
bool SameColor(const Eigen::Vector3f& a, const Eigen::Vector3f& b);

/// Up to three names quoted, then "and N more".
std::string NameList(const std::vector<std::string>& names);

/// `materials: auto`: an achromatic material colour shared by every part of a chromatic class
/// whose colour comes from its material is a placeholder; those parts get the class default.
void ReplacePlaceholderColors(const MeshEntry& entry, const std::string& context,
                              std::vector<ImportedPart>& parts, std::vector<std::string>& warnings);

/// Warnings about the loaded scene as a whole: no fruit; classes a colour segmenter cannot tell
/// apart (every part of one class has a colour another class has too); a one-colour plant.
void SceneWarnings(const Scene& scene, std::vector<std::string>& warnings);

// --- scene_fragments.cpp ----------------------------------------------------------------------

/// The future scene objects of one mesh entry's parts: `merge` rules applied, fruit parts split
/// into components (`fruit_instances: components`), fruit fragments under the size rule merged or
/// dropped (marked `removed`). Records fragments, warnings and each part's fate in `rep`, whose
/// part reports for `parts` start at `first_report`.
std::vector<Piece> FormPieces(const MeshEntry& entry, const std::string& context,
                              std::vector<ImportedPart>& parts, size_t first_report,
                              SceneFileReport& rep);

/// The bounding box's volume in cm³.
double VolumeCm3(const Box3& box);

}  // namespace avp::sim::internal

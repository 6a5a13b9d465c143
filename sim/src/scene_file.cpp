// The scene file's public surface (sim/scene_file.h): its limits, class colours, glob patterns,
// and LoadSceneFile, which reads a scene in named stages (scene_file_internal.h lists the files
// that hold them).

#include <algorithm>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <avp/core/semantic_class.h>
#include <avp/core/text.h>
#include <avp/io/yaml.h>
#include <avp/sim/scene_file.h>

#include "scene_file_internal.h"

namespace avp::sim {

const Limit& MaxMeshVertices() {
  static const Limit limit("max_mesh_vertices", uint64_t{1} << 24, "vertices",
                           "vertices of one mesh file of a scene, and of all of them together");
  return limit;
}

const Limit& MaxMeshFaces() {
  static const Limit limit("max_mesh_faces", uint64_t{1} << 25, "faces",
                           "faces of one mesh file of a scene, and triangles of all of them");
  return limit;
}

const Limit& MaxMeshFileBytes() {
  static const Limit limit("max_mesh_file_bytes", uint64_t{1} << 30, "bytes",
                           "size of one mesh file of a scene");
  return limit;
}

const Limit& MaxSceneTexturePixels() {
  static const Limit limit("max_scene_texture_pixels", uint64_t{256} << 20, "pixels",
                           "texture pixels one mesh file of a scene keeps decoded, all images");
  return limit;
}

namespace {

namespace fs = std::filesystem;

// Registered when the program starts, so `avp --limit NAME=N` knows them before a scene is read.
[[maybe_unused]] const Limit& kRegisterMaxMeshVertices = MaxMeshVertices();
[[maybe_unused]] const Limit& kRegisterMaxMeshFaces = MaxMeshFaces();
[[maybe_unused]] const Limit& kRegisterMaxMeshFileBytes = MaxMeshFileBytes();

}  // namespace

Eigen::Vector3f DefaultClassColor(SemanticClass c) {
  switch (c) {
    case SemanticClass::kFruit:
      return {0.55f, 0.05f, 0.03f};
    case SemanticClass::kLeaf:
      return {0.08f, 0.25f, 0.05f};
    case SemanticClass::kStem:
      return {0.16f, 0.30f, 0.07f};
    case SemanticClass::kSupport:
      return {0.33f, 0.22f, 0.11f};
    case SemanticClass::kGround:
      return {0.15f, 0.10f, 0.065f};
    default:
      return {0.5f, 0.5f, 0.5f};
  }
}

bool IsAchromatic(const Eigen::Vector3f& rgb) {
  const float hi = rgb.maxCoeff();
  const float lo = rgb.minCoeff();
  return hi < 0.01f || (hi - lo) < kAchromaticSaturation * hi;
}

std::string_view ToString(ColorSource source) {
  switch (source) {
    case ColorSource::kRule:
      return "rule";
    case ColorSource::kEntry:
      return "entry";
    case ColorSource::kTexture:
      return "texture";
    case ColorSource::kMaterial:
      return "material";
    case ColorSource::kClassDefault:
      return "class default";
    case ColorSource::kPlaceholder:
      return "placeholder replaced";
  }
  return "?";
}

bool GlobMatch(std::string_view pattern, std::string_view text) {
  // Iterative matcher with single-star backtracking: O(|pattern| * |text|) worst case.
  size_t p = 0;
  size_t t = 0;
  size_t star = std::string_view::npos;
  size_t star_t = 0;
  while (t < text.size()) {
    if (p < pattern.size() && (pattern[p] == '?' || pattern[p] == text[t])) {
      ++p;
      ++t;
    } else if (p < pattern.size() && pattern[p] == '*') {
      star = p++;
      star_t = t;
    } else if (star != std::string_view::npos) {
      p = star + 1;
      t = ++star_t;
    } else {
      return false;
    }
  }
  while (p < pattern.size() && pattern[p] == '*') ++p;
  return p == pattern.size();
}

bool GlobCapture(std::string_view pattern, std::string_view text,
                 std::vector<std::string>* captures) {
  // Depth-first search, each '*' trying the shortest text first, with the (pattern, text)
  // positions known to fail remembered: O(|pattern| * |text|^2) time at worst, recursion depth
  // at most |pattern|.
  const size_t np = pattern.size();
  const size_t nt = text.size();
  std::vector<char> failed((np + 1) * (nt + 1), 0);
  std::vector<std::pair<size_t, size_t>> spans;
  const auto match = [&](const auto& self, size_t p, size_t t) -> bool {
    char& known_bad = failed[p * (nt + 1) + t];
    if (known_bad != 0) return false;
    bool ok = false;
    if (p == np) {
      ok = t == nt;
    } else if (pattern[p] == '*') {
      for (size_t k = t; k <= nt && !ok; ++k) {
        spans.emplace_back(t, k);
        ok = self(self, p + 1, k);
        if (!ok) spans.pop_back();
      }
    } else if (t < nt && (pattern[p] == '?' || pattern[p] == text[t])) {
      ok = self(self, p + 1, t + 1);
    }
    if (!ok) known_bad = 1;
    return ok;
  };
  const bool ok = match(match, 0, 0);
  if (captures != nullptr) {
    captures->clear();
    if (ok) {
      for (const auto& [a, b] : spans) captures->emplace_back(text.substr(a, b - a));
    }
  }
  return ok;
}

namespace {

using internal::ImportedPart;
using internal::MeshEntry;
using internal::Piece;

/// Running totals of the scene's meshes: the limits hold for all of them together, too.
struct MeshTotals {
  uint64_t vertices = 0;
  uint64_t triangles = 0;
};

Status CheckSceneTotals(const std::vector<ImportedPart>& parts, const std::string& context,
                        MeshTotals& totals) {
  for (const ImportedPart& part : parts) {
    totals.vertices += part.mesh.vertices.size();
    totals.triangles += part.mesh.triangles.size();
  }
  AVP_RETURN_IF_ERROR(MaxMeshVertices().Check(
      fmt::format("{}: vertices of the scene's meshes up to this one", context), totals.vertices));
  AVP_RETURN_IF_ERROR(MaxMeshFaces().Check(
      fmt::format("{}: triangles of the scene's meshes up to this one", context),
      totals.triangles));
  return Status::Ok();
}

/// Rules: how many parts each classified, and how many it matches that an earlier one took; a
/// warning for each rule that classifies nothing.
void ReportRules(const MeshEntry& entry, size_t index, const std::string& context,
                 const std::vector<ImportedPart>& parts, SceneFileReport& rep) {
  for (size_t r = 0; r < entry.rules.size(); ++r) {
    SceneRuleReport rule_report;
    rule_report.mesh_entry = index;
    rule_report.index = r;
    rule_report.match = entry.rules[r].pattern;
    rule_report.semantic_class = entry.rules[r].semantic_class;
    for (const ImportedPart& part : parts) {
      if (part.rule == static_cast<int>(r)) {
        ++rule_report.parts;
      } else if (part.rule >= 0 && part.rule < static_cast<int>(r) &&
                 (GlobMatch(rule_report.match, part.node_name) ||
                  GlobMatch(rule_report.match, part.mesh_name) ||
                  (!part.material.empty() && GlobMatch(rule_report.match, part.material)))) {
        ++rule_report.shadowed;
      }
    }
    if (rule_report.parts == 0) {
      rep.warnings.push_back(fmt::format(
          "{}.classes[{}]: rule {} (class {}) classifies no part of {} ({} parts; node, mesh "
          "and material names are tested){}",
          context, r, QuoteText(rule_report.match, 80), ToString(rule_report.semantic_class),
          QuoteText(entry.file_text, 80), parts.size(),
          rule_report.shadowed > 0
              ? fmt::format("; it matches {} parts an earlier rule took", rule_report.shadowed)
              : std::string()));
    }
    rep.rules.push_back(std::move(rule_report));
  }
}

/// One report per part (fates are filled in by FormPieces).
void ReportParts(const MeshEntry& entry, size_t index, const std::vector<ImportedPart>& parts,
                 std::vector<ScenePartReport>& reports) {
  for (const ImportedPart& part : parts) {
    ScenePartReport pr;
    pr.name = part.name;
    pr.mesh_entry = index;
    pr.file = entry.file_text;
    pr.material = part.material;
    pr.semantic_class = part.semantic_class;
    pr.rule = part.rule;
    if (part.rule >= 0) pr.rule_match = entry.rules[static_cast<size_t>(part.rule)].pattern;
    pr.color = part.albedo;
    pr.color_source = part.color_source;
    pr.material_color = part.material_color;
    pr.vertices = part.mesh.vertices.size();
    pr.triangles = part.mesh.triangles.size();
    pr.bounds = part.mesh.Bounds();
    reports.push_back(std::move(pr));
  }
}

/// The pieces not removed as scene objects, with a report for each fruit. Instance ids are
/// 16-bit: a scene holds at most 65535 objects (a mesh split into components could otherwise ask
/// for millions).
Status AddPieces(const MeshEntry& entry, const std::string& context,
                 const std::vector<ImportedPart>& parts, std::vector<Piece>& pieces,
                 uint16_t& last_id, Scene& scene, std::vector<SceneFruitReport>& fruits) {
  size_t kept = 0;
  for (const Piece& piece : pieces) kept += piece.removed ? 0 : 1;
  constexpr size_t kMaxObjects = std::numeric_limits<uint16_t>::max();
  if (last_id + kept > kMaxObjects) {
    return ResourceExhaustedError(fmt::format(
        "{}: mesh '{}' adds {} objects to the {} of the scene; a scene holds at most {} "
        "(instance ids are 16-bit)",
        context, entry.file.string(), kept, scene.objects.size(), kMaxObjects));
  }
  for (Piece& piece : pieces) {
    if (piece.removed) continue;
    const ImportedPart& part = parts[piece.part];
    SceneObject object;
    object.name = piece.name;
    object.semantic_class = part.semantic_class;
    object.albedo = part.albedo;
    object.shape = std::move(piece.mesh);
    // Scene::Add's id (the largest + 1) without its scan over every object: linear time for
    // a mesh split into tens of thousands of fruits.
    object.instance_id = ++last_id;
    if (object.semantic_class == SemanticClass::kFruit) {
      const TriangleMesh& mesh = std::get<TriangleMesh>(object.shape);
      SceneFruitReport fruit;
      fruit.instance_id = object.instance_id;
      fruit.name = object.name;
      fruit.vertices = mesh.vertices.size();
      fruit.triangles = mesh.triangles.size();
      fruit.bounds = mesh.Bounds();
      fruit.volume_cm3 = internal::VolumeCm3(fruit.bounds);
      fruit.merged = std::move(piece.merged);
      fruits.push_back(std::move(fruit));
    }
    scene.objects.push_back(std::move(object));
  }
  return Status::Ok();
}

/// Mesh entry `index`: read, imported, checked, coloured, reported, split into pieces and added
/// to the scene.
Status AddMeshEntry(const YAML::Node& node, size_t index, const fs::path& base_dir,
                    const std::string& context, MeshTotals& totals, uint16_t& last_id, Scene& scene,
                    SceneFileReport& rep) {
  AVP_ASSIGN_OR_RETURN(const MeshEntry entry, internal::ReadMeshEntry(node, base_dir, context));
  AVP_ASSIGN_OR_RETURN(std::vector<ImportedPart> parts,
                       internal::ImportMesh(entry, context, rep.warnings));
  AVP_RETURN_IF_ERROR(CheckSceneTotals(parts, context, totals));
  internal::ReplacePlaceholderColors(entry, context, parts, rep.warnings);
  ReportRules(entry, index, context, parts, rep);
  const size_t first_report = rep.parts.size();
  ReportParts(entry, index, parts, rep.parts);
  std::vector<Piece> pieces = internal::FormPieces(entry, context, parts, first_report, rep);
  return AddPieces(entry, context, parts, pieces, last_id, scene, rep.fruits);
}

}  // namespace

Result<Scene> LoadSceneFile(const fs::path& yaml) { return LoadSceneFile(yaml, nullptr); }

Result<Scene> LoadSceneFile(const fs::path& yaml, SceneFileReport* report) {
  SceneFileReport local_report;
  SceneFileReport& rep = report != nullptr ? *report : local_report;
  rep = SceneFileReport();
  AVP_ASSIGN_OR_RETURN(const YAML::Node root, io::LoadYamlFile(yaml));
  AVP_ASSIGN_OR_RETURN(Scene scene, internal::ReadSceneSettings(root, yaml));
  const std::string file = yaml.filename().string();
  const YAML::Node meshes = root["meshes"];
  if (!meshes.IsDefined() || !meshes.IsSequence() || meshes.size() == 0) {
    return InvalidArgumentError(
        fmt::format("{}: 'meshes' must be a non-empty list of mesh entries", file));
  }
  const fs::path base_dir = yaml.parent_path();
  MeshTotals totals;
  uint16_t last_id = 0;
  for (const SceneObject& o : scene.objects) last_id = std::max(last_id, o.instance_id);
  for (size_t i = 0; i < meshes.size(); ++i) {
    const std::string context = fmt::format("{}: meshes[{}]", file, i);
    AVP_RETURN_IF_ERROR(AddMeshEntry(meshes[i], i, base_dir, context, totals, last_id, scene, rep));
  }
  internal::SceneWarnings(scene, rep.warnings);
  scene.warnings = rep.warnings;
  AVP_RETURN_IF_ERROR(scene.Validate().WithContext(file));
  scene.UpdatePlantBounds();
  return scene;
}

}  // namespace avp::sim

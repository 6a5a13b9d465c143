// The scene file's YAML (docs/scene-format.md): the scene's settings and each mesh entry, every
// key checked and every bad value named. LoadSceneFile (scene_file.cpp) builds the scene from
// what these stages return.

#include <cerrno>
#include <cmath>
#include <initializer_list>
#include <iterator>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <yaml-cpp/yaml.h>

#include <avp/core/semantic_class.h>
#include <avp/core/text.h>
#include <avp/io/yaml.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>

#include "scene_file_internal.h"

namespace avp::sim::internal {

namespace {

namespace fs = std::filesystem;

std::string KnownClasses() {
  std::vector<std::string> names;
  for (const SemanticClass c : AllSemanticClasses()) names.emplace_back(ToString(c));
  return fmt::format("{}", fmt::join(names, ", "));
}

Result<SemanticClass> ReadClass(const YAML::Node& node, std::string_view key,
                                std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const std::string name, io::ReadString(node, key, context));
  const std::optional<SemanticClass> c = SemanticClassFromString(name);
  if (!c) {
    return InvalidArgumentError(fmt::format("{}.{}: unknown semantic class {} (known: {})", context,
                                            key, QuoteText(name), KnownClasses()));
  }
  return *c;
}

Result<Eigen::Vector3f> ReadColor(const YAML::Node& node, std::string_view key,
                                  std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd v, io::ReadVector(node, key, 3, context));
  if ((v.array() < 0.0).any() || (v.array() > 1.0).any()) {
    return InvalidArgumentError(
        fmt::format("{}.{}: colour [{}, {}, {}] must be linear RGB with every value in [0, 1]",
                    context, key, v[0], v[1], v[2]));
  }
  return Eigen::Vector3f(v.cast<float>());
}

/// A string key with a few allowed values: "{context}.{key}: must be 'a', 'b' or 'c', got 'x'".
template <typename E>
Result<E> ReadChoice(const YAML::Node& node, std::string_view key, const std::string& context,
                     std::initializer_list<std::pair<std::string_view, E>> choices) {
  AVP_ASSIGN_OR_RETURN(const std::string value, io::ReadString(node, key, context));
  std::string allowed;
  size_t k = 0;
  for (const auto& [name, choice] : choices) {
    if (value == name) return choice;
    if (k > 0) allowed += k + 1 == choices.size() ? " or " : ", ";
    allowed += fmt::format("'{}'", name);
    ++k;
  }
  return InvalidArgumentError(
      fmt::format("{}.{}: must be {}, got {}", context, key, allowed, QuoteText(value)));
}

/// A finite number >= 0.
Result<double> ReadNonNegative(const YAML::Node& node, std::string_view key,
                               const std::string& context) {
  AVP_ASSIGN_OR_RETURN(const double value, io::ReadDouble(node, key, context));
  if (!std::isfinite(value) || value < 0.0) {
    return InvalidArgumentError(fmt::format("{}.{}: must be >= 0, got {}", context, key, value));
  }
  return value;
}

/// `file:` resolved against the scene file's directory; the file must exist.
Result<fs::path> ResolveMeshFile(const std::string& file_text, const fs::path& base_dir,
                                 const std::string& context) {
  const fs::path file(file_text);
  const fs::path resolved = file.is_absolute() ? file : base_dir / file;
  std::error_code ec;
  if (fs::is_regular_file(resolved, ec)) return resolved;
  // What is there instead, in the user's words: a folder, a device, a link loop, nothing.
  const std::string shown = EscapeText(resolved.lexically_normal().string(), 300);
  const fs::file_status link = fs::symlink_status(resolved, ec);
  const fs::file_status target = fs::status(resolved, ec);
  std::string what = "does not exist";
  if (ec.value() == ELOOP) {
    what = "is a symbolic link that loops (no file at its end)";
  } else if (fs::is_directory(target)) {
    what = "is a folder, not a mesh file";
  } else if (fs::exists(target)) {
    what = "is not a regular file (a device, pipe or socket)";
  } else if (fs::is_symlink(link)) {
    what = "is a symbolic link to nothing";
  }
  const std::string message = fmt::format("{}.file: mesh file '{}' {} (given as {})", context,
                                          shown, what, QuoteText(file_text));
  if (fs::exists(target) || ec.value() == ELOOP) return InvalidArgumentError(message);
  return NotFoundError(message);
}

/// `scale:` one number or [x, y, z], each > 0.
Result<Eigen::Vector3d> ReadScale(const YAML::Node& node, const std::string& context) {
  Eigen::Vector3d scale;
  if (node["scale"].IsSequence()) {
    AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd s, io::ReadVector(node, "scale", 3, context));
    scale = s;
  } else {
    AVP_ASSIGN_OR_RETURN(const double s, io::ReadDouble(node, "scale", context));
    scale = Eigen::Vector3d::Constant(s);
  }
  if ((scale.array() <= 0.0).any()) {
    return InvalidArgumentError(fmt::format("{}.scale: [{}, {}, {}] must be > 0", context,
                                            scale.x(), scale.y(), scale.z()));
  }
  return scale;
}

/// `classes: [{match, class, color}]`.
Result<std::vector<ClassRule>> ReadClassRules(const YAML::Node& classes,
                                              const std::string& context) {
  if (!classes.IsSequence()) {
    return InvalidArgumentError(
        fmt::format("{}.classes: must be a list of {{match, class, color}} rules", context));
  }
  std::vector<ClassRule> rules;
  for (size_t i = 0; i < classes.size(); ++i) {
    const std::string rule_context = fmt::format("{}.classes[{}]", context, i);
    const YAML::Node r = classes[i];
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(r, {"match", "class", "color"}, rule_context));
    ClassRule rule;
    AVP_ASSIGN_OR_RETURN(rule.pattern, io::ReadString(r, "match", rule_context));
    AVP_ASSIGN_OR_RETURN(rule.semantic_class, ReadClass(r, "class", rule_context));
    if (r["color"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(rule.color, ReadColor(r, "color", rule_context));
    }
    rules.push_back(std::move(rule));
  }
  return rules;
}

/// `merge: [{match, into}]`, each pattern non-empty and at most 256 characters.
Result<std::vector<MergeRule>> ReadMergeRules(const YAML::Node& merge, const std::string& context) {
  if (!merge.IsSequence()) {
    return InvalidArgumentError(
        fmt::format("{}.merge: must be a list of {{match, into}} rules", context));
  }
  std::vector<MergeRule> rules;
  for (size_t i = 0; i < merge.size(); ++i) {
    const std::string rule_context = fmt::format("{}.merge[{}]", context, i);
    const YAML::Node r = merge[i];
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(r, {"match", "into"}, rule_context));
    MergeRule rule;
    AVP_ASSIGN_OR_RETURN(rule.match, io::ReadString(r, "match", rule_context));
    AVP_ASSIGN_OR_RETURN(rule.into, io::ReadString(r, "into", rule_context));
    if (rule.match.size() > 256 || rule.into.size() > 256) {
      return InvalidArgumentError(
          fmt::format("{}: 'match' and 'into' hold at most 256 characters (got {} and {})",
                      rule_context, rule.match.size(), rule.into.size()));
    }
    if (rule.match.empty() || rule.into.empty()) {
      return InvalidArgumentError(
          fmt::format("{}: 'match' and 'into' must not be empty (got {} and {})", rule_context,
                      QuoteText(rule.match), QuoteText(rule.into)));
    }
    rules.push_back(std::move(rule));
  }
  return rules;
}

/// The fruit size rule: fruit_min_volume_cm3, fruit_min_vertices, fruit_small_parts and
/// fruit_merge_reach_mm, each when given.
Status ReadFruitSizeRule(const YAML::Node& node, const std::string& context, MeshEntry& entry) {
  if (node["fruit_min_volume_cm3"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.fruit_min_volume_cm3,
                         ReadNonNegative(node, "fruit_min_volume_cm3", context));
  }
  if (node["fruit_min_vertices"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.fruit_min_vertices,
                         io::ReadInt(node, "fruit_min_vertices", context));
    if (entry.fruit_min_vertices < 0) {
      return InvalidArgumentError(fmt::format("{}.fruit_min_vertices: must be >= 0, got {}",
                                              context, entry.fruit_min_vertices));
    }
  }
  if (node["fruit_small_parts"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(
        entry.fruit_small_parts,
        ReadChoice<SmallParts>(node, "fruit_small_parts", context,
                               {{"merge", SmallParts::kMerge}, {"drop", SmallParts::kDrop}}));
  }
  if (node["fruit_merge_reach_mm"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.fruit_merge_reach_mm,
                         ReadNonNegative(node, "fruit_merge_reach_mm", context));
  }
  return Status::Ok();
}

/// The top level's keys, its form (a map) and its version.
Status CheckSceneFileTop(const YAML::Node& root, const std::string& file) {
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(
      root,
      {"version", "name", "description", "start_joints_deg", "start_camera", "ground", "meshes"},
      file));
  if (!root.IsMap()) {
    return InvalidArgumentError(fmt::format("{}: a scene file must be a YAML map", file));
  }
  AVP_ASSIGN_OR_RETURN(const int64_t version, io::ReadInt(root, "version", file));
  if (version != kSceneFileVersion) {
    return InvalidArgumentError(fmt::format("{}: unsupported scene file version {} (supported: {})",
                                            file, version, kSceneFileVersion));
  }
  return Status::Ok();
}

Result<RigidTransform> ReadStartCamera(const YAML::Node& node, const std::string& context) {
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(node, {"eye", "target", "up"}, context));
  AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd eye, io::ReadVector(node, "eye", 3, context));
  AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd target, io::ReadVector(node, "target", 3, context));
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  if (node["up"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd u, io::ReadVector(node, "up", 3, context));
    up = u;
  }
  const Eigen::Vector3d forward = target - eye;
  if (forward.norm() < 1e-6 || forward.normalized().cross(up).norm() < 1e-6) {
    return InvalidArgumentError(fmt::format(
        "{}: eye [{}, {}, {}] and target [{}, {}, {}] must differ and the view must not be "
        "parallel to up [{}, {}, {}]",
        context, eye[0], eye[1], eye[2], target[0], target[1], target[2], up[0], up[1], up[2]));
  }
  return RigidTransform::LookAt(eye, target, up);
}

struct StartPose {
  std::vector<double> joints_rad;
  RigidTransform X_WC;
};

/// Start configuration: joints default to the reference start; the camera defaults to the
/// reference camera for the reference joints (any joint-1 yaw) and must be given otherwise.
Result<StartPose> ReadStartPose(const YAML::Node& root, const std::string& file) {
  StartPose start;
  std::vector<double> joints_deg(std::begin(kReferenceStartJointsDeg),
                                 std::end(kReferenceStartJointsDeg));
  if (root["start_joints_deg"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(joints_deg, io::ReadDoubles(root, "start_joints_deg", file));
    if (joints_deg.empty()) {
      return InvalidArgumentError(fmt::format("{}: 'start_joints_deg' must not be empty", file));
    }
  }
  for (const double deg : joints_deg) start.joints_rad.push_back(DegToRad(deg));
  if (root["start_camera"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(start.X_WC,
                         ReadStartCamera(root["start_camera"], file + ": start_camera"));
  } else {
    bool reference = joints_deg.size() == 6;
    for (size_t i = 1; reference && i < 6; ++i) {
      reference = std::abs(joints_deg[i] - kReferenceStartJointsDeg[i]) < 1e-9;
    }
    if (!reference) {
      return InvalidArgumentError(fmt::format(
          "{}: 'start_camera' (eye, target) is required when start_joints_deg [{}] differs from "
          "the reference start [{}] in joints 2-6",
          file, fmt::join(joints_deg, ", "), fmt::join(kReferenceStartJointsDeg, ", ")));
    }
    start.X_WC = ReferenceStartCameraPose(joints_deg[0]);
  }
  return start;
}

struct GroundSpec {
  bool on = false;
  double z_m = 0.0;
  std::optional<Eigen::Vector3f> color;
};

/// Ground: `ground: true`, or a map {z_m, color}; absent or false: none.
Result<GroundSpec> ReadGround(const YAML::Node& root, const std::string& file) {
  GroundSpec spec;
  const YAML::Node ground = root["ground"];
  if (!ground.IsDefined() || ground.IsNull()) return spec;
  spec.on = true;
  if (ground.IsScalar()) {
    AVP_ASSIGN_OR_RETURN(spec.on, io::ReadBool(root, "ground", file));
  } else {
    const std::string context = file + ": ground";
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(ground, {"z_m", "color"}, context));
    if (ground["z_m"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(spec.z_m, io::ReadDouble(ground, "z_m", context));
    }
    if (ground["color"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(spec.color, ReadColor(ground, "color", context));
    }
  }
  return spec;
}

}  // namespace

Result<Scene> ReadSceneSettings(const YAML::Node& root, const fs::path& yaml) {
  const std::string file = yaml.filename().string();
  AVP_RETURN_IF_ERROR(CheckSceneFileTop(root, file));
  Scene scene;
  scene.name = yaml.stem().string();
  if (root["name"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(scene.name, io::ReadString(root, "name", file));
  }
  if (root["description"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(scene.description, io::ReadString(root, "description", file));
  }
  AVP_ASSIGN_OR_RETURN(StartPose start, ReadStartPose(root, file));
  scene.start_joints_rad = std::move(start.joints_rad);
  scene.X_WC_start = start.X_WC;
  AVP_ASSIGN_OR_RETURN(const GroundSpec ground, ReadGround(root, file));
  if (ground.on) {
    AddGroundPlane(scene, ground.z_m);
    if (ground.color) scene.objects.back().albedo = *ground.color;
  }
  return scene;
}

Result<MeshEntry> ReadMeshEntry(const YAML::Node& node, const fs::path& base_dir,
                                const std::string& context) {
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(
      node,
      {"file", "pose", "scale", "up_axis", "default_class", "color", "fruit_instances", "classes",
       "materials", "fruit_min_volume_cm3", "fruit_min_vertices", "fruit_small_parts",
       "fruit_merge_reach_mm", "merge"},
      context));
  MeshEntry entry;
  AVP_ASSIGN_OR_RETURN(entry.file_text, io::ReadString(node, "file", context));
  AVP_ASSIGN_OR_RETURN(entry.file, ResolveMeshFile(entry.file_text, base_dir, context));
  if (node["pose"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.X_WM, io::ReadPose(node, "pose", context));
  }
  if (node["scale"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.scale, ReadScale(node, context));
  }
  if (node["up_axis"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.up_axis, ReadChoice<UpAxis>(node, "up_axis", context,
                                                           {{"y", UpAxis::kY}, {"z", UpAxis::kZ}}));
  }
  if (node["default_class"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.default_class, ReadClass(node, "default_class", context));
  }
  if (node["color"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.color, ReadColor(node, "color", context));
  }
  if (node["fruit_instances"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.fruit_instances,
                         ReadChoice<FruitInstances>(node, "fruit_instances", context,
                                                    {{"objects", FruitInstances::kObjects},
                                                     {"components", FruitInstances::kComponents}}));
  }
  if (const YAML::Node classes = node["classes"]; classes.IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.rules, ReadClassRules(classes, context));
  }
  if (node["materials"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.materials,
                         ReadChoice<MaterialMode>(node, "materials", context,
                                                  {{"auto", MaterialMode::kAuto},
                                                   {"use", MaterialMode::kUse},
                                                   {"ignore", MaterialMode::kIgnore}}));
  }
  AVP_RETURN_IF_ERROR(ReadFruitSizeRule(node, context, entry));
  if (const YAML::Node merge = node["merge"]; merge.IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.merge, ReadMergeRules(merge, context));
  }
  return entry;
}

}  // namespace avp::sim::internal

// `avp scene check FILE`: what a scene file's loader made of it (parts, classes, colours and
// where they came from, fruit instances, merged and dropped fragments, rules, warnings); `avp scene
// export`.
#include <algorithm>
#include <functional>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <avp/core/semantic_class.h>
#include <avp/io/file.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>
#include <avp/sim/scene_report.h>

namespace avp::sim {

namespace {

namespace fs = std::filesystem;

std::string Color(const Eigen::Vector3f& c) {
  return fmt::format("[{:.3f}, {:.3f}, {:.3f}]", c.x(), c.y(), c.z());
}

std::string SizeMm(const Box3& box) {
  const Eigen::Vector3d s = box.size() * 1000.0;
  return fmt::format("{:.1f} x {:.1f} x {:.1f} mm", s.x(), s.y(), s.z());
}

nlohmann::json Json(const Eigen::Vector3f& c) { return {c.x(), c.y(), c.z()}; }
nlohmann::json Json(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
nlohmann::json Json(const Box3& box) {
  return {{"min_m", Json(box.min())},
          {"max_m", Json(box.max())},
          {"size_mm", Json(Eigen::Vector3d(box.size() * 1000.0))}};
}

/// Per class: parts (from the report), instances (scene objects), colours with their part counts.
struct ClassSummary {
  size_t parts = 0;
  size_t instances = 0;
  std::vector<std::pair<Eigen::Vector3f, size_t>> colors;  // distinct colours of its objects
};

std::map<SemanticClass, ClassSummary> Summarize(const Scene& scene, const SceneFileReport& report) {
  std::map<SemanticClass, ClassSummary> out;
  for (const ScenePartReport& p : report.parts) ++out[p.semantic_class].parts;
  for (const SceneObject& o : scene.objects) {
    ClassSummary& s = out[o.semantic_class];
    ++s.instances;
    auto it = std::find_if(s.colors.begin(), s.colors.end(), [&](const auto& c) {
      return (c.first - o.albedo).cwiseAbs().maxCoeff() <= 0.5f / 255.0f;
    });
    if (it == s.colors.end()) {
      s.colors.emplace_back(o.albedo, 1);
    } else {
      ++it->second;
    }
  }
  return out;
}

std::string RuleText(const ScenePartReport& p) {
  return p.rule < 0 ? std::string("default_class")
                    : fmt::format("classes[{}] '{}'", p.rule, p.rule_match);
}

std::string ColorSourceText(const ScenePartReport& p) {
  std::string out(ToString(p.color_source));
  if (p.color_source == ColorSource::kPlaceholder) {
    out += fmt::format(": material '{}' {}", p.material, Color(p.material_color));
  } else if (p.color_source == ColorSource::kMaterial) {
    out += fmt::format(" '{}'", p.material);
  }
  return out;
}

std::string Text(const fs::path& file, const Scene& scene, const SceneFileReport& report) {
  std::string out;
  auto line = [&out](const std::string& text) {
    out += text;
    out += '\n';
  };
  size_t triangles = 0;
  for (const SceneObject& o : scene.objects) triangles += o.num_triangles();
  line(fmt::format("scene file {}: '{}', {} objects, {} triangles", file.string(), scene.name,
                   scene.objects.size(), triangles));
  if (!scene.plant_bounds.IsEmpty()) {
    line(fmt::format("plant bounds {} .. {} m ({})", Color(scene.plant_bounds.min().cast<float>()),
                     Color(scene.plant_bounds.max().cast<float>()), SizeMm(scene.plant_bounds)));
  }
  line("");
  line(fmt::format("parts ({}):", report.parts.size()));
  for (const ScenePartReport& p : report.parts) {
    line(fmt::format("  {}  [meshes[{}] {}]", p.name, p.mesh_entry, p.file));
    line(fmt::format("      class {} by {}; colour {} from {}", ToString(p.semantic_class),
                     RuleText(p), Color(p.color), ColorSourceText(p)));
    // A part split into many components: the first few, then a count (--json lists all).
    std::string fate;
    constexpr size_t kShown = 4;
    for (size_t k = 0; k < p.fate.size() && k < kShown; ++k) {
      fate += (fate.empty() ? "" : "; ") + p.fate[k];
    }
    if (p.fate.size() > kShown) {
      fate = fmt::format("{} components: {}; ... and {} more", p.fate.size(), fate,
                         p.fate.size() - kShown);
    }
    line(fmt::format("      {} triangles, {} vertices, {}; {}", p.triangles, p.vertices,
                     SizeMm(p.bounds), fate));
  }
  line("");
  line("classes:");
  for (const auto& [c, s] : Summarize(scene, report)) {
    std::vector<std::string> colors;
    for (const auto& [rgb, n] : s.colors) colors.push_back(fmt::format("{} x{}", Color(rgb), n));
    line(fmt::format("  {:<10} {} parts, {} instances; colours {}", ToString(c), s.parts,
                     s.instances, fmt::join(colors, ", ")));
  }
  line("");
  line(fmt::format("rules ({}):", report.rules.size()));
  for (const SceneRuleReport& r : report.rules) {
    line(fmt::format("  meshes[{}].classes[{}] '{}' -> {}: {} parts{}", r.mesh_entry, r.index,
                     r.match, ToString(r.semantic_class), r.parts,
                     r.shadowed > 0 ? fmt::format(" ({} more taken by earlier rules)", r.shadowed)
                                    : std::string()));
  }
  line("");
  line(fmt::format("fruit instances ({}):", report.fruits.size()));
  for (const SceneFruitReport& f : report.fruits) {
    std::string merged;
    if (!f.merged.empty()) {
      merged = fmt::format("; holds {} fragments: {}", f.merged.size(), fmt::join(f.merged, ", "));
    }
    const Eigen::Vector3d c = f.bounds.center();
    line(
        fmt::format("  #{} {}  centre [{:.3f}, {:.3f}, {:.3f}] m, {}, box {:.2f} cm3, {} "
                    "triangles{}",
                    f.instance_id, f.name, c.x(), c.y(), c.z(), SizeMm(f.bounds), f.volume_cm3,
                    f.triangles, merged));
  }
  size_t merged = 0, dropped = 0;
  for (const SceneFragmentReport& f : report.fragments) (f.into.empty() ? dropped : merged)++;
  line("");
  line(fmt::format("fragments: {} merged, {} dropped", merged, dropped));
  for (const SceneFragmentReport& f : report.fragments) {
    line(fmt::format(
        "  {} ({} vertices, box {:.3f} cm3): {} ({})", f.name, f.vertices, f.volume_cm3,
        f.into.empty() ? std::string("dropped")
                       : fmt::format("merged into {}, {:.1f} mm away", f.into, f.gap_mm),
        f.reason));
  }
  line("");
  line(fmt::format("warnings ({}):", report.warnings.size()));
  for (const std::string& w : report.warnings) line("  " + w);
  return out;
}

nlohmann::json ToJson(const fs::path& file, const Scene& scene, const SceneFileReport& report) {
  nlohmann::json j;
  j["file"] = file.string();
  j["name"] = scene.name;
  j["objects"] = scene.objects.size();
  j["triangles"] = scene.num_triangles();
  j["plant_bounds"] = Json(scene.plant_bounds);
  nlohmann::json parts = nlohmann::json::array();
  for (const ScenePartReport& p : report.parts) {
    nlohmann::json part = {{"name", p.name},
                           {"mesh_entry", p.mesh_entry},
                           {"file", p.file},
                           {"material", p.material},
                           {"class", ToString(p.semantic_class)},
                           {"rule", p.rule},
                           {"rule_match", p.rule_match},
                           {"color", Json(p.color)},
                           {"color_source", ToString(p.color_source)},
                           {"vertices", p.vertices},
                           {"triangles", p.triangles},
                           {"bounds", Json(p.bounds)},
                           {"fate", p.fate}};
    if (p.color_source == ColorSource::kPlaceholder) {
      part["material_color"] = Json(p.material_color);
    }
    parts.push_back(std::move(part));
  }
  j["parts"] = std::move(parts);
  nlohmann::json classes = nlohmann::json::object();
  for (const auto& [c, s] : Summarize(scene, report)) {
    nlohmann::json colors = nlohmann::json::array();
    for (const auto& [rgb, n] : s.colors) colors.push_back({{"color", Json(rgb)}, {"objects", n}});
    classes[std::string(ToString(c))] = {
        {"parts", s.parts}, {"instances", s.instances}, {"colors", std::move(colors)}};
  }
  j["classes"] = std::move(classes);
  nlohmann::json rules = nlohmann::json::array();
  for (const SceneRuleReport& r : report.rules) {
    rules.push_back({{"mesh_entry", r.mesh_entry},
                     {"index", r.index},
                     {"match", r.match},
                     {"class", ToString(r.semantic_class)},
                     {"parts", r.parts},
                     {"shadowed", r.shadowed}});
  }
  j["rules"] = std::move(rules);
  nlohmann::json fruits = nlohmann::json::array();
  for (const SceneFruitReport& f : report.fruits) {
    fruits.push_back({{"instance_id", f.instance_id},
                      {"name", f.name},
                      {"vertices", f.vertices},
                      {"triangles", f.triangles},
                      {"bounds", Json(f.bounds)},
                      {"volume_cm3", f.volume_cm3},
                      {"merged", f.merged}});
  }
  j["fruits"] = std::move(fruits);
  nlohmann::json fragments = nlohmann::json::array();
  for (const SceneFragmentReport& f : report.fragments) {
    fragments.push_back({{"name", f.name},
                         {"into", f.into},
                         {"dropped", f.into.empty()},
                         {"reason", f.reason},
                         {"vertices", f.vertices},
                         {"volume_cm3", f.volume_cm3},
                         {"gap_mm", f.gap_mm}});
  }
  j["fragments"] = std::move(fragments);
  j["warnings"] = report.warnings;
  return j;
}

}  // namespace

Result<std::string> DescribeSceneFile(const fs::path& file, bool json) {
  SceneFileReport report;
  AVP_ASSIGN_OR_RETURN(const Scene scene, LoadSceneFile(file, &report));
  if (json) return ToJson(file, scene, report).dump(2) + "\n";
  return Text(file, scene, report);
}

std::vector<fs::path> ExportedSceneFiles(const fs::path& yaml) {
  fs::path obj = yaml, mtl = yaml;
  return {yaml, obj.replace_extension(".obj"), mtl.replace_extension(".mtl")};
}

Result<fs::path> ExportScene(const SceneSource& source, const ScenarioRegistry& scenarios,
                             const fs::path& out_dir, bool force,
                             const std::function<void(const Scene&)>& on_scene) {
  if (out_dir.empty()) return InvalidArgumentError("the output folder (--out) is empty");
  if (!source.scene_file.empty()) {
    AVP_RETURN_IF_ERROR(
        io::CheckOutputIsNotInput(out_dir, "scene export folder", source.scene_file, "scene file"));
  }
  AVP_ASSIGN_OR_RETURN(Scene scene, LoadScene(source, scenarios));
  if (on_scene) on_scene(scene);
  // The arrangement is baked into the exported geometry; the file is named without '@'.
  std::replace(scene.name.begin(), scene.name.end(), '@', '-');
  const fs::path yaml = out_dir / (scene.name + ".yaml");
  for (const fs::path& f : ExportedSceneFiles(yaml)) {
    std::error_code ec;
    if (!force && fs::exists(fs::symlink_status(f, ec))) {
      return FailedPreconditionError(fmt::format(
          "output file '{}' already exists: give another --out, or --force to replace the "
          "exported scene",
          f.string()));
    }
  }
  AVP_RETURN_IF_ERROR(SaveSceneFiles(scene, out_dir));
  return yaml;
}

}  // namespace avp::sim

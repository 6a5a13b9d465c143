// avp scene check FILE: what a scene file's loader made of it (parts, classes, colours and where
// they came from, fruit instances, merged and dropped fragments, rules, warnings).
#include <algorithm>
#include <cstdio>
#include <iterator>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <avp/apps/scene_command.h>
#include <avp/core/semantic_class.h>
#include <avp/io/file.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>

#include "cli_common.h"

namespace avp::apps {

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

std::map<SemanticClass, ClassSummary> Summarize(const sim::Scene& scene,
                                                const sim::SceneFileReport& report) {
  std::map<SemanticClass, ClassSummary> out;
  for (const sim::ScenePartReport& p : report.parts) ++out[p.semantic_class].parts;
  for (const sim::SceneObject& o : scene.objects) {
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

std::string RuleText(const sim::ScenePartReport& p) {
  return p.rule < 0 ? std::string("default_class")
                    : fmt::format("classes[{}] '{}'", p.rule, p.rule_match);
}

std::string ColorSourceText(const sim::ScenePartReport& p) {
  std::string out(sim::ToString(p.color_source));
  if (p.color_source == sim::ColorSource::kPlaceholder) {
    out += fmt::format(": material '{}' {}", p.material, Color(p.material_color));
  } else if (p.color_source == sim::ColorSource::kMaterial) {
    out += fmt::format(" '{}'", p.material);
  }
  return out;
}

std::string Text(const fs::path& file, const sim::Scene& scene,
                 const sim::SceneFileReport& report) {
  std::string out;
  auto line = [&out](const std::string& text) {
    out += text;
    out += '\n';
  };
  size_t triangles = 0;
  for (const sim::SceneObject& o : scene.objects) triangles += o.num_triangles();
  line(fmt::format("scene file {}: '{}', {} objects, {} triangles", file.string(), scene.name,
                   scene.objects.size(), triangles));
  if (!scene.plant_bounds.IsEmpty()) {
    line(fmt::format("plant bounds {} .. {} m ({})", Color(scene.plant_bounds.min().cast<float>()),
                     Color(scene.plant_bounds.max().cast<float>()), SizeMm(scene.plant_bounds)));
  }
  line("");
  line(fmt::format("parts ({}):", report.parts.size()));
  for (const sim::ScenePartReport& p : report.parts) {
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
  for (const sim::SceneRuleReport& r : report.rules) {
    line(fmt::format("  meshes[{}].classes[{}] '{}' -> {}: {} parts{}", r.mesh_entry, r.index,
                     r.match, ToString(r.semantic_class), r.parts,
                     r.shadowed > 0 ? fmt::format(" ({} more taken by earlier rules)", r.shadowed)
                                    : std::string()));
  }
  line("");
  line(fmt::format("fruit instances ({}):", report.fruits.size()));
  for (const sim::SceneFruitReport& f : report.fruits) {
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
  for (const sim::SceneFragmentReport& f : report.fragments) (f.into.empty() ? dropped : merged)++;
  line("");
  line(fmt::format("fragments: {} merged, {} dropped", merged, dropped));
  for (const sim::SceneFragmentReport& f : report.fragments) {
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

nlohmann::json ToJson(const fs::path& file, const sim::Scene& scene,
                      const sim::SceneFileReport& report) {
  nlohmann::json j;
  j["file"] = file.string();
  j["name"] = scene.name;
  j["objects"] = scene.objects.size();
  j["triangles"] = scene.num_triangles();
  j["plant_bounds"] = Json(scene.plant_bounds);
  nlohmann::json parts = nlohmann::json::array();
  for (const sim::ScenePartReport& p : report.parts) {
    nlohmann::json part = {{"name", p.name},
                           {"mesh_entry", p.mesh_entry},
                           {"file", p.file},
                           {"material", p.material},
                           {"class", ToString(p.semantic_class)},
                           {"rule", p.rule},
                           {"rule_match", p.rule_match},
                           {"color", Json(p.color)},
                           {"color_source", sim::ToString(p.color_source)},
                           {"vertices", p.vertices},
                           {"triangles", p.triangles},
                           {"bounds", Json(p.bounds)},
                           {"fate", p.fate}};
    if (p.color_source == sim::ColorSource::kPlaceholder) {
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
  for (const sim::SceneRuleReport& r : report.rules) {
    rules.push_back({{"mesh_entry", r.mesh_entry},
                     {"index", r.index},
                     {"match", r.match},
                     {"class", ToString(r.semantic_class)},
                     {"parts", r.parts},
                     {"shadowed", r.shadowed}});
  }
  j["rules"] = std::move(rules);
  nlohmann::json fruits = nlohmann::json::array();
  for (const sim::SceneFruitReport& f : report.fruits) {
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
  for (const sim::SceneFragmentReport& f : report.fragments) {
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
  sim::SceneFileReport report;
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene, sim::LoadSceneFile(file, &report));
  if (json) return ToJson(file, scene, report).dump(2) + "\n";
  return Text(file, scene, report);
}

void LogSceneWarnings(const sim::Scene& scene) {
  for (const std::string& w : scene.warnings) spdlog::warn("scene '{}': {}", scene.name, w);
}

Result<fs::path> ExportScene(const sim::SceneSource& source, const sim::ScenarioRegistry& scenarios,
                             const fs::path& out_dir) {
  if (out_dir.empty()) return InvalidArgumentError("the output folder (--out) is empty");
  if (!source.scene_file.empty()) {
    AVP_RETURN_IF_ERROR(
        io::CheckOutputIsNotInput(out_dir, "scene export folder", source.scene_file, "scene file"));
  }
  AVP_ASSIGN_OR_RETURN(sim::Scene scene, sim::LoadScene(source, scenarios));
  LogSceneWarnings(scene);
  // The arrangement is baked into the exported geometry; the file is named without '@'.
  std::replace(scene.name.begin(), scene.name.end(), '@', '-');
  AVP_RETURN_IF_ERROR(sim::SaveSceneFiles(scene, out_dir));
  return out_dir / (scene.name + ".yaml");
}

void AddSceneCommand(CLI::App& app, CommandContext& context) {
  CLI::App* scene_cmd =
      app.add_subcommand("scene", "Scene files: check what a scene file's loader makes of it");
  scene_cmd->require_subcommand(1);
  struct Cli {
    std::string file;
    bool json = false;
  };
  auto cli = std::make_shared<Cli>();
  CLI::App* cmd = scene_cmd->add_subcommand(
      "check",
      "Load a scene file and print every part (class, rule, colour and its source, size), the "
      "classes, fruit instances, merged and dropped fragments, rules and warnings; exit code 0 "
      "when it loads (warnings are not errors)");
  cmd->add_option("file", cli->file, "Scene file (YAML, docs/scene-format.md)")->required();
  cmd->add_flag("--json", cli->json, "Print one JSON document instead of text");
  cmd->callback([&context, cli] {
    RunGuarded(context, [&] {
      const Result<std::string> text = DescribeSceneFile(cli->file, cli->json);
      if (!text.ok()) return Failed("scene check", text.status());
      std::fwrite(text->data(), 1, text->size(), stdout);
      return 0;
    });
  });

  struct ExportCli {
    sim::SceneSource source;
    std::string scene_file, out;
  };
  auto ex = std::make_shared<ExportCli>();
  CLI::App* export_cmd = scene_cmd->add_subcommand(
      "export",
      "Write a scenario (or an arranged scene file) as a scene file: <name>.yaml + .obj + .mtl in "
      "world coordinates, one OBJ object per part (open it in a modelling tool, edit it, load it "
      "back with --scene)");
  export_cmd->add_option("--scenario", ex->source.scenario,
                         "Built-in scenario name (see `avp scenes`); default: " +
                             std::string(sim::DefaultScenarioName()));
  export_cmd->add_option("--scene", ex->scene_file, "YAML scene file (docs/scene-format.md)");
  AddArrangementOption(*export_cmd, ex->source.arrangement);
  AddNumberOption(*export_cmd, "--seed", ex->source.seed, uint64_t{0}, MaxOf<uint64_t>(),
                  "Seed of the procedural plant");
  export_cmd->add_option("--out", ex->out, "Output folder")->required();
  export_cmd->callback([&context, ex] {
    RunGuarded(context, [&] {
      sim::SceneSource source = ex->source;
      source.scene_file = ex->scene_file;
      const Result<fs::path> yaml = ExportScene(source, context.registries->scenarios, ex->out);
      if (!yaml.ok()) return Failed("scene export", yaml.status());
      std::printf("wrote %s\n", yaml->string().c_str());
      return 0;
    });
  });
}

}  // namespace avp::apps

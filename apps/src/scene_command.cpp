// avp scene check FILE and avp scene export: the command line of sim's scene report
// (sim/scene_report.h).
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include <avp/sim/scene_report.h>

#include "cli_common.h"

namespace avp::apps {

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
      const Result<std::string> text = sim::DescribeSceneFile(cli->file, cli->json);
      if (!text.ok()) return Failed("scene check", text.status());
      std::fwrite(text->data(), 1, text->size(), stdout);
      return 0;
    });
  });

  struct ExportCli {
    SceneFlags scene;
    std::string out;
    bool force = false;
  };
  auto ex = std::make_shared<ExportCli>();
  CLI::App* export_cmd = scene_cmd->add_subcommand(
      "export",
      "Write a scenario (or an arranged scene file) as a scene file: <name>.yaml + .obj + .mtl in "
      "world coordinates, one OBJ object per part (open it in a modelling tool, edit it, load it "
      "back with --scene)");
  AddSceneFlags(*export_cmd, ex->scene, "Seed of the procedural plant");
  export_cmd->add_option("--out", ex->out, "Output folder")->required();
  export_cmd->add_flag("--force", ex->force, "Replace the files an earlier export left in --out");
  export_cmd->callback([&context, ex] {
    RunGuarded(context, [&] {
      const Result<std::filesystem::path> yaml = sim::ExportScene(
          ex->scene.Source(), context.registries->scenarios, ex->out, ex->force, LogSceneWarnings);
      if (!yaml.ok()) return Failed("scene export", yaml.status());
      const std::vector<std::filesystem::path> files = sim::ExportedSceneFiles(*yaml);
      std::printf("wrote %zu files to %s:\n", files.size(), ex->out.c_str());
      for (const std::filesystem::path& f : files) std::printf("  %s\n", f.string().c_str());
      return 0;
    });
  });
}

}  // namespace avp::apps

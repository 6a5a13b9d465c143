// The `avp` command line. Subcommands: scenes, render (run, bench, map, serve come later).
#include <cstdio>
#include <iostream>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <avp/apps/render_command.h>
#include <avp/core/error.h>
#include <avp/sim/scenario.h>

namespace {

int RunScenes() {
  const auto& scenarios = avp::sim::ListScenarios();
  size_t width = 0;
  for (const auto& s : scenarios) width = std::max(width, s.name.size());
  std::printf("Built-in scenarios (default: %s):\n",
              std::string(avp::sim::DefaultScenarioName()).c_str());
  for (const auto& s : scenarios) {
    std::printf("  %-*s  %s\n", static_cast<int>(width), s.name.c_str(), s.description.c_str());
  }
  std::printf(
      "Any seed gives a different plant of the same kind: avp render --scenario NAME --seed N\n");
  return 0;
}

int RenderAndReport(const avp::apps::RenderOptions& options) {
  const auto result = avp::apps::RunRender(options);
  if (!result.ok()) {
    spdlog::error("render failed: {}", result.status().ToString());
    return 1;
  }
  const auto& s = *result;
  spdlog::info("camera X_WC: {}", s.X_WC.ToString());
  spdlog::info("rendered {}x{} in {:.1f} ms ({} triangles); valid depth on {} pixels",
               options.intrinsics.width, options.intrinsics.height, s.render_ms, s.num_triangles,
               s.valid_depth_pixels);
  spdlog::info("fruit pixels: {} ({} of {} fruits visible)", s.fruit_pixels, s.visible_fruits,
               s.total_fruits);
  std::printf("wrote %zu files to %s:\n", s.files.size(), options.out_dir.string().c_str());
  for (const auto& f : s.files) std::printf("  %s\n", f.string().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "avp: active vision for agricultural robots (simulated RGB-D arm, semantic mapping, "
      "next-best-view planning)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "avp 0.1.0");

  app.add_subcommand("scenes", "List the built-in scenarios with one-line descriptions");

  avp::apps::RenderOptions render;
  std::vector<double> joints;
  std::vector<double> pose;
  std::string out_dir = render.out_dir.string();
  std::string scene_file;
  std::string arm_config;
  auto* render_cmd = app.add_subcommand(
      "render", "Render one simulated RGB-D + label view and write it to a folder");
  render_cmd->add_option("--scenario", render.scene.scenario,
                         "Built-in scenario name (see `avp scenes`); default: " +
                             std::string(avp::sim::DefaultScenarioName()));
  render_cmd->add_option("--scene", scene_file, "YAML scene file (docs/scene-format.md)");
  render_cmd->add_option("--seed", render.scene.seed, "Seed of the procedural plant and the noise")
      ->default_val(0);
  auto* joints_opt = render_cmd
                         ->add_option("--joints", joints,
                                      "Arm joint angles in degrees, comma separated, e.g. "
                                      "--joints=0,-70,60,0,47.5,0 (default: the scene's start)")
                         ->delimiter(',')
                         ->allow_extra_args(false);
  auto* pose_opt = render_cmd
                       ->add_option("--camera-pose", pose,
                                    "Camera optical frame pose in the robot base frame: "
                                    "x,y,z (m),roll,pitch,yaw (deg)")
                       ->delimiter(',')
                       ->allow_extra_args(false);
  joints_opt->excludes(pose_opt);
  render_cmd->add_option("--arm", arm_config,
                         "Arm config YAML (default: configs/arms/igus_rebel_d435.yaml)");
  render_cmd->add_flag("--noise", render.noise, "Apply the seeded D435-like depth noise model");
  render_cmd->add_option("--out", out_dir, "Output folder")->default_val(out_dir);

  CLI11_PARSE(app, argc, argv);

  try {
    if (app.got_subcommand("scenes")) return RunScenes();
    if (app.got_subcommand("render")) {
      render.scene.scene_file = scene_file;
      render.arm_config = arm_config;
      render.out_dir = out_dir;
      if (joints_opt->count() > 0) render.joints_deg = joints;
      if (pose_opt->count() > 0) render.camera_pose = pose;
      return RenderAndReport(render);
    }
  } catch (const avp::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  } catch (const std::exception& e) {
    spdlog::error("unexpected error: {}", e.what());
    return 2;
  }
  return 0;
}

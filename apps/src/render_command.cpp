#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/experiment/render.h>

#include "cli_common.h"

namespace avp::apps {

using experiment::RenderOptions;

namespace {

int RenderAndReport(const RenderOptions& options, const sim::ScenarioRegistry& scenarios) {
  RenderOptions o = options;
  o.on_scene = LogSceneWarnings;
  const auto result = experiment::RenderToFolder(o, scenarios);
  if (!result.ok()) return Failed("render", result.status());
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

struct RenderCli {
  RenderOptions options;
  std::vector<double> joints;
  std::vector<double> pose;
  std::string out_dir = RenderOptions{}.out_dir.string();
  SceneFlags scene;
  std::string arm_config;
  CLI::Option* joints_opt = nullptr;
  CLI::Option* pose_opt = nullptr;
};

}  // namespace

void AddRenderCommand(CLI::App& app, CommandContext& context) {
  auto cli = std::make_shared<RenderCli>();
  CLI::App* cmd = app.add_subcommand(
      "render", "Render one simulated RGB-D + label view and write it to a folder");
  AddSceneFlags(*cmd, cli->scene, "Seed of the procedural plant and the noise");
  cli->joints_opt = cmd->add_option("--joints", cli->joints,
                                    "Arm joint angles in degrees, comma separated, e.g. "
                                    "--joints=0,-70,60,0,47.5,0 (default: the scene's start)")
                        ->delimiter(',')
                        ->allow_extra_args(false);
  cli->pose_opt = cmd->add_option("--camera-pose", cli->pose,
                                  "Camera optical frame pose in the robot base frame: "
                                  "x,y,z (m),roll,pitch,yaw (deg)")
                      ->delimiter(',')
                      ->allow_extra_args(false);
  cli->joints_opt->excludes(cli->pose_opt);
  cmd->add_option("--arm", cli->arm_config,
                  "Arm config YAML (default: configs/arms/igus_rebel_d435.yaml)");
  cmd->add_flag("--noise,!--no-noise", cli->options.noise,
                "The seeded D435-like depth noise model (on by default, as in avp run; --no-noise: "
                "noise-free depth)");
  cmd->add_option("--out", cli->out_dir, "Output folder")->default_val(cli->out_dir);
  cmd->add_flag("--force", cli->options.force,
                "Replace an earlier render's files in --out (another command's folder is never "
                "written into)");
  cmd->callback([cli, &context] {
    RunGuarded(context, [&] {
      RenderOptions o = cli->options;
      o.scene = cli->scene.Source();
      o.arm_config = cli->arm_config;
      o.out_dir = cli->out_dir;
      if (cli->joints_opt->count() > 0) o.joints_deg = cli->joints;
      if (cli->pose_opt->count() > 0) o.camera_pose = cli->pose;
      return RenderAndReport(o, context.registries->scenarios);
    });
  });
}

}  // namespace avp::apps

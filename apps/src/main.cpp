// The `avp` command line. Subcommands: scenes, render, map (run, bench, serve come later).
#include <cstdio>
#include <iostream>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/apps/map_command.h>
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

int MapBuildAndReport(const avp::apps::MapBuildOptions& options) {
  avp::apps::MapBuildOptions o = options;
  o.on_view = [](const avp::apps::MapBuildView& v) {
    const Eigen::Vector3d eye = v.X_WC.translation();
    std::printf(
        "view %d/%d  azimuth %6.1f deg  eye (%.3f, %.3f, %.3f)  %zu endpoints, %zu fruit px in "
        "%zu masks -> known %zu, occupied %zu, labelled %zu, instances %zu  (render %.0f ms, "
        "integrate %.0f ms)\n",
        v.index + 1, v.views, v.azimuth_deg, eye.x(), eye.y(), eye.z(), v.stats.endpoints,
        v.fruit_pixels, v.masks, v.known_voxels, v.occupied_voxels, v.labelled_voxels, v.instances,
        v.render_ms, v.integrate_ms);
    std::fflush(stdout);
  };
  const auto result = avp::apps::RunMapBuild(o);
  if (!result.ok()) {
    spdlog::error("map build failed: {}", result.status().ToString());
    return 1;
  }
  const auto& s = *result;
  std::printf(
      "map of '%s': %zu known, %zu occupied, %zu labelled voxels; %zu fruit voxels in %zu "
      "instances (%zu fruits in the scene); %.1f s\n",
      s.scene_name.c_str(), s.known_voxels, s.occupied_voxels, s.labelled_voxels, s.fruit_voxels,
      s.instances.size(), s.total_fruits, s.seconds);
  std::printf("wrote %s (%llu bytes)\n", s.out.string().c_str(),
              static_cast<unsigned long long>(s.file_bytes));
  return 0;
}

int MapGtAndReport(const avp::apps::MapGtOptions& options) {
  const auto result = avp::apps::RunMapGt(options);
  if (!result.ok()) {
    spdlog::error("map gt failed: {}", result.status().ToString());
    return 1;
  }
  std::printf("wrote %s: %zu fruit surface voxels of %zu fruits of '%s' at %g mm (%llu bytes)\n",
              options.out.string().c_str(), result->voxels, result->fruits,
              result->scene_name.c_str(), options.voxel_size_m * 1000.0,
              static_cast<unsigned long long>(result->file_bytes));
  return 0;
}

int MapInfoAndReport(const std::string& path) {
  const auto result = avp::apps::RunMapInfo(path);
  if (!result.ok()) {
    spdlog::error("map info failed: {}", result.status().ToString());
    return 1;
  }
  std::fputs(avp::apps::FormatMapInfo(*result).c_str(), stdout);
  return 0;
}

int MapExportAndReport(const avp::apps::MapExportOptions& options) {
  const auto result = avp::apps::RunMapExport(options);
  if (!result.ok()) {
    spdlog::error("map export failed: {}", result.status().ToString());
    return 1;
  }
  const auto& s = *result;
  if (s.format == avp::apps::MapExportFormat::kPly) {
    std::printf("wrote %s: %zu labelled voxels (%llu bytes)\n", s.out.string().c_str(),
                s.labelled_voxels, static_cast<unsigned long long>(s.file_bytes));
  } else {
    std::printf("wrote %s: %zu occupied and %zu free voxels%s (%llu bytes)\n",
                s.out.string().c_str(), s.occupied_voxels, s.free_voxels,
                s.format == avp::apps::MapExportFormat::kOt
                    ? fmt::format(", {} coloured by class", s.labelled_voxels).c_str()
                    : "",
                static_cast<unsigned long long>(s.file_bytes));
  }
  return 0;
}

int MapCompareAndReport(const avp::apps::MapCompareOptions& options) {
  const auto result = avp::apps::RunMapCompare(options);
  if (!result.ok()) {
    spdlog::error("map compare failed: {}", result.status().ToString());
    return 1;
  }
  std::fputs(avp::apps::FormatMapCompare(*result).c_str(), stdout);
  if (!options.json_out.empty()) std::printf("wrote %s\n", options.json_out.string().c_str());
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

  // ---- avp map ----------------------------------------------------------------------------------
  auto* map_cmd = app.add_subcommand(
      "map", "Semantic occupancy maps: build from simulated views, inspect, export, compare");
  map_cmd->require_subcommand(1);

  avp::apps::MapBuildOptions build;
  std::string build_out = build.out.string();
  std::string build_policy = "reference-max";
  std::string build_carving = "raycast";
  auto* build_cmd = map_cmd->add_subcommand(
      "build", "Render views on an arc around a simulated plant, fuse them and save the map");
  build_cmd->add_option("--scenario", build.scene.scenario,
                        "Built-in scenario name (see `avp scenes`); default: " +
                            std::string(avp::sim::DefaultScenarioName()));
  build_cmd->add_option("--seed", build.scene.seed, "Seed of the procedural plant")->default_val(0);
  build_cmd->add_option("--views", build.views, "Number of views")->default_val(build.views);
  build_cmd->add_option("--voxel-size", build.voxel_size_m, "Voxel edge in metres (0.002 - 0.02)")
      ->default_val(build.voxel_size_m);
  build_cmd->add_option("--policy", build_policy, "Semantic fusion policy")
      ->check(CLI::IsMember({"reference-max", "bayesian"}))
      ->default_val(build_policy);
  build_cmd->add_option("--carving", build_carving, "Free-space carving")
      ->check(CLI::IsMember({"raycast", "projective", "none"}))
      ->default_val(build_carving);
  build_cmd
      ->add_option("--arc-deg", build.arc_deg,
                   "Arc of view azimuths around the plant, centred on the start view "
                   "(360 = full ring)")
      ->default_val(build.arc_deg);
  build_cmd
      ->add_option("--radius", build.radius_m,
                   "Horizontal camera distance from the plant centre, m (0 = the start "
                   "camera's)")
      ->default_val(build.radius_m);
  build_cmd->add_option("--threads", build.threads, "Integrator threads (0 = all)")
      ->default_val(build.threads);
  build_cmd->add_flag("--noise", build.noise, "Apply the seeded D435-like depth noise model");
  build_cmd->add_option("--out", build_out, "Output map file (.avpmap)")->default_val(build_out);

  avp::apps::MapGtOptions gt;
  std::string gt_out = gt.out.string();
  auto* gt_cmd = map_cmd->add_subcommand(
      "gt", "Write a scenario's fruit surface voxels as an OctoMap .bt ground truth");
  gt_cmd->add_option("--scenario", gt.scene.scenario, "Built-in scenario name");
  gt_cmd->add_option("--seed", gt.scene.seed, "Seed of the procedural plant")->default_val(0);
  gt_cmd->add_option("--voxel-size", gt.voxel_size_m, "Voxel edge in metres")
      ->default_val(gt.voxel_size_m);
  gt_cmd->add_option("--out", gt_out, "Output .bt file")->default_val(gt_out);

  std::string info_file;
  auto* info_cmd = map_cmd->add_subcommand("info", "Describe a map file");
  info_cmd->add_option("file", info_file, "Map file (.avpmap)")->required();

  avp::apps::MapExportOptions exp;
  std::string exp_map, exp_out;
  auto* export_cmd = map_cmd->add_subcommand(
      "export", "Export a map to OctoMap (.bt occupancy, .ot coloured by class) or PLY");
  export_cmd->add_option("file", exp_map, "Map file (.avpmap)")->required();
  export_cmd->add_option("--format", exp.format, "bt, ot or ply (default: from --out)")
      ->check(CLI::IsMember({"bt", "ot", "ply"}));
  export_cmd->add_option("--out", exp_out, "Output file")->required();
  export_cmd->add_flag("--ascii", exp.ply_ascii, "PLY: ASCII instead of binary little-endian");
  export_cmd->add_flag("--all-labelled", exp.ply_all_labelled,
                       "PLY: every labelled voxel, not only occupied ones");

  avp::apps::MapCompareOptions cmp;
  std::string cmp_map, cmp_gt, cmp_json, cmp_class = "fruit";
  auto* compare_cmd = map_cmd->add_subcommand(
      "compare", "Precision / recall / F1 of a map's labelled voxels against a ground-truth .bt");
  compare_cmd->add_option("file", cmp_map, "Map file (.avpmap)")->required();
  compare_cmd->add_option("--gt", cmp_gt, "Ground truth: OctoMap .bt (or .ot) of occupied voxels")
      ->required();
  compare_cmd
      ->add_option("--tolerance-voxels", cmp.tolerance_voxels,
                   "Also report matches within this many map voxels (0 = exact only)")
      ->default_val(cmp.tolerance_voxels);
  compare_cmd->add_option("--class", cmp_class, "Class of the predicted voxels")
      ->default_val(cmp_class);
  compare_cmd->add_option("--json", cmp_json, "Also write the result as JSON to this file");

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
    if (map_cmd->parsed()) {
      if (build_cmd->parsed()) {
        build.out = build_out;
        build.policy = *avp::mapping::FusionPolicyFromString(build_policy);
        build.carving = *avp::mapping::FreeSpaceCarvingFromString(build_carving);
        return MapBuildAndReport(build);
      }
      if (gt_cmd->parsed()) {
        gt.out = gt_out;
        return MapGtAndReport(gt);
      }
      if (info_cmd->parsed()) return MapInfoAndReport(info_file);
      if (export_cmd->parsed()) {
        exp.map = exp_map;
        exp.out = exp_out;
        return MapExportAndReport(exp);
      }
      if (compare_cmd->parsed()) {
        const auto cls = avp::SemanticClassFromString(cmp_class);
        if (!cls) {
          spdlog::error("map compare: unknown class '{}'", cmp_class);
          return 1;
        }
        cmp.map = cmp_map;
        cmp.gt = cmp_gt;
        cmp.json_out = cmp_json;
        cmp.semantic_class = *cls;
        return MapCompareAndReport(cmp);
      }
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

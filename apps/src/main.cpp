// The `avp` command line. Subcommands: scenes, render, map, run, bench, serve, segment.
#include <cstdio>
#include <iostream>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/apps/map_command.h>
#include <avp/apps/render_command.h>
#include <avp/apps/run_command.h>
#include <avp/apps/segment_command.h>
#include <avp/apps/serve_command.h>
#include <avp/core/error.h>
#include <avp/interop/remote_segmenter.h>
#include <avp/sim/scenario.h>
#include <avp/zsl/register.h>

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

std::string Join(const std::vector<std::string>& v) {
  std::string out;
  for (const std::string& s : v) out += (out.empty() ? "" : ", ") + s;
  return out;
}

int RunAndReport(const avp::apps::RunOptions& options) {
  avp::apps::RunOptions o = options;
  o.on_step = [](const avp::pipeline::StepRecord& s) {
    const Eigen::Vector3d eye = s.X_WC.translation();
    std::printf(
        "view %d/%d  eye (%.3f, %.3f, %.3f)  %zu masks  F1 %.3f (tol %.3f)  fruits %.0f/%.0f  "
        "[segment %.0f ms, integrate %.0f ms, plan %.0f ms%s]\n",
        s.view + 1, s.views_total, eye.x(), eye.y(), eye.z(), s.masks, s.Metric("f1"),
        s.Metric("f1_tol"), s.Metric("fruits_found"), s.Metric("fruits_total"), s.times.segment_ms,
        s.times.integrate_ms, s.times.plan_ms,
        s.planned ? fmt::format(", {} of {} candidates reachable", s.candidates_reachable,
                                s.candidates_generated)
                        .c_str()
                  : "");
    std::fflush(stdout);
  };
  const auto result = avp::apps::RunRun(o);
  if (!result.ok()) {
    spdlog::error("run failed: {}", result.status().ToString());
    return 1;
  }
  const auto& r = result->result;
  std::printf(
      "%s with %s / %s, seed %llu: %d views (%s%s%s) in %.1f s; final F1 %.3f, fruits found "
      "%zu/%zu\n",
      result->scene_name.c_str(), options.config.planner.c_str(), options.config.segmenter.c_str(),
      static_cast<unsigned long long>(options.config.seed), r.episode.views_fused(),
      std::string(avp::pipeline::ToString(r.episode.end)).c_str(),
      r.episode.end_reason.empty() ? "" : ": ", r.episode.end_reason.c_str(), result->seconds,
      r.final_metrics.exact.f1, r.final_metrics.fruits.found, r.final_metrics.fruits.total);
  if (!r.regret.empty()) {
    std::printf(
        "oracle regret per plan step (1 - true gain of the choice / best true gain; true "
        "rank of the choice; rank correlation of the gain with the true gain):\n");
    for (const avp::eval::StepRegret& g : r.regret) {
      std::printf("  step %d: regret %.2f, rank %zu of %zu, correlation %.2f\n", g.step + 1,
                  g.regret, g.chosen_true_rank, g.candidates, g.rank_correlation);
    }
  }
  std::printf("wrote %zu files to %s:\n", result->files.size(), options.out_dir.string().c_str());
  for (const auto& f : result->files) std::printf("  %s\n", f.string().c_str());
  return 0;
}

int BenchAndReport(const avp::apps::BenchOptions& options) {
  const auto result = avp::apps::RunBench(options);
  if (!result.ok()) {
    spdlog::error("bench failed: {}", result.status().ToString());
    return 1;
  }
  std::printf("%zu episodes (%zu failed) in %.1f s. Final view, mean ± 95 %% CI over %zu seeds:\n",
              result->episodes, result->failed, result->seconds, options.seeds.size());
  std::printf("  %-28s %-16s %-17s %-17s %s\n", "scenario", "planner", "F1 (exact)", "fruits found",
              "plan ms/step");
  for (const auto& c : result->cells) {
    std::printf("  %-28s %-16s %.3f ± %.3f     %.3f ± %.3f     %.0f\n", c.scenario.c_str(),
                c.planner.c_str(), c.final_f1_mean, c.final_f1_ci95, c.final_found_mean,
                c.final_found_ci95, c.plan_ms_mean);
  }
  std::printf("wrote %s and the per-run records under %s\n", result->files.front().string().c_str(),
              (options.out_dir / "runs").string().c_str());
  return 0;
}

int ServeSegmentationAndReport(avp::apps::ServeOptions options) {
  options.log = [](avp::apps::ServeLogLevel level, const std::string& message) {
    if (level == avp::apps::ServeLogLevel::kWarning) {
      spdlog::warn("{}", message);
    } else {
      spdlog::info("{}", message);
    }
  };
  const avp::Status status = avp::apps::RunServeSegmentation(options);
  if (!status.ok()) {
    spdlog::error("serve segmentation failed: {}", status.ToString());
    return 1;
  }
  return 0;
}

int SegmentAndReport(const avp::apps::SegmentOptions& options) {
  const auto result = avp::apps::RunSegment(options);
  if (!result.ok()) {
    spdlog::error("segment failed: {}", result.status().ToString());
    return 1;
  }
  std::fputs(avp::apps::FormatSegmentSummary(*result).c_str(), stdout);
  std::printf("wrote %zu files to %s:\n", result->files.size(), options.out_dir.string().c_str());
  for (const auto& f : result->files) std::printf("  %s\n", f.string().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // Every command and config accepts remote://host:port[/model] as a segmenter.
  avp::interop::RegisterRemoteSegmenter();
  // ... and ywes / lsam (models from AVP_ZSL_MODEL_DIR), ywes://DIR, lsam://DIR.
  avp::zsl::RegisterZslSegmenters();
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

  // avp run
  avp::apps::RunOptions run;
  std::string run_scene_file, run_policy = "bayesian", run_carving = "projective", run_gt;
  bool run_no_noise = false;
  auto* run_cmd = app.add_subcommand(
      "run", "One simulated active-vision episode into a run folder (docs/experiments.md)");
  run_cmd->add_option("--scenario", run.config.scenario, "Built-in scenario (see avp scenes)");
  run_cmd->add_option("--scene", run_scene_file, "YAML scene file instead of a scenario");
  run_cmd->add_option("--seed", run.config.seed, "Seed of the plant, the noise and every choice")
      ->default_val(0);
  run_cmd
      ->add_option(
          "--planner", run.config.planner,
          "View planner: " + Join(avp::eval::PlannerNames()) +
              "; diagnostic (uses the ground truth): " + Join(avp::eval::DiagnosticPlannerNames()))
      ->default_val(run.config.planner);
  run_cmd
      ->add_option("--segmenter", run.config.segmenter,
                   "Segmenter: " + Join(avp::eval::SegmenterNames()))
      ->default_val(run.config.segmenter);
  run_cmd->add_option("--views", run.config.views, "Fused views, start view included")
      ->default_val(run.config.views);
  run_cmd->add_option("--prompt", run.config.prompt, "Text prompt")->default_val(run.config.prompt);
  run_cmd->add_option("--voxel-size", run.config.voxel_size_m, "Voxel edge in metres")
      ->default_val(run.config.voxel_size_m);
  run_cmd->add_option("--policy", run_policy, "Semantic fusion: bayesian or reference-max")
      ->default_val(run_policy);
  run_cmd->add_option("--carving", run_carving, "Free space: projective, raycast or none")
      ->default_val(run_carving);
  run_cmd->add_flag("--no-noise", run_no_noise, "Noise-free depth");
  run_cmd->add_option("--gt", run_gt,
                      "Ground truth from an OctoMap .bt instead of the observable fruit surface");
  run_cmd
      ->add_option("--threads", run.config.threads,
                   "Threads (0 = all; results do not depend on it)")
      ->default_val(0);
  std::vector<std::string> run_planner_options;
  run_cmd->add_option("--planner-option", run_planner_options,
                      "avp-nbv option KEY=VALUE over its defaults (repeatable; e.g. p_unknown=0.1; "
                      "keys in docs/planning.md)");
  run_cmd->add_flag("--oracle-regret", run.config.oracle_regret,
                    "Measure each plan step's regret with the truth (record.json oracle_regret; "
                    "the plan times include it)");
  run_cmd->add_option("--out", run.out_dir, "Run folder")->default_val(run.out_dir.string());

  // avp bench
  avp::apps::BenchOptions bench;
  std::string bench_config, bench_scenarios, bench_planners, bench_seeds, bench_out = "out/bench";
  int bench_seed_count = 0;
  auto* bench_cmd = app.add_subcommand(
      "bench", "Scenarios x planners x seeds in parallel, with summary tables and plots");
  bench_cmd->add_option("--config", bench_config,
                        "Experiment YAML (e.g. configs/experiments/paper.yaml)");
  bench_cmd->add_option("--scenarios", bench_scenarios,
                        "Comma-separated scenarios (overrides the config)");
  bench_cmd->add_option("--planners", bench_planners,
                        "Comma-separated planners (overrides the config)");
  bench_cmd->add_option("--seeds", bench_seeds,
                        "Comma-separated seeds, or N for 0..N-1 (overrides the config)");
  bench_cmd->add_option("--views", bench.base.views, "Fused views per episode")->default_val(8);
  bench_cmd->add_option("--segmenter", bench.base.segmenter, "Segmenter")->default_val("oracle");
  bench_cmd->add_option("--jobs", bench.jobs, "Episodes at once (0 = hardware threads)")
      ->default_val(0);
  std::vector<std::string> bench_planner_options;
  bench_cmd->add_option("--planner-option", bench_planner_options,
                        "avp-nbv option KEY=VALUE for its episodes (repeatable; overrides the "
                        "config's avp_nbv_options)");
  bench_cmd->add_option("--out", bench_out, "Output folder")->default_val(bench_out);
  (void)bench_seed_count;

  // avp serve segmentation
  auto* serve_cmd = app.add_subcommand("serve", "Network services");
  serve_cmd->require_subcommand(1);
  avp::apps::ServeOptions serve;
  serve.server.host = "0.0.0.0";
  std::string serve_backends = "oracle";
  std::string serve_port_file;
  auto* serve_seg_cmd = serve_cmd->add_subcommand(
      "segmentation",
      "The segmentation service: KServe v2 / Open Inference Protocol over gRPC "
      "(docs/segmentation-service.md); runs until SIGINT / SIGTERM");
  serve_seg_cmd->add_option("--port", serve.server.port, "TCP port (0 = pick a free one)")
      ->default_val(serve.server.port);
  serve_seg_cmd
      ->add_option("--backend", serve_backends,
                   "Backends to serve, comma separated, each as a model of its name (" +
                       Join(avp::segmentation::SegmenterNames()) + ", registered ones)")
      ->default_val(serve_backends);
  serve_seg_cmd->add_option("--host", serve.server.host, "Address to listen on")
      ->default_val(serve.server.host);
  serve_seg_cmd->add_option("--threads", serve.server.threads, "Worker threads")
      ->default_val(serve.server.threads);
  serve_seg_cmd
      ->add_option("--instances", serve.server.instances_per_model,
                   "Segmenters per (backend, seed) running at once")
      ->default_val(serve.server.instances_per_model);
  serve_seg_cmd
      ->add_option("--seed", serve.server.default_seed, "Segmenter seed of requests that send none")
      ->default_val(serve.server.default_seed);
  serve_seg_cmd->add_option("--port-file", serve_port_file,
                            "Write the bound port to this file once listening");

  // avp segment
  avp::apps::SegmentOptions segment;
  std::string segment_image, segment_models, segment_out = segment.out_dir.string();
  auto* segment_cmd = app.add_subcommand(
      "segment",
      "Segment one image from a text prompt; writes overlay.png and instances.json "
      "(docs/zero-shot-models.md)");
  segment_cmd->add_option("--image", segment_image, "JPEG or PNG image")->required();
  segment_cmd->add_option("--prompt", segment.prompt, "Comma-separated phrases")
      ->default_val(segment.prompt);
  segment_cmd
      ->add_option("--backend", segment.backend,
                   "Segmenter: ywes, lsam (models from --models or AVP_ZSL_MODEL_DIR), "
                   "ywes://DIR, lsam://DIR, " +
                       Join(avp::segmentation::SegmenterNames()) + ", remote://host:port")
      ->default_val(segment.backend);
  segment_cmd->add_option("--models", segment_models,
                          "Model directory of ywes / lsam (default: AVP_ZSL_MODEL_DIR)");
  segment_cmd->add_option("--threshold", segment.threshold, "Drop instances scoring below this")
      ->default_val(segment.threshold);
  segment_cmd->add_option("--seed", segment.seed, "Segmenter seed (noisy segmenters only)")
      ->default_val(segment.seed);
  segment_cmd->add_option("--out", segment_out, "Output folder")->default_val(segment_out);

  CLI11_PARSE(app, argc, argv);

  try {
    if (app.got_subcommand("scenes")) return RunScenes();
    if (segment_cmd->parsed()) {
      segment.image = segment_image;
      segment.models = segment_models;
      segment.out_dir = segment_out;
      return SegmentAndReport(segment);
    }
    if (serve_seg_cmd->parsed()) {
      serve.server.backends.clear();
      size_t start = 0;
      while (start <= serve_backends.size()) {
        const size_t comma = serve_backends.find(',', start);
        std::string item = serve_backends.substr(
            start, comma == std::string::npos ? std::string::npos : comma - start);
        item.erase(0, item.find_first_not_of(" \t"));
        item.erase(item.find_last_not_of(" \t") + 1);
        if (!item.empty()) serve.server.backends.push_back(item);
        if (comma == std::string::npos) break;
        start = comma + 1;
      }
      serve.port_file = serve_port_file;
      return ServeSegmentationAndReport(serve);
    }
    if (app.got_subcommand("render")) {
      render.scene.scene_file = scene_file;
      render.arm_config = arm_config;
      render.out_dir = out_dir;
      if (joints_opt->count() > 0) render.joints_deg = joints;
      if (pose_opt->count() > 0) render.camera_pose = pose;
      return RenderAndReport(render);
    }
    if (run_cmd->parsed()) {
      run.config.scene_file = run_scene_file;
      run.config.gt_file = run_gt;
      run.config.depth_noise = !run_no_noise;
      const auto policy = avp::mapping::FusionPolicyFromString(run_policy);
      const auto carving = avp::mapping::FreeSpaceCarvingFromString(run_carving);
      if (!policy || !carving) {
        spdlog::error("run: unknown {} '{}'", policy ? "carving" : "policy",
                      policy ? run_carving : run_policy);
        return 1;
      }
      run.config.policy = *policy;
      run.config.carving = *carving;
      if (run.config.scenario.empty() && run.config.scene_file.empty()) {
        run.config.scenario = std::string(avp::sim::DefaultScenarioName());
      }
      if (const avp::Status s =
              avp::apps::ParsePlannerOptions(run_planner_options, run.config.planner_options);
          !s.ok()) {
        spdlog::error("run: {}", s.message());
        return 1;
      }
      return RunAndReport(run);
    }
    if (bench_cmd->parsed()) {
      if (!bench_config.empty()) {
        const int views = bench.base.views;
        const std::string segmenter = bench.base.segmenter;
        const int jobs = bench.jobs;
        auto loaded = avp::apps::LoadBenchConfig(bench_config);
        if (!loaded.ok()) {
          spdlog::error("bench: {}", loaded.status().ToString());
          return 1;
        }
        bench = *loaded;
        bench.jobs = jobs;
        if (bench_cmd->get_option("--views")->count() > 0) bench.base.views = views;
        if (bench_cmd->get_option("--segmenter")->count() > 0) bench.base.segmenter = segmenter;
      }
      auto split = [](const std::string& s) {
        std::vector<std::string> out;
        size_t start = 0;
        while (start <= s.size()) {
          const size_t comma = s.find(',', start);
          std::string item =
              s.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
          item.erase(0, item.find_first_not_of(" \t"));
          item.erase(item.find_last_not_of(" \t") + 1);
          if (!item.empty()) out.push_back(item);
          if (comma == std::string::npos) break;
          start = comma + 1;
        }
        return out;
      };
      if (const avp::Status s =
              avp::apps::ParsePlannerOptions(bench_planner_options, bench.base.planner_options);
          !s.ok()) {
        spdlog::error("bench: {}", s.message());
        return 1;
      }
      if (!bench_scenarios.empty()) bench.scenarios = split(bench_scenarios);
      if (!bench_planners.empty()) bench.planners = split(bench_planners);
      if (bench.scenarios.empty()) {
        for (const auto& s : avp::sim::ListScenarios()) bench.scenarios.push_back(s.name);
      }
      if (bench.planners.empty()) bench.planners = {"avp-nbv", "predefined", "reference-nbv"};
      if (!bench_seeds.empty()) {
        bench.seeds.clear();
        try {
          const std::vector<std::string> items = split(bench_seeds);
          if (items.size() == 1 && bench_seeds.find(',') == std::string::npos) {
            const unsigned long long n = std::stoull(items[0]);
            for (unsigned long long i = 0; i < n; ++i) bench.seeds.push_back(i);
          } else {
            for (const std::string& item : items) bench.seeds.push_back(std::stoull(item));
          }
        } catch (const std::exception&) {
          spdlog::error("bench: bad --seeds '{}' (a count N, or a list like 0,1,5)", bench_seeds);
          return 1;
        }
      }
      if (bench.seeds.empty()) {
        for (uint64_t i = 0; i < 10; ++i) bench.seeds.push_back(i);
      }
      bench.out_dir = bench_out;
      return BenchAndReport(bench);
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

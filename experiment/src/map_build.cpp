#include <chrono>
#include <cmath>
#include <numbers>
#include <string>
#include <system_error>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/core/segmentation.h>
#include <avp/core/stopwatch.h>
#include <avp/experiment/map_build.h>
#include <avp/experiment/output_folder.h>
#include <avp/experiment/run_config.h>
#include <avp/io/file.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/octomap_io.h>
#include <avp/pipeline/view_fusion.h>
#include <avp/sim/ground_truth.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/sensor_noise.h>

namespace avp::experiment {

namespace {

namespace fs = std::filesystem;
using Clock = SteadyClock;

Status ValidateBuildOptions(const MapBuildOptions& o) {
  std::vector<std::string> errors;
  if (o.views < 1 || o.views > 360) {
    errors.push_back(fmt::format("views ({}) must be in [1, 360]", o.views));
  }
  if (!(o.arc_deg >= 0.0 && o.arc_deg <= 360.0)) {
    errors.push_back(fmt::format("arc ({} deg) must be in [0, 360]", o.arc_deg));
  }
  if (!(o.radius_m >= 0.0 && o.radius_m <= 3.0)) {
    errors.push_back(
        fmt::format("radius ({} m) must be in [0, 3] (0 = the start distance)", o.radius_m));
  }
  if (!std::isfinite(o.roi_margin_m)) {
    errors.push_back(fmt::format("ROI margin ({}) must be finite", o.roi_margin_m));
  }
  if (!(o.mask_confidence > 0.0f && o.mask_confidence < 1.0f)) {
    errors.push_back(fmt::format("mask confidence ({}) must be in (0, 1)", o.mask_confidence));
  }
  if (o.threads < 0 || o.threads > kMaxThreads) {
    errors.push_back(fmt::format("threads ({}) must be in [0, {}]", o.threads, kMaxThreads));
  }
  if (o.out.empty()) errors.push_back("the output file (--out) is empty");
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(
      fmt::format("invalid map build options: {}", fmt::join(errors, "; ")));
}

}  // namespace

std::vector<RigidTransform> ArcViewPoses(const Eigen::Vector3d& target_W,
                                         const Eigen::Vector3d& start_eye_W, int views,
                                         double arc_deg, double radius_m,
                                         std::vector<double>* azimuths_deg) {
  const Eigen::Vector2d d = (start_eye_W - target_W).head<2>();
  const double start_azimuth = d.norm() > 1e-9 ? std::atan2(d.y(), d.x()) : std::numbers::pi;
  const bool ring = arc_deg >= 360.0;
  std::vector<RigidTransform> poses;
  for (int i = 0; i < views; ++i) {
    double offset_deg = 0.0;
    if (ring) {
      offset_deg = 360.0 * i / views;
    } else if (views > 1) {
      offset_deg = arc_deg * (static_cast<double>(i) / (views - 1) - 0.5);
    }
    const double a = start_azimuth + offset_deg * std::numbers::pi / 180.0;
    const Eigen::Vector3d eye(target_W.x() + radius_m * std::cos(a),
                              target_W.y() + radius_m * std::sin(a), start_eye_W.z());
    poses.push_back(RigidTransform::LookAt(eye, target_W, Eigen::Vector3d::UnitZ()));
    if (azimuths_deg != nullptr) azimuths_deg->push_back(a * 180.0 / std::numbers::pi);
  }
  return poses;
}

namespace {

/// Renders `view` (with the seeded depth noise when asked), segments it with the simulator's
/// labels (every mask at options.mask_confidence) and fuses it; fills the view's record.
Status FuseArcView(const sim::RgbdRenderer& renderer, const MapBuildOptions& options,
                   const Rng& noise_rng, pipeline::ViewFusion& fusion, MapBuildView& view) {
  const auto t0 = Clock::now();
  sim::RenderedFrame frame = renderer.Render(options.intrinsics, view.X_WC,
                                             static_cast<int64_t>(view.index) * 100'000'000);
  if (options.noise) {
    sim::DepthNoiseConfig noise;
    noise.enabled = true;
    Rng rng = noise_rng.Fork(static_cast<uint64_t>(view.index));
    sim::ApplyDepthNoise(noise, frame, rng);
  }
  view.render_ms = MsSince(t0);
  Segmentation segmentation =
      Segmentation::FromLabelImages(frame.instance_ids, frame.class_ids, options.mask_confidence);
  view.masks = segmentation.instances.size();
  for (uint8_t c : frame.class_ids.data()) {
    if (c == static_cast<uint8_t>(SemanticClass::kFruit)) ++view.fruit_pixels;
  }
  pipeline::StepRecord step;
  pipeline::ViewSeen seen;
  fusion.Fuse(robot::Observation{std::move(frame.rgbd), std::nullopt}, std::move(segmentation),
              step, seen);
  AVP_RETURN_IF_ERROR(step.integrate_status);
  view.stats = step.integration;
  view.integrate_ms = step.times.integrate_ms;
  // ViewFusion counted the known and occupied voxels; the labels of every class are counted here.
  const mapping::SemanticMap& map = fusion.map();
  view.known_voxels = step.known_voxels;
  view.occupied_voxels = step.occupied_voxels;
  view.labelled_voxels = map.grid().CountSemanticVoxels();
  view.instances = map.Instances().size();
  return Status::Ok();
}

}  // namespace

Result<MapBuildSummary> BuildMap(const MapBuildOptions& options,
                                 const sim::ScenarioRegistry& scenarios) {
  const auto t_start = Clock::now();
  AVP_RETURN_IF_ERROR(ValidateBuildOptions(options));
  AVP_RETURN_IF_ERROR(options.intrinsics.Validate());
  AVP_RETURN_IF_ERROR(CheckOutputFile(options.out, options.force));
  AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out, "map file (--out)",
                                                options.scene.scene_file, "scene file"));
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene, sim::LoadScene(options.scene, scenarios));
  if (options.on_scene) options.on_scene(scene);
  if (scene.plant_bounds.IsEmpty()) {
    return InvalidArgumentError(fmt::format("scene '{}' has no plant to map", scene.name));
  }

  mapping::MapOptions map_options = options.map;
  if (options.roi_margin_m >= 0.0) {
    map_options.grid.roi = scene.plant_bounds.Inflated(options.roi_margin_m);
  }
  AVP_RETURN_IF_ERROR(map_options.Validate());
  const mapping::IntegratorOptions& integrator_options = options.integrator;
  AVP_RETURN_IF_ERROR(integrator_options.Validate());
  const ThreadScope threads(options.threads);

  MapBuildSummary summary;
  summary.scene_name = scene.name;
  summary.out = options.out;
  summary.total_fruits = scene.Fruits().size();
  summary.target_W = scene.plant_bounds.center();
  const Eigen::Vector3d start_eye = scene.X_WC_start.translation();
  summary.radius_m =
      options.radius_m > 0.0 ? options.radius_m : (start_eye - summary.target_W).head<2>().norm();
  if (summary.radius_m < 0.15) {
    return InvalidArgumentError(fmt::format(
        "the start camera of scene '{}' is {:.3f} m from the plant centre {} horizontally: give "
        "--radius",
        scene.name, summary.radius_m,
        fmt::format("({:.3f}, {:.3f}, {:.3f})", summary.target_W.x(), summary.target_W.y(),
                    summary.target_W.z())));
  }
  std::vector<double> azimuths;
  const std::vector<RigidTransform> poses = ArcViewPoses(
      summary.target_W, start_eye, options.views, options.arc_deg, summary.radius_m, &azimuths);

  mapping::SemanticMap map(map_options);
  pipeline::EpisodeOptions fusion_options;
  fusion_options.integrator = integrator_options;
  fusion_options.target_class = SemanticClass::kFruit;
  pipeline::ViewFusion fusion(map, fusion_options);
  const sim::RgbdRenderer renderer(scene);
  const Rng noise_rng = Rng(options.scene.seed).Fork("map-build-noise");
  for (int i = 0; i < options.views; ++i) {
    MapBuildView view;
    view.index = i;
    view.views = options.views;
    view.azimuth_deg = azimuths[static_cast<size_t>(i)];
    view.X_WC = poses[static_cast<size_t>(i)];
    AVP_RETURN_IF_ERROR(FuseArcView(renderer, options, noise_rng, fusion, view));
    if (options.on_view) options.on_view(view);
    summary.views.push_back(view);
  }

  // The map after the last view (views >= 1: ValidateBuildOptions).
  summary.known_voxels = summary.views.back().known_voxels;
  summary.occupied_voxels = summary.views.back().occupied_voxels;
  summary.labelled_voxels = summary.views.back().labelled_voxels;
  summary.fruit_voxels = pipeline::CountTargetVoxels(map.grid(), SemanticClass::kFruit);
  summary.instances = map.Instances();

  mapping::MapSaveOptions save;
  const std::string source =
      options.scene.scene_file.empty()
          ? fmt::format("--scenario {}", options.scene.scenario.empty()
                                             ? sim::DefaultScenarioName()
                                             : std::string_view(options.scene.scenario))
          : fmt::format("--scene {}", options.scene.scene_file.string());
  save.note = fmt::format(
      "avp map build {}{} --seed {} --views {} --voxel-size {} --policy {} --carving {} "
      "--arc-deg {} --radius {:.3f}{}",
      source,
      options.scene.arrangement.empty() ? "" : " --arrangement " + options.scene.arrangement,
      options.scene.seed, options.views, options.map.grid.voxel_size_m,
      mapping::ToString(options.map.semantics.policy),
      mapping::ToString(options.integrator.carving), options.arc_deg, summary.radius_m,
      options.noise ? " --noise" : " --no-noise");
  // Every other map option that differs from the defaults (the header stores them all).
  for (const auto& [key, value] : mapping::MapOptionTable().Differences(options.map, {})) {
    if (key != "grid.voxel_size_m" && key != "semantics.policy") {
      save.note += fmt::format(" --map-option {}={}", key, value);
    }
  }
  AVP_RETURN_IF_ERROR(mapping::SaveMap(map, options.out, save));
  std::error_code ec;
  summary.file_bytes = fs::file_size(options.out, ec);
  summary.seconds = MsSince(t_start) / 1000.0;
  return summary;
}

Result<MapGtSummary> WriteGroundTruthOctree(const MapGtOptions& options,
                                            const sim::ScenarioRegistry& scenarios) {
  AVP_RETURN_IF_ERROR(CheckOutputFile(options.out, options.force));
  AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out, "ground truth file (--out)",
                                                options.scene.scene_file, "scene file"));
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene, sim::LoadScene(options.scene, scenarios));
  if (options.on_scene) options.on_scene(scene);
  mapping::GridOptions grid_options;
  grid_options.voxel_size_m = options.voxel_size_m;
  AVP_RETURN_IF_ERROR(grid_options.Validate());
  const sim::FruitVoxels truth = sim::VoxelizeFruitSurfaces(scene, options.voxel_size_m);
  mapping::OccupancyGrid grid(grid_options);
  for (const VoxelKey& k : truth.SortedKeys()) grid.SetLogOdds(k, grid.clamp_max_log_odds());
  AVP_ASSIGN_OR_RETURN(const mapping::OctomapExportStats stats,
                       mapping::ExportOctomapBinary(grid, options.out));
  MapGtSummary summary;
  summary.scene_name = scene.name;
  summary.fruits = scene.Fruits().size();
  summary.voxels = stats.occupied_voxels;
  summary.file_bytes = stats.file_bytes;
  return summary;
}

}  // namespace avp::experiment

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <numbers>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <avp/apps/map_command.h>
#include <avp/apps/scene_command.h>
#include <avp/core/options.h>
#include <avp/core/rng.h>
#include <avp/core/segmentation.h>
#include <avp/core/text.h>
#include <avp/experiment/run_config.h>
#include <avp/io/file.h>
#include <avp/io/json.h>
#include <avp/mapping/ply_export.h>
#include <avp/mapping/semantic_map.h>
#include <avp/report/progress.h>
#include <avp/sim/ground_truth.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/sensor_noise.h>

#include "cli_common.h"

namespace avp::apps {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

std::string HumanBytes(uint64_t bytes) {
  if (bytes < 1024) return fmt::format("{} B", bytes);
  if (bytes < 1024 * 1024) return fmt::format("{:.1f} KiB", static_cast<double>(bytes) / 1024.0);
  if (bytes < uint64_t{1} << 30) {
    return fmt::format("{:.1f} MiB", static_cast<double>(bytes) / (1024.0 * 1024.0));
  }
  return fmt::format("{:.2f} GiB", static_cast<double>(bytes) / (1024.0 * 1024.0 * 1024.0));
}

std::string FormatPoint(const Eigen::Vector3d& p, int decimals = 3) {
  return fmt::format("({:.{}f}, {:.{}f}, {:.{}f})", p.x(), decimals, p.y(), decimals, p.z(),
                     decimals);
}

size_t CountOccupiedOfClass(const mapping::OccupancyGrid& grid, SemanticClass c) {
  size_t n = 0;
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const mapping::SemanticCell& cell) {
    if (cell.cls() == c && grid.State(k) == mapping::VoxelState::kOccupied) ++n;
  });
  return n;
}

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
  if (o.threads < 0 || o.threads > experiment::kMaxThreads) {
    errors.push_back(
        fmt::format("threads ({}) must be in [0, {}]", o.threads, experiment::kMaxThreads));
  }
  if (o.out.empty()) errors.push_back("the output file (--out) is empty");
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(
      fmt::format("invalid map build options: {}", fmt::join(errors, "; ")));
}

}  // namespace

// ---- build
// ---------------------------------------------------------------------------------------

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

Result<MapBuildSummary> RunMapBuild(const MapBuildOptions& options,
                                    const sim::ScenarioRegistry& scenarios) {
  const auto t_start = Clock::now();
  AVP_RETURN_IF_ERROR(ValidateBuildOptions(options));
  AVP_RETURN_IF_ERROR(options.intrinsics.Validate());
  AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out, "map file (--out)",
                                                options.scene.scene_file, "scene file"));
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene, sim::LoadScene(options.scene, scenarios));
  LogSceneWarnings(scene);
  if (scene.plant_bounds.IsEmpty()) {
    return InvalidArgumentError(fmt::format("scene '{}' has no plant to map", scene.name));
  }

  mapping::MapOptions map_options = options.map;
  if (options.roi_margin_m >= 0.0) {
    map_options.grid.roi = scene.plant_bounds.Inflated(options.roi_margin_m);
  }
  AVP_RETURN_IF_ERROR(map_options.Validate());
  mapping::IntegratorOptions integrator_options = options.integrator;
  integrator_options.num_threads = options.threads;
  AVP_RETURN_IF_ERROR(integrator_options.Validate());

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
        scene.name, summary.radius_m, FormatPoint(summary.target_W)));
  }
  std::vector<double> azimuths;
  const std::vector<RigidTransform> poses = ArcViewPoses(
      summary.target_W, start_eye, options.views, options.arc_deg, summary.radius_m, &azimuths);

  mapping::SemanticMap map(map_options);
  const mapping::Integrator integrator(integrator_options);
  const sim::RgbdRenderer renderer(scene);
  const Rng noise_rng = Rng(options.scene.seed).Fork("map-build-noise");
  for (int i = 0; i < options.views; ++i) {
    MapBuildView view;
    view.index = i;
    view.views = options.views;
    view.azimuth_deg = azimuths[static_cast<size_t>(i)];
    view.X_WC = poses[static_cast<size_t>(i)];
    auto t0 = Clock::now();
    sim::RenderedFrame frame =
        renderer.Render(options.intrinsics, view.X_WC, static_cast<int64_t>(i) * 100'000'000);
    if (options.noise) {
      sim::DepthNoiseConfig noise;
      noise.enabled = true;
      Rng rng = noise_rng.Fork(static_cast<uint64_t>(i));
      sim::ApplyDepthNoise(noise, frame, rng);
    }
    view.render_ms = MsSince(t0);
    const Segmentation segmentation =
        Segmentation::FromLabelImages(frame.instance_ids, frame.class_ids, options.mask_confidence);
    view.masks = segmentation.instances.size();
    for (uint8_t c : frame.class_ids.data()) {
      if (c == static_cast<uint8_t>(SemanticClass::kFruit)) ++view.fruit_pixels;
    }
    t0 = Clock::now();
    AVP_ASSIGN_OR_RETURN(view.stats, integrator.Integrate(frame.rgbd, &segmentation, map));
    view.integrate_ms = MsSince(t0);
    view.known_voxels = map.grid().CountKnownVoxels();
    view.occupied_voxels = map.grid().CountOccupiedVoxels();
    view.labelled_voxels = map.grid().CountSemanticVoxels();
    view.instances = map.Instances().size();
    if (options.on_view) options.on_view(view);
    summary.views.push_back(view);
  }

  summary.known_voxels = map.grid().CountKnownVoxels();
  summary.occupied_voxels = map.grid().CountOccupiedVoxels();
  summary.labelled_voxels = map.grid().CountSemanticVoxels();
  summary.fruit_voxels = CountOccupiedOfClass(map.grid(), SemanticClass::kFruit);
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
      options.noise ? " --noise" : "");
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

// ---- gt
// ------------------------------------------------------------------------------------------

Result<MapGtSummary> RunMapGt(const MapGtOptions& options, const sim::ScenarioRegistry& scenarios) {
  AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out, "ground truth file (--out)",
                                                options.scene.scene_file, "scene file"));
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene, sim::LoadScene(options.scene, scenarios));
  LogSceneWarnings(scene);
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

// ---- info
// ----------------------------------------------------------------------------------------

Result<MapInfo> RunMapInfo(const fs::path& path) {
  MapInfo info;
  info.path = path;
  AVP_RETURN_IF_ERROR(io::CheckReadableFile(path, "map file").status());
  AVP_ASSIGN_OR_RETURN(const mapping::LoadedMap loaded, mapping::LoadAnyMap(path));
  info.source = loaded.source;
  info.file = loaded.source.avpmap;
  const mapping::SemanticMap& map = loaded.map;
  const mapping::OccupancyGrid& grid = map.grid();
  info.options = map.options();
  info.blocks = grid.num_blocks();
  info.semantic_blocks = grid.num_semantic_blocks();
  info.known_voxels = grid.CountKnownVoxels();
  info.occupied_voxels = grid.CountOccupiedVoxels();
  info.free_voxels = info.known_voxels - info.occupied_voxels;
  info.labelled_voxels = grid.CountSemanticVoxels();
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const mapping::SemanticCell& cell) {
    if (cell.semantic_class >= kNumSemanticClasses) return;
    ++info.labelled_by_class[cell.semantic_class];
    if (grid.State(k) == mapping::VoxelState::kOccupied)
      ++info.occupied_by_class[cell.semantic_class];
  });
  info.instances = map.Instances();
  info.known_bounds = grid.KnownBounds();
  info.memory_bytes = grid.MemoryBytes();
  return info;
}

std::string FormatMapInfo(const MapInfo& info) {
  const mapping::GridOptions& g = info.options.grid;
  const mapping::SemanticOptions& s = info.options.semantics;
  std::string out;
  const auto line = [&](std::string_view key, const std::string& value) {
    out += fmt::format("{:<13}{}\n", key, value);
  };
  const mapping::MapSource& src = info.source;
  const bool octomap = src.format != mapping::MapFileFormat::kAvpMap;
  if (!octomap) {
    line("map file",
         fmt::format("{} ({}, format version {}, CRC-32 0x{:08x})", info.path.string(),
                     HumanBytes(info.file.file_bytes), info.file.version, info.file.crc32));
  } else {
    line("map file", fmt::format("{} ({}, OctoMap {} {}, {} tree nodes)", info.path.string(),
                                 HumanBytes(src.file_bytes), EscapeText(src.tree_type, 64),
                                 mapping::MapFileExtension(src.format), src.tree_nodes));
    line("leaves", fmt::format("{} occupied, {} free ({} coarser than one voxel, expanded)",
                               src.occupied_leaves, src.free_leaves, src.coarse_leaves));
    if (src.tree_type == "ColorOcTree") {
      line("colours", fmt::format("{} occupied voxels in a class colour (read as that class), {} "
                                  "in avp's unlabelled grey, {} in other colours (unlabelled)",
                                  src.labelled_by_colour, src.unlabelled_grey, src.foreign_colour));
    }
    for (const std::string& lost : src.lost) line("not kept", lost);
  }
  if (!src.extension_note.empty()) line("note", src.extension_note);
  // The note is the file's text: escaped, so that a crafted map cannot reach the terminal.
  if (!info.file.note.empty()) line("made by", EscapeText(info.file.note, 1000));
  line("voxel size", fmt::format("{:g} mm", g.voxel_size_m * 1000.0));
  line("lattice", "voxel k covers [k s, (k + 1) s) on each axis (a voxel corner at the origin)");
  line("ROI", g.roi ? fmt::format("{} - {} m", FormatPoint(g.roi->min()), FormatPoint(g.roi->max()))
                    : std::string("none"));
  if (!octomap) {
    line("sensor model",
         fmt::format("hit {:g}, miss {:g}, clamp [{:g}, {:g}], occupied at p >= {:g}", g.sensor.hit,
                     g.sensor.miss, g.sensor.clamp_min, g.sensor.clamp_max,
                     g.sensor.occupied_threshold));
    if (s.policy == mapping::FusionPolicy::kReferenceMax) {
      line("fusion",
           fmt::format("{} (penalty {:g})", mapping::ToString(s.policy), s.reference_penalty));
    } else {
      line("fusion", fmt::format("{} (class log-odds [{:g}, {:g}], miss {:g}, label at p >= {:g})",
                                 mapping::ToString(s.policy), s.class_log_odds_min,
                                 s.class_log_odds_max, s.miss_log_odds, s.label_threshold));
    }
  }
  line("blocks",
       fmt::format("{} of 8^3 voxels ({} with semantics)", info.blocks, info.semantic_blocks));
  line("voxels", fmt::format("{} known: {} free, {} occupied; {} labelled", info.known_voxels,
                             info.free_voxels, info.occupied_voxels, info.labelled_voxels));
  std::string classes;
  for (SemanticClass c : AllSemanticClasses()) {
    const auto i = static_cast<size_t>(c);
    if (info.labelled_by_class[i] == 0) continue;
    if (!classes.empty()) classes += ", ";
    classes += fmt::format("{} {} ({} occupied)", ToString(c), info.labelled_by_class[i],
                           info.occupied_by_class[i]);
  }
  line("labels", classes.empty() ? std::string("none") : classes);
  line("bounds", info.known_bounds.IsEmpty()
                     ? std::string("empty")
                     : fmt::format("{} - {} m (known voxels)", FormatPoint(info.known_bounds.min()),
                                   FormatPoint(info.known_bounds.max())));
  line("memory", HumanBytes(info.memory_bytes) + " (blocks, semantic payload, hash table)");
  line("instances", std::to_string(info.instances.size()));
  if (!info.instances.empty()) {
    out += fmt::format("  {:>5}  {:<8} {:>7}  {:<26} {}\n", "id", "class", "voxels", "centroid (m)",
                       "mean confidence");
    for (const mapping::InstanceInfo& inst : info.instances) {
      out += fmt::format("  {:>5}  {:<8} {:>7}  {:<26} {:.3f}\n", inst.id,
                         ToString(inst.semantic_class), inst.voxels, FormatPoint(inst.centroid_W),
                         inst.mean_confidence);
    }
  }
  return out;
}

// ---- export
// --------------------------------------------------------------------------------------

std::optional<MapExportFormat> MapExportFormatFromString(std::string_view name) {
  if (name == "bt") return MapExportFormat::kBt;
  if (name == "ot") return MapExportFormat::kOt;
  if (name == "ply") return MapExportFormat::kPly;
  if (name == "avpmap") return MapExportFormat::kAvpMap;
  return std::nullopt;
}

Result<MapExportSummary> RunMapExport(const MapExportOptions& options) {
  if (options.out.empty()) return InvalidArgumentError("give the output file with --out");
  std::string format = options.format;
  if (format.empty()) {
    format = options.out.extension().string();
    if (!format.empty() && format[0] == '.') format.erase(0, 1);
  }
  const std::optional<MapExportFormat> f = MapExportFormatFromString(format);
  if (!f) {
    return InvalidArgumentError(fmt::format(
        "unknown export format {} (from {}): use avpmap, bt, ot or ply", QuoteText(format),
        options.format.empty() ? "the extension of --out" : "--format"));
  }
  // Outputs never overwrite inputs: `map export X --out X` would replace the map it reads.
  AVP_RETURN_IF_ERROR(
      io::CheckOutputIsNotInput(options.out, "export file (--out)", options.map, "map file"));
  AVP_RETURN_IF_ERROR(io::CheckReadableFile(options.map, "map file").status());
  AVP_ASSIGN_OR_RETURN(const mapping::LoadedMap loaded, mapping::LoadAnyMap(options.map));
  const mapping::SemanticMap& map = loaded.map;
  MapExportSummary summary;
  summary.format = *f;
  summary.out = options.out;
  summary.source = loaded.source;
  if (*f == MapExportFormat::kAvpMap) {
    mapping::MapSaveOptions save;
    save.note = fmt::format(
        "avp map export of {} ({}{})", options.map.filename().string(),
        mapping::ToString(loaded.source.format),
        loaded.source.tree_type.empty() ? std::string() : ", " + loaded.source.tree_type);
    if (loaded.source.format == mapping::MapFileFormat::kAvpMap &&
        !loaded.source.avpmap.note.empty()) {
      save.note += "; made by: " + loaded.source.avpmap.note;
    }
    if (save.note.size() > mapping::kMaxMapNoteBytes) save.note.resize(mapping::kMaxMapNoteBytes);
    AVP_RETURN_IF_ERROR(mapping::SaveMap(map, options.out, save));
    summary.occupied_voxels = map.grid().CountOccupiedVoxels();
    summary.free_voxels = map.grid().CountKnownVoxels() - summary.occupied_voxels;
    summary.labelled_voxels = map.grid().CountSemanticVoxels();
    std::error_code ec;
    summary.file_bytes = fs::file_size(options.out, ec);
    return summary;
  }
  if (*f == MapExportFormat::kPly) {
    mapping::PlyExportOptions ply;
    ply.binary = !options.ply_ascii;
    ply.occupied_only = !options.ply_all_labelled;
    AVP_ASSIGN_OR_RETURN(const mapping::PlyExportStats stats,
                         mapping::ExportSemanticPly(map.grid(), options.out, ply));
    summary.labelled_voxels = stats.vertices;
    summary.file_bytes = stats.file_bytes;
    return summary;
  }
  AVP_ASSIGN_OR_RETURN(const mapping::OctomapExportStats stats,
                       *f == MapExportFormat::kBt
                           ? mapping::ExportOctomapBinary(map.grid(), options.out)
                           : mapping::ExportOctomapColor(map, options.out));
  summary.occupied_voxels = stats.occupied_voxels;
  summary.free_voxels = stats.free_voxels;
  summary.labelled_voxels = stats.labelled_voxels;
  summary.file_bytes = stats.file_bytes;
  return summary;
}

// ---- compare
// -------------------------------------------------------------------------------------

Result<MapCompareSummary> RunMapCompare(const MapCompareOptions& options) {
  mapping::GroundTruthCompareOptions compare;
  compare.tolerance_voxels = options.tolerance_voxels;
  compare.semantic_class = options.semantic_class;
  AVP_RETURN_IF_ERROR(compare.Validate());
  if (!options.json_out.empty()) {
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.json_out, "result file (--json)",
                                                  options.map, "map file"));
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.json_out, "result file (--json)",
                                                  options.gt, "ground truth file"));
  }
  AVP_RETURN_IF_ERROR(io::CheckReadableFile(options.map, "map file").status());
  AVP_RETURN_IF_ERROR(io::CheckReadableFile(options.gt, "ground truth file").status());
  AVP_ASSIGN_OR_RETURN(const mapping::LoadedMap loaded, mapping::LoadAnyMap(options.map));
  const mapping::SemanticMap& map = loaded.map;
  MapCompareSummary summary;
  summary.map_source = loaded.source;
  mapping::VoxelSet gt;
  {
    AVP_ASSIGN_OR_RETURN(const mapping::LoadedMap gt_map, mapping::LoadAnyMap(options.gt));
    gt = mapping::GroundTruthVoxels(gt_map, options.semantic_class, &summary.gt_used_labels);
    summary.gt_source = gt_map.source;
  }
  summary.map = options.map;
  summary.gt = options.gt;
  summary.semantic_class = options.semantic_class;
  summary.gt_occupied_leaves = gt.occupied_leaves;
  summary.gt_coarse_leaves = gt.coarse_leaves;
  std::vector<int> tolerances = {0};
  if (options.tolerance_voxels > 0) tolerances.push_back(options.tolerance_voxels);
  for (int t : tolerances) {
    compare.tolerance_voxels = t;
    AVP_ASSIGN_OR_RETURN(mapping::GroundTruthComparison r,
                         mapping::CompareToGroundTruth(map.grid(), gt, compare));
    summary.results.push_back(r);
  }
  // Lattice check: the best exact F1 over the 26 one-voxel shifts of the prediction.
  {
    const mapping::OccupancyGrid& grid = map.grid();
    std::vector<VoxelKey> gt_keys;
    gt_keys.reserve(gt.keys.size());
    for (const VoxelKey& k : gt.keys) {
      gt_keys.push_back(summary.results.front().resampled ? grid.KeyOf(k.Center(gt.resolution_m))
                                                          : k);
    }
    const std::vector<VoxelKey> predicted =
        mapping::OccupiedVoxelsOfClass(grid, options.semantic_class);
    std::vector<VoxelKey> shifted(predicted.size());
    for (int dz = -1; dz <= 1; ++dz) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0 && dz == 0) continue;
          for (size_t i = 0; i < predicted.size(); ++i) {
            shifted[i] = VoxelKey{predicted[i].x + dx, predicted[i].y + dy, predicted[i].z + dz};
          }
          const double f1 = mapping::CompareVoxelSets(shifted, gt_keys, 0).f1;
          if (f1 > summary.best_shift_f1) {
            summary.best_shift_f1 = f1;
            summary.best_shift = VoxelKey{dx, dy, dz};
          }
        }
      }
    }
  }
  if (!options.json_out.empty()) {
    AVP_RETURN_IF_ERROR(io::WriteJsonFile(options.json_out, ToJson(summary)));
  }
  return summary;
}

std::string FormatMapCompare(const MapCompareSummary& s) {
  std::string out;
  const mapping::GroundTruthComparison& first = s.results.front();
  const auto describe = [](const mapping::MapSource& src) {
    return src.tree_type.empty()
               ? std::string(mapping::ToString(src.format))
               : fmt::format("{} {}", mapping::ToString(src.format), EscapeText(src.tree_type, 64));
  };
  out += fmt::format("map          {} ({}, {:g} mm voxels)\n", s.map.string(),
                     describe(s.map_source), first.map_resolution_m * 1000.0);
  if (s.gt_used_labels) {
    out += fmt::format("ground truth {} ({}, {:g} mm voxels, {} occupied voxels labelled {})\n",
                       s.gt.string(), describe(s.gt_source), first.gt_resolution_m * 1000.0,
                       first.gt_voxels_original, ToString(s.semantic_class));
  } else {
    out += fmt::format(
        "ground truth {} ({}, {:g} mm voxels, {} occupied voxels from {} leaves, {} of "
        "them pruned)\n",
        s.gt.string(), describe(s.gt_source), first.gt_resolution_m * 1000.0,
        first.gt_voxels_original, s.gt_occupied_leaves, s.gt_coarse_leaves);
  }
  out +=
      "lattice      both sides: voxel k covers [k s, (k + 1) s) on each axis (a corner at the "
      "origin)\n";
  if (!s.map_source.extension_note.empty()) {
    out += fmt::format("note         map: {}\n", s.map_source.extension_note);
  }
  if (!s.gt_source.extension_note.empty()) {
    out += fmt::format("note         ground truth: {}\n", s.gt_source.extension_note);
  }
  if (first.resampled) {
    out += fmt::format(
        "warning      resolutions differ (map {:g} mm, ground truth {:g} mm): GT voxel centres "
        "were mapped onto the map's {:g} mm lattice ({} GT voxels -> {}), so the exact scores "
        "also measure the resampling; for exact scores build the map at the GT's resolution "
        "(avp map build --voxel-size {:g})\n",
        first.map_resolution_m * 1000.0, first.gt_resolution_m * 1000.0,
        first.map_resolution_m * 1000.0, first.gt_voxels_original, first.ground_truth,
        first.gt_resolution_m);
  }
  out += fmt::format("predicted    {} occupied voxels labelled {}\n", first.predicted,
                     ToString(s.semantic_class));
  out += fmt::format("{:<12} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}\n", "tolerance", "TP", "FP",
                     "GT found", "FN", "precision", "recall", "F1");
  for (const mapping::GroundTruthComparison& r : s.results) {
    out += fmt::format("{:<12} {:>9} {:>9} {:>9} {:>9} {:>9.4f} {:>9.4f} {:>9.4f}\n",
                       r.tolerance_voxels == 0 ? std::string("exact")
                                               : fmt::format("+-{} voxel", r.tolerance_voxels),
                       r.tp, r.fp, r.gt_found, r.fn, r.precision, r.recall, r.f1);
  }
  if (first.predicted > 0 && first.ground_truth > 0) {
    out += fmt::format(
        "lattice check: the best one-voxel shift of the map, ({:+d}, {:+d}, {:+d}), gives exact "
        "F1 {:.4f} (unshifted {:.4f})\n",
        s.best_shift.x, s.best_shift.y, s.best_shift.z, s.best_shift_f1, first.f1);
    const mapping::GroundTruthComparison& last = s.results.back();
    if (last.tolerance_voxels > 0 && last.precision >= 0.95 && first.precision < 0.8) {
      out += fmt::format(
          "note         {:.0f} % of the predicted voxels lie within {} voxel(s) of the ground "
          "truth but only {:.0f} % on it: the two sides mark the same surfaces on different "
          "lattices or by different rules (resolution, a sub-voxel offset, solid vs surface); "
          "exact scores then measure that difference, tolerant ones the map (docs/evaluation.md, "
          "Comparing with another system's ground truth)\n",
          100.0 * last.precision, last.tolerance_voxels, 100.0 * first.precision);
    }
    if (s.best_shift_f1 >= first.f1 + 0.1) {
      out +=
          "warning      a one-voxel shift raises exact F1 by 0.1 or more: the two surfaces sit "
          "about a voxel apart (different frames, lattices or surface definitions); exact F1 "
          "is not comparable here, see docs/evaluation.md (Comparing with another system's "
          "ground truth)\n";
    }
  }
  out +=
      "TP: predicted voxels with a GT voxel within the tolerance (FP = predicted - TP); GT found: "
      "GT voxels with a predicted voxel within it (FN = GT - found). precision = TP / predicted, "
      "recall = found / GT.\n";
  return out;
}

nlohmann::json ToJson(const MapCompareSummary& s) {
  nlohmann::json results = nlohmann::json::array();
  for (const mapping::GroundTruthComparison& r : s.results) {
    results.push_back({{"tolerance_voxels", r.tolerance_voxels},
                       {"predicted", r.predicted},
                       {"ground_truth", r.ground_truth},
                       {"tp", r.tp},
                       {"fp", r.fp},
                       {"gt_found", r.gt_found},
                       {"fn", r.fn},
                       {"precision", r.precision},
                       {"recall", r.recall},
                       {"f1", r.f1}});
  }
  const mapping::GroundTruthComparison& first = s.results.front();
  return {{"map", s.map.string()},
          {"ground_truth", s.gt.string()},
          {"class", std::string(ToString(s.semantic_class))},
          {"map_resolution_m", first.map_resolution_m},
          {"gt_resolution_m", first.gt_resolution_m},
          {"resampled", first.resampled},
          {"gt_voxels_original", first.gt_voxels_original},
          {"gt_occupied_leaves", s.gt_occupied_leaves},
          {"gt_coarse_leaves", s.gt_coarse_leaves},
          {"map_format", std::string(mapping::ToString(s.map_source.format))},
          {"gt_format", std::string(mapping::ToString(s.gt_source.format))},
          {"gt_tree_type", s.gt_source.tree_type},
          {"gt_used_labels", s.gt_used_labels},
          {"best_one_voxel_shift", {s.best_shift.x, s.best_shift.y, s.best_shift.z}},
          {"best_one_voxel_shift_exact_f1", s.best_shift_f1},
          {"definitions",
           "tp: predicted voxels with a GT voxel within the tolerance cube; fp = predicted - tp; "
           "gt_found: GT voxels with a predicted voxel within it; fn = ground_truth - gt_found; "
           "precision = tp / predicted; recall = gt_found / ground_truth"},
          {"results", results}};
}

// ---- Reports printed by the commands -------------------------------------------------------

namespace {

int MapBuildAndReport(const MapBuildOptions& options, const sim::ScenarioRegistry& scenarios) {
  MapBuildOptions o = options;
  // Each view's line ends with the rate, the time elapsed and the time left (report::Progress's
  // words).
  const auto t0 = std::chrono::steady_clock::now();
  o.on_view = [t0](const MapBuildView& v) {
    const Eigen::Vector3d eye = v.X_WC.translation();
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::string progress = report::FormatProgressTimes(
        static_cast<size_t>(v.index + 1), static_cast<size_t>(std::max(v.views, 0)), elapsed);
    std::printf(
        "view %d/%d  azimuth %6.1f deg  eye (%.3f, %.3f, %.3f)  %zu endpoints, %zu fruit px in "
        "%zu masks -> known %zu, occupied %zu, labelled %zu, instances %zu  (render %.0f ms, "
        "integrate %.0f ms)  %s\n",
        v.index + 1, v.views, v.azimuth_deg, eye.x(), eye.y(), eye.z(), v.stats.endpoints,
        v.fruit_pixels, v.masks, v.known_voxels, v.occupied_voxels, v.labelled_voxels, v.instances,
        v.render_ms, v.integrate_ms, progress.c_str());
    std::fflush(stdout);
  };
  const auto result = RunMapBuild(o, scenarios);
  if (!result.ok()) return Failed("map build", result.status());
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

int MapGtAndReport(const MapGtOptions& options, const sim::ScenarioRegistry& scenarios) {
  const auto result = RunMapGt(options, scenarios);
  if (!result.ok()) return Failed("map gt", result.status());
  std::printf("wrote %s: %zu fruit surface voxels of %zu fruits of '%s' at %g mm (%llu bytes)\n",
              options.out.string().c_str(), result->voxels, result->fruits,
              result->scene_name.c_str(), options.voxel_size_m * 1000.0,
              static_cast<unsigned long long>(result->file_bytes));
  return 0;
}

int MapInfoAndReport(const std::string& path) {
  const auto result = RunMapInfo(path);
  if (!result.ok()) return Failed("map info", result.status());
  std::fputs(FormatMapInfo(*result).c_str(), stdout);
  return 0;
}

int MapExportAndReport(const MapExportOptions& options) {
  const auto result = RunMapExport(options);
  if (!result.ok()) return Failed("map export", result.status());
  const auto& s = *result;
  if (s.format == MapExportFormat::kPly) {
    std::printf("wrote %s: %zu labelled voxels (%llu bytes)\n", s.out.string().c_str(),
                s.labelled_voxels, static_cast<unsigned long long>(s.file_bytes));
  } else {
    std::printf("wrote %s: %zu occupied and %zu free voxels%s (%llu bytes)\n",
                s.out.string().c_str(), s.occupied_voxels, s.free_voxels,
                s.format == MapExportFormat::kOt
                    ? fmt::format(", {} coloured by class", s.labelled_voxels).c_str()
                : s.format == MapExportFormat::kAvpMap
                    ? fmt::format(", {} labelled", s.labelled_voxels).c_str()
                    : "",
                static_cast<unsigned long long>(s.file_bytes));
  }
  if (s.source.format != mapping::MapFileFormat::kAvpMap) {
    std::printf("read %s as OctoMap %s %s; not kept:\n", options.map.string().c_str(),
                EscapeText(s.source.tree_type, 64).c_str(),
                std::string(mapping::MapFileExtension(s.source.format)).c_str());
    for (const std::string& lost : s.source.lost) std::printf("  - %s\n", lost.c_str());
  }
  return 0;
}

int MapCompareAndReport(const MapCompareOptions& options) {
  const auto result = RunMapCompare(options);
  if (!result.ok()) return Failed("map compare", result.status());
  std::fputs(FormatMapCompare(*result).c_str(), stdout);
  if (!options.json_out.empty()) std::printf("wrote %s\n", options.json_out.string().c_str());
  return 0;
}

// ---- The command line ---------------------------------------------------------------------------

struct MapBuildCli {
  MapBuildOptions options;
  std::string out = MapBuildOptions{}.out.string();
  std::string scene_file;
  std::string policy, carving;
  double voxel_size_m = 0.0;
  std::vector<std::string> map_options;
  CLI::Option* voxel_opt = nullptr;
};

/// The map options of `avp map build`: the library's defaults, the shorthands given, then
/// --map-option KEY=VALUE.
Status ResolveBuildOptions(const MapBuildCli& cli, MapBuildOptions& o) {
  if (cli.voxel_opt->count() > 0) o.map.grid.voxel_size_m = cli.voxel_size_m;
  if (!cli.policy.empty()) {
    AVP_RETURN_IF_ERROR(mapping::MapOptionTable().Set(o.map, "semantics.policy", cli.policy));
  }
  if (!cli.carving.empty()) {
    AVP_RETURN_IF_ERROR(mapping::IntegratorOptionTable().Set(o.integrator, "carving", cli.carving));
  }
  AVP_ASSIGN_OR_RETURN(const OptionValues values, ParseKeyValues(cli.map_options, "map option"));
  AVP_RETURN_IF_ERROR(mapping::MapOptionTable().SetAll(o.map, values));
  o.out = cli.out;
  o.scene.scene_file = cli.scene_file;
  return Status::Ok();
}

void AddMapBuild(CLI::App& map_cmd, CommandContext& context) {
  auto cli = std::make_shared<MapBuildCli>();
  MapBuildOptions& b = cli->options;
  CLI::App* cmd = map_cmd.add_subcommand(
      "build", "Render views on an arc around a simulated plant, fuse them and save the map");
  cmd->add_option("--scenario", b.scene.scenario,
                  "Built-in scenario name (see `avp scenes`); default: " +
                      std::string(sim::DefaultScenarioName()));
  cmd->add_option("--scene", cli->scene_file,
                  "YAML scene file instead of a scenario (docs/scene-format.md)");
  AddArrangementOption(*cmd, b.scene.arrangement);
  AddNumberOption(*cmd, "--seed", b.scene.seed, uint64_t{0}, MaxOf<uint64_t>(),
                  "Seed of the procedural plant and the noise");
  AddNumberOption(*cmd, "--views", b.views, 1, 360, "Number of views");
  cli->voxel_opt = AddNumberOption(*cmd, "--voxel-size", cli->voxel_size_m, 0.0, 1e6,
                                   "Voxel edge in metres (map option grid.voxel_size_m)")
                       ->default_str(fmt::format("{}", b.map.grid.voxel_size_m));
  cmd->add_option("--policy", cli->policy, "Semantic fusion (map option semantics.policy)")
      ->check(CLI::IsMember({"reference-max", "bayesian"}))
      ->default_str(std::string(mapping::ToString(b.map.semantics.policy)));
  cmd->add_option("--carving", cli->carving, "Free-space carving")
      ->check(CLI::IsMember({"raycast", "projective", "none"}))
      ->default_str(std::string(mapping::ToString(b.integrator.carving)));
  AddKeyValueOption(*cmd, "--map-option", cli->map_options,
                    "Map option over the defaults (repeatable): grid.voxel_size_m, "
                    "grid.sensor.hit, semantics.policy, ... (docs/mapping.md)");
  AddNumberOption(*cmd, "--arc-deg", b.arc_deg, 0.0, 360.0,
                  "Arc of view azimuths around the plant, centred on the start view "
                  "(360 = full ring)");
  AddNumberOption(*cmd, "--radius", b.radius_m, 0.0, 3.0,
                  "Horizontal camera distance from the plant centre, m (0 = the start camera's)");
  AddNumberOption(*cmd, "--threads", b.threads, 0, experiment::kMaxThreads,
                  "Integrator threads (0 = all)");
  cmd->add_flag("--noise", b.noise, "Apply the seeded D435-like depth noise model");
  cmd->add_option("--out", cli->out, "Output map file (.avpmap)")->default_val(cli->out);
  cmd->callback([cli, &context] {
    RunGuarded(context, [&] {
      MapBuildOptions o = cli->options;
      if (const Status s = ResolveBuildOptions(*cli, o); !s.ok()) return Failed("map build", s);
      return MapBuildAndReport(o, context.registries->scenarios);
    });
  });
}

void AddMapGt(CLI::App& map_cmd, CommandContext& context) {
  auto gt = std::make_shared<MapGtOptions>();
  auto out = std::make_shared<std::string>(gt->out.string());
  auto scene_file = std::make_shared<std::string>();
  CLI::App* cmd = map_cmd.add_subcommand(
      "gt",
      "Write the fruit surface voxels of a scenario or scene file as an OctoMap .bt ground truth");
  cmd->add_option("--scenario", gt->scene.scenario, "Built-in scenario name");
  cmd->add_option("--scene", *scene_file,
                  "YAML scene file instead of a scenario (docs/scene-format.md)");
  AddArrangementOption(*cmd, gt->scene.arrangement);
  AddNumberOption(*cmd, "--seed", gt->scene.seed, uint64_t{0}, MaxOf<uint64_t>(),
                  "Seed of the procedural plant");
  AddNumberOption(*cmd, "--voxel-size", gt->voxel_size_m, 0.0, 1e6, "Voxel edge in metres");
  cmd->add_option("--out", *out, "Output .bt file")->default_val(*out);
  cmd->callback([gt, out, scene_file, &context] {
    RunGuarded(context, [&] {
      MapGtOptions o = *gt;
      o.out = *out;
      o.scene.scene_file = *scene_file;
      return MapGtAndReport(o, context.registries->scenarios);
    });
  });
}

void AddMapInfo(CLI::App& map_cmd, CommandContext& context) {
  auto file = std::make_shared<std::string>();
  CLI::App* cmd =
      map_cmd.add_subcommand("info", "Describe a map file (.avpmap, OctoMap .bt / .ot)");
  cmd->add_option("file", *file, "Map file: .avpmap, .bt or .ot (told apart by content)")
      ->required();
  cmd->callback([file, &context] { RunGuarded(context, [&] { return MapInfoAndReport(*file); }); });
}

struct MapExportCli {
  MapExportOptions options;
  std::string map, out;
};

void AddMapExport(CLI::App& map_cmd, CommandContext& context) {
  auto cli = std::make_shared<MapExportCli>();
  CLI::App* cmd = map_cmd.add_subcommand(
      "export",
      "Convert a map file (.avpmap, .bt, .ot) to OctoMap (.bt occupancy, .ot coloured by class), "
      "PLY or avp's .avpmap");
  cmd->add_option("file", cli->map, "Map file: .avpmap, .bt or .ot (told apart by content)")
      ->required();
  cmd->add_option("--format", cli->options.format, "avpmap, bt, ot or ply (default: from --out)")
      ->check(CLI::IsMember({"avpmap", "bt", "ot", "ply"}));
  cmd->add_option("--out", cli->out, "Output file")->required();
  cmd->add_flag("--ascii", cli->options.ply_ascii, "PLY: ASCII instead of binary little-endian");
  cmd->add_flag("--all-labelled", cli->options.ply_all_labelled,
                "PLY: every labelled voxel, not only occupied ones");
  cmd->callback([cli, &context] {
    RunGuarded(context, [&] {
      MapExportOptions o = cli->options;
      o.map = cli->map;
      o.out = cli->out;
      return MapExportAndReport(o);
    });
  });
}

struct MapCompareCli {
  MapCompareOptions options;
  std::string map, gt, json, semantic_class = "fruit";
};

void AddMapCompare(CLI::App& map_cmd, CommandContext& context) {
  auto cli = std::make_shared<MapCompareCli>();
  CLI::App* cmd = map_cmd.add_subcommand(
      "compare", "Precision / recall / F1 of a map's labelled voxels against a ground truth");
  cmd->add_option("file", cli->map,
                  "Map file: .avpmap, .bt or .ot (a ColorOcTree in class colours)")
      ->required();
  cmd->add_option("--gt", cli->gt,
                  "Ground truth: .bt / OcTree .ot (its occupied voxels) or a labelled .avpmap / "
                  "ColorOcTree .ot (its voxels of --class)")
      ->required();
  AddNumberOption(*cmd, "--tolerance-voxels", cli->options.tolerance_voxels, 0, MaxOf<int>(),
                  "Also report matches within this many map voxels (0 = exact only)");
  cmd->add_option("--class", cli->semantic_class, "Class of the predicted voxels")
      ->default_val(cli->semantic_class);
  cmd->add_option("--json", cli->json, "Also write the result as JSON to this file");
  cmd->callback([cli, &context] {
    RunGuarded(context, [&] {
      const auto cls = SemanticClassFromString(cli->semantic_class);
      if (!cls) {
        return Failed("map compare",
                      InvalidArgumentError(fmt::format("unknown class {} for --class",
                                                       QuoteText(cli->semantic_class))));
      }
      MapCompareOptions o = cli->options;
      o.map = cli->map;
      o.gt = cli->gt;
      o.json_out = cli->json;
      o.semantic_class = *cls;
      return MapCompareAndReport(o);
    });
  });
}

}  // namespace

void AddMapCommand(CLI::App& app, CommandContext& context) {
  CLI::App* cmd = app.add_subcommand(
      "map", "Semantic occupancy maps: build from simulated views, inspect, export, compare");
  cmd->require_subcommand(1);
  AddMapBuild(*cmd, context);
  AddMapGt(*cmd, context);
  AddMapInfo(*cmd, context);
  AddMapExport(*cmd, context);
  AddMapCompare(*cmd, context);
}

}  // namespace avp::apps

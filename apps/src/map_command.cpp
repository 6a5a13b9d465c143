#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/core/options.h>
#include <avp/core/text.h>
#include <avp/experiment/map_build.h>
#include <avp/experiment/output_folder.h>
#include <avp/experiment/run_config.h>
#include <avp/mapping/map_tools.h>
#include <avp/report/progress.h>

#include "cli_common.h"
#include "commands.h"

namespace avp::apps {

using experiment::MapBuildOptions;
using experiment::MapBuildView;
using experiment::MapGtOptions;
using mapping::MapCompareOptions;
using mapping::MapExportFormat;
using mapping::MapExportOptions;
using mapping::PlyVoxels;

// ---- Reports printed by the commands -------------------------------------------------------

namespace {

int MapBuildAndReport(const MapBuildOptions& options, const sim::ScenarioRegistry& scenarios) {
  MapBuildOptions o = options;
  o.on_scene = LogSceneWarnings;
  // Each view's line ends with the rate, the time elapsed and the time left (report::Progress's
  // words).
  const auto t0 = std::chrono::steady_clock::now();
  auto unit = std::make_shared<report::RateUnit>(report::RateUnit::kAuto);  // one per build
  o.on_view = [t0, unit](const MapBuildView& v) {
    const Eigen::Vector3d eye = v.X_WC.translation();
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::string progress =
        report::FormatProgressTimes(static_cast<size_t>(v.index + 1),
                                    static_cast<size_t>(std::max(v.views, 0)), elapsed, &*unit);
    std::printf(
        "view %d/%d  azimuth %6.1f deg  eye (%.3f, %.3f, %.3f)  %zu endpoints, %zu fruit px in "
        "%zu masks -> known %zu, occupied %zu, labelled %zu, instances %zu  (render %.0f ms, "
        "integrate %.0f ms)  %s\n",
        v.index + 1, v.views, v.azimuth_deg, eye.x(), eye.y(), eye.z(), v.stats.endpoints,
        v.fruit_pixels, v.masks, v.known_voxels, v.occupied_voxels, v.labelled_voxels, v.instances,
        v.render_ms, v.integrate_ms, progress.c_str());
    std::fflush(stdout);
  };
  const auto result = experiment::BuildMap(o, scenarios);
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
  MapGtOptions o = options;
  o.on_scene = LogSceneWarnings;
  const auto result = experiment::WriteGroundTruthOctree(o, scenarios);
  if (!result.ok()) return Failed("map gt", result.status());
  std::printf("wrote %s: %zu fruit surface voxels of %zu fruits of '%s' at %g mm (%llu bytes)\n",
              options.out.string().c_str(), result->voxels, result->fruits,
              result->scene_name.c_str(), options.voxel_size_m * 1000.0,
              static_cast<unsigned long long>(result->file_bytes));
  return 0;
}

int MapInfoAndReport(const std::string& path) {
  const auto result = mapping::ReadMapInfo(path);
  if (!result.ok()) return Failed("map info", result.status());
  std::fputs(mapping::FormatMapInfo(*result).c_str(), stdout);
  return 0;
}

/// What a PLY export wrote, by kind: "wrote plant.ply: 6369 occupied voxels, 1116 labelled in
/// class colours and 5253 unlabelled in grey (153135 bytes)".
std::string PlyExportLine(const mapping::MapExportSummary& s) {
  std::string what;
  switch (s.ply_voxels) {
    case PlyVoxels::kLabelled:
      what = fmt::format("{} labelled voxels", s.labelled_voxels);
      break;
    case PlyVoxels::kAllLabelled:
      what = fmt::format("{} labelled voxels, {} of them not occupied", s.labelled_voxels,
                         s.not_occupied_voxels);
      break;
    case PlyVoxels::kOccupied:
      what =
          fmt::format("{} occupied voxels, {} labelled in class colours and {} unlabelled in grey",
                      s.occupied_voxels, s.labelled_voxels, s.unlabelled_voxels);
      break;
  }
  return fmt::format("wrote {}: {} ({} bytes)\n", s.out.string(), what, s.file_bytes);
}

int MapExportAndReport(const MapExportOptions& options) {
  const auto result = mapping::ExportMapFile(options);
  if (!result.ok()) return Failed("map export", result.status());
  const auto& s = *result;
  if (s.format == MapExportFormat::kPly) {
    std::fputs(PlyExportLine(s).c_str(), stdout);
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
  const auto result = mapping::CompareMapFiles(options);
  if (!result.ok()) return Failed("map compare", result.status());
  std::fputs(mapping::FormatMapCompare(*result).c_str(), stdout);
  if (!options.json_out.empty()) std::printf("wrote %s\n", options.json_out.string().c_str());
  return 0;
}

// ---- The command line ---------------------------------------------------------------------------

struct MapBuildCli {
  MapBuildOptions options;
  SceneFlags scene;
  std::string out = MapBuildOptions{}.out.string();
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
  o.scene = cli.scene.Source();
  return Status::Ok();
}

void AddMapBuild(CLI::App& map_cmd, CommandContext& context) {
  auto cli = std::make_shared<MapBuildCli>();
  MapBuildOptions& b = cli->options;
  CLI::App* cmd = map_cmd.add_subcommand(
      "build", "Render views on an arc around a simulated plant, fuse them and save the map");
  AddSceneFlags(*cmd, cli->scene, "Seed of the procedural plant and the noise");
  AddNumberOption(*cmd, "--views", b.views, 1, 360, "Number of views");
  cli->voxel_opt = AddVoxelSizeOption(*cmd, cli->voxel_size_m);
  cmd->add_option("--policy", cli->policy, "Semantic fusion (map option semantics.policy)")
      ->check(CLI::IsMember({"reference-max", "bayesian"}))
      ->default_str(std::string(mapping::ToString(b.map.semantics.policy)));
  cmd->add_option("--carving", cli->carving, "Free-space carving")
      ->check(CLI::IsMember(mapping::FreeSpaceCarvingNames()))
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
  cmd->add_flag("--noise,!--no-noise", b.noise,
                "The seeded D435-like depth noise model (on by default, as in avp run; --no-noise: "
                "noise-free depth)");
  cmd->add_option("--out", cli->out, "Output map file (.avpmap)")->default_val(cli->out);
  cmd->add_flag("--force", cli->options.force, "Replace an existing --out file");
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
  auto scene = std::make_shared<SceneFlags>();
  CLI::App* cmd = map_cmd.add_subcommand(
      "gt",
      "Write the fruit surface voxels of a scenario or scene file as an OctoMap .bt ground truth");
  AddSceneFlags(*cmd, *scene, "Seed of the procedural plant");
  AddVoxelSizeOption(*cmd, gt->voxel_size_m);
  cmd->add_option("--out", *out, "Output .bt file")->default_val(*out);
  cmd->add_flag("--force", gt->force, "Replace an existing --out file");
  cmd->callback([gt, out, scene, &context] {
    RunGuarded(context, [&] {
      MapGtOptions o = *gt;
      o.out = *out;
      o.scene = scene->Source();
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
  std::string voxels = std::string(mapping::ToString(PlyVoxels::kLabelled));
  bool all_labelled = false;
  bool force = false;
};

/// --voxels NAME, or --all-labelled (its older spelling of `--voxels all-labelled`).
void AddPlyVoxelsOptions(CLI::App& cmd, MapExportCli& cli) {
  CLI::Option* voxels =
      cmd.add_option("--voxels", cli.voxels,
                     "PLY: which voxels. labelled: the occupied labelled ones; all-labelled: every "
                     "labelled one, occupied or not; occupied: every occupied one (the whole "
                     "plant), labelled ones in class colours, unlabelled ones in grey")
          ->check(CLI::IsMember({"labelled", "all-labelled", "occupied"}))
          ->default_str(cli.voxels);
  cmd.add_flag("--all-labelled", cli.all_labelled, "PLY: the same as --voxels all-labelled")
      ->excludes(voxels);
}

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
  cmd->add_flag("--force", cli->force, "Replace an existing --out file");
  cmd->add_flag("--ascii", cli->options.ply_ascii, "PLY: ASCII instead of binary little-endian");
  AddPlyVoxelsOptions(*cmd, *cli);
  cmd->callback([cli, &context] {
    RunGuarded(context, [&] {
      MapExportOptions o = cli->options;
      o.map = cli->map;
      o.out = cli->out;
      const std::optional<PlyVoxels> voxels = mapping::PlyVoxelsFromString(cli->voxels);
      if (!voxels) {
        return Failed("map export",
                      InvalidArgumentError(
                          fmt::format("unknown --voxels {}: use labelled, all-labelled or occupied",
                                      QuoteText(cli->voxels))));
      }
      o.ply_voxels = cli->all_labelled ? PlyVoxels::kAllLabelled : *voxels;
      // The output rule of every command that writes (experiment/output_folder.h).
      if (Status s = experiment::CheckOutputFile(o.out, cli->force); !s.ok()) {
        return Failed("map export", s);
      }
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

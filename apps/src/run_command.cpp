// avp run: one simulated active-vision episode into a run folder (docs/experiments.md).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <avp/experiment/run_config.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/options_yaml.h>
#include <avp/io/yaml.h>
#include <avp/report/progress.h>
#include <avp/report/run_report.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>

#include "cli_common.h"
#include "run_cli.h"

namespace avp::apps {

namespace {

/// Sets `key` from a shorthand flag when the flag was given.
Status ApplyIfGiven(const CLI::App& cmd, const char* flag, experiment::RunConfig& config,
                    std::string_view key, const std::string& value) {
  if (cmd.get_option(flag)->count() == 0) return Status::Ok();
  return experiment::SetRunConfigKey(config, key, value);
}

/// KEY=VALUE items of a --<section>-option flag, each set as "<prefix>KEY".
Status ApplyKeyValues(const std::vector<std::string>& items, std::string_view what,
                      std::string_view prefix, experiment::RunConfig& c) {
  AVP_ASSIGN_OR_RETURN(const OptionValues values, ParseKeyValues(items, what));
  for (const auto& [key, value] : values) {
    AVP_RETURN_IF_ERROR(experiment::SetRunConfigKey(c, std::string(prefix) + key, value));
  }
  return Status::Ok();
}

/// `--scenario` / `--scene` replace the scene source a --config named, and `--planner` naming
/// another planner drops the options the file gave the previous one (they were that planner's).
void ReplaceSourceAndPlanner(const CLI::App& cmd, const RunCli& cli, experiment::RunConfig& c) {
  if (cmd.get_option("--scenario")->count() > 0) {
    c.scene_file.clear();
    c.arrangement.clear();  // a scenario is arranged by its generator
  }
  if (cmd.get_option("--scene")->count() > 0) c.scenario.clear();
  if (cmd.get_option("--planner")->count() > 0 && cli.planner != c.planner.name) {
    c.planner.options.clear();
  }
}

/// `avp run` runs one episode: `--planners a,b` or `--scenarios a,b` (bench's spellings, accepted
/// as aliases) naming several is sent to `avp bench`.
Status CheckOneName(const CLI::App& cmd, const char* flag, const std::string& value) {
  if (cmd.get_option(flag)->count() == 0 || value.find(',') == std::string::npos) {
    return Status::Ok();
  }
  return InvalidArgumentError(
      fmt::format("{} {}: avp run runs one episode, with one of them; avp bench {}s {} runs "
                  "each of them",
                  flag, QuoteText(value), flag, EscapeText(value)));
}

Status ApplyShorthands(const CLI::App& cmd, const RunCli& cli, experiment::RunConfig& c) {
  AVP_RETURN_IF_ERROR(CheckOneName(cmd, "--planner", cli.planner));
  AVP_RETURN_IF_ERROR(CheckOneName(cmd, "--scenario", cli.scene.scenario));
  ReplaceSourceAndPlanner(cmd, cli, c);
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--scenario", c, "scenario", cli.scene.scenario));
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--scene", c, "scene_file", cli.scene.scene_file));
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--arrangement", c, "arrangement", cli.scene.arrangement));
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--seed", c, "seed", std::to_string(cli.scene.seed)));
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--planner", c, "planner.name", cli.planner));
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--gt", c, "ground_truth_file", cli.gt));
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--threads", c, "threads", std::to_string(cli.threads)));
  return ApplyKeyValues(cli.planner_options, "planner option", "planner.options.", c);
}

}  // namespace

Status ApplyEpisodeFlags(const CLI::App& cmd, const EpisodeFlags& flags, experiment::RunConfig& c) {
  if (cmd.get_option("--segmenter")->count() > 0 && flags.segmenter != c.segmenter.name) {
    c.segmenter.options.clear();  // they were the previous segmenter's
  }
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--segmenter", c, "segmenter.name", flags.segmenter));
  AVP_RETURN_IF_ERROR(
      ApplyIfGiven(cmd, "--views", c, "episode.views", std::to_string(flags.views)));
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--prompt", c, "episode.prompt", flags.prompt));
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--voxel-size", c, "map.grid.voxel_size_m",
                                   fmt::format("{}", flags.voxel_size_m)));
  AVP_RETURN_IF_ERROR(ApplyIfGiven(cmd, "--policy", c, "map.semantics.policy", flags.policy));
  AVP_RETURN_IF_ERROR(
      ApplyIfGiven(cmd, "--carving", c, "episode.integrator.carving", flags.carving));
  if (flags.no_noise) c.depth_noise.enabled = false;
  if (flags.oracle_regret) c.oracle_regret = true;
  if (flags.fuse_while_moving) c.episode.motion_fusion.enabled = true;
  AVP_RETURN_IF_ERROR(
      ApplyKeyValues(flags.segmenter_options, "segmenter option", "segmenter.options.", c));
  AVP_RETURN_IF_ERROR(ApplyKeyValues(flags.map_options, "map option", "map.", c));
  return ApplyKeyValues(flags.set, "--set item", "", c);
}

void AddEpisodeFlags(CLI::App& cmd, EpisodeFlags& flags) {
  const experiment::RunConfig d;
  cmd.add_option("--segmenter", flags.segmenter, "Segmenter; `--segmenter help` lists them")
      ->default_str(d.segmenter.name);
  AddNumberOption(cmd, "--views", flags.views, 0, MaxOf<int>(),
                  "Fused views per episode, start view included")
      ->default_str(std::to_string(d.episode.views));
  cmd.add_option("--prompt", flags.prompt, "Text prompt")->default_str(d.episode.prompt);
  AddVoxelSizeOption(cmd, flags.voxel_size_m);
  cmd.add_option("--policy", flags.policy, "Semantic fusion: bayesian or reference-max")
      ->default_str(std::string(mapping::ToString(d.map.semantics.policy)));
  cmd.add_option("--carving", flags.carving,
                 fmt::format("Free space: {}", fmt::join(mapping::FreeSpaceCarvingNames(), ", ")))
      ->default_str(std::string(mapping::ToString(d.episode.integrator.carving)));
  cmd.add_flag("--fuse-while-moving", flags.fuse_while_moving,
               fmt::format("Fuse the camera's frames taken while the arm moves between views "
                           "({} Hz; episode.motion_fusion.*, docs/sensing.md); off in the paper's "
                           "protocol, which counts views",
                           d.episode.motion_fusion.rate_hz));
  cmd.add_flag("--no-noise", flags.no_noise,
               "Noise-free depth (the seeded D435-like depth noise is on by default in every "
               "command)");
  AddKeyValueOption(cmd, "--segmenter-option", flags.segmenter_options,
                    "Segmenter option over its defaults (repeatable; `--segmenter help` lists "
                    "them)");
  AddKeyValueOption(cmd, "--map-option", flags.map_options,
                    "Map option (repeatable): grid.voxel_size_m, semantics.policy, ...");
  AddKeyValueOption(cmd, "--set", flags.set,
                    "Any key of the run configuration, as avp run --print-config names it "
                    "(repeatable)");
  cmd.add_flag("--oracle-regret", flags.oracle_regret,
               "Measure each plan step's regret and rank correlation with the truth (record.json "
               "oracle_regret; bench: summary.csv and summary.md per scenario); the episodes are "
               "unchanged, the plan times include it");
}

Result<experiment::CheckedRunConfig> ResolveConfig(const CLI::App& cmd, const RunCli& cli,
                                                   const experiment::Registries& registries,
                                                   const ConfigSection& section) {
  experiment::RunConfig c;
  c.motion.enabled = section.plan_motion;
  if (!cli.config_file.empty()) {
    AVP_ASSIGN_OR_RETURN(YAML::Node root, io::LoadYamlFile(cli.config_file));
    if (!section.name.empty() && root.IsMap() && root[section.name]) {
      if (section.node != nullptr) *section.node = YAML::Clone(root[section.name]);
      root.remove(section.name);
    }
    AVP_RETURN_IF_ERROR(experiment::ReadRunConfigYaml(root, cli.config_file, c));
  }
  AVP_RETURN_IF_ERROR(ApplyShorthands(cmd, cli, c));
  AVP_RETURN_IF_ERROR(ApplyEpisodeFlags(cmd, cli.episode, c));
  if (section.default_scene && c.scenario.empty() && c.scene_file.empty()) {
    c.scenario = std::string(sim::DefaultScenarioName());
  }
  // The one check of the configuration: what flows inward is valid (CheckedRunConfig).
  Result<experiment::CheckedRunConfig> checked =
      experiment::CheckedRunConfig::Check(std::move(c), registries);
  if (!checked.ok() && !cli.config_file.empty()) {
    return checked.status().WithContext(cli.config_file);
  }
  return checked;
}

void PrintStep(const pipeline::StepRecord& s) { PrintStepWithProgress(s, {}); }

void PrintStepWithProgress(const pipeline::StepRecord& s, std::string_view progress) {
  std::printf("%s\n", report::FormatStepLine(s, progress).c_str());
  std::fflush(stdout);
}

namespace {

/// The episode's moves: contacts with the true world (simulation), against what straight moves
/// would have hit, motion time and planning time per move (docs/motion.md).
void PrintMotionSummary(const pipeline::EpisodeResult& episode) {
  const pipeline::MotionTotals m = pipeline::SumMotion(episode);
  if (m.moves == 0) return;
  std::vector<double> ms = m.planning_ms;
  std::sort(ms.begin(), ms.end());
  const std::string contacts =
      m.contacts ? fmt::format("contacts {} (straight joint-space moves would have made {})",
                               m.contacts->total(),
                               m.straight_line_contacts ? m.straight_line_contacts->total() : 0)
                 : std::string("contacts unknown (no ground truth)");
  std::printf("motion: %d moves, %.1f s, %.2f rad; %s; planning %.0f ms median, %.0f ms max\n",
              m.moves, m.execution_s, m.path_length_rad, contacts.c_str(), ms[ms.size() / 2],
              ms.back());
  if (m.contacts && m.contacts->total() > 0)
    std::printf("  first contact: %s\n", m.contacts->first.c_str());
  if (episode.start_clearance && episode.start_clearance->broken()) {
    std::printf(
        "  start clearance broken: %s %.3f m apart at the start, inside the %.3f m the "
        "planner took as free (motion.collision.map.start_clearance_m and the field's cells)\n",
        episode.start_clearance->truth->nearest.c_str(), episode.start_clearance->truth->distance_m,
        episode.start_clearance->assumed_m);
  }
}

void PrintSummary(const experiment::RunConfig& config, const experiment::RunSummary& summary,
                  const std::filesystem::path& out_dir) {
  const experiment::RunResult& r = summary.result;
  std::printf(
      "%s with %s / %s, seed %llu: %d views (%s%s%s) in %.1f s; final F1 %.3f, fruits found "
      "%zu/%zu\n",
      summary.scene_name.c_str(), config.planner.name.c_str(), config.segmenter.name.c_str(),
      static_cast<unsigned long long>(config.seed), r.episode.views_fused(),
      std::string(pipeline::ToString(r.episode.end)).c_str(),
      r.episode.end_reason.empty() ? "" : ": ", r.episode.end_reason.c_str(), summary.seconds,
      r.final_metrics.exact.f1, r.final_metrics.fruits.found, r.final_metrics.fruits.total);
  for (const std::string& why : experiment::WhyNothingFound(config, r)) {
    std::printf("no fruit found: %s\n", why.c_str());
  }
  PrintMotionSummary(r.episode);
  if (!r.regret.empty()) {
    std::printf(
        "oracle regret per plan step (1 - true gain of the choice / best true gain; true "
        "rank of the choice; rank correlation of the gain with the true gain):\n");
    for (const eval::StepRegret& g : r.regret) {
      std::printf("  step %d: regret %.2f, rank %zu of %zu, correlation %.2f\n", g.step + 1,
                  g.regret, g.chosen_true_rank, g.candidates, g.rank_correlation);
    }
  }
  std::printf("wrote %zu files to %s:\n", summary.files.size(), out_dir.string().c_str());
  for (const auto& f : summary.files) std::printf("  %s\n", f.string().c_str());
}

int Run(const CLI::App& cmd, const RunCli& cli, const experiment::Registries& registries) {
  // `help` wherever a name is expected.
  if (int code = 0; PrintHelpForNames(registries, cli.scene.scenario, cli.planner,
                                      cli.episode.segmenter, &code)) {
    return code;
  }
  const Result<experiment::CheckedRunConfig> config = ResolveConfig(cmd, cli, registries);
  if (!config.ok()) return Failed("run", config.status());
  if (cli.print_config) {
    // Only a valid configuration is printed (ResolveConfig validates), so that --config reads
    // back whatever is printed.
    const Result<YAML::Node> yaml = experiment::RunConfigToYaml(**config, registries);
    if (!yaml.ok()) return Failed("run", yaml.status());
    std::fputs(io::YamlText(*yaml).c_str(), stdout);
    return 0;
  }
  experiment::RunFolderOptions options;
  // A scene file's warnings (placeholder materials, classes one colour shares ...) before the run,
  // from the scene the run loads (not a second load).
  options.on_scene = [](const sim::Scene& scene) { LogSceneWarnings(scene); };
  options.out_dir = cli.out;
  options.force = cli.force;
  options.record = cmd.count("--record") > 0;
  options.record_path = cli.record_file;
  options.record_compression = cli.record_compression;
  if (!cli.config_file.empty()) options.inputs.emplace_back(cli.config_file, "configuration file");
  // Each view's line ends with the rate, the time elapsed and the time left (report::Progress's
  // words), so that a long run shows how far it is.
  const auto t0 = std::chrono::steady_clock::now();
  // One rate unit for the whole run (the first view's).
  auto unit = std::make_shared<report::RateUnit>(report::RateUnit::kAuto);
  options.on_step = [t0, unit](const pipeline::StepRecord& s) {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    PrintStepWithProgress(s, report::FormatProgressTimes(
                                 static_cast<size_t>(s.view + 1),
                                 static_cast<size_t>(std::max(s.views_total, 0)), elapsed, &*unit));
  };
  const Result<experiment::RunSummary> summary = experiment::RunToFolder(*config, options);
  if (!summary.ok()) return Failed("run", summary.status());
  PrintSummary(**config, *summary, options.out_dir);
  // An episode cut short by its segmenter (a service that is down), or whose segmenter failed at
  // every view, is a failure of the command, its results saved.
  if (const Status failed = experiment::SegmenterFailure(summary->result); !failed.ok()) {
    return Failed("run", failed);
  }
  return 0;
}

}  // namespace

void AddRunOptions(CLI::App& cmd, RunCli& cli) {
  const experiment::RunConfig d;
  cmd.add_option("--config", cli.config_file,
                 "Run configuration YAML (as --print-config writes it); flags apply over it");
  cmd.add_flag("--print-config", cli.print_config,
               "Print the effective configuration as YAML (--config reads it back) and exit");
  // avp bench's plural spellings are accepted too (one name: avp run runs one episode).
  AddSceneFlags(cmd, cli.scene, "Seed of the plant, the noise and every choice",
                "--scenario,--scenarios");
  cmd.add_option("--planner,--planners", cli.planner,
                 "View planner; `--planner help` lists them, `--planner help:NAME` explains one")
      ->default_str(d.planner.name);
  AddEpisodeFlags(cmd, cli.episode);
  cmd.add_option(
      "--gt", cli.gt,
      "Ground truth from a map file instead of the observable fruit surface: an OctoMap .bt / .ot "
      "(its occupied voxels) or a labelled .avpmap / ColorOcTree .ot (its fruit voxels)");
  AddNumberOption(cmd, "--threads", cli.threads, 0, experiment::kMaxThreads,
                  "Threads (0 = all; results do not depend on it)");
  AddKeyValueOption(cmd, "--planner-option", cli.planner_options,
                    "Planner option over its defaults (repeatable; `--planner help` lists them)");
  cmd.add_option("--out", cli.out, "Run folder")->default_str(cli.out);
  cmd.add_flag("--force", cli.force,
               "Replace the results an earlier run left in --out (only an avp run folder)");
}

void AddRecordOption(CLI::App& cmd, RunCli& cli) {
  CLI::Option* record =
      cmd.add_option("--record", cli.record_file,
                     "Record the episode as MCAP (ros2 profile; Foxglove, ros2 bag): every view's "
                     "images, masks, TF, joints, candidates, map and step; FILE defaults to "
                     "RUN_DIR/episode.mcap (docs/recording.md)")
          ->expected(0, 1)
          ->type_name("[FILE]");
  AddRecordCompressionOption(cmd, cli.record_compression, record);
}

void AddRunCommand(CLI::App& app, CommandContext& context) {
  auto cli = std::make_shared<RunCli>();
  CLI::App* cmd = app.add_subcommand(
      "run", "One simulated active-vision episode into a run folder (docs/experiments.md)");
  AddRunOptions(*cmd, *cli);
  AddRecordOption(*cmd, *cli);
  cmd->callback([cli, cmd, &context] {
    RunGuarded(context, [&] { return Run(*cmd, *cli, *context.registries); });
  });
}

}  // namespace avp::apps

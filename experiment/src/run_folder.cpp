#include <chrono>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/experiment/episode_recording.h>
#include <avp/experiment/output_folder.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/json.h>
#include <avp/io/options_yaml.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/ply_export.h>
#include <avp/report/metrics_csv.h>
#include <avp/report/provenance.h>
#include <avp/report/run_html.h>
#include <avp/report/run_report.h>
#include <avp/report/svg_plot.h>

namespace avp::experiment {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

namespace {

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

json ComponentJson(const std::string& name, const AnyOptions& options) {
  return {{"name", name}, {"options", io::OptionsToJson(options.Values(), options.Info())}};
}

/// Calls the progress callback after every step.
class ProgressObserver final : public pipeline::EpisodeObserver {
 public:
  explicit ProgressObserver(const RunFolderOptions& options) : options_(options) {}
  void OnStep(const pipeline::StepRecord& s, const mapping::SemanticMap&) override {
    if (options_.on_step) options_.on_step(s);
  }

 private:
  const RunFolderOptions& options_;
};

/// map.avpmap, map.ot, fruit_voxels.ply and metrics.svg of a finished episode.
Status WriteMapAndPlot(const RunConfig& config, const FolderRun& run, const RunResult& result,
                       const mapping::SemanticMap& map, const fs::path& dir,
                       std::vector<fs::path>& files) {
  // avp's own map file (everything the map holds; `avp map info / compare / export` read it) ...
  const fs::path avpmap = dir / "map.avpmap";
  mapping::MapSaveOptions save;
  save.note = fmt::format("{} of {} (planner {}, segmenter {}, seed {})", run.command,
                          run.scene_name, config.planner.name, config.segmenter.name, config.seed);
  if (save.note.size() > mapping::kMaxMapNoteBytes) save.note.resize(mapping::kMaxMapNoteBytes);
  AVP_RETURN_IF_ERROR(mapping::SaveMap(map, avpmap, save));
  files.push_back(avpmap);
  // ... and the OctoMap ColorOcTree (octovis, other systems' tools).
  const fs::path ot = dir / "map.ot";
  AVP_RETURN_IF_ERROR(mapping::ExportOctomapColor(map, ot).status());
  files.push_back(ot);
  const fs::path ply = dir / "fruit_voxels.ply";
  AVP_RETURN_IF_ERROR(mapping::ExportSemanticPly(map.grid(), ply).status());
  files.push_back(ply);
  const fs::path svg = dir / "metrics.svg";
  AVP_RETURN_IF_ERROR(report::WriteLinePlotSvg(
      svg, report::EpisodeMetricsPlot(
               fmt::format("{} — {} / {} (seed {})", run.scene_name, config.planner.name,
                           config.segmenter.name, config.seed),
               result.episode.steps)));
  files.push_back(svg);
  return Status::Ok();
}

/// report.html: the episode in 3D, step by step (report/run_html.h, docs/report.md).
Status WriteRunReport(const RunConfig& config, const FolderRun& run, const RunResult& result,
                      const report::RunReportCollector& collector, const fs::path& path) {
  report::RunReportInfo info;
  const pipeline::EpisodeResult& e = result.episode;
  // A replay planned nothing: it fused the recording's views, where the recording's arm went.
  const bool replay = run.command == "avp replay";
  info.title =
      replay ? fmt::format("{} — replay of a recording, {}", run.scene_name, config.segmenter.name)
             : fmt::format("{} — {} / {} (seed {})", run.scene_name, config.planner.name,
                           config.segmenter.name, config.seed);
  info.facts = {
      {"command", run.command},
      {"scene", run.scene_name},
      {"planner", replay ? "none (a replay: the recording's camera poses)" : config.planner.name},
      {"segmenter", config.segmenter.name},
      {"seed", std::to_string(config.seed)},
      {"views", replay ? fmt::format("{} (the recording's)", e.views_fused())
                       : fmt::format("{} of {}", e.views_fused(), config.episode.views)},
      {"end", e.end_reason.empty()
                  ? std::string(pipeline::ToString(e.end))
                  : fmt::format("{} ({})", pipeline::ToString(e.end), e.end_reason)}};
  if (run.gt != nullptr) {
    info.facts.emplace_back("F1", fmt::format("{:.3f}", result.final_metrics.exact.f1));
    info.facts.emplace_back("fruits found",
                            fmt::format("{} of {}", result.final_metrics.fruits.found,
                                        result.final_metrics.fruits.total));
    // A run that finds nothing says why on its page too, as in the log and record.json.
    if (const std::vector<std::string> why = WhyNothingFound(config, result); !why.empty()) {
      info.facts.emplace_back("why no fruit was found", fmt::format("{}", fmt::join(why, "; ")));
    }
  }
  info.fruits = run.gt != nullptr ? report::FruitsJson(result.fruits) : json(nullptr);
  return report::WriteRunReportHtml(path, collector, info);
}

json RecordJson(const CheckedRunConfig& config, const FolderRun& run, const RunResult& result) {
  json config_json = RunConfigJson(config);
  json steps = json::array();
  for (const pipeline::StepRecord& s : result.episode.steps) steps.push_back(report::StepJson(s));
  json record{
      {"avp", run.command},
      {"config", std::move(config_json)},
      {"scene",
       {{"name", run.scene_name},
        {"description", run.scene_description},
        {"fruits", run.gt != nullptr ? json(run.gt->fruits.size()) : json(nullptr)}}},
      {"ground_truth",
       run.gt != nullptr ? report::GroundTruthJson(*run.gt, run.gt_seconds) : json(nullptr)},
      {"git_revision", report::SourceRevision()},
      {"host", report::HostDescription()},
      {"end", std::string(pipeline::ToString(result.episode.end))},
      {"end_reason", result.episode.end_reason},
      {"views_fused", result.episode.views_fused()},
      {"episode_seconds", result.episode.total_ms / 1e3},
      {"final_metrics",
       run.gt != nullptr ? report::MetricsJson(result.final_metrics) : json(nullptr)},
      // Every ground-truth fruit: found or not, from which view, how visible, its
      // errors; null without a ground truth, [] for one without fruits (a file).
      {"fruits", run.gt != nullptr ? report::FruitsJson(result.fruits) : json(nullptr)},
      // Why no fruit was found ([] when one was; null without a ground truth).
      {"nothing_found", run.gt != nullptr ? json(WhyNothingFound(*config, result)) : json(nullptr)},
      {"oracle_regret", report::RegretJson(result.regret)},
      // The episode's moves: contacts with the true world (simulation), motion time, planning.
      {"motion", report::MotionTotalsJson(result.episode)},
      {"steps", steps}};
  if (run.extra) {
    const json extra = run.extra();
    for (const auto& [key, value] : extra.items()) record[key] = value;
  }
  return record;
}

}  // namespace

json RunConfigJson(const CheckedRunConfig& checked) {
  const RunConfig& config = *checked;
  json out = io::OptionsToJson(RunConfigTable().Values(config), RunConfigTable().Info(config));
  out["planner"] = ComponentJson(config.planner.name, checked.planner_options());
  out["segmenter"] = ComponentJson(config.segmenter.name, checked.segmenter_options());
  return out;
}

namespace {

/// Every file a run folder holds.
constexpr std::string_view kRunOutputs[] = {kStateFileName, "record.json", "metrics.csv",
                                            "map.avpmap",   "map.ot",      "fruit_voxels.ply",
                                            "metrics.svg",  "report.html", "episode.mcap"};

/// Outputs never overwrite inputs: the folder and each of its files against the scene file, the
/// ground truth file and options.inputs.
Status CheckOutputsAreNotInputs(const RunConfig& config, const RunFolderOptions& options) {
  std::vector<std::pair<fs::path, std::string>> inputs = options.inputs;
  if (!config.scene_file.empty()) inputs.emplace_back(config.scene_file, "scene file");
  if (!config.ground_truth_file.empty()) {
    inputs.emplace_back(config.ground_truth_file, "ground truth file");
  }
  for (const auto& [input, what] : inputs) {
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out_dir, "run folder", input, what));
    if (options.record && !options.record_path.empty()) {
      AVP_RETURN_IF_ERROR(
          io::CheckOutputIsNotInput(options.record_path, "recording (--record)", input, what));
    }
    for (const std::string_view name : kRunOutputs) {
      AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out_dir / std::string(name),
                                                    "run folder output", input, what));
    }
  }
  return Status::Ok();
}

/// The episode and every result, into a prepared folder.
Result<RunSummary> WriteRunFolder(const CheckedRunConfig& checked, const RunFolderOptions& options,
                                  const FolderRun& run,
                                  const std::vector<pipeline::EpisodeObserver*>& observers) {
  const RunConfig& config = *checked;
  RunSummary summary;
  summary.scene_name = run.scene_name;
  const fs::path csv_path = options.out_dir / "metrics.csv";
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<report::MetricsCsvWriter> csv,
                       report::MetricsCsvWriter::Open(csv_path));
  // A row that cannot be written (a full disk) stops the episode: the run fails naming the file
  // rather than going on without its results.
  std::stop_source write_failed;
  csv->StopOnError(write_failed);
  // The user's stop reaches the episode through the same token.
  const std::stop_callback user_stop(options.stop,
                                     [&write_failed] { write_failed.request_stop(); });
  ProgressObserver progress(options);
  report::RunReportCollector report_data;
  std::vector<pipeline::EpisodeObserver*> all = {csv.get(), &progress, &report_data};
  all.insert(all.end(), observers.begin(), observers.end());
  // --record: the episode as MCAP, a chunk per view; a write error stops the episode as above.
  std::unique_ptr<ros::bag::McapRecorder> recorder;
  const fs::path mcap_path =
      options.record_path.empty() ? options.out_dir / "episode.mcap" : options.record_path;
  if (options.record) {
    AVP_ASSIGN_OR_RETURN(recorder, OpenEpisodeRecording(mcap_path, config, checked.registries(),
                                                        {.command = run.command,
                                                         .scene = run.scene_name,
                                                         .base_frame = options.record_base_frame,
                                                         .compression = options.record_compression,
                                                         .gt = run.gt}));
    recorder->StopOnError(write_failed);
    all.push_back(recorder.get());
  }
  std::unique_ptr<mapping::SemanticMap> map;
  AVP_ASSIGN_OR_RETURN(RunResult result, run.run(all, &map, write_failed.get_token()));
  AVP_RETURN_IF_ERROR(csv->Close());
  if (recorder != nullptr) AVP_RETURN_IF_ERROR(recorder->Close());
  result.gt_ms = run.gt_seconds * 1e3;
  summary.files.push_back(csv_path);
  if (recorder != nullptr) summary.files.push_back(mcap_path);
  if (map == nullptr) return InternalError("RunEpisodeToFolder: the episode returned no map");
  AVP_RETURN_IF_ERROR(WriteMapAndPlot(config, run, result, *map, options.out_dir, summary.files));
  const fs::path report_path = options.out_dir / "report.html";
  AVP_RETURN_IF_ERROR(WriteRunReport(config, run, result, report_data, report_path));
  summary.files.push_back(report_path);

  const json record = RecordJson(checked, run, result);
  const fs::path record_path = options.out_dir / "record.json";
  AVP_RETURN_IF_ERROR(io::WriteJsonFile(record_path, record));
  summary.files.insert(summary.files.begin(), record_path);
  summary.result = std::move(result);
  return summary;
}

}  // namespace

Result<RunSummary> RunEpisodeToFolder(const CheckedRunConfig& checked,
                                      const RunFolderOptions& options, const FolderRun& run,
                                      const std::vector<pipeline::EpisodeObserver*>& observers) {
  const auto t0 = Clock::now();
  const RunConfig& config = *checked;
  if (options.out_dir.empty()) return InvalidArgumentError("the output folder (--out) is empty");
  if (!run.run) return InvalidArgumentError("RunEpisodeToFolder: no episode to run");
  AVP_RETURN_IF_ERROR(CheckOutputsAreNotInputs(config, options));
  AVP_RETURN_IF_ERROR(PrepareOutputFolder(options.out_dir, RunFolderKind(), options.force));
  AVP_RETURN_IF_ERROR(MarkInProgress(options.out_dir, RunFolderKind(), run.command));
  Result<RunSummary> summary = WriteRunFolder(checked, options, run, observers);
  if (!summary.ok()) {
    MarkFailed(options.out_dir, RunFolderKind(), run.command, summary.status());
    return summary.status();
  }
  // A planner that threw: its results are written, and the run is a failure.
  if (summary->result.episode.end == pipeline::EpisodeEnd::kPlannerFault) {
    const Status fault =
        InternalError(fmt::format("planner fault: {}", summary->result.episode.end_reason));
    MarkFailed(options.out_dir, RunFolderKind(), run.command, fault);
    return fault;
  }
  AVP_RETURN_IF_ERROR(MarkComplete(options.out_dir, RunFolderKind(), run.command));
  summary->seconds = SecondsSince(t0);
  return summary;
}

Result<RunSummary> RunToFolder(const CheckedRunConfig& checked, const RunFolderOptions& options) {
  const RunConfig& config = *checked;
  if (options.out_dir.empty()) return InvalidArgumentError("the output folder (--out) is empty");
  // Refused at once, before the scene's ground truth is computed.
  AVP_RETURN_IF_ERROR(CheckOutputsAreNotInputs(config, options));
  AVP_RETURN_IF_ERROR(CheckOutputFolder(options.out_dir, RunFolderKind(), options.force));
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene, LoadScene(config, checked.registries()));
  if (options.on_scene) options.on_scene(scene);
  const auto t_gt = Clock::now();
  AVP_ASSIGN_OR_RETURN(const eval::GroundTruth gt, GroundTruthFor(config, scene));
  FolderRun run;
  run.scene_name = scene.name;
  run.scene_description = scene.description;
  run.gt = &gt;
  run.gt_seconds = SecondsSince(t_gt);
  run.run = [&](const std::vector<pipeline::EpisodeObserver*>& observers,
                std::unique_ptr<mapping::SemanticMap>* map, std::stop_token stop) {
    return RunEpisodeOnScene(checked, scene, gt, observers, map, stop);
  };
  return RunEpisodeToFolder(checked, options, run);
}

}  // namespace avp::experiment

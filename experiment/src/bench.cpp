// Running a bench (avp bench): its (scenario, seed) groups with their scenes and ground truth,
// every episode into its run folder, the shard's manifest (bench_shards.cpp), and the summary.

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
#include <set>
#include <stop_token>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/core/text.h>
#include <avp/experiment/bench.h>
#include <avp/experiment/episode_recording.h>
#include <avp/experiment/episode_runner.h>
#include <avp/experiment/output_folder.h>
#include <avp/io/file.h>
#include <avp/io/json.h>
#include <avp/io/options_yaml.h>
#include <avp/io/yaml.h>
#include <avp/report/bench_html.h>
#include <avp/report/metrics_csv.h>
#include <avp/report/progress.h>
#include <avp/report/provenance.h>
#include <avp/report/run_report.h>
#include <avp/sim/scene_file.h>

#include "bench_internal.h"

namespace avp::experiment {

namespace fs = std::filesystem;

namespace internal {

/// The summary, plots and report.html of a bench folder from its episodes as read back.
Result<BenchSummary> WriteSummaryAndReport(const fs::path& out_dir,
                                           const report::BenchDescription& description,
                                           const std::vector<report::BenchEpisode>& episodes,
                                           double seconds) {
  AVP_ASSIGN_OR_RETURN(report::BenchTables tables,
                       report::WriteBenchSummary(out_dir, description, episodes, seconds));
  // report.html: the same numbers as the summary, with per-scenario plots and links to the runs.
  const fs::path html = out_dir / "report.html";
  AVP_RETURN_IF_ERROR(report::WriteBenchReportHtml(
      html, report::BenchReportJson(description, episodes, seconds, out_dir)));
  BenchSummary summary;
  summary.cells = std::move(tables.cells);
  summary.leads = std::move(tables.leads);
  summary.files = std::move(tables.files);
  summary.files.push_back(html);
  summary.report_html = html;
  summary.episodes = episodes.size();
  summary.failed = tables.failed;
  return summary;
}

}  // namespace internal

namespace {

using internal::CheckDisplayNames;
using internal::Clock;
using internal::EntryError;
using internal::Group;
using internal::GroupKey;
using internal::JobConfig;
using internal::JobRef;
using internal::kManifestName;
using internal::ReadManifest;
using internal::SecondsSince;

/// fn(i) for every i in [0, n) on config.jobs threads (0: the hardware's); each job runs
/// serially inside (core/parallel.h).
template <typename Fn>
void InJobs(const BenchConfig& config, size_t n, Fn&& fn) {
  const ThreadScope jobs(config.jobs);
  ParallelFor(n, std::forward<Fn>(fn));
}

/// The scene of each scene-file entry of `list`: every file read once, then arranged once per
/// entry (in parallel); fills the entries' display names. Registered scenarios get nullptr (they
/// are built per seed). Two entries with the same display name (or the same run folder name) are
/// an error naming both.
Result<std::vector<std::shared_ptr<const sim::Scene>>> LoadSceneFiles(
    const BenchConfig& config, std::vector<BenchScenario>& list) {
  std::vector<fs::path> files;
  for (const BenchScenario& b : list) {
    if (!b.scene_file.empty() &&
        std::find(files.begin(), files.end(), b.scene_file) == files.end()) {
      files.push_back(b.scene_file);
    }
  }
  std::vector<Result<sim::Scene>> read(files.size(), InternalError("not read"));
  InJobs(config, files.size(), [&](size_t i) { read[i] = sim::LoadSceneFile(files[i]); });
  // What the loader warns about (a placeholder material, fruit fragments, a plant under the
  // ground...), once per file, before hours of episodes (docs/scene-format.md, "Warnings").
  for (size_t i = 0; i < files.size(); ++i) {
    if (!read[i].ok()) continue;
    for (const std::string& w : read[i]->warnings) {
      std::fprintf(stderr, "warning: scene file '%s': %s\n", files[i].string().c_str(), w.c_str());
    }
  }
  std::vector<Result<sim::Scene>> arranged(list.size(), InternalError("not arranged"));
  InJobs(config, list.size(), [&](size_t i) {
    const BenchScenario& b = list[i];
    if (b.scene_file.empty()) return;
    const size_t f =
        static_cast<size_t>(std::find(files.begin(), files.end(), b.scene_file) - files.begin());
    if (!read[f].ok()) {
      arranged[i] = read[f].status();
      return;
    }
    Result<sim::Arrangement> a = sim::ParseArrangement(b.arrangement);
    if (!a.ok()) {
      arranged[i] = a.status();
      return;
    }
    sim::Scene scene = *read[f];
    if (Result<sim::ArrangementReport> r = sim::ApplyArrangement(scene, *a); !r.ok()) {
      arranged[i] = r.status();
      return;
    }
    arranged[i] = std::move(scene);
  });
  std::vector<std::shared_ptr<const sim::Scene>> scenes(list.size());
  for (size_t i = 0; i < list.size(); ++i) {
    if (list[i].scene_file.empty()) continue;
    if (!arranged[i].ok()) return EntryError(list[i], arranged[i].status());
    list[i].display_name = arranged[i]->name;
    scenes[i] = std::make_shared<const sim::Scene>(std::move(*arranged[i]));
  }
  AVP_RETURN_IF_ERROR(CheckDisplayNames(list));
  return scenes;
}

/// Every (scenario, seed) of the bench in list order, seeds inner: scene files read (and their
/// display names known), no scene made and no ground truth computed yet.
Result<std::vector<Group>> ListGroups(const BenchConfig& config, std::vector<BenchScenario>& list) {
  AVP_ASSIGN_OR_RETURN(const std::vector<std::shared_ptr<const sim::Scene>> files,
                       LoadSceneFiles(config, list));
  std::vector<Group> groups;
  for (size_t i = 0; i < list.size(); ++i) {
    for (uint64_t seed : config.seeds) {
      Group g;
      g.scenario = list[i].display_name;
      g.seed = seed;
      g.source = &list[i];
      g.scene = files[i];
      groups.push_back(std::move(g));
    }
  }
  return groups;
}

/// The scene and ground truth of every group with needed[i], in parallel.
Status ComputeGroundTruth(const BenchConfig& config, const Registries& registries,
                          std::vector<Group>& groups, const std::vector<bool>& needed) {
  std::vector<size_t> todo;
  for (size_t i = 0; i < groups.size(); ++i) {
    if (needed[i]) todo.push_back(i);
  }
  std::vector<Status> scene_status(groups.size());
  report::Progress bar(report::ProgressOn(stderr, "ground truth", todo.size(), config.progress));
  InJobs(config, todo.size(), [&](size_t t) {
    const size_t i = todo[t];
    Group& g = groups[i];
    if (g.scene == nullptr) {
      Result<sim::Scene> scene = registries.scenarios.Make(g.source->scenario, g.seed);
      if (!scene.ok()) {
        scene_status[i] = scene.status();
        bar.Done(fmt::format("{} seed {} failed", g.scenario, g.seed));
        return;
      }
      scene->name = g.scenario;
      g.scene = std::make_shared<const sim::Scene>(std::move(*scene));
    }
    g.gt = GroundTruthFor(JobConfig(config, *g.source, g.seed, ""), *g.scene);
    bar.Done(fmt::format("{} seed {} {}", g.scenario, g.seed, g.gt.ok() ? "ok" : "failed"));
  });
  for (size_t i : todo) {
    const Group& g = groups[i];
    if (!scene_status[i].ok()) return scene_status[i];
    if (!g.gt.ok()) {
      return Status(g.gt.status().code(), fmt::format("ground truth of {} seed {}: {}", g.scenario,
                                                      g.seed, g.gt.status().message()));
    }
  }
  return Status::Ok();
}

/// The first result of the bench that could not be written, or the user's stop: it asks every
/// running episode to stop and keeps new ones from starting.
class WriteFailure {
 public:
  void Set(const Status& s) {
    {
      const std::lock_guard<std::mutex> lock(mu_);
      if (first_.ok()) first_ = s;
    }
    stop_.request_stop();
  }
  bool failed() const { return stop_.stop_requested(); }
  std::stop_source& stop() { return stop_; }
  Status first() {
    const std::lock_guard<std::mutex> lock(mu_);
    return first_;
  }

 private:
  std::mutex mu_;
  Status first_;
  std::stop_source stop_;
};

/// The episode's per-view metrics, plan times, per-fruit results and regret into the bench's row.
void TakeResults(const RunResult& r, report::BenchEpisode& j) {
  for (const pipeline::StepRecord& s : r.episode.steps) {
    j.metrics.push_back(s.metrics);
    if (s.planned) j.plan_ms.push_back(s.times.plan_ms);
  }
  const pipeline::MotionTotals motion = pipeline::SumMotion(r.episode);
  if (motion.contacts) j.contacts = motion.contacts->total();
  if (motion.straight_line_contacts)
    j.straight_line_contacts = motion.straight_line_contacts->total();
  j.motion_s = motion.execution_s;
  j.move_planning_ms = motion.planning_ms;
  if (const auto& start = r.episode.start_clearance; start && start->truth) {
    j.start_clearance_broken = start->broken() ? 1.0 : 0.0;
  }
  for (const eval::FruitResult& f : r.fruits) {
    j.fruits.push_back({.best_visible_fraction = f.best_visible_fraction,
                        .episode_visible_fraction = f.episode_visible_fraction,
                        .found = f.found});
  }
  for (const eval::StepRegret& step : r.regret) {
    j.regret.push_back({.step = step.step,
                        .candidates = step.candidates,
                        .regret = step.regret,
                        .chosen_true_rank = step.chosen_true_rank,
                        .rank_correlation = step.rank_correlation});
  }
}

/// A bench episode's record.json: what ran, how it ended, its plan times, motion and fruits.
nlohmann::json BenchRecord(const RunConfig& c, const Registries& registries, const RunResult& r,
                           const report::BenchEpisode& j, const std::string& revision) {
  const planning::PlannerEntry* entry = registries.planners.Find(j.planner);
  const nlohmann::json options = io::OptionsToJson(
      c.planner.options, entry != nullptr ? entry->options.Info() : std::vector<OptionInfo>{});
  nlohmann::json rec{{"scenario", j.scenario},
                     {"planner", j.planner},
                     {"seed", j.seed},
                     {"segmenter", c.segmenter.name},
                     {"views", c.episode.views},
                     {"planner_options", options},
                     {"end", std::string(pipeline::ToString(r.episode.end))},
                     {"end_reason", r.episode.end_reason},
                     {"episode_seconds", j.episode_s},
                     {"plan_ms", j.plan_ms},
                     {"motion", report::MotionTotalsJson(r.episode)},
                     {"git_revision", revision},
                     {"fruits", report::FruitsJson(r.fruits)}};
  if (c.oracle_regret) rec["oracle_regret"] = report::RegretJson(r.regret);
  // A scene file's entry: the file and the arrangement its scene was made with.
  if (!c.scene_file.empty()) rec["scene_file"] = c.scene_file.string();
  if (!c.arrangement.empty()) rec["arrangement"] = c.arrangement;
  return rec;
}

/// One episode into runs/<scenario>/<planner>/seed-<n>/: metrics.csv as it goes, record.json,
/// avp-state.json around them. A file that cannot be written fails the bench (WriteFailure).
report::BenchEpisode RunJob(const BenchConfig& config, const Registries& registries, const Group& g,
                            const std::string& planner, const std::string& revision,
                            WriteFailure& failure) {
  report::BenchEpisode j;
  j.scenario = g.scenario;
  j.planner = planner;
  j.seed = g.seed;
  if (failure.failed()) {
    j.status =
        CancelledError(fmt::format("not run: the bench stopped: {}", failure.first().message()));
    return j;
  }
  // The job's configuration (the bench's, this scenario, seed and planner), checked once here.
  const Result<CheckedRunConfig> checked =
      CheckedRunConfig::Check(JobConfig(config, *g.source, g.seed, planner), registries);
  const fs::path dir = config.out_dir / report::BenchRunFolder(j.scenario, j.planner, j.seed);
  const auto fail = [&](const Status& s) {
    failure.Set(s);
    MarkFailed(dir, RunFolderKind(), "avp bench", s);
    j.status = s;
    return j;
  };
  // The bench folder was empty (or emptied by --force): a per-run folder holding anything now is
  // a mix of two runs, refused.
  if (Status s = PrepareOutputFolder(dir, RunFolderKind(), false); !s.ok()) {
    failure.Set(s);
    j.status = s;
    return j;
  }
  if (Status s = MarkInProgress(dir, RunFolderKind(), "avp bench"); !s.ok()) return fail(s);
  if (!checked.ok()) {  // as an episode that failed: the bench goes on
    MarkFailed(dir, RunFolderKind(), "avp bench", checked.status());
    j.status = checked.status();
    return j;
  }
  const RunConfig& c = **checked;
  Result<std::unique_ptr<report::MetricsCsvWriter>> csv =
      report::MetricsCsvWriter::Open(dir / "metrics.csv");
  if (!csv.ok()) return fail(csv.status());
  (*csv)->StopOnError(failure.stop());
  std::vector<pipeline::EpisodeObserver*> observers = {csv->get()};
  std::unique_ptr<ros::bag::McapRecorder> recorder;
  if (config.record) {
    Result<std::unique_ptr<ros::bag::McapRecorder>> opened =
        OpenEpisodeRecording(dir / "episode.mcap", c, registries,
                             {.command = "avp bench",
                              .scene = j.scenario,
                              .compression = config.record_compression,
                              .gt = &*g.gt});
    if (!opened.ok()) return fail(opened.status());
    recorder = std::move(*opened);
    recorder->StopOnError(failure.stop());
    observers.push_back(recorder.get());
  }
  const auto te = Clock::now();
  Result<RunResult> r =
      RunEpisodeOnScene(*checked, *g.scene, *g.gt, observers, nullptr, failure.stop().get_token());
  j.episode_s = SecondsSince(te);
  if (Status s = (*csv)->Close(); !s.ok()) return fail(s);
  if (recorder != nullptr) {
    if (Status s = recorder->Close(); !s.ok()) return fail(s);
  }
  if (!r.ok()) {
    MarkFailed(dir, RunFolderKind(), "avp bench", r.status());
    j.status = r.status();
    return j;
  }
  // Stopped from outside (BenchConfig::stop): an episode cut short is no result, and a resumed
  // bench runs it again.
  if (r->episode.end == pipeline::EpisodeEnd::kInterrupted) {
    j.status = CancelledError(fmt::format("interrupted: {}", r->episode.end_reason));
    MarkFailed(dir, RunFolderKind(), "avp bench", j.status);
    return j;
  }
  TakeResults(*r, j);
  if (Status s =
          io::WriteJsonFile(dir / "record.json", BenchRecord(c, registries, *r, j, revision));
      !s.ok()) {
    return fail(s);
  }
  // A planner that threw: the episode is kept on disk, its folder failed, out of the statistics.
  if (r->episode.end == pipeline::EpisodeEnd::kPlannerFault) {
    j.status = InternalError(fmt::format("planner fault: {}", r->episode.end_reason));
    MarkFailed(dir, RunFolderKind(), "avp bench", j.status);
    return j;
  }
  if (Status s = MarkComplete(dir, RunFolderKind(), "avp bench"); !s.ok()) return fail(s);
  // A segmenter that failed (a service that is down) leaves views without segmentation: the
  // episode is kept on disk but counted as failed, out of the statistics.
  if (r->episode.end == pipeline::EpisodeEnd::kSegmenterFault) {
    j.status = UnavailableError(fmt::format("segmenter fault: {}", r->episode.end_reason));
  }
  return j;
}

/// True when a run folder says complete and holds its record (what --resume skips).
bool RunIsComplete(const fs::path& dir) {
  const Result<FolderState> state = ReadFolderState(dir);
  std::error_code ec;
  return state.ok() && state->state == "complete" && fs::is_regular_file(dir / "record.json", ec);
}

/// Outputs never overwrite inputs: the bench folder and its summary files against the inputs.
Status CheckBenchOutputs(const BenchConfig& config, const std::vector<BenchScenario>& list) {
  std::vector<std::pair<fs::path, std::string>> inputs = config.inputs;
  for (const BenchScenario& b : list) {
    if (!b.scene_file.empty()) inputs.emplace_back(b.scene_file, "scene file");
  }
  for (const auto& [input, what] : inputs) {
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(config.out_dir, "bench folder", input, what));
    for (const char* name : {"summary.md", "summary.csv", "fruits_by_visibility.csv", "report.html",
                             "avp-state.json"}) {
      AVP_RETURN_IF_ERROR(
          io::CheckOutputIsNotInput(config.out_dir / name, "bench output", input, what));
    }
    // An input inside the bench folder would be removed by --force or mixed with results.
    std::error_code ec;
    const fs::path in = fs::weakly_canonical(input, ec);
    const fs::path out = fs::weakly_canonical(config.out_dir, ec);
    if (!ec && std::mismatch(out.begin(), out.end(), in.begin(), in.end()).first == out.end()) {
      return InvalidArgumentError(fmt::format(
          "the {} '{}' is inside the bench folder '{}': outputs never overwrite inputs; give "
          "another --out",
          what, input.string(), config.out_dir.string()));
    }
  }
  return Status::Ok();
}

/// The bench folder's manifest before any episode: the bench, its jobs, this shard.
nlohmann::json StartManifest(const BenchConfig& config, const std::vector<BenchScenario>& list,
                             const std::vector<Group>& groups, const std::vector<JobRef>& refs,
                             const std::string& revision) {
  return {{"format", internal::kManifestFormat},
          {"bench", internal::DescriptionJson(config, list)},
          {"revision", revision},
          {"jobs", internal::JobsJson(groups, refs)},
          {"shard", {{"index", config.shard_index}, {"count", config.shard_count}}},
          {"ground_truth", nlohmann::json::array()},
          {"seconds", 0.0}};
}

/// What the interrupted bench of the folder (--resume) leaves to this one: its visibility per
/// group and its seconds, once its manifest is known to be this bench's.
Status ResumeFrom(const nlohmann::json& previous, const nlohmann::json& manifest,
                  const BenchConfig& config,
                  std::map<GroupKey, report::FruitVisibility>& visibility,
                  double& previous_seconds) {
  if (const std::string d = internal::ManifestDifference(previous, manifest, true); !d.empty()) {
    return FailedPreconditionError(fmt::format(
        "cannot resume '{}': it holds another bench ({} differs); give another --out, or "
        "--force to start it again",
        config.out_dir.string(), d));
  }
  visibility = internal::VisibilityFromJson(previous.at("ground_truth"));
  previous_seconds = previous.value("seconds", 0.0);
  return Status::Ok();
}

/// A job's run folder.
fs::path RunDir(const BenchConfig& config, const std::vector<Group>& groups, const JobRef& ref) {
  return config.out_dir /
         report::BenchRunFolder(groups[ref.group].scenario, ref.planner, groups[ref.group].seed);
}

/// The jobs of this shard still to run: with --resume, finished runs are skipped and unfinished
/// or failed ones emptied (only what avp writes).
Result<std::vector<size_t>> PendingJobs(const BenchConfig& config, const std::vector<Group>& groups,
                                        const std::vector<JobRef>& refs,
                                        const std::vector<size_t>& mine) {
  std::vector<size_t> pending;
  for (size_t i : mine) {
    const fs::path dir = RunDir(config, groups, refs[i]);
    if (config.resume && RunIsComplete(dir)) continue;
    if (config.resume) AVP_RETURN_IF_ERROR(PrepareOutputFolder(dir, RunFolderKind(), true));
    pending.push_back(i);
  }
  return pending;
}

/// The ground truth of the groups with a job to run, and of those whose visibility is unknown;
/// their visibility into `visibility`.
Status ComputeNeededGroundTruth(const BenchConfig& config, const Registries& registries,
                                std::vector<Group>& groups, const std::vector<JobRef>& refs,
                                const std::vector<size_t>& mine, const std::vector<size_t>& pending,
                                std::map<GroupKey, report::FruitVisibility>& visibility) {
  std::vector<bool> needed(groups.size(), false);
  for (size_t i : pending) needed[refs[i].group] = true;
  for (size_t i : mine) {
    const Group& g = groups[refs[i].group];
    if (!visibility.contains({g.scenario, g.seed})) needed[refs[i].group] = true;
  }
  AVP_RETURN_IF_ERROR(ComputeGroundTruth(config, registries, groups, needed));
  for (size_t gi = 0; gi < groups.size(); ++gi) {
    if (!needed[gi]) continue;
    report::FruitVisibility f;
    f.Add(*groups[gi].gt);
    visibility[{groups[gi].scenario, groups[gi].seed}] = f;
  }
  return Status::Ok();
}

/// The pending jobs' episodes, in parallel; the first result that could not be written stops
/// the bench.
Status RunPendingJobs(const BenchConfig& config, const Registries& registries,
                      const std::vector<Group>& groups, const std::vector<JobRef>& refs,
                      const std::vector<size_t>& pending, const std::string& revision) {
  WriteFailure failure;
  // The user's stop ends the bench as a write failure does: running episodes stop, no new one
  // starts.
  const std::stop_callback user_stop(config.stop, [&failure] {
    failure.Set(CancelledError("the bench was interrupted; resume it to run the rest"));
  });
  {
    report::Progress bar(report::ProgressOn(stderr, "episodes", pending.size(), config.progress));
    InJobs(config, pending.size(), [&](size_t t) {
      const JobRef& r = refs[pending[t]];
      const report::BenchEpisode e =
          RunJob(config, registries, groups[r.group], r.planner, revision, failure);
      bar.Done(fmt::format("{} {} seed {} {}", e.scenario, e.planner, e.seed,
                           e.status.ok() ? "ok" : "failed"));
    });
  }
  if (failure.failed()) return failure.first();
  return Status::Ok();
}

/// Every episode of this shard as written: the same numbers whether it ran now, in an earlier
/// (resumed) run, or on another machine (MergeBenches).
Result<std::vector<report::BenchEpisode>> ReadShardEpisodes(const BenchConfig& config,
                                                            const std::vector<Group>& groups,
                                                            const std::vector<JobRef>& refs,
                                                            const std::vector<size_t>& mine) {
  std::vector<report::BenchEpisode> episodes;
  episodes.reserve(mine.size());
  for (size_t i : mine) {
    const Group& g = groups[refs[i].group];
    AVP_ASSIGN_OR_RETURN(report::BenchEpisode e,
                         report::ReadBenchEpisode(RunDir(config, groups, refs[i]), g.scenario,
                                                  refs[i].planner, g.seed));
    episodes.push_back(std::move(e));
  }
  return episodes;
}

Result<BenchSummary> RunBenchInFolder(const BenchConfig& config, const Registries& registries,
                                      std::vector<BenchScenario>& list, Clock::time_point t0,
                                      const std::optional<nlohmann::json>& previous) {
  std::error_code ec;
  fs::create_directories(config.out_dir / "runs", ec);
  if (ec) {
    return IoError(
        fmt::format("cannot create '{}': {}", (config.out_dir / "runs").string(), ec.message()));
  }
  AVP_ASSIGN_OR_RETURN(std::vector<Group> groups, ListGroups(config, list));
  // Asked of git once, not per episode (two processes each).
  const std::string revision = report::SourceRevision();
  std::vector<JobRef> refs;
  for (size_t gi = 0; gi < groups.size(); ++gi) {
    for (const std::string& p : config.planners) refs.push_back({gi, p});
  }
  nlohmann::json manifest = StartManifest(config, list, groups, refs, revision);
  std::map<GroupKey, report::FruitVisibility> visibility;
  double previous_seconds = 0.0;
  if (previous.has_value()) {
    AVP_RETURN_IF_ERROR(ResumeFrom(*previous, manifest, config, visibility, previous_seconds));
  }
  const std::vector<size_t> mine =
      internal::ShardJobs(refs, groups.size(), config.shard_index, config.shard_count);
  AVP_ASSIGN_OR_RETURN(const std::vector<size_t> pending, PendingJobs(config, groups, refs, mine));
  AVP_RETURN_IF_ERROR(
      ComputeNeededGroundTruth(config, registries, groups, refs, mine, pending, visibility));
  manifest["ground_truth"] = internal::VisibilityJson(visibility);
  manifest["seconds"] = previous_seconds;
  AVP_RETURN_IF_ERROR(io::WriteJsonFile(config.out_dir / kManifestName, manifest));
  AVP_RETURN_IF_ERROR(RunPendingJobs(config, registries, groups, refs, pending, revision));
  AVP_ASSIGN_OR_RETURN(const std::vector<report::BenchEpisode> episodes,
                       ReadShardEpisodes(config, groups, refs, mine));
  const double seconds = previous_seconds + SecondsSince(t0);
  manifest["seconds"] = seconds;
  AVP_RETURN_IF_ERROR(io::WriteJsonFile(config.out_dir / kManifestName, manifest));
  BenchSummary summary;
  if (config.shard_count == 1) {
    report::BenchDescription description =
        internal::DescriptionFromJson(manifest["bench"], revision);
    description.visibility = internal::VisibilityByScenario(visibility);
    AVP_ASSIGN_OR_RETURN(
        summary, internal::WriteSummaryAndReport(config.out_dir, description, episodes, seconds));
  } else {
    summary.episodes = episodes.size();
    for (const report::BenchEpisode& e : episodes) summary.failed += e.status.ok() ? 0 : 1;
  }
  summary.resumed = mine.size() - pending.size();
  return summary;
}

}  // namespace

Result<BenchSummary> RunBench(const BenchConfig& config, const Registries& registries) {
  const auto t0 = Clock::now();
  AVP_RETURN_IF_ERROR(config.Validate(registries));
  AVP_ASSIGN_OR_RETURN(std::vector<BenchScenario> list,
                       ExpandScenarioList(config.scenarios, registries.scenarios));
  AVP_RETURN_IF_ERROR(CheckBenchOutputs(config, list));
  // --resume into a folder that holds a bench: its bench.json, checked against this bench once
  // the job list is known; a missing or empty folder starts afresh.
  std::optional<nlohmann::json> previous;
  std::error_code ec;
  const bool has_content =
      fs::is_directory(config.out_dir, ec) && !fs::is_empty(config.out_dir, ec);
  if (config.resume && has_content) {
    Result<nlohmann::json> m = ReadManifest(config.out_dir);
    if (!m.ok()) {
      return Status(m.status().code(), fmt::format("cannot resume: {}", m.status().message()));
    }
    previous = std::move(*m);
  } else {
    AVP_RETURN_IF_ERROR(PrepareOutputFolder(config.out_dir, BenchFolderKind(), config.force));
  }
  AVP_RETURN_IF_ERROR(MarkInProgress(config.out_dir, BenchFolderKind(), "avp bench"));
  Result<BenchSummary> summary = RunBenchInFolder(config, registries, list, t0, previous);
  if (!summary.ok()) {
    MarkFailed(config.out_dir, BenchFolderKind(), "avp bench", summary.status());
    return summary.status();
  }
  AVP_RETURN_IF_ERROR(MarkComplete(config.out_dir, BenchFolderKind(), "avp bench"));
  summary->seconds = SecondsSince(t0);
  return summary;
}

Result<ConditionsSummary> RunBenchConditions(const BenchConfig& config,
                                             const Registries& registries) {
  const auto t0 = Clock::now();
  if (config.conditions.empty()) return InvalidArgumentError("the bench has no conditions");
  AVP_RETURN_IF_ERROR(config.Validate(registries));
  AVP_ASSIGN_OR_RETURN(std::vector<BenchScenario> list,
                       ExpandScenarioList(config.scenarios, registries.scenarios));
  AVP_RETURN_IF_ERROR(CheckBenchOutputs(config, list));
  std::vector<std::string> names;
  for (const BenchCondition& c : config.conditions) names.push_back(c.name);
  const OutputFolderKind kind = ConditionsFolderKind(names);
  AVP_RETURN_IF_ERROR(PrepareOutputFolder(config.out_dir, kind, config.force));
  AVP_RETURN_IF_ERROR(MarkInProgress(config.out_dir, kind, "avp bench"));
  ConditionsSummary summary;
  std::vector<report::ConditionBench> benches;
  const auto fail = [&](const Status& s) {
    MarkFailed(config.out_dir, kind, "avp bench", s);
    return s;
  };
  for (size_t i = 0; i < config.conditions.size(); ++i) {
    const BenchCondition& c = config.conditions[i];
    AVP_ASSIGN_OR_RETURN(const BenchConfig derived, ConditionBenchConfig(config, c));
    if (config.progress) {
      std::fprintf(stderr, "condition %zu/%zu: %s%s%s\n", i + 1, config.conditions.size(),
                   c.name.c_str(), c.description.empty() ? "" : " - ", c.description.c_str());
    }
    Result<BenchSummary> s = RunBench(derived, registries);
    if (!s.ok()) return fail(s.status().WithContext(fmt::format("condition '{}'", c.name)));
    summary.episodes += s->episodes;
    summary.failed += s->failed;
    summary.benches.emplace_back(c.name, std::move(*s));
    benches.push_back({c.name, c.description, derived.out_dir});
  }
  Result<report::ConditionTables> tables =
      report::WriteConditionTables(config.out_dir, benches, config.planners.front());
  if (!tables.ok()) return fail(tables.status());
  summary.tables = std::move(*tables);
  AVP_RETURN_IF_ERROR(MarkComplete(config.out_dir, kind, "avp bench"));
  summary.seconds = SecondsSince(t0);
  return summary;
}

}  // namespace avp::experiment

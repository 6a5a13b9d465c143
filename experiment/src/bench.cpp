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

namespace avp::experiment {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const Limit& MaxBenchEpisodes() {
  static const Limit limit("max_bench_episodes", 100000, "episodes",
                           "episodes of one avp bench (scenarios x planners x seeds)");
  return limit;
}

Status CheckSeedCount(uint64_t count, std::string_view what) {
  if (count > kMaxBenchSeeds) {
    return InvalidArgumentError(
        fmt::format("{} ({}) must be at most {} seeds", what, count, kMaxBenchSeeds));
  }
  return Status::Ok();
}

namespace {

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

/// One (scenario, seed): its scene and ground truth, shared by the planners. A scene file's scene
/// is one for all seeds (shared); a registered scenario's is built per seed.
struct Group {
  std::string scenario;  ///< the display name (BenchScenario::display_name)
  uint64_t seed = 0;
  const BenchScenario* source = nullptr;
  std::shared_ptr<const sim::Scene> scene;
  Result<eval::GroundTruth> gt = InternalError("not computed");
};

/// The base configuration of every job: one thread inside, the scene from the job's scenario.
RunConfig JobBase(const BenchConfig& config) {
  RunConfig base = config.base;
  base.threads = 1;
  base.scene_file.clear();
  base.arrangement.clear();
  return base;
}

RunConfig JobConfig(const BenchConfig& config, const BenchScenario& scenario, uint64_t seed,
                    const std::string& planner) {
  RunConfig c = JobBase(config);
  c.scenario = scenario.scenario;
  c.scene_file = scenario.scene_file;
  c.arrangement = scenario.arrangement;
  c.seed = seed;
  c.planner.name = planner;
  const auto options = config.planner_options.find(planner);
  c.planner.options = options == config.planner_options.end() ? OptionValues{} : options->second;
  return c;
}

/// A scenarios entry in a message: escaped, and long enough for a path (QuoteText shortens).
std::string QuoteEntry(std::string_view entry) {
  return fmt::format("'{}'", EscapeText(entry, 4096));
}

/// "scenarios entry 'plant.yaml@paper' (scene file '/abs/plant.yaml'): <status>".
Status EntryError(const BenchScenario& b, const Status& s) {
  std::string where = fmt::format("scenarios entry {}", QuoteEntry(b.entry));
  if (!b.scene_file.empty()) where += fmt::format(" (scene file '{}')", b.scene_file.string());
  return s.WithContext(where);
}

/// Two entries with the same display name, or names that give the same run folder, are an error
/// naming both entries.
Status CheckDisplayNames(const std::vector<BenchScenario>& list) {
  std::map<std::string, const BenchScenario*> by_name, by_folder;
  for (const BenchScenario& b : list) {
    if (b.display_name.empty()) continue;  // a scene file not read yet
    const auto [n, new_name] = by_name.emplace(b.display_name, &b);
    const auto [f, new_folder] = by_folder.emplace(report::SafeFileName(b.display_name), &b);
    if (!new_name || !new_folder) {
      const BenchScenario& other = !new_name ? *n->second : *f->second;
      return InvalidArgumentError(fmt::format(
          "scenarios entries {} and {} have the same name {} in the summaries and run folders{}: "
          "list each once, or give one scene file another `name:`",
          QuoteEntry(other.entry), QuoteEntry(b.entry), QuoteText(other.display_name),
          other.display_name == b.display_name ? std::string()
                                               : fmt::format(" (folder {})", QuoteText(f->first))));
    }
  }
  return Status::Ok();
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
  ParallelFor(files.size(), config.jobs, [&](size_t i) { read[i] = sim::LoadSceneFile(files[i]); });
  // What the loader warns about (a placeholder material, fruit fragments, a plant under the
  // ground...), once per file, before hours of episodes (docs/scene-format.md, "Warnings").
  for (size_t i = 0; i < files.size(); ++i) {
    if (!read[i].ok()) continue;
    for (const std::string& w : read[i]->warnings) {
      std::fprintf(stderr, "warning: scene file '%s': %s\n", files[i].string().c_str(), w.c_str());
    }
  }
  std::vector<Result<sim::Scene>> arranged(list.size(), InternalError("not arranged"));
  ParallelFor(list.size(), config.jobs, [&](size_t i) {
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
  ParallelFor(todo.size(), config.jobs, [&](size_t t) {
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

/// The first result of the bench that could not be written: it asks every running episode to
/// stop and keeps new ones from starting.
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
    j.status = CancelledError("not run: the bench stopped (a result could not be written)");
    return j;
  }
  const RunConfig c = JobConfig(config, *g.source, g.seed, planner);
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
  Result<std::unique_ptr<report::MetricsCsvWriter>> csv =
      report::MetricsCsvWriter::Open(dir / "metrics.csv");
  if (!csv.ok()) return fail(csv.status());
  (*csv)->StopOnError(failure.stop());
  std::vector<pipeline::EpisodeObserver*> observers = {csv->get()};
  std::unique_ptr<recording::McapRecorder> recorder;
  if (config.record) {
    Result<std::unique_ptr<recording::McapRecorder>> opened =
        OpenEpisodeRecording(dir / "episode.mcap", c, registries,
                             {.command = "avp bench", .scene = j.scenario, .gt = &*g.gt});
    if (!opened.ok()) return fail(opened.status());
    recorder = std::move(*opened);
    recorder->StopOnError(failure.stop());
    observers.push_back(recorder.get());
  }
  const auto te = Clock::now();
  Result<RunResult> r = RunEpisodeOnScene(c, registries, *g.scene, *g.gt, observers, nullptr,
                                          failure.stop().get_token());
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
  for (const pipeline::StepRecord& s : r->episode.steps) {
    j.metrics.push_back(s.metrics);
    if (s.planned) j.plan_ms.push_back(s.times.plan_ms);
  }
  for (const eval::FruitResult& f : r->fruits) {
    j.fruits.push_back({.best_visible_fraction = f.best_visible_fraction,
                        .episode_visible_fraction = f.episode_visible_fraction,
                        .found = f.found});
  }
  for (const eval::StepRegret& step : r->regret) {
    j.regret.push_back({.step = step.step,
                        .candidates = step.candidates,
                        .regret = step.regret,
                        .chosen_true_rank = step.chosen_true_rank,
                        .rank_correlation = step.rank_correlation});
  }
  const planning::PlannerEntry* entry = registries.planners.Find(planner);
  const nlohmann::json options = io::OptionsToJson(
      c.planner.options, entry != nullptr ? entry->options.Info() : std::vector<OptionInfo>{});
  nlohmann::json rec{{"scenario", j.scenario},
                     {"planner", j.planner},
                     {"seed", j.seed},
                     {"segmenter", c.segmenter.name},
                     {"views", c.episode.views},
                     {"planner_options", options},
                     {"end", std::string(pipeline::ToString(r->episode.end))},
                     {"end_reason", r->episode.end_reason},
                     {"episode_seconds", j.episode_s},
                     {"plan_ms", j.plan_ms},
                     {"git_revision", revision},
                     {"fruits", report::FruitsJson(r->fruits)}};
  // A scene file's entry: the file and the arrangement its scene was made with.
  if (c.oracle_regret) rec["oracle_regret"] = report::RegretJson(r->regret);
  if (!c.scene_file.empty()) rec["scene_file"] = c.scene_file.string();
  if (!c.arrangement.empty()) rec["arrangement"] = c.arrangement;
  if (Status s = io::WriteJsonFile(dir / "record.json", rec); !s.ok()) return fail(s);
  if (Status s = MarkComplete(dir, RunFolderKind(), "avp bench"); !s.ok()) return fail(s);
  // A segmenter that failed (a service that is down) leaves views without segmentation: the
  // episode is kept on disk but counted as failed, out of the statistics.
  if (r->episode.end == pipeline::EpisodeEnd::kSegmenterFault) {
    j.status = UnavailableError(fmt::format("segmenter fault: {}", r->episode.end_reason));
  }
  return j;
}

// ---- bench.json: what a bench folder holds, for merging shards and resuming.

constexpr const char* kManifestFormat = "avp-bench 1";
constexpr const char* kManifestName = "bench.json";

nlohmann::json OptionValuesJson(const OptionValues& values) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& [k, v] : values) out.push_back({k, v});
  return out;
}

OptionValues OptionValuesFromJson(const nlohmann::json& j) {
  OptionValues out;
  for (const nlohmann::json& kv : j) {
    out.emplace_back(kv.at(0).get<std::string>(), kv.at(1).get<std::string>());
  }
  return out;
}

/// The summary's description of the bench, without the visibility (which comes per group).
nlohmann::json DescriptionJson(const BenchConfig& config, const std::vector<BenchScenario>& list) {
  nlohmann::json scenarios = nlohmann::json::array();
  for (const BenchScenario& b : list) scenarios.push_back(b.display_name);
  nlohmann::json options = nlohmann::json::object();
  for (const auto& [planner, values] : config.planner_options) {
    options[planner] = OptionValuesJson(values);
  }
  return {{"description", config.description},
          {"entries", config.scenarios},
          {"scenarios", std::move(scenarios)},
          {"planners", config.planners},
          {"seeds", config.seeds},
          {"views", config.base.episode.views},
          {"segmenter", config.base.segmenter.name},
          {"voxel_size_m", config.base.map.grid.voxel_size_m},
          {"planner_options", std::move(options)},
          {"run_options", OptionValuesJson(RunConfigTable().Differences(JobBase(config),
                                                                        JobBase(BenchConfig{})))}};
}

report::BenchDescription DescriptionFromJson(const nlohmann::json& bench,
                                             const std::string& revision) {
  report::BenchDescription d;
  d.scenarios = bench.at("scenarios").get<std::vector<std::string>>();
  d.planners = bench.at("planners").get<std::vector<std::string>>();
  d.seeds = bench.at("seeds").size();
  d.views = bench.at("views").get<int>();
  d.segmenter = bench.at("segmenter").get<std::string>();
  d.voxel_size_m = bench.at("voxel_size_m").get<double>();
  d.revision = revision;
  for (const auto& [planner, values] : bench.at("planner_options").items()) {
    d.planner_options[planner] = OptionValuesFromJson(values);
  }
  d.description = bench.at("description").get<std::string>();
  d.run_options = OptionValuesFromJson(bench.at("run_options"));
  return d;
}

/// One job of the bench: its group (scenario, seed) and planner.
struct JobRef {
  size_t group;
  std::string planner;
};

nlohmann::json JobsJson(const std::vector<Group>& groups, const std::vector<JobRef>& refs) {
  nlohmann::json out = nlohmann::json::array();
  for (const JobRef& r : refs) {
    out.push_back({groups[r.group].scenario, r.planner, groups[r.group].seed});
  }
  return out;
}

using GroupKey = std::pair<std::string, uint64_t>;  // (scenario, seed)

nlohmann::json VisibilityJson(const std::map<GroupKey, report::FruitVisibility>& v) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& [key, f] : v) {
    out.push_back({{"scenario", key.first},
                   {"seed", key.second},
                   {"fruits", f.fruits},
                   {"visible", f.visible}});
  }
  return out;
}

std::map<GroupKey, report::FruitVisibility> VisibilityFromJson(const nlohmann::json& j) {
  std::map<GroupKey, report::FruitVisibility> out;
  for (const nlohmann::json& g : j) {
    report::FruitVisibility f;
    f.fruits = g.at("fruits").get<double>();
    const nlohmann::json& visible = g.at("visible");
    for (size_t i = 0; i < f.visible.size() && i < visible.size(); ++i) {
      f.visible[i] = visible.at(i).get<double>();
    }
    out[{g.at("scenario").get<std::string>(), g.at("seed").get<uint64_t>()}] = f;
  }
  return out;
}

/// Per scenario, the sum over its groups (the summary's "fruits by visibility" denominators).
std::map<std::string, report::FruitVisibility> VisibilityByScenario(
    const std::map<GroupKey, report::FruitVisibility>& groups) {
  std::map<std::string, report::FruitVisibility> out;
  for (const auto& [key, f] : groups) {
    report::FruitVisibility& s = out[key.first];
    s.fruits += f.fruits;
    for (size_t i = 0; i < s.visible.size(); ++i) s.visible[i] += f.visible[i];
  }
  return out;
}

/// A bench folder's bench.json, read and checked for the keys the merge and resume use.
Result<nlohmann::json> ReadManifest(const fs::path& dir) {
  const fs::path file = dir / kManifestName;
  std::error_code ec;
  if (!fs::exists(file, ec)) {
    return FailedPreconditionError(fmt::format(
        "'{}' has no {}: not a bench folder of this avp version (or its bench never started)",
        dir.string(), kManifestName));
  }
  AVP_ASSIGN_OR_RETURN(nlohmann::json j, io::ReadJsonFile(file));
  try {
    if (j.at("format").get<std::string>() != kManifestFormat) {
      return ParseError(fmt::format("{}: format '{}', this avp reads '{}'", file.string(),
                                    j.at("format").get<std::string>(), kManifestFormat));
    }
    for (const char* key : {"bench", "revision", "jobs", "shard", "ground_truth"}) {
      if (!j.contains(key)) return ParseError(fmt::format("{}: no '{}'", file.string(), key));
    }
    (void)DescriptionFromJson(j.at("bench"), j.at("revision").get<std::string>());
    (void)VisibilityFromJson(j.at("ground_truth"));
    for (const nlohmann::json& job : j.at("jobs")) {
      (void)job.at(0).get<std::string>();
      (void)job.at(1).get<std::string>();
      (void)job.at(2).get<uint64_t>();
    }
    if (j.at("shard").at("count").get<uint64_t>() == 0 ||
        j.at("shard").at("index").get<uint64_t>() == 0 ||
        j.at("shard").at("index").get<uint64_t>() > j.at("shard").at("count").get<uint64_t>()) {
      return ParseError(fmt::format("{}: a bad shard {}", file.string(), j.at("shard").dump()));
    }
  } catch (const nlohmann::json::exception& e) {
    return ParseError(fmt::format("{}: not an avp bench.json: {}", file.string(), e.what()));
  }
  return j;
}

/// The first of a manifest's identity keys on which `a` and `b` differ ("" when none): what a
/// merge and a resume require to be equal.
std::string ManifestDifference(const nlohmann::json& a, const nlohmann::json& b, bool same_shard) {
  if (a.at("bench") != b.at("bench")) {
    for (const auto& [key, value] : a.at("bench").items()) {
      if (!b.at("bench").contains(key) || b.at("bench").at(key) != value) {
        return fmt::format("the configuration ({}: {} against {})", key, value.dump(),
                           b.at("bench").value(key, nlohmann::json()).dump());
      }
    }
    return "the configuration";
  }
  if (a.at("jobs") != b.at("jobs")) return "the job list";
  if (a.at("revision") != b.at("revision")) {
    return fmt::format("the revision ({} against {})", a.at("revision").dump(),
                       b.at("revision").dump());
  }
  if (a.at("shard").at("count") != b.at("shard").at("count")) {
    return fmt::format("the shard count ({} against {})", a.at("shard").at("count").dump(),
                       b.at("shard").at("count").dump());
  }
  if (same_shard && a.at("shard") != b.at("shard")) {
    return fmt::format("the shard ({}/{} against {}/{})", a.at("shard").at("index").dump(),
                       a.at("shard").at("count").dump(), b.at("shard").at("index").dump(),
                       b.at("shard").at("count").dump());
  }
  return "";
}

/// The jobs (indices into the job list, ascending) of shard `index` of `count`. The (scenario,
/// seed) groups are dealt, each with all its planners (so that its ground truth is computed by one
/// shard only): in a fixed shuffled order (by MixSeed of the group's index, the same on every
/// machine), round-robin, so that every shard gets a share of every scenario whatever N is
/// (dealing the list in its own order would give a shard runs of one scenario).
std::vector<size_t> ShardJobs(const std::vector<JobRef>& refs, size_t groups, uint64_t index,
                              uint64_t count) {
  std::vector<size_t> order(groups);
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(), [](size_t a, size_t b) {
    const uint64_t ha = MixSeed(a), hb = MixSeed(b);
    return ha != hb ? ha < hb : a < b;
  });
  std::vector<bool> ours(groups, false);
  for (size_t r = index - 1; r < order.size(); r += count) ours[order[r]] = true;
  std::vector<size_t> mine;
  for (size_t i = 0; i < refs.size(); ++i) {
    if (ours[refs[i].group]) mine.push_back(i);
  }
  return mine;
}

/// True when a run folder says complete and holds its record (what --resume skips).
bool RunIsComplete(const fs::path& dir) {
  const Result<FolderState> state = ReadFolderState(dir);
  std::error_code ec;
  return state.ok() && state->state == "complete" && fs::is_regular_file(dir / "record.json", ec);
}

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
  summary.files = std::move(tables.files);
  summary.files.push_back(html);
  summary.report_html = html;
  summary.episodes = episodes.size();
  summary.failed = tables.failed;
  return summary;
}

/// A seed (or count) of the config: a whole number >= 0, never wrapped from a negative one.
Result<uint64_t> SeedValue(const YAML::Node& node, const std::string& what) {
  const std::optional<uint64_t> v =
      node.IsScalar() ? options_internal::ParseUnsigned(node.Scalar()) : std::nullopt;
  if (!v) {
    return InvalidArgumentError(
        fmt::format("{} ({}) must be a whole number >= 0", what,
                    node.IsScalar() ? QuoteText(node.Scalar()) : std::string("not a number")));
  }
  return *v;
}

Status ReadSeeds(const YAML::Node& seeds, const std::string& ctx, std::vector<uint64_t>& out) {
  if (seeds && seeds.IsSequence()) {
    AVP_RETURN_IF_ERROR(CheckSeedCount(seeds.size(), ctx + ": seeds"));
    for (const YAML::Node& s : seeds) {
      AVP_ASSIGN_OR_RETURN(const uint64_t seed, SeedValue(s, ctx + ": a seed"));
      out.push_back(seed);
    }
    return Status::Ok();
  }
  if (seeds && seeds.IsMap()) {
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(seeds, {"first", "count"}, ctx + ": seeds"));
    uint64_t first = 0;
    if (seeds["first"]) {
      AVP_ASSIGN_OR_RETURN(first, SeedValue(seeds["first"], ctx + ": seeds.first"));
    }
    AVP_ASSIGN_OR_RETURN(const uint64_t count, SeedValue(seeds["count"], ctx + ": seeds.count"));
    AVP_RETURN_IF_ERROR(CheckSeedCount(count, ctx + ": seeds.count"));
    for (uint64_t i = 0; i < count; ++i) out.push_back(first + i);
    return Status::Ok();
  }
  return InvalidArgumentError(fmt::format("{}: 'seeds' must be a list or {{first, count}}", ctx));
}

Status ReadStrings(const YAML::Node& root, const char* key, const std::string& ctx,
                   std::vector<std::string>& out) {
  const YAML::Node n = root[key];
  if (!n || !n.IsSequence() || n.size() == 0) {
    return InvalidArgumentError(fmt::format("{}: '{}' must be a non-empty list", ctx, key));
  }
  for (const YAML::Node& item : n) out.push_back(item.as<std::string>());
  return Status::Ok();
}

/// What each job sets itself (its scenario, seed, planner; one thread) may not come from the run
/// tree, where it would be silently overridden.
Status RejectPerJobKeys(const YAML::Node& run, const std::string& ctx) {
  if (!run || !run.IsMap()) return Status::Ok();
  for (const char* key : {"scenario", "scene_file", "arrangement", "seed", "planner", "threads"}) {
    if (run[key]) {
      return InvalidArgumentError(fmt::format(
          "{}: run.{} is set by each job (scenarios, planners, seeds lists; episodes run one "
          "thread each): give it there, not in run",
          ctx, key));
    }
  }
  return Status::Ok();
}

Status ReadPlannerOptions(const YAML::Node& node, const std::string& ctx, BenchConfig& o) {
  if (!node) return Status::Ok();
  if (!node.IsMap()) {
    return InvalidArgumentError(
        fmt::format("{}: 'planner_options' must be a map of planner: {{option: value}}", ctx));
  }
  for (const auto& kv : node) {
    const std::string planner = kv.first.as<std::string>();
    AVP_ASSIGN_OR_RETURN(OptionValues values,
                         io::FlattenYaml(kv.second, ctx + ": planner_options." + planner));
    o.planner_options[planner] = std::move(values);
  }
  return Status::Ok();
}

Status ReadConditions(const YAML::Node& node, const std::string& ctx, BenchConfig& o) {
  if (!node) return Status::Ok();
  if (!node.IsSequence() || node.size() == 0) {
    return InvalidArgumentError(
        fmt::format("{}: 'conditions' must be a non-empty list of {{name, description, run, "
                    "planner_options}}",
                    ctx));
  }
  for (size_t i = 0; i < node.size(); ++i) {
    const YAML::Node item = node[i];
    const std::string where = fmt::format("{}: conditions[{}]", ctx, i);
    if (!item.IsMap()) {
      return InvalidArgumentError(
          fmt::format("{}: must be a map {{name, description, run, planner_options}}", where));
    }
    AVP_RETURN_IF_ERROR(
        io::RejectUnknownKeys(item, {"name", "description", "run", "planner_options"}, where));
    BenchCondition c;
    if (!item["name"] || !item["name"].IsScalar()) {
      return InvalidArgumentError(fmt::format("{}: 'name' is missing", where));
    }
    c.name = item["name"].as<std::string>();
    if (item["description"]) c.description = item["description"].as<std::string>();
    if (item["run"]) {
      AVP_RETURN_IF_ERROR(RejectPerJobKeys(item["run"], where));
      AVP_ASSIGN_OR_RETURN(c.run, io::FlattenYaml(item["run"], where + ".run"));
    }
    BenchConfig options;
    AVP_RETURN_IF_ERROR(ReadPlannerOptions(item["planner_options"], where, options));
    c.planner_options = std::move(options.planner_options);
    o.conditions.push_back(std::move(c));
  }
  return Status::Ok();
}

/// A condition's name is a folder name of its own beside conditions.md / .csv.
bool IsConditionName(const std::string& name) {
  if (name.empty() || name.size() > 100 || name.front() == '.' || name == "conditions.md" ||
      name == "conditions.csv" || name == kStateFileName) {
    return false;
  }
  return std::all_of(name.begin(), name.end(), [](char ch) {
    return std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '-' || ch == '_';
  });
}

}  // namespace

bool IsSceneFileEntry(std::string_view entry) {
  const std::string_view path = entry.substr(0, entry.rfind('@'));
  const auto ends_with = [&](std::string_view suffix) {
    if (path.size() < suffix.size()) return false;
    const std::string_view tail = path.substr(path.size() - suffix.size());
    return std::equal(tail.begin(), tail.end(), suffix.begin(), [](char a, char b) {
      return std::tolower(static_cast<unsigned char>(a)) == b;
    });
  };
  return ends_with(".yaml") || ends_with(".yml") || path.find('/') != std::string_view::npos;
}

Result<std::vector<BenchScenario>> ExpandScenarioList(const std::vector<std::string>& entries,
                                                      const sim::ScenarioRegistry& scenarios) {
  std::vector<BenchScenario> out;
  for (const std::string& entry : entries) {
    if (entry.empty()) return InvalidArgumentError("a scenario name is empty");
    const size_t at = entry.rfind('@');
    const std::string base = entry.substr(0, at);
    const std::string arrangement = at == std::string::npos ? "" : entry.substr(at + 1);
    const auto bad = [&](const std::string& why) {
      return InvalidArgumentError(fmt::format("scenarios entry {}: {}", QuoteEntry(entry), why));
    };
    if (base.empty()) return bad("no scenario or scene file before '@'");
    if (at != std::string::npos && arrangement.empty()) {
      return bad(fmt::format("no arrangement after '@' (known: {}, {})",
                             fmt::join(sim::ArrangementNames(), ", "), sim::kPaperArrangements));
    }
    const bool file = IsSceneFileEntry(entry);
    std::vector<std::string> arrangements = {arrangement};
    if (arrangement == sim::kPaperArrangements) {
      if (!file) {
        return bad(fmt::format(
            "'{}' arranges a scene file's plant four ways; the scenario '{}' is arranged by its "
            "generator (the paper's scenarios are tomato-multiple-clusters, "
            "tomato-full-occlusion, tomato-single-cluster and tomato-unoriented-start)",
            sim::kPaperArrangements, base));
      }
      arrangements = sim::ArrangementNames();
    }
    for (const std::string& a : arrangements) {
      const Result<sim::Arrangement> parsed = sim::ParseArrangement(a);
      if (!parsed.ok()) return bad(parsed.status().message());
      BenchScenario b;
      b.entry = entry;
      b.arrangement = a;
      if (file) {
        b.scene_file = base;
      } else {
        if (scenarios.Find(base) == nullptr) {
          return bad(fmt::format(
              "unknown scenario '{}' (known: {}; a scene file ends in .yaml or .yml, or has a "
              "'/': ./{})",
              base, fmt::join(scenarios.Names(), ", "), base));
        }
        if (!parsed->IsIdentity()) {
          return bad(fmt::format(
              "arrangement '{}' is for scene files: the scenario '{}' is arranged by its "
              "generator (only 'reference' is accepted)",
              a, base));
        }
        b.scenario = base;
        b.display_name = a.empty() ? base : base + "@" + a;
      }
      out.push_back(std::move(b));
    }
  }
  return out;
}

Status BenchConfig::Validate(const Registries& registries) const {
  std::vector<std::string> errors;
  if (scenarios.empty()) errors.push_back("no scenario");
  if (planners.empty()) errors.push_back("no planner");
  if (seeds.empty()) errors.push_back("no seed");
  const Result<std::vector<BenchScenario>> list =
      ExpandScenarioList(scenarios, registries.scenarios);
  if (!list.ok()) {
    errors.push_back(list.status().message());
  } else {
    for (const BenchScenario& b : *list) {
      std::error_code ec;
      if (!b.scene_file.empty() && !fs::is_regular_file(b.scene_file, ec)) {
        errors.push_back(fmt::format(
            "scenarios entry {}: scene file '{}' {}", QuoteEntry(b.entry), b.scene_file.string(),
            fs::exists(b.scene_file, ec) ? "is not a regular file" : "does not exist"));
      }
    }
    if (Status s = CheckDisplayNames(*list); !s.ok()) errors.push_back(s.message());
  }
  if (!base.arrangement.empty()) {
    errors.push_back(
        fmt::format("the run configuration's arrangement ('{}') is set per scenarios entry: give "
                    "FILE.yaml@ARRANGEMENT there",
                    base.arrangement));
  }
  for (const std::string& p : planners) {
    const auto options = planner_options.find(p);
    const Result<AnyOptions> o = registries.planners.Options(
        p, options == planner_options.end() ? OptionValues{} : options->second);
    if (!o.ok()) errors.push_back(o.status().message());
  }
  for (const auto& [planner, options] : planner_options) {
    if (std::find(planners.begin(), planners.end(), planner) == planners.end()) {
      errors.push_back(
          fmt::format("options are given for planner '{}', which is not among the "
                      "planners ({})",
                      planner, fmt::join(planners, ", ")));
    }
  }
  for (const std::string& p : planners) {
    if (p.empty()) errors.push_back("a planner name is empty");
  }
  if (shard_count == 0 || shard_index == 0 || shard_index > shard_count) {
    errors.push_back(
        fmt::format("the shard {}/{} must be K/N with 1 <= K <= N", shard_index, shard_count));
  }
  if (resume && force) {
    errors.push_back("--resume keeps the finished runs and --force removes them: give one");
  }
  if (!conditions.empty() && (shard_count != 1 || resume)) {
    errors.push_back(
        "a bench with conditions is not sharded or resumed (yet): run each condition as its own "
        "bench (avp bench --set ...) and compare them with avp bench compare");
  }
  if (Status s = CheckSeedCount(seeds.size(), "seeds"); !s.ok()) errors.push_back(s.message());
  const size_t num_scenarios = list.ok() ? list->size() : scenarios.size();
  uint64_t shown = 0;
  // Every condition runs the whole bench again.
  const uint64_t runs = std::max<uint64_t>(1, conditions.size());
  if (__builtin_mul_overflow(uint64_t{num_scenarios}, uint64_t{planners.size()}, &shown) ||
      __builtin_mul_overflow(shown, uint64_t{seeds.size()}, &shown) ||
      __builtin_mul_overflow(shown, runs, &shown)) {
    shown = UINT64_MAX;
  }
  if (Status s = MaxBenchEpisodes().Check(
          fmt::format("{} scenarios x {} planners x {} seeds{}", num_scenarios, planners.size(),
                      seeds.size(), runs > 1 ? fmt::format(" x {} conditions", runs) : ""),
          shown);
      !s.ok()) {
    return s;
  }
  const std::set<uint64_t> unique(seeds.begin(), seeds.end());
  if (unique.size() != seeds.size()) errors.push_back("seeds repeat");
  if (jobs < 0 || jobs > kMaxThreads) {
    errors.push_back(fmt::format("jobs ({}) must be in [0, {}]", jobs, kMaxThreads));
  }
  if (out_dir.empty()) errors.push_back("the output folder (--out) is empty");
  std::set<std::string> condition_names;
  for (const BenchCondition& c : conditions) {
    if (!IsConditionName(c.name)) {
      errors.push_back(fmt::format(
          "condition name {} must be a folder name: letters, digits, '.', '-', '_' (not first '.')",
          QuoteText(c.name)));
      continue;
    }
    if (!condition_names.insert(c.name).second) {
      errors.push_back(fmt::format("condition '{}' is given twice", c.name));
      continue;
    }
    Result<BenchConfig> derived = ConditionBenchConfig(*this, c);
    if (derived.ok()) {
      if (Status s = derived->Validate(registries); !s.ok()) {
        errors.push_back(fmt::format("condition '{}': {}", c.name, s.message()));
      }
    } else {
      errors.push_back(derived.status().message());
    }
  }
  if (errors.empty()) {
    RunConfig probe = JobBase(*this);
    probe.scenario = list->front().scenario;
    probe.scene_file = list->front().scene_file;
    probe.planner.name = planners.front();
    probe.planner.options.clear();
    return probe.Validate(registries).WithContext("invalid bench configuration");
  }
  return InvalidArgumentError("invalid bench configuration: " +
                              fmt::format("{}", fmt::join(errors, "; ")));
}

Result<BenchConfig> LoadBenchConfig(const fs::path& yaml) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node root, io::LoadYamlFile(yaml));
  const std::string ctx = yaml.string();
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(
      root,
      {"description", "scenarios", "planners", "seeds", "planner_options", "run", "conditions"},
      ctx));
  BenchConfig o;
  try {
    if (root["description"]) o.description = root["description"].as<std::string>();
    AVP_RETURN_IF_ERROR(ReadStrings(root, "scenarios", ctx, o.scenarios));
    // A scene file of the list is relative to the config file.
    for (std::string& entry : o.scenarios) {
      if (!IsSceneFileEntry(entry)) continue;
      const size_t at = entry.rfind('@');
      const fs::path file = entry.substr(0, at);
      if (file.is_relative()) {
        entry = (yaml.parent_path() / file).lexically_normal().string() +
                (at == std::string::npos ? std::string() : entry.substr(at));
      }
    }
    AVP_RETURN_IF_ERROR(ReadStrings(root, "planners", ctx, o.planners));
    AVP_RETURN_IF_ERROR(ReadSeeds(root["seeds"], ctx, o.seeds));
    AVP_RETURN_IF_ERROR(ReadPlannerOptions(root["planner_options"], ctx, o));
    AVP_RETURN_IF_ERROR(ReadRunConfigYaml(root["run"], ctx + ": run", o.base));
    AVP_RETURN_IF_ERROR(RejectPerJobKeys(root["run"], ctx));
    AVP_RETURN_IF_ERROR(ReadConditions(root["conditions"], ctx, o));
  } catch (const YAML::Exception& e) {
    return InvalidArgumentError(fmt::format("{}: {}", ctx, e.what()));
  }
  return o;
}

namespace {

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
  nlohmann::json manifest = {
      {"format", kManifestFormat},
      {"bench", DescriptionJson(config, list)},
      {"revision", revision},
      {"jobs", JobsJson(groups, refs)},
      {"shard", {{"index", config.shard_index}, {"count", config.shard_count}}},
      {"ground_truth", nlohmann::json::array()},
      {"seconds", 0.0}};
  std::map<GroupKey, report::FruitVisibility> visibility;
  double previous_seconds = 0.0;
  if (previous.has_value()) {
    if (const std::string d = ManifestDifference(*previous, manifest, true); !d.empty()) {
      return FailedPreconditionError(fmt::format(
          "cannot resume '{}': it holds another bench ({} differs); give another --out, or "
          "--force to start it again",
          config.out_dir.string(), d));
    }
    visibility = VisibilityFromJson(previous->at("ground_truth"));
    previous_seconds = previous->value("seconds", 0.0);
  }
  std::vector<size_t> mine = ShardJobs(refs, groups.size(), config.shard_index, config.shard_count);
  std::vector<size_t> pending;
  const auto run_dir = [&](size_t i) {
    return config.out_dir / report::BenchRunFolder(groups[refs[i].group].scenario, refs[i].planner,
                                                   groups[refs[i].group].seed);
  };
  for (size_t i : mine) {
    if (config.resume && RunIsComplete(run_dir(i))) continue;
    // An unfinished or failed run of the interrupted bench: emptied (only what avp writes).
    if (config.resume) AVP_RETURN_IF_ERROR(PrepareOutputFolder(run_dir(i), RunFolderKind(), true));
    pending.push_back(i);
  }
  // The ground truth of the groups with a job to run, and of those whose visibility is unknown.
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
  manifest["ground_truth"] = VisibilityJson(visibility);
  manifest["seconds"] = previous_seconds;
  AVP_RETURN_IF_ERROR(io::WriteJsonFile(config.out_dir / kManifestName, manifest));

  WriteFailure failure;
  {
    report::Progress bar(report::ProgressOn(stderr, "episodes", pending.size(), config.progress));
    ParallelFor(pending.size(), config.jobs, [&](size_t t) {
      const JobRef& r = refs[pending[t]];
      const report::BenchEpisode e =
          RunJob(config, registries, groups[r.group], r.planner, revision, failure);
      bar.Done(fmt::format("{} {} seed {} {}", e.scenario, e.planner, e.seed,
                           e.status.ok() ? "ok" : "failed"));
    });
  }
  if (failure.failed()) return failure.first();
  // Every episode of this folder as written: the same numbers whether it ran now, in an earlier
  // (resumed) run, or on another machine (MergeBenches).
  std::vector<report::BenchEpisode> episodes;
  episodes.reserve(mine.size());
  for (size_t i : mine) {
    const Group& g = groups[refs[i].group];
    AVP_ASSIGN_OR_RETURN(report::BenchEpisode e,
                         report::ReadBenchEpisode(run_dir(i), g.scenario, refs[i].planner, g.seed));
    episodes.push_back(std::move(e));
  }
  const double seconds = previous_seconds + SecondsSince(t0);
  manifest["seconds"] = seconds;
  AVP_RETURN_IF_ERROR(io::WriteJsonFile(config.out_dir / kManifestName, manifest));
  BenchSummary summary;
  if (config.shard_count == 1) {
    report::BenchDescription description = DescriptionFromJson(manifest["bench"], revision);
    description.visibility = VisibilityByScenario(visibility);
    AVP_ASSIGN_OR_RETURN(summary,
                         WriteSummaryAndReport(config.out_dir, description, episodes, seconds));
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

namespace {

/// True when `inner` is `outer` or lies inside it (both made absolute and normal).
bool IsInside(const fs::path& inner, const fs::path& outer) {
  std::error_code ec;
  const fs::path in = fs::weakly_canonical(fs::absolute(inner, ec), ec);
  const fs::path out = fs::weakly_canonical(fs::absolute(outer, ec), ec);
  if (ec || in.empty() || out.empty()) return false;
  return std::mismatch(out.begin(), out.end(), in.begin(), in.end()).first == out.end();
}

std::string JobName(const nlohmann::json& job) {
  return fmt::format("{} / {} / seed {}", job.at(0).get<std::string>(),
                     job.at(1).get<std::string>(), job.at(2).get<uint64_t>());
}

}  // namespace

Result<BenchSummary> MergeBenches(const std::vector<fs::path>& shards, const fs::path& out_dir,
                                  bool force, bool progress) {
  if (shards.empty()) return InvalidArgumentError("no shard folder to merge");
  std::vector<nlohmann::json> manifests;
  std::map<uint64_t, fs::path> by_index;
  for (const fs::path& dir : shards) {
    if (IsInside(out_dir, dir) || IsInside(dir, out_dir)) {
      return InvalidArgumentError(
          fmt::format("the output folder '{}' and the shard '{}' lie one inside the other: give "
                      "another --out",
                      out_dir.string(), dir.string()));
    }
    AVP_ASSIGN_OR_RETURN(nlohmann::json m, ReadManifest(dir));
    AVP_ASSIGN_OR_RETURN(const FolderState state, ReadFolderState(dir));
    if (state.state != "complete") {
      return FailedPreconditionError(fmt::format(
          "the shard '{}' is {} (not complete): rerun its avp bench with --resume first",
          dir.string(), state.state));
    }
    if (!manifests.empty()) {
      if (const std::string d = ManifestDifference(manifests.front(), m, false); !d.empty()) {
        return InvalidArgumentError(
            fmt::format("the shards '{}' and '{}' are not of one bench: {} differs",
                        shards.front().string(), dir.string(), d));
      }
    }
    const uint64_t index = m.at("shard").at("index").get<uint64_t>();
    if (const auto [it, fresh] = by_index.emplace(index, dir); !fresh) {
      return InvalidArgumentError(fmt::format("shard {}/{} is given twice: '{}' and '{}'", index,
                                              m.at("shard").at("count").get<uint64_t>(),
                                              it->second.string(), dir.string()));
    }
    manifests.push_back(std::move(m));
  }
  const nlohmann::json& first = manifests.front();
  const nlohmann::json& jobs = first.at("jobs");
  // Each job from the one shard whose folder holds it complete.
  std::vector<fs::path> source(jobs.size());
  std::vector<std::string> missing;
  for (size_t i = 0; i < jobs.size(); ++i) {
    const fs::path rel =
        report::BenchRunFolder(jobs[i].at(0).get<std::string>(), jobs[i].at(1).get<std::string>(),
                               jobs[i].at(2).get<uint64_t>());
    for (const fs::path& dir : shards) {
      std::error_code ec;
      if (!fs::exists(dir / rel / kStateFileName, ec)) continue;
      if (!source[i].empty()) {
        return InvalidArgumentError(fmt::format("the job {} is in two shards: '{}' and '{}'",
                                                JobName(jobs[i]), source[i].string(),
                                                dir.string()));
      }
      source[i] = dir / rel;
    }
    if (source[i].empty()) missing.push_back(JobName(jobs[i]));
  }
  if (!missing.empty()) {
    std::vector<uint64_t> absent;
    for (uint64_t k = 1; k <= first.at("shard").at("count").get<uint64_t>(); ++k) {
      if (!by_index.contains(k)) absent.push_back(k);
    }
    return InvalidArgumentError(fmt::format(
        "{} of {} jobs are in no shard (first: {}){}", missing.size(), jobs.size(), missing.front(),
        absent.empty() ? std::string()
                       : fmt::format("; shards {} of {} are not given", fmt::join(absent, ", "),
                                     first.at("shard").at("count").get<uint64_t>())));
  }
  AVP_RETURN_IF_ERROR(PrepareOutputFolder(out_dir, BenchFolderKind(), force));
  AVP_RETURN_IF_ERROR(MarkInProgress(out_dir, BenchFolderKind(), "avp bench merge"));
  const auto fail = [&](const Status& s) {
    MarkFailed(out_dir, BenchFolderKind(), "avp bench merge", s);
    return s;
  };
  std::map<GroupKey, report::FruitVisibility> visibility;
  double seconds = 0.0;
  for (const nlohmann::json& m : manifests) {
    visibility.merge(VisibilityFromJson(m.at("ground_truth")));
    seconds += m.value("seconds", 0.0);
  }
  std::vector<report::BenchEpisode> episodes;
  episodes.reserve(jobs.size());
  {
    report::Progress bar(report::ProgressOn(stderr, "runs copied", jobs.size(), progress));
    for (size_t i = 0; i < jobs.size(); ++i) {
      const std::string scenario = jobs[i].at(0).get<std::string>();
      const std::string planner = jobs[i].at(1).get<std::string>();
      const uint64_t seed = jobs[i].at(2).get<uint64_t>();
      const fs::path to = out_dir / report::BenchRunFolder(scenario, planner, seed);
      std::error_code ec;
      fs::create_directories(to.parent_path(), ec);
      if (!ec) fs::copy(source[i], to, fs::copy_options::recursive, ec);
      if (ec) {
        return fail(IoError(fmt::format("cannot copy '{}' to '{}': {}", source[i].string(),
                                        to.string(), ec.message())));
      }
      Result<report::BenchEpisode> e = report::ReadBenchEpisode(to, scenario, planner, seed);
      if (!e.ok()) return fail(e.status());
      episodes.push_back(std::move(*e));
      bar.Done(fmt::format("{} {} seed {}", scenario, planner, seed));
    }
  }
  nlohmann::json manifest = first;
  manifest["shard"] = {{"index", 1}, {"count", 1}};
  manifest["ground_truth"] = VisibilityJson(visibility);
  manifest["seconds"] = seconds;
  manifest["merged_from"] = nlohmann::json::array();
  for (const fs::path& dir : shards) manifest["merged_from"].push_back(dir.string());
  if (Status s = io::WriteJsonFile(out_dir / kManifestName, manifest); !s.ok()) return fail(s);
  report::BenchDescription description =
      DescriptionFromJson(first.at("bench"), first.at("revision").get<std::string>());
  description.visibility = VisibilityByScenario(visibility);
  Result<BenchSummary> summary = WriteSummaryAndReport(out_dir, description, episodes, seconds);
  if (!summary.ok()) return fail(summary.status());
  AVP_RETURN_IF_ERROR(MarkComplete(out_dir, BenchFolderKind(), "avp bench merge"));
  // The bench's time: its shards' wall times added up (as summary.md says), not the copying's.
  summary->seconds = seconds;
  return summary;
}

Result<BenchConfig> ConditionBenchConfig(const BenchConfig& config, const BenchCondition& c) {
  BenchConfig b = config;
  b.conditions.clear();
  b.out_dir = config.out_dir / c.name;
  b.force = false;  // the conditions' folder was empty, or emptied
  for (const auto& [key, value] : c.run) {
    if (Status s = SetRunConfigKey(b.base, key, value); !s.ok()) {
      return InvalidArgumentError(fmt::format("condition '{}': run: {}", c.name, s.message()));
    }
  }
  for (const auto& [planner, values] : c.planner_options) {
    for (const auto& kv : values) b.planner_options[planner].push_back(kv);
  }
  const std::string what = c.description.empty() ? c.name : c.name + ": " + c.description;
  b.description =
      config.description.empty() ? "condition " + what : config.description + "; condition " + what;
  return b;
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

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <stop_token>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include <avp/core/parallel.h>
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

Result<std::vector<Group>> BuildGroups(const BenchConfig& config, const Registries& registries,
                                       std::vector<BenchScenario>& list) {
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
  std::vector<Status> scene_status(groups.size());
  report::Progress bar(report::ProgressOn(stderr, "ground truth", groups.size(), config.progress));
  ParallelFor(groups.size(), config.jobs, [&](size_t i) {
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
  for (size_t i = 0; i < groups.size(); ++i) {
    const Group& g = groups[i];
    if (!scene_status[i].ok()) return scene_status[i];
    if (!g.gt.ok()) {
      return Status(g.gt.status().code(), fmt::format("ground truth of {} seed {}: {}", g.scenario,
                                                      g.seed, g.gt.status().message()));
    }
  }
  return groups;
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

report::BenchDescription Describe(const BenchConfig& config, const std::vector<BenchScenario>& list,
                                  const std::vector<Group>& groups, const std::string& revision) {
  report::BenchDescription d;
  for (const BenchScenario& b : list) d.scenarios.push_back(b.display_name);
  d.planners = config.planners;
  d.seeds = config.seeds.size();
  d.views = config.base.episode.views;
  d.segmenter = config.base.segmenter.name;
  d.voxel_size_m = config.base.map.grid.voxel_size_m;
  d.revision = revision;
  d.planner_options = config.planner_options;
  d.description = config.description;
  d.run_options = RunConfigTable().Differences(JobBase(config), JobBase(BenchConfig{}));
  for (const Group& g : groups) d.visibility[g.scenario].Add(*g.gt);
  return d;
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
                                      std::vector<BenchScenario>& list, Clock::time_point t0) {
  std::error_code ec;
  fs::create_directories(config.out_dir / "runs", ec);
  if (ec) {
    return IoError(
        fmt::format("cannot create '{}': {}", (config.out_dir / "runs").string(), ec.message()));
  }
  AVP_ASSIGN_OR_RETURN(const std::vector<Group> groups, BuildGroups(config, registries, list));
  // Asked of git once, not per episode (two processes each).
  const std::string revision = report::SourceRevision();
  struct JobRef {
    size_t group;
    std::string planner;
  };
  std::vector<JobRef> refs;
  for (size_t gi = 0; gi < groups.size(); ++gi) {
    for (const std::string& p : config.planners) refs.push_back({gi, p});
  }
  std::vector<report::BenchEpisode> episodes(refs.size());
  WriteFailure failure;
  {
    report::Progress bar(report::ProgressOn(stderr, "episodes", refs.size(), config.progress));
    ParallelFor(refs.size(), config.jobs, [&](size_t i) {
      episodes[i] =
          RunJob(config, registries, groups[refs[i].group], refs[i].planner, revision, failure);
      const report::BenchEpisode& e = episodes[i];
      bar.Done(fmt::format("{} {} seed {} {}", e.scenario, e.planner, e.seed,
                           e.status.ok() ? "ok" : "failed"));
    });
  }
  if (failure.failed()) return failure.first();
  const report::BenchDescription description = Describe(config, list, groups, revision);
  const double seconds = SecondsSince(t0);
  AVP_ASSIGN_OR_RETURN(report::BenchTables tables,
                       report::WriteBenchSummary(config.out_dir, description, episodes, seconds));
  // report.html: the same numbers as the summary, with per-scenario plots and links to the runs.
  const fs::path html = config.out_dir / "report.html";
  AVP_RETURN_IF_ERROR(report::WriteBenchReportHtml(
      html, report::BenchReportJson(description, episodes, seconds, config.out_dir)));
  BenchSummary summary;
  summary.cells = std::move(tables.cells);
  summary.files = std::move(tables.files);
  summary.files.push_back(html);
  summary.report_html = html;
  summary.episodes = episodes.size();
  summary.failed = tables.failed;
  return summary;
}

}  // namespace

Result<BenchSummary> RunBench(const BenchConfig& config, const Registries& registries) {
  const auto t0 = Clock::now();
  AVP_RETURN_IF_ERROR(config.Validate(registries));
  AVP_ASSIGN_OR_RETURN(std::vector<BenchScenario> list,
                       ExpandScenarioList(config.scenarios, registries.scenarios));
  AVP_RETURN_IF_ERROR(CheckBenchOutputs(config, list));
  AVP_RETURN_IF_ERROR(PrepareOutputFolder(config.out_dir, BenchFolderKind(), config.force));
  AVP_RETURN_IF_ERROR(MarkInProgress(config.out_dir, BenchFolderKind(), "avp bench"));
  Result<BenchSummary> summary = RunBenchInFolder(config, registries, list, t0);
  if (!summary.ok()) {
    MarkFailed(config.out_dir, BenchFolderKind(), "avp bench", summary.status());
    return summary.status();
  }
  AVP_RETURN_IF_ERROR(MarkComplete(config.out_dir, BenchFolderKind(), "avp bench"));
  summary->seconds = SecondsSince(t0);
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

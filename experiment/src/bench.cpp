#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
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
#include <avp/experiment/episode_runner.h>
#include <avp/experiment/output_folder.h>
#include <avp/io/file.h>
#include <avp/io/json.h>
#include <avp/io/options_yaml.h>
#include <avp/io/yaml.h>
#include <avp/report/metrics_csv.h>
#include <avp/report/provenance.h>
#include <avp/report/run_report.h>

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

/// One (scenario, seed): its scene and ground truth, shared by the planners.
struct Group {
  std::string scenario;
  uint64_t seed = 0;
  Result<sim::Scene> scene = InternalError("not built");
  Result<eval::GroundTruth> gt = InternalError("not computed");
};

class ProgressBar {
 public:
  ProgressBar(bool enabled, size_t total, std::string what)
      : enabled_(enabled), total_(total), what_(std::move(what)), t0_(Clock::now()) {}
  void Tick() {
    const size_t done = ++done_;
    if (!enabled_) return;
    std::lock_guard<std::mutex> lock(mu_);
    const double s = SecondsSince(t0_);
    const double eta =
        done > 0 ? s / static_cast<double>(done) * static_cast<double>(total_ - done) : 0.0;
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(kWidth * static_cast<double>(done) /
                                        static_cast<double>(std::max<size_t>(total_, 1)));
    std::fprintf(stderr, "\r%s [%s%s] %zu/%zu  %.0f s elapsed, ~%.0f s left   ", what_.c_str(),
                 std::string(static_cast<size_t>(filled), '#').c_str(),
                 std::string(static_cast<size_t>(kWidth - filled), '.').c_str(), done, total_, s,
                 eta);
    if (done == total_) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  }

 private:
  bool enabled_;
  size_t total_;
  std::string what_;
  Clock::time_point t0_;
  std::atomic<size_t> done_{0};
  std::mutex mu_;
};

/// The base configuration of every job: one thread inside, the scene from the job's scenario.
RunConfig JobBase(const BenchConfig& config) {
  RunConfig base = config.base;
  base.threads = 1;
  base.scene_file.clear();
  return base;
}

RunConfig JobConfig(const BenchConfig& config, const std::string& scenario, uint64_t seed,
                    const std::string& planner) {
  RunConfig c = JobBase(config);
  c.scenario = scenario;
  c.seed = seed;
  c.planner.name = planner;
  const auto options = config.planner_options.find(planner);
  c.planner.options = options == config.planner_options.end() ? OptionValues{} : options->second;
  return c;
}

Result<std::vector<Group>> BuildGroups(const BenchConfig& config, const Registries& registries) {
  std::vector<Group> groups;
  for (const std::string& s : config.scenarios) {
    for (uint64_t seed : config.seeds) groups.push_back(Group{s, seed});
  }
  ProgressBar bar(config.progress, groups.size(), "ground truth");
  ParallelFor(groups.size(), config.jobs, [&](size_t i) {
    Group& g = groups[i];
    g.scene = registries.scenarios.Make(g.scenario, g.seed);
    if (g.scene.ok()) {
      RunConfig c = JobBase(config);
      c.scenario = g.scenario;
      c.seed = g.seed;
      g.gt = GroundTruthFor(c, *g.scene);
    }
    bar.Tick();
  });
  for (const Group& g : groups) {
    if (!g.scene.ok()) return g.scene.status();
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
  const RunConfig c = JobConfig(config, g.scenario, g.seed, planner);
  const fs::path dir = config.out_dir / "runs" / report::SafeFileName(j.scenario) /
                       report::SafeFileName(j.planner) / fmt::format("seed-{}", j.seed);
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
  const std::vector<pipeline::EpisodeObserver*> observers = {csv->get()};
  const auto te = Clock::now();
  Result<RunResult> r = RunEpisodeOnScene(c, registries, *g.scene, *g.gt, observers, nullptr,
                                          failure.stop().get_token());
  j.episode_s = SecondsSince(te);
  if (Status s = (*csv)->Close(); !s.ok()) return fail(s);
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
  const planning::PlannerEntry* entry = registries.planners.Find(planner);
  const nlohmann::json options = io::OptionsToJson(
      c.planner.options, entry != nullptr ? entry->options.Info() : std::vector<OptionInfo>{});
  const nlohmann::json rec{{"scenario", j.scenario},
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
  if (Status s = io::WriteJsonFile(dir / "record.json", rec); !s.ok()) return fail(s);
  if (Status s = MarkComplete(dir, RunFolderKind(), "avp bench"); !s.ok()) return fail(s);
  // A segmenter that failed (a service that is down) leaves views without segmentation: the
  // episode is kept on disk but counted as failed, out of the statistics.
  if (r->episode.end == pipeline::EpisodeEnd::kSegmenterFault) {
    j.status = UnavailableError(fmt::format("segmenter fault: {}", r->episode.end_reason));
  }
  return j;
}

report::BenchDescription Describe(const BenchConfig& config, const std::vector<Group>& groups,
                                  const std::string& revision) {
  report::BenchDescription d;
  d.scenarios = config.scenarios;
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
  for (const char* key : {"scenario", "scene_file", "seed", "planner", "threads"}) {
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

}  // namespace

Status BenchConfig::Validate(const Registries& registries) const {
  std::vector<std::string> errors;
  if (scenarios.empty()) errors.push_back("no scenario");
  if (planners.empty()) errors.push_back("no planner");
  if (seeds.empty()) errors.push_back("no seed");
  for (const std::string& s : scenarios) {
    if (registries.scenarios.Find(s) == nullptr) {
      errors.push_back(fmt::format("unknown scenario '{}' (known: {})", s,
                                   fmt::join(registries.scenarios.Names(), ", ")));
    }
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
  for (const std::string& s : scenarios) {
    if (s.empty()) errors.push_back("a scenario name is empty");
  }
  for (const std::string& p : planners) {
    if (p.empty()) errors.push_back("a planner name is empty");
  }
  if (Status s = CheckSeedCount(seeds.size(), "seeds"); !s.ok()) errors.push_back(s.message());
  uint64_t shown = 0;
  if (__builtin_mul_overflow(uint64_t{scenarios.size()}, uint64_t{planners.size()}, &shown) ||
      __builtin_mul_overflow(shown, uint64_t{seeds.size()}, &shown)) {
    shown = UINT64_MAX;
  }
  if (Status s =
          MaxBenchEpisodes().Check(fmt::format("{} scenarios x {} planners x {} seeds",
                                               scenarios.size(), planners.size(), seeds.size()),
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
  if (errors.empty()) {
    RunConfig probe = JobBase(*this);
    probe.scenario = scenarios.front();
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
      root, {"description", "scenarios", "planners", "seeds", "planner_options", "run"}, ctx));
  BenchConfig o;
  try {
    if (root["description"]) o.description = root["description"].as<std::string>();
    AVP_RETURN_IF_ERROR(ReadStrings(root, "scenarios", ctx, o.scenarios));
    AVP_RETURN_IF_ERROR(ReadStrings(root, "planners", ctx, o.planners));
    AVP_RETURN_IF_ERROR(ReadSeeds(root["seeds"], ctx, o.seeds));
    AVP_RETURN_IF_ERROR(ReadPlannerOptions(root["planner_options"], ctx, o));
    AVP_RETURN_IF_ERROR(ReadRunConfigYaml(root["run"], ctx + ": run", o.base));
    AVP_RETURN_IF_ERROR(RejectPerJobKeys(root["run"], ctx));
  } catch (const YAML::Exception& e) {
    return InvalidArgumentError(fmt::format("{}: {}", ctx, e.what()));
  }
  return o;
}

namespace {

/// Outputs never overwrite inputs: the bench folder and its summary files against the inputs.
Status CheckBenchOutputs(const BenchConfig& config) {
  for (const auto& [input, what] : config.inputs) {
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(config.out_dir, "bench folder", input, what));
    for (const char* name :
         {"summary.md", "summary.csv", "fruits_by_visibility.csv", "avp-state.json"}) {
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
                                      Clock::time_point t0) {
  std::error_code ec;
  fs::create_directories(config.out_dir / "runs", ec);
  if (ec) {
    return IoError(
        fmt::format("cannot create '{}': {}", (config.out_dir / "runs").string(), ec.message()));
  }
  AVP_ASSIGN_OR_RETURN(const std::vector<Group> groups, BuildGroups(config, registries));
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
    ProgressBar bar(config.progress, refs.size(), "episodes");
    ParallelFor(refs.size(), config.jobs, [&](size_t i) {
      episodes[i] =
          RunJob(config, registries, groups[refs[i].group], refs[i].planner, revision, failure);
      bar.Tick();
    });
  }
  if (failure.failed()) return failure.first();
  AVP_ASSIGN_OR_RETURN(report::BenchTables tables,
                       report::WriteBenchSummary(config.out_dir, Describe(config, groups, revision),
                                                 episodes, SecondsSince(t0)));
  BenchSummary summary;
  summary.cells = std::move(tables.cells);
  summary.files = std::move(tables.files);
  summary.episodes = episodes.size();
  summary.failed = tables.failed;
  return summary;
}

}  // namespace

Result<BenchSummary> RunBench(const BenchConfig& config, const Registries& registries) {
  const auto t0 = Clock::now();
  AVP_RETURN_IF_ERROR(config.Validate(registries));
  AVP_RETURN_IF_ERROR(CheckBenchOutputs(config));
  AVP_RETURN_IF_ERROR(PrepareOutputFolder(config.out_dir, BenchFolderKind(), config.force));
  AVP_RETURN_IF_ERROR(MarkInProgress(config.out_dir, BenchFolderKind(), "avp bench"));
  Result<BenchSummary> summary = RunBenchInFolder(config, registries, t0);
  if (!summary.ok()) {
    MarkFailed(config.out_dir, BenchFolderKind(), "avp bench", summary.status());
    return summary.status();
  }
  AVP_RETURN_IF_ERROR(MarkComplete(config.out_dir, BenchFolderKind(), "avp bench"));
  summary->seconds = SecondsSince(t0);
  return summary;
}

}  // namespace avp::experiment

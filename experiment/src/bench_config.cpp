// BenchConfig: the bench file (YAML), its scenarios list (registered scenarios, scene files with
// their arrangements), each condition's derived bench, and Validate.

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <yaml-cpp/yaml.h>

#include <avp/core/text.h>
#include <avp/experiment/bench.h>
#include <avp/experiment/output_folder.h>
#include <avp/io/options_yaml.h>
#include <avp/io/yaml.h>
#include <avp/report/bench_summary.h>
#include <avp/sim/scenario.h>

#include "bench_internal.h"

namespace avp::experiment {

namespace fs = std::filesystem;

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

namespace internal {

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

}  // namespace internal

namespace {

using internal::CheckDisplayNames;
using internal::QuoteEntry;

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

/// The scenarios list: entries that parse, scene files that exist, display names distinct.
void CheckScenarioList(const Result<std::vector<BenchScenario>>& list,
                       std::vector<std::string>& errors) {
  if (!list.ok()) {
    errors.push_back(list.status().message());
    return;
  }
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

/// Each planner's options valid, options only for listed planners, no empty planner name.
void CheckPlanners(const BenchConfig& config, const Registries& registries,
                   std::vector<std::string>& errors) {
  for (const std::string& p : config.planners) {
    const auto options = config.planner_options.find(p);
    const Result<AnyOptions> o = registries.planners.Options(
        p, options == config.planner_options.end() ? OptionValues{} : options->second);
    if (!o.ok()) errors.push_back(o.status().message());
  }
  for (const auto& [planner, options] : config.planner_options) {
    if (std::find(config.planners.begin(), config.planners.end(), planner) ==
        config.planners.end()) {
      errors.push_back(
          fmt::format("options are given for planner '{}', which is not among the "
                      "planners ({})",
                      planner, fmt::join(config.planners, ", ")));
    }
  }
  for (const std::string& p : config.planners) {
    if (p.empty()) errors.push_back("a planner name is empty");
  }
}

/// The shard K/N, --resume against --force, and conditions (neither sharded nor resumed).
void CheckShardsAndResume(const BenchConfig& config, std::vector<std::string>& errors) {
  if (config.shard_count == 0 || config.shard_index == 0 ||
      config.shard_index > config.shard_count) {
    errors.push_back(fmt::format("the shard {}/{} must be K/N with 1 <= K <= N", config.shard_index,
                                 config.shard_count));
  }
  if (config.resume && config.force) {
    errors.push_back("--resume keeps the finished runs and --force removes them: give one");
  }
  if (!config.conditions.empty() && (config.shard_count != 1 || config.resume)) {
    errors.push_back(
        "a bench with conditions is not sharded or resumed (yet): run each condition as its own "
        "bench (avp bench --set ...) and compare them with avp bench compare");
  }
}

/// scenarios x planners x seeds (x conditions: every condition runs the whole bench again)
/// against max_bench_episodes.
Status CheckEpisodeCount(const BenchConfig& config, size_t num_scenarios) {
  uint64_t shown = 0;
  const uint64_t runs = std::max<uint64_t>(1, config.conditions.size());
  if (__builtin_mul_overflow(uint64_t{num_scenarios}, uint64_t{config.planners.size()}, &shown) ||
      __builtin_mul_overflow(shown, uint64_t{config.seeds.size()}, &shown) ||
      __builtin_mul_overflow(shown, runs, &shown)) {
    shown = UINT64_MAX;
  }
  return MaxBenchEpisodes().Check(
      fmt::format("{} scenarios x {} planners x {} seeds{}", num_scenarios, config.planners.size(),
                  config.seeds.size(), runs > 1 ? fmt::format(" x {} conditions", runs) : ""),
      shown);
}

/// Each condition: a folder name, given once, and its derived bench valid.
void CheckConditions(const BenchConfig& config, const Registries& registries,
                     std::vector<std::string>& errors) {
  std::set<std::string> condition_names;
  for (const BenchCondition& c : config.conditions) {
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
    Result<BenchConfig> derived = ConditionBenchConfig(config, c);
    if (derived.ok()) {
      if (Status s = derived->Validate(registries); !s.ok()) {
        errors.push_back(fmt::format("condition '{}': {}", c.name, s.message()));
      }
    } else {
      errors.push_back(derived.status().message());
    }
  }
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
  CheckScenarioList(list, errors);
  if (!base.arrangement.empty()) {
    errors.push_back(
        fmt::format("the run configuration's arrangement ('{}') is set per scenarios entry: give "
                    "FILE.yaml@ARRANGEMENT there",
                    base.arrangement));
  }
  CheckPlanners(*this, registries, errors);
  CheckShardsAndResume(*this, errors);
  if (Status s = CheckSeedCount(seeds.size(), "seeds"); !s.ok()) errors.push_back(s.message());
  AVP_RETURN_IF_ERROR(CheckEpisodeCount(*this, list.ok() ? list->size() : scenarios.size()));
  const std::set<uint64_t> unique(seeds.begin(), seeds.end());
  if (unique.size() != seeds.size()) errors.push_back("seeds repeat");
  if (jobs < 0 || jobs > kMaxThreads) {
    errors.push_back(fmt::format("jobs ({}) must be in [0, {}]", jobs, kMaxThreads));
  }
  if (out_dir.empty()) errors.push_back("the output folder (--out) is empty");
  CheckConditions(*this, registries, errors);
  if (errors.empty()) {
    RunConfig probe = internal::JobBase(*this);
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
  return ReadBenchConfigYaml(root, yaml.string(), yaml.parent_path());
}

Result<BenchConfig> ReadBenchConfigYaml(const YAML::Node& root, std::string_view context,
                                        const fs::path& base_dir) {
  const std::string ctx(context);
  if (!root.IsMap()) {
    return InvalidArgumentError(fmt::format("{}: a bench configuration is a mapping", ctx));
  }
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
        entry = (base_dir / file).lexically_normal().string() +
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

void FillBenchDefaults(BenchConfig& config, const Registries& registries) {
  if (config.scenarios.empty()) config.scenarios = registries.scenarios.EvaluationNames();
  if (config.planners.empty()) config.planners = {"avp-nbv", "predefined", "reference-nbv"};
  if (config.seeds.empty()) {
    for (uint64_t i = 0; i < 10; ++i) config.seeds.push_back(i);
  }
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

}  // namespace avp::experiment

// bench.json, what a bench folder holds (the bench's description, its job list, the shard, the
// fruits' visibility per group), for resuming a bench and merging its shards; the shards' jobs
// and MergeBenches.

#include <algorithm>
#include <cstdint>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

#include <avp/core/rng.h>
#include <avp/experiment/bench.h>
#include <avp/experiment/output_folder.h>
#include <avp/io/json.h>
#include <avp/report/bench_html.h>
#include <avp/report/conditions.h>
#include <avp/report/progress.h>

#include "bench_internal.h"

namespace avp::experiment {

namespace fs = std::filesystem;

namespace internal {

namespace {

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

}  // namespace

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

nlohmann::json JobsJson(const std::vector<Group>& groups, const std::vector<JobRef>& refs) {
  nlohmann::json out = nlohmann::json::array();
  for (const JobRef& r : refs) {
    out.push_back({groups[r.group].scenario, r.planner, groups[r.group].seed});
  }
  return out;
}

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

}  // namespace internal

namespace {

using internal::GroupKey;

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

/// The shards' manifests, each of a complete shard of one bench, each shard given once
/// (`by_index`: shard index -> folder); no shard inside the output folder or around it.
Result<std::vector<nlohmann::json>> ReadShardManifests(const std::vector<fs::path>& shards,
                                                       const fs::path& out_dir,
                                                       std::map<uint64_t, fs::path>& by_index) {
  std::vector<nlohmann::json> manifests;
  for (const fs::path& dir : shards) {
    if (IsInside(out_dir, dir) || IsInside(dir, out_dir)) {
      return InvalidArgumentError(
          fmt::format("the output folder '{}' and the shard '{}' lie one inside the other: give "
                      "another --out",
                      out_dir.string(), dir.string()));
    }
    AVP_ASSIGN_OR_RETURN(nlohmann::json m, internal::ReadManifest(dir));
    AVP_ASSIGN_OR_RETURN(const FolderState state, ReadFolderState(dir));
    if (state.state != "complete") {
      return FailedPreconditionError(fmt::format(
          "the shard '{}' is {} (not complete): rerun its avp bench with --resume first",
          dir.string(), state.state));
    }
    if (!manifests.empty()) {
      if (const std::string d = internal::ManifestDifference(manifests.front(), m, false);
          !d.empty()) {
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
  return manifests;
}

/// Each job's run folder, from the one shard whose folder holds it; every job in one.
Result<std::vector<fs::path>> JobSources(const nlohmann::json& first,
                                         const std::vector<fs::path>& shards,
                                         const std::map<uint64_t, fs::path>& by_index) {
  const nlohmann::json& jobs = first.at("jobs");
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
  return source;
}

/// Every job's run folder copied into the output folder, its episode read back.
Result<std::vector<report::BenchEpisode>> CopyRuns(const nlohmann::json& jobs,
                                                   const std::vector<fs::path>& source,
                                                   const fs::path& out_dir, bool progress) {
  std::vector<report::BenchEpisode> episodes;
  episodes.reserve(jobs.size());
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
      return IoError(fmt::format("cannot copy '{}' to '{}': {}", source[i].string(), to.string(),
                                 ec.message()));
    }
    AVP_ASSIGN_OR_RETURN(report::BenchEpisode e,
                         report::ReadBenchEpisode(to, scenario, planner, seed));
    episodes.push_back(std::move(e));
    bar.Done(fmt::format("{} {} seed {}", scenario, planner, seed));
  }
  return episodes;
}

}  // namespace

Result<BenchSummary> MergeBenches(const std::vector<fs::path>& shards, const fs::path& out_dir,
                                  bool force, bool progress) {
  if (shards.empty()) return InvalidArgumentError("no shard folder to merge");
  std::map<uint64_t, fs::path> by_index;
  AVP_ASSIGN_OR_RETURN(const std::vector<nlohmann::json> manifests,
                       ReadShardManifests(shards, out_dir, by_index));
  const nlohmann::json& first = manifests.front();
  AVP_ASSIGN_OR_RETURN(const std::vector<fs::path> source, JobSources(first, shards, by_index));
  AVP_RETURN_IF_ERROR(PrepareOutputFolder(out_dir, BenchFolderKind(), force));
  AVP_RETURN_IF_ERROR(MarkInProgress(out_dir, BenchFolderKind(), "avp bench merge"));
  const auto fail = [&](const Status& s) {
    MarkFailed(out_dir, BenchFolderKind(), "avp bench merge", s);
    return s;
  };
  std::map<GroupKey, report::FruitVisibility> visibility;
  double seconds = 0.0;
  for (const nlohmann::json& m : manifests) {
    visibility.merge(internal::VisibilityFromJson(m.at("ground_truth")));
    seconds += m.value("seconds", 0.0);
  }
  Result<std::vector<report::BenchEpisode>> episodes =
      CopyRuns(first.at("jobs"), source, out_dir, progress);
  if (!episodes.ok()) return fail(episodes.status());
  nlohmann::json manifest = first;
  manifest["shard"] = {{"index", 1}, {"count", 1}};
  manifest["ground_truth"] = internal::VisibilityJson(visibility);
  manifest["seconds"] = seconds;
  manifest["merged_from"] = nlohmann::json::array();
  for (const fs::path& dir : shards) manifest["merged_from"].push_back(dir.string());
  if (Status s = io::WriteJsonFile(out_dir / internal::kManifestName, manifest); !s.ok()) {
    return fail(s);
  }
  report::BenchDescription description =
      internal::DescriptionFromJson(first.at("bench"), first.at("revision").get<std::string>());
  description.visibility = internal::VisibilityByScenario(visibility);
  Result<BenchSummary> summary =
      internal::WriteSummaryAndReport(out_dir, description, *episodes, seconds);
  if (!summary.ok()) return fail(summary.status());
  AVP_RETURN_IF_ERROR(MarkComplete(out_dir, BenchFolderKind(), "avp bench merge"));
  // The bench's time: its shards' wall times added up (as summary.md says), not the copying's.
  summary->seconds = seconds;
  return summary;
}

}  // namespace avp::experiment

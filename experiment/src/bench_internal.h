#pragma once

// Private to experiment/: what the parts of `avp bench` share. One concept per file:
//   bench_config.cpp   BenchConfig: the YAML file, the scenarios list, Validate
//   bench.cpp          running a bench: groups, ground truth, episodes, the summary
//   bench_shards.cpp   bench.json (the manifest), shards of a bench and their merge

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include <avp/core/status.h>
#include <avp/eval/ground_truth.h>
#include <avp/experiment/bench.h>
#include <avp/experiment/run_config.h>
#include <avp/report/bench_summary.h>
#include <avp/sim/scene.h>

namespace avp::experiment::internal {

using Clock = std::chrono::steady_clock;

inline double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// --- bench_config.cpp ----------------------------------------------------------------------------

/// The base configuration of every job: one thread inside, the scene from the job's scenario.
RunConfig JobBase(const BenchConfig& config);

/// One job's configuration: the base with its scenario (or scene file and arrangement), seed and
/// planner with its options.
RunConfig JobConfig(const BenchConfig& config, const BenchScenario& scenario, uint64_t seed,
                    const std::string& planner);

/// A scenarios entry in a message: escaped, and long enough for a path (QuoteText shortens).
std::string QuoteEntry(std::string_view entry);

/// "scenarios entry 'plant.yaml@paper' (scene file '/abs/plant.yaml'): <status>".
Status EntryError(const BenchScenario& b, const Status& s);

/// Two entries with the same display name, or names that give the same run folder, are an error
/// naming both entries.
Status CheckDisplayNames(const std::vector<BenchScenario>& list);

// --- bench_shards.cpp ----------------------------------------------------------------------------

/// One (scenario, seed): its scene and ground truth, shared by the planners. A scene file's scene
/// is one for all seeds (shared); a registered scenario's is built per seed.
struct Group {
  std::string scenario;  ///< the display name (BenchScenario::display_name)
  uint64_t seed = 0;
  const BenchScenario* source = nullptr;
  std::shared_ptr<const sim::Scene> scene;
  Result<eval::GroundTruth> gt = InternalError("not computed");
};

/// One job of the bench: its group (scenario, seed) and planner.
struct JobRef {
  size_t group;
  std::string planner;
};

using GroupKey = std::pair<std::string, uint64_t>;  // (scenario, seed)

inline constexpr const char* kManifestFormat = "avp-bench 1";
inline constexpr const char* kManifestName = "bench.json";

/// The summary's description of the bench, without the visibility (which comes per group).
nlohmann::json DescriptionJson(const BenchConfig& config, const std::vector<BenchScenario>& list);
report::BenchDescription DescriptionFromJson(const nlohmann::json& bench,
                                             const std::string& revision);
nlohmann::json JobsJson(const std::vector<Group>& groups, const std::vector<JobRef>& refs);
nlohmann::json VisibilityJson(const std::map<GroupKey, report::FruitVisibility>& v);
std::map<GroupKey, report::FruitVisibility> VisibilityFromJson(const nlohmann::json& j);

/// Per scenario, the sum over its groups (the summary's "fruits by visibility" denominators).
std::map<std::string, report::FruitVisibility> VisibilityByScenario(
    const std::map<GroupKey, report::FruitVisibility>& groups);

/// A bench folder's bench.json, read and checked for the keys the merge and resume use.
Result<nlohmann::json> ReadManifest(const std::filesystem::path& dir);

/// The first of a manifest's identity keys on which `a` and `b` differ ("" when none): what a
/// merge and a resume require to be equal.
std::string ManifestDifference(const nlohmann::json& a, const nlohmann::json& b, bool same_shard);

/// The jobs (indices into the job list, ascending) of shard `index` of `count`.
std::vector<size_t> ShardJobs(const std::vector<JobRef>& refs, size_t groups, uint64_t index,
                              uint64_t count);

// --- bench.cpp -----------------------------------------------------------------------------------

/// The summary, plots and report.html of a bench folder from its episodes as read back.
Result<BenchSummary> WriteSummaryAndReport(const std::filesystem::path& out_dir,
                                           const report::BenchDescription& description,
                                           const std::vector<report::BenchEpisode>& episodes,
                                           double seconds);

}  // namespace avp::experiment::internal

// Sweep throughput (docs/cluster.md, docs/benchmarks.md): episodes per minute of one bench run
//   sweep_plain_episodes_per_min     as plain `avp bench --jobs J` (J = the hardware threads)
//   sweep_1_shard_episodes_per_min   as `--shard 1/1 --jobs J`, then `avp bench merge`
//   sweep_2_shards_episodes_per_min  as two shards at once (`--shard 1/2` and `2/2`, each with
//                                    --jobs J/2, as two machines or array tasks would be), then
//                                    the merge
// each against the plain run (ratio = rate / plain rate), with the merge's own time
// (sweep_merge_ms) and a gate that the merged summary.csv equals the plain one to the byte
// (sweep_merged_summary_identical, target >= 1). The bench: tomato-single-cluster and
// tomato-multiple-clusters, avp-nbv and predefined, seeds 0..S-1 (S = 4; 2 with --quick), 4 views,
// the oracle segmenter; the ground truth is part of each run's time, as it is of a real one.
//
// Usage: bench_sweep [--avp_json=PATH] [--quick]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <avp/experiment/bench.h>

#include "bench_report.h"

namespace avp {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void Check(const Status& s, const char* what) {
  if (!s.ok()) {
    std::fprintf(stderr, "bench_sweep: %s: %s\n", what, s.ToString().c_str());
    std::exit(1);
  }
}

int Main(bool quick, const std::string& json) {
  const experiment::Registries registries = experiment::BuiltinRegistries();
  const fs::path dir = fs::temp_directory_path() / "avp_bench_sweep";
  fs::remove_all(dir);
  const int threads = std::max(2, static_cast<int>(std::thread::hardware_concurrency()));
  experiment::BenchConfig base;
  base.scenarios = {"tomato-single-cluster", "tomato-multiple-clusters"};
  base.planners = {"avp-nbv", "predefined"};
  for (uint64_t s = 0; s < (quick ? 2u : 4u); ++s) base.seeds.push_back(s);
  base.base.episode.views = 4;
  base.progress = false;
  base.jobs = threads;
  const double episodes =
      static_cast<double>(base.scenarios.size() * base.planners.size() * base.seeds.size());
  std::printf("bench_sweep: %.0f episodes, %d hardware threads\n", episodes, threads);

  // Plain.
  experiment::BenchConfig plain = base;
  plain.out_dir = dir / "plain";
  auto t0 = Clock::now();
  Check(experiment::RunBench(plain, registries).status(), "plain bench");
  const double plain_s = Since(t0);

  // One shard and its merge.
  experiment::BenchConfig one = base;
  one.out_dir = dir / "one" / "shard-1";
  t0 = Clock::now();
  Check(experiment::RunBench(one, registries).status(), "shard 1/1");
  Check(experiment::MergeBenches({one.out_dir}, dir / "one" / "merged", false, false).status(),
        "merge of 1 shard");
  const double one_s = Since(t0);

  // Two shards at once, each with half the threads, and their merge.
  std::vector<experiment::BenchConfig> shards(2, base);
  std::vector<Status> status(2);
  t0 = Clock::now();
  {
    std::vector<std::thread> workers;
    for (int k = 0; k < 2; ++k) {
      shards[k].shard_index = static_cast<uint64_t>(k + 1);
      shards[k].shard_count = 2;
      shards[k].jobs = std::max(1, threads / 2);
      shards[k].out_dir = dir / "two" / ("shard-" + std::to_string(k + 1));
      workers.emplace_back(
          [&, k] { status[k] = experiment::RunBench(shards[k], registries).status(); });
    }
    for (std::thread& w : workers) w.join();
  }
  Check(status[0], "shard 1/2");
  Check(status[1], "shard 2/2");
  const auto tm = Clock::now();
  Check(experiment::MergeBenches({shards[0].out_dir, shards[1].out_dir}, dir / "two" / "merged",
                                 false, false)
            .status(),
        "merge of 2 shards");
  const double merge_s = Since(tm);
  const double two_s = Since(t0);

  const std::string reference = Slurp(plain.out_dir / "summary.csv");
  const bool identical = !reference.empty() &&
                         Slurp(dir / "one" / "merged" / "summary.csv") == reference &&
                         Slurp(dir / "two" / "merged" / "summary.csv") == reference;
  const double plain_rate = 60.0 * episodes / plain_s;
  const double one_rate = 60.0 * episodes / one_s;
  const double two_rate = 60.0 * episodes / two_s;
  std::printf("  plain avp bench --jobs %d   %6.1f s  %6.1f episodes/min\n", threads, plain_s,
              plain_rate);
  std::printf("  1 shard + merge            %6.1f s  %6.1f episodes/min  (%.2fx)\n", one_s,
              one_rate, one_rate / plain_rate);
  std::printf("  2 shards at once + merge   %6.1f s  %6.1f episodes/min  (%.2fx; merge %.0f ms)\n",
              two_s, two_rate, two_rate / plain_rate, 1e3 * merge_s);
  std::printf("  merged summary.csv identical to the plain one: %s\n", identical ? "yes" : "NO");
  const std::string ref = "plain avp bench --jobs " + std::to_string(threads);
  std::vector<bench::BenchRecord> records = {
      bench::MakeRecord("sweep_plain_episodes_per_min", plain_rate, "episodes/min"),
      bench::MakeRecord("sweep_1_shard_episodes_per_min", one_rate, "episodes/min", ref, plain_rate,
                        one_rate / plain_rate),
      bench::MakeRecord("sweep_2_shards_episodes_per_min", two_rate, "episodes/min", ref,
                        plain_rate, two_rate / plain_rate),
      bench::MakeRecord("sweep_merge_ms", 1e3 * merge_s, "ms"),
      bench::MakeRecord("sweep_merged_summary_identical", identical ? 1.0 : 0.0, "", std::nullopt,
                        std::nullopt, std::nullopt, ">=1"),
  };
  fs::remove_all(dir);
  if (!json.empty() && !bench::WriteBenchRecords(json, records)) return 1;
  return identical ? 0 : 1;
}

}  // namespace
}  // namespace avp

int main(int argc, char** argv) {
  const std::string json = avp::bench::TakeJsonPathArgument(argc, argv);
  bool quick = false;
  for (int i = 1; i < argc; ++i) quick = quick || std::strcmp(argv[i], "--quick") == 0;
  return avp::Main(quick, json);
}

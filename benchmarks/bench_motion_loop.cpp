// Collision-free motion in the loop it serves (docs/motion.md, "What it costs"; issue 34's time
// goals). The paper protocol's seven scenarios, seeds 0..S-1 (S = 2; 1 with --quick), avp-nbv
// with the oracle segmenter and 8 views, each episode run twice in a row on the same thread:
// straight joint-space moves (today's loop) and planned moves (motion.enabled). Records:
//   motion_planning_per_move/{p50,p99,max}  one move's planning (its attempts summed), ms;
//                                           targets p50 <= 50, p99 <= 500
//   plan_step/{p50,p99,max}                 a plan step: the obstacle field's update, the
//                                           candidates and their gain, and the move's planning,
//                                           ms; target p99 <= 500
//   plan_step_straight_moves/{p50,p99,max}  the same in the straight episodes (candidates and
//                                           gain only), for comparison
//   episode_wall_time/<scenario>            the planned episodes' mean wall time against the
//                                           straight ones' (ratio); target <= 1.5x. The planned
//                                           tomato episodes often end early, with fewer views:
//                                           their ratio is below what a full episode would cost.
//   contacts_planned/<scenario>             contacts of the planned moves (straight moves' as the
//                                           reference); target < 1
// The collision check's rate against FCL's own queries is bench_motion's.
//
// Usage: bench_motion_loop [--avp_json=PATH] [--quick]
#include <cstdio>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include <avp/experiment/episode_runner.h>
#include <avp/sim/scenario.h>

#include "bench_report.h"

namespace avp {
namespace {

/// One paper episode of avp-nbv: straight moves, or planned ones.
Result<experiment::RunResult> PaperEpisode(const std::string& scenario, uint64_t seed,
                                           bool planned) {
  static const auto* registries = new experiment::Registries(experiment::BuiltinRegistries());
  experiment::RunConfig c;
  c.scenario = scenario;
  c.seed = seed;
  c.planner.name = "avp-nbv";
  c.segmenter.name = "oracle";
  c.episode.views = 8;
  c.motion.enabled = planned;
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene, sim::MakeScenario(scenario, seed));
  AVP_ASSIGN_OR_RETURN(const eval::GroundTruth gt, experiment::GroundTruthFor(c, scene));
  AVP_ASSIGN_OR_RETURN(const auto checked, experiment::CheckedRunConfig::Check(c, *registries));
  return experiment::RunEpisodeOnScene(checked, scene, gt);
}

/// p50 / p99 / max records of `values` (ms), printed too.
void AddPercentiles(const std::string& name, const std::vector<double>& values,
                    const std::optional<std::string>& p50_target,
                    std::vector<bench::BenchRecord>& records) {
  const double p50 = bench::Percentile(values, 0.5), p99 = bench::Percentile(values, 0.99),
               max = bench::Percentile(values, 1.0);
  records.push_back(bench::MakeRecord(name + "/p50", p50, "ms", std::nullopt, std::nullopt,
                                      std::nullopt, p50_target));
  records.push_back(bench::MakeRecord(name + "/p99", p99, "ms", std::nullopt, std::nullopt,
                                      std::nullopt, "<=500"));
  records.push_back(bench::MakeRecord(name + "/max", max, "ms"));
  std::printf("%s: %zu, median %.1f ms, p99 %.1f ms, max %.1f ms\n", name.c_str(), values.size(),
              p50, p99, max);
}

int Run(int seeds, const std::string& json_path) {
  std::vector<bench::BenchRecord> records;
  std::vector<double> move_ms, step_ms, straight_step_ms;
  int failures = 0;
  for (const std::string scenario :
       {"tomato-full-occlusion", "tomato-multiple-clusters", "tomato-single-cluster",
        "tomato-unoriented-start", "espalier-multiple-fruits", "espalier-full-occlusion",
        "espalier-unoriented-start"}) {
    double wall_ms[2] = {0.0, 0.0};
    int contacts[2] = {0, 0};
    for (int seed = 0; seed < seeds; ++seed) {
      for (const bool planned : {false, true}) {
        const auto r = PaperEpisode(scenario, static_cast<uint64_t>(seed), planned);
        if (!r.ok()) {
          std::fprintf(stderr, "%s seed %d: %s\n", scenario.c_str(), seed,
                       r.status().ToString().c_str());
          ++failures;
          continue;
        }
        const pipeline::EpisodeResult& e = r->episode;
        wall_ms[planned] += e.total_ms;
        const pipeline::MotionTotals t = pipeline::SumMotion(e);
        if (t.contacts) contacts[planned] += t.contacts->total();
        if (planned) move_ms.insert(move_ms.end(), t.planning_ms.begin(), t.planning_ms.end());
        for (const pipeline::StepRecord& s : e.steps) {
          if (s.planned) {
            (planned ? step_ms : straight_step_ms)
                .push_back(s.times.plan_ms + s.motion.planning_ms);
          }
        }
      }
    }
    const double ratio = wall_ms[1] / wall_ms[0];
    std::printf(
        "%-26s wall time %.1f s planned / %.1f s straight = %.2fx; contacts %d planned, %d "
        "straight\n",
        scenario.c_str(), wall_ms[1] / 1e3, wall_ms[0] / 1e3, ratio, contacts[1], contacts[0]);
    std::fflush(stdout);
    records.push_back(bench::MakeRecord("episode_wall_time/" + scenario, wall_ms[1] / seeds, "ms",
                                        "straight moves", wall_ms[0] / seeds, ratio, "<=1.5x"));
    records.push_back(bench::MakeRecord("contacts_planned/" + scenario, contacts[1], "contacts",
                                        "straight moves", contacts[0], std::nullopt, "<1"));
  }
  AddPercentiles("motion_planning_per_move", move_ms, "<=50", records);
  AddPercentiles("plan_step", step_ms, std::nullopt, records);
  AddPercentiles("plan_step_straight_moves", straight_step_ms, std::nullopt, records);
  if (!json_path.empty() && !bench::WriteBenchRecords(json_path, records)) return 1;
  return failures == 0 ? 0 : 1;
}

}  // namespace
}  // namespace avp

int main(int argc, char** argv) {
  const std::string json = avp::bench::TakeJsonPathArgument(argc, argv);
  int seeds = 2;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) {
      seeds = 1;
    } else {
      std::fprintf(stderr, "usage: bench_motion_loop [--avp_json=PATH] [--quick]\n");
      return 2;
    }
  }
  return avp::Run(seeds, json);
}

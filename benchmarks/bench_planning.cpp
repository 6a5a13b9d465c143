// Cost of one avp-nbv plan step (AvpNbvPlanner::Plan) on a realistic map.
//
// The map: the built-in scenario tomato-full-occlusion, seed 0, 5 mm voxels, after the first
// kViews views of an avp-nbv episode (oracle segmenter, projective carving, the settings of
// `avp run`). The request is the one the episode would make for its next view.
//
// Cases:
//   BM_AvpNbvPlan/threads:N      the whole plan step (grid build, candidates + IK, gains,
//                                ranking) with the default grid (8^3 bricks), at 1 and 2
//                                threads. Reference in the same run,
//                                alternating with it: the same step with the plain dense grid
//                                (brick_shift 0, no skipping: the walk before bricks). Counters:
//                                generated / reachable candidates, dense_ms (the reference's
//                                mean), speedup (dense_ms / plan ms), identical (1 when both
//                                ranked the same candidates with bit-identical gains; the run
//                                fails otherwise).
//   BM_AvpNbvGains/layout:L      the gain evaluation alone (AvpViewGain of every reachable
//                                candidate of the step, 1 thread) on a grid built once: L = 0
//                                dense, 1 bricked (the default), 2 bricked + skipping. Counters:
//                                candidates, ms per candidate, free_bricks (fraction),
//                                grid_MB.
//   BM_GainGridBuild/shift:S/skip:K  GainGrid::Build on the map (dense, bricked, bricked with
//                                the all-free flags).
// Target (2 cores): <= 500 ms per plan step with 2 threads and >= 300 reachable candidates.

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <vector>

#include <benchmark/benchmark.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/mapping/semantic_map.h>
#include <avp/pipeline/episode.h>
#include <avp/planning/avp_nbv_planner.h>
#include <avp/planning/gain_grid.h>
#include <avp/robot/arm.h>
#include <avp/robot/arm_model.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/sim/scenario.h>
#include <avp/sim/sim_arm.h>
#include <avp/sim/sim_rgbd_source.h>

#include "bench_report.h"

namespace avp::planning {
namespace {

constexpr const char* kScenario = "tomato-full-occlusion";
constexpr uint64_t kSeed = 0;
/// Views fused before the timed plan step (the start view included).
constexpr int kViews = 3;

void Die(const Status& s) {
  std::fprintf(stderr, "bench_planning: %s\n", s.ToString().c_str());
  std::abort();
}

/// The map after kViews views of an episode and the request for the next view.
struct Fixture {
  sim::Scene scene;
  std::unique_ptr<robot::ArmModel> arm;
  std::unique_ptr<mapping::SemanticMap> map;
  PlanningRequest request;
  Rng rng{0};
};

const Fixture& GetFixture() {
  static const Fixture* fixture = [] {
    auto* f = new Fixture;
    Result<sim::Scene> scene = sim::MakeScenario(kScenario, kSeed);
    if (!scene.ok()) Die(scene.status());
    f->scene = std::move(*scene);
    Result<robot::ArmModel> arm = robot::LoadDefaultArm(AVP_CONFIG_DIR);
    if (!arm.ok()) Die(arm.status());
    f->arm = std::make_unique<robot::ArmModel>(std::move(*arm));
    Eigen::VectorXd q0 = f->arm->home_joints();
    if (!f->scene.start_joints_rad.empty()) {
      q0 = Eigen::Map<const Eigen::VectorXd>(
          f->scene.start_joints_rad.data(),
          static_cast<Eigen::Index>(f->scene.start_joints_rad.size()));
    }
    sim::SimArm sim_arm(*f->arm, q0);
    Result<std::unique_ptr<segmentation::Segmenter>> segmenter =
        segmentation::BuiltinSegmenters().Make("oracle", Rng(kSeed).Fork("segmenter").NextU64());
    if (!segmenter.ok()) Die(segmenter.status());
    const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
    sim::DepthNoiseConfig noise;
    noise.enabled = true;
    sim::SimRgbdSource source(f->scene, K, noise, kSeed);
    mapping::MapOptions map_options;
    map_options.grid.voxel_size_m = 0.005;
    f->map = std::make_unique<mapping::SemanticMap>(map_options);
    AvpNbvPlanner planner;
    pipeline::EpisodeOptions eo;
    eo.views = kViews;
    eo.roi = f->scene.plant_bounds.Inflated(0.05);
    eo.integrator.carving = mapping::FreeSpaceCarving::kProjective;
    eo.integrator.max_range_m = 1.5;
    eo.seed = kSeed;
    pipeline::EpisodeComponents components{
        &source, segmenter->get(), &sim_arm, &planner, f->map.get(), {}, nullptr};
    Result<pipeline::EpisodeResult> episode = pipeline::RunEpisode(components, eo);
    if (!episode.ok()) Die(episode.status());
    if (episode->views_fused() != kViews) {
      std::fprintf(stderr, "bench_planning: the episode ended after %d views: %s\n",
                   episode->views_fused(), episode->end_reason.c_str());
      std::abort();
    }
    // The request RunEpisode makes after its last fused view (as if the budget were 8 views).
    PlanningRequest& r = f->request;
    r.map = f->map.get();
    r.arm = f->arm.get();
    r.q_current = sim_arm.CurrentJoints();
    r.X_WC_current = sim_arm.CurrentCameraPose();
    r.q_start = episode->steps.front().q;
    r.X_WC_start = episode->steps.front().X_WC;
    r.K = K;
    r.roi = eo.roi;
    r.view_index = kViews;
    r.views_total = 8;
    for (const pipeline::StepRecord& s : episode->steps) r.fused_views.push_back(s.X_WC);
    r.target_class = eo.target_class;
    f->rng = Rng(kSeed).Fork("planner").Fork(static_cast<uint64_t>(kViews));
    return f;
  }();
  return *fixture;
}

AvpNbvOptions DenseOptions(AvpNbvOptions o) {
  o.grid.brick_shift = 0;
  o.grid.skip_free_bricks = false;
  return o;
}

bool SameRanking(const PlanResult& a, const PlanResult& b) {
  if (a.ranked.size() != b.ranked.size() || a.reachable != b.reachable) return false;
  for (size_t i = 0; i < a.ranked.size(); ++i) {
    if (a.ranked[i].gain != b.ranked[i].gain || a.ranked[i].utility != b.ranked[i].utility ||
        a.ranked[i].X_WC.translation() != b.ranked[i].X_WC.translation() ||
        a.ranked[i].X_WC.rotation() != b.ranked[i].X_WC.rotation()) {
      return false;
    }
  }
  return true;
}

double Ms(std::chrono::steady_clock::duration d) {
  return std::chrono::duration<double, std::milli>(d).count();
}

/// The benchmark's thread count (its argument) for the gains and the IK: avp's one parallelism
/// setting, for the benchmark's scope (core/parallel.h).
int BenchThreads(const benchmark::State& state) { return static_cast<int>(state.range(0)); }

/// The plan-step benchmarks' runs: 1 and 2 threads, 2 iterations each, wall time in ms.
void PlanStepRuns(benchmark::internal::Benchmark* b) {
  b->ArgName("threads")
      ->Arg(1)
      ->Arg(2)
      ->Iterations(2)
      ->Unit(benchmark::kMillisecond)
      ->UseRealTime();
}

void BM_AvpNbvPlan(benchmark::State& state) {
  const Fixture& f = GetFixture();
  const ThreadScope threads(BenchThreads(state));
  const AvpNbvOptions options{};
  AvpNbvPlanner planner(options);
  AvpNbvPlanner dense(DenseOptions(options));
  PlanResult result, reference;
  double dense_ms = 0.0;
  bool identical = true;
  for (auto _ : state) {
    Rng rng = f.rng;
    result = planner.Plan(f.request, rng);
    benchmark::DoNotOptimize(result.ranked.data());
    state.PauseTiming();
    Rng dense_rng = f.rng;
    const auto t0 = std::chrono::steady_clock::now();
    reference = dense.Plan(f.request, dense_rng);
    dense_ms += Ms(std::chrono::steady_clock::now() - t0);
    identical = identical && SameRanking(result, reference);
    state.ResumeTiming();
  }
  if (!result.status.ok()) {
    state.SkipWithError(result.status.ToString().c_str());
    return;
  }
  if (!identical) {
    state.SkipWithError("the bricked and the dense grid ranked the candidates differently");
    return;
  }
  dense_ms /= static_cast<double>(state.iterations());
  state.counters["threads"] = static_cast<double>(BenchThreads(state));
  state.counters["generated"] = static_cast<double>(result.generated);
  state.counters["reachable"] = static_cast<double>(result.reachable);
  state.counters["dense_ms"] = dense_ms;
  // speedup = dense_ms / (ms per iteration): kIsIterationInvariantRate divides by the time.
  state.counters["speedup"] =
      benchmark::Counter(dense_ms * 1e-3, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["identical"] = identical ? 1.0 : 0.0;
}
BENCHMARK(BM_AvpNbvPlan)->Apply(PlanStepRuns);

/// One avp-nbv step with `options`, timed, beside the default step in the same run
/// (hand_written_ms, and ratio = the variant's time / the default's).
void PlanVariant(benchmark::State& state, const AvpNbvOptions& options) {
  const Fixture& f = GetFixture();
  const ThreadScope threads(BenchThreads(state));
  AvpNbvPlanner planner(options);
  AvpNbvPlanner hand_written(AvpNbvOptions{});
  PlanResult result;
  double hand_ms = 0.0;
  for (auto _ : state) {
    Rng rng = f.rng;
    result = planner.Plan(f.request, rng);
    benchmark::DoNotOptimize(result.ranked.data());
    state.PauseTiming();
    Rng hand_rng = f.rng;
    const auto t0 = std::chrono::steady_clock::now();
    benchmark::DoNotOptimize(hand_written.Plan(f.request, hand_rng).ranked.data());
    hand_ms += Ms(std::chrono::steady_clock::now() - t0);
    state.ResumeTiming();
  }
  if (!result.status.ok() || !result.warnings.empty()) {
    state.SkipWithError(result.status.ok() ? result.warnings.front().c_str()
                                           : result.status.ToString().c_str());
    return;
  }
  hand_ms /= static_cast<double>(state.iterations());
  state.counters["threads"] = static_cast<double>(BenchThreads(state));
  state.counters["reachable"] = static_cast<double>(result.reachable);
  state.counters["hand_written_ms"] = hand_ms;
  // ratio = (time per iteration) / hand_ms: the rate hand_ms / time, inverted.
  state.counters["ratio"] = benchmark::Counter(
      hand_ms * 1e-3, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

// The step ranked by the learned gain (configs/models/learned.onnx: the features of every
// reachable candidate, then the model; docs/planning.md "A learned gain"). Budget: <= 0.5 s on
// 2 cores.
void BM_AvpNbvPlanLearned(benchmark::State& state) {
  AvpNbvOptions o;
  o.gain_model = "learned";
  PlanVariant(state, o);
}
BENCHMARK(BM_AvpNbvPlanLearned)->Apply(PlanStepRuns);

// The step with the non-myopic choice (two views looked ahead) on the hand-written gain.
void BM_AvpNbvPlanLookahead(benchmark::State& state) {
  AvpNbvOptions o;
  o.lookahead_views = 2;
  PlanVariant(state, o);
}
BENCHMARK(BM_AvpNbvPlanLookahead)->Apply(PlanStepRuns);

// The same step with every candidate scored with every fine ray (coarse_ray_stride_px = 0), the
// pass that coarse to fine replaces; same_choice = 1 when both choose the same view.
void BM_AvpNbvPlanEveryRay(benchmark::State& state) {
  const Fixture& f = GetFixture();
  const ThreadScope threads(BenchThreads(state));
  const AvpNbvOptions options{};
  AvpNbvOptions every = options;
  every.coarse_ray_stride_px = 0;
  AvpNbvPlanner planner(every);
  PlanResult result;
  for (auto _ : state) {
    Rng rng = f.rng;
    result = planner.Plan(f.request, rng);
    benchmark::DoNotOptimize(result.ranked.data());
  }
  if (!result.status.ok()) {
    state.SkipWithError(result.status.ToString().c_str());
    return;
  }
  Rng rng = f.rng;
  const PlanResult c2f = AvpNbvPlanner(options).Plan(f.request, rng);
  state.counters["threads"] = static_cast<double>(BenchThreads(state));
  state.counters["reachable"] = static_cast<double>(result.reachable);
  state.counters["same_choice"] = c2f.status.ok() && c2f.ranked.front().X_WC.translation() ==
                                                         result.ranked.front().X_WC.translation()
                                      ? 1.0
                                      : 0.0;
}
BENCHMARK(BM_AvpNbvPlanEveryRay)->Apply(PlanStepRuns);

void BM_AvpNbvGains(benchmark::State& state) {
  const Fixture& f = GetFixture();
  const int layout = static_cast<int>(state.range(0));
  AvpNbvOptions options;
  if (layout == 0) options = DenseOptions(options);
  options.grid.skip_free_bricks = layout == 2;
  // The reachable candidates of the step (default options: the candidates do not depend on the
  // grid's layout), every one scored with every ray (no coarse pass) to compare the gains.
  Rng rng = f.rng;
  AvpNbvOptions every;
  every.coarse_ray_stride_px = 0;
  const PlanResult plan = AvpNbvPlanner(every).Plan(f.request, rng);
  Result<GainGrid> grid =
      GainGrid::Build(*f.request.map, f.request.target_class, f.request.roi, options.grid);
  if (!grid.ok() || !plan.status.ok()) {
    state.SkipWithError(grid.ok() ? plan.status.ToString().c_str()
                                  : grid.status().ToString().c_str());
    return;
  }
  bool identical = true;
  for (auto _ : state) {
    for (const ViewCandidate& c : plan.ranked) {
      const double g = AvpViewGain(*grid, c.X_WC, f.request.K, options);
      identical = identical && g == c.gain;
    }
  }
  if (!identical) {
    state.SkipWithError("a gain differs from the planner's");
    return;
  }
  state.counters["candidates"] = static_cast<double>(plan.ranked.size());
  state.counters["ms_per_candidate"] = benchmark::Counter(
      1e-3 * static_cast<double>(plan.ranked.size()),
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["free_bricks"] =
      static_cast<double>(grid->free_bricks()) / static_cast<double>(grid->bricks());
  state.counters["grid_MB"] =
      4e-6 * static_cast<double>(grid->bricks()) * std::pow(grid->brick_edge(), 3);
}
BENCHMARK(BM_AvpNbvGains)
    ->ArgName("layout")
    ->Arg(0)
    ->Arg(1)
    ->Arg(2)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_GainGridBuild(benchmark::State& state) {
  const Fixture& f = GetFixture();
  GainGridOptions options;
  options.brick_shift = static_cast<int>(state.range(0));
  options.skip_free_bricks = state.range(1) != 0;
  size_t bricks = 0, free = 0;
  for (auto _ : state) {
    Result<GainGrid> grid =
        GainGrid::Build(*f.request.map, f.request.target_class, f.request.roi, options);
    if (!grid.ok()) {
      state.SkipWithError(grid.status().ToString().c_str());
      return;
    }
    bricks = grid->bricks();
    free = grid->free_bricks();
  }
  state.counters["free_bricks"] = static_cast<double>(free) / static_cast<double>(bricks);
}
BENCHMARK(BM_GainGridBuild)
    ->ArgNames({"shift", "skip"})
    ->Args({0, 0})
    ->Args({3, 0})
    ->Args({3, 1})
    ->Iterations(5)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace avp::planning

int main(int argc, char** argv) {
  // docs/planning.md: a plan step <= 500 ms on 2 cores with >= 300 reachable candidates.
  return avp::bench::GoogleBenchmarkMain(argc, argv, {{"BM_AvpNbvPlan/threads:2", "<=500"}});
}

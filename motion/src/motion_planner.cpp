#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>
#include <mutex>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <ompl/base/MotionValidator.h>
#include <ompl/base/PlannerTerminationCondition.h>
#include <ompl/base/StateSampler.h>
#include <ompl/base/spaces/RealVectorStateSpace.h>
#include <ompl/geometric/SimpleSetup.h>
#include <ompl/geometric/planners/rrt/RRTConnect.h>
#include <ompl/util/Console.h>

#include <avp/core/stopwatch.h>
#include <avp/motion/motion_planner.h>

namespace avp::motion {

namespace ob = ompl::base;
namespace og = ompl::geometric;

namespace {

Eigen::VectorXd ToEigen(const ob::State* state, int n) {
  const auto* s = state->as<ob::RealVectorStateSpace::StateType>();
  Eigen::VectorXd q(n);
  for (int i = 0; i < n; ++i) q[i] = s->values[i];
  return q;
}

/// OMPL's state sampler with avp's generator: the same seed draws the same states on any
/// machine, whatever OMPL's process-wide seed (ompl::RNG) is. Counts its draws for the sample
/// budget.
class SeededSampler final : public ob::StateSampler {
 public:
  SeededSampler(const ob::StateSpace* space, uint64_t seed, std::shared_ptr<std::atomic<int>> draws)
      : ob::StateSampler(space), rng_(seed), draws_(std::move(draws)) {}

  void sampleUniform(ob::State* state) override {
    draws_->fetch_add(1, std::memory_order_relaxed);
    const ob::RealVectorBounds& b = space_->as<ob::RealVectorStateSpace>()->getBounds();
    auto* s = state->as<ob::RealVectorStateSpace::StateType>();
    for (size_t i = 0; i < b.low.size(); ++i) s->values[i] = rng_.Uniform(b.low[i], b.high[i]);
  }
  void sampleUniformNear(ob::State* state, const ob::State* near, double distance) override {
    const ob::RealVectorBounds& b = space_->as<ob::RealVectorStateSpace>()->getBounds();
    auto* s = state->as<ob::RealVectorStateSpace::StateType>();
    const auto* c = near->as<ob::RealVectorStateSpace::StateType>();
    for (size_t i = 0; i < b.low.size(); ++i) {
      s->values[i] = std::clamp(rng_.Uniform(c->values[i] - distance, c->values[i] + distance),
                                b.low[i], b.high[i]);
    }
  }
  void sampleGaussian(ob::State* state, const ob::State* mean, double stddev) override {
    const ob::RealVectorBounds& b = space_->as<ob::RealVectorStateSpace>()->getBounds();
    auto* s = state->as<ob::RealVectorStateSpace::StateType>();
    const auto* m = mean->as<ob::RealVectorStateSpace::StateType>();
    for (size_t i = 0; i < b.low.size(); ++i) {
      s->values[i] = std::clamp(rng_.Normal(m->values[i], stddev), b.low[i], b.high[i]);
    }
  }

 private:
  Rng rng_;
  std::shared_ptr<std::atomic<int>> draws_;
};

/// OMPL's edge check through CollisionChecker::CheckSegment: no point of the arm moves more than
/// max_step_m between checked states (a Cartesian bound, not OMPL's joint-space fraction).
class SegmentValidator final : public ob::MotionValidator {
 public:
  SegmentValidator(const ob::SpaceInformationPtr& si, const CollisionChecker& checker, int n)
      : ob::MotionValidator(si), checker_(checker), n_(n) {}

  bool checkMotion(const ob::State* s1, const ob::State* s2) const override {
    const bool free = checker_.CheckSegment(ToEigen(s1, n_), ToEigen(s2, n_)).free;
    (free ? valid_ : invalid_)++;
    return free;
  }
  bool checkMotion(const ob::State* s1, const ob::State* s2,
                   std::pair<ob::State*, double>& last_valid) const override {
    const SegmentCheck check = checker_.CheckSegment(ToEigen(s1, n_), ToEigen(s2, n_), true);
    if (check.free) {
      ++valid_;
      return true;
    }
    ++invalid_;
    const double step = check.states > 1 ? check.at_fraction / (check.states - 1) : 0.0;
    last_valid.second = std::max(0.0, check.at_fraction - step);
    if (last_valid.first != nullptr) {
      si_->getStateSpace()->interpolate(s1, s2, last_valid.second, last_valid.first);
    }
    return false;
  }

 private:
  const CollisionChecker& checker_;
  int n_;
};

/// Greedy shortcuts: from each kept vertex, the farthest later vertex the straight segment
/// reaches without collision. Deterministic (OMPL's PathSimplifier draws from its own RNG).
std::vector<Eigen::VectorXd> Shortcut(const std::vector<Eigen::VectorXd>& path,
                                      const CollisionChecker& checker) {
  if (path.size() <= 2) return path;
  std::vector<Eigen::VectorXd> out{path.front()};
  size_t i = 0;
  while (i + 1 < path.size()) {
    size_t j = path.size() - 1;
    while (j > i + 1 && !checker.CheckSegment(path[i], path[j]).free) --j;
    out.push_back(path[j]);
    i = j;
  }
  return out;
}

double PathLength(const std::vector<Eigen::VectorXd>& path) {
  double length = 0.0;
  for (size_t i = 1; i < path.size(); ++i) length += (path[i] - path[i - 1]).norm();
  return length;
}

/// A point along `path` at arc length `s`: the segment it lies on (i: from path[i] to
/// path[i + 1]) and the point.
std::pair<size_t, Eigen::VectorXd> PointAt(const std::vector<Eigen::VectorXd>& path, double s) {
  for (size_t i = 0; i + 1 < path.size(); ++i) {
    const double l = (path[i + 1] - path[i]).norm();
    if (s <= l || i + 2 == path.size()) {
      const double f = l > 0.0 ? std::clamp(s / l, 0.0, 1.0) : 0.0;
      return {i, path[i] + f * (path[i + 1] - path[i])};
    }
    s -= l;
  }
  return {0, path.front()};
}

/// Partial shortcuts (MotionOptions::shortcut_tries): two points drawn along the path, on
/// different segments, are joined straight when that is free; every try that is taken makes the
/// path shorter (the triangle inequality), and the draws come from `rng` (reproducible).
std::vector<Eigen::VectorXd> ShortcutPartially(std::vector<Eigen::VectorXd> path,
                                               const CollisionChecker& checker, int tries,
                                               Rng& rng) {
  for (int t = 0; t < tries && path.size() > 2; ++t) {
    const double length = PathLength(path);
    double a = rng.Uniform(0.0, length), b = rng.Uniform(0.0, length);
    if (a > b) std::swap(a, b);
    auto [ia, pa] = PointAt(path, a);
    auto [ib, pb] = PointAt(path, b);
    if (ib <= ia) continue;  // the same segment: nothing to cut
    if (!checker.CheckSegment(pa, pb).free) continue;
    std::vector<Eigen::VectorXd> cut(path.begin(), path.begin() + static_cast<long>(ia) + 1);
    cut.push_back(std::move(pa));
    cut.push_back(std::move(pb));
    cut.insert(cut.end(), path.begin() + static_cast<long>(ib) + 1, path.end());
    // Drop a point that coincides with its neighbour (a draw at a vertex).
    std::vector<Eigen::VectorXd> kept{cut.front()};
    for (size_t i = 1; i < cut.size(); ++i) {
      if ((cut[i] - kept.back()).norm() > 1e-9) kept.push_back(std::move(cut[i]));
    }
    path = std::move(kept);
  }
  return path;
}

void QuietOmpl() {
  static std::once_flag once;
  std::call_once(once, [] { ompl::msg::setLogLevel(ompl::msg::LOG_WARN); });
}

/// RRT-Connect from `start` to `goal` with `checker`; the path's vertices, or empty.
std::vector<Eigen::VectorXd> Search(const CollisionChecker& checker, const MotionOptions& options,
                                    const Eigen::VectorXd& start, const Eigen::VectorXd& goal,
                                    uint64_t seed, int& samples) {
  QuietOmpl();
  const robot::ArmModel& arm = checker.robot().arm();
  const int n = arm.num_joints();
  auto space = std::make_shared<ob::RealVectorStateSpace>(static_cast<unsigned>(n));
  ob::RealVectorBounds bounds(static_cast<unsigned>(n));
  for (int i = 0; i < n; ++i) {
    const auto si = static_cast<size_t>(i);
    const double lo = arm.lower_limits()[i];
    const double hi = arm.upper_limits()[i];
    // Continuous joints: one turn either side of the move.
    bounds.low[si] = std::isfinite(lo) ? lo : std::min(start[i], goal[i]) - std::numbers::pi;
    bounds.high[si] = std::isfinite(hi) ? hi : std::max(start[i], goal[i]) + std::numbers::pi;
  }
  space->setBounds(bounds);
  auto draws = std::make_shared<std::atomic<int>>(0);
  space->setStateSamplerAllocator([seed, draws](const ob::StateSpace* s) {
    return std::make_shared<SeededSampler>(s, seed, draws);
  });
  og::SimpleSetup setup(space);
  const ob::SpaceInformationPtr& si = setup.getSpaceInformation();
  setup.setStateValidityChecker(
      [&checker, n](const ob::State* s) { return checker.IsFree(ToEigen(s, n)); });
  si->setMotionValidator(std::make_shared<SegmentValidator>(si, checker, n));
  auto planner = std::make_shared<og::RRTConnect>(si);
  if (options.range_rad > 0.0) planner->setRange(options.range_rad);
  setup.setPlanner(planner);
  ob::ScopedState<> s0(space);
  ob::ScopedState<> s1(space);
  for (int i = 0; i < n; ++i) {
    s0[static_cast<unsigned>(i)] = start[i];
    s1[static_cast<unsigned>(i)] = goal[i];
  }
  setup.setStartAndGoalStates(s0, s1);
  const int max_samples = options.max_samples;
  const ob::PlannerTerminationCondition ptc =
      ob::plannerOrTerminationCondition(ob::timedPlannerTerminationCondition(options.timeout_s),
                                        ob::PlannerTerminationCondition([draws, max_samples] {
                                          return draws->load() >= max_samples;
                                        }));
  const ob::PlannerStatus status = setup.solve(ptc);
  samples = draws->load();
  std::vector<Eigen::VectorXd> path;
  if (status != ob::PlannerStatus::EXACT_SOLUTION) return path;
  for (const ob::State* s : setup.getSolutionPath().getStates()) path.push_back(ToEigen(s, n));
  return path;
}

}  // namespace

const OptionTable<MotionOptions>& MotionOptionTable() {
  static const auto* table = [] {
    using M = MotionOptions;
    auto* t = new OptionTable<M>("motion option");
    t->Flag("enabled", &M::enabled,
            "plan every move collision-free (off: straight joint-space moves, unchecked)");
    t->Nested("collision", &M::collision, CollisionOptionTable());
    t->Integer("max_samples", &M::max_samples, "", ValueRange::Closed(10, 10'000'000),
               "RRT-Connect stops after drawing this many states");
    t->Real("timeout_s", &M::timeout_s, "s", ValueRange::LeftOpen(0, 600),
            "RRT-Connect stops after this wall time (a safety net)");
    t->Real("range_rad", &M::range_rad, "rad", ValueRange::Closed(0, 100),
            "RRT-Connect's step in joint space (0: OMPL's default, 0.2 of the space's extent)");
    t->Integer("shortcut_tries", &M::shortcut_tries, "", ValueRange::Closed(0, 10'000),
               "tries at a partial shortcut between two points drawn along a searched path (0: "
               "vertex shortcuts only)");
    t->Real("velocity_scaling", &M::velocity_scaling, "", ValueRange::LeftOpen(0, 1),
            "fraction of each joint's velocity limit the trajectory uses");
    t->Real("acceleration_scaling", &M::acceleration_scaling, "", ValueRange::LeftOpen(0, 1),
            "fraction of the joints' acceleration limit the trajectory uses");
    t->Real("sample_period_s", &M::sample_period_s, "s", ValueRange::LeftOpen(0, 10),
            "spacing of the trajectory's points in time");
    t->Integer("max_attempts", &M::max_attempts, "", ValueRange::Closed(1, 1000),
               "moves planned to ranked candidates after a view before the episode gives up");
    t->Real("step_back_m", &M::step_back_m, "m", ValueRange::Closed(0, 1),
            "a candidate view in collision is moved back along its optical axis up to this far "
            "(0: dropped)");
    return t;
  }();
  return *table;
}

Status MotionOptions::Validate() const {
  AVP_RETURN_IF_ERROR(MotionOptionTable().Validate(*this));
  return collision.Validate();
}

MotionPlan MotionPlanner::Plan(const Eigen::VectorXd& q_start, const Eigen::VectorXd& q_goal,
                               Rng& rng) const {
  const auto t0 = SteadyClock::now();
  MotionPlan plan;
  const robot::ArmModel& arm = checker_->robot().arm();
  const auto finish = [&](Status status) {
    plan.status = std::move(status);
    plan.planning_ms = MsSince(t0);
    return plan;
  };
  for (const auto* q : {&q_start, &q_goal}) {
    if (const Status s = arm.CheckJoints(*q); !s.ok()) {
      return finish(s.WithContext(q == &q_start ? "motion start" : "motion goal"));
    }
  }
  // A start closer to the map than the margin (the map grew around the arm) plans with the
  // start's own clearance, so that the arm can back away; a start inside an obstacle cannot.
  const CollisionChecker* checker = checker_;
  CollisionChecker relaxed = *checker_;
  if (const StateCheck start = checker_->Check(q_start); !start.free()) {
    const double clearance = checker_->MapClearance(q_start);
    if (start.obstacle != Obstacle::kMap || !(clearance > 0.0)) {
      return finish(InvalidArgumentError(fmt::format("the start state is in collision ({}: {})",
                                                     ToString(start.obstacle), start.detail)));
    }
    relaxed = checker_->WithMargin(0.5 * clearance);
    checker = &relaxed;
  }
  if (const StateCheck goal = checker->Check(q_goal); !goal.free()) {
    return finish(InvalidArgumentError(
        fmt::format("the goal is in collision ({}: {})", ToString(goal.obstacle), goal.detail)));
  }
  plan.straight_check = checker->CheckSegment(q_start, q_goal, /*in_order=*/true);
  if (plan.straight_check.free) {
    plan.straight = true;
    plan.path = {q_start, q_goal};
  } else {
    std::vector<Eigen::VectorXd> found =
        Search(*checker, options_, q_start, q_goal, rng.NextU64(), plan.samples);
    if (found.empty()) {
      return finish(UnreachableError(fmt::format(
          "no collision-free path found ({} samples, {:.0f} ms; the straight line hits {} at "
          "{:.0f} %: {})",
          plan.samples, MsSince(t0), ToString(plan.straight_check.first_collision.obstacle),
          100.0 * plan.straight_check.at_fraction, plan.straight_check.first_collision.detail)));
    }
    plan.path = Shortcut(found, *checker);
    if (options_.shortcut_tries > 0 && plan.path.size() > 2) {
      Rng shortcuts(rng.NextU64());
      plan.path = Shortcut(
          ShortcutPartially(std::move(plan.path), *checker, options_.shortcut_tries, shortcuts),
          *checker);
    }
  }
  plan.path_length = PathLength(plan.path);
  Result<robot::JointTrajectory> trajectory =
      robot::TimeParameterize(arm, plan.path, options_.velocity_scaling,
                              options_.acceleration_scaling, options_.sample_period_s);
  if (!trajectory.ok()) return finish(trajectory.status());
  plan.trajectory = std::move(*trajectory);
  return finish(Status::Ok());
}

}  // namespace avp::motion

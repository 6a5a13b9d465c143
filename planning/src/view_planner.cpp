// Request validation, candidate ranking and the "near a fused view" test shared by the planners.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/core/parallel.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

namespace {

bool IsFinitePose(const RigidTransform& X) {
  return X.rotation().allFinite() && X.translation().allFinite();
}

void AppendJointProblems(std::string_view field, const Eigen::VectorXd& q, int expected,
                         std::vector<std::string>& problems) {
  if (q.size() != expected) {
    problems.push_back(fmt::format("{} has {} joints, the arm has {}", field, q.size(), expected));
  } else if (!q.allFinite()) {
    problems.push_back(fmt::format("{} has a non-finite entry", field));
  }
}

/// Utility for sorting: NaN ranks last.
double SortKey(double utility) {
  return std::isnan(utility) ? -std::numeric_limits<double>::infinity() : utility;
}

}  // namespace

Status ValidateRequest(const PlanningRequest& request) {
  std::vector<std::string> problems;
  if (request.map == nullptr) problems.push_back("map must not be null");
  if (request.arm == nullptr) {
    problems.push_back("arm must not be null");
  } else {
    const int n = request.arm->num_joints();
    AppendJointProblems("q_current", request.q_current, n, problems);
    // q_start may be left empty by callers that do not track it.
    if (request.q_start.size() != 0) AppendJointProblems("q_start", request.q_start, n, problems);
  }
  if (!IsFinitePose(request.X_WC_current)) problems.push_back("X_WC_current must be finite");
  if (!IsFinitePose(request.X_WC_start)) problems.push_back("X_WC_start must be finite");
  if (const Status k = request.K.Validate(); !k.ok()) problems.push_back("K: " + k.message());
  if (request.roi.IsEmpty() || !request.roi.min().allFinite() || !request.roi.max().allFinite()) {
    problems.push_back(
        fmt::format("roi ({}) must be finite and non-empty", request.roi.ToString()));
  }
  if (request.view_index < 1) {
    problems.push_back(
        fmt::format("view_index ({}) must be >= 1 (view 0 is the start view)", request.view_index));
  }
  if (request.views_total < 1) {
    problems.push_back(fmt::format("views_total ({}) must be >= 1", request.views_total));
  }
  for (size_t i = 0; i < request.fused_views.size(); ++i) {
    if (!IsFinitePose(request.fused_views[i])) {
      problems.push_back(fmt::format("fused_views[{}] must be finite", i));
    }
  }
  const int target = static_cast<int>(request.target_class);
  if (target <= 0 || target >= kNumSemanticClasses) {
    problems.push_back(
        fmt::format("target_class ({}) must be a class other than background", target));
  }
  if (problems.empty()) return Status::Ok();
  return InvalidArgumentError(
      fmt::format("invalid planning request: {}", fmt::join(problems, "; ")));
}

bool InSeenFreeSpace(const mapping::OccupancyGrid& grid, const Box3& roi, const Eigen::Vector3d& p,
                     double radius) {
  constexpr double kStep = 0.01;
  const int n = static_cast<int>(std::ceil(radius / kStep));
  for (int i = -n; i <= n; ++i) {
    for (int j = -n; j <= n; ++j) {
      for (int k = -n; k <= n; ++k) {
        const Eigen::Vector3d d(i * kStep, j * kStep, k * kStep);
        if (d.norm() > radius || !roi.Contains(p + d)) continue;
        if (grid.State(grid.KeyOf(p + d)) != mapping::VoxelState::kFree) return false;
      }
    }
  }
  return true;
}

namespace {

/// Moves `c` (its joints in collision) back along its optical axis until its arm is free and its
/// camera stands in seen free space (PlanningRequest::collision_step_back_m). IK starts from the
/// previous step's joints. True when it found such a pose.
bool StepBack(const PlanningRequest& request, ViewCandidate& c) {
  constexpr double kStep = 0.05;
  const robot::ArmModel& arm = *request.arm;
  robot::IkOptions ik = arm.config().ik;
  ik.max_restarts = 0;  // from the previous step's joints only: no generator needed
  Rng unused(0);
  Eigen::VectorXd seed = c.q;
  const int steps = static_cast<int>(std::floor(request.collision_step_back_m / kStep + 1e-9));
  for (int s = 1; s <= steps; ++s) {
    const RigidTransform X(c.X_WC.rotation(),
                           c.X_WC.translation() - s * kStep * c.X_WC.rotation().col(2));
    const robot::IkResult res = arm.SolveCameraIk(X, seed, unused, ik);
    if (!res.ok()) return false;  // out of reach: farther back is farther still
    seed = res.q;
    if (request.collision->IsFree(res.q) &&
        InSeenFreeSpace(request.map->grid(), request.roi, X.translation(), kSeenClearance_m)) {
      c.X_WC = X;
      c.q = res.q;
      c.cost = (res.q - request.q_current).norm();
      return true;
    }
  }
  return false;
}

}  // namespace

size_t DropCollidingCandidates(const PlanningRequest& request,
                               std::vector<ViewCandidate>& candidates) {
  if (request.collision == nullptr) return 0;
  std::vector<char> collides(candidates.size(), 0);
  ParallelFor(candidates.size(), [&](size_t i) {
    ViewCandidate& c = candidates[i];
    collides[i] = c.reachable && !request.collision->IsFree(c.q) && !StepBack(request, c);
  });
  size_t dropped = 0;
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (!collides[i]) continue;
    candidates[i].reachable = false;
    candidates[i].in_collision = true;
    ++dropped;
  }
  return dropped;
}

PlanResult RankCandidates(std::vector<ViewCandidate> candidates, size_t generated,
                          std::string_view planner_name) {
  PlanResult result;
  result.generated = generated;
  std::vector<size_t> order;
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (candidates[i].reachable) order.push_back(i);
    if (candidates[i].in_collision) ++result.in_collision;
  }
  result.reachable = order.size();
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    const double ua = SortKey(candidates[a].utility), ub = SortKey(candidates[b].utility);
    if (ua != ub) return ua > ub;
    return candidates[a].cost < candidates[b].cost;  // then generation order (stable)
  });
  result.ranked.reserve(order.size());
  for (size_t i : order) result.ranked.push_back(std::move(candidates[i]));
  if (result.ranked.empty()) {
    result.status = NotFoundError(
        fmt::format("{}: no valid candidate: {} generated, {} kept after filtering, 0 reachable "
                    "({} in collision)",
                    planner_name, generated, candidates.size(), result.in_collision));
  }
  return result;
}

bool IsNearAny(const RigidTransform& X_WC, const std::vector<RigidTransform>& views,
               double position_tol_m, double angle_tol_rad) {
  return std::any_of(views.begin(), views.end(), [&](const RigidTransform& v) {
    return X_WC.IsNearlyEqualTo(v, position_tol_m, angle_tol_rad);
  });
}

double PlantCoreDistance(const Eigen::Vector3d& p, const Box3& roi) {
  const Eigen::Vector3d c = roi.center();
  const double hx = 0.5 * (roi.max().x() - roi.min().x());
  const double hy = 0.5 * (roi.max().y() - roi.min().y());
  double dx = std::abs(p.x() - c.x());
  double dy = std::abs(p.y() - c.y());
  if (hx >= hy) {
    dx = std::max(0.0, dx - (hx - hy));
  } else {
    dy = std::max(0.0, dy - (hy - hx));
  }
  return std::hypot(dx, dy);
}

}  // namespace avp::planning

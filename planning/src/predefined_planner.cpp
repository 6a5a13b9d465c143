// The predefined planner: the reference system's zig-zag joint waypoints (reference-system.md
// §4.7), and a generic zig-zag generated from the ROI. See docs/planning.md, "Predefined".
#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>
#include <vector>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/planning/predefined_planner.h>

namespace avp::planning {

namespace {

Eigen::VectorXd Vec6(double a, double b, double c, double d, double e, double f) {
  Eigen::VectorXd v(6);
  v << a, b, c, d, e, f;
  return v;
}

bool SameBox(const Box3& a, const Box3& b) { return a.min() == b.min() && a.max() == b.max(); }

bool SamePose(const RigidTransform& a, const RigidTransform& b) {
  return a.rotation() == b.rotation() && a.translation() == b.translation();
}

}  // namespace

const OptionTable<PredefinedOptions>& PredefinedOptionTable() {
  static const auto* table = [] {
    using O = PredefinedOptions;
    auto* t = new OptionTable<O>("predefined planner option");
    t->Real("generic_distance_m", &O::generic_distance_m, "m", ValueRange::Above(0),
            "generic: camera plane's distance from the ROI's axis, towards the base");
    t->Real("generic_lateral_fraction", &O::generic_lateral_fraction, "", ValueRange::AtLeast(0),
            "generic: left/right offsets as a fraction of the ROI's half-width");
    t->Real("generic_bottom_fraction", &O::generic_bottom_fraction, "", ValueRange::Closed(0, 1),
            "generic: lowest camera height as a fraction of the ROI's height");
    t->Real("generic_top_fraction", &O::generic_top_fraction, "", ValueRange::Closed(0, 1),
            "generic: highest camera height as a fraction of the ROI's height");
    t->Integer("generic_waypoints", &O::generic_waypoints, "", ValueRange::Closed(0, 1000),
               "generic: waypoints (0: one per view after the start)");
    t->AddRule([](const O& o, std::vector<std::string>& problems) {
      const ValueRange unit = ValueRange::Closed(0, 1);
      if (unit.Contains(o.generic_bottom_fraction) && unit.Contains(o.generic_top_fraction) &&
          o.generic_bottom_fraction > o.generic_top_fraction) {
        problems.push_back(
            fmt::format("generic_bottom_fraction ({}) must be <= generic_top_fraction ({})",
                        o.generic_bottom_fraction, o.generic_top_fraction));
      }
    });
    return t;
  }();
  return *table;
}

Status PredefinedOptions::Validate() const { return PredefinedOptionTable().Validate(*this); }

std::vector<PlannerEntry> PredefinedPlannerEntries() {
  std::vector<PlannerEntry> entries;
  for (const auto& [set, name, description] :
       {std::tuple{PredefinedOptions::Set::kNarrow, "predefined",
                   "the reference's zig-zag of joint waypoints (zig_zag_plane_narrow)"},
        std::tuple{PredefinedOptions::Set::kWide, "predefined-wide",
                   "the reference's wide zig-zag (zig_zag_plane_wide)"},
        std::tuple{PredefinedOptions::Set::kGeneric, "predefined-generic",
                   "a zig-zag generated from the ROI, for scenes other than the reference's"}}) {
    PredefinedOptions defaults;
    defaults.set = set;
    entries.push_back(MakePlannerEntry<PredefinedOptions>(
        name, description, PredefinedOptionTable(), defaults,
        [](const PredefinedOptions& o, const PlannerContext&) {
          return Result<std::unique_ptr<ViewPlanner>>(std::make_unique<PredefinedPlanner>(o));
        }));
  }
  return entries;
}

std::string_view ToString(PredefinedOptions::Set set) {
  switch (set) {
    case PredefinedOptions::Set::kNarrow:
      return "narrow";
    case PredefinedOptions::Set::kWide:
      return "wide";
    case PredefinedOptions::Set::kGeneric:
      return "generic";
  }
  return "?";
}

std::optional<PredefinedOptions::Set> PredefinedSetFromString(std::string_view name) {
  for (const auto set : {PredefinedOptions::Set::kNarrow, PredefinedOptions::Set::kWide,
                         PredefinedOptions::Set::kGeneric}) {
    if (name == ToString(set)) return set;
  }
  return std::nullopt;
}

Eigen::VectorXd ReferenceStartJointsDeg() { return Vec6(0, -40, 90, 0, 40, 0); }

std::vector<Eigen::VectorXd> ReferenceWaypointsDeg(PredefinedOptions::Set set) {
  // av_planning/config/predefined_planning_waypoints.yaml, reference joint convention, degrees.
  switch (set) {
    case PredefinedOptions::Set::kNarrow:  // zig_zag_plane_narrow_waypoints (the default)
      return {Vec6(-65, 19, 1, 66, 82, -18),    Vec6(64, -7, 50, -70, 73, 40),
              Vec6(-65, -14, 66, 74, 70, -49),  Vec6(64, -23, 87, -78, 68, 61),
              Vec6(-65, -26, 96, 81, 66, -68),  Vec6(64, -31, 113, -86, 65, 81),
              Vec6(-65, -30, 118, 89, 65, -87), Vec6(65, -30, 133, -96, 66, 105)};
    case PredefinedOptions::Set::kWide:  // zig_zag_plane_wide_waypoints
      return {Vec6(-75, 30, 4, 77, 81, -33),   Vec6(73, 5, 56, -83, 76, 61),
              Vec6(-75, 1, 70, 85, 75, -70),   Vec6(72, -4, 86, -88, 74, 82),
              Vec6(-75, -3, 97, 92, 74, -94),  Vec6(72, -3, 106, -94, 74, 104),
              Vec6(-75, 5, 113, 98, 76, -119), Vec6(72, 10, 116, -100, 77, 128)};
    case PredefinedOptions::Set::kGeneric:
      return {};
  }
  return {};
}

std::vector<RigidTransform> GenericZigZagPoses(const Box3& roi, int n,
                                               const PredefinedOptions& options) {
  AVP_THROW_UNLESS(!roi.IsEmpty() && roi.min().allFinite() && roi.max().allFinite(),
                   roi.ToString());
  AVP_THROW_UNLESS(n >= 0, n);
  const Status valid = options.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());

  const Eigen::Vector3d c = roi.center();
  // Viewing direction: horizontal, from the robot base towards the ROI's centre axis.
  Eigen::Vector3d f(c.x(), c.y(), 0.0);
  if (f.norm() < 1e-9) f = Eigen::Vector3d::UnitX();
  f.normalize();
  const Eigen::Vector3d right = f.cross(Eigen::Vector3d::UnitZ());  // image right
  const Eigen::Vector3d size = roi.size();
  const double half_width = 0.5 * (std::abs(right.x()) * size.x() + std::abs(right.y()) * size.y());
  const double lateral = options.generic_lateral_fraction * half_width;

  std::vector<RigidTransform> poses;
  poses.reserve(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    const double t = n == 1 ? 0.0 : static_cast<double>(i) / (n - 1);
    const double fraction = options.generic_bottom_fraction +
                            t * (options.generic_top_fraction - options.generic_bottom_fraction);
    const double z = roi.min().z() + fraction * size.z();
    const Eigen::Vector3d axis_point(c.x(), c.y(), z);
    const double side = i % 2 == 0 ? 1.0 : -1.0;
    const Eigen::Vector3d eye =
        axis_point - options.generic_distance_m * f + side * lateral * right;
    poses.push_back(RigidTransform::LookAt(eye, axis_point, Eigen::Vector3d::UnitZ()));
  }
  return poses;
}

PredefinedPlanner::PredefinedPlanner(const PredefinedOptions& options) : options_(options) {
  const Status valid = options_.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
}

const PredefinedPlanner::Waypoints& PredefinedPlanner::WaypointsFor(const PlanningRequest& request,
                                                                    Rng& rng) {
  AVP_THROW_UNLESS(request.arm != nullptr);
  const robot::ArmModel& arm = *request.arm;
  if (options_.set != PredefinedOptions::Set::kGeneric) {
    waypoints_ = {};
    for (const Eigen::VectorXd& deg : ReferenceWaypointsDeg(options_.set)) {
      AVP_THROW_UNLESS(arm.num_joints() == deg.size(), arm.num_joints(), deg.size());
      waypoints_.q.push_back(arm.FromReferenceJoints(deg * (EIGEN_PI / 180.0)));
    }
    cached_ = false;
    return waypoints_;
  }
  if (cached_ && SameBox(cached_roi_, request.roi) && cached_views_total_ == request.views_total &&
      SamePose(cached_start_, request.X_WC_start)) {
    return waypoints_;
  }
  const int n = options_.generic_waypoints > 0 ? options_.generic_waypoints
                                               : std::max(0, request.views_total - 1);
  waypoints_ = {};
  Eigen::VectorXd seed = request.q_start.size() != 0 ? request.q_start : request.q_current;
  // A pose the arm cannot reach is pulled towards the start camera in steps (its lateral offset
  // and height blended towards the start eye's, still looking at the axis at its own height)
  // before it is dropped: the zig-zag keeps its shape where the workspace allows.
  const Eigen::Vector3d start_eye = request.X_WC_start.translation();
  for (const RigidTransform& X_WC : GenericZigZagPoses(request.roi, n, options_)) {
    const Eigen::Vector3d eye = X_WC.translation();
    const Eigen::Vector3d look = eye + X_WC.rotation().col(2);  // optical z: the viewing direction
    bool placed = false;
    for (double blend : {0.0, 0.25, 0.5, 0.75}) {
      const Eigen::Vector3d e = (1.0 - blend) * eye + blend * start_eye;
      const Eigen::Vector3d target(look.x(), look.y(), e.z());
      const RigidTransform X = RigidTransform::LookAt(e, target, Eigen::Vector3d::UnitZ());
      const robot::IkResult ik = arm.SolveCameraIk(X, seed, rng);
      if (ik.ok() && arm.WithinLimits(ik.q)) {
        waypoints_.q.push_back(ik.q);
        seed = ik.q;
        placed = true;
        break;
      }
    }
    if (!placed) ++waypoints_.dropped;
  }
  cached_ = true;
  cached_roi_ = request.roi;
  cached_views_total_ = request.views_total;
  cached_start_ = request.X_WC_start;
  return waypoints_;
}

namespace {

/// With a collision checker: waypoint p_k and every later one, in order, without those already
/// visited (near a fused view: an earlier view moved past a skipped waypoint) and those whose
/// joints are in collision (counted), so that the loop skips a waypoint it cannot reach without
/// collision for the next.
PlanResult RankRemainingWaypoints(const PlanningRequest& request,
                                  const PredefinedPlanner::Waypoints& w,
                                  const std::string& set_name) {
  const robot::ArmModel& arm = *request.arm;
  PlanResult result;
  std::vector<ViewCandidate> candidates;
  for (size_t i = static_cast<size_t>(request.view_index - 1); i < w.q.size(); ++i) {
    ViewCandidate c;
    c.q = w.q[i];
    c.X_WC = arm.CameraPose(c.q);
    if (IsNearAny(c.X_WC, request.fused_views)) continue;
    c.reachable = arm.WithinLimits(c.q);
    c.cost = (c.q - request.q_current).norm();
    c.source = fmt::format("waypoint p{}", i + 1);
    candidates.push_back(std::move(c));
  }
  result.generated = candidates.size();
  result.in_collision = DropCollidingCandidates(request, candidates);
  for (ViewCandidate& c : candidates) {
    if (c.reachable) result.ranked.push_back(std::move(c));
  }
  result.reachable = result.ranked.size();
  if (result.ranked.empty()) {
    result.status = NotFoundError(fmt::format(
        "predefined ({}): no waypoint from p{} on is free: {} not yet visited, {} of them in "
        "collision, {} outside the joint limits",
        set_name, request.view_index, result.generated, result.in_collision,
        result.generated - result.in_collision));
  }
  return result;
}

}  // namespace

PlanResult PredefinedPlanner::Plan(const PlanningRequest& request, Rng& rng) {
  PlanResult result;
  if (const Status s = ValidateRequest(request); !s.ok()) {
    result.status = s.WithContext("predefined");
    return result;
  }
  const robot::ArmModel& arm = *request.arm;
  if (options_.set != PredefinedOptions::Set::kGeneric && arm.num_joints() != 6) {
    result.status = InvalidArgumentError(fmt::format(
        "predefined ({}): the reference waypoints are for the 6-joint ReBeL, the arm has {} joints",
        ToString(options_.set), arm.num_joints()));
    return result;
  }
  const Waypoints& w = WaypointsFor(request, rng);
  const std::string set_name(ToString(options_.set));
  const int k = request.view_index;
  if (static_cast<size_t>(k) > w.q.size()) {
    std::string dropped;
    if (w.dropped > 0) dropped = fmt::format(" ({} unreachable generic poses dropped)", w.dropped);
    result.status = NotFoundError(fmt::format(
        "predefined ({}): waypoints exhausted: view_index {} asks for p{}, the set has {} "
        "waypoints{}",
        set_name, k, k, w.q.size(), dropped));
    return result;
  }
  if (request.collision != nullptr) return RankRemainingWaypoints(request, w, set_name);
  const Eigen::VectorXd& q = w.q[static_cast<size_t>(k - 1)];
  result.generated = 1;
  if (!arm.WithinLimits(q)) {
    result.status =
        NotFoundError(fmt::format("predefined ({}): waypoint p{} is outside the joint "
                                  "limits: {}",
                                  set_name, k, arm.CheckJoints(q).message()));
    return result;
  }
  ViewCandidate c;
  c.q = q;
  c.X_WC = arm.CameraPose(q);
  c.reachable = true;
  c.cost = (q - request.q_current).norm();
  c.source = "waypoint";
  result.reachable = 1;
  result.ranked.push_back(std::move(c));
  return result;
}

}  // namespace avp::planning

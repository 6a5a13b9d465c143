#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include <fcl/geometry/collision_geometry.h>
#include <fmt/format.h>

#include <avp/motion/collision_checker.h>

namespace avp::motion {

/// A declared world object: a plane as its half-space (checked against the sphere cover), any
/// other shape as FCL geometry with its pose and world-frame bounds.
struct CollisionChecker::WorldObject {
  std::string name;
  bool is_plane = false;
  Eigen::Vector3d normal_W = Eigen::Vector3d::UnitZ();  ///< plane: solid where normal·p <= offset
  double offset = 0.0;
  std::shared_ptr<const fcl::CollisionGeometry<double>> geometry;
  Eigen::Isometry3d X_WO = Eigen::Isometry3d::Identity();
};

namespace {

const OptionTable<ObstacleFieldOptions>& FieldOptionTable() {
  static const auto* table = [] {
    using F = ObstacleFieldOptions;
    auto* t = new OptionTable<F>("obstacle field option");
    t->Real("resolution_m", &F::resolution_m, "m", ValueRange::Closed(0.002, 0.1),
            "cell of the map's distance field (a cell is an obstacle when any voxel in it is)");
    t->Flag("unknown_is_obstacle", &F::unknown_is_obstacle,
            "unknown voxels inside the region of interest are obstacles");
    t->Flag("unknown_behind_start_is_free", &F::unknown_behind_start_is_free,
            "unknown space behind the first view's image plane (the robot's side) is free");
    t->Real("start_clearance_m", &F::start_clearance_m, "m", ValueRange::Closed(0, 0.5),
            "free space assumed around the arm at its start pose (it was placed clear of the "
            "plant)");
    t->Real("unknown_band_m", &F::unknown_band_m, "m", ValueRange::Closed(0, 10),
            "only unknown voxels this close to an occupied one are obstacles (0: all in the ROI)");
    t->Real("max_distance_m", &F::max_distance_m, "m", ValueRange::LeftOpen(0, 10),
            "distances are exact up to this");
    return t;
  }();
  return *table;
}

}  // namespace

std::string_view ToString(Obstacle obstacle) {
  switch (obstacle) {
    case Obstacle::kNone:
      return "none";
    case Obstacle::kJointLimits:
      return "joint limits";
    case Obstacle::kMap:
      return "map";
    case Obstacle::kWorld:
      return "world";
    case Obstacle::kSelf:
      return "self";
  }
  return "unknown";
}

const OptionTable<CollisionOptions>& CollisionOptionTable() {
  static const auto* table = [] {
    using C = CollisionOptions;
    auto* t = new OptionTable<C>("collision option");
    t->Real("margin_m", &C::margin_m, "m", ValueRange::Closed(0, 0.5),
            "clearance kept from the map's obstacles and the declared world objects");
    t->Real("self_margin_m", &C::self_margin_m, "m", ValueRange::Closed(0, 0.1),
            "clearance between the arm's own bodies");
    t->Real("max_step_m", &C::max_step_m, "m", ValueRange::LeftOpen(0, 0.05),
            "most any point of the arm moves between two checked states of a motion");
    t->Nested("map", &C::field, FieldOptionTable());
    t->AddRule([](const C& o, std::vector<std::string>& problems) {
      if (o.margin_m > 0.0 && o.max_step_m > 2.0 * o.margin_m) {
        problems.push_back(fmt::format(
            "max_step_m ({}) must be at most 2 x margin_m ({}): a body could pass an obstacle "
            "between two checked states",
            o.max_step_m, o.margin_m));
      }
    });
    return t;
  }();
  return *table;
}

Status CollisionOptions::Validate() const {
  AVP_RETURN_IF_ERROR(CollisionOptionTable().Validate(*this));
  return field.Validate();
}

CollisionChecker::CollisionChecker(RobotGeometry robot, CollisionOptions options)
    : robot_(std::move(robot)),
      options_(std::move(options)),
      field_(std::make_shared<const ObstacleField>()),
      states_checked_(std::make_shared<std::atomic<int64_t>>(0)) {}

namespace {

/// InvalidArgument naming the first joint whose limits have zero width: the planner searches
/// between the limits (OMPL needs lower < upper), and such a joint cannot move.
Status CheckJointRanges(const robot::ArmModel& arm) {
  for (int i = 0; i < arm.num_joints(); ++i) {
    const double lo = arm.lower_limits()[i], hi = arm.upper_limits()[i];
    if (std::isfinite(lo) && std::isfinite(hi) && !(lo < hi)) {
      return InvalidArgumentError(fmt::format(
          "joint '{}' has limits of zero width ([{}, {}]): it cannot move, and collision-free "
          "motion plans between the limits; make it a fixed joint in the URDF, or widen it",
          arm.joint_names()[static_cast<size_t>(i)], lo, hi));
    }
  }
  return Status::Ok();
}

}  // namespace

Result<CollisionChecker> CollisionChecker::Create(RobotGeometry robot,
                                                  const std::vector<robot::CollisionShape>& world,
                                                  const CollisionOptions& options) {
  AVP_RETURN_IF_ERROR(options.Validate());
  AVP_RETURN_IF_ERROR(CheckJointRanges(robot.arm()));
  CollisionChecker checker(std::move(robot), options);
  for (const robot::CollisionShape& shape : world) {
    auto object = std::make_shared<WorldObject>();
    object->name = shape.name;
    object->X_WO = shape.X_PS.ToIsometry();
    if (shape.kind == robot::ShapeKind::kPlane) {
      object->is_plane = true;
      object->normal_W = object->X_WO.linear().col(2);
      object->offset = object->normal_W.dot(object->X_WO.translation());
    } else {
      AVP_ASSIGN_OR_RETURN(object->geometry, MakeFclGeometry(shape, "collision.world"));
    }
    checker.world_.push_back(std::move(object));
  }
  return checker;
}

Status CollisionChecker::SetMap(const mapping::OccupancyGrid& grid, const Box3& roi) {
  // The field covers what the arm can reach (every body within max_reach + its size of the base)
  // and no more than the map's blocks and the ROI span.
  const robot::ArmModel& arm = robot_.arm();
  double body_size = 0.0;
  for (const RobotBody& body : robot_.bodies()) {
    for (const Sphere& s : body.spheres)
      body_size = std::max(body_size, s.center.norm() + s.radius);
  }
  const double reach = arm.max_reach_m() + body_size + options_.margin_m;
  const Eigen::Vector3d base = arm.JointFrames(arm.home_joints()).front().translation();
  const Box3 reach_box(base - Eigen::Vector3d::Constant(reach),
                       base + Eigen::Vector3d::Constant(reach));
  Box3 content = roi;
  const double block_m = grid.voxel_size_m() * mapping::kBlockEdge;
  grid.ForEachBlock([&](const mapping::OccupancyBlock& block) {
    const Eigen::Vector3d lo = Eigen::Vector3d(block.key.x, block.key.y, block.key.z) * block_m;
    content.Extend(lo);
    content.Extend(lo + Eigen::Vector3d::Constant(block_m));
  });
  const Box3 bounds = content.Intersection(reach_box);
  if (bounds.IsEmpty()) {
    field_ = std::make_shared<const ObstacleField>();
    return Status::Ok();
  }
  AVP_ASSIGN_OR_RETURN(ObstacleField field, ObstacleField::Build(grid, roi, bounds, options_.field,
                                                                 swept_, clear_halfspace_));
  field_ = std::make_shared<const ObstacleField>(std::move(field));
  return Status::Ok();
}

void CollisionChecker::MarkSwept(const Eigen::VectorXd& q) {
  // A state within a centimetre of travel of the last one marked adds nothing the pad does not
  // already cover: the swept list grows with the distance travelled, not with the states.
  if (last_swept_.size() == q.size() && robot_.MaxDisplacement(q - last_swept_) < 0.01) return;
  MarkFree(q, options_.margin_m);
}

void CollisionChecker::MarkStart(const Eigen::VectorXd& q) {
  MarkFree(q, options_.field.start_clearance_m);
}

double CollisionChecker::FieldRounding() const {
  return 1.5 * std::sqrt(3.0) * options_.field.resolution_m + 1e-3;
}

double CollisionChecker::StartFreeDistance() const {
  return options_.field.start_clearance_m + FieldRounding();
}

void CollisionChecker::MarkFree(const Eigen::VectorXd& q, double clearance_m) {
  last_swept_ = q;
  const std::vector<Eigen::Isometry3d> links = robot_.LinkPoses(q);
  // Padded, as MoveIt's self-filter pads the robot: the clearance plus the field's rounding, so
  // that q itself is clearance_m from the unknown space around it.
  const double pad = clearance_m + FieldRounding();
  for (const RobotBody& body : robot_.bodies()) {
    if (!body.moves) continue;
    const Eigen::Isometry3d& X_WL = links[static_cast<size_t>(body.link)];
    for (const Sphere& s : body.spheres) swept_.push_back({X_WL * s.center, s.radius + pad});
  }
}

void CollisionChecker::ClearMap() {
  field_ = std::make_shared<const ObstacleField>();
  swept_.clear();
  last_swept_.resize(0);
  clear_halfspace_.reset();
}

void CollisionChecker::SetStartView(const RigidTransform& X_WC, const Box3& roi) {
  if (!options_.field.unknown_behind_start_is_free) return;
  // The plane through the start camera facing the plant: its normal is the horizontal direction
  // from the robot's base to the ROI's centre (the optical axis when that is vertical).
  const Eigen::Vector3d base =
      robot_.arm().JointFrames(robot_.arm().home_joints()).front().translation();
  Eigen::Vector3d n = roi.center() - base;
  n.z() = 0.0;
  if (n.norm() < 1e-6) n = X_WC.rotation().col(2);
  n.normalize();
  clear_halfspace_ = Eigen::Vector4d(n.x(), n.y(), n.z(), n.dot(X_WC.translation()));
}

CollisionChecker::Hit CollisionChecker::Find(const Eigen::VectorXd& q) const {
  states_checked_->fetch_add(1, std::memory_order_relaxed);
  const robot::ArmModel& arm = robot_.arm();
  if (!arm.WithinLimits(q)) return {Obstacle::kJointLimits, 0, 0, std::nullopt};
  const std::vector<Eigen::Isometry3d> links = robot_.LinkPoses(q);
  const std::vector<RobotBody>& bodies = robot_.bodies();
  const double margin = options_.margin_m;
  // The map and the declared planes, against each moving body's spheres.
  for (size_t i = 0; i < bodies.size(); ++i) {
    const RobotBody& body = bodies[i];
    if (!body.moves) continue;
    const Eigen::Isometry3d& X_WL = links[static_cast<size_t>(body.link)];
    for (const Sphere& s : body.spheres) {
      const Eigen::Vector3d c = X_WL * s.center;
      if (!field_->empty()) {
        const double clearance = field_->Distance(c) - s.radius;
        if (clearance < margin) return {Obstacle::kMap, i, 0, clearance};
      }
      for (size_t k = 0; k < world_.size(); ++k) {
        const WorldObject& object = *world_[k];
        if (!object.is_plane) continue;
        const double clearance = object.normal_W.dot(c) - object.offset - s.radius;
        if (clearance < margin) return {Obstacle::kWorld, i, k, clearance};
      }
    }
  }
  // Other declared objects, with FCL against the bodies' true shapes.
  for (size_t i = 0; i < bodies.size(); ++i) {
    const RobotBody& body = bodies[i];
    if (!body.moves) continue;
    const Eigen::Isometry3d X_WG = links[static_cast<size_t>(body.link)] * body.X_LG;
    for (size_t k = 0; k < world_.size(); ++k) {
      const WorldObject& object = *world_[k];
      if (object.is_plane) continue;
      if (WithinDistance(*body.geometry, X_WG, *object.geometry, object.X_WO, margin)) {
        return {Obstacle::kWorld, i, k, std::nullopt};
      }
    }
  }
  for (const auto& [a, b] : robot_.self_check_pairs()) {
    const RobotBody& ba = bodies[static_cast<size_t>(a)];
    const RobotBody& bb = bodies[static_cast<size_t>(b)];
    if (!BoundsWithin(ba, links[static_cast<size_t>(ba.link)], bb,
                      links[static_cast<size_t>(bb.link)], options_.self_margin_m)) {
      continue;
    }
    if (WithinDistance(*ba.geometry, links[static_cast<size_t>(ba.link)] * ba.X_LG, *bb.geometry,
                       links[static_cast<size_t>(bb.link)] * bb.X_LG, options_.self_margin_m)) {
      return {Obstacle::kSelf, static_cast<size_t>(a), static_cast<size_t>(b), std::nullopt};
    }
  }
  return {};
}

StateCheck CollisionChecker::Describe(const Eigen::VectorXd& q, const Hit& hit) const {
  const std::vector<RobotBody>& bodies = robot_.bodies();
  const double margin = options_.margin_m;
  switch (hit.obstacle) {
    case Obstacle::kNone:
      return {};
    case Obstacle::kJointLimits:
      return {hit.obstacle, robot_.arm().CheckJoints(q).message()};
    case Obstacle::kMap:
      return {hit.obstacle,
              fmt::format("'{}' within {:.3f} m of the map's obstacles (margin {} m)",
                          bodies[hit.body].name, std::max(*hit.clearance, 0.0), margin)};
    case Obstacle::kWorld:
      if (!hit.clearance) {  // FCL's boolean query: within the margin, no distance
        return {hit.obstacle, fmt::format("'{}' within {} m of '{}'", bodies[hit.body].name, margin,
                                          world_[hit.other]->name)};
      }
      return {hit.obstacle,
              fmt::format("'{}' within {:.3f} m of '{}' (margin {} m)", bodies[hit.body].name,
                          std::max(*hit.clearance, 0.0), world_[hit.other]->name, margin)};
    case Obstacle::kSelf:
      return {hit.obstacle,
              fmt::format("'{}' – '{}'", bodies[hit.body].name, bodies[hit.other].name)};
  }
  return {};
}

StateCheck CollisionChecker::Check(const Eigen::VectorXd& q) const { return Describe(q, Find(q)); }

bool CollisionChecker::IsFree(const Eigen::VectorXd& q) const {
  return Find(q).obstacle == Obstacle::kNone;
}

SegmentCheck CollisionChecker::CheckSegment(const Eigen::VectorXd& a, const Eigen::VectorXd& b,
                                            bool in_order) const {
  SegmentCheck result;
  const Eigen::VectorXd dq = b - a;
  const double travel = robot_.MaxDisplacement(dq);
  const int steps = std::max(1, static_cast<int>(std::ceil(travel / options_.max_step_m)));
  const auto check = [&](int i) {
    const double f = static_cast<double>(i) / steps;
    const Eigen::VectorXd q = a + f * dq;
    const Hit hit = Find(q);
    ++result.states;
    if (hit.obstacle == Obstacle::kNone) return true;
    result.free = false;
    result.first_collision = Describe(q, hit);  // once per segment: the check stops here
    result.at_fraction = f;
    return false;
  };
  if (in_order) {
    for (int i = 0; i <= steps; ++i) {
      if (!check(i)) return result;
    }
    return result;
  }
  // The ends, then the midpoints of the intervals left, coarse to fine: a colliding segment is
  // usually rejected after a few states; a free one costs the same as in order.
  if (!check(0) || !check(steps)) return result;
  std::vector<std::pair<int, int>> intervals{{0, steps}};
  std::vector<std::pair<int, int>> next;
  while (!intervals.empty()) {
    next.clear();
    for (const auto& [lo, hi] : intervals) {
      if (hi - lo < 2) continue;
      const int mid = lo + (hi - lo) / 2;
      if (!check(mid)) return result;
      next.emplace_back(lo, mid);
      next.emplace_back(mid, hi);
    }
    intervals.swap(next);
  }
  return result;
}

double CollisionChecker::MapClearance(const Eigen::VectorXd& q) const {
  if (field_->empty()) return options_.field.max_distance_m;
  const std::vector<Eigen::Isometry3d> links = robot_.LinkPoses(q);
  double clearance = options_.field.max_distance_m;
  for (const RobotBody& body : robot_.bodies()) {
    if (!body.moves) continue;
    const Eigen::Isometry3d& X_WL = links[static_cast<size_t>(body.link)];
    for (const Sphere& s : body.spheres) {
      clearance = std::min(clearance, field_->Distance(X_WL * s.center) - s.radius);
    }
  }
  return clearance;
}

CollisionChecker CollisionChecker::WithMargin(double margin_m) const {
  CollisionChecker copy = *this;
  copy.options_.margin_m = margin_m;
  // Keep max_step_m <= 2 margin_m (down to 1 mm), so bodies still cannot pass an obstacle
  // between checked states.
  copy.options_.max_step_m = std::min(options_.max_step_m, std::max(2.0 * margin_m, 0.001));
  return copy;
}

int64_t CollisionChecker::states_checked() const {
  return states_checked_->load(std::memory_order_relaxed);
}

}  // namespace avp::motion

#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/mapping/voxel_grid.h>
#include <avp/motion/obstacle_field.h>
#include <avp/motion/robot_geometry.h>

namespace avp::motion {

/// What counts as an obstacle and how far the arm keeps from it (the run config's `motion.*`).
struct CollisionOptions {
  /// Clearance the arm keeps from the map's obstacles and the declared world objects (metres).
  double margin_m = 0.02;
  /// Clearance between the arm's own bodies (pairs not in the allowed list).
  double self_margin_m = 0.005;
  /// No point of the arm moves more than this between two checked states of a motion (metres):
  /// with margin_m >= max_step_m a swept body cannot pass through an obstacle between samples.
  double max_step_m = 0.005;
  ObstacleFieldOptions field;

  /// OK, or InvalidArgument naming each bad value.
  Status Validate() const;
};
const OptionTable<CollisionOptions>& CollisionOptionTable();

/// What made a state invalid.
enum class Obstacle : uint8_t {
  kNone,
  kJointLimits,  ///< outside the joint limits
  kMap,          ///< an occupied voxel, or an unknown one inside the ROI, within the margin
  kWorld,        ///< a declared world object (collision.world) within the margin
  kSelf,         ///< two of the arm's own bodies
};
std::string_view ToString(Obstacle obstacle);

/// The verdict on one joint state.
struct StateCheck {
  Obstacle obstacle = Obstacle::kNone;
  /// "link_5 within 0.012 m of the map", "flange/d435 – ground", "link_2 – link_7".
  std::string detail;
  bool free() const { return obstacle == Obstacle::kNone; }
};

/// The verdict on a straight joint-space segment, sampled so that no point of the arm moves
/// more than max_step_m between samples.
struct SegmentCheck {
  bool free = true;
  /// A state in collision (when !free: the first along the segment when checked in order, else
  /// the first found coarse to fine), and where along the segment (0..1).
  StateCheck first_collision;
  double at_fraction = 0.0;
  /// States checked.
  int states = 0;
};

/// The world the planner may not touch, and the checks against it: the robot's collision model,
/// the declared world objects (the arm config's collision.world), and the map's obstacle field.
/// The map is taken in with SetMap before each plan; everything else is fixed. Check and
/// CheckSegment are const and thread-safe (candidate filtering runs them in parallel).
class CollisionChecker {
 public:
  /// Errors: bad options, a world shape FCL cannot build (naming it).
  static Result<CollisionChecker> Create(RobotGeometry robot,
                                         const std::vector<robot::CollisionShape>& world,
                                         const CollisionOptions& options);

  /// Rebuilds the obstacle field from the map: occupied voxels, and unknown voxels inside `roi`
  /// (options.field.unknown_is_obstacle), except in the space the arm has swept (MarkSwept).
  /// The field covers the arm's reach. Errors from ObstacleField::Build.
  Status SetMap(const mapping::OccupancyGrid& grid, const Box3& roi);
  /// Records that the arm occupied state q (it moved through it): the space of its bodies there
  /// holds nothing it did not touch, so unknown voxels there are not obstacles at the next SetMap
  /// (occupied ones still are). Padded by margin_m and 1.5 field-cell diagonals, as MoveIt's
  /// self-filter pads the robot, so that q itself passes the check: on a planned path the space
  /// within margin_m was already free; the cell diagonals beyond it are taken as free too.
  void MarkSwept(const Eigen::VectorXd& q);
  /// The arm stands at q when the episode starts: unknown space within StartFreeDistance() of its
  /// bodies' sphere cover is free. With start_clearance_m below margin_m, the first move plans
  /// with the start's own clearance (MotionPlanner::Plan).
  void MarkStart(const Eigen::VectorXd& q);
  /// How far from the arm's bodies (their sphere cover) MarkStart frees unknown space, metres:
  /// options.field.start_clearance_m plus the field's rounding, 1.5 cell diagonals and 1 mm
  /// (0.047 m at the defaults), so that the start itself is start_clearance_m from what is
  /// left; the arm may move into that rounding where the field's cells allow.
  double StartFreeDistance() const;
  /// Forgets the map, the swept space and the start view (a new episode).
  void ClearMap();
  /// With options.field.unknown_behind_start_is_free: unknown space on the robot's side of the
  /// episode's first camera position is free (the robot starts in front of the plant, nothing of
  /// it between the camera and the base): the half-space behind the vertical plane through the
  /// camera whose normal is the horizontal direction from the base to the ROI's centre.
  void SetStartView(const RigidTransform& X_WC, const Box3& roi);

  StateCheck Check(const Eigen::VectorXd& q) const;
  /// Check without the message (the planner's hot path: most states it samples collide).
  bool IsFree(const Eigen::VectorXd& q) const;
  /// The straight segment a → b (joint space), checked at the max_step_m resolution: the ends,
  /// then midpoints coarse to fine (a colliding segment is rejected early), or with `in_order`
  /// from a to b (the first colliding state).
  SegmentCheck CheckSegment(const Eigen::VectorXd& a, const Eigen::VectorXd& b,
                            bool in_order = false) const;
  /// The smallest distance of the arm's sphere cover from the map's obstacles at q, minus the
  /// spheres' radii (metres; negative inside); +max_distance when the field is empty.
  double MapClearance(const Eigen::VectorXd& q) const;

  const RobotGeometry& robot() const { return robot_; }
  const CollisionOptions& options() const { return options_; }
  const ObstacleField& field() const { return *field_; }
  /// A copy with another margin_m (and max_step_m at most twice it, at least 1 mm), sharing the
  /// map's field (a move whose start is closer to the map than the margin plans with the start's
  /// own clearance).
  CollisionChecker WithMargin(double margin_m) const;
  /// States checked since creation (all threads), for benchmarks.
  int64_t states_checked() const;

 private:
  CollisionChecker(RobotGeometry robot, CollisionOptions options);

  struct WorldObject;
  /// What Find met at a state: body indexes into robot_.bodies(), other into world_ (kWorld) or
  /// bodies (kSelf); clearance for the map and planes (none from FCL's boolean queries).
  struct Hit {
    Obstacle obstacle = Obstacle::kNone;
    size_t body = 0;
    size_t other = 0;
    std::optional<double> clearance;
  };
  Hit Find(const Eigen::VectorXd& q) const;
  /// Unknown space within clearance_m of the arm's bodies at q (plus the field's conservatism) is
  /// free at the next SetMap.
  void MarkFree(const Eigen::VectorXd& q, double clearance_m);
  /// What the field's cells can understate a distance by, and 1 mm: 1.5 cell diagonals (a cell
  /// centre within half a diagonal of the point, a value up to a diagonal low).
  double FieldRounding() const;
  /// The verdict with its message, formatted only when a caller wants it.
  StateCheck Describe(const Eigen::VectorXd& q, const Hit& hit) const;

  RobotGeometry robot_;
  CollisionOptions options_;
  std::vector<std::shared_ptr<const WorldObject>> world_;
  std::shared_ptr<const ObstacleField> field_;
  std::vector<Sphere> swept_;
  Eigen::VectorXd last_swept_;  ///< the last state MarkSwept took
  std::optional<Eigen::Vector4d> clear_halfspace_;
  std::shared_ptr<std::atomic<int64_t>> states_checked_;
};

}  // namespace avp::motion

#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include <avp/core/status.h>
#include <avp/motion/obstacle_field.h>
#include <avp/robot/arm_config.h>
#include <avp/robot/arm_model.h>

namespace fcl {
template <typename S>
class CollisionGeometry;
}  // namespace fcl

namespace avp::motion {

/// One rigid shape of the robot: a URDF collision shape of a link, or a shape the arm config
/// attaches to the tip link (the camera's body).
struct RobotBody {
  /// "link_2", "link_2#1" (a link's second shape), "flange/d435" (attached).
  std::string name;
  /// Index of the link it is fixed to in ArmModel::links().
  int link = 0;
  /// The shape, its pose X_PS in the link frame.
  robot::CollisionShape shape;
  /// FCL's geometry of the shape (meshes: a BVHModel<OBBRSS> of the scaled vertices).
  std::shared_ptr<const fcl::CollisionGeometry<double>> geometry;
  /// Pose of `geometry` in the link frame (shape.X_PS: FCL centres its primitives as URDF does).
  Eigen::Isometry3d X_LG = Eigen::Isometry3d::Identity();
  /// Spheres covering the shape, in the link frame (conservative: every point of the shape is
  /// inside one of them).
  std::vector<Sphere> spheres;
  /// A sphere holding the whole shape, in the link frame (a cheap first test before FCL's).
  Sphere bound;
  /// False for shapes on links fixed to the base (before the first movable joint): they never
  /// move, so they are not checked against the world (the base stands on the ground).
  bool moves = true;
};

/// Why a pair of bodies is not checked for self-collision (MoveIt's setup assistant's reasons).
enum class AllowedReason : uint8_t {
  kSameLink,  ///< the two shapes are fixed to the same rigid link group (no joint between them)
  kAdjacent,  ///< their links are parent and child across one movable joint
  kDefault,   ///< in contact at the home pose
  kAlways,    ///< in contact in more than 95 % of 1000 random states (seeded, reproducible)
};
std::string_view ToString(AllowedReason reason);

struct AllowedPair {
  int a = 0;
  int b = 0;
  AllowedReason reason = AllowedReason::kSameLink;
};

/// How the robot's collision model was obtained, for the user to read.
enum class GeometrySource : uint8_t {
  kCollision,  ///< the URDF's <collision> shapes (plus the arm config's attached shapes)
  kVisual,     ///< the URDF has no <collision> shape: its <visual> shapes are used (a warning)
  kCapsules,   ///< neither: capsules of radius fallback_radius_m between joint origins (a warning)
};
std::string_view ToString(GeometrySource source);

struct RobotGeometryOptions {
  /// Radius of the fallback capsules when the URDF has neither collision nor visual shapes.
  double fallback_radius_m = 0.05;
  /// Largest sphere radius the sphere cover may use along a cylinder or a box's long side
  /// (smaller = tighter cover, more spheres).
  double sphere_spacing_m = 0.03;
};

/// The robot's collision model: its bodies, their spheres, the allowed-collision list, and the
/// bound on how far the robot's points move for a joint step.
///
/// Built from the URDF's collision geometry (boxes, cylinders, spheres, meshes read with assimp)
/// plus the arm config's `collision.attached` shapes on the tip link. The allowed-collision list is
/// computed once here: same link, adjacent links, in contact at the home pose, in contact in
/// more than 95 % of 1000 random states (seeded: the same list on every machine). Copies share
/// the immutable data; every method is const and thread-safe.
class RobotGeometry {
 public:
  /// Errors: InvalidArgument naming the link, the shape and the bad size (zero or negative
  /// sizes, a zero mesh scale), NotFound naming a mesh file that is not there, InvalidArgument
  /// for a "package://" mesh (resolve it to a path first) or a mesh assimp cannot read. A URDF
  /// without <collision> shapes falls back to its <visual> shapes, or to capsules between the
  /// joint origins, with a warning in warnings() (never a silent no-check).
  static Result<RobotGeometry> Create(const robot::ArmModel& arm,
                                      const RobotGeometryOptions& options = {});

  const robot::ArmModel& arm() const;
  const std::vector<RobotBody>& bodies() const;
  GeometrySource source() const;
  /// What a user should know about the model (fallbacks), one sentence each.
  const std::vector<std::string>& warnings() const;
  /// Body pairs (a < b) checked for self-collision, and the ones allowed (not checked).
  const std::vector<std::pair<int, int>>& self_check_pairs() const;
  const std::vector<AllowedPair>& allowed_pairs() const;

  /// X_WL of every link (ArmModel::LinkPoses); a body's pose is links[body.link] · body.X_LG.
  std::vector<Eigen::Isometry3d> LinkPoses(const Eigen::VectorXd& q) const;
  /// X_WG of every body's geometry.
  std::vector<Eigen::Isometry3d> BodyPoses(const Eigen::VectorXd& q) const;

  /// An upper bound (metres) on how far any point of any body moves along the straight joint
  /// segment q → q + dq: Σᵢ Rᵢ |dqᵢ|, Rᵢ the largest distance from joint i's axis to a point
  /// distal to it (revolute), 1 for prismatic joints.
  double MaxDisplacement(const Eigen::VectorXd& dq) const;
  /// Rᵢ of MaxDisplacement, per joint.
  const Eigen::VectorXd& lever_arms() const;

  /// The first self-colliding checked pair at q (bodies within `margin_m` of each other), or
  /// (−1, −1) when there is none.
  std::pair<int, int> SelfCollision(const Eigen::VectorXd& q, double margin_m = 0.0) const;

  struct Impl;

 private:
  explicit RobotGeometry(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
  std::shared_ptr<const Impl> impl_;
};

/// Whether the bounding spheres of bodies `a` and `b` (their links posed at X_WLa, X_WLb) come
/// within `margin_m`: when not, the bodies cannot either.
bool BoundsWithin(const RobotBody& a, const Eigen::Isometry3d& X_WLa, const RobotBody& b,
                  const Eigen::Isometry3d& X_WLb, double margin_m);

/// Whether two FCL objects, posed at X_A and X_B, are within `margin_m` of each other (in
/// contact when 0). FCL's narrow phase can throw on touching contacts (fcl#319, #390): a throw
/// counts as a contact.
bool WithinDistance(const fcl::CollisionGeometry<double>& a, const Eigen::Isometry3d& X_A,
                    const fcl::CollisionGeometry<double>& b, const Eigen::Isometry3d& X_B,
                    double margin_m);

/// FCL's geometry of a shape, in the shape's own frame: primitives centred as URDF centres them,
/// a mesh (loaded with assimp, its vertices scaled) as a BVHModel<OBBRSS>, a plane as the
/// fcl::Halfspace z <= 0. Errors (the shape's Validate, a missing or unreadable mesh file, a
/// "package://" name) name `what` and the shape.
Result<std::shared_ptr<const fcl::CollisionGeometry<double>>> MakeFclGeometry(
    const robot::CollisionShape& shape, std::string_view what);

}  // namespace avp::motion

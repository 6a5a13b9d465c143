#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/status.h>
#include <avp/core/transform.h>

namespace avp::robot {

/// The kind of a collision shape. Boxes, cylinders and spheres are centred on their frame;
/// a cylinder's axis is its frame's z; a plane is the solid half-space z <= 0 of its frame.
enum class ShapeKind : uint8_t { kBox, kCylinder, kSphere, kMesh, kPlane };
std::string_view ToString(ShapeKind kind);

/// One collision (or visual) shape: of a link (URDF), fixed to the tip link (the camera's body in
/// the arm config), or fixed in the world (a table, a wall, the ground: the arm config's
/// collision.world).
struct CollisionShape {
  std::string name;
  ShapeKind kind = ShapeKind::kBox;
  /// kBox: edge lengths (x, y, z); kCylinder: (radius, radius, length); kSphere: (radius, radius,
  /// radius); kMesh: the scale per axis; kPlane: unused. Metres.
  Eigen::Vector3d size = Eigen::Vector3d::Zero();
  /// kMesh: the mesh file (any format assimp reads), resolved against the URDF's folder.
  std::filesystem::path mesh;
  /// Pose of the shape in its parent frame (link, tip link or world).
  RigidTransform X_PS;

  static CollisionShape Box(std::string name, const Eigen::Vector3d& size, const RigidTransform& X);
  static CollisionShape Cylinder(std::string name, double radius, double length,
                                 const RigidTransform& X);
  static CollisionShape Sphere(std::string name, double radius, const RigidTransform& X);
  /// The half-space below the x-y plane of X (its z <= 0) is solid.
  static CollisionShape Plane(std::string name, const RigidTransform& X);

  /// OK, or InvalidArgument naming `what`, the shape and the bad size (every size finite and
  /// > 0; a mesh with a file and a finite, non-zero scale).
  Status Validate(std::string_view what) const;
};

/// Collision geometry the URDF does not carry, from the arm config's `collision:` section.
struct CollisionConfig {
  /// Shapes fixed to the tip link (the camera's body, its bracket), poses in the tip frame F.
  std::vector<CollisionShape> attached;
  /// Fixed obstacles in the world frame W: the ground or table the arm stands on, a wall, posts.
  std::vector<CollisionShape> world;
};

/// Settings of the inverse-kinematics solver (KDL ChainIkSolverPos_LMA with random restarts).
struct IkOptions {
  /// Random restarts after the attempt from the seed; each restart starts from joints drawn
  /// uniformly within the limits. 0 = the seed only.
  int max_restarts = 20;
  /// A solution is accepted when the flange (or camera) is within these of the target.
  double position_tolerance_m = 1e-4;
  double orientation_tolerance_rad = 1e-3;
  /// Levenberg-Marquardt iterations per attempt.
  int max_iterations = 50;
  /// Seed of the generator IsReachable() uses, so that the check is a pure function of the pose.
  uint64_t reachability_seed = 0;

  /// OK, or InvalidArgument naming every bad field and its value.
  Status Validate() const;
};

/// Replaces the URDF limits of one joint. Units: radians (revolute, continuous) or metres
/// (prismatic). A continuous joint with an override becomes a limited one.
struct JointLimitOverride {
  std::string joint;
  double lower = 0.0;
  double upper = 0.0;
};

/// Where the camera's optical frame C (REP-103: x right, y down, z forward) sits on the tip link F.
struct CameraMount {
  std::string frame_name = "camera_color_optical_frame";
  /// Pose of the optical frame in the tip (flange) frame.
  RigidTransform X_FC = DefaultX_FC();

  /// The ReBeL + D435 mount: optical z = flange x (the approach axis), optical x = −flange y,
  /// optical y = −flange z, optical origin at (0.03, 0, 0.06) m in the flange frame.
  static RigidTransform DefaultX_FC();
};

/// Maps a joint vector of another system's convention (the reference system, AIRLab-POLIMI
/// active-vision) to this arm's URDF convention, joint by joint:
///   q_urdf[i] = sign[i] * q_other[i] + offset_rad[i].
/// Empty vectors mean the identity map.
struct JointConvention {
  std::vector<double> sign;        ///< +1 or −1 per joint
  std::vector<double> offset_rad;  ///< radians (metres for prismatic joints)

  bool IsIdentity() const { return sign.empty() && offset_rad.empty(); }
};

/// Everything that defines an arm: a URDF, the chain in it, limits, the camera mount and IK
/// settings. Another arm is another URDF plus another one of these.
struct ArmConfig {
  /// The URDF file. ArmConfig::LoadYaml resolves a relative path against the YAML file's folder.
  std::filesystem::path urdf_path;
  /// The chain runs from base_link (the world frame W of avp) to tip_link (frame F).
  std::string base_link = "base_link";
  std::string tip_link = "flange";
  std::vector<JointLimitOverride> joint_limit_overrides;
  /// Where SimArm starts and the default IK seed (radians / metres, URDF convention). Empty: all
  /// zeros clamped into the limits.
  std::vector<double> home_joints;
  CameraMount camera_mount;
  IkOptions ik;
  /// The reference system's joint convention relative to this URDF (see JointConvention).
  JointConvention reference_convention;
  /// Collision geometry beyond the URDF's (key `collision`; see docs/motion.md).
  CollisionConfig collision;
  /// Acceleration limit of every joint (rad/s², m/s² for prismatic joints); the URDF has none.
  /// The ReBeL's: 5.24 rad/s² (300 °/s², igus). Key `joint_acceleration_limit`.
  double joint_acceleration_limit = 5.24;

  /// Checks the fields that need no URDF (names non-empty, finite numbers, lower < upper, signs
  /// ±1, equal vector lengths, IK options). Names, joint counts and limits against the URDF are
  /// checked by ArmModel::Create. Reports every bad field at once:
  ///   "invalid arm config: tip_link ('') must not be empty; ik.max_restarts (-1) must be >= 0"
  Status Validate() const;

  /// Reads an arm YAML (see configs/arms/igus_rebel_d435.yaml for every key). Errors: NotFound
  /// when the YAML or the URDF it names is missing (naming the path), ParseError / InvalidArgument
  /// naming the file, the key and the bad value (unknown keys are rejected).
  static Result<ArmConfig> LoadYaml(const std::filesystem::path& path);
};

}  // namespace avp::robot

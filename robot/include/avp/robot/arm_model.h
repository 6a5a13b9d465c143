#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/robot/arm_config.h>

namespace avp::robot {

enum class JointType {
  kRevolute,    ///< radians, finite limits
  kContinuous,  ///< radians, no limits (lower = −inf, upper = +inf)
  kPrismatic,   ///< metres, finite limits
};

std::string_view ToString(JointType type);

/// One movable joint of the chain, limits after the config's overrides.
struct JointInfo {
  std::string name;
  JointType type = JointType::kRevolute;
  double lower = 0.0;           ///< radians or metres
  double upper = 0.0;           ///< radians or metres
  double velocity_limit = 0.0;  ///< rad/s or m/s, from the URDF (0 when not given)
};

/// One link of the chain (base_link, the child of every joint from there to the tip, and links
/// fixed to those by fixed joints elsewhere in the tree), with its URDF geometry.
struct LinkInfo {
  std::string name;
  /// The movable joint whose moving frame this link is fixed to (an index into joints()); −1 for
  /// links fixed to the base.
  int joint = -1;
  /// The link's frame in that joint's frame (after the joint's motion; in the base for −1).
  Eigen::Isometry3d X_JL = Eigen::Isometry3d::Identity();
  /// The URDF's <collision> and <visual> shapes, poses in the link frame; mesh files resolved
  /// against the URDF's folder ("package://" names are kept as written).
  std::vector<CollisionShape> collision;
  std::vector<CollisionShape> visual;
};

/// Outcome of one inverse-kinematics query.
struct IkResult {
  /// OK, or Unreachable with a message naming the target and the best residual reached.
  Status status;
  /// The solution (within the limits) when OK; otherwise the best attempt, which may violate the
  /// limits or miss the target.
  Eigen::VectorXd q;
  /// Levenberg-Marquardt iterations summed over all attempts.
  int iterations = 0;
  /// Random restarts used: 0 when the attempt from the seed succeeded.
  int restarts = 0;
  /// Residual of `q` against the target: distance in metres and rotation angle in radians.
  double position_error_m = 0.0;
  double orientation_error_rad = 0.0;

  bool ok() const { return status.ok(); }
};

/// The kinematic model of a serial arm, built from a URDF with urdfdom and KDL: the chain from
/// the base link (world W) to the tip link (flange F) with fixed joints folded in, joint limits,
/// forward kinematics, inverse kinematics with random restarts, and the camera mount (frame C).
///
/// Joint vectors are Eigen::VectorXd of size num_joints() in URDF order, radians (metres for
/// prismatic joints), URDF convention. Copies are cheap (the chain is shared, immutable), and
/// every method is const and safe to call from several threads at once.
class ArmModel {
 public:
  /// Loads config.urdf_path and builds the chain. NotFound if the file is missing; ParseError if
  /// urdfdom rejects it; NotFound naming an unknown base/tip link or overridden joint (with the
  /// names that exist); InvalidArgument for a bad config or a chain urdfdom/KDL cannot express
  /// (floating or planar joints, mimic joints, no movable joint).
  static Result<ArmModel> Create(const ArmConfig& config);
  /// As Create, from URDF text; config.urdf_path is used in messages only.
  static Result<ArmModel> FromUrdfString(std::string_view urdf_xml, const ArmConfig& config);

  int num_joints() const;
  const std::vector<std::string>& joint_names() const;
  const std::vector<JointInfo>& joints() const;
  /// Limits per joint; ±infinity for continuous joints.
  const Eigen::VectorXd& lower_limits() const;
  const Eigen::VectorXd& upper_limits() const;
  /// The config's home joints (or zeros clamped into the limits).
  const Eigen::VectorXd& home_joints() const;
  const ArmConfig& config() const;
  const std::string& base_link() const;
  const std::string& tip_link() const;
  /// Pose of the camera optical frame in the tip frame.
  const RigidTransform& X_FC() const;
  /// An upper bound on the distance from the first joint's origin to the tip (metres); targets
  /// farther away are rejected without running the solver.
  double max_reach_m() const;

  /// True when q has num_joints() finite entries, each within its limits (± tolerance).
  bool WithinLimits(const Eigen::VectorXd& q, double tolerance = 1e-9) const;
  /// OK, InvalidArgument (wrong size, NaN or infinite entry) or OutOfRange naming the first bad
  /// joint, its value in radians and degrees, and its limits.
  Status CheckJoints(const Eigen::VectorXd& q) const;
  /// q with every entry clamped into its limits. @pre q.size() == num_joints(), entries finite.
  Eigen::VectorXd ClampToLimits(const Eigen::VectorXd& q) const;
  /// Joints drawn uniformly within the limits (continuous joints within [−π, π]).
  Eigen::VectorXd RandomJoints(Rng& rng) const;

  /// The chain's links, base first, in tree order (see LinkInfo).
  const std::vector<LinkInfo>& links() const;
  /// The index of the link named `name` in links(), or −1.
  int LinkIndex(std::string_view name) const;
  /// X_WJ of every movable joint's frame after its motion (joint i's pose is X_WJ[i]); a link's
  /// pose is X_WJ[link.joint] · link.X_JL (the base frame for joint −1).
  /// @throws avp::Error if q has the wrong size or a non-finite entry.
  std::vector<Eigen::Isometry3d> JointFrames(const Eigen::VectorXd& q) const;
  /// X_WL of every link in links() order, from JointFrames.
  std::vector<Eigen::Isometry3d> LinkPoses(const Eigen::VectorXd& q) const;
  /// Index of the tip link in links().
  int tip_link_index() const;

  /// X_WF, the tip (flange) pose in the base frame.
  /// @throws avp::Error if q has the wrong size or a non-finite entry (limits are not checked).
  RigidTransform ForwardKinematics(const Eigen::VectorXd& q) const;
  /// X_WC = X_WF · X_FC, the camera optical frame in the base frame. Same preconditions.
  RigidTransform CameraPose(const Eigen::VectorXd& q) const;

  /// Joints that put the tip at X_WF, within the limits. Tries `q_seed` (clamped into the limits)
  /// first, then up to options.max_restarts random starts drawn from `rng`; revolute angles are
  /// wrapped by multiples of 2π into the limits (continuous ones to the value nearest the seed).
  /// Deterministic given the state of `rng`; `rng` is only advanced when a restart is needed.
  /// Targets beyond max_reach_m() fail at once. Expected failures are statuses (Unreachable).
  /// @throws avp::Error if q_seed has the wrong size or a non-finite entry.
  IkResult SolveIk(const RigidTransform& X_WF, const Eigen::VectorXd& q_seed, Rng& rng) const;
  IkResult SolveIk(const RigidTransform& X_WF, const Eigen::VectorXd& q_seed, Rng& rng,
                   const IkOptions& options) const;
  /// Joints that put the camera optical frame at X_WC (solves for X_WF = X_WC · X_FC⁻¹; the
  /// residuals are those of the flange, which equal the camera's in orientation).
  IkResult SolveCameraIk(const RigidTransform& X_WC, const Eigen::VectorXd& q_seed, Rng& rng) const;
  IkResult SolveCameraIk(const RigidTransform& X_WC, const Eigen::VectorXd& q_seed, Rng& rng,
                         const IkOptions& options) const;
  /// Whether SolveCameraIk succeeds from the home joints with a generator seeded from
  /// config().ik.reachability_seed: a pure function of X_WC.
  bool IsReachable(const RigidTransform& X_WC) const;

  /// Converts a joint vector of the reference system's convention (config().reference_convention)
  /// to this URDF's: q_urdf = sign ∘ q_ref + offset. @pre size num_joints(), finite.
  Eigen::VectorXd FromReferenceJoints(const Eigen::VectorXd& q_ref) const;
  /// The inverse of FromReferenceJoints.
  Eigen::VectorXd ToReferenceJoints(const Eigen::VectorXd& q_urdf) const;

  struct Impl;  // defined in arm_model.cpp

 private:
  explicit ArmModel(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
  std::shared_ptr<const Impl> impl_;  // immutable after construction; shared between copies
};

/// Loads an arm YAML (ArmConfig::LoadYaml) and builds its model; errors carry the YAML path.
Result<ArmModel> LoadArm(const std::filesystem::path& arm_yaml);

/// Loads `<config_dir>/arms/igus_rebel_d435.yaml`. With an empty `config_dir`: the environment
/// variable AVP_CONFIG_DIR if set, else the source tree's configs/ folder compiled into the
/// library.
Result<ArmModel> LoadDefaultArm(const std::filesystem::path& config_dir = {});

/// The config folder LoadDefaultArm uses when given none (see there).
std::filesystem::path DefaultConfigDir();

}  // namespace avp::robot

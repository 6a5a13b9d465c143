#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <console_bridge/console.h>
#include <fmt/format.h>
#include <fmt/ostream.h>
#include <kdl/chain.hpp>
#include <kdl/chainiksolverpos_lma.hpp>
#include <kdl/frames.hpp>
#include <kdl/jntarray.hpp>
#include <kdl/joint.hpp>
#include <kdl/segment.hpp>
#include <urdf_model/model.h>
#include <urdf_parser/urdf_parser.h>

#include <avp/core/error.h>
#include <avp/robot/arm_model.h>

namespace avp::robot {

namespace {

/// Degrees for a message: three decimals, or six significant digits past a million (a huge angle
/// is not echoed as a 300-digit number).
std::string DegreesText(double deg) {
  return std::abs(deg) < 1e6 ? fmt::format("{:.3f}", deg) : fmt::format("{:.6g}", deg);
}

constexpr double kTwoPi = 2.0 * EIGEN_PI;

// urdfdom reports parse errors through console_bridge (to stderr by default). While parsing, this
// handler collects them so that they end up in the returned Status instead. console_bridge's
// handler is process-global, hence the mutex.
class CollectingOutputHandler : public console_bridge::OutputHandler {
 public:
  void log(const std::string& text, console_bridge::LogLevel level, const char* /*filename*/,
           int /*line*/) override {
    if (level >= console_bridge::CONSOLE_BRIDGE_LOG_WARN) messages.push_back(text);
  }
  std::vector<std::string> messages;
};

std::mutex& UrdfParseMutex() {
  static std::mutex mutex;
  return mutex;
}

Eigen::Isometry3d ToIsometry(const urdf::Pose& pose) {
  double x = 0.0, y = 0.0, z = 0.0, w = 1.0;
  pose.rotation.getQuaternion(x, y, z, w);
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::Quaterniond(w, x, y, z).normalized().toRotationMatrix();
  X.translation() = Eigen::Vector3d(pose.position.x, pose.position.y, pose.position.z);
  return X;
}

KDL::Frame ToKdl(const Eigen::Isometry3d& X) {
  const Eigen::Matrix3d& R = X.linear();
  return KDL::Frame(KDL::Rotation(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0),
                                  R(2, 1), R(2, 2)),
                    KDL::Vector(X.translation().x(), X.translation().y(), X.translation().z()));
}

KDL::Vector ToKdl(const Eigen::Vector3d& v) { return KDL::Vector(v.x(), v.y(), v.z()); }

std::string JoinNames(const std::vector<std::string>& names) {
  std::vector<std::string> sorted = names;
  std::sort(sorted.begin(), sorted.end());
  return fmt::format("{}", fmt::join(sorted, ", "));
}

std::string FormatJointsDeg(const Eigen::VectorXd& q) {
  std::vector<std::string> parts;
  for (int i = 0; i < q.size(); ++i) parts.push_back(fmt::format("{:.2f}", RadToDeg(q[i])));
  return fmt::format("[{}] deg", fmt::join(parts, ", "));
}

RigidTransform FromIsometry(const Eigen::Isometry3d& X) {
  return RigidTransform(X.linear(), X.translation());
}

Eigen::Isometry3d ToIso(const RigidTransform& X) { return X.ToIsometry(); }

double RotationAngle(const Eigen::Matrix3d& R_a, const Eigen::Matrix3d& R_b) {
  // As RigidTransform::AngleTo: atan2 keeps full precision near 0, where acos does not.
  const Eigen::Matrix3d R = R_a.transpose() * R_b;
  const Eigen::Vector3d two_sin_axis(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));
  return std::atan2(0.5 * two_sin_axis.norm(), 0.5 * (R.trace() - 1.0));
}

}  // namespace

std::string_view ToString(JointType type) {
  switch (type) {
    case JointType::kRevolute:
      return "revolute";
    case JointType::kContinuous:
      return "continuous";
    case JointType::kPrismatic:
      return "prismatic";
  }
  return "unknown";
}

// ---- Impl ---------------------------------------------------------------------------------------

struct ArmModel::Impl {
  ArmConfig config;
  std::vector<JointInfo> joints;
  std::vector<std::string> names;
  Eigen::VectorXd lower;
  Eigen::VectorXd upper;
  Eigen::VectorXd home;
  // Kinematics with fixed joints folded in: for movable joint i, X_origin[i] is the pose of its
  // frame (at q_i = 0) in the frame of joint i − 1 after its motion (the base for i = 0), and
  // axis[i] its unit axis in its own frame. X_last_tip is the tip in the last joint's frame.
  std::vector<Eigen::Isometry3d> X_origin;
  std::vector<Eigen::Vector3d> axis;
  Eigen::Isometry3d X_last_tip = Eigen::Isometry3d::Identity();
  RigidTransform X_FC;
  double max_reach_m = 0.0;
  // A sharper reach test (see ComputeReachBounds): the origin of joint `fixed_joint` is fixed in
  // the base, that of joint `wrist_joint` follows from the tip pose alone, and the links between
  // them span at most `wrist_reach_m`. Unused when wrist_joint <= fixed_joint.
  int fixed_joint = 0;
  int wrist_joint = 0;
  Eigen::Vector3d p_fixed = Eigen::Vector3d::Zero();
  Eigen::Vector3d p_wrist_in_tip = Eigen::Vector3d::Zero();
  double wrist_reach_m = 0.0;
  // The chain's links (LinkInfo) and the tip link's index among them.
  std::vector<LinkInfo> links;
  int tip_link = 0;
  // The same chain for KDL's solvers. KDL::Joint caches its last pose in mutable members, so every
  // solve works on its own copy of this chain.
  KDL::Chain chain;

  /// The last joint's frame after its motion; with `frames`, every joint's.
  Eigen::Isometry3d JointFrames(const Eigen::VectorXd& q,
                                std::vector<Eigen::Isometry3d>* frames) const {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    for (size_t i = 0; i < X_origin.size(); ++i) {
      X = X * X_origin[i];
      if (joints[i].type == JointType::kPrismatic) {
        X.translation() += X.linear() * (axis[i] * q[static_cast<Eigen::Index>(i)]);
      } else {
        X.linear() = X.linear() *
                     Eigen::AngleAxisd(q[static_cast<Eigen::Index>(i)], axis[i]).toRotationMatrix();
      }
      if (frames != nullptr) frames->push_back(X);
    }
    return X;
  }

  Eigen::Isometry3d Fk(const Eigen::VectorXd& q) const {
    return JointFrames(q, nullptr) * X_last_tip;
  }

  bool IsRotational(int i) const {
    return joints[static_cast<size_t>(i)].type != JointType::kPrismatic;
  }

  // Points whose position does not depend on all joints give a cheap necessary condition for
  // reachability, which spares the solver's restarts on far targets:
  // - Joint 0's origin is fixed; so is joint 1's if its offset from joint 0 lies along joint 0's
  //   (rotational) axis. For the ReBeL: joint2 at (0, 0, 0.249).
  // - The last joint's origin follows from the tip pose (X_tip · X_last_tip⁻¹); if that joint is
  //   rotational and its offset from the joint before lies along its axis, that joint's origin
  //   does too. For the ReBeL: joint5, 0.122 m behind the flange along the flange x axis.
  // Between the two, the links can at most stretch out in a line.
  void ComputeReachBounds() {
    const int n = static_cast<int>(joints.size());
    auto parallel = [](const Eigen::Vector3d& t, const Eigen::Vector3d& direction) {
      return t.cross(direction).norm() <= 1e-9 * std::max(t.norm(), 1.0);
    };
    fixed_joint = 0;
    Eigen::Isometry3d X_fixed = X_origin[0];
    if (n > 1 && IsRotational(0) && parallel(X_origin[1].translation(), axis[0])) {
      fixed_joint = 1;
      X_fixed = X_fixed * X_origin[1];
    }
    p_fixed = X_fixed.translation();

    // Last joint's frame (after its motion) in the tip frame, and its origin.
    const Eigen::Isometry3d X_tip_last = X_last_tip.inverse();
    wrist_joint = n - 1;
    p_wrist_in_tip = X_tip_last.translation();
    const auto last = static_cast<size_t>(n - 1);
    const Eigen::Vector3d t_last_in_last =
        X_origin[last].linear().transpose() * X_origin[last].translation();
    if (n - 1 > fixed_joint && IsRotational(n - 1) && parallel(t_last_in_last, axis[last])) {
      wrist_joint = n - 2;
      p_wrist_in_tip = X_tip_last * (-t_last_in_last);
    }
    wrist_reach_m = 0.0;
    for (int i = fixed_joint + 1; i <= wrist_joint; ++i) {
      wrist_reach_m += X_origin[static_cast<size_t>(i)].translation().norm();
    }
    for (int i = fixed_joint; i <= wrist_joint; ++i) {
      if (!IsRotational(i)) wrist_reach_m += std::max(std::abs(lower[i]), std::abs(upper[i]));
    }
  }
};

// ---- Construction stages (FromUrdfString) -------------------------------------------------------

namespace {

/// The URDF parsed by urdfdom; ParseError with urdfdom's messages when it rejects the text.
Result<urdf::ModelInterfaceSharedPtr> ParsedUrdf(std::string_view urdf_xml,
                                                 const std::string& where) {
  urdf::ModelInterfaceSharedPtr urdf_model;
  std::vector<std::string> parse_messages;
  {
    std::lock_guard<std::mutex> lock(UrdfParseMutex());
    CollectingOutputHandler handler;
    console_bridge::useOutputHandler(&handler);
    try {
      urdf_model = urdf::parseURDF(std::string(urdf_xml));
    } catch (const std::exception& e) {
      handler.messages.push_back(e.what());
      urdf_model = nullptr;
    }
    console_bridge::restorePreviousOutputHandler();
    parse_messages = std::move(handler.messages);
  }
  if (!urdf_model) {
    return ParseError(fmt::format("{} could not be parsed: {}", where,
                                  parse_messages.empty()
                                      ? std::string("(no details)")
                                      : fmt::format("{}", fmt::join(parse_messages, "; "))));
  }
  return urdf_model;
}

/// The joints from config.base_link down to config.tip_link, base first (fixed ones included).
Result<std::vector<urdf::JointConstSharedPtr>> JointsFromBaseToTip(
    const urdf::ModelInterface& urdf_model, const ArmConfig& config, const std::string& where) {
  std::vector<std::string> link_names;
  for (const auto& [name, link] : urdf_model.links_) link_names.push_back(name);
  for (const std::string* link : {&config.base_link, &config.tip_link}) {
    if (!urdf_model.getLink(*link)) {
      return NotFoundError(fmt::format("{}: unknown link '{}' ({} is '{}'; links: {})", where,
                                       *link, link == &config.base_link ? "base_link" : "tip_link",
                                       *link, JoinNames(link_names)));
    }
  }

  // Walk from the tip up to the base.
  std::vector<urdf::JointConstSharedPtr> path;
  for (urdf::LinkConstSharedPtr link = urdf_model.getLink(config.tip_link);
       link->name != config.base_link;) {
    if (!link->parent_joint) {
      return InvalidArgumentError(
          fmt::format("{}: tip_link '{}' is not below base_link '{}' (the tree's root is '{}')",
                      where, config.tip_link, config.base_link, link->name));
    }
    path.push_back(link->parent_joint);
    link = urdf_model.getLink(link->parent_joint->parent_link_name);
  }
  std::reverse(path.begin(), path.end());
  return path;
}

/// Name, type and URDF limits of a movable (non-fixed) joint; InvalidArgument for a joint a
/// serial chain cannot use (unsupported type, mimic, zero axis, missing <limit>).
Result<JointInfo> MovableJointInfo(const urdf::Joint& joint, const std::string& where) {
  JointInfo info;
  info.name = joint.name;
  switch (joint.type) {
    case urdf::Joint::REVOLUTE:
      info.type = JointType::kRevolute;
      break;
    case urdf::Joint::CONTINUOUS:
      info.type = JointType::kContinuous;
      break;
    case urdf::Joint::PRISMATIC:
      info.type = JointType::kPrismatic;
      break;
    default:
      return InvalidArgumentError(fmt::format(
          "{}: joint '{}' has an unsupported type (code {}); serial chains may use revolute, "
          "continuous, prismatic and fixed joints",
          where, joint.name, static_cast<int>(joint.type)));
  }
  if (joint.mimic) {
    return InvalidArgumentError(
        fmt::format("{}: joint '{}' mimics '{}'; mimic joints are not supported", where, joint.name,
                    joint.mimic->joint_name));
  }
  const Eigen::Vector3d axis(joint.axis.x, joint.axis.y, joint.axis.z);
  if (!(axis.norm() > 1e-9)) {
    return InvalidArgumentError(fmt::format("{}: joint '{}' has a zero axis", where, joint.name));
  }
  if (info.type == JointType::kContinuous) {
    info.lower = -std::numeric_limits<double>::infinity();
    info.upper = std::numeric_limits<double>::infinity();
  } else {
    if (!joint.limits) {
      return InvalidArgumentError(
          fmt::format("{}: {} joint '{}' has no <limit>", where, ToString(info.type), joint.name));
    }
    info.lower = joint.limits->lower;
    info.upper = joint.limits->upper;
  }
  if (joint.limits) info.velocity_limit = joint.limits->velocity;
  return info;
}

/// impl.joints, X_origin, axis and X_last_tip from the URDF path, fixed joints folded into the
/// next movable joint's origin (or into the tip).
Status AppendMovableJoints(const std::vector<urdf::JointConstSharedPtr>& path,
                           const std::string& where, ArmModel::Impl& impl) {
  Eigen::Isometry3d pending = Eigen::Isometry3d::Identity();
  for (const urdf::JointConstSharedPtr& joint : path) {
    const Eigen::Isometry3d X_parent_joint = ToIsometry(joint->parent_to_joint_origin_transform);
    if (joint->type == urdf::Joint::FIXED) {
      pending = pending * X_parent_joint;
      continue;
    }
    AVP_ASSIGN_OR_RETURN(const JointInfo info, MovableJointInfo(*joint, where));
    impl.joints.push_back(info);
    impl.X_origin.push_back(pending * X_parent_joint);
    impl.axis.push_back(Eigen::Vector3d(joint->axis.x, joint->axis.y, joint->axis.z).normalized());
    pending = Eigen::Isometry3d::Identity();
  }
  impl.X_last_tip = pending;
  if (impl.joints.empty()) {
    return InvalidArgumentError(fmt::format("{}: the chain from '{}' to '{}' has no movable joint",
                                            where, impl.config.base_link, impl.config.tip_link));
  }
  return Status::Ok();
}

/// A URDF <collision> or <visual> geometry as a CollisionShape (mesh files resolved against
/// `folder`; "package://" names kept as written).
CollisionShape ShapeOf(const urdf::Geometry& geometry, const urdf::Pose& origin,
                       const std::string& name, const std::filesystem::path& folder) {
  CollisionShape shape;
  shape.name = name;
  shape.X_PS = FromIsometry(ToIsometry(origin));
  switch (geometry.type) {
    case urdf::Geometry::BOX: {
      const auto& box = static_cast<const urdf::Box&>(geometry);
      shape.kind = ShapeKind::kBox;
      shape.size = Eigen::Vector3d(box.dim.x, box.dim.y, box.dim.z);
      break;
    }
    case urdf::Geometry::CYLINDER: {
      const auto& c = static_cast<const urdf::Cylinder&>(geometry);
      shape.kind = ShapeKind::kCylinder;
      shape.size = Eigen::Vector3d(c.radius, c.radius, c.length);
      break;
    }
    case urdf::Geometry::SPHERE: {
      const auto& sp = static_cast<const urdf::Sphere&>(geometry);
      shape.kind = ShapeKind::kSphere;
      shape.size = Eigen::Vector3d::Constant(sp.radius);
      break;
    }
    case urdf::Geometry::MESH: {
      const auto& m = static_cast<const urdf::Mesh&>(geometry);
      shape.kind = ShapeKind::kMesh;
      shape.size = Eigen::Vector3d(m.scale.x, m.scale.y, m.scale.z);
      std::string file = m.filename;
      if (file.rfind("file://", 0) == 0) file = file.substr(7);
      shape.mesh = std::filesystem::path(file);
      if (file.find("://") == std::string::npos && shape.mesh.is_relative()) {
        shape.mesh = (folder / shape.mesh).lexically_normal();
      }
      break;
    }
  }
  return shape;
}

/// `link` as a LinkInfo fixed to joint `joint` at X_JL, with its URDF geometry.
LinkInfo MakeLinkInfo(const urdf::Link& link, int joint, const Eigen::Isometry3d& X_JL,
                      const std::filesystem::path& folder) {
  LinkInfo info{link.name, joint, X_JL, {}, {}};
  for (size_t i = 0; i < link.collision_array.size(); ++i) {
    const urdf::Collision& c = *link.collision_array[i];
    if (!c.geometry) continue;
    info.collision.push_back(ShapeOf(*c.geometry, c.origin,
                                     c.name.empty() ? fmt::format("{}#{}", link.name, i) : c.name,
                                     folder));
  }
  for (size_t i = 0; i < link.visual_array.size(); ++i) {
    const urdf::Visual& v = *link.visual_array[i];
    if (!v.geometry) continue;
    info.visual.push_back(ShapeOf(*v.geometry, v.origin,
                                  v.name.empty() ? fmt::format("{}#{}", link.name, i) : v.name,
                                  folder));
  }
  return info;
}

/// Appends `link` and, depth first, every link fixed to it by fixed joints that are not on the
/// chain's path (a camera's links, a gripper's body).
void AppendFixedSubtree(const urdf::ModelInterface& model, const urdf::Link& link, int joint,
                        const Eigen::Isometry3d& X_JL, const std::vector<std::string>& on_path,
                        const std::filesystem::path& folder, std::vector<LinkInfo>& out) {
  out.push_back(MakeLinkInfo(link, joint, X_JL, folder));
  for (const urdf::JointSharedPtr& child : link.child_joints) {
    if (child->type != urdf::Joint::FIXED) continue;
    if (std::find(on_path.begin(), on_path.end(), child->child_link_name) != on_path.end())
      continue;
    const urdf::LinkConstSharedPtr child_link = model.getLink(child->child_link_name);
    if (!child_link) continue;
    AppendFixedSubtree(model, *child_link, joint,
                       X_JL * ToIsometry(child->parent_to_joint_origin_transform), on_path, folder,
                       out);
  }
}

/// impl.links and impl.tip_link: base_link, then the child of every joint on the path, each with
/// the links fixed to it off the path.
void CollectLinks(const urdf::ModelInterface& model,
                  const std::vector<urdf::JointConstSharedPtr>& path, ArmModel::Impl& impl) {
  const std::filesystem::path folder = impl.config.urdf_path.parent_path();
  std::vector<std::string> on_path{impl.config.base_link};
  for (const urdf::JointConstSharedPtr& joint : path) on_path.push_back(joint->child_link_name);
  int joint_index = -1;
  Eigen::Isometry3d X_JL = Eigen::Isometry3d::Identity();
  AppendFixedSubtree(model, *model.getLink(impl.config.base_link), joint_index, X_JL, on_path,
                     folder, impl.links);
  for (const urdf::JointConstSharedPtr& joint : path) {
    if (joint->type == urdf::Joint::FIXED) {
      X_JL = X_JL * ToIsometry(joint->parent_to_joint_origin_transform);
    } else {
      ++joint_index;
      X_JL = Eigen::Isometry3d::Identity();
    }
    if (joint->child_link_name == impl.config.tip_link) {
      impl.tip_link = static_cast<int>(impl.links.size());
    }
    AppendFixedSubtree(model, *model.getLink(joint->child_link_name), joint_index, X_JL, on_path,
                       folder, impl.links);
  }
}

/// Applies config.joint_limit_overrides to `joints` (an overridden continuous joint becomes
/// revolute); NotFound naming the movable joints for an unknown one.
Status ApplyJointLimitOverrides(const ArmConfig& config, std::vector<JointInfo>& joints) {
  for (const JointLimitOverride& o : config.joint_limit_overrides) {
    auto it = std::find_if(joints.begin(), joints.end(),
                           [&](const JointInfo& j) { return j.name == o.joint; });
    if (it == joints.end()) {
      std::vector<std::string> names;
      for (const JointInfo& j : joints) names.push_back(j.name);
      return NotFoundError(fmt::format(
          "joint_limit_overrides: unknown joint '{}' (movable joints from '{}' to '{}': {})",
          o.joint, config.base_link, config.tip_link, fmt::join(names, ", ")));
    }
    if (it->type == JointType::kContinuous) it->type = JointType::kRevolute;
    it->lower = o.lower;
    it->upper = o.upper;
  }
  return Status::Ok();
}

/// impl.names, lower and upper from impl.joints; InvalidArgument for a lower limit above upper.
Status FillJointLimits(const std::string& where, ArmModel::Impl& impl) {
  const int n = static_cast<int>(impl.joints.size());
  impl.lower.resize(n);
  impl.upper.resize(n);
  for (int i = 0; i < n; ++i) {
    const JointInfo& j = impl.joints[static_cast<size_t>(i)];
    if (j.type != JointType::kContinuous && !(j.lower <= j.upper)) {
      return InvalidArgumentError(fmt::format("{}: joint '{}' has lower limit {} above upper {}",
                                              where, j.name, j.lower, j.upper));
    }
    impl.names.push_back(j.name);
    impl.lower[i] = j.lower;
    impl.upper[i] = j.upper;
  }
  return Status::Ok();
}

/// The config's home joints, or zeros clamped into the limits when it has none.
Result<Eigen::VectorXd> HomeJoints(const ArmConfig& config, const ArmModel::Impl& impl) {
  const int n = static_cast<int>(impl.joints.size());
  if (config.home_joints.empty()) {
    return Eigen::VectorXd(Eigen::VectorXd::Zero(n).cwiseMax(impl.lower).cwiseMin(impl.upper));
  }
  if (static_cast<int>(config.home_joints.size()) != n) {
    return InvalidArgumentError(fmt::format("home_joints has {} entries, the chain {} joints ({})",
                                            config.home_joints.size(), n,
                                            fmt::join(impl.names, ", ")));
  }
  return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(config.home_joints.data(), n));
}

/// KDL chain: one segment per movable joint; the trailing fixed transform is folded into the
/// last segment's tip.
KDL::Chain KdlChain(const ArmModel::Impl& impl) {
  KDL::Chain chain;
  const int n = static_cast<int>(impl.joints.size());
  for (int i = 0; i < n; ++i) {
    const auto si = static_cast<size_t>(i);
    const Eigen::Isometry3d& F = impl.X_origin[si];
    const Eigen::Vector3d axis_parent = F.linear() * impl.axis[si];
    const KDL::Joint::JointType kdl_type =
        impl.joints[si].type == JointType::kPrismatic ? KDL::Joint::TransAxis : KDL::Joint::RotAxis;
    const KDL::Joint kdl_joint(impl.names[si], ToKdl(Eigen::Vector3d(F.translation())),
                               ToKdl(axis_parent), kdl_type);
    const Eigen::Isometry3d f_tip = (i == n - 1) ? F * impl.X_last_tip : F;
    chain.addSegment(KDL::Segment(impl.names[si] + "_segment", kdl_joint, ToKdl(f_tip)));
  }
  return chain;
}

/// Reach bound (metres): the first joint's origin is fixed in the base; everything after it can at
/// most stretch out in a line.
double MaxReach(const ArmModel::Impl& impl) {
  double reach = impl.X_last_tip.translation().norm();
  const int n = static_cast<int>(impl.joints.size());
  for (int i = 0; i < n; ++i) {
    const auto si = static_cast<size_t>(i);
    if (i > 0) reach += impl.X_origin[si].translation().norm();
    if (impl.joints[si].type == JointType::kPrismatic) {
      reach += std::max(std::abs(impl.lower[i]), std::abs(impl.upper[i]));
    }
  }
  return reach;
}

}  // namespace

// ---- Construction -------------------------------------------------------------------------------

Result<ArmModel> ArmModel::Create(const ArmConfig& config) {
  std::ifstream in(config.urdf_path);
  if (!in) {
    return NotFoundError(fmt::format("cannot open URDF file '{}'", config.urdf_path.string()));
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  return FromUrdfString(buffer.str(), config);
}

Result<ArmModel> ArmModel::FromUrdfString(std::string_view urdf_xml, const ArmConfig& config) {
  AVP_RETURN_IF_ERROR(config.Validate());
  const std::string where = config.urdf_path.empty()
                                ? std::string("URDF")
                                : fmt::format("URDF '{}'", config.urdf_path.string());
  AVP_ASSIGN_OR_RETURN(const urdf::ModelInterfaceSharedPtr urdf_model, ParsedUrdf(urdf_xml, where));
  AVP_ASSIGN_OR_RETURN(const std::vector<urdf::JointConstSharedPtr> path,
                       JointsFromBaseToTip(*urdf_model, config, where));

  auto impl = std::make_shared<Impl>();
  impl->config = config;
  AVP_RETURN_IF_ERROR(AppendMovableJoints(path, where, *impl));
  CollectLinks(*urdf_model, path, *impl);
  AVP_RETURN_IF_ERROR(ApplyJointLimitOverrides(config, impl->joints));
  AVP_RETURN_IF_ERROR(FillJointLimits(where, *impl));
  AVP_ASSIGN_OR_RETURN(impl->home, HomeJoints(config, *impl));
  const int n = static_cast<int>(impl->joints.size());
  const JointConvention& rc = config.reference_convention;
  if (!rc.IsIdentity() && static_cast<int>(rc.sign.size()) != n) {
    return InvalidArgumentError(
        fmt::format("reference_convention has {} entries, the chain {} joints ({})", rc.sign.size(),
                    n, fmt::join(impl->names, ", ")));
  }
  impl->chain = KdlChain(*impl);
  impl->max_reach_m = MaxReach(*impl);
  impl->ComputeReachBounds();
  impl->X_FC = config.camera_mount.X_FC;

  ArmModel model(std::move(impl));
  if (const Status s = model.CheckJoints(model.home_joints()); !s.ok()) {
    return InvalidArgumentError(fmt::format("home_joints: {}", s.message()));
  }
  return model;
}

Result<ArmModel> LoadArm(const std::filesystem::path& arm_yaml) {
  AVP_ASSIGN_OR_RETURN(const ArmConfig config, ArmConfig::LoadYaml(arm_yaml));
  Result<ArmModel> model = ArmModel::Create(config);
  if (!model.ok()) return model.status().WithContext(arm_yaml.string());
  return model;
}

std::filesystem::path DefaultConfigDir() {
  if (const char* env = std::getenv("AVP_CONFIG_DIR"); env != nullptr && env[0] != '\0') {
    return std::filesystem::path(env);
  }
  return std::filesystem::path(AVP_DEFAULT_CONFIG_DIR);
}

Result<ArmModel> LoadDefaultArm(const std::filesystem::path& config_dir) {
  const std::filesystem::path dir = config_dir.empty() ? DefaultConfigDir() : config_dir;
  return LoadArm(dir / "arms" / "igus_rebel_d435.yaml");
}

// ---- Accessors ----------------------------------------------------------------------------------

int ArmModel::num_joints() const { return static_cast<int>(impl_->joints.size()); }
const std::vector<std::string>& ArmModel::joint_names() const { return impl_->names; }
const std::vector<JointInfo>& ArmModel::joints() const { return impl_->joints; }
const Eigen::VectorXd& ArmModel::lower_limits() const { return impl_->lower; }
const Eigen::VectorXd& ArmModel::upper_limits() const { return impl_->upper; }
const Eigen::VectorXd& ArmModel::home_joints() const { return impl_->home; }
const ArmConfig& ArmModel::config() const { return impl_->config; }
const std::string& ArmModel::base_link() const { return impl_->config.base_link; }
const std::string& ArmModel::tip_link() const { return impl_->config.tip_link; }
const RigidTransform& ArmModel::X_FC() const { return impl_->X_FC; }
double ArmModel::max_reach_m() const { return impl_->max_reach_m; }

// ---- Limits -------------------------------------------------------------------------------------

bool ArmModel::WithinLimits(const Eigen::VectorXd& q, double tolerance) const {
  if (q.size() != num_joints() || !q.allFinite()) return false;
  for (int i = 0; i < q.size(); ++i) {
    if (q[i] < impl_->lower[i] - tolerance || q[i] > impl_->upper[i] + tolerance) return false;
  }
  return true;
}

Status ArmModel::CheckJoints(const Eigen::VectorXd& q) const {
  if (q.size() != num_joints()) {
    return InvalidArgumentError(fmt::format("joint vector has {} entries, the arm {} ({})",
                                            q.size(), num_joints(), fmt::join(impl_->names, ", ")));
  }
  for (int i = 0; i < q.size(); ++i) {
    const auto si = static_cast<size_t>(i);
    if (!std::isfinite(q[i])) {
      return InvalidArgumentError(
          fmt::format("joint '{}' (index {}) is {}", impl_->names[si], i, q[i]));
    }
  }
  for (int i = 0; i < q.size(); ++i) {
    const auto si = static_cast<size_t>(i);
    if (q[i] < impl_->lower[i] - 1e-9 || q[i] > impl_->upper[i] + 1e-9) {
      const bool angular = impl_->joints[si].type != JointType::kPrismatic;
      return OutOfRangeError(
          angular
              ? fmt::format("joint '{}' = {:.6g} rad ({} deg) is outside its limits "
                            "[{:.6g}, {:.6g}] rad ([{:.3f}, {:.3f}] deg)",
                            impl_->names[si], q[i], DegreesText(RadToDeg(q[i])), impl_->lower[i],
                            impl_->upper[i], RadToDeg(impl_->lower[i]), RadToDeg(impl_->upper[i]))
              : fmt::format("joint '{}' = {:.6g} m is outside its limits [{:.6g}, {:.6g}] m",
                            impl_->names[si], q[i], impl_->lower[i], impl_->upper[i]));
    }
  }
  return Status::Ok();
}

Eigen::VectorXd ArmModel::ClampToLimits(const Eigen::VectorXd& q) const {
  AVP_THROW_UNLESS(q.size() == num_joints() && q.allFinite(), q.size(), num_joints(),
                   q.transpose());
  return q.cwiseMax(impl_->lower).cwiseMin(impl_->upper);
}

Eigen::VectorXd ArmModel::RandomJoints(Rng& rng) const {
  Eigen::VectorXd q(num_joints());
  for (int i = 0; i < q.size(); ++i) {
    if (impl_->joints[static_cast<size_t>(i)].type == JointType::kContinuous) {
      q[i] = rng.Uniform(-EIGEN_PI, EIGEN_PI);
    } else {
      q[i] = rng.Uniform(impl_->lower[i], impl_->upper[i]);
    }
  }
  return q;
}

// ---- Forward kinematics -------------------------------------------------------------------------

RigidTransform ArmModel::ForwardKinematics(const Eigen::VectorXd& q) const {
  AVP_THROW_UNLESS(q.size() == num_joints() && q.allFinite(), q.size(), num_joints(),
                   q.transpose());
  return FromIsometry(impl_->Fk(q));
}

const std::vector<LinkInfo>& ArmModel::links() const { return impl_->links; }

int ArmModel::tip_link_index() const { return impl_->tip_link; }

int ArmModel::LinkIndex(std::string_view name) const {
  for (size_t i = 0; i < impl_->links.size(); ++i) {
    if (impl_->links[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

std::vector<Eigen::Isometry3d> ArmModel::JointFrames(const Eigen::VectorXd& q) const {
  AVP_THROW_UNLESS(q.size() == num_joints() && q.allFinite(), q.size(), num_joints(),
                   q.transpose());
  std::vector<Eigen::Isometry3d> frames;
  frames.reserve(static_cast<size_t>(num_joints()));
  impl_->JointFrames(q, &frames);
  return frames;
}

std::vector<Eigen::Isometry3d> ArmModel::LinkPoses(const Eigen::VectorXd& q) const {
  const std::vector<Eigen::Isometry3d> frames = JointFrames(q);
  std::vector<Eigen::Isometry3d> poses;
  poses.reserve(impl_->links.size());
  for (const LinkInfo& link : impl_->links) {
    poses.push_back(link.joint < 0 ? link.X_JL
                                   : frames[static_cast<size_t>(link.joint)] * link.X_JL);
  }
  return poses;
}

RigidTransform ArmModel::CameraPose(const Eigen::VectorXd& q) const {
  return ForwardKinematics(q) * impl_->X_FC;
}

// ---- Inverse kinematics -------------------------------------------------------------------------

namespace {

// Moves each angle by a multiple of 2π: revolute joints into their limits (nearest the seed when
// several fit), continuous joints to the value nearest the seed. Prismatic joints stay.
void WrapAngles(const std::vector<JointInfo>& joints, const Eigen::VectorXd& seed,
                Eigen::VectorXd& q) {
  for (int i = 0; i < q.size(); ++i) {
    const JointInfo& j = joints[static_cast<size_t>(i)];
    if (j.type == JointType::kPrismatic || !std::isfinite(q[i])) continue;
    if (j.type == JointType::kContinuous) {
      q[i] -= kTwoPi * std::round((q[i] - seed[i]) / kTwoPi);
      continue;
    }
    const double k_min = std::ceil((j.lower - q[i]) / kTwoPi);
    const double k_max = std::floor((j.upper - q[i]) / kTwoPi);
    double best = q[i];
    double best_distance = std::numeric_limits<double>::infinity();
    for (double k = k_min; k <= k_max; k += 1.0) {
      const double candidate = q[i] + k * kTwoPi;
      const double distance = std::abs(candidate - seed[i]);
      if (distance < best_distance) {
        best = candidate;
        best_distance = distance;
      }
    }
    q[i] = best;  // unchanged when no multiple fits: the caller then rejects it
  }
}

}  // namespace

IkResult ArmModel::SolveIk(const RigidTransform& X_WF, const Eigen::VectorXd& q_seed,
                           Rng& rng) const {
  return SolveIk(X_WF, q_seed, rng, impl_->config.ik);
}

IkResult ArmModel::SolveIk(const RigidTransform& X_WF, const Eigen::VectorXd& q_seed, Rng& rng,
                           const IkOptions& options) const {
  AVP_THROW_UNLESS(q_seed.size() == num_joints() && q_seed.allFinite(), q_seed.size(), num_joints(),
                   q_seed.transpose());
  if (const Status s = options.Validate(); !s.ok()) ThrowStatus(s);
  const Impl& m = *impl_;
  const int n = num_joints();

  IkResult result;
  result.q = ClampToLimits(q_seed);

  // Beyond the reach bound: no solver run.
  const Eigen::Vector3d p_first = m.X_origin.front().translation();
  const double distance = (X_WF.translation() - p_first).norm();
  const Eigen::Vector3d p_wrist = X_WF * m.p_wrist_in_tip;
  const double wrist_distance = (p_wrist - m.p_fixed).norm();
  const bool beyond_reach = distance > m.max_reach_m + options.position_tolerance_m;
  if (beyond_reach || (m.wrist_joint > m.fixed_joint &&
                       wrist_distance > m.wrist_reach_m + options.position_tolerance_m)) {
    const Eigen::Isometry3d X = m.Fk(result.q);
    result.position_error_m = (X.translation() - X_WF.translation()).norm();
    result.orientation_error_rad = RotationAngle(X.linear(), X_WF.rotation());
    result.status = UnreachableError(
        beyond_reach
            ? fmt::format(
                  "flange target {} is {:.3f} m from the first joint, beyond the arm's reach "
                  "({:.3f} m)",
                  X_WF.ToString(), distance, m.max_reach_m)
            : fmt::format("flange target {} puts joint '{}' {:.3f} m from joint '{}', farther "
                          "than the links between them reach ({:.3f} m)",
                          X_WF.ToString(), m.names[static_cast<size_t>(m.wrist_joint)],
                          wrist_distance, m.names[static_cast<size_t>(m.fixed_joint)],
                          m.wrist_reach_m));
    return result;
  }

  // Position and orientation errors are weighted so that both tolerances map to the same
  // weighted norm; LMA stops at a tenth of it and the result is checked with our own FK.
  const double w_rot = options.position_tolerance_m / options.orientation_tolerance_rad;
  Eigen::Matrix<double, 6, 1> L;
  L << 1.0, 1.0, 1.0, w_rot, w_rot, w_rot;
  const KDL::Chain chain = m.chain;  // private copy: KDL joints cache state (see Impl)
  KDL::ChainIkSolverPos_LMA solver(chain, L, 0.1 * options.position_tolerance_m,
                                   options.max_iterations, 1e-12);
  const KDL::Frame target = ToKdl(ToIso(X_WF));
  KDL::JntArray q_init(static_cast<unsigned int>(n));
  KDL::JntArray q_out(static_cast<unsigned int>(n));

  double best_score = std::numeric_limits<double>::infinity();
  int converged_outside_limits = 0;
  const int attempts = 1 + options.max_restarts;
  for (int attempt = 0; attempt < attempts; ++attempt) {
    const Eigen::VectorXd start = attempt == 0 ? result.q.eval() : RandomJoints(rng);
    q_init.data = start;
    solver.CartToJnt(q_init, target, q_out);
    result.iterations += std::max(solver.lastNrOfIter, 0);
    result.restarts = attempt;

    Eigen::VectorXd q = q_out.data;
    if (!q.allFinite()) continue;
    WrapAngles(m.joints, start, q);
    const Eigen::Isometry3d X = m.Fk(q);
    const double position_error = (X.translation() - X_WF.translation()).norm();
    const double orientation_error = RotationAngle(X.linear(), X_WF.rotation());
    const bool on_target = position_error <= options.position_tolerance_m &&
                           orientation_error <= options.orientation_tolerance_rad;
    const bool in_limits = WithinLimits(q, 1e-9);
    if (on_target && !in_limits) ++converged_outside_limits;
    const double score = position_error + w_rot * orientation_error;
    if ((on_target && in_limits) || score < best_score) {
      best_score = score;
      result.q = q;
      result.position_error_m = position_error;
      result.orientation_error_rad = orientation_error;
    }
    if (on_target && in_limits) {
      result.q = ClampToLimits(q);  // remove rounding-level excursions
      result.status = Status::Ok();
      return result;
    }
  }
  result.status = UnreachableError(fmt::format(
      "no joints within the limits reach flange target {} after {} attempts (1 + {} restarts, "
      "{} iterations); best residual {:.4g} m, {:.4g} rad at {}{}",
      X_WF.ToString(), attempts, options.max_restarts, result.iterations, result.position_error_m,
      result.orientation_error_rad, FormatJointsDeg(result.q),
      converged_outside_limits > 0
          ? fmt::format("; {} attempts reached it outside the limits", converged_outside_limits)
          : std::string()));
  return result;
}

IkResult ArmModel::SolveCameraIk(const RigidTransform& X_WC, const Eigen::VectorXd& q_seed,
                                 Rng& rng) const {
  return SolveCameraIk(X_WC, q_seed, rng, impl_->config.ik);
}

IkResult ArmModel::SolveCameraIk(const RigidTransform& X_WC, const Eigen::VectorXd& q_seed,
                                 Rng& rng, const IkOptions& options) const {
  IkResult result = SolveIk(X_WC * impl_->X_FC.inverse(), q_seed, rng, options);
  if (!result.ok()) {
    result.status = UnreachableError(
        fmt::format("camera target X_WC {}: {}", X_WC.ToString(), result.status.message()));
  }
  return result;
}

bool ArmModel::IsReachable(const RigidTransform& X_WC) const {
  Rng rng(impl_->config.ik.reachability_seed);
  return SolveCameraIk(X_WC, impl_->home, rng).ok();
}

// ---- Joint conventions --------------------------------------------------------------------------

Eigen::VectorXd ArmModel::FromReferenceJoints(const Eigen::VectorXd& q_ref) const {
  AVP_THROW_UNLESS(q_ref.size() == num_joints() && q_ref.allFinite(), q_ref.size(), num_joints(),
                   q_ref.transpose());
  const JointConvention& rc = impl_->config.reference_convention;
  if (rc.IsIdentity()) return q_ref;
  Eigen::VectorXd q(q_ref.size());
  for (int i = 0; i < q.size(); ++i) {
    const auto si = static_cast<size_t>(i);
    q[i] = rc.sign[si] * q_ref[i] + rc.offset_rad[si];
  }
  return q;
}

Eigen::VectorXd ArmModel::ToReferenceJoints(const Eigen::VectorXd& q_urdf) const {
  AVP_THROW_UNLESS(q_urdf.size() == num_joints() && q_urdf.allFinite(), q_urdf.size(), num_joints(),
                   q_urdf.transpose());
  const JointConvention& rc = impl_->config.reference_convention;
  if (rc.IsIdentity()) return q_urdf;
  Eigen::VectorXd q(q_urdf.size());
  for (int i = 0; i < q.size(); ++i) {
    const auto si = static_cast<size_t>(i);
    q[i] = rc.sign[si] * (q_urdf[i] - rc.offset_rad[si]);
  }
  return q;
}

}  // namespace avp::robot

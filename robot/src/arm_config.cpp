#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/io/yaml.h>
#include <avp/robot/arm_config.h>

namespace avp::robot {

namespace {

bool AllFinite(const std::vector<double>& v) {
  for (double x : v) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}

Status JoinProblems(std::string_view what, const std::vector<std::string>& problems) {
  if (problems.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid {}: {}", what, fmt::join(problems, "; ")));
}

void ValidateIk(const IkOptions& ik, std::string_view prefix, std::vector<std::string>& problems) {
  if (ik.max_restarts < 0) {
    problems.push_back(fmt::format("{}max_restarts ({}) must be >= 0", prefix, ik.max_restarts));
  }
  if (!(ik.position_tolerance_m > 0.0) || !std::isfinite(ik.position_tolerance_m)) {
    problems.push_back(fmt::format("{}position_tolerance_m ({}) must be finite and > 0", prefix,
                                   ik.position_tolerance_m));
  }
  if (!(ik.orientation_tolerance_rad > 0.0) || !std::isfinite(ik.orientation_tolerance_rad)) {
    problems.push_back(fmt::format("{}orientation_tolerance_rad ({}) must be finite and > 0",
                                   prefix, ik.orientation_tolerance_rad));
  }
  if (ik.max_iterations < 1) {
    problems.push_back(
        fmt::format("{}max_iterations ({}) must be >= 1", prefix, ik.max_iterations));
  }
}

// Reads an optional list given either in SI units (`key`) or in degrees (`key_deg`).
Result<std::vector<double>> ReadSiOrDegrees(const YAML::Node& node, const std::string& key,
                                            std::string_view context) {
  const std::string key_deg = key + "_deg";
  const bool has_si = node[key].IsDefined();
  const bool has_deg = node[key_deg].IsDefined();
  if (has_si && has_deg) {
    return InvalidArgumentError(
        fmt::format("{}: give either '{}' or '{}', not both", context, key, key_deg));
  }
  if (has_si) return io::ReadDoubles(node, key, context);
  if (!has_deg) return std::vector<double>{};
  AVP_ASSIGN_OR_RETURN(std::vector<double> values, io::ReadDoubles(node, key_deg, context));
  for (double& v : values) v = DegToRad(v);
  return values;
}

Result<double> ReadSiOrDegree(const YAML::Node& node, const std::string& key,
                              std::string_view context) {
  const std::string key_deg = key + "_deg";
  const bool has_si = node[key].IsDefined();
  const bool has_deg = node[key_deg].IsDefined();
  if (has_si == has_deg) {
    return InvalidArgumentError(
        fmt::format("{}: give exactly one of '{}' and '{}'", context, key, key_deg));
  }
  if (has_si) return io::ReadDouble(node, key, context);
  AVP_ASSIGN_OR_RETURN(const double deg, io::ReadDouble(node, key_deg, context));
  return DegToRad(deg);
}

/// One shape of the `collision:` section: {name, box: {size}, cylinder: {radius, length},
/// sphere: {radius}, plane: {} or mesh: {file, scale}, pose: {xyz, rpy(_deg)}}; a mesh file is
/// resolved against `folder`.
Result<CollisionShape> ReadShape(const YAML::Node& node, const std::filesystem::path& folder,
                                 const std::string& ctx) {
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(
      node, {"name", "box", "cylinder", "sphere", "plane", "mesh", "pose"}, ctx));
  CollisionShape shape;
  AVP_ASSIGN_OR_RETURN(shape.name, io::ReadString(node, "name", ctx));
  const std::string sctx = fmt::format("{} ('{}')", ctx, shape.name);
  int kinds = 0;
  for (const char* key : {"box", "cylinder", "sphere", "plane", "mesh"}) {
    if (node[key].IsDefined()) ++kinds;
  }
  if (kinds != 1) {
    return InvalidArgumentError(fmt::format(
        "{}: give exactly one of box, cylinder, sphere, plane and mesh ({} given)", sctx, kinds));
  }
  if (const YAML::Node b = node["box"]; b.IsDefined()) {
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(b, {"size"}, sctx + ": box"));
    shape.kind = ShapeKind::kBox;
    AVP_ASSIGN_OR_RETURN(shape.size, io::ReadVector(b, "size", 3, sctx + ": box"));
  } else if (const YAML::Node c = node["cylinder"]; c.IsDefined()) {
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(c, {"radius", "length"}, sctx + ": cylinder"));
    shape.kind = ShapeKind::kCylinder;
    AVP_ASSIGN_OR_RETURN(const double r, io::ReadDouble(c, "radius", sctx + ": cylinder"));
    AVP_ASSIGN_OR_RETURN(const double l, io::ReadDouble(c, "length", sctx + ": cylinder"));
    shape.size = Eigen::Vector3d(r, r, l);
  } else if (const YAML::Node sp = node["sphere"]; sp.IsDefined()) {
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(sp, {"radius"}, sctx + ": sphere"));
    shape.kind = ShapeKind::kSphere;
    AVP_ASSIGN_OR_RETURN(const double r, io::ReadDouble(sp, "radius", sctx + ": sphere"));
    shape.size = Eigen::Vector3d::Constant(r);
  } else if (const YAML::Node m = node["mesh"]; m.IsDefined()) {
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(m, {"file", "scale"}, sctx + ": mesh"));
    shape.kind = ShapeKind::kMesh;
    AVP_ASSIGN_OR_RETURN(const std::string file, io::ReadString(m, "file", sctx + ": mesh"));
    shape.mesh = std::filesystem::path(file);
    if (shape.mesh.is_relative()) shape.mesh = (folder / shape.mesh).lexically_normal();
    shape.size = Eigen::Vector3d::Ones();
    if (m["scale"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(shape.size, io::ReadVector(m, "scale", 3, sctx + ": mesh"));
    }
  } else {
    shape.kind = ShapeKind::kPlane;
  }
  if (node["pose"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(shape.X_PS, io::ReadPose(node, "pose", sctx));
  }
  return shape;
}

Result<std::vector<CollisionShape>> ReadShapes(const YAML::Node& node, std::string_view key,
                                               const std::filesystem::path& folder,
                                               const std::string& ctx) {
  std::vector<CollisionShape> shapes;
  const YAML::Node list = node[std::string(key)];
  if (!list.IsDefined() || list.IsNull()) return shapes;
  if (!list.IsSequence()) {
    return InvalidArgumentError(fmt::format("{}: '{}' must be a list of shapes", ctx, key));
  }
  for (size_t i = 0; i < list.size(); ++i) {
    AVP_ASSIGN_OR_RETURN(CollisionShape shape,
                         ReadShape(list[i], folder, fmt::format("{}: {}[{}]", ctx, key, i)));
    shapes.push_back(std::move(shape));
  }
  return shapes;
}

/// The `ik:` section over the defaults in `out`.
Status ReadIk(const YAML::Node& root, const std::string& ctx, IkOptions& out) {
  const YAML::Node ik = root["ik"];
  if (!ik.IsDefined()) return Status::Ok();
  {
    const std::string ictx = ctx + ": ik";
    AVP_RETURN_IF_ERROR(
        io::RejectUnknownKeys(ik,
                              {"max_restarts", "position_tolerance_m", "orientation_tolerance_rad",
                               "max_iterations", "reachability_seed"},
                              ictx));
    if (ik["max_restarts"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(const int64_t v, io::ReadInt(ik, "max_restarts", ictx));
      out.max_restarts = static_cast<int>(v);
    }
    if (ik["position_tolerance_m"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(out.position_tolerance_m,
                           io::ReadDouble(ik, "position_tolerance_m", ictx));
    }
    if (ik["orientation_tolerance_rad"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(out.orientation_tolerance_rad,
                           io::ReadDouble(ik, "orientation_tolerance_rad", ictx));
    }
    if (ik["max_iterations"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(const int64_t v, io::ReadInt(ik, "max_iterations", ictx));
      out.max_iterations = static_cast<int>(v);
    }
    if (ik["reachability_seed"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(const int64_t v, io::ReadInt(ik, "reachability_seed", ictx));
      out.reachability_seed = static_cast<uint64_t>(v);
    }
  }
  return Status::Ok();
}

/// The `collision:` section (attached and world shapes), mesh files relative to the YAML's folder.
Status ReadCollision(const YAML::Node& root, const std::filesystem::path& path,
                     const std::string& ctx, CollisionConfig& out) {
  const YAML::Node collision = root["collision"];
  if (!collision.IsDefined()) return Status::Ok();
  const std::string cctx = ctx + ": collision";
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(collision, {"attached", "world"}, cctx));
  AVP_ASSIGN_OR_RETURN(out.attached, ReadShapes(collision, "attached", path.parent_path(), cctx));
  AVP_ASSIGN_OR_RETURN(out.world, ReadShapes(collision, "world", path.parent_path(), cctx));
  return Status::Ok();
}

}  // namespace

std::string_view ToString(ShapeKind kind) {
  switch (kind) {
    case ShapeKind::kBox:
      return "box";
    case ShapeKind::kCylinder:
      return "cylinder";
    case ShapeKind::kSphere:
      return "sphere";
    case ShapeKind::kMesh:
      return "mesh";
    case ShapeKind::kPlane:
      return "plane";
  }
  return "unknown";
}

CollisionShape CollisionShape::Box(std::string name, const Eigen::Vector3d& size,
                                   const RigidTransform& X) {
  return {std::move(name), ShapeKind::kBox, size, {}, X};
}

CollisionShape CollisionShape::Cylinder(std::string name, double radius, double length,
                                        const RigidTransform& X) {
  return {std::move(name), ShapeKind::kCylinder, Eigen::Vector3d(radius, radius, length), {}, X};
}

CollisionShape CollisionShape::Sphere(std::string name, double radius, const RigidTransform& X) {
  return {std::move(name), ShapeKind::kSphere, Eigen::Vector3d::Constant(radius), {}, X};
}

CollisionShape CollisionShape::Plane(std::string name, const RigidTransform& X) {
  return {std::move(name), ShapeKind::kPlane, Eigen::Vector3d::Zero(), {}, X};
}

Status CollisionShape::Validate(std::string_view what) const {
  if (kind == ShapeKind::kPlane) return Status::Ok();
  if (kind == ShapeKind::kMesh) {
    if (mesh.empty()) {
      return InvalidArgumentError(fmt::format("{} '{}': mesh without a file", what, name));
    }
    if (!size.allFinite() || (size.array() == 0.0).any()) {
      return InvalidArgumentError(
          fmt::format("{} '{}': mesh scale ({}, {}, {}) must be finite "
                      "and non-zero",
                      what, name, size.x(), size.y(), size.z()));
    }
    return Status::Ok();
  }
  const bool bad = !size.allFinite() || !(size.minCoeff() > 0.0);
  if (!bad) return Status::Ok();
  switch (kind) {
    case ShapeKind::kBox:
      return InvalidArgumentError(
          fmt::format("{} '{}': box size ({}, {}, {}) m must be finite "
                      "and > 0",
                      what, name, size.x(), size.y(), size.z()));
    case ShapeKind::kCylinder:
      return InvalidArgumentError(
          fmt::format("{} '{}': cylinder radius ({}) m and length ({}) m "
                      "must be finite and > 0",
                      what, name, size.x(), size.z()));
    default:
      return InvalidArgumentError(
          fmt::format("{} '{}': sphere radius ({}) m must be finite and > "
                      "0",
                      what, name, size.x()));
  }
}

RigidTransform CameraMount::DefaultX_FC() {
  Eigen::Matrix3d R_FC;
  R_FC.col(0) = -Eigen::Vector3d::UnitY();  // image right = −flange y
  R_FC.col(1) = -Eigen::Vector3d::UnitZ();  // image down = −flange z
  R_FC.col(2) = Eigen::Vector3d::UnitX();   // optical axis = flange x (approach axis)
  return RigidTransform(R_FC, Eigen::Vector3d(0.03, 0.0, 0.06));
}

Status IkOptions::Validate() const {
  std::vector<std::string> problems;
  ValidateIk(*this, "", problems);
  return JoinProblems("IK options", problems);
}

Status ArmConfig::Validate() const {
  std::vector<std::string> problems;
  if (urdf_path.empty()) problems.push_back("urdf_path ('') must not be empty");
  if (base_link.empty()) problems.push_back("base_link ('') must not be empty");
  if (tip_link.empty()) problems.push_back("tip_link ('') must not be empty");
  if (!base_link.empty() && base_link == tip_link) {
    problems.push_back(
        fmt::format("tip_link ('{}') must differ from base_link ('{}')", tip_link, base_link));
  }
  for (size_t i = 0; i < joint_limit_overrides.size(); ++i) {
    const JointLimitOverride& o = joint_limit_overrides[i];
    if (o.joint.empty()) {
      problems.push_back(fmt::format("joint_limit_overrides[{}].joint ('') must not be empty", i));
    }
    if (!std::isfinite(o.lower) || !std::isfinite(o.upper) || !(o.lower < o.upper)) {
      problems.push_back(fmt::format(
          "joint_limit_overrides[{}] ({}): lower ({}) must be < upper ({}), both finite", i,
          o.joint, o.lower, o.upper));
    }
  }
  if (!AllFinite(home_joints)) {
    problems.push_back(
        fmt::format("home_joints ([{}]) must be finite", fmt::join(home_joints, ", ")));
  }
  if (camera_mount.frame_name.empty()) {
    problems.push_back("camera_mount.frame_name ('') must not be empty");
  }
  ValidateIk(ik, "ik.", problems);
  const JointConvention& rc = reference_convention;
  if (rc.sign.size() != rc.offset_rad.size()) {
    problems.push_back(
        fmt::format("reference_convention: sign ({} entries) and offset ({} entries) must have "
                    "the same length",
                    rc.sign.size(), rc.offset_rad.size()));
  }
  for (size_t i = 0; i < rc.sign.size(); ++i) {
    if (rc.sign[i] != 1.0 && rc.sign[i] != -1.0) {
      problems.push_back(
          fmt::format("reference_convention.sign[{}] ({}) must be +1 or -1", i, rc.sign[i]));
    }
  }
  if (!AllFinite(rc.offset_rad)) {
    problems.push_back(fmt::format("reference_convention.offset ([{}]) must be finite",
                                   fmt::join(rc.offset_rad, ", ")));
  }
  if (!home_joints.empty() && !rc.sign.empty() && home_joints.size() != rc.sign.size()) {
    problems.push_back(fmt::format(
        "home_joints ({} entries) and reference_convention ({} entries) must have the same length",
        home_joints.size(), rc.sign.size()));
  }
  for (const CollisionShape& shape : collision.attached) {
    if (const Status st = shape.Validate("collision.attached"); !st.ok()) {
      problems.push_back(st.message());
    }
    if (shape.kind == ShapeKind::kPlane) {
      problems.push_back(
          fmt::format("collision.attached '{}': a plane cannot be fixed to the arm", shape.name));
    }
  }
  for (const CollisionShape& shape : collision.world) {
    if (const Status st = shape.Validate("collision.world"); !st.ok()) {
      problems.push_back(st.message());
    }
  }
  if (!std::isfinite(joint_acceleration_limit) || !(joint_acceleration_limit > 0.0)) {
    problems.push_back(fmt::format("joint_acceleration_limit ({}) must be finite and > 0",
                                   joint_acceleration_limit));
  }
  return JoinProblems("arm config", problems);
}

Result<ArmConfig> ArmConfig::LoadYaml(const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node root, io::LoadYamlFile(path));
  const std::string ctx = path.string();
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(
      root,
      {"urdf", "base_link", "tip_link", "home_joints", "home_joints_deg", "joint_limit_overrides",
       "camera_mount", "ik", "reference_convention", "collision", "joint_acceleration_limit"},
      ctx));

  ArmConfig config;
  AVP_ASSIGN_OR_RETURN(const std::string urdf, io::ReadString(root, "urdf", ctx));
  config.urdf_path = std::filesystem::path(urdf);
  if (config.urdf_path.is_relative()) config.urdf_path = path.parent_path() / config.urdf_path;
  config.urdf_path = config.urdf_path.lexically_normal();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(config.urdf_path, ec)) {
    return NotFoundError(
        fmt::format("{}: 'urdf' names '{}', which is not a file (resolved to '{}')", ctx, urdf,
                    config.urdf_path.string()));
  }
  if (root["base_link"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(config.base_link, io::ReadString(root, "base_link", ctx));
  }
  if (root["tip_link"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(config.tip_link, io::ReadString(root, "tip_link", ctx));
  }
  AVP_ASSIGN_OR_RETURN(config.home_joints, ReadSiOrDegrees(root, "home_joints", ctx));

  if (const YAML::Node overrides = root["joint_limit_overrides"];
      overrides.IsDefined() && !overrides.IsNull()) {
    if (!overrides.IsSequence()) {
      return InvalidArgumentError(
          fmt::format("{}: 'joint_limit_overrides' must be a list of {{joint, lower(_deg), "
                      "upper(_deg)}}",
                      ctx));
    }
    for (size_t i = 0; i < overrides.size(); ++i) {
      const YAML::Node o = overrides[i];
      const std::string octx = fmt::format("{}: joint_limit_overrides[{}]", ctx, i);
      AVP_RETURN_IF_ERROR(
          io::RejectUnknownKeys(o, {"joint", "lower", "upper", "lower_deg", "upper_deg"}, octx));
      JointLimitOverride limit;
      AVP_ASSIGN_OR_RETURN(limit.joint, io::ReadString(o, "joint", octx));
      AVP_ASSIGN_OR_RETURN(limit.lower, ReadSiOrDegree(o, "lower", octx));
      AVP_ASSIGN_OR_RETURN(limit.upper, ReadSiOrDegree(o, "upper", octx));
      config.joint_limit_overrides.push_back(limit);
    }
  }

  if (const YAML::Node mount = root["camera_mount"]; mount.IsDefined()) {
    const std::string mctx = ctx + ": camera_mount";
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(mount, {"frame", "pose"}, mctx));
    if (mount["frame"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(config.camera_mount.frame_name, io::ReadString(mount, "frame", mctx));
    }
    if (mount["pose"].IsDefined()) {
      AVP_ASSIGN_OR_RETURN(config.camera_mount.X_FC, io::ReadPose(mount, "pose", mctx));
    }
  }

  AVP_RETURN_IF_ERROR(ReadIk(root, ctx, config.ik));

  if (const YAML::Node rc = root["reference_convention"]; rc.IsDefined()) {
    const std::string rctx = ctx + ": reference_convention";
    AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(rc, {"sign", "offset", "offset_deg"}, rctx));
    AVP_ASSIGN_OR_RETURN(config.reference_convention.sign, io::ReadDoubles(rc, "sign", rctx));
    AVP_ASSIGN_OR_RETURN(config.reference_convention.offset_rad,
                         ReadSiOrDegrees(rc, "offset", rctx));
  }

  AVP_RETURN_IF_ERROR(ReadCollision(root, path, ctx, config.collision));
  if (root["joint_acceleration_limit"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(config.joint_acceleration_limit,
                         io::ReadDouble(root, "joint_acceleration_limit", ctx));
  }

  AVP_RETURN_IF_ERROR(config.Validate().WithContext(ctx));
  return config;
}

}  // namespace avp::robot

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/cylinder.h>
#include <fcl/geometry/shape/halfspace.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/math/bv/OBBRSS.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/distance.h>
#include <fmt/format.h>

#include <avp/core/limits.h>
#include <avp/core/rng.h>
#include <avp/motion/robot_geometry.h>

namespace avp::motion {

using Geometry = fcl::CollisionGeometry<double>;

struct RobotGeometry::Impl {
  robot::ArmModel arm;
  RobotGeometryOptions options;
  std::vector<RobotBody> bodies;
  GeometrySource source = GeometrySource::kCollision;
  std::vector<std::string> warnings;
  std::vector<std::pair<int, int>> self_pairs;
  std::vector<AllowedPair> allowed;
  Eigen::VectorXd lever_arms;

  explicit Impl(robot::ArmModel a) : arm(std::move(a)) {}
};

std::string_view ToString(AllowedReason reason) {
  switch (reason) {
    case AllowedReason::kSameLink:
      return "same link";
    case AllowedReason::kAdjacent:
      return "adjacent";
    case AllowedReason::kDefault:
      return "in contact at home";
    case AllowedReason::kAlways:
      return "always in contact";
  }
  return "unknown";
}

std::string_view ToString(GeometrySource source) {
  switch (source) {
    case GeometrySource::kCollision:
      return "collision";
    case GeometrySource::kVisual:
      return "visual";
    case GeometrySource::kCapsules:
      return "capsules";
  }
  return "unknown";
}

namespace {

/// The default of max_collision_mesh_file_bytes: 256 MiB. A robot's collision meshes (URDF links,
/// the arm config's `collision.attached` and `collision.world`) are a few MB at most; a larger file
/// is a mistake (a scanned scene, the wrong file) that assimp would read whole into memory.
constexpr uint64_t kMaxCollisionMeshFileBytes = uint64_t{256} << 20;

/// The process-wide limit (core/limits.h) on one collision mesh file, checked before assimp opens
/// it: ResourceExhausted naming the shape, the file, its size and the limit. Raise it with
/// `avp --limit max_collision_mesh_file_bytes=N` (docs/limits.md).
const Limit& MaxCollisionMeshFileBytes() {
  static const Limit limit("max_collision_mesh_file_bytes", kMaxCollisionMeshFileBytes, "bytes",
                           "size of one collision mesh file (URDF, collision.attached / world)");
  return limit;
}
// Registered when the program starts, so `avp --limit` and `avp limits` know it.
[[maybe_unused]] const Limit& kRegisterMaxCollisionMeshFileBytes = MaxCollisionMeshFileBytes();

/// The triangles of a mesh file, scaled, in the file's root frame (node transforms applied).
/// The file's size is checked against MaxCollisionMeshFileBytes() before assimp reads it.
Result<std::shared_ptr<const Geometry>> LoadMesh(const robot::CollisionShape& shape,
                                                 std::string_view what) {
  const std::string file = shape.mesh.string();
  if (file.find("://") != std::string::npos) {
    return InvalidArgumentError(fmt::format(
        "{} '{}': mesh '{}' is a package or URL name; write it as a path (relative to the "
        "URDF's folder)",
        what, shape.name, file));
  }
  std::error_code ec;
  if (!std::filesystem::is_regular_file(shape.mesh, ec)) {
    return NotFoundError(fmt::format("{} '{}': mesh file '{}' not found", what, shape.name, file));
  }
  const uint64_t file_bytes = std::filesystem::file_size(shape.mesh, ec);
  if (ec) {
    return IoError(fmt::format("{} '{}': cannot read mesh file '{}': {}", what, shape.name, file,
                               ec.message()));
  }
  AVP_RETURN_IF_ERROR(MaxCollisionMeshFileBytes().Check(
      fmt::format("{} '{}': mesh file '{}' of {} bytes", what, shape.name, file, file_bytes),
      file_bytes));
  Assimp::Importer importer;
  const aiScene* scene =
      importer.ReadFile(file, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices);
  if (scene == nullptr || scene->mRootNode == nullptr) {
    return InvalidArgumentError(fmt::format("{} '{}': cannot read mesh '{}': {}", what, shape.name,
                                            file, importer.GetErrorString()));
  }
  std::vector<fcl::Vector3d> vertices;
  std::vector<fcl::Triangle> triangles;
  std::vector<std::pair<const aiNode*, aiMatrix4x4>> stack{{scene->mRootNode, aiMatrix4x4()}};
  while (!stack.empty()) {
    const auto [node, parent] = stack.back();
    stack.pop_back();
    const aiMatrix4x4 X = parent * node->mTransformation;
    for (unsigned m = 0; m < node->mNumMeshes; ++m) {
      const aiMesh* mesh = scene->mMeshes[node->mMeshes[m]];
      const size_t base = vertices.size();
      for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
        const aiVector3D p = X * mesh->mVertices[v];
        vertices.emplace_back(p.x * shape.size.x(), p.y * shape.size.y(), p.z * shape.size.z());
      }
      for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
        const aiFace& face = mesh->mFaces[f];
        if (face.mNumIndices != 3) continue;
        triangles.emplace_back(base + face.mIndices[0], base + face.mIndices[1],
                               base + face.mIndices[2]);
      }
    }
    for (unsigned c = 0; c < node->mNumChildren; ++c) stack.emplace_back(node->mChildren[c], X);
  }
  if (triangles.empty()) {
    return InvalidArgumentError(
        fmt::format("{} '{}': mesh '{}' has no triangle", what, shape.name, file));
  }
  auto model = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  model->beginModel(static_cast<int>(triangles.size()), static_cast<int>(vertices.size()));
  model->addSubModel(vertices, triangles);
  model->endModel();
  model->computeLocalAABB();
  return std::shared_ptr<const Geometry>(std::move(model));
}

/// Axis-aligned bounds of a shape in its own frame (planes: none; meshes: their vertices).
std::pair<Eigen::Vector3d, Eigen::Vector3d> LocalBounds(const robot::CollisionShape& shape,
                                                        const Geometry& geometry) {
  switch (shape.kind) {
    case robot::ShapeKind::kBox:
      return {-0.5 * shape.size, 0.5 * shape.size};
    case robot::ShapeKind::kCylinder: {
      const Eigen::Vector3d h(shape.size.x(), shape.size.x(), 0.5 * shape.size.z());
      return {-h, h};
    }
    case robot::ShapeKind::kSphere:
      return {-shape.size, shape.size};
    default:
      return {geometry.aabb_local.min_, geometry.aabb_local.max_};
  }
}

/// Spheres covering an axis-aligned box [lo, hi] (its frame), at most ~`spacing` apart along
/// its long sides: a grid of sub-boxes, each inside the sphere through its corners.
std::vector<Sphere> CoverBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double spacing) {
  const Eigen::Vector3d extent = (hi - lo).cwiseMax(1e-9);
  const double edge = std::max(extent.minCoeff(), spacing);
  Eigen::Vector3i n;
  // At most 64 spheres along a side (a huge box gets larger spheres, still covering it).
  for (int i = 0; i < 3; ++i) {
    n[i] = std::clamp(static_cast<int>(std::ceil(extent[i] / edge)), 1, 64);
  }
  const Eigen::Vector3d cell = extent.cwiseQuotient(n.cast<double>());
  const double radius = 0.5 * cell.norm();
  std::vector<Sphere> spheres;
  for (int x = 0; x < n.x(); ++x) {
    for (int y = 0; y < n.y(); ++y) {
      for (int z = 0; z < n.z(); ++z) {
        const Eigen::Vector3d c =
            lo + cell.cwiseProduct(Eigen::Vector3d(x + 0.5, y + 0.5, z + 0.5));
        spheres.push_back({c, radius});
      }
    }
  }
  return spheres;
}

/// Spheres covering a shape, in the shape's frame.
std::vector<Sphere> CoverShape(const robot::CollisionShape& shape, const Geometry& geometry,
                               double spacing) {
  if (shape.kind == robot::ShapeKind::kSphere) return {{Eigen::Vector3d::Zero(), shape.size.x()}};
  if (shape.kind == robot::ShapeKind::kCylinder) {
    // Spheres on the axis, one per `step` of length: each holds its slab of the cylinder.
    const double r = shape.size.x();
    const double length = shape.size.z();
    const int k = std::clamp(static_cast<int>(std::ceil(length / std::min(r, spacing))), 1, 256);
    const double half_step = 0.5 * length / k;
    std::vector<Sphere> spheres;
    for (int j = 0; j < k; ++j) {
      spheres.push_back({Eigen::Vector3d(0.0, 0.0, -0.5 * length + (2 * j + 1) * half_step),
                         std::hypot(r, half_step)});
    }
    return spheres;
  }
  const auto [lo, hi] = LocalBounds(shape, geometry);
  return CoverBox(lo, hi, spacing);
}

/// Per movable joint i, the constant offset of joint i + 1's origin (or of the tip) in joint i's
/// frame.
std::vector<Eigen::Vector3d> JointOffsets(const robot::ArmModel& arm) {
  const std::vector<Eigen::Isometry3d> frames = arm.JointFrames(arm.home_joints());
  std::vector<Eigen::Vector3d> offsets;
  for (size_t i = 0; i < frames.size(); ++i) {
    const Eigen::Isometry3d next =
        i + 1 < frames.size()
            ? frames[i + 1]
            : arm.LinkPoses(arm.home_joints())[static_cast<size_t>(arm.tip_link_index())];
    offsets.push_back((frames[i].inverse() * next).translation());
  }
  return offsets;
}

/// The shapes each link contributes, by source; fills `source` and `warnings`.
std::vector<std::pair<int, robot::CollisionShape>> ChooseShapes(
    const robot::ArmModel& arm, const RobotGeometryOptions& options, GeometrySource& source,
    std::vector<std::string>& warnings) {
  std::vector<std::pair<int, robot::CollisionShape>> shapes;
  const std::vector<robot::LinkInfo>& links = arm.links();
  for (size_t l = 0; l < links.size(); ++l) {
    for (const robot::CollisionShape& s : links[l].collision) shapes.emplace_back(l, s);
  }
  source = GeometrySource::kCollision;
  if (shapes.empty()) {
    for (size_t l = 0; l < links.size(); ++l) {
      for (const robot::CollisionShape& s : links[l].visual) shapes.emplace_back(l, s);
    }
    source = GeometrySource::kVisual;
    if (!shapes.empty()) {
      warnings.push_back(fmt::format(
          "URDF '{}' has no <collision> shape on the chain: its <visual> shapes are used for "
          "collision checking",
          arm.config().urdf_path.string()));
    }
  }
  if (shapes.empty()) {
    // Capsules (as cylinders with end spheres in the cover) between consecutive joint origins.
    source = GeometrySource::kCapsules;
    const std::vector<Eigen::Vector3d> offsets = JointOffsets(arm);
    for (size_t i = 0; i < offsets.size(); ++i) {
      const double length = offsets[i].norm();
      if (length < 1e-6) continue;
      const Eigen::Vector3d dir = offsets[i] / length;
      const Eigen::Quaterniond R =
          Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), dir);
      const int link = [&] {
        for (size_t l = 0; l < links.size(); ++l) {
          if (links[l].joint == static_cast<int>(i)) return static_cast<int>(l);
        }
        return 0;
      }();
      // The link frame of joint i's child is the joint frame (X_JL = I for the first link of a
      // joint), so the segment runs from its origin to `offsets[i]`.
      shapes.emplace_back(link,
                          robot::CollisionShape::Cylinder(
                              fmt::format("{}/capsule", links[static_cast<size_t>(link)].name),
                              options.fallback_radius_m, length + 2.0 * options.fallback_radius_m,
                              RigidTransform(R, 0.5 * offsets[i])));
    }
    warnings.push_back(fmt::format(
        "URDF '{}' has neither <collision> nor <visual> shapes on the chain: the arm is modelled "
        "as {} cylinders of radius {} m between its joint origins",
        arm.config().urdf_path.string(), shapes.size(), options.fallback_radius_m));
  }
  const int tip = arm.tip_link_index();
  for (const robot::CollisionShape& s : arm.config().collision.attached) {
    robot::CollisionShape attached = s;
    attached.name = fmt::format("{}/{}", arm.tip_link(), s.name);
    shapes.emplace_back(tip, std::move(attached));
  }
  return shapes;
}

/// Rᵢ of MaxDisplacement: from joint i's origin, the chain of joint offsets out to each body's
/// joint, plus the body's farthest point from its joint's origin.
Eigen::VectorXd LeverArms(const robot::ArmModel& arm, const std::vector<RobotBody>& bodies) {
  const int n = arm.num_joints();
  const std::vector<Eigen::Vector3d> offsets = JointOffsets(arm);
  Eigen::VectorXd R = Eigen::VectorXd::Zero(n);
  for (const RobotBody& body : bodies) {
    const robot::LinkInfo& link = arm.links()[static_cast<size_t>(body.link)];
    if (link.joint < 0) continue;
    double reach_in_joint = 0.0;  // farthest point of the body from its joint's origin
    for (const Sphere& s : body.spheres) {
      reach_in_joint = std::max(reach_in_joint, (link.X_JL * s.center).norm() + s.radius);
    }
    double chain = reach_in_joint;
    for (int i = link.joint; i >= 0; --i) {
      const auto si = static_cast<size_t>(i);
      if (arm.joints()[si].type == robot::JointType::kPrismatic) {
        R[i] = 1.0;
        chain += std::max(std::abs(arm.lower_limits()[i]), std::abs(arm.upper_limits()[i]));
      } else {
        R[i] = std::max(R[i], chain);
      }
      if (i > 0) chain += offsets[si - 1].norm();
    }
  }
  return R;
}

/// The allowed-collision list and the pairs left to check.
void ComputeAllowedPairs(RobotGeometry::Impl& impl, const RobotGeometry& geometry) {
  const robot::ArmModel& arm = impl.arm;
  const auto joint_of = [&](int body) {
    return arm.links()[static_cast<size_t>(impl.bodies[static_cast<size_t>(body)].link)].joint;
  };
  const int num = static_cast<int>(impl.bodies.size());
  std::vector<std::pair<int, int>> candidates;
  for (int a = 0; a < num; ++a) {
    for (int b = a + 1; b < num; ++b) {
      const int ja = joint_of(a);
      const int jb = joint_of(b);
      if (ja == jb) {
        impl.allowed.push_back({a, b, AllowedReason::kSameLink});
      } else if (std::abs(ja - jb) == 1) {
        impl.allowed.push_back({a, b, AllowedReason::kAdjacent});
      } else {
        candidates.emplace_back(a, b);
      }
    }
  }
  const auto in_contact = [&](const std::vector<Eigen::Isometry3d>& poses, int a, int b) {
    const auto sa = static_cast<size_t>(a);
    const auto sb = static_cast<size_t>(b);
    return WithinDistance(*impl.bodies[sa].geometry, poses[sa], *impl.bodies[sb].geometry,
                          poses[sb], 0.0);
  };
  const std::vector<Eigen::Isometry3d> home = geometry.BodyPoses(arm.home_joints());
  std::vector<std::pair<int, int>> remaining;
  for (const auto& [a, b] : candidates) {
    if (in_contact(home, a, b)) {
      impl.allowed.push_back({a, b, AllowedReason::kDefault});
    } else {
      remaining.emplace_back(a, b);
    }
  }
  // Always: in contact in more than 95 % of 1000 random states (a fixed seed: the same list on
  // every machine).
  constexpr int kStates = 1000;
  std::vector<int> hits(remaining.size(), 0);
  Rng rng(0x5e1fc011);
  for (int k = 0; k < kStates; ++k) {
    const std::vector<Eigen::Isometry3d> poses = geometry.BodyPoses(arm.RandomJoints(rng));
    for (size_t p = 0; p < remaining.size(); ++p) {
      if (in_contact(poses, remaining[p].first, remaining[p].second)) ++hits[p];
    }
  }
  for (size_t p = 0; p < remaining.size(); ++p) {
    if (hits[p] > kStates * 95 / 100) {
      impl.allowed.push_back({remaining[p].first, remaining[p].second, AllowedReason::kAlways});
    } else {
      impl.self_pairs.push_back(remaining[p]);
    }
  }
}

}  // namespace

Result<std::shared_ptr<const Geometry>> MakeFclGeometry(const robot::CollisionShape& shape,
                                                        std::string_view what) {
  AVP_RETURN_IF_ERROR(shape.Validate(what));
  std::shared_ptr<Geometry> geometry;
  switch (shape.kind) {
    case robot::ShapeKind::kBox:
      geometry = std::make_shared<fcl::Boxd>(shape.size);
      break;
    case robot::ShapeKind::kCylinder:
      geometry = std::make_shared<fcl::Cylinderd>(shape.size.x(), shape.size.z());
      break;
    case robot::ShapeKind::kSphere:
      geometry = std::make_shared<fcl::Sphered>(shape.size.x());
      break;
    case robot::ShapeKind::kPlane:
      geometry = std::make_shared<fcl::Halfspaced>(Eigen::Vector3d::UnitZ(), 0.0);
      break;
    case robot::ShapeKind::kMesh:
      return LoadMesh(shape, what);
  }
  geometry->computeLocalAABB();
  return std::shared_ptr<const Geometry>(std::move(geometry));
}

bool WithinDistance(const Geometry& a, const Eigen::Isometry3d& X_A, const Geometry& b,
                    const Eigen::Isometry3d& X_B, double margin_m) {
  // FCL's geometry-level queries: unlike fcl::CollisionObject's constructor they do not
  // recompute (write) the shared geometry's bounds, so threads may share the geometry.
  try {
    fcl::CollisionRequestd request;
    fcl::CollisionResultd result;
    if (fcl::collide(&a, X_A, &b, X_B, request, result) > 0) return true;
    if (margin_m <= 0.0) return false;
    fcl::DistanceRequestd dreq;
    fcl::DistanceResultd dres;
    return fcl::distance(&a, X_A, &b, X_B, dreq, dres) < margin_m;
  } catch (const std::exception&) {
    return true;  // libccd's EPA can throw on touching contacts: count it as a contact
  }
}

bool BoundsWithin(const RobotBody& a, const Eigen::Isometry3d& X_WLa, const RobotBody& b,
                  const Eigen::Isometry3d& X_WLb, double margin_m) {
  const double d = (X_WLa * a.bound.center - X_WLb * b.bound.center).norm();
  return d <= a.bound.radius + b.bound.radius + margin_m;
}

Result<RobotGeometry> RobotGeometry::Create(const robot::ArmModel& arm,
                                            const RobotGeometryOptions& options) {
  if (!(options.fallback_radius_m > 0.0) || !std::isfinite(options.fallback_radius_m) ||
      !(options.sphere_spacing_m > 0.0) || !std::isfinite(options.sphere_spacing_m)) {
    return InvalidArgumentError(fmt::format(
        "robot geometry options: fallback_radius_m ({}) and sphere_spacing_m ({}) must be finite "
        "and > 0",
        options.fallback_radius_m, options.sphere_spacing_m));
  }
  auto impl = std::make_shared<Impl>(arm);
  impl->options = options;
  const auto shapes = ChooseShapes(arm, options, impl->source, impl->warnings);
  for (const auto& [link, shape] : shapes) {
    const std::string what =
        fmt::format("link '{}' collision shape", arm.links()[static_cast<size_t>(link)].name);
    AVP_ASSIGN_OR_RETURN(std::shared_ptr<const Geometry> geometry, MakeFclGeometry(shape, what));
    RobotBody body;
    body.name = shape.name;
    body.link = link;
    body.shape = shape;
    body.X_LG = shape.X_PS.ToIsometry();
    for (const Sphere& s : CoverShape(shape, *geometry, options.sphere_spacing_m)) {
      body.spheres.push_back({body.X_LG * s.center, s.radius});
    }
    body.bound.center = body.X_LG.translation();
    for (const Sphere& sp : body.spheres) {
      body.bound.radius =
          std::max(body.bound.radius, (sp.center - body.bound.center).norm() + sp.radius);
    }
    body.geometry = std::move(geometry);
    body.moves = arm.links()[static_cast<size_t>(link)].joint >= 0;
    impl->bodies.push_back(std::move(body));
  }
  impl->lever_arms = LeverArms(arm, impl->bodies);
  RobotGeometry geometry(impl);
  ComputeAllowedPairs(*impl, geometry);
  return geometry;
}

const robot::ArmModel& RobotGeometry::arm() const { return impl_->arm; }
const std::vector<RobotBody>& RobotGeometry::bodies() const { return impl_->bodies; }
GeometrySource RobotGeometry::source() const { return impl_->source; }
const std::vector<std::string>& RobotGeometry::warnings() const { return impl_->warnings; }
const std::vector<std::pair<int, int>>& RobotGeometry::self_check_pairs() const {
  return impl_->self_pairs;
}
const std::vector<AllowedPair>& RobotGeometry::allowed_pairs() const { return impl_->allowed; }
const Eigen::VectorXd& RobotGeometry::lever_arms() const { return impl_->lever_arms; }

std::vector<Eigen::Isometry3d> RobotGeometry::LinkPoses(const Eigen::VectorXd& q) const {
  return impl_->arm.LinkPoses(q);
}

std::vector<Eigen::Isometry3d> RobotGeometry::BodyPoses(const Eigen::VectorXd& q) const {
  const std::vector<Eigen::Isometry3d> links = impl_->arm.LinkPoses(q);
  std::vector<Eigen::Isometry3d> poses;
  poses.reserve(impl_->bodies.size());
  for (const RobotBody& body : impl_->bodies) {
    poses.push_back(links[static_cast<size_t>(body.link)] * body.X_LG);
  }
  return poses;
}

double RobotGeometry::MaxDisplacement(const Eigen::VectorXd& dq) const {
  return impl_->lever_arms.dot(dq.cwiseAbs());
}

std::pair<int, int> RobotGeometry::SelfCollision(const Eigen::VectorXd& q, double margin_m) const {
  const std::vector<Eigen::Isometry3d> links = LinkPoses(q);  // once: bodies' poses follow
  for (const auto& [a, b] : impl_->self_pairs) {
    const RobotBody& ba = impl_->bodies[static_cast<size_t>(a)];
    const RobotBody& bb = impl_->bodies[static_cast<size_t>(b)];
    const Eigen::Isometry3d& X_WLa = links[static_cast<size_t>(ba.link)];
    const Eigen::Isometry3d& X_WLb = links[static_cast<size_t>(bb.link)];
    if (!BoundsWithin(ba, X_WLa, bb, X_WLb, margin_m)) continue;
    if (WithinDistance(*ba.geometry, X_WLa * ba.X_LG, *bb.geometry, X_WLb * bb.X_LG, margin_m)) {
      return {a, b};
    }
  }
  return {-1, -1};
}

}  // namespace avp::motion

#pragma once

#include <cstdint>
#include <string>
#include <variant>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>

namespace avp::sim {

/// An indexed triangle mesh in the world frame (metres). Triangles are counter-clockwise seen
/// from outside where that matters (it does not for ray casting: both sides are hit).
struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3i> triangles;

  size_t num_triangles() const { return triangles.size(); }
  bool empty() const { return triangles.empty(); }
  /// Appends `other` transformed by X_WO (other's vertices are in frame O).
  void Append(const TriangleMesh& other, const RigidTransform& X_WO = RigidTransform::Identity());
  void Transform(const RigidTransform& X_WO);
  Box3 Bounds() const;
  /// Every index in range, every vertex finite, no degenerate (zero-area) triangles is not
  /// required. Names the first bad element.
  Status Validate() const;
};

/// An analytic ellipsoid (fruit): points p with |diag(1/radii) R_WE^T (p - center_W)| = 1.
/// Rendered exactly (not tessellated), so depth of a sphere is exact to float precision.
struct Ellipsoid {
  Eigen::Vector3d center_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d radii = Eigen::Vector3d::Constant(0.03);
  Eigen::Matrix3d R_WE = Eigen::Matrix3d::Identity();  ///< columns: the ellipsoid's axes in W

  /// Implicit function: < 0 inside, 0 on the surface, > 0 outside (scaled squared norm - 1).
  double Implicit(const Eigen::Vector3d& p_W) const;
  Box3 Bounds() const;
};

/// One thing in the scene: a leaf, a stem segment, a fruit, the ground ...
struct SceneObject {
  std::string name;
  SemanticClass semantic_class = SemanticClass::kOther;
  /// Unique per object, > 0; written into instance label images. Assigned by Scene::Add.
  uint16_t instance_id = 0;
  /// Base colour, linear RGB in [0, 1]; the renderer shades it.
  Eigen::Vector3f albedo = Eigen::Vector3f(0.5f, 0.5f, 0.5f);
  std::variant<TriangleMesh, Ellipsoid> shape;

  Box3 Bounds() const;
  size_t num_triangles() const;
};

/// Ground truth of one fruit: centre and semi-axes (for meshes: of the axis-aligned bounding box).
struct FruitTruth {
  uint16_t instance_id = 0;
  std::string name;
  Eigen::Vector3d center_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d radii = Eigen::Vector3d::Zero();
  /// Mean of the three semi-axes, metres.
  double mean_radius_m() const { return radii.mean(); }
};

/// A simulated world in the robot base frame W (x forward from the arm, z up, metres), plus the arm
/// configuration an episode starts from.
struct Scene {
  std::string name;         ///< scenario name or scene file stem
  std::string description;  ///< one line
  uint64_t seed = 0;        ///< the seed it was generated with (0 for files)
  std::vector<SceneObject> objects;
  /// Arm start configuration, radians, one value per arm joint (empty: the arm's default).
  std::vector<double> start_joints_rad;
  /// Nominal pose of the camera optical frame at the start (what start_joints_rad aims for).
  RigidTransform X_WC_start;
  /// The plant's region of interest (bounds of every non-ground object), metres.
  Box3 plant_bounds;

  /// Adds an object, assigns the next free instance id and returns it.
  /// @throws avp::Error when more than 65535 objects are added.
  uint16_t Add(SceneObject object);
  /// Shorthand for Add(SceneObject{object_name, semantic_class, 0, albedo, shape}).
  uint16_t Add(std::string object_name, SemanticClass semantic_class, const Eigen::Vector3f& albedo,
               std::variant<TriangleMesh, Ellipsoid> shape);
  /// The fruits, in instance-id order.
  std::vector<FruitTruth> Fruits() const;
  size_t num_triangles() const;
  /// nullptr when no object has that id.
  const SceneObject* FindInstance(uint16_t instance_id) const;
  /// Recomputes plant_bounds from the objects that are neither ground nor background.
  void UpdatePlantBounds();
  /// Unique ids, valid meshes, finite ellipsoids with positive radii.
  Status Validate() const;
};

/// Empty when `a` and `b` hold the same objects with bit-identical geometry, names, classes, ids
/// and colours (same seed, same scene); otherwise a description of the first difference.
std::string DescribeDifference(const Scene& a, const Scene& b);

}  // namespace avp::sim

#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/image.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>

namespace avp::sim {

/// A colour texture: the diffuse / base-colour map of a mesh part (docs/scene-format.md,
/// "Textures"). Texels are 8-bit sRGB as in the image file, row 0 the image's top row; alpha is not
/// kept.
struct Texture {
  ImageRgb8 image;
  /// Linear-RGB factor every sample is multiplied by, each in [0, 1] (glTF's baseColorFactor; 1
  /// for OBJ and COLLADA, whose texture replaces the material colour).
  Eigen::Vector3f factor = Eigen::Vector3f::Ones();
  /// Where the texels came from (an image file, or "'plant.glb' embedded texture 0"), for messages.
  std::string source;

  /// Linear RGB at texture coordinates st = (s, t), OpenGL convention: (0, 0) is the bottom-left
  /// corner of the image, (1, 1) the top-right (s to the right, t up). Wrap mode repeat (s and t
  /// modulo 1); bilinear between texel centres, interpolated in linear RGB (each texel decoded
  /// from sRGB with the IEC 61966-2-1 transfer function), times `factor`. Non-finite coordinates
  /// give MeanColor(). The image must not be empty (Validate).
  Eigen::Vector3f Sample(const Eigen::Vector2f& st) const;
  /// Mean linear colour (times factor) over the triangle with texture coordinates a, b, c: the
  /// mean of Sample() at the 45 points of a barycentric lattice of step 1/8 (corners included).
  Eigen::Vector3f MeanOverTriangle(const Eigen::Vector2f& a, const Eigen::Vector2f& b,
                                   const Eigen::Vector2f& c) const;
  /// Mean linear colour of every texel, times factor.
  Eigen::Vector3f MeanColor() const;
  /// A non-empty image and a finite factor in [0, 1]; names the source.
  Status Validate() const;
};

/// An indexed triangle mesh in the world frame (metres). Triangles are counter-clockwise seen
/// from outside where that matters (it does not for ray casting: both sides are hit).
///
/// Colour of a triangle, first that applies: the texture sampled at the texture coordinates
/// interpolated over the triangle, face_albedo[triangle], the albedo of the object holding the
/// mesh. A mesh has either a texture or per-triangle colours, not both.
struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3i> triangles;
  /// Texture coordinates, one per vertex (Texture::Sample's convention), or empty: none.
  std::vector<Eigen::Vector2f> uvs;
  /// The colour map (needs uvs), or null. Shared: parts of a mesh file share a decoded image.
  std::shared_ptr<const Texture> texture;
  /// Linear-RGB colour in [0, 1] per triangle, or empty: the object's albedo (e.g. a fruit whose
  /// calyx part, of another colour, was merged into it).
  std::vector<Eigen::Vector3f> face_albedo;

  size_t num_triangles() const { return triangles.size(); }
  bool empty() const { return triangles.empty(); }
  /// True when the mesh carries colours of its own (a texture or per-triangle colours).
  bool has_own_colors() const { return texture != nullptr || !face_albedo.empty(); }
  /// Appends `other` transformed by X_WO (other's vertices are in frame O). Texture coordinates
  /// are kept where both meshes have them (or this one has no vertices yet). Colours: meshes
  /// without colours of their own stay so; a texture is kept when both share it (the same
  /// pointer) or this mesh has no triangles yet, per-triangle colours are concatenated. Any other
  /// mix becomes per-triangle colours (FaceColors()), which needs the colour of a mesh without
  /// its own: use the overload with the objects' albedos; this one throws avp::Error then.
  void Append(const TriangleMesh& other, const RigidTransform& X_WO = RigidTransform::Identity());
  /// As above; `albedo` and `other_albedo` are the colours of the objects that hold this mesh and
  /// `other`. Two meshes without colours of their own and different albedos become per-triangle
  /// colours, so the merged mesh renders each part in its own colour under object albedo `albedo`.
  void Append(const TriangleMesh& other, const RigidTransform& X_WO, const Eigen::Vector3f& albedo,
              const Eigen::Vector3f& other_albedo);
  /// The colour of every triangle: the texture's mean over the triangle
  /// (Texture::MeanOverTriangle), face_albedo, or `albedo` (the object's).
  std::vector<Eigen::Vector3f> FaceColors(const Eigen::Vector3f& albedo) const;
  /// Moves the vertices; texture coordinates and colours are unchanged.
  void Transform(const RigidTransform& X_WO);
  Box3 Bounds() const;
  /// Every index in range, every vertex finite, no degenerate (zero-area) triangles is not
  /// required; uvs empty or one per vertex, finite; a texture only with uvs, and valid;
  /// face_albedo empty or one per triangle, finite in [0, 1]; not both a texture and face_albedo.
  /// Names the first bad element.
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
  /// Base colour, linear RGB in [0, 1]; the renderer shades it. A mesh with colours of its own
  /// (a texture, per-triangle colours) renders those; albedo is then the representative colour
  /// (a texture's mean colour) used where an object has one colour (scene check, OBJ export).
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
  /// What a scene file's loader found doubtful but loadable (a placeholder material replaced,
  /// classes one colour shares, a class rule matching nothing, fruit fragments merged or
  /// dropped ...; docs/scene-format.md), one sentence each. Commands that load a scene print
  /// them; `avp scene check` lists them. Empty for the built-in scenarios.
  std::vector<std::string> warnings;

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
/// and colours (texture coordinates, per-triangle colours and textures included; same seed, same
/// scene); otherwise a description of the first difference.
std::string DescribeDifference(const Scene& a, const Scene& b);

}  // namespace avp::sim

#pragma once

#include <optional>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/sim/scene.h>

/// Small geometry primitives for procedural scenes. Every builder returns a `TriangleMesh` in a
/// local frame stated in its comment (metres); place it with `TriangleMesh::Transform` or
/// `TriangleMesh::Append(mesh, X_WO)`. Closed builders (tube with caps, box, icosphere) return
/// consistently oriented, watertight meshes with outward-facing counter-clockwise triangles.
namespace avp::sim {

/// Samples a cubic Bézier curve p0 → p3 (control points p1, p2) at `num_points` >= 2 evenly spaced
/// parameter values, both ends included.
/// @throws avp::Error if num_points < 2.
std::vector<Eigen::Vector3d> SampleCubicBezier(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                                               const Eigen::Vector3d& p2, const Eigen::Vector3d& p3,
                                               int num_points);

/// Linear interpolation of `num_points` >= 2 values from `first` to `last` (both included).
std::vector<double> LinearRadii(double first, double last, int num_points);

/// A generalised cylinder (stems, branches, petioles, cordons, wires) in world coordinates along
/// the polyline `centreline` with one radius per point. Cross-sections are regular `sides`-gons
/// oriented by parallel transport (no twist), so curved tubes do not pinch.
/// Triangles: 2·sides·(n − 1), plus sides − 2 per capped end (caps make the tube closed).
/// @throws avp::Error unless centreline.size() >= 2, radii.size() == centreline.size(), every
/// radius > 0 and finite, sides >= 3, and consecutive points are distinct.
TriangleMesh MakeTube(std::span<const Eigen::Vector3d> centreline, std::span<const double> radii_m,
                      int sides = 8, bool cap_ends = true);

/// A straight capped cylinder from p0 to p1 (a two-point tube).
TriangleMesh MakeCylinder(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, double radius_m,
                          int sides = 8, bool cap_ends = true);

/// Shape of a thin leaf blade (an open, curved surface; rays hit both sides).
struct LeafBladeParams {
  double length_m = 0.08;  ///< base to tip, along local +x
  double width_m = 0.04;   ///< maximum width, along local y
  /// Position of the widest point as a fraction of the length, in (0, 1) (0.4: ovate).
  double widest_at = 0.4;
  /// Total downward bend of the midrib from base to tip, radians (positive bends the tip to −z).
  double midrib_bend_rad = 0.5;
  /// Cupping: the margins rise by cup·(half width) above the midrib (negative: they droop).
  double cup = 0.15;
  /// Rotation of the tip about the midrib relative to the base, radians.
  double twist_rad = 0.0;
  int segments_along = 8;   ///< quads along the midrib, >= 2
  int segments_across = 3;  ///< quads from the midrib to each margin, >= 1

  /// Every bad field at once.
  Status Validate() const;
  /// 2 · segments_along · 2 · segments_across minus the 2·segments_across degenerate tip
  /// triangles that are not emitted.
  int num_triangles() const;
};

/// A leaf blade in its local frame: petiole joint at the origin, midrib starting along +x, blade
/// width along y, upper side facing +z. The outline is a smooth lanceolate/ovate curve that is zero
/// at the base and at the tip (tip triangles collapse into one point, so the tip is a fan).
/// @throws avp::Error if `params` fail Validate().
TriangleMesh MakeLeafBlade(const LeafBladeParams& params);

/// An axis-aligned box centred at the origin with the given half sizes (12 triangles, closed).
/// @throws avp::Error unless every half size is > 0.
TriangleMesh MakeBox(const Eigen::Vector3d& half_size_m);
/// A box covering `box` (world axis-aligned, 12 triangles, closed). @throws if box is empty.
TriangleMesh MakeBox(const Box3& box);

/// A flat rectangle in the local z = 0 plane, centred at the origin, normal +z (2 triangles).
/// @throws avp::Error unless both half sizes are > 0.
TriangleMesh MakeQuad(double half_x_m, double half_y_m);

/// A flat disc in the local z = 0 plane, centred at the origin, normal +z (`segments` triangles).
/// @throws avp::Error unless radius > 0 and segments >= 3.
TriangleMesh MakeDisc(double radius_m, int segments = 24);

/// A unit-radius-scaled icosphere centred at the origin: 20·4^subdivisions triangles, closed.
/// @throws avp::Error unless radius > 0 and 0 <= subdivisions <= 6.
TriangleMesh MakeIcosphere(double radius_m, int subdivisions = 2);

/// An icosphere tessellation of `ellipsoid` in world coordinates (for exporters; the renderer
/// draws ellipsoids analytically). Vertices lie on the ellipsoid surface.
TriangleMesh TessellateEllipsoid(const Ellipsoid& ellipsoid, int subdivisions = 2);

/// Mesh measures.
double SurfaceArea(const TriangleMesh& mesh);
/// Signed volume enclosed by a closed, outward-oriented mesh (divergence theorem).
double SignedVolume(const TriangleMesh& mesh);
/// True when every directed edge (a, b) is matched by exactly one opposite edge (b, a): the mesh is
/// watertight and consistently oriented (indices, not positions, are compared).
bool IsClosed(const TriangleMesh& mesh);

/// Splits a mesh into connected components. Triangles are connected when they share a vertex
/// index or a vertex position (exactly equal coordinates), so unwelded meshes are handled too.
/// Components are returned in the order of their first triangle, each with compacted vertices
/// (and their texture coordinates), the texture and its triangles' colours.
std::vector<TriangleMesh> ConnectedComponents(const TriangleMesh& mesh);

/// `n` >= 1 nearly evenly spread unit vectors (Fibonacci lattice), deterministic.
std::vector<Eigen::Vector3d> FibonacciSphere(int n);

/// Answers "does the segment a → b cross a triangle?" over a set of meshes: brute force over
/// chunks of up to 32 consecutive triangles, each culled by its bounding box. Meant for scene
/// generation (thousands of queries against ~10^5 triangles), not for rendering.
class SegmentOcclusionTester {
 public:
  /// Adds the mesh's triangles (world coordinates).
  void Add(const TriangleMesh& mesh);
  /// True when a triangle crosses the open segment (a, b), ignoring hits within 1e-6 of either end.
  bool IsBlocked(const Eigen::Vector3d& a, const Eigen::Vector3d& b) const;
  size_t num_triangles() const { return v0_.size(); }

 private:
  struct Chunk {
    Box3 box;
    size_t first = 0;
    size_t count = 0;
  };
  std::vector<Eigen::Vector3d> v0_, e1_, e2_;
  std::vector<Chunk> chunks_;
};

// ---- Scene-generation helpers shared by the procedural plants -----------------------------------

/// Makes a plant hide its fruit from one viewpoint: after the plant is grown, fruit surface points
/// that can be seen from `eye_W` within the cone (`view_direction_W`, `cone_half_angle_deg`) are
/// covered by extra leaves, one at a time, until none is visible or `max_leaves` were added.
/// Only leaves, stems and supports count as occluders (a fruit behind a fruit is still a fruit).
struct OcclusionScreen {
  bool enabled = false;
  Eigen::Vector3d eye_W = Eigen::Vector3d(0.22, 0.0, 0.677);
  Eigen::Vector3d view_direction_W = Eigen::Vector3d::UnitX();
  /// Half opening of the checked view cone; 45 deg covers a D435 (69 x 42.5 deg) with margin.
  double cone_half_angle_deg = 45.0;
  /// Surface points sampled per fruit (those facing the eye are tested).
  int samples_per_fruit = 160;
  int max_leaves = 150;

  /// Every bad field at once (only checked when enabled).
  Status Validate() const;
};

/// The bookkeeping behind OcclusionScreen: samples the fruit ellipsoids' surfaces, keeps the points
/// that face the eye inside the view cone, and reports one that no occluder hides yet. Occluders
/// only ever get added, so a hidden sample is never tested again.
class FruitVisibility {
 public:
  /// @throws avp::Error if `screen` fails Validate().
  FruitVisibility(const OcclusionScreen& screen, std::span<const Ellipsoid> fruits);
  void AddOccluder(const TriangleMesh& mesh) { occluders_.Add(mesh); }
  /// Adds the mesh of every non-fruit object in scene.objects[first_object, end).
  void AddSceneOccluders(const Scene& scene, size_t first_object);
  /// A fruit surface point (slightly lifted off the surface) still visible from the eye, with the
  /// index of its fruit; nullopt when every sample is hidden.
  std::optional<std::pair<Eigen::Vector3d, size_t>> FindVisible();
  /// Samples still visible (re-tests every remaining sample).
  int CountVisible();
  size_t num_samples() const { return num_samples_; }

 private:
  struct Sample {
    Eigen::Vector3d p_W;
    size_t fruit = 0;
  };
  Eigen::Vector3d eye_W_;
  std::vector<Sample> pending_;  // samples not yet known to be hidden
  size_t num_samples_ = 0;
  SegmentOcclusionTester occluders_;
};

/// The centre of a leaf that hides fruit point `p_W` from `eye_W`: the first point on the line of
/// sight at distance min_distance_m, min_distance_m + 1 cm, ... (< 0.25 m; each with up to 1 cm of
/// jitter from `rng`) that lies at least `clearance_m` outside every fruit's bounding sphere.
Eigen::Vector3d ScreenLeafCentre(const Eigen::Vector3d& p_W, const Eigen::Vector3d& eye_W,
                                 std::span<const Ellipsoid> fruits, double min_distance_m,
                                 double clearance_m, Rng& rng);

/// A rotation whose x axis is `direction` (normalised) and whose z axis is as close as possible
/// to `up_hint` (the frame of a leaf blade: x along the midrib, z the upper side). Falls back to
/// any perpendicular z when the two are parallel. @throws avp::Error if direction is zero.
Eigen::Matrix3d RotationWithXAxis(const Eigen::Vector3d& direction, const Eigen::Vector3d& up_hint);

/// An albedo scaled by a common factor in [1 − spread, 1 + spread] and per-channel factors in
/// [1 − spread/2, 1 + spread/2], clamped to [0, 1] (organ-to-organ colour variation).
Eigen::Vector3f VaryAlbedo(const Eigen::Vector3f& albedo, double spread, Rng& rng);

/// A rotation whose z axis is `direction` (normalised; any perpendicular x axis, chosen
/// deterministically). @throws avp::Error if direction is zero or not finite.
Eigen::Matrix3d RotationWithZAxis(const Eigen::Vector3d& direction);

}  // namespace avp::sim

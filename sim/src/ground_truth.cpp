// Fruit-surface voxels for evaluation.
//
// A voxel is the closed cube [k s, (k + 1) s]^3 (VoxelKey lattice). It is a surface voxel when the
// fruit's surface passes through it:
//
// * Ellipsoid: f(p) = |A (p - c)|^2 - 1 is continuous and convex, and the cube is connected, so the
//   surface meets the cube iff min_cube f <= 0 <= max_cube f. Both extremes are computed exactly
//   (up to rounding), so thin crossings (the surface clipping a cube edge or face between corners)
//   are not missed:
//     - max_cube f is attained at a corner (convex function over a polytope);
//     - min_cube f: if any corner is <= 0 the minimum is too; otherwise it is the convex quadratic
//       program min (p - c)^T A^T A (p - c) over the cube, solved by enumerating its 27 KKT cases
//       (each coordinate free, at its lower or at its upper bound): the minimiser lies in the
//       relative interior of one face, edge, vertex or the cube itself, where it is the
//       unconstrained minimiser over that face's affine hull. Every candidate is clamped into the
//       cube and evaluated there, so rounding can only over-estimate the minimum by ~1e-16.
//   A voxel whose centre is further than the cube's half-diagonal (measured in the ellipsoid's
//   unit-sphere frame) from the unit sphere is rejected before that.
// * Triangle mesh: the union over triangles of the voxels that overlap the triangle, by the
//   separating-axis test of Akenine-Moeller ("Fast 3D triangle-box overlap testing", 2001):
//   13 axes (3 box normals, the triangle normal, 9 edge cross products); touching counts.
//
// Only voxels in each fruit's bounding box (each triangle's, for meshes) are visited.

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/Dense>
#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/sim/ground_truth.h>

namespace avp::sim {
namespace {

/// Guard against absurd voxel sizes: at most this many voxels in one fruit's bounding box.
constexpr double kMaxVoxelsPerFruit = 1u << 27;

struct KeyRange {
  std::array<int64_t, 3> lo{};
  std::array<int64_t, 3> hi{};  // inclusive

  int64_t Count() const { return (hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1); }
};

KeyRange RangeOf(const Box3& box, double s, const std::string& name) {
  KeyRange r;
  double count = 1.0;
  for (int a = 0; a < 3; ++a) {
    const double lo = std::floor(box.min()[a] / s);
    const double hi = std::floor(box.max()[a] / s);
    const double kLimit = std::numeric_limits<int32_t>::max() - 1.0;
    AVP_THROW_UNLESS(std::abs(lo) <= kLimit && std::abs(hi) <= kLimit, name, s, box.ToString());
    r.lo[a] = static_cast<int64_t>(lo);
    r.hi[a] = static_cast<int64_t>(hi);
    count *= hi - lo + 1.0;
  }
  AVP_THROW_UNLESS(count <= kMaxVoxelsPerFruit, name, s, count, kMaxVoxelsPerFruit);
  return r;
}

/// min over y in [lo, hi] of y^T Q y (Q symmetric positive definite), exact up to rounding.
double MinQuadraticOverBox(const Eigen::Matrix3d& Q, const Eigen::Vector3d& lo,
                           const Eigen::Vector3d& hi) {
  double best = std::numeric_limits<double>::infinity();
  for (int mask = 0; mask < 27; ++mask) {
    std::array<int, 3> state{mask % 3, (mask / 3) % 3, mask / 9};  // 0 free, 1 lo, 2 hi
    Eigen::Vector3d y = Eigen::Vector3d::Zero();
    std::array<int, 3> free{};
    int num_free = 0;
    for (int a = 0; a < 3; ++a) {
      if (state[a] == 0) {
        free[num_free++] = a;
      } else {
        y[a] = state[a] == 1 ? lo[a] : hi[a];
      }
    }
    if (num_free > 0) {
      // Q_FF y_F = -Q_FB y_B (y_F is zero in y, so Q y restricted to F is Q_FB y_B).
      const Eigen::Vector3d Qy = Q * y;
      if (num_free == 1) {
        const int f = free[0];
        y[f] = -Qy[f] / Q(f, f);
      } else if (num_free == 2) {
        Eigen::Matrix2d M;
        M << Q(free[0], free[0]), Q(free[0], free[1]), Q(free[1], free[0]), Q(free[1], free[1]);
        const Eigen::Vector2d sol = M.ldlt().solve(-Eigen::Vector2d(Qy[free[0]], Qy[free[1]]));
        y[free[0]] = sol[0];
        y[free[1]] = sol[1];
      }  // num_free == 3: y = 0, the unconstrained minimiser
      bool feasible = true;
      for (int i = 0; i < num_free; ++i) {
        const int f = free[i];
        const double tol = 1e-12 * (hi[f] - lo[f]);
        if (!(y[f] >= lo[f] - tol && y[f] <= hi[f] + tol)) feasible = false;
        y[f] = std::clamp(y[f], lo[f], hi[f]);
      }
      if (!feasible) continue;
    }
    best = std::min(best, y.dot(Q * y));
  }
  return best;
}

template <typename Emit>
void VoxelizeEllipsoid(const Ellipsoid& e, double s, const std::string& name, Emit&& emit) {
  const KeyRange r = RangeOf(e.Bounds(), s, name);
  const Eigen::Matrix3d A = e.radii.cwiseInverse().asDiagonal() * e.R_WE.transpose();
  const Eigen::Matrix3d Q = A.transpose() * A;
  const double half_diag_unit = 0.5 * std::sqrt(3.0) * s / e.radii.minCoeff();
  auto f = [&](const Eigen::Vector3d& p) { return (A * (p - e.center_W)).squaredNorm() - 1.0; };

  // Corner values of two z-layers of the lattice: corner (i, j) at layer k is (lo + (i,j,k)) s.
  const int64_t nx = r.hi[0] - r.lo[0] + 2;
  const int64_t ny = r.hi[1] - r.lo[1] + 2;
  std::vector<double> below(static_cast<size_t>(nx * ny));
  std::vector<double> above(below.size());
  auto fill_layer = [&](int64_t kz, std::vector<double>& layer) {
    for (int64_t j = 0; j < ny; ++j) {
      for (int64_t i = 0; i < nx; ++i) {
        layer[j * nx + i] = f(Eigen::Vector3d((r.lo[0] + i) * s, (r.lo[1] + j) * s, kz * s));
      }
    }
  };
  fill_layer(r.lo[2], below);
  for (int64_t kz = r.lo[2]; kz <= r.hi[2]; ++kz) {
    fill_layer(kz + 1, above);
    for (int64_t j = 0; j + 1 < ny; ++j) {
      for (int64_t i = 0; i + 1 < nx; ++i) {
        const size_t c = static_cast<size_t>(j * nx + i);
        const std::array<double, 8> corners = {below[c],          below[c + 1],     below[c + nx],
                                               below[c + nx + 1], above[c],         above[c + 1],
                                               above[c + nx],     above[c + nx + 1]};
        const double fmin = *std::min_element(corners.begin(), corners.end());
        const double fmax = *std::max_element(corners.begin(), corners.end());
        const VoxelKey key{static_cast<int32_t>(r.lo[0] + i), static_cast<int32_t>(r.lo[1] + j),
                           static_cast<int32_t>(kz)};
        if (fmax < 0.0) continue;  // the whole cube is inside
        if (fmin <= 0.0) {         // corners on both sides
          emit(key);
          continue;
        }
        // All corners outside: does the cube still dip into the ellipsoid?
        const Eigen::Vector3d lo = Eigen::Vector3d(key.x, key.y, key.z) * s - e.center_W;
        const Eigen::Vector3d hi = lo + Eigen::Vector3d::Constant(s);
        const Eigen::Vector3d centre = 0.5 * (lo + hi);
        if ((A * centre).norm() - half_diag_unit > 1.0) continue;
        if (MinQuadraticOverBox(Q, lo, hi) <= 1.0) emit(key);
      }
    }
    std::swap(below, above);
  }
}

/// Separating-axis triangle / axis-aligned box overlap; the box is centred at the origin with
/// half extent h, the triangle (a, b, c) is given relative to the box centre. Closed sets.
bool TriangleBoxOverlap(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                        const Eigen::Vector3d& c, const Eigen::Vector3d& h) {
  // Box face normals: the triangle's AABB against the box.
  for (int k = 0; k < 3; ++k) {
    if (std::min({a[k], b[k], c[k]}) > h[k] || std::max({a[k], b[k], c[k]}) < -h[k]) return false;
  }
  const std::array<Eigen::Vector3d, 3> edges = {b - a, c - b, a - c};
  // Triangle normal: the plane against the box.
  const Eigen::Vector3d n = edges[0].cross(edges[1]);
  if (std::abs(n.dot(a)) > h.dot(n.cwiseAbs())) return false;
  // Nine edge x box-axis cross products.
  for (const Eigen::Vector3d& e : edges) {
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d axis = Eigen::Vector3d::Unit(k).cross(e);
      const double pa = axis.dot(a);
      const double pb = axis.dot(b);
      const double pc = axis.dot(c);
      const double radius = h.dot(axis.cwiseAbs());
      if (std::min({pa, pb, pc}) > radius || std::max({pa, pb, pc}) < -radius) return false;
    }
  }
  return true;
}

template <typename Emit>
void VoxelizeMesh(const TriangleMesh& mesh, double s, const std::string& name, Emit&& emit) {
  (void)RangeOf(mesh.Bounds(), s, name);  // checks the voxel count of the whole fruit
  const Eigen::Vector3d half = Eigen::Vector3d::Constant(0.5 * s);
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d v0 = mesh.vertices[t.x()].cast<double>();
    const Eigen::Vector3d v1 = mesh.vertices[t.y()].cast<double>();
    const Eigen::Vector3d v2 = mesh.vertices[t.z()].cast<double>();
    Box3 box;
    box.Extend(v0);
    box.Extend(v1);
    box.Extend(v2);
    // A vertex exactly on a voxel face also touches the voxel below: widen by one key there.
    const KeyRange r = RangeOf(box, s, name);
    for (int64_t z = r.lo[2] - 1; z <= r.hi[2]; ++z) {
      for (int64_t y = r.lo[1] - 1; y <= r.hi[1]; ++y) {
        for (int64_t x = r.lo[0] - 1; x <= r.hi[0]; ++x) {
          const Eigen::Vector3d centre((x + 0.5) * s, (y + 0.5) * s, (z + 0.5) * s);
          if (TriangleBoxOverlap(v0 - centre, v1 - centre, v2 - centre, half)) {
            emit(VoxelKey{static_cast<int32_t>(x), static_cast<int32_t>(y),
                          static_cast<int32_t>(z)});
          }
        }
      }
    }
  }
}

}  // namespace

std::vector<VoxelKey> FruitVoxels::SortedKeys() const {
  std::vector<VoxelKey> keys;
  keys.reserve(voxels.size());
  for (const auto& [key, id] : voxels) keys.push_back(key);
  std::sort(keys.begin(), keys.end());
  return keys;
}

namespace {

/// emit(object, key) for every voxel the surface of every object `keep(object)` accepts passes
/// through. `caller` names the function in errors.
template <typename Keep, typename Emit>
void VoxelizeObjects(const Scene& scene, double voxel_size_m, const char* caller, Keep&& keep,
                     Emit&& emit) {
  AVP_THROW_UNLESS(std::isfinite(voxel_size_m) && voxel_size_m > 0.0, voxel_size_m);
  const Status valid = scene.Validate();
  if (!valid.ok()) throw Error(fmt::format("{}: invalid scene: {}", caller, valid.ToString()));
  for (const SceneObject& object : scene.objects) {
    if (!keep(object)) continue;
    auto emit_key = [&](const VoxelKey& key) { emit(object, key); };
    if (const auto* e = std::get_if<Ellipsoid>(&object.shape)) {
      AVP_THROW_UNLESS(IsRotationMatrix(e->R_WE, 1e-6), object.name, e->R_WE);
      VoxelizeEllipsoid(*e, voxel_size_m, object.name, emit_key);
    } else {
      const TriangleMesh& mesh = std::get<TriangleMesh>(object.shape);
      if (!mesh.empty()) VoxelizeMesh(mesh, voxel_size_m, object.name, emit_key);
    }
  }
}

}  // namespace

FruitVoxels VoxelizeFruitSurfaces(const Scene& scene, double voxel_size_m) {
  FruitVoxels out;
  out.voxel_size_m = voxel_size_m;
  VoxelizeObjects(
      scene, voxel_size_m, "VoxelizeFruitSurfaces",
      [](const SceneObject& o) { return o.semantic_class == SemanticClass::kFruit; },
      [&](const SceneObject& o, const VoxelKey& key) {
        auto [it, inserted] = out.voxels.emplace(key, o.instance_id);
        if (!inserted) it->second = std::min(it->second, o.instance_id);
      });
  return out;
}

std::vector<VoxelKey> VoxelizeObstacleSurfaces(const Scene& scene, double voxel_size_m) {
  std::vector<VoxelKey> keys;
  VoxelizeObjects(
      scene, voxel_size_m, "VoxelizeObstacleSurfaces",
      [](const SceneObject& o) {
        return o.semantic_class != SemanticClass::kBackground &&
               o.semantic_class != SemanticClass::kGround;
      },
      [&](const SceneObject&, const VoxelKey& key) { keys.push_back(key); });
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  return keys;
}

}  // namespace avp::sim

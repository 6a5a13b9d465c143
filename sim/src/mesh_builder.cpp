#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <numeric>
#include <string>
#include <unordered_map>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/core/ray.h>
#include <avp/sim/mesh_builder.h>

namespace avp::sim {

namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Vector3f ToFloat(const Eigen::Vector3d& p) { return p.cast<float>(); }

/// Any unit vector perpendicular to unit `t`, chosen deterministically.
Eigen::Vector3d AnyPerpendicular(const Eigen::Vector3d& t) {
  const Eigen::Vector3d helper =
      std::abs(t.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return (helper - helper.dot(t) * t).normalized();
}

/// Union-find with path halving.
class DisjointSets {
 public:
  explicit DisjointSets(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0); }
  size_t Find(size_t i) {
    while (parent_[i] != i) {
      parent_[i] = parent_[parent_[i]];
      i = parent_[i];
    }
    return i;
  }
  void Union(size_t a, size_t b) {
    a = Find(a);
    b = Find(b);
    if (a == b) return;
    if (a < b) {
      parent_[b] = a;
    } else {
      parent_[a] = b;
    }
  }

 private:
  std::vector<size_t> parent_;
};

}  // namespace

std::vector<Eigen::Vector3d> SampleCubicBezier(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                                               const Eigen::Vector3d& p2, const Eigen::Vector3d& p3,
                                               int num_points) {
  AVP_THROW_UNLESS(num_points >= 2, num_points);
  std::vector<Eigen::Vector3d> points;
  points.reserve(static_cast<size_t>(num_points));
  for (int i = 0; i < num_points; ++i) {
    const double t = static_cast<double>(i) / (num_points - 1);
    const double s = 1.0 - t;
    points.push_back(s * s * s * p0 + 3.0 * s * s * t * p1 + 3.0 * s * t * t * p2 + t * t * t * p3);
  }
  return points;
}

std::vector<double> LinearRadii(double first, double last, int num_points) {
  AVP_THROW_UNLESS(num_points >= 2, num_points);
  std::vector<double> radii(static_cast<size_t>(num_points));
  for (int i = 0; i < num_points; ++i) {
    const double t = static_cast<double>(i) / (num_points - 1);
    radii[static_cast<size_t>(i)] = first + (last - first) * t;
  }
  return radii;
}

TriangleMesh MakeTube(std::span<const Eigen::Vector3d> centreline, std::span<const double> radii_m,
                      int sides, bool cap_ends) {
  const size_t n = centreline.size();
  AVP_THROW_UNLESS(n >= 2 && radii_m.size() == n, n, radii_m.size());
  AVP_THROW_UNLESS(sides >= 3, sides);
  for (size_t i = 0; i < n; ++i) {
    AVP_THROW_UNLESS(std::isfinite(radii_m[i]) && radii_m[i] > 0.0, i, radii_m[i]);
    AVP_THROW_UNLESS(centreline[i].allFinite(), i, centreline[i].transpose());
    if (i > 0) {
      const double step = (centreline[i] - centreline[i - 1]).norm();
      AVP_THROW_UNLESS(step > 1e-9, i, step);
    }
  }

  // Tangents: central differences inside, one-sided at the ends.
  std::vector<Eigen::Vector3d> tangents(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& a = centreline[i == 0 ? 0 : i - 1];
    const Eigen::Vector3d& b = centreline[i + 1 == n ? n - 1 : i + 1];
    Eigen::Vector3d t = b - a;
    if (t.norm() < 1e-12) t = centreline[i] - centreline[i - 1];  // a hairpin: use the incoming
    tangents[i] = t.normalized();
  }

  TriangleMesh mesh;
  mesh.vertices.reserve(n * static_cast<size_t>(sides));
  // Parallel transport of the section frame: project the previous normal onto the new section
  // plane; if the tube turns by ~90 degrees within one step, restart from any perpendicular.
  Eigen::Vector3d normal = AnyPerpendicular(tangents[0]);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& t = tangents[i];
    if (i > 0) {
      Eigen::Vector3d projected = normal - normal.dot(t) * t;
      normal = projected.norm() > 1e-6 ? projected.normalized() : AnyPerpendicular(t);
    }
    const Eigen::Vector3d binormal = t.cross(normal);
    for (int k = 0; k < sides; ++k) {
      const double theta = 2.0 * kPi * k / sides;
      mesh.vertices.push_back(ToFloat(
          centreline[i] + radii_m[i] * (std::cos(theta) * normal + std::sin(theta) * binormal)));
    }
  }

  mesh.triangles.reserve(2 * static_cast<size_t>(sides) * (n - 1) +
                         (cap_ends ? 2 * static_cast<size_t>(sides - 2) : 0));
  for (size_t i = 0; i + 1 < n; ++i) {
    const int a = static_cast<int>(i) * sides;
    const int b = a + sides;
    for (int k = 0; k < sides; ++k) {
      const int k1 = (k + 1) % sides;
      mesh.triangles.emplace_back(a + k, a + k1, b + k1);
      mesh.triangles.emplace_back(a + k, b + k1, b + k);
    }
  }
  if (cap_ends) {
    const int last = static_cast<int>(n - 1) * sides;
    for (int k = 1; k + 1 < sides; ++k) {
      mesh.triangles.emplace_back(0, k + 1, k);                   // faces −t at the start
      mesh.triangles.emplace_back(last, last + k, last + k + 1);  // faces +t at the end
    }
  }
  return mesh;
}

TriangleMesh MakeCylinder(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, double radius_m,
                          int sides, bool cap_ends) {
  const std::array<Eigen::Vector3d, 2> line = {p0, p1};
  const std::array<double, 2> radii = {radius_m, radius_m};
  return MakeTube(line, radii, sides, cap_ends);
}

Status LeafBladeParams::Validate() const {
  std::vector<std::string> errors;
  if (!(std::isfinite(length_m) && length_m > 0.0)) {
    errors.push_back(fmt::format("length_m ({}) must be > 0", length_m));
  }
  if (!(std::isfinite(width_m) && width_m > 0.0)) {
    errors.push_back(fmt::format("width_m ({}) must be > 0", width_m));
  }
  if (!(widest_at > 0.0 && widest_at < 1.0)) {
    errors.push_back(fmt::format("widest_at ({}) must be in (0, 1)", widest_at));
  }
  if (!std::isfinite(midrib_bend_rad) || std::abs(midrib_bend_rad) > kPi) {
    errors.push_back(fmt::format("midrib_bend_rad ({}) must be in [-pi, pi]", midrib_bend_rad));
  }
  if (!std::isfinite(cup) || std::abs(cup) > 2.0) {
    errors.push_back(fmt::format("cup ({}) must be in [-2, 2]", cup));
  }
  if (!std::isfinite(twist_rad) || std::abs(twist_rad) > kPi) {
    errors.push_back(fmt::format("twist_rad ({}) must be in [-pi, pi]", twist_rad));
  }
  if (segments_along < 2 || segments_along > 64) {
    errors.push_back(fmt::format("segments_along ({}) must be in [2, 64]", segments_along));
  }
  if (segments_across < 1 || segments_across > 32) {
    errors.push_back(fmt::format("segments_across ({}) must be in [1, 32]", segments_across));
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid leaf blade: {}", fmt::join(errors, "; ")));
}

int LeafBladeParams::num_triangles() const {
  return 2 * segments_across * (2 * segments_along - 1);
}

TriangleMesh MakeLeafBlade(const LeafBladeParams& params) {
  const Status status = params.Validate();
  AVP_THROW_UNLESS(status.ok(), status.message());
  const int na = params.segments_along;
  const int columns = 2 * params.segments_across + 1;  // v = -1 ... +1
  const double L = params.length_m;
  const double a = params.widest_at;

  // Half-width profile: a sine bump reparametrised so that its maximum sits at `widest_at`; the
  // base keeps a narrow 8 % stalk so the first row does not collapse.
  const auto half_width = [&](double u) {
    const double g = u < a ? 0.5 * u / a : 0.5 + 0.5 * (u - a) / (1.0 - a);
    const double s = std::sin(kPi * g);
    return 0.5 * params.width_m * std::max(s, u < a ? 0.08 : 0.0);
  };

  TriangleMesh mesh;
  mesh.vertices.reserve(static_cast<size_t>(na * columns + 1));
  // March the midrib as a planar arc in the xz plane: tangent angle phi(s) = -bend * s / L.
  Eigen::Vector3d midrib = Eigen::Vector3d::Zero();
  const double ds = L / na;
  for (int i = 0; i <= na; ++i) {
    const double u = static_cast<double>(i) / na;
    if (i > 0) {
      const double phi_mid = -params.midrib_bend_rad * (u - 0.5 / na);
      midrib += ds * Eigen::Vector3d(std::cos(phi_mid), 0.0, std::sin(phi_mid));
    }
    if (i == na) {  // the tip: one vertex shared by the last row of triangles
      mesh.vertices.push_back(ToFloat(midrib));
      break;
    }
    const double phi = -params.midrib_bend_rad * u;
    const Eigen::Vector3d up(-std::sin(phi), 0.0, std::cos(phi));  // blade normal at the midrib
    const double tau = params.twist_rad * u;
    const Eigen::Vector3d lateral = std::cos(tau) * Eigen::Vector3d::UnitY() + std::sin(tau) * up;
    const Eigen::Vector3d lift = -std::sin(tau) * Eigen::Vector3d::UnitY() + std::cos(tau) * up;
    const double w = half_width(u);
    for (int j = 0; j < columns; ++j) {
      const double v = -1.0 + 2.0 * j / (columns - 1);
      mesh.vertices.push_back(ToFloat(midrib + v * w * lateral + params.cup * w * v * v * lift));
    }
  }

  const int tip = na * columns;
  mesh.triangles.reserve(static_cast<size_t>(params.num_triangles()));
  for (int i = 0; i < na; ++i) {
    for (int j = 0; j + 1 < columns; ++j) {
      const int p00 = i * columns + j;
      const int p01 = p00 + 1;
      if (i + 1 == na) {
        mesh.triangles.emplace_back(p00, tip, p01);
      } else {
        const int p10 = p00 + columns;
        const int p11 = p10 + 1;
        mesh.triangles.emplace_back(p00, p10, p11);
        mesh.triangles.emplace_back(p00, p11, p01);
      }
    }
  }
  return mesh;
}

TriangleMesh MakeBox(const Eigen::Vector3d& half_size_m) {
  AVP_THROW_UNLESS(half_size_m.allFinite() && (half_size_m.array() > 0.0).all(),
                   half_size_m.transpose());
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i) {
    mesh.vertices.push_back(ToFloat(Eigen::Vector3d((i & 1) ? half_size_m.x() : -half_size_m.x(),
                                                    (i & 2) ? half_size_m.y() : -half_size_m.y(),
                                                    (i & 4) ? half_size_m.z() : -half_size_m.z())));
  }
  // Corner index bits: x = 1, y = 2, z = 4. Two outward counter-clockwise triangles per face.
  const int faces[6][4] = {
      {0, 2, 3, 1},  // -z
      {4, 5, 7, 6},  // +z
      {0, 1, 5, 4},  // -y
      {2, 6, 7, 3},  // +y
      {0, 4, 6, 2},  // -x
      {1, 3, 7, 5},  // +x
  };
  for (const auto& f : faces) {
    mesh.triangles.emplace_back(f[0], f[1], f[2]);
    mesh.triangles.emplace_back(f[0], f[2], f[3]);
  }
  return mesh;
}

TriangleMesh MakeBox(const Box3& box) {
  AVP_THROW_UNLESS(!box.IsEmpty() && (box.size().array() > 0.0).all(), box.ToString());
  TriangleMesh mesh = MakeBox(Eigen::Vector3d(0.5 * box.size()));
  mesh.Transform(RigidTransform(box.center()));
  return mesh;
}

TriangleMesh MakeQuad(double half_x_m, double half_y_m) {
  AVP_THROW_UNLESS(half_x_m > 0.0 && half_y_m > 0.0, half_x_m, half_y_m);
  TriangleMesh mesh;
  mesh.vertices = {ToFloat({-half_x_m, -half_y_m, 0.0}), ToFloat({half_x_m, -half_y_m, 0.0}),
                   ToFloat({half_x_m, half_y_m, 0.0}), ToFloat({-half_x_m, half_y_m, 0.0})};
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
  return mesh;
}

TriangleMesh MakeDisc(double radius_m, int segments) {
  AVP_THROW_UNLESS(radius_m > 0.0 && segments >= 3, radius_m, segments);
  TriangleMesh mesh;
  mesh.vertices.push_back(Eigen::Vector3f::Zero());
  for (int k = 0; k < segments; ++k) {
    const double theta = 2.0 * kPi * k / segments;
    mesh.vertices.push_back(ToFloat({radius_m * std::cos(theta), radius_m * std::sin(theta), 0.0}));
  }
  for (int k = 0; k < segments; ++k) {
    mesh.triangles.emplace_back(0, 1 + k, 1 + (k + 1) % segments);
  }
  return mesh;
}

TriangleMesh MakeIcosphere(double radius_m, int subdivisions) {
  AVP_THROW_UNLESS(radius_m > 0.0 && subdivisions >= 0 && subdivisions <= 6, radius_m,
                   subdivisions);
  const double phi = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, phi, 0}, {1, phi, 0}, {-1, -phi, 0}, {1, -phi, 0},
                                    {0, -1, phi}, {0, 1, phi}, {0, -1, -phi}, {0, 1, -phi},
                                    {phi, 0, -1}, {phi, 0, 1}, {-phi, 0, -1}, {-phi, 0, 1}};
  for (Eigen::Vector3d& p : v) p.normalize();
  std::vector<Eigen::Vector3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int level = 0; level < subdivisions; ++level) {
    std::map<std::pair<int, int>, int> midpoints;
    const auto midpoint = [&](int a, int b) {
      const std::pair<int, int> key = a < b ? std::make_pair(a, b) : std::make_pair(b, a);
      const auto it = midpoints.find(key);
      if (it != midpoints.end()) return it->second;
      v.push_back((v[static_cast<size_t>(a)] + v[static_cast<size_t>(b)]).normalized());
      const int index = static_cast<int>(v.size()) - 1;
      midpoints.emplace(key, index);
      return index;
    };
    std::vector<Eigen::Vector3i> next;
    next.reserve(f.size() * 4);
    for (const Eigen::Vector3i& t : f) {
      const int ab = midpoint(t[0], t[1]);
      const int bc = midpoint(t[1], t[2]);
      const int ca = midpoint(t[2], t[0]);
      next.emplace_back(t[0], ab, ca);
      next.emplace_back(t[1], bc, ab);
      next.emplace_back(t[2], ca, bc);
      next.emplace_back(ab, bc, ca);
    }
    f = std::move(next);
  }
  TriangleMesh mesh;
  mesh.vertices.reserve(v.size());
  for (const Eigen::Vector3d& p : v) mesh.vertices.push_back(ToFloat(radius_m * p));
  mesh.triangles = std::move(f);
  return mesh;
}

TriangleMesh TessellateEllipsoid(const Ellipsoid& ellipsoid, int subdivisions) {
  TriangleMesh mesh = MakeIcosphere(1.0, subdivisions);
  for (Eigen::Vector3f& p : mesh.vertices) {
    p = ToFloat(ellipsoid.center_W +
                ellipsoid.R_WE * ellipsoid.radii.cwiseProduct(p.cast<double>()));
  }
  return mesh;
}

double SurfaceArea(const TriangleMesh& mesh) {
  double area = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[static_cast<size_t>(t[0])].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[static_cast<size_t>(t[1])].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[static_cast<size_t>(t[2])].cast<double>();
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  return area;
}

double SignedVolume(const TriangleMesh& mesh) {
  double volume = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[static_cast<size_t>(t[0])].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[static_cast<size_t>(t[1])].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[static_cast<size_t>(t[2])].cast<double>();
    volume += a.dot(b.cross(c)) / 6.0;
  }
  return volume;
}

bool IsClosed(const TriangleMesh& mesh) {
  if (mesh.triangles.empty()) return false;
  // Count directed edges; a closed oriented mesh has count(a, b) == count(b, a) == 1.
  std::map<std::pair<int, int>, int> edges;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const int a = t[k];
      const int b = t[(k + 1) % 3];
      if (a == b) return false;
      if (++edges[{a, b}] > 1) return false;
    }
  }
  for (const auto& [edge, count] : edges) {
    const auto it = edges.find({edge.second, edge.first});
    if (it == edges.end() || it->second != 1) return false;
  }
  return true;
}

std::vector<TriangleMesh> ConnectedComponents(const TriangleMesh& mesh) {
  const size_t nv = mesh.vertices.size();
  DisjointSets sets(nv);
  // Weld equal positions (bitwise-equal floats; -0 and +0 compare equal after normalising).
  struct KeyHash {
    size_t operator()(const std::array<uint32_t, 3>& k) const {
      uint64_t h = 0xcbf29ce484222325ULL;
      for (uint32_t x : k) h = (h ^ x) * 0x100000001b3ULL;
      return static_cast<size_t>(h);
    }
  };
  std::unordered_map<std::array<uint32_t, 3>, size_t, KeyHash> first_at;
  first_at.reserve(nv);
  for (size_t i = 0; i < nv; ++i) {
    std::array<uint32_t, 3> key;
    for (int k = 0; k < 3; ++k) {
      const float c = mesh.vertices[i][k] == 0.0f ? 0.0f : mesh.vertices[i][k];
      std::memcpy(&key[static_cast<size_t>(k)], &c, sizeof(float));
    }
    const auto [it, inserted] = first_at.emplace(key, i);
    if (!inserted) sets.Union(i, it->second);
  }
  for (const Eigen::Vector3i& t : mesh.triangles) {
    sets.Union(static_cast<size_t>(t[0]), static_cast<size_t>(t[1]));
    sets.Union(static_cast<size_t>(t[0]), static_cast<size_t>(t[2]));
  }

  std::vector<TriangleMesh> components;
  std::unordered_map<size_t, size_t> component_of_root;
  std::vector<int> new_index(nv, -1);
  // Texture coordinates, the texture and per-triangle colours go with their vertices/triangles.
  const bool uvs = mesh.uvs.size() == nv;
  const bool faces = mesh.face_albedo.size() == mesh.triangles.size();
  for (size_t ti = 0; ti < mesh.triangles.size(); ++ti) {
    const Eigen::Vector3i& t = mesh.triangles[ti];
    const size_t root = sets.Find(static_cast<size_t>(t[0]));
    auto [it, inserted] = component_of_root.emplace(root, components.size());
    if (inserted) {
      components.emplace_back();
      components.back().texture = mesh.texture;
    }
    TriangleMesh& out = components[it->second];
    Eigen::Vector3i mapped;
    for (int k = 0; k < 3; ++k) {
      const size_t vi = static_cast<size_t>(t[k]);
      if (new_index[vi] < 0) {
        new_index[vi] = static_cast<int>(out.vertices.size());
        out.vertices.push_back(mesh.vertices[vi]);
        if (uvs) out.uvs.push_back(mesh.uvs[vi]);
      }
      mapped[k] = new_index[vi];
    }
    out.triangles.push_back(mapped);
    if (faces && !mesh.face_albedo.empty()) out.face_albedo.push_back(mesh.face_albedo[ti]);
  }
  return components;
}

std::vector<Eigen::Vector3d> FibonacciSphere(int n) {
  AVP_THROW_UNLESS(n >= 1, n);
  std::vector<Eigen::Vector3d> points;
  points.reserve(static_cast<size_t>(n));
  const double golden_angle = kPi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double theta = golden_angle * i;
    points.emplace_back(r * std::cos(theta), r * std::sin(theta), z);
  }
  return points;
}

void SegmentOcclusionTester::Add(const TriangleMesh& mesh) {
  constexpr size_t kChunk = 32;
  for (size_t first = 0; first < mesh.triangles.size(); first += kChunk) {
    Chunk chunk;
    chunk.first = v0_.size();
    const size_t end = std::min(mesh.triangles.size(), first + kChunk);
    for (size_t i = first; i < end; ++i) {
      const Eigen::Vector3i& t = mesh.triangles[i];
      const Eigen::Vector3d a = mesh.vertices[static_cast<size_t>(t[0])].cast<double>();
      const Eigen::Vector3d b = mesh.vertices[static_cast<size_t>(t[1])].cast<double>();
      const Eigen::Vector3d c = mesh.vertices[static_cast<size_t>(t[2])].cast<double>();
      v0_.push_back(a);
      e1_.push_back(b - a);
      e2_.push_back(c - a);
      chunk.box.Extend(a);
      chunk.box.Extend(b);
      chunk.box.Extend(c);
    }
    chunk.count = v0_.size() - chunk.first;
    chunk.box = chunk.box.Inflated(1e-7);
    chunks_.push_back(chunk);
  }
}

bool SegmentOcclusionTester::IsBlocked(const Eigen::Vector3d& a, const Eigen::Vector3d& b) const {
  const double length = (b - a).norm();
  if (length < 2e-6) return false;
  const Ray ray = Ray::Between(a, b);
  const double t_lo = 1e-6;
  const double t_hi = length - 1e-6;
  for (const Chunk& chunk : chunks_) {
    if (!chunk.box.Intersect(ray)) continue;
    for (size_t i = chunk.first; i < chunk.first + chunk.count; ++i) {
      // Möller–Trumbore.
      const Eigen::Vector3d p = ray.direction.cross(e2_[i]);
      const double det = e1_[i].dot(p);
      if (std::abs(det) < 1e-14) continue;
      const double inv_det = 1.0 / det;
      const Eigen::Vector3d s = ray.origin - v0_[i];
      const double u = s.dot(p) * inv_det;
      if (u < 0.0 || u > 1.0) continue;
      const Eigen::Vector3d q = s.cross(e1_[i]);
      const double v = ray.direction.dot(q) * inv_det;
      if (v < 0.0 || u + v > 1.0) continue;
      const double t = e2_[i].dot(q) * inv_det;
      if (t > t_lo && t < t_hi) return true;
    }
  }
  return false;
}

Status OcclusionScreen::Validate() const {
  if (!enabled) return Status::Ok();
  std::vector<std::string> errors;
  if (!eye_W.allFinite()) {
    errors.push_back(
        fmt::format("eye_W ({}, {}, {}) must be finite", eye_W.x(), eye_W.y(), eye_W.z()));
  }
  if (!view_direction_W.allFinite() || view_direction_W.norm() < 1e-9) {
    errors.push_back(fmt::format("view_direction_W ({}, {}, {}) must be finite and non-zero",
                                 view_direction_W.x(), view_direction_W.y(), view_direction_W.z()));
  }
  if (!(cone_half_angle_deg > 0.0 && cone_half_angle_deg <= 90.0)) {
    errors.push_back(
        fmt::format("cone_half_angle_deg ({}) must be in (0, 90]", cone_half_angle_deg));
  }
  if (samples_per_fruit < 8 || samples_per_fruit > 10000) {
    errors.push_back(
        fmt::format("samples_per_fruit ({}) must be in [8, 10000]", samples_per_fruit));
  }
  if (max_leaves < 0 || max_leaves > 10000) {
    errors.push_back(fmt::format("max_leaves ({}) must be in [0, 10000]", max_leaves));
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid occlusion screen: {}", fmt::join(errors, "; ")));
}

FruitVisibility::FruitVisibility(const OcclusionScreen& screen, std::span<const Ellipsoid> fruits)
    : eye_W_(screen.eye_W) {
  const Status status = screen.Validate();
  AVP_THROW_UNLESS(status.ok(), status.message());
  const Eigen::Vector3d view = screen.view_direction_W.normalized();
  const double cos_cone = std::cos(screen.cone_half_angle_deg * kPi / 180.0);
  const std::vector<Eigen::Vector3d> unit = FibonacciSphere(screen.samples_per_fruit);
  for (size_t f = 0; f < fruits.size(); ++f) {
    const Ellipsoid& e = fruits[f];
    for (const Eigen::Vector3d& u : unit) {
      const Eigen::Vector3d p = e.center_W + e.R_WE * e.radii.cwiseProduct(u);
      const Eigen::Vector3d normal = (e.R_WE * u.cwiseQuotient(e.radii)).normalized();
      const Eigen::Vector3d to_eye = eye_W_ - p;
      if (normal.dot(to_eye) <= 0.0) continue;                    // faces away
      if ((-to_eye).normalized().dot(view) < cos_cone) continue;  // outside the cone
      pending_.push_back({p + 1e-4 * normal, f});
    }
  }
  num_samples_ = pending_.size();
}

void FruitVisibility::AddSceneOccluders(const Scene& scene, size_t first_object) {
  for (size_t i = first_object; i < scene.objects.size(); ++i) {
    const SceneObject& o = scene.objects[i];
    if (o.semantic_class == SemanticClass::kFruit) continue;
    if (const auto* mesh = std::get_if<TriangleMesh>(&o.shape)) AddOccluder(*mesh);
  }
}

Eigen::Vector3d ScreenLeafCentre(const Eigen::Vector3d& p_W, const Eigen::Vector3d& eye_W,
                                 std::span<const Ellipsoid> fruits, double min_distance_m,
                                 double clearance_m, Rng& rng) {
  const Eigen::Vector3d to_eye = (eye_W - p_W).normalized();
  Eigen::Vector3d q = p_W + min_distance_m * to_eye;
  for (double dist = min_distance_m; dist < 0.25; dist += 0.01) {
    q = p_W + (dist + rng.Uniform(0.0, 0.01)) * to_eye;
    bool clear = true;
    for (const Ellipsoid& f : fruits) {
      if ((f.center_W - q).norm() < f.radii.maxCoeff() + clearance_m) clear = false;
    }
    if (clear) break;
  }
  return q;
}

std::optional<std::pair<Eigen::Vector3d, size_t>> FruitVisibility::FindVisible() {
  size_t keep = 0;
  std::optional<size_t> found;
  for (size_t i = 0; i < pending_.size(); ++i) {
    const bool hidden = !found && occluders_.IsBlocked(eye_W_, pending_[i].p_W);
    if (hidden) continue;  // dropped: occluders only grow
    if (!found) found = keep;
    pending_[keep++] = pending_[i];
  }
  pending_.resize(keep);
  if (!found) return std::nullopt;
  // Rotate the visible sample to the back so that a failed attempt moves on to another one.
  const Sample sample = pending_[*found];
  pending_.erase(pending_.begin() + static_cast<std::ptrdiff_t>(*found));
  pending_.push_back(sample);
  return std::make_pair(sample.p_W, sample.fruit);
}

int FruitVisibility::CountVisible() {
  std::vector<Sample> visible;
  for (const Sample& s : pending_) {
    if (!occluders_.IsBlocked(eye_W_, s.p_W)) visible.push_back(s);
  }
  pending_ = std::move(visible);
  return static_cast<int>(pending_.size());
}

Eigen::Matrix3d RotationWithXAxis(const Eigen::Vector3d& direction,
                                  const Eigen::Vector3d& up_hint) {
  const double norm = direction.norm();
  AVP_THROW_UNLESS(std::isfinite(norm) && norm > 1e-12, direction.transpose());
  const Eigen::Vector3d x = direction / norm;
  Eigen::Vector3d z = up_hint - up_hint.dot(x) * x;
  z = z.norm() > 1e-6 ? Eigen::Vector3d(z.normalized()) : AnyPerpendicular(x);
  Eigen::Matrix3d R;
  R.col(0) = x;
  R.col(1) = z.cross(x);
  R.col(2) = z;
  return R;
}

Eigen::Vector3f VaryAlbedo(const Eigen::Vector3f& albedo, double spread, Rng& rng) {
  Eigen::Vector3f out;
  const double common = rng.Uniform(1.0 - spread, 1.0 + spread);
  for (int k = 0; k < 3; ++k) {
    const double channel = rng.Uniform(1.0 - 0.5 * spread, 1.0 + 0.5 * spread);
    out[k] = static_cast<float>(std::clamp(albedo[k] * common * channel, 0.0, 1.0));
  }
  return out;
}

Eigen::Matrix3d RotationWithZAxis(const Eigen::Vector3d& direction) {
  const double norm = direction.norm();
  AVP_THROW_UNLESS(std::isfinite(norm) && norm > 1e-12, direction.transpose());
  const Eigen::Vector3d z = direction / norm;
  const Eigen::Vector3d x = AnyPerpendicular(z);
  Eigen::Matrix3d R;
  R.col(0) = x;
  R.col(1) = z.cross(x);
  R.col(2) = z;
  return R;
}

}  // namespace avp::sim

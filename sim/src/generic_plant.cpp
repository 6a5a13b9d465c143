#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include <avp/sim/generic_plant.h>
#include <avp/sim/mesh_builder.h>

#include "occlusion_screen.h"

namespace avp::sim {

namespace {

constexpr double kPi = 3.14159265358979323846;
const Eigen::Vector3d kUp = Eigen::Vector3d::UnitZ();

/// What one plant of a draw looks like (sampled per plant).
struct PlantShape {
  Eigen::Vector3d base_W = Eigen::Vector3d::Zero();
  int stems = 1;
  double height_m = 1.0;
  double stem_radius_m = 0.01;
  int children_min = 2, children_max = 4;
  int levels = 2;
  double branch_angle_min_deg = 25.0, branch_angle_max_deg = 70.0;
  double leaf_length_m = 0.08;
  double leaf_width_ratio = 0.45;
  double leaf_spacing_m = 0.05;
  int clusters = 3;
  int fruits_per_cluster_max = 5;
  bool planar = false;              ///< wall, trellis: branches stay near the plane x = base.x
  double child_length_scale = 1.0;  ///< trellis: long, near-horizontal trained arms
  bool far_side_fruit = false;
};

/// A grown branch: its centreline (for leaves and fruit attachment) and level (0: a stem).
struct Branch {
  std::vector<Eigen::Vector3d> line;
  double radius_m = 0.01;
  int level = 0;
};

Eigen::Vector3d PointAt(const std::vector<Eigen::Vector3d>& line, double f) {
  const double t = std::clamp(f, 0.0, 1.0) * static_cast<double>(line.size() - 1);
  const size_t i = std::min(static_cast<size_t>(t), line.size() - 2);
  const double u = t - static_cast<double>(i);
  return (1.0 - u) * line[i] + u * line[i + 1];
}

Eigen::Vector3d TangentAt(const std::vector<Eigen::Vector3d>& line, double f) {
  const double t = std::clamp(f, 0.0, 1.0) * static_cast<double>(line.size() - 1);
  const size_t i = std::min(static_cast<size_t>(t), line.size() - 2);
  return (line[i + 1] - line[i]).normalized();
}

/// A unit direction at `angle` from `axis`, at a random azimuth about it (planar: the azimuth
/// that keeps the direction nearest the plane x = const, either way).
Eigen::Vector3d Deviate(const Eigen::Vector3d& axis, double angle_rad, bool planar, Rng& rng) {
  const Eigen::Matrix3d R = RotationWithZAxis(axis);
  double az = rng.Uniform(0.0, 2.0 * kPi);
  if (planar) {
    // The in-plane directions perpendicular to the axis are ±(x × axis); jitter ±20°.
    const Eigen::Vector3d in_plane = Eigen::Vector3d::UnitX().cross(axis);
    if (in_plane.norm() > 1e-6) {
      const Eigen::Vector3d local = R.transpose() * in_plane.normalized();
      az = std::atan2(local.y(), local.x()) + (rng.Bernoulli(0.5) ? 0.0 : kPi) +
           rng.Uniform(-0.35, 0.35);
    }
  }
  const Eigen::Vector3d local(std::sin(angle_rad) * std::cos(az),
                              std::sin(angle_rad) * std::sin(az), std::cos(angle_rad));
  return (R * local).normalized();
}

/// A gently curved branch from `start` along `direction`, drooping under its own weight.
std::vector<Eigen::Vector3d> BranchLine(const Eigen::Vector3d& start,
                                        const Eigen::Vector3d& direction, double length,
                                        double droop, Rng& rng) {
  const Eigen::Vector3d end = start + length * direction - droop * length * kUp;
  const Eigen::Vector3d jitter(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1));
  const Eigen::Vector3d c1 = start + length / 3.0 * direction + 0.05 * length * jitter;
  const Eigen::Vector3d c2 = start + 2.0 * length / 3.0 * direction - 0.5 * droop * length * kUp;
  return SampleCubicBezier(start, c1, c2, end, 6);
}

/// Grows a branch and, recursively, its children into `branches`.
void Grow(const PlantShape& shape, const std::vector<Eigen::Vector3d>& line, double radius,
          int level, Rng& rng, std::vector<Branch>& branches) {
  branches.push_back({line, radius, level});
  if (level >= shape.levels) return;
  const int children =
      static_cast<int>(rng.UniformInt(shape.children_min, shape.children_max)) - level;
  double length = 0.0;
  for (size_t i = 1; i < line.size(); ++i) length += (line[i] - line[i - 1]).norm();
  for (int c = 0; c < children; ++c) {
    const double f = rng.Uniform(level == 0 ? 0.25 : 0.15, 0.9);
    const Eigen::Vector3d at = PointAt(line, f);
    const double angle =
        rng.Uniform(shape.branch_angle_min_deg, shape.branch_angle_max_deg) * kPi / 180.0;
    const Eigen::Vector3d dir = Deviate(TangentAt(line, f), angle, shape.planar, rng);
    const double child_length = length * rng.Uniform(0.25, 0.55) * (1.0 - 0.4 * f) *
                                (level == 0 ? shape.child_length_scale : 1.0);
    const double child_radius = std::max(0.0025, radius * rng.Uniform(0.4, 0.65));
    Grow(shape, BranchLine(at, dir, child_length, rng.Uniform(0.0, 0.35), rng), child_radius,
         level + 1, rng, branches);
  }
}

Eigen::Vector3f LeafColor(Rng& rng) {
  const Eigen::Vector3f greens[3] = {
      {0.10f, 0.30f, 0.06f}, {0.18f, 0.36f, 0.08f}, {0.08f, 0.22f, 0.10f}};
  return VaryAlbedo(greens[rng.UniformInt(0, 2)], 0.15, rng);
}

Eigen::Vector3f FruitColor(Rng& rng) {
  const Eigen::Vector3f colors[5] = {{0.55f, 0.05f, 0.04f},
                                     {0.70f, 0.30f, 0.03f},
                                     {0.65f, 0.55f, 0.05f},
                                     {0.25f, 0.45f, 0.08f},
                                     {0.25f, 0.05f, 0.25f}};
  return VaryAlbedo(colors[rng.UniformInt(0, 4)], 0.1, rng);
}

/// One blade of `length` at `at`, its midrib along `direction` (upper side towards `up_hint`).
void AddBlade(const Eigen::Vector3d& at, const Eigen::Vector3d& direction,
              const Eigen::Vector3d& up_hint, double length, double width_ratio, Rng& rng,
              TriangleMesh& blades) {
  LeafBladeParams p;
  p.length_m = length;
  p.width_m = length * width_ratio;
  p.widest_at = rng.Uniform(0.3, 0.6);
  p.midrib_bend_rad = rng.Uniform(0.0, 0.8);
  p.cup = rng.Uniform(-0.1, 0.3);
  p.twist_rad = rng.Uniform(-0.3, 0.3);
  p.segments_along = 5;
  p.segments_across = 2;
  TriangleMesh blade = MakeLeafBlade(p);
  blade.Transform(RigidTransform(RotationWithXAxis(direction, up_hint), at));
  blades.Append(blade);
}

/// Leaves along every branch above the first 15 cm of a stem, one object per branch.
int AddLeaves(const PlantShape& shape, const std::vector<Branch>& branches, const std::string& name,
              Rng& rng, Scene& scene) {
  int leaves = 0;
  for (size_t b = 0; b < branches.size(); ++b) {
    const Branch& branch = branches[b];
    double length = 0.0;
    for (size_t i = 1; i < branch.line.size(); ++i) {
      length += (branch.line[i] - branch.line[i - 1]).norm();
    }
    const int n = static_cast<int>(length / shape.leaf_spacing_m);
    TriangleMesh blades;
    for (int i = 0; i < n; ++i) {
      const double f = rng.Uniform(branch.level == 0 ? 0.3 : 0.1, 1.0);
      const Eigen::Vector3d at = PointAt(branch.line, f);
      if (at.z() - shape.base_W.z() < 0.15) continue;
      const Eigen::Vector3d t = TangentAt(branch.line, f);
      const Eigen::Vector3d dir =
          Deviate(t, rng.Uniform(40.0, 100.0) * kPi / 180.0, shape.planar, rng);
      const double length_m = shape.leaf_length_m * rng.Uniform(0.7, 1.3);
      const Eigen::Vector3d up =
          kUp + 0.5 * Eigen::Vector3d(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1));
      AddBlade(at, dir, up, length_m, shape.leaf_width_ratio * rng.Uniform(0.8, 1.2), rng, blades);
      ++leaves;
    }
    if (!blades.triangles.empty()) {
      scene.Add(fmt::format("{}/leaves_{:02}", name, b), SemanticClass::kLeaf, LeafColor(rng),
                std::move(blades));
    }
  }
  return leaves;
}

/// Fruit clusters hung from random branch points; their ellipsoids, non-overlapping.
std::vector<Ellipsoid> AddFruit(const PlantShape& shape, const std::vector<Branch>& branches,
                                const std::string& name, Rng& rng, Scene& scene,
                                std::vector<Ellipsoid>& all_fruit, GenericPlantInfo& info) {
  std::vector<Ellipsoid> fruit;
  TriangleMesh pedicels;
  for (int c = 0; c < shape.clusters; ++c) {
    // An attachment point: a random branch (stems only above 30 % of their height).
    const Branch& branch =
        branches[static_cast<size_t>(rng.UniformInt(0, static_cast<int64_t>(branches.size()) - 1))];
    Eigen::Vector3d attach = PointAt(branch.line, rng.Uniform(branch.level == 0 ? 0.3 : 0.2, 1.0));
    if (shape.far_side_fruit && attach.x() < shape.base_W.x()) {
      attach.x() = 2.0 * shape.base_W.x() - attach.x();  // mirrored to the far side
    }
    const double radius = rng.Uniform(0.015, 0.045);
    const Eigen::Vector3d out(rng.Uniform(-1, 1), rng.Uniform(-1, 1), 0.0);
    const Eigen::Vector3d centre = attach - rng.Uniform(0.03, 0.08) * kUp + 0.02 * out;
    const int n = static_cast<int>(rng.UniformInt(1, shape.fruits_per_cluster_max));
    for (int i = 0, tries = 0; i < n && tries < 40; ++tries) {
      Ellipsoid e;
      const double r = radius * rng.Uniform(0.85, 1.15);
      e.radii = Eigen::Vector3d(r * rng.Uniform(0.9, 1.1), r * rng.Uniform(0.9, 1.1),
                                r * rng.Uniform(0.8, 1.15));
      e.center_W = centre + Eigen::Vector3d(rng.Normal(0, 1.2 * radius),
                                            rng.Normal(0, 1.2 * radius), rng.Normal(0, radius));
      if (e.center_W.z() - e.radii.z() < shape.base_W.z() + 0.08) continue;
      bool overlaps = false;
      for (const Ellipsoid& o : all_fruit) {
        overlaps = overlaps || (o.center_W - e.center_W).norm() <
                                   o.radii.maxCoeff() + e.radii.maxCoeff() + 0.002;
      }
      if (overlaps) continue;
      e.R_WE = Eigen::AngleAxisd(rng.Uniform(0.0, 2.0 * kPi), kUp).toRotationMatrix();
      const Eigen::Vector3d top = e.center_W + e.radii.z() * kUp;
      if ((attach - top).norm() > 0.004) {
        const Eigen::Vector3d p[2] = {attach, top};
        const double radii[2] = {0.0018, 0.0015};
        pedicels.Append(MakeTube(p, radii, 4, false));
      }
      all_fruit.push_back(e);
      fruit.push_back(e);
      info.fruit_ids.push_back(scene.Add(fmt::format("{}/fruit_{}_{}", name, c, i),
                                         SemanticClass::kFruit, FruitColor(rng), e));
      ++i;
    }
  }
  if (!pedicels.triangles.empty()) {
    scene.Add(name + "/pedicels", SemanticClass::kStem, Eigen::Vector3f(0.2f, 0.3f, 0.1f),
              std::move(pedicels));
  }
  return fruit;
}

PlantShape DrawShape(const GenericPlantDraw& draw, const Eigen::Vector3d& base, double height,
                     Rng& rng) {
  PlantShape s;
  s.base_W = base;
  s.height_m = height;
  using Layout = GenericPlantDraw::Layout;
  const bool trellis = draw.layout == Layout::kTrellis;
  s.planar = draw.layout == Layout::kWall || trellis;
  s.stems = draw.layout == Layout::kWall  ? static_cast<int>(rng.UniformInt(4, 8))
            : draw.layout == Layout::kRow ? 1
                                          : static_cast<int>(rng.UniformInt(1, 3));
  s.stem_radius_m = rng.Uniform(0.006, 0.016);
  s.children_min = static_cast<int>(rng.UniformInt(2, 4));
  s.children_max = s.children_min + static_cast<int>(rng.UniformInt(0, 2));
  s.levels = static_cast<int>(rng.UniformInt(2, 3));
  s.branch_angle_min_deg = rng.Uniform(15.0, 40.0);
  s.branch_angle_max_deg = s.branch_angle_min_deg + rng.Uniform(15.0, 50.0);
  if (trellis) {  // arms trained out along the plane, spurs off them
    s.children_min = static_cast<int>(rng.UniformInt(3, 6));
    s.children_max = s.children_min + static_cast<int>(rng.UniformInt(0, 3));
    s.branch_angle_min_deg = rng.Uniform(65.0, 80.0);
    s.branch_angle_max_deg = rng.Uniform(85.0, 100.0);
    s.child_length_scale = rng.Uniform(1.6, 2.6);
  }
  const double density = rng.Uniform(0.2, 1.8);
  s.leaf_length_m = rng.Uniform(0.03, 0.18);
  s.leaf_width_ratio = rng.Uniform(0.25, 0.7);
  // Leaves per metre of branch grow with the density and shrink with the leaf size.
  s.leaf_spacing_m = std::clamp(0.6 * s.leaf_length_m / density, 0.015, 0.3);
  const int plants = std::max(1, draw.plants);
  s.clusters = std::max(1, static_cast<int>(rng.UniformInt(1, 7)) / (plants > 1 ? 2 : 1));
  s.fruits_per_cluster_max = static_cast<int>(rng.UniformInt(1, 8));
  s.far_side_fruit = draw.far_side_fruit;
  return s;
}

/// The stems of one plant: near-vertical, spread over its footprint (a wall: along y).
void GrowStems(const PlantShape& shape, double footprint_m, Rng& rng,
               std::vector<Branch>& branches) {
  for (int i = 0; i < shape.stems; ++i) {
    Eigen::Vector3d foot = shape.base_W;
    if (shape.planar) {
      foot.y() += footprint_m * ((i + 0.5) / shape.stems - 0.5) + rng.Uniform(-0.03, 0.03);
      foot.x() += rng.Uniform(-0.02, 0.02);
    } else if (shape.stems > 1) {
      foot += Eigen::Vector3d(rng.Uniform(-0.06, 0.06), rng.Uniform(-0.06, 0.06), 0.0);
    }
    const double tilt = rng.Uniform(0.0, shape.stems > 1 ? 20.0 : 10.0) * kPi / 180.0;
    const Eigen::Vector3d dir = Deviate(kUp, tilt, shape.planar, rng);
    const double h = shape.height_m * rng.Uniform(0.8, 1.0);
    Grow(shape, BranchLine(foot, dir, h, 0.0, rng), shape.stem_radius_m, 0, rng, branches);
  }
}

/// Two round stakes beyond the ends of a wall or trellis `footprint_m` wide along y, and 1–4
/// wires between them at random heights, a little in front of or behind the plane (class support).
void AddSupports(const Eigen::Vector3d& centre, double footprint_m, Rng rng, Scene& scene) {
  const double half = 0.5 * footprint_m + rng.Uniform(0.05, 0.15);
  const double height = rng.Uniform(0.8, 1.6);
  const double x = centre.x() + (rng.Bernoulli(0.5) ? 1.0 : -1.0) * rng.Uniform(0.01, 0.04);
  const Eigen::Vector3f wood = VaryAlbedo({0.35f, 0.27f, 0.16f}, 0.2, rng);
  for (const double side : {-1.0, 1.0}) {
    const Eigen::Vector3d foot(x, centre.y() + side * half, centre.z());
    scene.Add(fmt::format("generic/stake_{}", side < 0 ? 0 : 1), SemanticClass::kSupport, wood,
              MakeCylinder(foot, foot + height * kUp, rng.Uniform(0.015, 0.035), 10, true));
  }
  const int wires = static_cast<int>(rng.UniformInt(1, 4));
  for (int w = 0; w < wires; ++w) {
    const double z = centre.z() + rng.Uniform(0.25, 0.95) * height;
    const Eigen::Vector3d a(x, centre.y() - half, z), b(x, centre.y() + half, z);
    scene.Add(fmt::format("generic/wire_{}", w), SemanticClass::kSupport,
              VaryAlbedo({0.5f, 0.5f, 0.52f}, 0.1, rng),
              MakeCylinder(a, b, rng.Uniform(0.001, 0.0025), 6, true));
  }
}

/// A covering leaf of the occlusion screen: a blade facing the eye on a thin shoot from below.
internal::ScreenLeaf BuildScreenLeaf(double leaf_m, int k, const internal::ScreenSpot& spot,
                                     Rng& r) {
  internal::ScreenLeaf leaf;
  const double length = std::max(0.05, leaf_m) * r.Uniform(1.1, 1.4);
  Eigen::Vector3d direction(r.Uniform(-0.5, 0.5), r.Uniform(-0.5, 0.5), -1.0);
  direction -= direction.dot(spot.to_eye) * spot.to_eye;
  const Eigen::Matrix3d R = RotationWithXAxis(direction, spot.to_eye);
  const Eigen::Vector3d blade_base = spot.centre_W - 0.45 * length * R.col(0);
  const Eigen::Vector3d p[2] = {blade_base - Eigen::Vector3d(0.0, 0.0, 0.06), blade_base};
  const double radii[2] = {0.002, 0.0015};
  leaf.stem = MakeTube(p, radii, 4, true);
  AddBlade(blade_base, R.col(0), spot.to_eye, length, 0.6, r, leaf.blades);
  leaf.stem_name = fmt::format("generic/screen_shoot_{:02}", k);
  leaf.stem_albedo = Eigen::Vector3f(0.2f, 0.3f, 0.1f);
  leaf.blades_name = fmt::format("generic/screen_leaves_{:02}", k);
  leaf.blades_albedo = LeafColor(r);
  return leaf;
}

}  // namespace

const char* GenericLayoutName(GenericPlantDraw::Layout layout) {
  switch (layout) {
    case GenericPlantDraw::Layout::kSingle:
      return "single";
    case GenericPlantDraw::Layout::kRow:
      return "row";
    case GenericPlantDraw::Layout::kWall:
      return "wall";
    case GenericPlantDraw::Layout::kTrellis:
      return "trellis";
  }
  return "?";
}

GenericPlantDraw DrawGenericLayout(Rng& rng) {
  GenericPlantDraw d;
  const double u = rng.Uniform01();
  using Layout = GenericPlantDraw::Layout;
  d.layout = u < 0.4   ? Layout::kSingle
             : u < 0.6 ? Layout::kRow
             : u < 0.8 ? Layout::kWall
                       : Layout::kTrellis;
  d.plants = d.layout == Layout::kRow ? static_cast<int>(rng.UniformInt(2, 4)) : 1;
  d.supports = (d.layout == Layout::kTrellis && rng.Bernoulli(0.7)) ||
               (d.layout == Layout::kWall && rng.Bernoulli(0.3));
  d.occluded = rng.Bernoulli(0.3);
  d.far_side_fruit = rng.Bernoulli(0.3);
  if (rng.Bernoulli(0.3)) {
    d.start_yaw_deg = (rng.Bernoulli(0.5) ? 1.0 : -1.0) * rng.Uniform(15.0, 55.0);
  }
  return d;
}

GenericPlantInfo AddGenericPlants(const GenericPlantDraw& draw, const RigidTransform& X_WC_start,
                                  Rng& rng, Scene& scene) {
  GenericPlantInfo info;
  info.draw = draw;
  const size_t first_object = scene.objects.size();
  const Rng plant_rng(rng.NextU64());
  Rng place = plant_rng.Fork("place");
  const Eigen::Vector3d centre(place.Uniform(0.55, 0.85), place.Uniform(-0.35, 0.35), 0.0);
  const bool row = draw.layout == GenericPlantDraw::Layout::kRow;
  const double spacing = place.Uniform(0.25, 0.45);
  // A wall's or a trellis's width.
  const double footprint = draw.layout == GenericPlantDraw::Layout::kTrellis
                               ? place.Uniform(1.0, 2.0)
                               : place.Uniform(0.8, 1.4);
  std::vector<Ellipsoid> all_fruit;
  for (int p = 0; p < draw.plants; ++p) {
    Rng r = plant_rng.Fork(static_cast<uint64_t>(p + 1));
    Eigen::Vector3d base = centre;
    if (row) base.y() += spacing * (p - 0.5 * (draw.plants - 1)) + r.Uniform(-0.03, 0.03);
    const double height = r.Uniform(0.6, 1.3) * (row ? 0.85 : 1.0);
    const PlantShape shape = DrawShape(draw, base, height, r);
    std::vector<Branch> branches;
    GrowStems(shape, footprint, r, branches);
    const std::string name = fmt::format("generic/plant_{}", p);
    TriangleMesh wood;
    for (const Branch& b : branches) {
      const std::vector<double> radii = LinearRadii(b.radius_m, std::max(0.0015, 0.45 * b.radius_m),
                                                    static_cast<int>(b.line.size()));
      wood.Append(MakeTube(b.line, radii, 6, true));
    }
    scene.Add(name + "/wood", SemanticClass::kStem, VaryAlbedo({0.25f, 0.20f, 0.10f}, 0.2, r),
              std::move(wood));
    info.num_leaves += AddLeaves(shape, branches, name, r, scene);
    AddFruit(shape, branches, name, r, scene, all_fruit, info);
    info.num_branches += static_cast<int>(branches.size());
  }
  if (draw.supports) AddSupports(centre, footprint, plant_rng.Fork("supports"), scene);
  if (draw.occluded && !all_fruit.empty()) {
    OcclusionScreen screen;
    screen.enabled = true;
    screen.eye_W = X_WC_start.translation();
    screen.view_direction_W = X_WC_start.rotation().col(2);
    const double leaf_m = 0.08;
    const internal::ScreenResult result = internal::AddOcclusionScreen(
        screen, all_fruit, first_object, plant_rng, {.min_distance_m = 0.04, .clearance_m = 0.01},
        [&](int k, const internal::ScreenSpot& spot, Rng& r) {
          return BuildScreenLeaf(leaf_m, k, spot, r);
        },
        scene);
    info.num_screen_leaves = result.num_leaves;
    info.num_visible_samples = result.num_visible_samples;
  }
  const internal::ObjectTotals totals = internal::CountObjectsSince(scene, first_object);
  info.num_triangles = totals.num_triangles;
  info.num_objects = totals.num_objects;
  return info;
}

}  // namespace avp::sim

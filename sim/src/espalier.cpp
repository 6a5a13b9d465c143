#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/sim/espalier.h>
#include <avp/sim/mesh_builder.h>

#include "occlusion_screen.h"

namespace avp::sim {

namespace {

constexpr double kPi = 3.14159265358979323846;
const Eigen::Vector3d kUp = Eigen::Vector3d::UnitZ();
const Eigen::Vector3d kFront = -Eigen::Vector3d::UnitX();  // towards the arm

const Eigen::Vector3f kBarkColor(0.20f, 0.13f, 0.08f);
const Eigen::Vector3f kLeafColor(0.07f, 0.22f, 0.04f);
const Eigen::Vector3f kWoodColor(0.36f, 0.26f, 0.15f);
const Eigen::Vector3f kWireColor(0.55f, 0.56f, 0.58f);

double DistanceToSegment(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                         const Eigen::Vector3d& b) {
  const Eigen::Vector3d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0.0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return (a + t * ab - p).norm();
}

/// A branch centreline with its radius per point (trunk, cordon).
struct Branch {
  std::vector<Eigen::Vector3d> line;
  std::vector<double> radii;

  /// Distance from p to the branch surface (negative inside), and the closest centreline point.
  std::pair<double, Eigen::Vector3d> Clearance(const Eigen::Vector3d& p) const {
    double best = std::numeric_limits<double>::infinity();
    Eigen::Vector3d closest = line.front();
    for (size_t i = 0; i + 1 < line.size(); ++i) {
      const Eigen::Vector3d ab = line[i + 1] - line[i];
      const double t = std::clamp((p - line[i]).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
      const Eigen::Vector3d c = line[i] + t * ab;
      const double r = radii[i] + t * (radii[i + 1] - radii[i]);
      const double d = (p - c).norm() - r;
      if (d < best) {
        best = d;
        closest = c;
      }
    }
    return {best, closest};
  }
};

/// A leaf on a petiole: blade of `length_m` starting `petiole_m` from `base` along `direction`.
void AddLeaf(const Eigen::Vector3d& base, const Eigen::Vector3d& direction, double length_m,
             double petiole_m, Rng& rng, TriangleMesh& blades, TriangleMesh& petioles,
             std::optional<Eigen::Matrix3d> frame = std::nullopt) {
  const Eigen::Vector3d d = direction.normalized();
  const Eigen::Vector3d blade_base = base + petiole_m * d;
  if (petiole_m > 0.004) {
    const std::vector<Eigen::Vector3d> line = {base, blade_base};
    petioles.Append(MakeTube(line, LinearRadii(0.0012, 0.0009, 2), 4, true));
  }
  LeafBladeParams blade;
  blade.length_m = length_m;
  blade.width_m = length_m * rng.Uniform(0.45, 0.6);
  blade.widest_at = rng.Uniform(0.4, 0.55);
  blade.midrib_bend_rad = rng.Uniform(0.2, 0.8);
  blade.cup = rng.Uniform(0.05, 0.3);
  blade.twist_rad = rng.Uniform(-0.35, 0.35);
  blade.segments_along = 6;
  blade.segments_across = 2;
  Eigen::Matrix3d R;
  if (frame) {
    R = *frame;
    blade.midrib_bend_rad = rng.Uniform(0.05, 0.25);
    blade.width_m = length_m * rng.Uniform(0.58, 0.66);
  } else {
    // Espalier leaves turn their upper side to the light: up and away from the wall.
    const Eigen::Vector3d outward = d.x() <= 0.0 ? kFront : Eigen::Vector3d(-kFront);
    R = RotationWithXAxis(d, (kUp + rng.Uniform(0.2, 0.8) * outward).normalized());
  }
  blades.Append(MakeLeafBlade(blade), RigidTransform(R, blade_base));
}

// ---- Frame: tiers and trunk ---------------------------------------------------------------------

constexpr double kBendRadius = 0.07;  // m, the quarter bend from the trunk into each cordon

/// The trunk's centreline: straight up from the base, bowed sideways along half a sine wave
/// (no offset at the base).
struct TrunkModel {
  Eigen::Vector3d base_W = Eigen::Vector3d::Zero();
  double height_m = 0.0;  ///< where the top cordons leave the trunk
  Eigen::Vector2d wobble_m = Eigen::Vector2d::Zero();
  double phase = 0.0;

  Eigen::Vector3d At(double h) const {
    const double s = std::sin(kPi * h / height_m + phase) - std::sin(phase);
    return Eigen::Vector3d(base_W + Eigen::Vector3d(wobble_m.x() * s, wobble_m.y() * s, h));
  }
};

/// Draws the tiers (info.num_tiers; info.tier_heights_m, all but the top one jittered by +-2 cm)
/// and the trunk's bow; the trunk ends one bend below the top tier (info.trunk_height_m).
TrunkModel DrawFrame(const EspalierParams& params, Rng& frame_rng, EspalierInfo& info) {
  const int tiers = static_cast<int>(frame_rng.UniformInt(params.tiers_min, params.tiers_max));
  info.num_tiers = tiers;
  for (int i = 0; i < tiers; ++i) {
    const double z = params.first_tier_height_m +
                     (params.height_m - params.first_tier_height_m) * i / (tiers - 1);
    info.tier_heights_m.push_back(z + (i + 1 < tiers ? frame_rng.Uniform(-0.02, 0.02) : 0.0));
  }
  info.trunk_height_m = info.tier_heights_m.back() - kBendRadius;
  const Eigen::Vector2d trunk_wobble(frame_rng.Uniform(-0.012, 0.012),
                                     frame_rng.Uniform(-0.012, 0.012));
  TrunkModel trunk;
  trunk.base_W = params.trunk_base_W;
  trunk.height_m = info.trunk_height_m;
  trunk.wobble_m = trunk_wobble;
  trunk.phase = frame_rng.Uniform(0.0, 2.0 * kPi);
  return trunk;
}

/// Adds "<prefix>/trunk", tapering to 70 % of trunk_radius_m at the top; returns its branch.
Branch AddTrunk(const EspalierParams& params, const TrunkModel& trunk, Rng& frame_rng,
                Scene& scene) {
  Branch branch;
  const int n = std::max(6, static_cast<int>(std::ceil(trunk.height_m / 0.04)) + 1);
  for (int i = 0; i < n; ++i) {
    const double h = trunk.height_m * i / (n - 1);
    branch.line.push_back(trunk.At(h));
    branch.radii.push_back(params.trunk_radius_m * (1.0 - 0.3 * h / trunk.height_m));
  }
  scene.Add(params.name_prefix + "/trunk", SemanticClass::kStem,
            VaryAlbedo(kBarkColor, 0.08, frame_rng), MakeTube(branch.line, branch.radii, 12, true));
  return branch;
}

// ---- Supports -----------------------------------------------------------------------------------

/// The supports: two end posts and one wire per tier just behind the cordons.
struct Trellis {
  double post_y =
      0.0;  ///< the posts' distance from the trunk along y, m (set without supports too)
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> wires;  ///< end points in W
};

/// Adds "<prefix>/post_L|R" and "<prefix>/wire_T" when params.supports.
Trellis AddTrellis(const EspalierParams& params, const std::vector<double>& tier_heights_m,
                   const Rng& tree_rng, Scene& scene) {
  const Eigen::Vector3d& B = params.trunk_base_W;
  Trellis trellis;
  trellis.post_y = 0.5 * params.width_m + 0.1;
  if (!params.supports) return trellis;
  const double post_y = trellis.post_y;
  const double wire_x = B.x() + params.cordon_base_radius_m + 0.004;  // just behind the cordons
  Rng support_rng = tree_rng.Fork("supports");
  const double post_height = params.height_m + 0.2;
  for (const double side : {1.0, -1.0}) {
    const Eigen::Vector3d centre(B.x() + 0.02, B.y() + side * post_y, B.z() + 0.5 * post_height);
    TriangleMesh post = MakeBox(Eigen::Vector3d(0.035, 0.035, 0.5 * post_height));
    post.Transform(RigidTransform(centre));
    scene.Add(fmt::format("{}/post_{}", params.name_prefix, side > 0 ? "L" : "R"),
              SemanticClass::kSupport, VaryAlbedo(kWoodColor, 0.1, support_rng), std::move(post));
  }
  for (size_t i = 0; i < tier_heights_m.size(); ++i) {
    const double z = B.z() + tier_heights_m[i] + 0.004;
    const Eigen::Vector3d a(wire_x, B.y() - post_y, z);
    const Eigen::Vector3d b(wire_x, B.y() + post_y, z);
    trellis.wires.emplace_back(a, b);
    scene.Add(fmt::format("{}/wire_{}", params.name_prefix, i), SemanticClass::kSupport,
              VaryAlbedo(kWireColor, 0.05, support_rng), MakeCylinder(a, b, 0.0015, 6, true));
  }
  return trellis;
}

// ---- Cordons, spurs, leaves ---------------------------------------------------------------------

/// A cordon's radius at fraction t of its length: cordon_base_radius_m at the trunk (t = 0),
/// cordon_tip_radius_m at the tip (t = 1).
double CordonRadius(const EspalierParams& params, double t) {
  return params.cordon_base_radius_m +
         (params.cordon_tip_radius_m - params.cordon_base_radius_m) * t;
}

/// One cordon: a quarter bend out of the trunk, then a run along +-y (`side`) that sags and
/// wobbles a little.
struct Cordon {
  double side = 1.0;
  double reach = 0.0;  ///< from the trunk to the tip along y, m
  double run = 0.0;    ///< the run's length along y (reach less the bend), m
  double sag = 0.0;
  double wobble = 0.0;
  double phase = 0.0;
  Eigen::Vector3d start = Eigen::Vector3d::Zero();  ///< where the bend ends and the run begins
  Branch branch;

  /// The centreline at fraction t of the run.
  Eigen::Vector3d AxisAt(double t) const {
    return start + Eigen::Vector3d(wobble * std::sin(3.0 * kPi * t + phase), side * run * t,
                                   -sag * std::sin(kPi * t));
  }
};

/// Draws the shape of the cordon at tier height z (above the trunk base) on `side` and samples
/// its branch.
Cordon LayOutCordon(const EspalierParams& params, const TrunkModel& trunk, double z, double side,
                    Rng& r) {
  Cordon cordon;
  cordon.side = side;
  cordon.reach = 0.5 * params.width_m * r.Uniform(0.92, 1.0);
  cordon.sag = r.Uniform(0.0, 0.02);
  cordon.wobble = r.Uniform(0.0, 0.008);
  cordon.phase = r.Uniform(0.0, 2.0 * kPi);
  std::vector<Eigen::Vector3d>& line = cordon.branch.line;
  const Eigen::Vector3d join = trunk.At(z - kBendRadius);
  for (int k = 0; k <= 4; ++k) {
    const double a = 0.5 * kPi * k / 4.0;
    line.push_back(join + Eigen::Vector3d(0.0, side * kBendRadius * (1.0 - std::cos(a)),
                                          kBendRadius * std::sin(a)));
  }
  cordon.start = line.back();
  cordon.run = cordon.reach - kBendRadius;
  const int n = std::max(4, static_cast<int>(std::ceil(cordon.run / 0.025)));
  for (int k = 1; k <= n; ++k) line.push_back(cordon.AxisAt(static_cast<double>(k) / n));
  for (size_t k = 0; k < line.size(); ++k) {
    cordon.branch.radii.push_back(CordonRadius(params, static_cast<double>(k) / (line.size() - 1)));
  }
  return cordon;
}

/// What one cordon's growth adds: wood (class stem: the cordon, spurs, shoots, petioles) and leaf
/// blades.
struct CordonGrowth {
  TriangleMesh wood;
  TriangleMesh blades;
  int num_leaves = 0;
};

/// A short woody stub on a cordon that carries a leaf rosette and maybe apples.
struct Spur {
  Eigen::Vector3d base;  // on the cordon axis
  Eigen::Vector3d tip;
  size_t cordon = 0;  // index into Canopy::cordon_wood
};

/// A spur's direction (unit): mostly up, some towards the front or back, a few down.
Eigen::Vector3d DrawSpurDirection(Rng& r) {
  const double u = r.Uniform01();
  Eigen::Vector3d dir = u < 0.5   ? Eigen::Vector3d(r.Uniform(-0.4, 0.4), 0.0, 1.0)
                        : u < 0.9 ? Eigen::Vector3d(u < 0.7 ? -1.0 : 1.0, 0.0, r.Uniform(-0.2, 0.6))
                                  : Eigen::Vector3d(r.Uniform(-0.4, 0.4), 0.0, -1.0);
  dir += Eigen::Vector3d(0.0, r.Uniform(-0.3, 0.3), 0.0);
  dir.normalize();
  return dir;
}

/// Summer growth from a spur's tip: a shoot, mostly upwards, with a leaf every ~3 cm in a spiral,
/// smaller towards its end. `leaf_m`: the tree's mean blade length, m.
void AddLeafyShoot(const Eigen::Vector3d& tip, double leaf_m, Rng& r, CordonGrowth& growth) {
  const Eigen::Vector3d up_dir =
      (kUp + Eigen::Vector3d(r.Uniform(-0.5, 0.5), r.Uniform(-0.4, 0.4), 0.0)).normalized();
  const double shoot_len = r.Uniform(0.08, 0.22);
  const Eigen::Vector3d bow(r.Uniform(-0.03, 0.03), r.Uniform(-0.03, 0.03), 0.0);
  const std::vector<Eigen::Vector3d> shoot = SampleCubicBezier(
      tip, tip + 0.35 * shoot_len * up_dir + 0.5 * bow, tip + 0.7 * shoot_len * up_dir + bow,
      tip + shoot_len * up_dir + 0.5 * bow, 6);
  growth.wood.Append(MakeTube(shoot, LinearRadii(0.0028, 0.0014, 6), 5, true));
  double phyllo = r.Uniform(0.0, 2.0 * kPi);
  for (double f = 0.15; f <= 1.0; f += 0.03 / shoot_len * r.Uniform(0.8, 1.2)) {
    const size_t seg = std::min<size_t>(4, static_cast<size_t>(f * 5.0));
    const Eigen::Vector3d at = shoot[seg] + (f * 5.0 - seg) * (shoot[seg + 1] - shoot[seg]);
    phyllo += 2.4;  // ~137.5 degrees
    const Eigen::Vector3d leaf_dir =
        Eigen::Vector3d(std::cos(phyllo), std::sin(phyllo), r.Uniform(0.2, 0.9));
    AddLeaf(at, leaf_dir, leaf_m * r.Uniform(0.7, 1.15) * (1.1 - 0.4 * f), r.Uniform(0.01, 0.02), r,
            growth.blades, growth.wood);
    ++growth.num_leaves;
  }
}

/// The rosette at a spur's tip: ~6 leaves per unit of leaf_density, spread evenly around and
/// mostly rising. `leaf_m`: the tree's mean blade length, m.
void AddSpurRosette(const Eigen::Vector3d& tip, double leaf_density, double leaf_m, Rng& r,
                    CordonGrowth& growth) {
  const int leaves = static_cast<int>(std::lround(6.0 * leaf_density * r.Uniform(0.7, 1.3)));
  const double phase0 = r.Uniform(0.0, 2.0 * kPi);
  for (int k = 0; k < leaves; ++k) {
    const double azimuth = phase0 + 2.0 * kPi * (k + r.Uniform(-0.2, 0.2)) / leaves;
    const double elevation = r.Uniform(-0.2, 0.9);
    const Eigen::Vector3d leaf_dir =
        std::cos(elevation) * Eigen::Vector3d(std::cos(azimuth), std::sin(azimuth), 0.0) +
        std::sin(elevation) * kUp;
    AddLeaf(tip, leaf_dir, leaf_m * r.Uniform(0.8, 1.2), r.Uniform(0.015, 0.03), r, growth.blades,
            growth.wood);
    ++growth.num_leaves;
  }
}

/// Spurs every ~spur_spacing_m (+-30 %) along the cordon's run, each with a rosette, some with a
/// leafy shoot (45 % at leaf density 1). `leaf_m`: the tree's mean blade length, m.
std::vector<Spur> AddSpurs(const EspalierParams& params, const Cordon& cordon, size_t cordon_index,
                           double leaf_m, Rng& r, CordonGrowth& growth) {
  std::vector<Spur> spurs;
  for (double y = 0.08 + r.Uniform(0.0, params.spur_spacing_m); y < cordon.reach - 0.02;
       y += params.spur_spacing_m * r.Uniform(0.7, 1.3)) {
    const double t = (y - kBendRadius) / cordon.run;
    if (t < 0.0) continue;
    const Eigen::Vector3d base = cordon.AxisAt(t);
    const Eigen::Vector3d dir = DrawSpurDirection(r);
    const double length = r.Uniform(0.025, 0.06);
    const Eigen::Vector3d tip = base + length * dir;
    const std::vector<Eigen::Vector3d> spur_line = {base, base + 0.5 * length * dir, tip};
    growth.wood.Append(MakeTube(spur_line, LinearRadii(0.0055, 0.0035, 3), 5, true));
    spurs.push_back({base, tip, cordon_index});
    if (r.Bernoulli(std::min(1.0, 0.45 * params.leaf_density))) {
      AddLeafyShoot(tip, leaf_m, r, growth);
    }
    AddSpurRosette(tip, params.leaf_density, leaf_m, r, growth);
  }
  return spurs;
}

/// Single leaves along the cordon, left where summer pruning removed the shoots: one every
/// 3.5 cm / leaf_density (+-40 %). `leaf_m`: the tree's mean blade length, m.
void AddCordonLeaves(const EspalierParams& params, const Cordon& cordon, double leaf_m, Rng& r,
                     CordonGrowth& growth) {
  if (params.leaf_density <= 0.0) return;
  const double spacing = 0.035 / params.leaf_density;
  for (double y = 0.1 + r.Uniform(0.0, spacing); y < cordon.reach;
       y += spacing * r.Uniform(0.6, 1.4)) {
    const double t = (y - kBendRadius) / cordon.run;
    if (t < 0.0) continue;
    const Eigen::Vector3d axis = cordon.AxisAt(t);
    const double around = r.Uniform(0.0, 2.0 * kPi);
    const Eigen::Vector3d radial(std::cos(around), 0.0, std::sin(around));
    const double radius = CordonRadius(params, t);
    const Eigen::Vector3d leaf_dir =
        (radial + Eigen::Vector3d(0.0, cordon.side * r.Uniform(0.0, 0.8), r.Uniform(0.0, 0.8)))
            .normalized();
    AddLeaf(axis + radius * radial, leaf_dir, leaf_m * r.Uniform(0.8, 1.2), r.Uniform(0.01, 0.025),
            r, growth.blades, growth.wood);
    ++growth.num_leaves;
  }
}

/// The tree's wood and where its apples can hang.
struct Canopy {
  std::vector<Branch> branches;  ///< trunk, then cordons (for collision checks and the screen)
  std::vector<Spur> spurs;
  /// Stem parts per cordon, added to the scene after the apples have added their stalks.
  std::vector<TriangleMesh> cordon_wood;
  std::vector<std::string> cordon_names;
};

/// Grows both cordons of every tier with their spurs and leaves, each from its own stream; adds
/// "<prefix>/leaves_T_L|R" now and keeps the wood in `canopy`. `leaf_m`: the mean blade length, m.
void GrowCordons(const EspalierParams& params, const TrunkModel& trunk, double leaf_m,
                 const Rng& tree_rng, Canopy& canopy, Scene& scene, EspalierInfo& info) {
  for (int i = 0; i < info.num_tiers; ++i) {
    const double z = info.tier_heights_m[static_cast<size_t>(i)];
    for (const double side : {1.0, -1.0}) {
      Rng r = tree_rng.Fork(static_cast<uint64_t>(2 * i + (side > 0 ? 0 : 1)));
      Cordon cordon = LayOutCordon(params, trunk, z, side, r);
      CordonGrowth growth;
      growth.wood = MakeTube(cordon.branch.line, cordon.branch.radii, 8, true);
      const std::vector<Spur> spurs =
          AddSpurs(params, cordon, canopy.cordon_wood.size(), leaf_m, r, growth);
      canopy.spurs.insert(canopy.spurs.end(), spurs.begin(), spurs.end());
      info.num_spurs += static_cast<int>(spurs.size());
      AddCordonLeaves(params, cordon, leaf_m, r, growth);
      info.num_leaves += growth.num_leaves;
      const std::string suffix = fmt::format("{}_{}", i, side > 0 ? "L" : "R");
      canopy.cordon_names.push_back(fmt::format("{}/cordon_{}", params.name_prefix, suffix));
      canopy.cordon_wood.push_back(std::move(growth.wood));
      if (!growth.blades.empty()) {
        Eigen::Vector3f green = kLeafColor;
        green *= static_cast<float>(r.Uniform(0.85, 1.15));
        scene.Add(fmt::format("{}/leaves_{}", params.name_prefix, suffix), SemanticClass::kLeaf,
                  VaryAlbedo(green, 0.1, r), std::move(growth.blades));
      }
      canopy.branches.push_back(std::move(cordon.branch));
    }
  }
}

// ---- Apples -------------------------------------------------------------------------------------

/// 0, 1, ..., n - 1 in a random order (Fisher-Yates with the project's generator).
std::vector<size_t> ShuffledIndices(size_t n, Rng& rng) {
  std::vector<size_t> order(n);
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  for (size_t i = order.size(); i > 1; --i) {
    std::swap(order[i - 1],
              order[static_cast<size_t>(rng.UniformInt(0, static_cast<int64_t>(i - 1)))]);
  }
  return order;
}

/// Whether an apple of radius r centred at c is above the ground margin, not deep into another
/// apple, and clear of the wood, the wires and the posts.
bool AppleFits(const Eigen::Vector3d& c, double r, const EspalierParams& params,
               const std::vector<Ellipsoid>& apples, const Canopy& canopy, const Trellis& trellis) {
  const Eigen::Vector3d& B = params.trunk_base_W;
  if (c.z() - r < B.z() + 0.03) return false;
  for (const Ellipsoid& other : apples) {
    if ((other.center_W - c).norm() < 0.97 * (r + other.radii.maxCoeff())) return false;
  }
  for (const Branch& branch : canopy.branches) {
    if (branch.Clearance(c).first < r + 0.003) return false;
  }
  for (const auto& [a, b] : trellis.wires) {
    if (DistanceToSegment(c, a, b) < r + 0.004) return false;
  }
  if (params.supports && std::abs(std::abs(c.y() - B.y()) - trellis.post_y) < r + 0.04) {
    return false;
  }
  return true;
}

/// A candidate centre for an apple of `radius` hanging below the spur's base, swung towards the
/// allowed side (params.fruit_side) by psi from the vertical.
Eigen::Vector3d DrawAppleCentre(const EspalierParams& params, const Spur& spur, double radius,
                                Rng& r) {
  double side = 0.0;
  double psi = 0.0;
  switch (params.fruit_side) {
    case FruitSide::kBoth:
      side = r.Bernoulli(0.5) ? 1.0 : -1.0;
      psi = r.Uniform(0.0, 1.2);
      break;
    case FruitSide::kFront:
      side = -1.0;
      psi = r.Uniform(0.5, 1.3);
      break;
    case FruitSide::kBack:
      side = 1.0;
      psi = r.Uniform(0.7, 1.4);
      break;
  }
  const double gap = params.cordon_base_radius_m + r.Uniform(0.008, 0.025);
  return spur.base + r.Uniform(-0.02, 0.02) * Eigen::Vector3d::UnitY() +
         (radius + gap) * (std::sin(psi) * side * Eigen::Vector3d::UnitX() - std::cos(psi) * kUp);
}

/// An apple at `centre`: slightly flattened along its axis, which leans up to ~14 deg from the
/// vertical.
struct Apple {
  Ellipsoid shape;
  Eigen::Vector3d axis;
};
Apple ShapeApple(const EspalierParams& params, const Eigen::Vector3d& centre, double radius,
                 Rng& r) {
  Apple apple;
  apple.shape.center_W = centre;
  apple.shape.radii = Eigen::Vector3d(
      radius, radius, std::max(params.fruit_radius_min_m, radius * r.Uniform(0.85, 0.95)));
  apple.axis =
      (kUp + Eigen::Vector3d(r.Uniform(-0.25, 0.25), r.Uniform(-0.25, 0.25), 0.0)).normalized();
  apple.shape.R_WE = Eigen::AngleAxisd(r.Uniform(0.0, 2.0 * kPi), apple.axis).toRotationMatrix() *
                     RotationWithZAxis(apple.axis);
  return apple;
}

/// An apple's albedo: red (red_fraction of them) or yellow-green with a faint blush.
Eigen::Vector3f DrawAppleAlbedo(double red_fraction, Rng& r) {
  const bool red = r.Bernoulli(red_fraction);
  const double blush = red ? r.Uniform(0.65, 1.0) : r.Uniform(0.0, 0.3);
  return VaryAlbedo(AppleColor(blush), 0.06, r);
}

/// The stalk from the top of the apple (in its cavity) towards the spur's base.
TriangleMesh AppleStalk(const EspalierParams& params, const Apple& apple,
                        const Eigen::Vector3d& spur_base) {
  const Eigen::Vector3d top = apple.shape.center_W + 0.8 * apple.shape.radii.z() * apple.axis;
  const Eigen::Vector3d towards = spur_base - top;
  const double stalk =
      std::min(0.028, std::max(0.012, towards.norm() - params.cordon_base_radius_m));
  const std::vector<Eigen::Vector3d> line = {top, top + stalk * towards.normalized()};
  return MakeTube(line, LinearRadii(0.0018, 0.0015, 2), 5, true);
}

/// Hangs apples (fruits_min..fruits_max, one or two per spur) from spurs taken in a random order,
/// 12 tries each to find room; adds "<prefix>/apple_NN" and their stalks to the cordons' wood.
std::vector<Ellipsoid> HangApples(const EspalierParams& params, const Trellis& trellis,
                                  const Rng& tree_rng, Canopy& canopy, Scene& scene,
                                  EspalierInfo& info) {
  Rng apple_rng = tree_rng.Fork("apples");
  const int target = static_cast<int>(apple_rng.UniformInt(params.fruits_min, params.fruits_max));
  const std::vector<size_t> order = ShuffledIndices(canopy.spurs.size(), apple_rng);
  std::vector<Ellipsoid> apples;
  for (size_t k = 0; k < order.size() && static_cast<int>(apples.size()) < target; ++k) {
    Rng r = apple_rng.Fork(static_cast<uint64_t>(order[k]));
    const Spur& spur = canopy.spurs[order[k]];
    const int cluster = r.Bernoulli(0.25) ? 2 : 1;
    for (int c = 0; c < cluster && static_cast<int>(apples.size()) < target; ++c) {
      const double radius = r.Uniform(params.fruit_radius_min_m, params.fruit_radius_max_m);
      bool placed = false;
      for (int attempt = 0; attempt < 12 && !placed; ++attempt) {
        const Eigen::Vector3d centre = DrawAppleCentre(params, spur, radius, r);
        if (!AppleFits(centre, radius, params, apples, canopy, trellis)) continue;
        placed = true;
        const Apple apple = ShapeApple(params, centre, radius, r);
        apples.push_back(apple.shape);
        const uint16_t id =
            scene.Add(fmt::format("{}/apple_{:02}", params.name_prefix, apples.size() - 1),
                      SemanticClass::kFruit, DrawAppleAlbedo(params.red_fraction, r), apple.shape);
        info.fruit_ids.push_back(id);
        canopy.cordon_wood[spur.cordon].Append(AppleStalk(params, apple, spur.base));
      }
    }
  }
  return apples;
}

// ---- Occlusion screen ---------------------------------------------------------------------------

/// The point on a branch's centreline whose surface is nearest to p (over all branches).
Eigen::Vector3d NearestBranchPoint(const std::vector<Branch>& branches, const Eigen::Vector3d& p) {
  Eigen::Vector3d anchor = branches.front().line.front();
  double best = std::numeric_limits<double>::infinity();
  for (const Branch& branch : branches) {
    const auto [d, c] = branch.Clearance(p);
    if (d < best) {
      best = d;
      anchor = c;
    }
  }
  return anchor;
}

/// Covering leaf k of the occlusion screen: a blade centred on the spot and facing the eye, at the
/// end of a shoot from the nearest branch with two companion leaves, as on a real one.
/// `leaf_m`: the tree's mean blade length, m.
internal::ScreenLeaf BuildScreenShoot(const EspalierParams& params,
                                      const std::vector<Branch>& branches, double leaf_m, int k,
                                      const internal::ScreenSpot& spot, Rng& r) {
  const Eigen::Vector3d& q = spot.centre_W;
  const Eigen::Vector3d& to_eye = spot.to_eye;
  const Eigen::Vector3d anchor = NearestBranchPoint(branches, q);
  const double length = leaf_m * r.Uniform(1.15, 1.35);
  Eigen::Vector3d direction = Eigen::Vector3d(0.0, r.Uniform(-0.5, 0.5), -1.0);
  direction -= direction.dot(to_eye) * to_eye;
  Eigen::Matrix3d R = RotationWithXAxis(direction, to_eye);
  R = Eigen::AngleAxisd(r.Uniform(-0.25, 0.25), R.col(1)).toRotationMatrix() * R;
  const Eigen::Vector3d blade_base = q - 0.45 * length * R.col(0);
  Eigen::Vector3d shoot = blade_base - anchor;
  if (shoot.norm() < 0.01) shoot += 0.01 * kFront;
  const std::vector<Eigen::Vector3d> line =
      SampleCubicBezier(anchor, anchor + 0.4 * shoot + 0.02 * kUp,
                        anchor + 0.8 * shoot + 0.01 * kUp, anchor + shoot, 6);
  internal::ScreenLeaf leaf;
  leaf.stem = MakeTube(line, LinearRadii(0.003, 0.0018, 6), 5, true);
  AddLeaf(blade_base, R.col(0), length, 0.0, r, leaf.blades, leaf.stem, R);
  for (int j = 0; j < 2; ++j) {
    const Eigen::Vector3d at = line[static_cast<size_t>(2 + j)];
    const double az = r.Uniform(0.0, 2.0 * kPi);
    AddLeaf(at, Eigen::Vector3d(std::cos(az), std::sin(az), r.Uniform(0.0, 0.8)),
            leaf_m * r.Uniform(0.8, 1.2), r.Uniform(0.01, 0.02), r, leaf.blades, leaf.stem);
  }
  leaf.stem_name = fmt::format("{}/screen_shoot_{:02}", params.name_prefix, k);
  leaf.stem_albedo = VaryAlbedo(kBarkColor, 0.1, r);
  leaf.blades_name = fmt::format("{}/screen_leaves_{:02}", params.name_prefix, k);
  leaf.blades_albedo = VaryAlbedo(kLeafColor, 0.12, r);
  return leaf;
}

}  // namespace

Eigen::Vector3f AppleColor(double blush) {
  const double t = std::clamp(blush, 0.0, 1.0);
  const Eigen::Vector3f yellow_green(0.42f, 0.50f, 0.09f);
  const Eigen::Vector3f red(0.48f, 0.035f, 0.03f);
  return yellow_green + static_cast<float>(t) * (red - yellow_green);
}

Status EspalierParams::Validate() const {
  std::vector<std::string> errors;
  const auto check = [&](bool ok, std::string message) {
    if (!ok) errors.push_back(std::move(message));
  };
  check(!name_prefix.empty(), "name_prefix must not be empty");
  check(trunk_base_W.allFinite(),
        fmt::format("trunk_base_W ({}, {}, {}) must be finite", trunk_base_W.x(), trunk_base_W.y(),
                    trunk_base_W.z()));
  check(width_m >= 0.4 && width_m <= 4.0, fmt::format("width_m ({}) must be in [0.4, 4]", width_m));
  check(height_m >= 0.5 && height_m <= 3.0,
        fmt::format("height_m ({}) must be in [0.5, 3]", height_m));
  check(tiers_min >= 2, fmt::format("tiers_min ({}) must be >= 2", tiers_min));
  check(tiers_max >= tiers_min && tiers_max <= 8,
        fmt::format("tiers_max ({}) must be in [tiers_min ({}), 8]", tiers_max, tiers_min));
  check(first_tier_height_m >= 0.15 && first_tier_height_m <= height_m - 0.2,
        fmt::format("first_tier_height_m ({}) must be in [0.15, height_m - 0.2 ({})]",
                    first_tier_height_m, height_m - 0.2));
  check(trunk_radius_m > 0.0 && trunk_radius_m <= 0.1,
        fmt::format("trunk_radius_m ({}) must be in (0, 0.1]", trunk_radius_m));
  check(cordon_base_radius_m > 0.0 && cordon_base_radius_m <= trunk_radius_m,
        fmt::format("cordon_base_radius_m ({}) must be in (0, trunk_radius_m ({})]",
                    cordon_base_radius_m, trunk_radius_m));
  check(cordon_tip_radius_m > 0.0 && cordon_tip_radius_m <= cordon_base_radius_m,
        fmt::format("cordon_tip_radius_m ({}) must be in (0, cordon_base_radius_m ({})]",
                    cordon_tip_radius_m, cordon_base_radius_m));
  check(spur_spacing_m >= 0.03 && spur_spacing_m <= 0.5,
        fmt::format("spur_spacing_m ({}) must be in [0.03, 0.5]", spur_spacing_m));
  check(leaf_density >= 0.0 && leaf_density <= 3.0,
        fmt::format("leaf_density ({}) must be in [0, 3]", leaf_density));
  check(leaf_length_m >= 0.02 && leaf_length_m <= 0.2,
        fmt::format("leaf_length_m ({}) must be in [0.02, 0.2]", leaf_length_m));
  check(fruits_min >= 0, fmt::format("fruits_min ({}) must be >= 0", fruits_min));
  check(fruits_max >= fruits_min && fruits_max <= 200,
        fmt::format("fruits_max ({}) must be in [fruits_min ({}), 200]", fruits_max, fruits_min));
  check(fruit_radius_min_m >= 0.01,
        fmt::format("fruit_radius_min_m ({}) must be >= 0.01", fruit_radius_min_m));
  check(fruit_radius_max_m >= fruit_radius_min_m && fruit_radius_max_m <= 0.1,
        fmt::format("fruit_radius_max_m ({}) must be in [fruit_radius_min_m ({}), 0.1]",
                    fruit_radius_max_m, fruit_radius_min_m));
  check(red_fraction >= 0.0 && red_fraction <= 1.0,
        fmt::format("red_fraction ({}) must be in [0, 1]", red_fraction));
  const Status screen = occlusion.Validate();
  if (!screen.ok()) errors.push_back(screen.message());
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid espalier: {}", fmt::join(errors, "; ")));
}

EspalierInfo AddEspalier(const EspalierParams& params, Rng& rng, Scene& scene) {
  const Status valid = params.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
  // One draw from the caller's generator seeds the tree; each stage forks its own streams.
  const Rng tree_rng(rng.NextU64());
  EspalierInfo info;
  const size_t first_object = scene.objects.size();

  Rng frame_rng = tree_rng.Fork("frame");
  const TrunkModel trunk = DrawFrame(params, frame_rng, info);
  Canopy canopy;
  canopy.branches.push_back(AddTrunk(params, trunk, frame_rng, scene));
  const Trellis trellis = AddTrellis(params, info.tier_heights_m, tree_rng, scene);
  // Mean blade length, m: leaf_length_m scaled by density^0.3 (clamped to [0.7, 1.4]).
  const double leaf_m =
      params.leaf_length_m * std::clamp(std::pow(params.leaf_density, 0.3), 0.7, 1.4);
  GrowCordons(params, trunk, leaf_m, tree_rng, canopy, scene, info);
  const std::vector<Ellipsoid> apples = HangApples(params, trellis, tree_rng, canopy, scene, info);
  for (size_t i = 0; i < canopy.cordon_wood.size(); ++i) {
    scene.Add(canopy.cordon_names[i], SemanticClass::kStem, VaryAlbedo(kBarkColor, 0.1, frame_rng),
              std::move(canopy.cordon_wood[i]));
  }

  const internal::ScreenResult screen = internal::AddOcclusionScreen(
      params.occlusion, apples, first_object, tree_rng,
      {.min_distance_m = 0.04, .clearance_m = 0.01},
      [&](int k, const internal::ScreenSpot& spot, Rng& r) {
        return BuildScreenShoot(params, canopy.branches, leaf_m, k, spot, r);
      },
      scene);
  internal::RecordScreenAndTotals(screen, scene, first_object, info);
  return info;
}

}  // namespace avp::sim

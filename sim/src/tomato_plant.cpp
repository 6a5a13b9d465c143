#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/tomato_plant.h>

#include "occlusion_screen.h"

namespace avp::sim {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kGoldenAngleRad = 137.5 * kPi / 180.0;

const Eigen::Vector3d kUp = Eigen::Vector3d::UnitZ();

double Clamp01(double x) { return std::clamp(x, 0.0, 1.0); }

Eigen::Vector3d Horizontal(double azimuth_rad) {
  return {std::cos(azimuth_rad), std::sin(azimuth_rad), 0.0};
}

/// The main stem's centreline: a vertical line bent by a smooth lean and a small zig-zag.
struct StemModel {
  Eigen::Vector3d base_W = Eigen::Vector3d::Zero();
  double height_m = 1.2;
  Eigen::Vector3d lean_dir = Eigen::Vector3d::UnitX();
  double lean_m = 0.0;
  Eigen::Vector3d wobble_dir = Eigen::Vector3d::UnitY();
  double wobble_m = 0.0;
  double wobble_phase = 0.0;
  double base_radius_m = 0.011;
  double top_radius_m = 0.004;

  Eigen::Vector3d At(double h) const {
    const double f = std::clamp(h / height_m, 0.0, 1.0);
    return base_W + h * kUp + lean_m * std::pow(f, 1.5) * lean_dir +
           wobble_m * f * std::sin(2.0 * kPi * h / 0.23 + wobble_phase) * wobble_dir;
  }
  double RadiusAt(double h) const {
    const double f = std::clamp(h / height_m, 0.0, 1.0);
    return base_radius_m + (top_radius_m - base_radius_m) * f;
  }
};

/// Position and tangent at arc-length fraction f in [0, 1] of a polyline.
struct CurvePoint {
  Eigen::Vector3d p;
  Eigen::Vector3d tangent;
};
CurvePoint PointAlong(const std::vector<Eigen::Vector3d>& line, double f) {
  std::vector<double> cumulative(line.size(), 0.0);
  for (size_t i = 1; i < line.size(); ++i) {
    cumulative[i] = cumulative[i - 1] + (line[i] - line[i - 1]).norm();
  }
  const double target = Clamp01(f) * cumulative.back();
  size_t i = 1;
  while (i + 1 < line.size() && cumulative[i] < target) ++i;
  const double seg = cumulative[i] - cumulative[i - 1];
  const double t = seg > 0.0 ? (target - cumulative[i - 1]) / seg : 0.0;
  return {line[i - 1] + t * (line[i] - line[i - 1]), (line[i] - line[i - 1]).normalized()};
}

Eigen::Matrix3d RotationAbout(const Eigen::Vector3d& axis, double angle_rad) {
  return Eigen::AngleAxisd(angle_rad, axis.normalized()).toRotationMatrix();
}

/// One compound leaf: a rachis tube and the leaflets along it.
struct CompoundLeaf {
  TriangleMesh rachis;
  TriangleMesh leaflets;
  int num_main_leaflets = 0;
};

struct CompoundLeafSpec {
  std::vector<Eigen::Vector3d> rachis_line;  // from the stem node to the terminal leaflet's base
  double rachis_base_radius_m = 0.003;
  int pairs = 3;
  double leaflet_length_m = 0.08;
  bool intercalary = true;
  /// When set, the terminal leaflet uses this frame (x: blade direction, z: upper side) instead
  /// of following the rachis; used by the occlusion screen to face the eye.
  std::optional<Eigen::Matrix3d> terminal_frame;
  double terminal_length_m = 0.0;  ///< 0: 1.2 x leaflet_length_m
};

LeafBladeParams RandomLeafletShape(double length_m, Rng& rng, int segments_along,
                                   int segments_across) {
  LeafBladeParams blade;
  blade.length_m = length_m;
  blade.width_m = length_m * rng.Uniform(0.45, 0.58);
  blade.widest_at = rng.Uniform(0.33, 0.45);
  blade.midrib_bend_rad = rng.Uniform(0.15, 0.65);
  blade.cup = rng.Uniform(0.05, 0.3);
  blade.twist_rad = rng.Uniform(-0.3, 0.3);
  blade.segments_along = segments_along;
  blade.segments_across = segments_across;
  return blade;
}

CompoundLeaf BuildCompoundLeaf(const CompoundLeafSpec& spec, Rng& rng) {
  CompoundLeaf leaf;
  const std::vector<double> radii =
      LinearRadii(spec.rachis_base_radius_m, 0.45 * spec.rachis_base_radius_m,
                  static_cast<int>(spec.rachis_line.size()));
  leaf.rachis = MakeTube(spec.rachis_line, radii, 6, true);

  const auto add_leaflet = [&](const CurvePoint& at, double side, double length_m,
                               double spread_rad, bool small) {
    // Leaf plane: normal N is the rachis normal closest to world up; leaflets fan out sideways.
    const Eigen::Matrix3d rachis_frame = RotationWithXAxis(at.tangent, kUp);
    const Eigen::Vector3d T = rachis_frame.col(0);
    const Eigen::Vector3d S = rachis_frame.col(1);  // to the left of the rachis
    const Eigen::Vector3d N = rachis_frame.col(2);
    Eigen::Vector3d direction = std::cos(spread_rad) * T + side * std::sin(spread_rad) * S;
    direction = (direction - rng.Uniform(0.0, 0.35) * N).normalized();  // leaflets droop
    Eigen::Matrix3d R = RotationWithXAxis(direction, N);
    R = RotationAbout(R.col(0), side * rng.Uniform(-0.1, 0.45)) * R;  // roll about the midrib
    const LeafBladeParams blade =
        small ? RandomLeafletShape(length_m, rng, 4, 1) : RandomLeafletShape(length_m, rng, 11, 3);
    const Eigen::Vector3d base = at.p + 0.006 * direction;
    leaf.leaflets.Append(MakeLeafBlade(blade), RigidTransform(R, base));
  };

  // Lateral pairs between 32 % and 86 % of the rachis, growing towards the tip.
  const int pairs = spec.pairs;
  double previous_f = 0.25;
  for (int j = 0; j < pairs; ++j) {
    const double f = pairs == 1 ? 0.6 : 0.32 + 0.54 * j / (pairs - 1);
    const double length = spec.leaflet_length_m * (0.75 + 0.45 * f) * rng.Uniform(0.85, 1.15);
    for (const double side : {1.0, -1.0}) {
      const double jitter_f = std::clamp(f + rng.Uniform(-0.03, 0.03), 0.0, 0.97);
      add_leaflet(PointAlong(spec.rachis_line, jitter_f), side, length,
                  rng.Uniform(50.0, 78.0) * kPi / 180.0, false);
    }
    if (spec.intercalary && j > 0) {
      const double fm = 0.5 * (previous_f + f);
      for (const double side : {1.0, -1.0}) {
        if (!rng.Bernoulli(0.7)) continue;
        add_leaflet(PointAlong(spec.rachis_line, fm), side,
                    spec.leaflet_length_m * rng.Uniform(0.22, 0.35),
                    rng.Uniform(60.0, 90.0) * kPi / 180.0, true);
      }
    }
    previous_f = f;
  }
  leaf.num_main_leaflets = 2 * pairs + 1;

  // Terminal leaflet.
  const CurvePoint tip = PointAlong(spec.rachis_line, 1.0);
  const double terminal_length = spec.terminal_length_m > 0.0
                                     ? spec.terminal_length_m
                                     : 1.2 * spec.leaflet_length_m * rng.Uniform(0.9, 1.1);
  LeafBladeParams blade = RandomLeafletShape(terminal_length, rng, 11, 3);
  Eigen::Matrix3d R;
  if (spec.terminal_frame) {
    R = *spec.terminal_frame;
    blade.midrib_bend_rad = rng.Uniform(0.1, 0.3);
    blade.width_m = terminal_length * rng.Uniform(0.58, 0.65);
  } else {
    Eigen::Vector3d direction = (tip.tangent - rng.Uniform(0.1, 0.4) * kUp).normalized();
    R = RotationWithXAxis(direction, kUp);
  }
  leaf.leaflets.Append(MakeLeafBlade(blade), RigidTransform(R, tip.p));
  return leaf;
}

Eigen::Vector3f LeafColor(double height_fraction, Rng& rng) {
  // Young leaves are a lighter, yellower green; old ones darker. Linear RGB.
  const Eigen::Vector3f young(0.12f, 0.32f, 0.05f);
  const Eigen::Vector3f old(0.06f, 0.19f, 0.035f);
  const float t = static_cast<float>(Clamp01(height_fraction));
  Eigen::Vector3f c = old + t * (young - old);
  if (rng.Bernoulli(0.12)) c += Eigen::Vector3f(0.05f, 0.03f, 0.0f);  // a yellowing leaf
  return VaryAlbedo(c, 0.12, rng);
}

const Eigen::Vector3f kStemColor(0.16f, 0.30f, 0.07f);

// ---- Stem and stake -----------------------------------------------------------------------------

/// Draws the main stem (height, lean, zig-zag) and adds "<prefix>/stem".
StemModel AddStem(const TomatoPlantParams& params, const Rng& plant_rng, Scene& scene) {
  Rng stem_rng = plant_rng.Fork("stem");
  StemModel stem;
  stem.base_W = params.stem_base_W;
  stem.height_m = stem_rng.Uniform(params.height_min_m, params.height_max_m);
  stem.lean_dir = Horizontal(stem_rng.Uniform(0.0, 2.0 * kPi));
  stem.lean_m = stem_rng.Uniform(0.0, params.stem_lean_max_m);
  stem.wobble_dir = Horizontal(stem_rng.Uniform(0.0, 2.0 * kPi));
  stem.wobble_m = stem_rng.Uniform(0.002, 0.008);
  stem.wobble_phase = stem_rng.Uniform(0.0, 2.0 * kPi);
  stem.base_radius_m = params.stem_base_radius_m;
  stem.top_radius_m = params.stem_top_radius_m;
  const int n = std::max(8, static_cast<int>(std::ceil(stem.height_m / 0.025)) + 1);
  std::vector<Eigen::Vector3d> line;
  std::vector<double> radii;
  for (int i = 0; i < n; ++i) {
    const double h = stem.height_m * i / (n - 1);
    line.push_back(stem.At(h));
    radii.push_back(stem.RadiusAt(h));
  }
  scene.Add(params.name_prefix + "/stem", SemanticClass::kStem,
            VaryAlbedo(kStemColor, 0.08, stem_rng), MakeTube(line, radii, 12, true));
  return stem;
}

/// A vertical stake from base_W, height_m tall.
struct Stake {
  Eigen::Vector3d base_W = Eigen::Vector3d::Zero();
  double height_m = 0.0;
};

/// Draws the stake's height (90-105 % of the stem's, drawn even without a stake) and adds
/// "<prefix>/stake" when params.stake.
Stake AddStake(const TomatoPlantParams& params, const StemModel& stem, const Rng& plant_rng,
               Scene& scene) {
  Rng stake_rng = plant_rng.Fork("stake");
  Stake stake;
  stake.base_W = params.stem_base_W + params.stake_offset_m;
  stake.height_m = stem.height_m * stake_rng.Uniform(0.9, 1.05);
  if (params.stake) {
    scene.Add(
        params.name_prefix + "/stake", SemanticClass::kSupport,
        VaryAlbedo(Eigen::Vector3f(0.33f, 0.22f, 0.11f), 0.1, stake_rng),
        MakeCylinder(stake.base_W, stake.base_W + stake.height_m * kUp, params.stake_radius_m, 8));
  }
  return stake;
}

// ---- Compound leaves (phyllotaxis) --------------------------------------------------------------

/// Pairs of lateral leaflets of one compound leaf: 2 pairs + 1 (the terminal) main leaflets lie
/// in [leaflets_min, leaflets_max].
int DrawLeafletPairs(const TomatoPlantParams& params, Rng& r) {
  return static_cast<int>(
      r.UniformInt((params.leaflets_min - 1) / 2, (params.leaflets_max - 1) / 2));
}

/// The leaf at stem height h pointing at `azimuth`: near the apex leaves are younger (shorter,
/// steeper, smaller leaflets); low ones keep their tips (and drooping leaflets) off the ground.
/// `size_scale`: the leaf size factor from the density.
CompoundLeafSpec StemLeafSpec(const TomatoPlantParams& params, const StemModel& stem,
                              double size_scale, double h, double azimuth, Rng& r) {
  const double fh = h / stem.height_m;
  const Eigen::Vector3d d = Horizontal(azimuth);
  const Eigen::Vector3d lateral = kUp.cross(d);
  const double youth = std::clamp((fh - 0.75) / 0.25, 0.0, 1.0);
  const double length =
      params.leaf_length_m * size_scale * r.Uniform(0.8, 1.2) * (1.0 - 0.55 * youth);
  const double elevation = (r.Uniform(30.0, 55.0) + 25.0 * youth) * kPi / 180.0;
  const Eigen::Vector3d s = stem.At(h);
  const double droop =
      std::min(r.Uniform(0.05, 0.35) * (1.0 - youth), (s.z() - stem.base_W.z() - 0.12) / length);
  const Eigen::Vector3d p0 = s + 0.8 * stem.RadiusAt(h) * d;
  const Eigen::Vector3d p1 =
      p0 + 0.3 * length * (std::cos(elevation) * d + std::sin(elevation) * kUp);
  const Eigen::Vector3d p2 =
      p0 + 0.7 * length * d + 0.15 * length * kUp + r.Uniform(-0.08, 0.08) * length * lateral;
  const Eigen::Vector3d p3 = p0 + length * d - droop * length * kUp;
  CompoundLeafSpec spec;
  spec.rachis_line = SampleCubicBezier(p0, p1, p2, p3, 14);
  spec.rachis_base_radius_m = 0.0032 * size_scale;
  spec.pairs = DrawLeafletPairs(params, r);
  spec.leaflet_length_m = params.leaflet_length_m * size_scale * (1.0 - 0.4 * youth);
  spec.intercalary = params.intercalary_leaflets;
  return spec;
}

/// Compound leaves every 1 / (12 leaf_density) m (+-20 %) in a 137.5 deg spiral, from
/// first_leaf_height_m to 4 cm below the top; adds "<prefix>/leaf_NN" (+ "/rachis") and returns
/// how many.
int AddStemLeaves(const TomatoPlantParams& params, const StemModel& stem, double size_scale,
                  const Rng& plant_rng, Scene& scene) {
  if (params.leaf_density <= 0.0) return 0;
  const Rng leaves_rng = plant_rng.Fork("leaves");
  const double leaf_spacing_m = 1.0 / (12.0 * params.leaf_density);
  Rng layout = leaves_rng.Fork("layout");
  const double phase = layout.Uniform(0.0, 2.0 * kPi);
  int k = 0;
  for (double h = params.first_leaf_height_m + layout.Uniform(0.0, leaf_spacing_m);
       h < stem.height_m - 0.04; h += leaf_spacing_m * layout.Uniform(0.8, 1.2), ++k) {
    Rng r = leaves_rng.Fork(static_cast<uint64_t>(k));
    const double azimuth = phase + k * kGoldenAngleRad + r.Uniform(-0.17, 0.17);
    CompoundLeaf leaf = BuildCompoundLeaf(StemLeafSpec(params, stem, size_scale, h, azimuth, r), r);
    const std::string name = fmt::format("{}/leaf_{:02}", params.name_prefix, k);
    scene.Add(name + "/rachis", SemanticClass::kStem, VaryAlbedo(kStemColor, 0.1, r),
              std::move(leaf.rachis));
    scene.Add(name, SemanticClass::kLeaf, LeafColor(h / stem.height_m, r),
              std::move(leaf.leaflets));
  }
  return k;  // one leaf per step
}

// ---- Trusses and fruits -------------------------------------------------------------------------

/// Where a new fruit may go: above the ground, not deep into a fruit placed so far, clear of the
/// stem and the stake.
struct FruitRoom {
  const TomatoPlantParams& params;
  const StemModel& stem;
  Stake stake;
  std::vector<Ellipsoid> fruits;  ///< placed so far

  bool Fits(const Eigen::Vector3d& c, double r) const {
    if (c.z() - r < 0.02) return false;      // above the ground
    for (const Ellipsoid& other : fruits) {  // slight touching is fine, no deep overlap
      if ((other.center_W - c).norm() < 0.95 * (r + other.radii.maxCoeff())) return false;
    }
    const double h = c.z() - stem.base_W.z();
    const Eigen::Vector3d axis = stem.At(std::clamp(h, 0.0, stem.height_m));
    if ((c - axis).head<2>().norm() < r + stem.RadiusAt(h) + 0.004) return false;
    if (params.stake && c.z() < stake.base_W.z() + stake.height_m + r &&
        (c - stake.base_W).head<2>().norm() < r + params.stake_radius_m + 0.003) {
      return false;
    }
    return true;
  }
};

/// A truss's rachis: from the peduncle's end e0 along e (outwards and down), curling sideways
/// along `lateral`; u is the distance along e, m.
struct TrussAxis {
  Eigen::Vector3d e0 = Eigen::Vector3d::Zero();
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  Eigen::Vector3d lateral = Eigen::Vector3d::Zero();
  double curl = 0.0;

  Eigen::Vector3d At(double u) const { return e0 + u * e + curl * u * u * lateral; }
};

/// One truss as it grows.
struct Truss {
  int index = 0;
  TrussAxis axis;
  std::vector<double> fruit_radii;  ///< largest (proximal) first
  double ripeness = 0.0;            ///< before the per-fruit gradient and jitter
  TriangleMesh mesh;                ///< peduncle, rachis, pedicels, calyces
  double last_u = 0.0;              ///< where the last placed fruit hangs
  int placed = 0;
};

/// The peduncle from the stem at height h towards `azimuth`: out from the stem, arching slightly
/// up, then down into the rachis, whose shape it returns.
TrussAxis AddPeduncle(const StemModel& stem, double h, double azimuth, Rng& r,
                      TriangleMesh& truss_mesh) {
  const Eigen::Vector3d d = Horizontal(azimuth);
  const Eigen::Vector3d lateral = kUp.cross(d);
  const Eigen::Vector3d s = stem.At(h) + 0.8 * stem.RadiusAt(h) * d;
  const double peduncle = r.Uniform(0.05, 0.09);
  const Eigen::Vector3d e0 = s + peduncle * d - 0.02 * kUp;
  const std::vector<Eigen::Vector3d> peduncle_line = SampleCubicBezier(
      s, s + 0.35 * peduncle * d + 0.02 * kUp, s + 0.75 * peduncle * d + 0.005 * kUp, e0, 8);
  truss_mesh.Append(MakeTube(peduncle_line, LinearRadii(0.0035, 0.0025, 8), 6, true));
  // Rachis: a gently curved line going outwards and down.
  const double beta = r.Uniform(35.0, 65.0) * kPi / 180.0;
  TrussAxis axis;
  axis.e0 = e0;
  axis.e = std::cos(beta) * d - std::sin(beta) * kUp;
  axis.lateral = lateral;
  axis.curl = r.Uniform(-0.8, 0.8);
  return axis;
}

/// The radii of a truss's fruits, fruits_per_truss_min..max of them, largest first (proximal
/// fruits are the largest).
std::vector<double> DrawFruitRadii(const TomatoPlantParams& params, Rng& r) {
  const int n =
      static_cast<int>(r.UniformInt(params.fruits_per_truss_min, params.fruits_per_truss_max));
  std::vector<double> radii(static_cast<size_t>(n));
  for (double& radius : radii) {
    radius = r.Uniform(params.fruit_radius_min_m, params.fruit_radius_max_m);
  }
  std::sort(radii.begin(), radii.end(), std::greater<>());
  return radii;
}

/// Where a fruit hangs from the rachis: `u` along it, `attach` on it, `center` of the fruit.
struct FruitSpot {
  bool fits = false;
  double u = 0.0;  ///< the last one tried when nothing fits
  Eigen::Vector3d attach = Eigen::Vector3d::Zero();
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
};

/// Slides a fruit of `radius` along the rachis from u0 in 6 mm steps (40 tries) on `side` until it
/// fits, then the same on the other side of the rachis.
FruitSpot FindFruitSpot(const TrussAxis& axis, double u0, double radius, double side,
                        const FruitRoom& room) {
  FruitSpot spot;
  for (int attempt = 0; attempt < 80 && !spot.fits; ++attempt) {
    const double this_side = attempt < 40 ? side : -side;
    spot.u = u0 + 0.006 * (attempt % 40);
    spot.attach = axis.At(spot.u);
    spot.center = spot.attach + this_side * (0.75 * radius + 0.006) * axis.lateral -
                  (0.7 * radius + 0.006) * kUp;
    spot.fits = room.Fits(spot.center, radius);
  }
  return spot;
}

/// A tomato at `spot`: slightly flattened along its axis, which leans towards the attachment.
struct Tomato {
  Ellipsoid shape;
  Eigen::Vector3d axis;
};
Tomato ShapeTomato(const TomatoPlantParams& params, const FruitSpot& spot, double radius, Rng& r) {
  Tomato fruit;
  fruit.shape.center_W = spot.center;
  const double polar = std::max(params.fruit_radius_min_m, radius * r.Uniform(0.82, 0.95));
  fruit.shape.radii = Eigen::Vector3d(radius, radius, polar);
  fruit.axis = (0.6 * (spot.attach - spot.center).normalized() + 0.4 * kUp).normalized();
  Eigen::Matrix3d R = RotationWithZAxis(fruit.axis);
  R = RotationAbout(fruit.axis, r.Uniform(0.0, 2.0 * kPi)) * R;
  fruit.shape.R_WE = R;
  return fruit;
}

/// The albedo of fruit i of n on a truss: lower trusses are riper and within a truss the proximal
/// fruits ripen first; ripeness is mapped into [ripeness_min, ripeness_max].
Eigen::Vector3f DrawTomatoAlbedo(const TomatoPlantParams& params, double truss_ripeness, int i,
                                 int n, Rng& r) {
  const double ripeness =
      Clamp01(truss_ripeness + 0.2 * (0.5 - static_cast<double>(i) / std::max(1, n - 1)) +
              r.Normal(0.0, 0.07));
  const double mapped =
      params.ripeness_min + (params.ripeness_max - params.ripeness_min) * ripeness;
  return VaryAlbedo(TomatoColor(mapped), 0.05, r);
}

/// The pedicel from the rachis at `attach` to the calyx at the fruit's top, and its five sepals.
void AddPedicelAndCalyx(const Tomato& fruit, const Eigen::Vector3d& attach, Rng& r,
                        TriangleMesh& truss_mesh) {
  const double radius = fruit.shape.radii.x();
  const double polar = fruit.shape.radii.z();
  const Eigen::Matrix3d& R = fruit.shape.R_WE;
  const Eigen::Vector3d& axis = fruit.axis;
  const Eigen::Vector3d top = fruit.shape.center_W + polar * axis;
  if ((top - attach).norm() > 0.003) {
    const Eigen::Vector3d mid = 0.5 * (top + attach) + 0.004 * kUp;
    const std::vector<Eigen::Vector3d> pedicel = {attach, mid, top};
    truss_mesh.Append(MakeTube(pedicel, LinearRadii(0.0016, 0.0013, 3), 5, true));
  }
  const double sepal_phase = r.Uniform(0.0, 2.0 * kPi);
  for (int k = 0; k < 5; ++k) {
    const double theta = sepal_phase + 2.0 * kPi * k / 5.0;
    const Eigen::Vector3d out = std::cos(theta) * R.col(0) + std::sin(theta) * R.col(1);
    LeafBladeParams sepal;
    sepal.length_m = 0.55 * radius * r.Uniform(0.85, 1.15);
    sepal.width_m = 0.2 * radius;
    sepal.widest_at = 0.3;
    sepal.midrib_bend_rad = std::min(1.2, sepal.length_m * polar / (radius * radius));
    sepal.cup = 0.0;
    sepal.segments_along = 3;
    sepal.segments_across = 1;
    truss_mesh.Append(MakeLeafBlade(sepal),
                      RigidTransform(RotationWithXAxis(out, axis), top + 0.0015 * axis));
  }
}

/// Hangs the truss's fruits along its rachis, alternating sides, each where it first fits (a
/// fruit with no room is left out); adds "<prefix>/fruit_K_J" and their pedicels and calyces.
void HangFruits(const TomatoPlantParams& params, Truss& truss, Rng& r, FruitRoom& room,
                Scene& scene, TomatoPlantInfo& info) {
  const std::vector<double>& radii = truss.fruit_radii;
  const int n = static_cast<int>(radii.size());
  double u = 0.0;
  for (int i = 0; i < n; ++i) {
    const double radius = radii[static_cast<size_t>(i)];
    const double side = (i % 2 == 0 ? 1.0 : -1.0) * (truss.axis.curl >= 0.0 ? 1.0 : -1.0);
    u = i == 0 ? 0.012 + 0.3 * radius
               : u + r.Uniform(0.5, 0.7) * (radii[static_cast<size_t>(i - 1)] + radius);
    const FruitSpot spot = FindFruitSpot(truss.axis, u, radius, side, room);
    u = spot.u;
    if (!spot.fits) continue;  // no room on this truss: a smaller truss (see fruits_per_truss)
    truss.last_u = u;
    const Tomato fruit = ShapeTomato(params, spot, radius, r);
    room.fruits.push_back(fruit.shape);
    const uint16_t id = scene.Add(
        fmt::format("{}/fruit_{}_{}", params.name_prefix, truss.index, truss.placed),
        SemanticClass::kFruit, DrawTomatoAlbedo(params, truss.ripeness, i, n, r), fruit.shape);
    info.fruit_ids.push_back(id);
    ++truss.placed;
    AddPedicelAndCalyx(fruit, spot.attach, r, truss.mesh);
  }
}

/// The rachis tube, running a little past the last fruit.
void AddTrussRachis(Truss& truss) {
  const double rachis_length = std::max(0.02, truss.last_u + 0.012);
  const int m = std::max(3, static_cast<int>(std::ceil(rachis_length / 0.01)) + 1);
  std::vector<Eigen::Vector3d> rachis_line;
  for (int i = 0; i < m; ++i) rachis_line.push_back(truss.axis.At(rachis_length * i / (m - 1)));
  truss.mesh.Append(MakeTube(rachis_line, LinearRadii(0.0025, 0.0015, m), 6, true));
}

/// trusses_min..max trusses up the stem, alternating sides (or within the azimuth spread), each
/// with its fruits; adds "<prefix>/truss_K" and the fruits, and returns the fruits' shapes.
std::vector<Ellipsoid> AddTrusses(const TomatoPlantParams& params, const Rng& plant_rng,
                                  FruitRoom room, Scene& scene, TomatoPlantInfo& info) {
  Rng truss_rng = plant_rng.Fork("trusses");
  const int num_trusses =
      static_cast<int>(truss_rng.UniformInt(params.trusses_min, params.trusses_max));
  const double spread = params.truss_azimuth_spread_deg * kPi / 180.0;
  const bool full_circle = params.truss_azimuth_spread_deg >= 360.0;
  double azimuth =
      full_circle ? truss_rng.Uniform(0.0, 2.0 * kPi) : params.truss_azimuth_deg * kPi / 180.0;
  for (int t = 0; t < num_trusses; ++t) {
    Rng r = truss_rng.Fork(static_cast<uint64_t>(t));
    const double fraction = params.truss_height_min_fraction +
                            (params.truss_height_max_fraction - params.truss_height_min_fraction) *
                                (t + r.Uniform(0.15, 0.85)) / num_trusses;
    const double h = fraction * room.stem.height_m;
    if (full_circle) {
      if (t > 0) azimuth += kPi + r.Uniform(-0.9, 0.9);  // trusses alternate sides
    } else {
      azimuth = params.truss_azimuth_deg * kPi / 180.0 + r.Uniform(-0.5, 0.5) * spread;
    }
    Truss truss;
    truss.index = t;
    truss.axis = AddPeduncle(room.stem, h, azimuth, r, truss.mesh);
    truss.fruit_radii = DrawFruitRadii(params, r);
    // Lower trusses are riper.
    truss.ripeness = Clamp01(1.0 - (t + 0.5) / std::max(1, num_trusses) + r.Normal(0.0, 0.12));
    HangFruits(params, truss, r, room, scene, info);
    AddTrussRachis(truss);
    scene.Add(fmt::format("{}/truss_{}", params.name_prefix, t), SemanticClass::kStem,
              VaryAlbedo(kStemColor, 0.1, r), std::move(truss.mesh));
    info.fruits_per_truss.push_back(truss.placed);
  }
  return std::move(room.fruits);
}

// ---- Occlusion screen ---------------------------------------------------------------------------

/// The terminal leaflet of a covering leaf: `length_m` long, in frame R (facing the eye, tilted a
/// little, pointing outwards and down from the stem), its midrib starting at `base_W`.
struct ScreenLeaflet {
  double length_m = 0.0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d base_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d outward = Eigen::Vector3d::Zero();  ///< horizontal, away from the stem
};
ScreenLeaflet OrientScreenLeaflet(const StemModel& stem, double size_scale,
                                  const internal::ScreenSpot& spot, Rng& r) {
  const Eigen::Vector3d& q = spot.centre_W;
  const Eigen::Vector3d& to_eye = spot.to_eye;
  ScreenLeaflet leaflet;
  leaflet.length_m = r.Uniform(0.10, 0.13) * size_scale;
  const double h_q = std::clamp(q.z() - stem.base_W.z(), 0.0, stem.height_m);
  Eigen::Vector3d outward = q - stem.At(h_q);
  outward.z() = 0.0;
  if (outward.norm() < 1e-3) outward = -to_eye;
  Eigen::Vector3d direction = outward.normalized() - r.Uniform(0.3, 1.0) * kUp;
  direction -= direction.dot(to_eye) * to_eye;
  if (direction.norm() < 1e-6) direction = RotationWithZAxis(to_eye).col(0);
  Eigen::Matrix3d R = RotationWithXAxis(direction, to_eye);
  R = RotationAbout(R.col(1), r.Uniform(-0.25, 0.25)) * R;
  leaflet.R = R;
  // The blade's middle is ~0.42 of its length along the midrib.
  leaflet.base_W = q - 0.42 * leaflet.length_m * R.col(0);
  leaflet.outward = outward;
  return leaflet;
}

/// Covering leaf k of the occlusion screen: a compound leaf whose rachis arches out from a stem
/// node above the spot to its terminal leaflet, which is centred on the spot and faces the eye.
internal::ScreenLeaf BuildScreenLeaf(const TomatoPlantParams& params, const StemModel& stem,
                                     double size_scale, int k, const internal::ScreenSpot& spot,
                                     Rng& r) {
  const ScreenLeaflet leaflet = OrientScreenLeaflet(stem, size_scale, spot, r);
  const double h_node = std::clamp(leaflet.base_W.z() - stem.base_W.z() + r.Uniform(0.02, 0.07),
                                   params.first_leaf_height_m, stem.height_m - 0.03);
  const Eigen::Vector3d s = stem.At(h_node);
  Eigen::Vector3d reach = leaflet.base_W - s;
  Eigen::Vector3d reach_dir = reach;
  reach_dir.z() = 0.0;
  if (reach_dir.norm() < 1e-3) reach_dir = leaflet.outward;
  reach_dir.normalize();
  const Eigen::Vector3d p0 = s + 0.8 * stem.RadiusAt(h_node) * reach_dir;
  reach = leaflet.base_W - p0;
  if (reach.norm() < 0.02) reach += 0.02 * reach_dir;
  CompoundLeafSpec spec;
  spec.rachis_line = SampleCubicBezier(p0, p0 + 0.4 * reach + 0.04 * kUp,
                                       p0 + 0.75 * reach + 0.03 * kUp, p0 + reach, 12);
  spec.rachis_base_radius_m = 0.003 * size_scale;
  spec.pairs = DrawLeafletPairs(params, r);
  spec.leaflet_length_m = params.leaflet_length_m * size_scale;
  spec.intercalary = params.intercalary_leaflets;
  spec.terminal_frame = leaflet.R;
  spec.terminal_length_m = leaflet.length_m;
  CompoundLeaf leaf = BuildCompoundLeaf(spec, r);
  internal::ScreenLeaf screen_leaf;
  screen_leaf.blades_name = fmt::format("{}/screen_leaf_{:02}", params.name_prefix, k);
  screen_leaf.stem_name = screen_leaf.blades_name + "/rachis";
  screen_leaf.stem = std::move(leaf.rachis);
  screen_leaf.stem_albedo = VaryAlbedo(kStemColor, 0.1, r);
  screen_leaf.blades = std::move(leaf.leaflets);
  screen_leaf.blades_albedo = LeafColor(h_node / stem.height_m, r);
  return screen_leaf;
}

}  // namespace

Eigen::Vector3f TomatoColor(double ripeness) {
  const double t = Clamp01(ripeness);
  const Eigen::Vector3f green(0.16f, 0.36f, 0.05f);
  const Eigen::Vector3f breaker(0.45f, 0.42f, 0.06f);
  const Eigen::Vector3f orange(0.78f, 0.26f, 0.03f);
  const Eigen::Vector3f red(0.56f, 0.035f, 0.02f);
  const auto mix = [](const Eigen::Vector3f& a, const Eigen::Vector3f& b, double s) {
    return Eigen::Vector3f(a + static_cast<float>(s) * (b - a));
  };
  if (t < 0.35) return mix(green, breaker, t / 0.35);
  if (t < 0.65) return mix(breaker, orange, (t - 0.35) / 0.3);
  return mix(orange, red, (t - 0.65) / 0.35);
}

Status TomatoPlantParams::Validate() const {
  std::vector<std::string> errors;
  const auto check = [&](bool ok, std::string message) {
    if (!ok) errors.push_back(std::move(message));
  };
  check(!name_prefix.empty(), "name_prefix must not be empty");
  check(stem_base_W.allFinite(), fmt::format("stem_base_W ({}, {}, {}) must be finite",
                                             stem_base_W.x(), stem_base_W.y(), stem_base_W.z()));
  check(height_min_m >= 0.3 && height_min_m <= 3.0,
        fmt::format("height_min_m ({}) must be in [0.3, 3]", height_min_m));
  check(height_max_m >= height_min_m && height_max_m <= 3.0,
        fmt::format("height_max_m ({}) must be in [height_min_m ({}), 3]", height_max_m,
                    height_min_m));
  check(stem_base_radius_m > 0.0 && stem_base_radius_m <= 0.05,
        fmt::format("stem_base_radius_m ({}) must be in (0, 0.05]", stem_base_radius_m));
  check(stem_top_radius_m > 0.0 && stem_top_radius_m <= stem_base_radius_m,
        fmt::format("stem_top_radius_m ({}) must be in (0, stem_base_radius_m ({})]",
                    stem_top_radius_m, stem_base_radius_m));
  check(stem_lean_max_m >= 0.0 && stem_lean_max_m <= 0.3,
        fmt::format("stem_lean_max_m ({}) must be in [0, 0.3]", stem_lean_max_m));
  check(leaf_density >= 0.0 && leaf_density <= 3.0,
        fmt::format("leaf_density ({}) must be in [0, 3]", leaf_density));
  check(leaf_length_m >= 0.05 && leaf_length_m <= 1.0,
        fmt::format("leaf_length_m ({}) must be in [0.05, 1]", leaf_length_m));
  check(leaflet_length_m >= 0.01 && leaflet_length_m <= 0.3,
        fmt::format("leaflet_length_m ({}) must be in [0.01, 0.3]", leaflet_length_m));
  check(leaflets_min >= 3 && leaflets_min % 2 == 1,
        fmt::format("leaflets_min ({}) must be odd and >= 3", leaflets_min));
  check(leaflets_max >= leaflets_min && leaflets_max <= 15 && leaflets_max % 2 == 1,
        fmt::format("leaflets_max ({}) must be odd and in [leaflets_min ({}), 15]", leaflets_max,
                    leaflets_min));
  check(first_leaf_height_m >= 0.0 && first_leaf_height_m < height_min_m,
        fmt::format("first_leaf_height_m ({}) must be in [0, height_min_m ({}))",
                    first_leaf_height_m, height_min_m));
  check(trusses_min >= 0, fmt::format("trusses_min ({}) must be >= 0", trusses_min));
  check(
      trusses_max >= trusses_min && trusses_max <= 12,
      fmt::format("trusses_max ({}) must be in [trusses_min ({}), 12]", trusses_max, trusses_min));
  check(fruits_per_truss_min >= 1,
        fmt::format("fruits_per_truss_min ({}) must be >= 1", fruits_per_truss_min));
  check(fruits_per_truss_max >= fruits_per_truss_min && fruits_per_truss_max <= 12,
        fmt::format("fruits_per_truss_max ({}) must be in [fruits_per_truss_min ({}), 12]",
                    fruits_per_truss_max, fruits_per_truss_min));
  check(fruit_radius_min_m >= 0.005,
        fmt::format("fruit_radius_min_m ({}) must be >= 0.005", fruit_radius_min_m));
  check(fruit_radius_max_m >= fruit_radius_min_m && fruit_radius_max_m <= 0.08,
        fmt::format("fruit_radius_max_m ({}) must be in [fruit_radius_min_m ({}), 0.08]",
                    fruit_radius_max_m, fruit_radius_min_m));
  check(
      truss_height_min_fraction >= 0.2 && truss_height_min_fraction <= 1.0,
      fmt::format("truss_height_min_fraction ({}) must be in [0.2, 1]", truss_height_min_fraction));
  check(truss_height_max_fraction >= truss_height_min_fraction && truss_height_max_fraction <= 1.0,
        fmt::format("truss_height_max_fraction ({}) must be in [truss_height_min_fraction ({}), 1]",
                    truss_height_max_fraction, truss_height_min_fraction));
  check(std::isfinite(truss_azimuth_deg),
        fmt::format("truss_azimuth_deg ({}) must be finite", truss_azimuth_deg));
  check(truss_azimuth_spread_deg >= 0.0 && truss_azimuth_spread_deg <= 360.0,
        fmt::format("truss_azimuth_spread_deg ({}) must be in [0, 360]", truss_azimuth_spread_deg));
  check(ripeness_min >= 0.0 && ripeness_min <= ripeness_max && ripeness_max <= 1.0,
        fmt::format("ripeness range [{}, {}] must satisfy 0 <= min <= max <= 1", ripeness_min,
                    ripeness_max));
  check(stake_radius_m > 0.0 && stake_radius_m <= 0.05,
        fmt::format("stake_radius_m ({}) must be in (0, 0.05]", stake_radius_m));
  check(stake_offset_m.allFinite() &&
            (!stake || stake_offset_m.head<2>().norm() >= stem_base_radius_m + stake_radius_m),
        fmt::format("stake_offset_m ({}, {}) must be finite and clear the stem (horizontal "
                    "distance >= {} m)",
                    stake_offset_m.x(), stake_offset_m.y(), stem_base_radius_m + stake_radius_m));
  const Status screen = occlusion.Validate();
  if (!screen.ok()) errors.push_back(screen.message());
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid tomato plant: {}", fmt::join(errors, "; ")));
}

TomatoPlantInfo AddTomatoPlant(const TomatoPlantParams& params, Rng& rng, Scene& scene) {
  const Status valid = params.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
  // One draw from the caller's generator seeds this plant; organs get independent sub-streams,
  // so e.g. changing the leaf density does not move the fruit.
  const Rng plant_rng(rng.NextU64());
  TomatoPlantInfo info;
  const size_t first_object = scene.objects.size();

  const StemModel stem = AddStem(params, plant_rng, scene);
  info.height_m = stem.height_m;
  info.stem_top_W = stem.At(stem.height_m);
  const double size_scale = std::clamp(std::pow(params.leaf_density, 0.35), 0.6, 1.5);
  info.num_leaves = AddStemLeaves(params, stem, size_scale, plant_rng, scene);
  const Stake stake = AddStake(params, stem, plant_rng, scene);
  const std::vector<Ellipsoid> fruits =
      AddTrusses(params, plant_rng, FruitRoom{params, stem, stake, {}}, scene, info);

  const internal::ScreenResult screen = internal::AddOcclusionScreen(
      params.occlusion, fruits, first_object, plant_rng,
      {.min_distance_m = 0.05, .clearance_m = 0.012},
      [&](int k, const internal::ScreenSpot& spot, Rng& r) {
        return BuildScreenLeaf(params, stem, size_scale, k, spot, r);
      },
      scene);
  internal::RecordScreenAndTotals(screen, scene, first_object, info);
  return info;
}

}  // namespace avp::sim

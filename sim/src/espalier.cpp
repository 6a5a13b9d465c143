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
  const Rng tree_rng(rng.NextU64());
  const std::string& prefix = params.name_prefix;
  const Eigen::Vector3d& B = params.trunk_base_W;
  EspalierInfo info;
  const size_t first_object = scene.objects.size();

  // ---- Frame: tiers, trunk ----------------------------------------------------------------------
  Rng frame_rng = tree_rng.Fork("frame");
  const int tiers = static_cast<int>(frame_rng.UniformInt(params.tiers_min, params.tiers_max));
  info.num_tiers = tiers;
  for (int i = 0; i < tiers; ++i) {
    const double z = params.first_tier_height_m +
                     (params.height_m - params.first_tier_height_m) * i / (tiers - 1);
    info.tier_heights_m.push_back(z + (i + 1 < tiers ? frame_rng.Uniform(-0.02, 0.02) : 0.0));
  }
  const double bend_radius = 0.07;
  info.trunk_height_m = info.tier_heights_m.back() - bend_radius;
  const Eigen::Vector2d trunk_wobble(frame_rng.Uniform(-0.012, 0.012),
                                     frame_rng.Uniform(-0.012, 0.012));
  const double trunk_phase = frame_rng.Uniform(0.0, 2.0 * kPi);
  const auto trunk_at = [&](double h) {
    const double s = std::sin(kPi * h / info.trunk_height_m + trunk_phase) - std::sin(trunk_phase);
    return Eigen::Vector3d(B + Eigen::Vector3d(trunk_wobble.x() * s, trunk_wobble.y() * s, h));
  };
  std::vector<Branch> branches;  // trunk, then cordons (for collision checks and the screen)
  {
    Branch trunk;
    const int n = std::max(6, static_cast<int>(std::ceil(info.trunk_height_m / 0.04)) + 1);
    for (int i = 0; i < n; ++i) {
      const double h = info.trunk_height_m * i / (n - 1);
      trunk.line.push_back(trunk_at(h));
      trunk.radii.push_back(params.trunk_radius_m * (1.0 - 0.3 * h / info.trunk_height_m));
    }
    scene.Add(prefix + "/trunk", SemanticClass::kStem, VaryAlbedo(kBarkColor, 0.08, frame_rng),
              MakeTube(trunk.line, trunk.radii, 12, true));
    branches.push_back(std::move(trunk));
  }

  // ---- Supports ---------------------------------------------------------------------------------
  const double post_y = 0.5 * params.width_m + 0.1;
  const double wire_x = B.x() + params.cordon_base_radius_m + 0.004;  // just behind the cordons
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> wires;
  Rng support_rng = tree_rng.Fork("supports");
  if (params.supports) {
    const double post_height = params.height_m + 0.2;
    for (const double side : {1.0, -1.0}) {
      const Eigen::Vector3d centre(B.x() + 0.02, B.y() + side * post_y, B.z() + 0.5 * post_height);
      TriangleMesh post = MakeBox(Eigen::Vector3d(0.035, 0.035, 0.5 * post_height));
      post.Transform(RigidTransform(centre));
      scene.Add(fmt::format("{}/post_{}", prefix, side > 0 ? "L" : "R"), SemanticClass::kSupport,
                VaryAlbedo(kWoodColor, 0.1, support_rng), std::move(post));
    }
    for (int i = 0; i < tiers; ++i) {
      const double z = B.z() + info.tier_heights_m[static_cast<size_t>(i)] + 0.004;
      const Eigen::Vector3d a(wire_x, B.y() - post_y, z);
      const Eigen::Vector3d b(wire_x, B.y() + post_y, z);
      wires.emplace_back(a, b);
      scene.Add(fmt::format("{}/wire_{}", prefix, i), SemanticClass::kSupport,
                VaryAlbedo(kWireColor, 0.05, support_rng), MakeCylinder(a, b, 0.0015, 6, true));
    }
  }

  // ---- Cordons, spurs, leaves -------------------------------------------------------------------
  const double leaf_scale = std::clamp(std::pow(params.leaf_density, 0.3), 0.7, 1.4);
  struct Spur {
    Eigen::Vector3d base;  // on the cordon axis
    Eigen::Vector3d tip;
    size_t cordon = 0;  // index into cordon_meshes
  };
  std::vector<Spur> spurs;
  std::vector<TriangleMesh> cordon_meshes;  // stem parts per cordon (apple stalks added later)
  std::vector<std::string> cordon_names;
  for (int i = 0; i < tiers; ++i) {
    const double z = info.tier_heights_m[static_cast<size_t>(i)];
    for (const double side : {1.0, -1.0}) {
      Rng r = tree_rng.Fork(static_cast<uint64_t>(2 * i + (side > 0 ? 0 : 1)));
      const double reach = 0.5 * params.width_m * r.Uniform(0.92, 1.0);
      const double sag = r.Uniform(0.0, 0.02);
      const double wobble = r.Uniform(0.0, 0.008);
      const double phase = r.Uniform(0.0, 2.0 * kPi);
      Branch cordon;
      // A quarter bend out of the trunk, then horizontal along ±y.
      const Eigen::Vector3d join = trunk_at(z - bend_radius);
      for (int k = 0; k <= 4; ++k) {
        const double a = 0.5 * kPi * k / 4.0;
        cordon.line.push_back(join + Eigen::Vector3d(0.0, side * bend_radius * (1.0 - std::cos(a)),
                                                     bend_radius * std::sin(a)));
      }
      const Eigen::Vector3d start = cordon.line.back();
      const double run = reach - bend_radius;
      const int n = std::max(4, static_cast<int>(std::ceil(run / 0.025)));
      for (int k = 1; k <= n; ++k) {
        const double t = static_cast<double>(k) / n;
        cordon.line.push_back(start + Eigen::Vector3d(wobble * std::sin(3.0 * kPi * t + phase),
                                                      side * run * t, -sag * std::sin(kPi * t)));
      }
      for (size_t k = 0; k < cordon.line.size(); ++k) {
        const double t = static_cast<double>(k) / (cordon.line.size() - 1);
        cordon.radii.push_back(params.cordon_base_radius_m +
                               (params.cordon_tip_radius_m - params.cordon_base_radius_m) * t);
      }
      TriangleMesh wood = MakeTube(cordon.line, cordon.radii, 8, true);
      TriangleMesh blades;
      const size_t cordon_index = cordon_meshes.size();

      // Spurs along the horizontal part, each with a leaf cluster.
      for (double y = 0.08 + r.Uniform(0.0, params.spur_spacing_m); y < reach - 0.02;
           y += params.spur_spacing_m * r.Uniform(0.7, 1.3)) {
        const double t = (y - bend_radius) / run;
        if (t < 0.0) continue;
        const Eigen::Vector3d base =
            start + Eigen::Vector3d(wobble * std::sin(3.0 * kPi * t + phase), side * run * t,
                                    -sag * std::sin(kPi * t));
        // Mostly up, some towards the front or back, a few down.
        const double u = r.Uniform01();
        Eigen::Vector3d dir = u < 0.5 ? Eigen::Vector3d(r.Uniform(-0.4, 0.4), 0.0, 1.0)
                              : u < 0.9
                                  ? Eigen::Vector3d(u < 0.7 ? -1.0 : 1.0, 0.0, r.Uniform(-0.2, 0.6))
                                  : Eigen::Vector3d(r.Uniform(-0.4, 0.4), 0.0, -1.0);
        dir += Eigen::Vector3d(0.0, r.Uniform(-0.3, 0.3), 0.0);
        dir.normalize();
        const double length = r.Uniform(0.025, 0.06);
        const Eigen::Vector3d tip = base + length * dir;
        const std::vector<Eigen::Vector3d> spur_line = {base, base + 0.5 * length * dir, tip};
        wood.Append(MakeTube(spur_line, LinearRadii(0.0055, 0.0035, 3), 5, true));
        spurs.push_back({base, tip, cordon_index});
        ++info.num_spurs;
        // Summer growth: a leafy shoot from some spurs, mostly upwards.
        if (r.Bernoulli(std::min(1.0, 0.45 * params.leaf_density))) {
          const Eigen::Vector3d up_dir =
              (kUp + Eigen::Vector3d(r.Uniform(-0.5, 0.5), r.Uniform(-0.4, 0.4), 0.0)).normalized();
          const double shoot_len = r.Uniform(0.08, 0.22);
          const Eigen::Vector3d bow(r.Uniform(-0.03, 0.03), r.Uniform(-0.03, 0.03), 0.0);
          const std::vector<Eigen::Vector3d> shoot = SampleCubicBezier(
              tip, tip + 0.35 * shoot_len * up_dir + 0.5 * bow,
              tip + 0.7 * shoot_len * up_dir + bow, tip + shoot_len * up_dir + 0.5 * bow, 6);
          wood.Append(MakeTube(shoot, LinearRadii(0.0028, 0.0014, 6), 5, true));
          double phyllo = r.Uniform(0.0, 2.0 * kPi);
          for (double f = 0.15; f <= 1.0; f += 0.03 / shoot_len * r.Uniform(0.8, 1.2)) {
            const size_t seg = std::min<size_t>(4, static_cast<size_t>(f * 5.0));
            const Eigen::Vector3d at = shoot[seg] + (f * 5.0 - seg) * (shoot[seg + 1] - shoot[seg]);
            phyllo += 2.4;  // ~137.5 degrees
            const Eigen::Vector3d leaf_dir =
                Eigen::Vector3d(std::cos(phyllo), std::sin(phyllo), r.Uniform(0.2, 0.9));
            AddLeaf(at, leaf_dir,
                    params.leaf_length_m * leaf_scale * r.Uniform(0.7, 1.15) * (1.1 - 0.4 * f),
                    r.Uniform(0.01, 0.02), r, blades, wood);
            ++info.num_leaves;
          }
        }
        const int leaves =
            static_cast<int>(std::lround(6.0 * params.leaf_density * r.Uniform(0.7, 1.3)));
        const double phase0 = r.Uniform(0.0, 2.0 * kPi);
        for (int k = 0; k < leaves; ++k) {
          const double azimuth = phase0 + 2.0 * kPi * (k + r.Uniform(-0.2, 0.2)) / leaves;
          const double elevation = r.Uniform(-0.2, 0.9);
          const Eigen::Vector3d leaf_dir =
              std::cos(elevation) * Eigen::Vector3d(std::cos(azimuth), std::sin(azimuth), 0.0) +
              std::sin(elevation) * kUp;
          AddLeaf(tip, leaf_dir, params.leaf_length_m * leaf_scale * r.Uniform(0.8, 1.2),
                  r.Uniform(0.015, 0.03), r, blades, wood);
          ++info.num_leaves;
        }
      }
      // Single leaves along the cordon (shoots removed by summer pruning leave these).
      if (params.leaf_density > 0.0) {
        const double spacing = 0.035 / params.leaf_density;
        for (double y = 0.1 + r.Uniform(0.0, spacing); y < reach;
             y += spacing * r.Uniform(0.6, 1.4)) {
          const double t = (y - bend_radius) / run;
          if (t < 0.0) continue;
          const Eigen::Vector3d axis =
              start + Eigen::Vector3d(wobble * std::sin(3.0 * kPi * t + phase), side * run * t,
                                      -sag * std::sin(kPi * t));
          const double around = r.Uniform(0.0, 2.0 * kPi);
          const Eigen::Vector3d radial(std::cos(around), 0.0, std::sin(around));
          const double radius = params.cordon_base_radius_m +
                                (params.cordon_tip_radius_m - params.cordon_base_radius_m) * t;
          const Eigen::Vector3d leaf_dir =
              (radial + Eigen::Vector3d(0.0, side * r.Uniform(0.0, 0.8), r.Uniform(0.0, 0.8)))
                  .normalized();
          AddLeaf(axis + radius * radial, leaf_dir,
                  params.leaf_length_m * leaf_scale * r.Uniform(0.8, 1.2), r.Uniform(0.01, 0.025),
                  r, blades, wood);
          ++info.num_leaves;
        }
      }
      const std::string suffix = fmt::format("{}_{}", i, side > 0 ? "L" : "R");
      cordon_names.push_back(fmt::format("{}/cordon_{}", prefix, suffix));
      cordon_meshes.push_back(std::move(wood));
      if (!blades.empty()) {
        Eigen::Vector3f green = kLeafColor;
        green *= static_cast<float>(r.Uniform(0.85, 1.15));
        scene.Add(fmt::format("{}/leaves_{}", prefix, suffix), SemanticClass::kLeaf,
                  VaryAlbedo(green, 0.1, r), std::move(blades));
      }
      branches.push_back(std::move(cordon));
    }
  }

  // ---- Apples -----------------------------------------------------------------------------------
  Rng apple_rng = tree_rng.Fork("apples");
  const int target = static_cast<int>(apple_rng.UniformInt(params.fruits_min, params.fruits_max));
  std::vector<size_t> order(spurs.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  for (size_t i = order.size(); i > 1; --i) {  // Fisher-Yates with the project's generator
    std::swap(order[i - 1],
              order[static_cast<size_t>(apple_rng.UniformInt(0, static_cast<int64_t>(i - 1)))]);
  }
  std::vector<Ellipsoid> apples;
  const auto apple_fits = [&](const Eigen::Vector3d& c, double r) {
    if (c.z() - r < B.z() + 0.03) return false;
    for (const Ellipsoid& other : apples) {
      if ((other.center_W - c).norm() < 0.97 * (r + other.radii.maxCoeff())) return false;
    }
    for (const Branch& branch : branches) {
      if (branch.Clearance(c).first < r + 0.003) return false;
    }
    for (const auto& [a, b] : wires) {
      if (DistanceToSegment(c, a, b) < r + 0.004) return false;
    }
    if (params.supports && std::abs(std::abs(c.y() - B.y()) - post_y) < r + 0.04) return false;
    return true;
  };
  for (size_t k = 0; k < order.size() && static_cast<int>(apples.size()) < target; ++k) {
    Rng r = apple_rng.Fork(static_cast<uint64_t>(order[k]));
    const Spur& spur = spurs[order[k]];
    const int cluster = r.Bernoulli(0.25) ? 2 : 1;
    for (int c = 0; c < cluster && static_cast<int>(apples.size()) < target; ++c) {
      const double radius = r.Uniform(params.fruit_radius_min_m, params.fruit_radius_max_m);
      bool placed = false;
      for (int attempt = 0; attempt < 12 && !placed; ++attempt) {
        // Hang below the spur's base, swung towards the allowed side by psi from the vertical.
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
        const Eigen::Vector3d centre =
            spur.base + r.Uniform(-0.02, 0.02) * Eigen::Vector3d::UnitY() +
            (radius + gap) *
                (std::sin(psi) * side * Eigen::Vector3d::UnitX() - std::cos(psi) * kUp);
        if (!apple_fits(centre, radius)) continue;
        placed = true;
        Ellipsoid apple;
        apple.center_W = centre;
        apple.radii = Eigen::Vector3d(
            radius, radius, std::max(params.fruit_radius_min_m, radius * r.Uniform(0.85, 0.95)));
        const Eigen::Vector3d axis =
            (kUp + Eigen::Vector3d(r.Uniform(-0.25, 0.25), r.Uniform(-0.25, 0.25), 0.0))
                .normalized();
        apple.R_WE = Eigen::AngleAxisd(r.Uniform(0.0, 2.0 * kPi), axis).toRotationMatrix() *
                     RotationWithZAxis(axis);
        apples.push_back(apple);
        const bool red = r.Bernoulli(params.red_fraction);
        const double blush = red ? r.Uniform(0.65, 1.0) : r.Uniform(0.0, 0.3);
        const uint16_t id =
            scene.Add(fmt::format("{}/apple_{:02}", prefix, apples.size() - 1),
                      SemanticClass::kFruit, VaryAlbedo(AppleColor(blush), 0.06, r), apple);
        info.fruit_ids.push_back(id);
        // Stalk from the top of the apple (in its cavity) towards the spur base.
        const Eigen::Vector3d top = centre + 0.8 * apple.radii.z() * axis;
        const Eigen::Vector3d towards = spur.base - top;
        const double stalk =
            std::min(0.028, std::max(0.012, towards.norm() - params.cordon_base_radius_m));
        const std::vector<Eigen::Vector3d> line = {top, top + stalk * towards.normalized()};
        cordon_meshes[spur.cordon].Append(MakeTube(line, LinearRadii(0.0018, 0.0015, 2), 5, true));
      }
    }
  }
  for (size_t i = 0; i < cordon_meshes.size(); ++i) {
    scene.Add(cordon_names[i], SemanticClass::kStem, VaryAlbedo(kBarkColor, 0.1, frame_rng),
              std::move(cordon_meshes[i]));
  }

  // ---- Occlusion screen -------------------------------------------------------------------------
  if (params.occlusion.enabled) {
    FruitVisibility visibility(params.occlusion, apples);
    visibility.AddSceneOccluders(scene, first_object);
    Rng screen_rng = tree_rng.Fork("screen");
    const Eigen::Vector3d eye = params.occlusion.eye_W;
    for (int k = 0; k < params.occlusion.max_leaves; ++k) {
      const auto visible = visibility.FindVisible();
      if (!visible) break;
      Rng r = screen_rng.Fork(static_cast<uint64_t>(k));
      const Eigen::Vector3d p = visible->first;
      const Eigen::Vector3d to_eye = (eye - p).normalized();
      // The covering leaf's centre q sits on the line of sight, a few centimetres in front of the
      // fruit and clear of every fruit.
      const Eigen::Vector3d q = ScreenLeafCentre(p, eye, apples, 0.04, 0.01, r);
      // A shoot from the nearest branch to the covering leaf, which faces the eye.
      Eigen::Vector3d anchor = branches.front().line.front();
      double best = std::numeric_limits<double>::infinity();
      for (const Branch& branch : branches) {
        const auto [d, c] = branch.Clearance(q);
        if (d < best) {
          best = d;
          anchor = c;
        }
      }
      const double length = params.leaf_length_m * leaf_scale * r.Uniform(1.15, 1.35);
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
      TriangleMesh wood = MakeTube(line, LinearRadii(0.003, 0.0018, 6), 5, true);
      TriangleMesh blades;
      AddLeaf(blade_base, R.col(0), length, 0.0, r, blades, wood, R);
      // Two companions on the shoot, as on a real one.
      for (int j = 0; j < 2; ++j) {
        const Eigen::Vector3d at = line[static_cast<size_t>(2 + j)];
        const double az = r.Uniform(0.0, 2.0 * kPi);
        AddLeaf(at, Eigen::Vector3d(std::cos(az), std::sin(az), r.Uniform(0.0, 0.8)),
                params.leaf_length_m * leaf_scale * r.Uniform(0.8, 1.2), r.Uniform(0.01, 0.02), r,
                blades, wood);
      }
      visibility.AddOccluder(wood);
      visibility.AddOccluder(blades);
      scene.Add(fmt::format("{}/screen_shoot_{:02}", prefix, k), SemanticClass::kStem,
                VaryAlbedo(kBarkColor, 0.1, r), std::move(wood));
      scene.Add(fmt::format("{}/screen_leaves_{:02}", prefix, k), SemanticClass::kLeaf,
                VaryAlbedo(kLeafColor, 0.12, r), std::move(blades));
      ++info.num_screen_leaves;
    }
    info.num_visible_samples = visibility.CountVisible();
  }

  for (size_t i = first_object; i < scene.objects.size(); ++i) {
    info.num_triangles += scene.objects[i].num_triangles();
  }
  info.num_objects = scene.objects.size() - first_object;
  return info;
}

}  // namespace avp::sim

#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scene.h>

namespace avp::sim {

/// A procedural greenhouse tomato (Solanum lycopersicum) in the world frame: one tapering, slightly
/// curved main stem; compound leaves in a 137.5 deg spiral, each a petiole/rachis with an odd
/// number of leaflets (thin curved blades) plus small intercalary leaflets; trusses (peduncle,
/// rachis, pedicels, calyces) carrying ellipsoidal fruits coloured by ripeness; an optional stake.
/// Ranges are sampled per plant with the generator passed to AddTomatoPlant.
struct TomatoPlantParams {
  std::string name_prefix = "tomato";  ///< object names: "<prefix>/stem", "<prefix>/fruit_2_3" ...
  /// Where the stem meets the ground, metres in W (the reference plant stands at (0.7, 0, 0)).
  Eigen::Vector3d stem_base_W = Eigen::Vector3d(0.7, 0.0, 0.0);

  // Main stem.
  double height_min_m = 1.0;  ///< stem height is uniform in [height_min_m, height_max_m]
  double height_max_m = 1.4;
  double stem_base_radius_m = 0.011;
  double stem_top_radius_m = 0.004;
  /// Horizontal offset of the stem top from the vertical through the base (random direction).
  double stem_lean_max_m = 0.05;

  // Leaves.
  /// Occlusion control: 1 = typical greenhouse plant (~12 compound leaves per metre of stem),
  /// 0 = no leaves. Leaf count scales linearly, leaf size with density^0.35 (clamped to
  /// [0.6, 1.5]).
  double leaf_density = 1.0;
  double leaf_length_m = 0.40;     ///< compound leaf (petiole + rachis) at density 1, +-20 %
  double leaflet_length_m = 0.09;  ///< mid-rachis lateral leaflet at density 1, +-15 %
  int leaflets_min = 5;            ///< main leaflets per leaf (odd: pairs + terminal)
  int leaflets_max = 9;
  bool intercalary_leaflets = true;  ///< small leaflets between the main pairs
  double first_leaf_height_m = 0.18;

  // Trusses and fruits.
  int trusses_min = 3;
  int trusses_max = 6;
  int fruits_per_truss_min = 2;
  int fruits_per_truss_max = 8;
  /// Every semi-axis of every fruit lies in [fruit_radius_min_m, fruit_radius_max_m].
  double fruit_radius_min_m = 0.015;
  double fruit_radius_max_m = 0.035;
  /// Truss attachment heights as fractions of the stem height.
  double truss_height_min_fraction = 0.42;
  double truss_height_max_fraction = 0.82;
  /// Trusses point within +-spread/2 of this azimuth (radians from +x towards +y about z);
  /// a spread of 360 deg puts them anywhere.
  double truss_azimuth_deg = 0.0;
  double truss_azimuth_spread_deg = 360.0;
  /// Ripeness in [0, 1] (0 green, 0.5 orange, 1 red) is drawn within this range.
  double ripeness_min = 0.0;
  double ripeness_max = 1.0;

  // Support.
  bool stake = true;
  double stake_radius_m = 0.007;
  /// Stake position relative to the stem base (on the far side by default, away from the arm).
  Eigen::Vector3d stake_offset_m = Eigen::Vector3d(0.035, -0.02, 0.0);

  OcclusionScreen occlusion;

  /// Every bad field at once: "invalid tomato plant: height_min_m (2) must be <= height_max_m
  /// (1.4); leaflets_min (4) must be odd and >= 3".
  Status Validate() const;
};

/// What AddTomatoPlant built (for tests and logs).
struct TomatoPlantInfo {
  double height_m = 0.0;
  Eigen::Vector3d stem_top_W = Eigen::Vector3d::Zero();
  int num_leaves = 0;         ///< compound leaves from the phyllotaxis
  int num_screen_leaves = 0;  ///< leaves added by the occlusion screen
  /// Fruit surface samples still visible from the occlusion eye after screening (0 = hidden).
  int num_visible_samples = 0;
  /// Fruits placed per truss: drawn in [fruits_per_truss_min, fruits_per_truss_max]; a fruit that
  /// finds no free room along either side of its truss (80 tries) is left out, so a count may
  /// fall below the minimum (no case in 4000 trusses of the built-in scenarios' parameters).
  std::vector<int> fruits_per_truss;
  std::vector<uint16_t> fruit_ids;  ///< instance ids of the fruits, in creation order
  size_t num_triangles = 0;
  size_t num_objects = 0;
};

/// Grows one tomato plant into `scene`: objects "<prefix>/stem" (stem), "<prefix>/leaf_NN" (leaf,
/// the leaflets) with "<prefix>/leaf_NN/rachis" (stem), "<prefix>/truss_K" (stem: peduncle,
/// rachis, pedicels, calyces), "<prefix>/fruit_K_J" (fruit ellipsoids), "<prefix>/stake"
/// (support), "<prefix>/screen_leaf_NN" (+ rachis) from the occlusion screen. Does not add a
/// ground plane and does not update plant bounds. Deterministic in (params, rng state).
/// @throws avp::Error if params fail Validate().
TomatoPlantInfo AddTomatoPlant(const TomatoPlantParams& params, Rng& rng, Scene& scene);

/// Linear-RGB albedo of a tomato of ripeness in [0, 1] (green → orange → red).
Eigen::Vector3f TomatoColor(double ripeness);

}  // namespace avp::sim

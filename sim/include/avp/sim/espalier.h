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

/// Where the apples of an espalier hang relative to the tree's vertical plane.
enum class FruitSide {
  kBoth,   ///< either side or below the cordons
  kFront,  ///< on the arm's side (−x)
  kBack,   ///< behind the cordons (+x), away from the arm
};

/// A procedural apple espalier: a planar trained tree in the vertical plane x = trunk_base_W.x()
/// facing the arm, with a trunk and 3–4 tiers of horizontal cordons along ±y, short spurs carrying
/// leaf clusters and apples, single leaves along the cordons, and support posts with one wire per
/// tier. Ranges are sampled per tree with the generator passed to AddEspalier.
struct EspalierParams {
  std::string name_prefix = "espalier";  ///< object names "<prefix>/trunk", "<prefix>/apple_07" ...
  /// Foot of the trunk, metres in W; the tree's plane is x = trunk_base_W.x().
  Eigen::Vector3d trunk_base_W = Eigen::Vector3d(0.7, 0.0, 0.0);
  double width_m = 1.5;   ///< cordon tip to cordon tip (each side reaches 92–100 % of half of it)
  double height_m = 1.2;  ///< height of the top tier above the trunk base
  int tiers_min = 3;
  int tiers_max = 4;
  double first_tier_height_m = 0.4;
  double trunk_radius_m = 0.028;
  double cordon_base_radius_m = 0.016;
  double cordon_tip_radius_m = 0.006;
  double spur_spacing_m = 0.07;  ///< mean distance between spurs along a cordon (+-30 %)

  /// 1 = a typical summer canopy (~6 leaves per spur, a leafy upright shoot on ~45 % of the
  /// spurs, a leaf every 3.5 cm along the cordons); counts scale linearly, leaf size with
  /// density^0.3 (clamped to [0.7, 1.4]). 0 = bare wood.
  double leaf_density = 1.0;
  double leaf_length_m = 0.08;  ///< blade length at density 1, +-20 %

  /// Apples drawn in [fruits_min, fruits_max] and hung from randomly chosen spurs; if the spurs run
  /// out of free room (far more spurs than apples by default) fewer are placed.
  int fruits_min = 12;
  int fruits_max = 24;
  /// Every semi-axis of every apple lies in [fruit_radius_min_m, fruit_radius_max_m].
  double fruit_radius_min_m = 0.030;
  double fruit_radius_max_m = 0.045;
  FruitSide fruit_side = FruitSide::kBoth;
  /// Fraction of red apples; the rest are yellow-green with a faint blush.
  double red_fraction = 0.7;

  bool supports = true;  ///< two end posts and one wire per tier (class support)
  OcclusionScreen occlusion;

  /// Every bad field at once.
  Status Validate() const;
};

/// What AddEspalier built.
struct EspalierInfo {
  int num_tiers = 0;
  std::vector<double> tier_heights_m;  ///< z of each tier above the trunk base
  double trunk_height_m = 0.0;         ///< where the top cordons leave the trunk
  int num_spurs = 0;
  int num_leaves = 0;
  int num_screen_leaves = 0;
  int num_visible_samples = 0;  ///< see TomatoPlantInfo
  std::vector<uint16_t> fruit_ids;
  size_t num_triangles = 0;
  size_t num_objects = 0;
};

/// Grows one espalier into `scene`: "<prefix>/trunk" (stem), "<prefix>/cordon_T_L|R" (stem:
/// cordon, spurs, petioles, apple stalks), "<prefix>/leaves_T_L|R" (leaf), "<prefix>/apple_NN"
/// (fruit ellipsoids), "<prefix>/post_L|R" and "<prefix>/wire_T" (support), and the occlusion
/// screen's "<prefix>/screen_shoot_NN" (stem) and "<prefix>/screen_leaves_NN" (leaf). No ground.
/// @throws avp::Error if params fail Validate().
EspalierInfo AddEspalier(const EspalierParams& params, Rng& rng, Scene& scene);

/// Linear-RGB albedo of an apple: `blush` in [0, 1] from yellow-green to deep red.
Eigen::Vector3f AppleColor(double blush);

}  // namespace avp::sim

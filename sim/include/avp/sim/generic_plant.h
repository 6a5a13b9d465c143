#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include <avp/core/rng.h>
#include <avp/core/transform.h>
#include <avp/sim/scene.h>

namespace avp::sim {

/// A deliberately generic procedural plant family, for training learned view planners ONLY
/// (docs/planning.md, "A learned gain"). It shares no shape rule with the tomato and espalier
/// generators (they are the test set): branches grow recursively from one or more stems in random
/// directions, leaves are simple blades of random size and density, fruit hangs in clusters of
/// random size and placement. One seed draws everything, including the layout, the occlusion and
/// the start:
///
/// - layout: a single plant (1–3 stems, p 0.4), a row of 2–4 smaller plants along y (p 0.2), a
///   wall (a hedge of 4–8 stems along y whose branches stay near one vertical plane, 0.8–1.4 m
///   wide, p 0.2) or a trellis (1–3 stems in one plane 1–2 m wide, their long arms trained out
///   near-horizontally, 65–100° from the stem, with spurs off them, p 0.2); a trellis stands
///   between stakes with 1–4 wires with p 0.7, a wall with p 0.3;
/// - the plant's place (its footprint centre x in [0.55, 0.85] m, y in [−0.35, 0.35] m), height
///   (0.6–1.3 m), branching (2–6 children per branch, 2–3 levels), leaf size (3–18 cm) and
///   density (0.2–1.8), fruit clusters (1–7 of 1–8 fruits, radii 1.5–4.5 cm, on any side, or
///   on the side away from the arm);
/// - occlusion: with probability 0.3 an occlusion screen hides every fruit from the start view;
/// - the start: with probability 0.3 the arm is yawed 15–55° away from the plant (either way).
struct GenericPlantDraw {
  enum class Layout { kSingle, kRow, kWall, kTrellis };
  Layout layout = Layout::kSingle;
  int plants = 1;
  bool supports = false;  ///< stakes and wires (class support), for a wall or a trellis
  bool occluded = false;
  bool far_side_fruit = false;
  double start_yaw_deg = 0.0;
};

/// "single", "row", "wall", "trellis".
const char* GenericLayoutName(GenericPlantDraw::Layout layout);

/// What AddGenericPlants built.
struct GenericPlantInfo {
  GenericPlantDraw draw;
  int num_branches = 0;
  int num_leaves = 0;
  int num_screen_leaves = 0;
  int num_visible_samples = 0;  ///< fruit samples still visible from the start eye (screen)
  std::vector<uint16_t> fruit_ids;
  size_t num_triangles = 0;
  size_t num_objects = 0;
};

/// Draws the layout, occlusion and start of seed `rng` (the first draws of the family: a scene's
/// start pose is known before its plants grow, for the occlusion screen).
GenericPlantDraw DrawGenericLayout(Rng& rng);

/// Grows the plants of `draw` into `scene` (no ground), objects "generic/plant_P/...". With
/// draw.occluded, the occlusion screen hides the fruit from the camera at `X_WC_start`.
GenericPlantInfo AddGenericPlants(const GenericPlantDraw& draw, const RigidTransform& X_WC_start,
                                  Rng& rng, Scene& scene);

}  // namespace avp::sim

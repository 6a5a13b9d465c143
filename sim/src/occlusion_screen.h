#pragma once

// Private helpers shared by the procedural plants (tomato, espalier): the occlusion screen's
// leaf-by-leaf loop and a plant's object totals.

#include <cstddef>
#include <functional>
#include <span>
#include <string>

#include <Eigen/Core>

#include <avp/core/rng.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scene.h>

namespace avp::sim::internal {

/// Where the screen wants a covering leaf: the leaf's centre on the line of sight to a fruit
/// point that is still visible, and the unit direction from that fruit point to the eye.
struct ScreenSpot {
  Eigen::Vector3d centre_W;
  Eigen::Vector3d to_eye;
};

/// The two objects a plant adds for one covering leaf, in this order: its woody part (class stem:
/// a shoot or a rachis) and its blades (class leaf).
struct ScreenLeaf {
  std::string stem_name;
  Eigen::Vector3f stem_albedo = Eigen::Vector3f::Zero();
  TriangleMesh stem;
  std::string blades_name;
  Eigen::Vector3f blades_albedo = Eigen::Vector3f::Zero();
  TriangleMesh blades;
};

/// Builds covering leaf number k at `spot`, drawing from `rng` (leaf k's own stream). Called once
/// per added leaf (at most OcclusionScreen::max_leaves times), so std::function costs nothing here.
using ScreenLeafBuilder = std::function<ScreenLeaf(int k, const ScreenSpot& spot, Rng& rng)>;

/// How far in front of the fruit a covering leaf's centre goes: ScreenLeafCentre's arguments.
struct ScreenLeafPlacement {
  double min_distance_m = 0.0;
  double clearance_m = 0.0;
};

/// What AddOcclusionScreen did (both 0 when the screen is disabled).
struct ScreenResult {
  int num_leaves = 0;
  int num_visible_samples = 0;  ///< fruit samples still visible from the eye afterwards
};

/// Runs `screen` (when enabled) for a plant whose fruits are `fruits` and whose objects are
/// scene.objects[first_object, end): while a fruit sample is visible from the eye and fewer than
/// max_leaves were added, places a leaf centre in front of it (see ScreenLeafCentre), builds leaf k
/// there with `build_leaf` on stream k of plant_rng.Fork("screen"), and adds it to the scene and
/// to the occluders.
ScreenResult AddOcclusionScreen(const OcclusionScreen& screen, std::span<const Ellipsoid> fruits,
                                size_t first_object, const Rng& plant_rng,
                                const ScreenLeafPlacement& placement,
                                const ScreenLeafBuilder& build_leaf, Scene& scene);

/// A plant's totals: the triangles and objects in scene.objects[first_object, end).
struct ObjectTotals {
  size_t num_triangles = 0;
  size_t num_objects = 0;
};
ObjectTotals CountObjectsSince(const Scene& scene, size_t first_object);

/// Records what the screen did and the plant's totals (its objects are
/// scene.objects[first_object, end)) in a plant's info: TomatoPlantInfo or EspalierInfo.
template <typename PlantInfo>
void RecordScreenAndTotals(const ScreenResult& screen, const Scene& scene, size_t first_object,
                           PlantInfo& info) {
  info.num_screen_leaves = screen.num_leaves;
  info.num_visible_samples = screen.num_visible_samples;
  const ObjectTotals totals = CountObjectsSince(scene, first_object);
  info.num_triangles = totals.num_triangles;
  info.num_objects = totals.num_objects;
}

}  // namespace avp::sim::internal

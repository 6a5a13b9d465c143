#include "occlusion_screen.h"

#include <cstdint>
#include <utility>

namespace avp::sim::internal {

ScreenResult AddOcclusionScreen(const OcclusionScreen& screen, std::span<const Ellipsoid> fruits,
                                size_t first_object, const Rng& plant_rng,
                                const ScreenLeafPlacement& placement,
                                const ScreenLeafBuilder& build_leaf, Scene& scene) {
  ScreenResult result;
  if (!screen.enabled) return result;
  FruitVisibility visibility(screen, fruits);
  visibility.AddSceneOccluders(scene, first_object);
  const Rng screen_rng = plant_rng.Fork("screen");
  const Eigen::Vector3d eye = screen.eye_W;
  for (int k = 0; k < screen.max_leaves; ++k) {
    const auto visible = visibility.FindVisible();
    if (!visible) break;
    Rng r = screen_rng.Fork(static_cast<uint64_t>(k));
    const Eigen::Vector3d p = visible->first;
    ScreenSpot spot;
    spot.to_eye = (eye - p).normalized();
    // The covering leaf's centre sits on the line of sight, a few centimetres in front of the
    // fruit and clear of every fruit.
    spot.centre_W =
        ScreenLeafCentre(p, eye, fruits, placement.min_distance_m, placement.clearance_m, r);
    ScreenLeaf leaf = build_leaf(k, spot, r);
    visibility.AddOccluder(leaf.stem);
    visibility.AddOccluder(leaf.blades);
    scene.Add(leaf.stem_name, SemanticClass::kStem, leaf.stem_albedo, std::move(leaf.stem));
    scene.Add(leaf.blades_name, SemanticClass::kLeaf, leaf.blades_albedo, std::move(leaf.blades));
    ++result.num_leaves;
  }
  result.num_visible_samples = visibility.CountVisible();
  return result;
}

ObjectTotals CountObjectsSince(const Scene& scene, size_t first_object) {
  ObjectTotals totals;
  for (size_t i = first_object; i < scene.objects.size(); ++i) {
    totals.num_triangles += scene.objects[i].num_triangles();
  }
  totals.num_objects = scene.objects.size() - first_object;
  return totals;
}

}  // namespace avp::sim::internal

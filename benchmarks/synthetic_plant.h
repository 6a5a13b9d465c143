#pragma once

// The seeded benchmark plant of docs/performance.md (section 0), shared by bench_render and
// bench_map: a 1 m stem (r = 6 mm) standing at the world origin, 60 cupped disc leaves
// (r = 25-60 mm, heights 0.15-0.95 m) and 10 spherical fruits (r = 22-35 mm, heights 0.2-0.8 m).

#include <cstdint>

#include <avp/sim/scene.h>

namespace avp::bench {

/// What surrounds the plant.
enum class PlantBackground : uint8_t {
  /// A 6 m x 6 m floor at z = 0 (bench_render's scene).
  kFloor,
  /// Plant-only: a 0.9 m x 0.9 m table top at z = 0 under the plant is the only other surface,
  /// so most rays of a view have no return.
  kTableTop,
  /// Full image: an (effectively) infinite floor at z = 0 (80 m x 80 m) plus a cylindrical
  /// backdrop of radius 0.9 m and height 3 m around the stem, so almost every pixel returns.
  kFloorAndBackdrop,
};

/// The plant with the given background. Fruits are analytic ellipsoids, or 20 480-triangle
/// icospheres when `tessellated_fruits`. Same seed, same scene.
sim::Scene SyntheticPlant(PlantBackground background, bool tessellated_fruits = false,
                          uint64_t seed = 1);

}  // namespace avp::bench

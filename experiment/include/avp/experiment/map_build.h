#pragma once

// `avp map build` and `avp map gt`: a semantic map of a simulated plant from views on an arc
// around it, and the plant's fruit-surface ground truth as an OctoMap file (docs/mapping.md).

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include <avp/core/camera.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/semantic_map.h>
#include <avp/mapping/voxel_grid.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene.h>

namespace avp::experiment {

// ---- Build --------------------------------------------------------------------------------------

/// What one fused view did.
struct MapBuildView {
  int index = 0;  ///< 0-based
  int views = 0;
  double azimuth_deg = 0.0;  ///< around the plant centre, world frame (0 = looking along -x)
  RigidTransform X_WC;
  size_t fruit_pixels = 0;
  size_t masks = 0;
  mapping::IntegrationStats stats;
  double render_ms = 0.0;
  double integrate_ms = 0.0;
  // Map totals after the view.
  size_t known_voxels = 0;
  size_t occupied_voxels = 0;
  size_t labelled_voxels = 0;
  size_t instances = 0;
};

/// `avp map build`: renders views of a simulated plant on an arc around it, segments them with the
/// simulator's ground truth and fuses them into a semantic map through the pipeline's
/// pipeline::ViewFusion (as an episode fuses its views), and saves it (.avpmap).
struct MapBuildOptions {
  sim::SceneSource scene;
  int views = 6;
  /// The map (voxel size, sensor model, semantic fusion) and the integrator (carving, range):
  /// the library's defaults, as `avp run` uses them; the ROI is set from roi_margin_m.
  mapping::MapOptions map;
  mapping::IntegratorOptions integrator;
  /// Threads of the integrator (0 = all hardware threads; a ThreadScope, core/parallel.h); the
  /// map does not depend on it.
  int threads = 0;
  /// Confidence given to every ground-truth mask (the segmenter's calibrated score).
  float mask_confidence = 0.9f;
  /// Total arc of camera azimuths around the plant, centred on the scene's start view; 360 (or
  /// more) = a full ring with views evenly spaced.
  double arc_deg = 120.0;
  /// Horizontal distance from the plant centre; 0 = the start camera's distance.
  double radius_m = 0.0;
  /// The map's ROI is the plant bounds grown by this margin; negative = no ROI.
  double roi_margin_m = 0.1;
  CameraIntrinsics intrinsics = CameraIntrinsics::RealSenseD435();
  /// Apply the seeded D435-like depth noise model (on by default, as in episodes; seeded from
  /// scene.seed and the view index).
  bool noise = true;
  std::filesystem::path out = "out/map.avpmap";
  /// Replace an existing file (output_folder.h's CheckOutputFile: refused otherwise).
  bool force = false;
  /// Called once with the loaded scene (e.g. to print its warnings); may be empty.
  std::function<void(const sim::Scene&)> on_scene;
  /// Called after each view is fused (progress lines); may be empty.
  std::function<void(const MapBuildView&)> on_view;
};

struct MapBuildSummary {
  std::string scene_name;
  Eigen::Vector3d target_W = Eigen::Vector3d::Zero();
  double radius_m = 0.0;
  std::vector<MapBuildView> views;
  size_t known_voxels = 0;
  size_t occupied_voxels = 0;
  size_t labelled_voxels = 0;
  size_t fruit_voxels = 0;  ///< occupied and labelled fruit
  std::vector<mapping::InstanceInfo> instances;
  size_t total_fruits = 0;  ///< fruits in the scene
  uint64_t file_bytes = 0;
  double seconds = 0.0;
  std::filesystem::path out;
};

/// Camera poses of the views: on a horizontal arc (or ring) of `radius_m` around `target_W` at the
/// height of `start_eye_W`, centred on the start eye's azimuth, each looking at the target with
/// the image up towards world +z. Exposed for tests.
std::vector<RigidTransform> ArcViewPoses(const Eigen::Vector3d& target_W,
                                         const Eigen::Vector3d& start_eye_W, int views,
                                         double arc_deg, double radius_m,
                                         std::vector<double>* azimuths_deg = nullptr);

/// Errors name the bad value (unknown scenario, views < 1, voxel size out of range ...).
Result<MapBuildSummary> BuildMap(const MapBuildOptions& options,
                                 const sim::ScenarioRegistry& scenarios);

// ---- Ground truth -------------------------------------------------------------------------------

/// `avp map gt`: the scene's fruit surfaces voxelised (sim::VoxelizeFruitSurfaces) and written as
/// an OctoMap .bt of occupied voxels: the same kind of ground truth as the reference system's.
struct MapGtOptions {
  sim::SceneSource scene;
  /// The map's default voxel size (mapping::GridOptions), so that a map built with the defaults
  /// and this ground truth share one lattice; 0.006 gives the resolution of the reference
  /// system's ground-truth octrees (reference-system.md).
  double voxel_size_m = mapping::GridOptions{}.voxel_size_m;
  std::filesystem::path out = "out/gt.bt";
  /// Replace an existing file (output_folder.h's CheckOutputFile: refused otherwise).
  bool force = false;
  /// Called once with the loaded scene (e.g. to print its warnings); may be empty.
  std::function<void(const sim::Scene&)> on_scene;
};
struct MapGtSummary {
  std::string scene_name;
  size_t fruits = 0;
  size_t voxels = 0;
  uint64_t file_bytes = 0;
};
/// Errors: the scene's, a voxel size out of range, an output that is the scene file, the writer's.
Result<MapGtSummary> WriteGroundTruthOctree(const MapGtOptions& options,
                                            const sim::ScenarioRegistry& scenarios);

}  // namespace avp::experiment

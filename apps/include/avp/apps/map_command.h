#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <avp/core/box.h>
#include <avp/core/camera.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/map_reader.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/semantics.h>
#include <avp/sim/scenario.h>

namespace avp::apps {

// ---- avp map build
// --------------------------------------------------------------------------------

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
/// simulator's ground truth, fuses them into a semantic map and saves it (.avpmap).
struct MapBuildOptions {
  sim::SceneSource scene;
  int views = 6;
  /// The map (voxel size, sensor model, semantic fusion) and the integrator (carving, range):
  /// the library's defaults, as `avp run` uses them; the ROI is set from roi_margin_m.
  mapping::MapOptions map;
  mapping::IntegratorOptions integrator;
  /// Threads of the integrator (0 = all hardware threads); the map does not depend on it.
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
  /// Apply the seeded D435-like depth noise model (seeded from scene.seed and the view index).
  bool noise = false;
  std::filesystem::path out = "out/map.avpmap";
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
Result<MapBuildSummary> RunMapBuild(const MapBuildOptions& options,
                                    const sim::ScenarioRegistry& scenarios);

// ---- avp map gt
// -----------------------------------------------------------------------------------

/// `avp map gt`: the scene's fruit surfaces voxelised (sim::VoxelizeFruitSurfaces) and written as
/// an OctoMap .bt of occupied voxels: the same kind of ground truth as the reference system's.
struct MapGtOptions {
  sim::SceneSource scene;
  /// 6 mm: the resolution of the reference system's ground-truth octrees (reference-system.md).
  double voxel_size_m = 0.006;
  std::filesystem::path out = "out/gt.bt";
};
struct MapGtSummary {
  std::string scene_name;
  size_t fruits = 0;
  size_t voxels = 0;
  uint64_t file_bytes = 0;
};
Result<MapGtSummary> RunMapGt(const MapGtOptions& options, const sim::ScenarioRegistry& scenarios);

// ---- avp map info
// ---------------------------------------------------------------------------------

/// Any map file LoadAnyMap reads (.avpmap, .bt, .ot): `file` is the .avpmap header (empty for
/// OctoMap files), `source` says what the file was and what reading it kept.
struct MapInfo {
  std::filesystem::path path;
  mapping::MapFileInfo file;
  mapping::MapSource source;
  mapping::MapOptions options;
  size_t blocks = 0;
  size_t semantic_blocks = 0;
  size_t known_voxels = 0;
  size_t free_voxels = 0;
  size_t occupied_voxels = 0;
  size_t labelled_voxels = 0;
  /// Labelled voxels per class (all / occupied only), indexed by SemanticClass value.
  std::array<size_t, kNumSemanticClasses> labelled_by_class{};
  std::array<size_t, kNumSemanticClasses> occupied_by_class{};
  std::vector<mapping::InstanceInfo> instances;
  Box3 known_bounds;
  size_t memory_bytes = 0;
};

Result<MapInfo> RunMapInfo(const std::filesystem::path& path);
/// The report `avp map info` prints (docs/map-format.md shows one).
std::string FormatMapInfo(const MapInfo& info);

// ---- avp map export
// -------------------------------------------------------------------------------

enum class MapExportFormat { kBt, kOt, kPly, kAvpMap };
/// "bt", "ot", "ply", "avpmap"; nullopt otherwise.
std::optional<MapExportFormat> MapExportFormatFromString(std::string_view name);

/// The input may be any map file LoadAnyMap reads (.avpmap, .bt, .ot): e.g. .ot -> .avpmap.
struct MapExportOptions {
  std::filesystem::path map;
  /// Empty: taken from the extension of `out`.
  std::string format;
  std::filesystem::path out;
  bool ply_ascii = false;
  /// PLY: every labelled voxel, not only the occupied ones.
  bool ply_all_labelled = false;
};
struct MapExportSummary {
  MapExportFormat format = MapExportFormat::kBt;
  std::filesystem::path out;
  size_t occupied_voxels = 0;  ///< bt / ot
  size_t free_voxels = 0;      ///< bt / ot
  size_t labelled_voxels = 0;  ///< ot: coloured by class; ply: vertices; avpmap: labelled
  uint64_t file_bytes = 0;
  mapping::MapSource source;  ///< what was read
};
Result<MapExportSummary> RunMapExport(const MapExportOptions& options);

// ---- avp map compare
// ------------------------------------------------------------------------------

/// Both files may be any map file LoadAnyMap reads. The ground truth is the GT file's occupied
/// voxels labelled `semantic_class` when it carries labels (an .avpmap, a ColorOcTree in class
/// colours), otherwise all its occupied voxels (.bt, OcTree).
struct MapCompareOptions {
  std::filesystem::path map;
  std::filesystem::path gt;
  /// Results are given exactly (0) and, when > 0, with this Chebyshev tolerance in map voxels.
  int tolerance_voxels = 1;
  SemanticClass semantic_class = SemanticClass::kFruit;
  /// Also write the result as JSON here (empty: no file).
  std::filesystem::path json_out;
};
struct MapCompareSummary {
  std::filesystem::path map;
  std::filesystem::path gt;
  SemanticClass semantic_class = SemanticClass::kFruit;
  size_t gt_occupied_leaves = 0;
  size_t gt_coarse_leaves = 0;
  mapping::MapSource map_source;
  mapping::MapSource gt_source;
  /// The GT file carried labels and only its voxels of `semantic_class` were taken.
  bool gt_used_labels = false;
  /// Exact first, then the tolerance (when > 0).
  std::vector<mapping::GroundTruthComparison> results;
  /// Lattice check: the exact F1 after moving every predicted voxel by the one-voxel shift
  /// (each component in {-1, 0, 1}, not all 0) that raises it most; a large gain over the
  /// unshifted exact F1 means the two sides' surfaces sit a voxel apart (a frame or lattice
  /// offset, or a different surface definition), not that the map is wrong.
  VoxelKey best_shift;
  double best_shift_f1 = 0.0;
};
Result<MapCompareSummary> RunMapCompare(const MapCompareOptions& options);
std::string FormatMapCompare(const MapCompareSummary& summary);
nlohmann::json ToJson(const MapCompareSummary& summary);

}  // namespace avp::apps

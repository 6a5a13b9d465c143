#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include <avp/core/camera.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/core/voxel_key.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/voxel_grid.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/scene.h>

namespace avp::eval {

/// How the observable ground truth is computed (docs/evaluation.md).
struct GroundTruthOptions {
  /// Voxel edge of the ground truth; must equal the evaluated map's (mapping::VoxelSizeRange).
  /// A run sets it from its map; the default is the map's.
  double voxel_size_m = mapping::GridOptions{}.voxel_size_m;
  /// Observation views: for each fruit, camera positions on spheres of these radii (metres)
  /// around its centre, over a fan of azimuths and elevations facing the robot base (the world
  /// origin), looking at the fruit; kept only when the arm reaches them (ArmModel::SolveCameraIk
  /// from the start joints, seeded), i.e. views the arm could really take.
  std::vector<double> radii_m = {0.28, 0.40, 0.55};
  /// Azimuths per radius and elevation, spread evenly over the fan centred on the direction from
  /// the fruit to the base, +-azimuth_half_range_deg wide (one azimuth: the centre only).
  int azimuths = 9;
  /// Elevations of the camera above the fruit's horizontal plane, degrees, each in (-89, 89).
  std::vector<double> elevations_deg = {-30.0, 0.0, 30.0, 55.0};
  double azimuth_half_range_deg = 85.0;
  /// Render size of the observation views; fx, fy, cx, cy are scaled from the episode camera
  /// (its field of view is kept), its depth range is kept.
  int image_width = 320;
  int image_height = 240;
  /// Returns farther from the camera than this (Euclidean) are ignored, as the integrator's
  /// max_range_m ignores them. A run sets it from its integrator; the default is the
  /// integrator's.
  double max_range_m = mapping::IntegratorOptions{}.max_range_m;
  /// Seed of the IK restarts (each view draws from its own stream of it).
  uint64_t seed = 0;

  /// OK, or InvalidArgument naming every bad field and its value.
  Status Validate() const;
};

/// The fields of GroundTruthOptions that describe the observation views (radii_m, azimuths,
/// elevations_deg, azimuth_half_range_deg, image_width, image_height); voxel_size_m, max_range_m,
/// and seed come from the run and are checked by a rule. The views are rendered on
/// avp::Threads() threads (core/parallel.h); the result does not depend on it.
const OptionTable<GroundTruthOptions>& GroundTruthOptionTable();

/// The visible-fraction levels at which `avp run` (record.json) and `avp bench` (summary.md)
/// count fruits by GroundTruth::FruitsVisibleAtLeast: below 0.05 the oracle segmenter never
/// detects a fruit (its v_min), at 0.25 it does with p 0.40, from 0.5 with p 0.97 (v_full).
inline constexpr std::array<double, 3> kVisibleFractionLevels = {0.05, 0.25, 0.50};

/// One candidate observation view of ObservableGroundTruth.
struct ObservationView {
  uint16_t fruit_id = 0;  ///< the fruit it looks at
  double radius_m = 0.0;
  double azimuth_deg = 0.0;    ///< of the camera seen from the fruit, about world z
  double elevation_deg = 0.0;  ///< of the camera above the fruit's horizontal plane
  RigidTransform X_WC;         ///< camera optical frame looking at the fruit centre, image up = +z
};

/// The fruit-surface voxels a map is scored against, with the fruits they belong to.
struct GroundTruth {
  double voxel_size_m = 0.0;
  /// Observable fruit-surface voxels -> fruit instance id (0 = unknown fruit, for a file read
  /// without a scene).
  std::unordered_map<VoxelKey, uint16_t, VoxelKeyHash> voxels;
  /// Every fruit of the scene, in instance-id order (empty for a file read without a scene).
  std::vector<sim::FruitTruth> fruits;
  /// Observable voxels per fruit of `fruits` (0 = never observable).
  std::unordered_map<uint16_t, size_t> voxels_per_fruit;
  /// Per fruit of `fruits`, the largest visible fraction over the reachable observation views:
  /// its visible pixels (fruit class, valid depth within max_range_m) over the area it would cover
  /// unoccluded, pi (f r / z)^2 (segmentation::ExpectedFruitAreaPx, as the oracle segmenter
  /// measures it), clamped to [0, 1]; 0 when no view sees it. How hidden a fruit is from the best
  /// view the arm can take: a detector that needs some fraction of a fruit in view (the oracle
  /// segmenter's v_min) cannot find a fruit below it. Empty for files.
  std::unordered_map<uint16_t, double> best_visible_fraction;
  /// Observation views generated and those the arm reaches (0 for files).
  size_t views_tried = 0;
  size_t views_reachable = 0;
  /// The reachable observation views, in candidate order (empty for files).
  std::vector<ObservationView> views;
  /// "observable:<scene name>" or "file:<path>".
  std::string source;

  /// The voxel keys in ascending (x, y, z) order.
  std::vector<VoxelKey> SortedKeys() const;
  /// Fruits with at least one observable voxel.
  size_t ObservableFruits() const;
  /// Fruits whose best_visible_fraction is at least `fraction`.
  size_t FruitsVisibleAtLeast(double fraction) const;
};

/// Every candidate view of every fruit, in order fruit (id) -> radius -> elevation -> azimuth;
/// views whose camera would be below the ground plane (z <= 0) are left out.
/// @pre options.Validate() is OK (throws avp::Error otherwise).
std::vector<ObservationView> ObservationViews(const std::vector<sim::FruitTruth>& fruits,
                                              const GroundTruthOptions& options);

/// The intrinsics of the observation views: `K`'s field of view, principal point and depth range
/// at options.image_width x options.image_height.
CameraIntrinsics ObservationIntrinsics(const CameraIntrinsics& K,
                                       const GroundTruthOptions& options);

/// The observable ground truth: the voxels (VoxelKey lattice, options.voxel_size_m) that contain a
/// point of a fruit's surface seen in at least one reachable observation view. Every fruit pixel
/// of a view with a valid depth within options.max_range_m is back-projected to its 3-D point;
/// its voxel joins the set with the pixel's instance id (the smaller id when two fruits share a
/// voxel). This is what a perfect map integrating those views would mark as occupied fruit, so
/// F1 = 1 is attainable. Deterministic: the same inputs give the same set for any thread count.
/// Errors: InvalidArgument for bad options, intrinsics, a q_start of the wrong size or with a
/// non-finite entry, or an invalid scene.
Result<GroundTruth> ObservableGroundTruth(const sim::Scene& scene, const robot::ArmModel& arm,
                                          const Eigen::VectorXd& q_start, const CameraIntrinsics& K,
                                          const GroundTruthOptions& options);

/// A ground truth read from a map file (mapping::LoadAnyMap): an OctoMap .bt or .ot gives its
/// occupied voxels at the finest resolution; a file that carries classes (an .avpmap, a
/// ColorOcTree in avp's class colours, e.g. a run's map.avpmap / map.ot) gives its occupied
/// fruit voxels, and `source` says so ("file:PATH (its fruit voxels)"). With a scene, each voxel
/// goes to the fruit whose surface is nearest its centre (distance | |p - c| - mean radius |, ties
/// to the smaller id) and `fruits` / `voxels_per_fruit` are filled; without one (nullptr) every
/// voxel has id 0 and there are no fruits. The file is checked before and after OctoMap reads it,
/// so a truncated or corrupt file is an error, never a different ground truth. Errors: those of
/// LoadAnyMap (NotFound, InvalidArgument, ResourceExhausted, ParseError, OutOfRange).
Result<GroundTruth> GroundTruthFromOctomapFile(const std::filesystem::path& bt,
                                               const sim::Scene* scene);

}  // namespace avp::eval

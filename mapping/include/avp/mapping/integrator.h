#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/mapping/semantic_map.h>

namespace avp::mapping {

/// How free space is carved.
enum class FreeSpaceCarving : uint8_t {
  /// Trace every ray from the sensor to its endpoint (OctoMap's semantics, exactly).
  kRayCast = 0,
  /// The same result as kRayCast computed voxel by voxel: end points are marked exactly as
  /// kRayCast; for each voxel of the frustum the integrator looks for a pixel whose ray carves it
  /// (pixel under the voxel centre first, then the voxel's footprint, pruned by a max-depth
  /// pyramid). Much faster on full images; needs a depth image (Integrate) and a field of view
  /// below 150 degrees. Differs from kRayCast only on floating-point ties (bench_map reports it).
  kProjective = 1,
  /// No free space at all (the reference system's `process_free_space: False`).
  kNone = 2,
  /// One ray per voxel holding a return, to that voxel's centre: OctoMap's
  /// `insertPointCloud(..., discretize = true)`. Occupied voxels are kRayCast's (except a return
  /// within max range whose voxel centre is beyond it: that voxel carves up to max range and is
  /// not marked, as in OctoMap); free space differs from kRayCast only in thin slivers that one
  /// return's ray crosses and its voxel centre's does not. Far fewer rays on dense clouds (a 5 mm
  /// voxel holds ~20 returns of a 640x480 camera at 0.6 m), so it is the fastest exact mode:
  /// meant for streams (frames fused while the arm moves). Works on images and clouds.
  kEndVoxelRays = 3,
};
/// Every mode, in the order of the option's choices and the CLIs' lists.
inline constexpr std::array<FreeSpaceCarving, 4> kFreeSpaceCarvings = {
    FreeSpaceCarving::kProjective, FreeSpaceCarving::kRayCast, FreeSpaceCarving::kEndVoxelRays,
    FreeSpaceCarving::kNone};
std::string_view ToString(FreeSpaceCarving carving);
/// "raycast", "projective", "end-voxel" or "none".
std::optional<FreeSpaceCarving> FreeSpaceCarvingFromString(std::string_view name);
/// The names of kFreeSpaceCarvings, in that order (for command-line choices).
std::vector<std::string> FreeSpaceCarvingNames();
/// Each of kFreeSpaceCarvings with its name, in that order (an option table's choices).
std::vector<std::pair<FreeSpaceCarving, std::string>> FreeSpaceCarvingChoices();

struct IntegratorOptions {
  /// Returns beyond this carve free space up to it and mark no endpoint (OctoMap's maxrange).
  double max_range_m = 1.5;
  /// kProjective: kRayCast's result, much faster on depth images (IntegratePointCloud refuses
  /// it: it needs the image); kEndVoxelRays: OctoMap's discretized insertion, fastest.
  FreeSpaceCarving carving = FreeSpaceCarving::kProjective;
  /// Set by code, not a configuration key (fusion during motion sets the planning ROI): only
  /// this box is updated. Returns outside it mark nothing; with the ray modes (raycast,
  /// end-voxel) each ray is walked only where it is inside the box (from where it enters to its
  /// end or to where it leaves, that last voxel excluded), which is what makes it cheaper; with
  /// projective carving the free space is not cut. Must be finite and non-empty when set.
  std::optional<Box3> clip_box;
  /// Every pixel_stride-th pixel of every pixel_stride-th row is fused (1: all): a camera stream
  /// decimated by subsampling, as the RealSense's decimation filter thins depth for high frame
  /// rates. Set by code (fusion during motion); > 1 only with the ray modes.
  int pixel_stride = 1;
  Status Validate() const;
};

/// The fields of IntegratorOptions: max_range_m and carving.
const OptionTable<IntegratorOptions>& IntegratorOptionTable();

struct IntegrationStats {
  size_t pixels = 0;            ///< pixels (or points) examined
  size_t invalid_depth = 0;     ///< zero, negative, NaN or infinite depth (skipped)
  size_t beyond_max_range = 0;  ///< returns beyond max range (free space only)
  size_t rejected_points = 0;   ///< endpoints outside the map's ROI or key range
  size_t endpoints = 0;         ///< valid returns within max range
  size_t occupied_updates = 0;  ///< voxels that received a hit
  size_t free_updates = 0;      ///< voxels that received a miss
  size_t masked_endpoints = 0;  ///< endpoints inside some instance mask
  SemanticFrameStats semantics;
  double seconds = 0.0;  ///< wall time of the call

  std::string ToString() const;
};

/// Fuses depth (and segmentation) into a SemanticMap. Stateless apart from options; one frame per
/// call, each voxel updated at most once per frame, occupied wins over free (as OctoMap).
class Integrator {
 public:
  /// @throws avp::Error if options.Validate() fails.
  explicit Integrator(const IntegratorOptions& options = {});
  const IntegratorOptions& options() const { return options_; }

  /// Integrates one RGB-D frame: frame.Validate() must pass; `segmentation` may be null (no
  /// semantics), otherwise its size must match the depth image. Depth values that are zero,
  /// negative, NaN or infinite are skipped and counted. Returns an error naming the bad value
  /// on size mismatches or an invalid frame; the map is untouched then.
  Result<IntegrationStats> Integrate(const RgbdFrame& frame, const Segmentation* segmentation,
                                     SemanticMap& map) const;

  /// OctoMap's insertPointCloud(cloud, origin, max_range) on the occupancy grid: the same
  /// semantics, for side-by-side comparisons. Non-finite points are skipped and counted.
  Result<IntegrationStats> IntegratePointCloud(std::span<const Eigen::Vector3f> points_W,
                                               const Eigen::Vector3d& origin_W,
                                               OccupancyGrid& grid) const;

 private:
  IntegratorOptions options_;
};

}  // namespace avp::mapping

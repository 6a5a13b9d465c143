#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/camera.h>
#include <avp/core/entropy.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/core/voxel_key.h>
#include <avp/mapping/semantic_map.h>
#include <avp/planning/candidates.h>
#include <avp/planning/gain_grid.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

/// The volumetric information gain utilities of Isler et al., ICRA 2016 (nbv-literature.md §1.1).
enum class IslerUtility {
  kAverageEntropy,   ///< "ae": mean per-voxel entropy over the rays that end on an occupied voxel
  kOcclusionAware,   ///< "oa": Σ p_vis H_b(p)
  kUnobservedVoxel,  ///< "uv": Σ over unknown voxels of p_vis H_b(p)
  kRearSideVoxel,    ///< "rsv": occupied voxels reached right after an unknown one
  kRearSideEntropy,  ///< "rse": p_vis H_b over the unknown run before an occupied end, + its term
  kProximityCount,   ///< "pc": Σ over unknown voxels of (d_max - d_occ)
};

/// "ae", "oa", "uv", "rsv", "rse", "pc".
std::string_view ToString(IslerUtility utility);
/// Inverse of ToString; nullopt for other names.
std::optional<IslerUtility> IslerUtilityFromString(std::string_view name);
/// All six, in the order of the enum.
const std::vector<IslerUtility>& AllIslerUtilities();

/// Distance from each voxel to the nearest occupied voxel (between voxel centres), up to
/// max_distance_m, for the proximity-count utility. Dense over the occupied voxels' bounding box
/// inflated by max_distance_m, two bytes per voxel; built by dilating only the occupied voxels
/// that have a non-occupied 6-neighbour (the nearest occupied voxel of any non-occupied voxel is
/// always one of these), so time is proportional to the surface voxels x the ball's volume.
class ProximityField {
 public:
  ProximityField() = default;
  /// InvalidArgument for max_distance_m not in [0, 0.2] m or a box above max_bytes. With
  /// `region`, only the occupied voxels within max_distance_m of it are taken: the distances are
  /// exact for voxels inside `region` (and the field no larger than it needs, however large the
  /// map; e.g. a ground plane outside a plant's ROI).
  static Result<ProximityField> Build(const mapping::SemanticMap& map, double max_distance_m,
                                      size_t max_bytes = size_t{1} << 30,
                                      const std::optional<Box3>& region = std::nullopt);

  double max_distance_m() const { return max_distance_m_; }
  /// Distance in metres from the centre of `k` to the nearest occupied voxel centre, when it is
  /// at most max_distance_m (0 for occupied voxels); nullopt otherwise.
  std::optional<double> DistanceToOccupied(const VoxelKey& k) const;

  /// The largest squared distance (voxel units) within max_distance_m (same rule as the gain
  /// grid's near-target ball: exact for radii that are whole voxels).
  static int64_t Threshold(double max_distance_m, double voxel_size_m);

 private:
  double voxel_size_m_ = mapping::GridOptions{}.voxel_size_m;
  double max_distance_m_ = 0.0;
  int64_t threshold_ = 0;
  VoxelKey min_;
  Eigen::Vector3i dims_ = Eigen::Vector3i::Zero();
  /// Squared distance in voxel units; 0xffff = farther than max_distance_m.
  std::vector<uint16_t> d2_;
};

/// What one ray contributes to a view's gain.
struct IslerRayGain {
  /// Bits (AE, OA, UV, RSE), a count (RSV) or metres (PC).
  double gain = 0.0;
  /// AE only: voxels of a ray that ends on an occupied voxel (the mean's denominator); 0 else.
  int64_t voxels = 0;
  /// The ray ended on an occupied voxel.
  bool hit = false;
};

/// Ray rules shared by all utilities. A ray from `from` towards `to` visits the voxels of the
/// segment [from, to) (GainGrid::Walk; the voxel of `to` is not visited) and ends at, and
/// includes, its first occupied voxel, as the reference implementation's castRay +
/// computeRayKeys. A ray that hits nothing simply runs to max range: there is no "void ray"
/// bonus (rpg_ig_active_reconstruction's H(p)/(1 - p) is the geometric sum under its buggy
/// visibility update). Voxels x_0, x_1, ... in order, p_i = GainVoxel::p_occ (0.5 for unknown),
/// and the visibility is the exclusive product p_vis(x_i) = Π_{j<i} (1 - p_j), p_vis(x_0) = 1
/// (not the reference implementation's p_vis *= p_occ). Per ray:
///   - AE: on a hit, gain = Σ_i H_b(p_i) over all its voxels and voxels = their number (the
///     view's gain is Σ gain / Σ voxels over the hit rays); 0 otherwise.
///   - OA: Σ_i p_vis(x_i) H_b(p_i).
///   - UV: Σ_i 1[x_i unknown] p_vis(x_i) H_b(p_i).
///   - RSV: 1 when the ray hits and the voxel before the hit is unknown, else 0.
///   - RSE: on a hit, Σ p_vis H_b over the contiguous run of unknown voxels just before the hit
///     voxel, plus p_vis H_b of the hit voxel; 0 otherwise.
///   - PC: Σ over unknown voxels with an occupied voxel within d_max of (d_max - d_occ), metres.
struct IslerRayOptions {
  /// Ray length from the optical centre (metres), > 0.
  double max_range_m = 1.0;
  /// A ray through every stride-th pixel of the camera (RayDirections), >= 1.
  int ray_stride_px = 16;
  /// PC's d_max (metres), in [0, 0.2].
  double proximity_max_distance_m = 0.02;
  Status Validate() const;
};

/// The fields of IslerRayOptions.
const OptionTable<IslerRayOptions>& IslerRayOptionTable();

/// Fast evaluator: streams GainGrid::Walk. `proximity` is required for kProximityCount (ignored
/// otherwise). @throws avp::Error if it is missing for PC.
IslerRayGain EvaluateIslerRay(IslerUtility utility, const GainGrid& grid,
                              const ProximityField* proximity, const Eigen::Vector3d& from,
                              const Eigen::Vector3d& to);

/// Slow reference evaluator: collects the ray's keys with mapping::TraverseRay, drops the end
/// voxel, reads every voxel with ReadGainVoxel from the map (and PC's d_occ by scanning the map
/// around the voxel), and applies the same rules in a plain loop.
IslerRayGain EvaluateIslerRayReference(IslerUtility utility, const mapping::SemanticMap& map,
                                       SemanticClass target, const Box3& roi,
                                       double proximity_max_distance_m, const Eigen::Vector3d& from,
                                       const Eigen::Vector3d& to);

/// Combines ray gains into a view gain: Σ gain / Σ voxels for AE (0 when no ray hit), Σ gain
/// for the others.
double CombineIslerRays(IslerUtility utility, const std::vector<IslerRayGain>& rays);

/// A view's gain: every ray of RayDirections(K, ray_stride_px) from the optical centre of X_WC,
/// max_range_m long, through EvaluateIslerRay, combined with CombineIslerRays.
double IslerViewGain(IslerUtility utility, const GainGrid& grid, const ProximityField* proximity,
                     const RigidTransform& X_WC, const CameraIntrinsics& K,
                     const IslerRayOptions& options);
/// The same with EvaluateIslerRayReference (slow; for tests).
double IslerViewGainReference(IslerUtility utility, const mapping::SemanticMap& map,
                              SemanticClass target, const Box3& roi, const RigidTransform& X_WC,
                              const CameraIntrinsics& K, const IslerRayOptions& options);

struct IslerPlannerOptions {
  IslerUtility utility = IslerUtility::kOcclusionAware;
  /// The shared candidate generator (GenerateShellCandidates around FindViewTargets), so the
  /// literature baselines compete with avp-nbv on the same candidates.
  ShellCandidateOptions candidates;
  GainGridOptions grid;
  IslerRayOptions rays;
  /// WeightedLinearUtility of the reference implementation: U = w_ig G / ΣG - w_c C / ΣC, sums
  /// over the reachable candidates (a term is 0 when its sum is 0). w_ig, w_c >= 0.
  double gain_weight = 1.0;
  double cost_weight = 0.1;
  Status Validate() const;
};

/// The fields of IslerPlannerOptions but `utility` (the planner's name chooses it):
/// candidates.*, grid.*, rays.*, gain_weight, cost_weight.
const OptionTable<IslerPlannerOptions>& IslerPlannerOptionTable();

/// "isler-ae", "isler-oa", "isler-uv", "isler-rsv", "isler-rse", "isler-pc"
/// (RegisterBuiltinPlanners).
std::vector<PlannerEntry> IslerPlannerEntries();

/// Next-best view by one of the Isler et al. utilities ("isler-ae", "isler-oa", "isler-uv",
/// "isler-rsv", "isler-rse", "isler-pc"): candidates from the shared shell generator, gain by
/// IslerViewGain (G), motion cost C = |q - q_current|, utility U = w_ig G/ΣG - w_c C/ΣC, ranked
/// by RankCandidates. Never stops early.
class IslerPlanner final : public ViewPlanner {
 public:
  /// @throws avp::Error if options.Validate() fails.
  explicit IslerPlanner(const IslerPlannerOptions& options = {});
  std::string_view name() const override { return name_; }
  PlanResult Plan(const PlanningRequest& request, Rng& rng) override;

  const IslerPlannerOptions& options() const { return options_; }

 private:
  IslerPlannerOptions options_;
  std::string name_;
};

}  // namespace avp::planning

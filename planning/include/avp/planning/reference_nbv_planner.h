#pragma once

#include <cstddef>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/camera.h>
#include <avp/core/rng.h>
#include <avp/core/transform.h>
#include <avp/mapping/semantic_map.h>
#include <avp/planning/gain_grid.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

/// Parameters of the reference system's NBV planner (av_planning/src/nbv_planning_pipeline.cpp,
/// reference-system.md §4.8), with its values as defaults.
struct ReferenceNbvOptions {
  /// Positions per axis of the `square_random` layout: floor(sqrt(40)) = 6, i.e. 36 positions.
  int grid_size = 6;
  /// Spacing of the positions in base y and z (metres): 6 x 0.08 m spans +-0.2 m.
  double grid_spacing_m = 0.08;
  /// Half-range of the uniform jitter along the start pose's local y and z (metres).
  double jitter_m = 0.04;
  /// Tilt of the 4 extra orientations (about local Y and local Z, both signs), degrees.
  double tilt_deg = 30.0;
  /// Ray length: castRay's maxRange (metres).
  double max_range_m = 2.0;
  /// `full_attention` ROI: the occupied voxels' extent in the start view's frame is shrunk to its
  /// central 1/ratio in depth, width and height (4 / 4 / 1: 25 %, 25 %, full height). >= 1.
  double depth_ratio = 4.0;
  double width_ratio = 4.0;
  double height_ratio = 1.0;
  /// Confidences are clamped to [eps, 1 - eps] before H_b, so c in {0, 1} gives no NaN
  /// (the reference's entropy was NaN there), in (0, 0.5).
  double confidence_epsilon = 1e-6;
  /// Candidates within these tolerances of a fused view (or of the current pose) are dropped.
  double fused_position_tol_m = 0.02;
  double fused_angle_tol_rad = 0.1745;
  /// The gain grid the rays are walked on (the near-target radius is unused here).
  GainGridOptions grid{.near_target_radius_m = 0.0};

  /// Names every bad value.
  Status Validate() const;
};

/// The fields of ReferenceNbvOptions (all but the gain grid's).
const OptionTable<ReferenceNbvOptions>& ReferenceNbvOptionTable();

/// "reference-nbv"'s registry entry (RegisterBuiltinPlanners).
PlannerEntry ReferenceNbvPlannerEntry();

/// The 5 x grid_size^2 candidate poses (180 with the defaults) around the **start** camera pose,
/// in generation order: for each height row (base z offset, ascending), for each column (base y
/// offset, ascending), the position X_WC_start.translation() + (0, dy, dz) in base axes (x
/// fixed), jittered by U(+-jitter_m) along the start pose's local y then local z (two draws from
/// `rng`, in that order); then 5 orientations at that position: straight (the start camera's),
/// +tilt and -tilt about local Y, +tilt and -tilt about local Z.
///
/// The reference's pose is the end effector's, with local x the viewing direction. In avp's
/// camera optical frame (z forward, x right, y down) that frame's axes are: local x = +z_C,
/// local y = -x_C (image left), local z = -y_C (image up), which is exactly the flange frame for
/// the default camera mount (docs/robot.md). Rotations are about the optical centre. Candidates
/// have source "grid" and are not IK-checked.
std::vector<ViewCandidate> ReferenceCandidatePoses(const RigidTransform& X_WC_start,
                                                   const ReferenceNbvOptions& options, Rng& rng);

/// The `full_attention` ROI, as a box in the start view's camera frame S (= C at X_WC_start).
struct FullAttentionRoi {
  RigidTransform X_WS;
  /// Empty when the map has no occupied voxel.
  Box3 box_S;
  /// Whether world point p_W lies in the ROI (the test is made in frame S, the frame the box was
  /// built in: the reference compared S-frame bounds with base-frame coordinates).
  bool Contains(const Eigen::Vector3d& p_W) const;
};

/// The extent of every occupied voxel centre expressed in the start view's frame S, each axis
/// shrunk about its centre to 1/ratio of its size: depth (z_S) by depth_ratio, width (x_S) by
/// width_ratio, height (y_S) by height_ratio.
FullAttentionRoi ComputeFullAttentionRoi(const mapping::SemanticMap& map,
                                         const RigidTransform& X_WS,
                                         const ReferenceNbvOptions& options);

/// A target-class voxel the reference planner casts rays towards.
struct ReferenceTarget {
  Eigen::Vector3d p_W;
};

/// Centres of the voxels labelled with `target` (any occupancy state) that lie inside `roi`, in
/// the map's semantic iteration order.
std::vector<ReferenceTarget> ReferenceTargets(const mapping::SemanticMap& map, SemanticClass target,
                                              const FullAttentionRoi& roi);

/// One candidate's evaluation.
struct ReferenceViewEvaluation {
  /// U = Σ over rays of H_b(c) of the ray's first occupied voxel when it carries the target class
  /// (c its map confidence, clamped), in bits.
  double utility = 0.0;
  /// Rays cast: targets in front of the camera and inside the image of K.
  size_t rays = 0;
  /// Rays whose first occupied voxel carries the target class.
  size_t target_hits = 0;
};

/// Casts one ray per target whose centre projects into the image of `K` (in front of the
/// camera, the true field of view), from the optical centre of X_WC towards the target centre,
/// max_range_m long, walked on `grid`; the first occupied voxel ends the ray (free and unknown
/// voxels are passed, as castRay with ignoreUnknown). Hit voxels' confidences come from `map`
/// (unquantised).
ReferenceViewEvaluation EvaluateReferenceView(const GainGrid& grid, const mapping::SemanticMap& map,
                                              const std::vector<ReferenceTarget>& targets,
                                              const RigidTransform& X_WC, const CameraIntrinsics& K,
                                              const ReferenceNbvOptions& options);

/// The reference system's NBV planner ("reference-nbv"), reproduced with its documented bugs
/// fixed (docs/planning.md, "reference-nbv"):
///
/// Reproduced: candidates every step around the start pose (ReferenceCandidatePoses: 6 x 6
/// positions x 5 orientations = 180), IK as the only filter, the `full_attention` ROI (occupied
/// extent shrunk 4 / 4 / 1), one ray per target-class voxel in the FOV and the ROI, the first
/// occupied voxel within 2 m, U = Σ H_b(c) over hit target voxels (expected_semantic_information
/// _gain), arg-max of U.
///
/// Fixed: the ROI is built and tested in one frame; rays start at the optical centre, not the
/// end effector; the FOV is the true one from request.K (not Gazebo's halved tangent); c is
/// clamped (no NaN); jitter comes from the passed, seeded rng; an empty candidate set is a
/// NotFound status, not a crash; candidates near a fused view or the current pose are dropped;
/// all reachable candidates are ranked (the loop falls back to the next one when a move fails);
/// when no candidate has U > 0 the reachable ones are ranked in a seeded random order, instead of
/// staying at the current pose.
class ReferenceNbvPlanner final : public ViewPlanner {
 public:
  /// @throws avp::Error if options.Validate() fails.
  explicit ReferenceNbvPlanner(const ReferenceNbvOptions& options = {});
  std::string_view name() const override { return "reference-nbv"; }
  PlanResult Plan(const PlanningRequest& request, Rng& rng) override;

  const ReferenceNbvOptions& options() const { return options_; }

 private:
  ReferenceNbvOptions options_;
};

}  // namespace avp::planning

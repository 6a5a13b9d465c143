#pragma once

#include <optional>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/transform.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

/// Options of the predefined (non-adaptive) planner.
struct PredefinedOptions {
  enum class Set {
    /// The reference's default `zig_zag_plane_narrow` joint waypoints (reference-system.md §4.7).
    kNarrow,
    /// The reference's `zig_zag_plane_wide` joint waypoints.
    kWide,
    /// A zig-zag generated from the request's ROI, for scenes other than the reference's.
    kGeneric,
  };
  Set set = Set::kNarrow;

  // ---- kGeneric -------------------------------------------------------------------------------
  /// Distance of the camera plane from the ROI's vertical centre axis, towards the robot base
  /// (metres, > 0).
  double generic_distance_m = 0.45;
  /// Left/right camera offsets as a fraction of the ROI's half-width across the viewing
  /// direction (the camera alternates between -f and +f of it), >= 0.
  double generic_lateral_fraction = 0.3;
  /// The lowest and highest camera heights as fractions of the ROI's height from its bottom, in
  /// [0, 1] with bottom <= top; the waypoints climb evenly from bottom to top.
  double generic_bottom_fraction = 0.4;
  double generic_top_fraction = 0.7;
  /// Waypoints generated (p1, p2, ...); 0: request.views_total - 1, one per view after the start.
  int generic_waypoints = 0;

  /// Names every bad value.
  Status Validate() const;
};

/// "narrow", "wide", "generic".
/// The fields of PredefinedOptions but `set`, which the planner's name chooses.
const OptionTable<PredefinedOptions>& PredefinedOptionTable();

/// "predefined" (the reference's narrow zig-zag), "predefined-wide" and "predefined-generic"
/// (RegisterBuiltinPlanners).
std::vector<PlannerEntry> PredefinedPlannerEntries();

std::string_view ToString(PredefinedOptions::Set set);
/// Inverse of ToString; nullopt for other names.
std::optional<PredefinedOptions::Set> PredefinedSetFromString(std::string_view name);

/// The reference system's initial pose (0, -40, 90, 0, 40, 0), reference joint convention,
/// degrees: view 0 of every predefined set.
Eigen::VectorXd ReferenceStartJointsDeg();

/// The reference's joint waypoints p1 ... p8 of `set` (kNarrow or kWide; empty for kGeneric) in
/// the reference joint convention, degrees, as in av_planning's
/// predefined_planning_waypoints.yaml. Convert with robot::ArmModel::FromReferenceJoints.
std::vector<Eigen::VectorXd> ReferenceWaypointsDeg(PredefinedOptions::Set set);

/// The camera poses of the generic zig-zag, before IK. Let f be the horizontal direction from the
/// robot base (world origin) towards the ROI's vertical centre axis (+x when the axis passes
/// through the origin) and r = f x z the camera's right. Pose i of `n` sits on the vertical
/// plane `generic_distance_m` before the axis (towards the base), offset along r by
/// +generic_lateral_fraction (i even: right, as the reference's p1) or - (i odd: left) of the
/// ROI's half-width across f, at a height climbing evenly from generic_bottom_fraction to
/// generic_top_fraction of the ROI's height; it looks horizontally at the axis at its own height,
/// image up = world +z.
/// @throws avp::Error for an empty or non-finite ROI, n < 0, or invalid options.
std::vector<RigidTransform> GenericZigZagPoses(const Box3& roi, int n,
                                               const PredefinedOptions& options);

/// Plays a fixed list of waypoints, one per view: view k of the episode (request.view_index)
/// goes to waypoint p_k, view 0 being the start pose. With the reference's sets, 8 fused views
/// are start + p1 ... p7 (the reference also moved to p8 but never observed it).
///
/// `ranked` holds exactly one candidate, the next waypoint (source "waypoint", gain and utility
/// 0, cost = joint distance from q_current). When the waypoints are exhausted or the waypoint is
/// outside the joint limits the status is NotFound naming the view and the set.
///
/// kGeneric: the poses of GenericZigZagPoses are IK-solved once per episode, in order, each from
/// the previous solution (the first from request.q_start, or q_current when q_start is empty),
/// with `rng`; unreachable poses are dropped, the rest are the waypoints p1, p2, ... The list is
/// recomputed when the ROI, the budget or the start pose changes (a new episode).
class PredefinedPlanner final : public ViewPlanner {
 public:
  /// @throws avp::Error if options.Validate() fails.
  explicit PredefinedPlanner(const PredefinedOptions& options = {});
  std::string_view name() const override { return "predefined"; }
  PlanResult Plan(const PlanningRequest& request, Rng& rng) override;

  const PredefinedOptions& options() const { return options_; }

  /// The waypoints p1, p2, ... (URDF joints) the planner plays for `request`'s episode, with how
  /// many generic poses were dropped as unreachable (0 for the reference sets).
  struct Waypoints {
    std::vector<Eigen::VectorXd> q;
    size_t dropped = 0;
  };
  /// @throws avp::Error if request.arm is null or, for the reference sets, has not 6 joints.
  const Waypoints& WaypointsFor(const PlanningRequest& request, Rng& rng);

 private:
  PredefinedOptions options_;
  // Cache of the generic set: valid for (roi, views_total, X_WC_start).
  bool cached_ = false;
  Box3 cached_roi_;
  int cached_views_total_ = 0;
  RigidTransform cached_start_;
  Waypoints waypoints_;
};

}  // namespace avp::planning

#pragma once

#include <vector>

#include <avp/core/rng.h>
#include <avp/planning/gain_grid.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

/// 3-D candidate views around targets (avp-nbv's generator; also used by the random and the
/// literature baselines so they compete on the same candidates).
struct ShellCandidateOptions {
  /// Camera distances from the target (metres): radii are drawn uniformly between the smallest
  /// and the largest.
  std::vector<double> radii_m = {0.35, 0.55};
  /// Camera elevations above the target's horizontal plane (degrees): drawn between the smallest
  /// and the largest (uniform in area).
  std::vector<double> elevations_deg = {-30.0, 45.0};
  /// Azimuths are drawn within this half-width of the direction from the target to the robot
  /// base (degrees), where the arm can look at the plant from.
  double azimuth_half_range_deg = 70.0;
  /// At most this many targets: fruit instances (largest first), then frontier clusters, then
  /// the ROI centre.
  int max_targets = 12;
  /// Candidates to generate (spread evenly over the targets) before the reachability check;
  /// with more than max_targets targets (extra_frontier_targets) each still gets
  /// max_candidates / max_targets, so there are more.
  int max_candidates = 720;
  /// No candidate whose eye is within this distance of a known occupied voxel.
  double clearance_m = 0.03;
  /// Within this horizontal distance of the plant's core (PlantCoreDistance: where
  /// the foliage is) a camera must sit in known free space: the planner never puts the camera
  /// into unmapped foliage. 0 turns the rule off.
  double plant_core_radius_m = 0.25;
  /// Targets along the plant's core (PlantCoreDistance's medial axis at the ROI's mid-height)
  /// at least this far apart (metres): one at the ROI centre for a square ROI, several along a
  /// long one (a row or an espalier wall), so candidates cover a wide plant. 0: the ROI centre
  /// only.
  double core_target_spacing_m = 0.0;
  /// Frontier clusters are chosen heaviest first (0), or spread: each next one maximises its
  /// weight times min(1, d / frontier_spread_m), d its distance to the targets chosen before it
  /// (fruit and frontiers), so the frontier targets cover the whole boundary of what was seen (a
  /// wide plant's ends, a low tier) instead of its heaviest stretch (metres).
  double frontier_spread_m = 0.0;
  /// With frontier_spread_m: the heaviest this many frontier clusters are taken first, as without
  /// spreading, and only the others are spread.
  int frontier_spread_after = 0;
  /// Frontier clusters beyond max_targets, added after all others: each next one maximises its
  /// weight x min(1, d / extra_frontier_spread_m), d its distance to the targets chosen before it
  /// (the heaviest remaining when extra_frontier_spread_m is 0). They get as many candidates as
  /// every other target (max_candidates / max_targets each), so the plan has more candidates
  /// and the others keep theirs. 0: none.
  int extra_frontier_targets = 0;
  double extra_frontier_spread_m = 0.3;
  /// Up to this many targets in regions of the ROI that no view has seen yet, next to the plant
  /// seen so far (where it likely goes on): the ROI is cut into cubes of unseen_cell_m, a cube
  /// with at most 10 % of its voxels known is unseen, and it is weighted by the occupied voxels
  /// of the 3 x 3 x 3 cubes around it (0: not a target). Chosen greedily, each next one
  /// maximising its weight x min(1, d / (3 unseen_cell_m)), d its distance to the targets chosen
  /// before it (fruit and the plant's core included). They come out of the frontiers' share of
  /// max_targets. 0 turns them off (the default: measured in docs/planning.md, it did not help).
  int unseen_targets = 0;
  /// Edge of the cubes the ROI is cut into for unseen_targets (metres); larger, by factors of
  /// 1.25, when the ROI would hold more than 2^20 cubes.
  double unseen_cell_m = 0.1;
  /// IK restarts per candidate after the attempt from the current joints.
  int ik_restarts = 1;

  /// Names every bad value (ShellCandidateOptionTable).
  Status Validate() const;
};

/// The fields of ShellCandidateOptions. The IK checks run on avp::Threads() threads.
const OptionTable<ShellCandidateOptions>& ShellCandidateOptionTable();

/// Where candidates look: target points with a label ("fruit-shell", "frontier", "roi").
struct ViewTarget {
  Eigen::Vector3d p_W = Eigen::Vector3d::Zero();
  std::string source;
  double weight = 1.0;
};

/// Targets for the shell generator: the centroids of the map's target-class instances (largest
/// first), centres of frontier clusters inside the ROI (unknown voxels next to free ones), and
/// the plant's core: the ROI centre, or with core_target_spacing_m points along the core of a
/// long ROI (CoreTargets); at most options.max_targets (the core's points are always kept).
/// Points along the plant's core at the ROI's mid-height: the medial axis of the ROI's footprint
/// (PlantCoreDistance: the vertical axis of a square ROI, a segment along the long side of a
/// long one) evenly, ends included, 1 + floor(axis length / spacing_m) of them (at least
/// spacing_m apart), at most max_points; the ROI centre alone when the axis is shorter than
/// spacing_m or spacing_m is 0.
std::vector<Eigen::Vector3d> CoreTargets(const Box3& roi, double spacing_m, int max_points);

std::vector<ViewTarget> FindViewTargets(const PlanningRequest& request, const GainGrid& grid,
                                        const ShellCandidateOptions& options);

/// Candidates on shells around `targets`, looking at them (image up = world +z), each
/// IK-checked from request.q_current (q, reachable and cost filled). Directions and radii are
/// drawn from `rng` (deterministic given its state); eyes beyond the arm's reach, below 5 cm,
/// within clearance_m of a known occupied voxel, in unknown space within plant_core_radius_m of
/// the ROI's axis, or within 2 cm / 10 deg of a fused view are dropped before IK.
std::vector<ViewCandidate> GenerateShellCandidates(const PlanningRequest& request,
                                                   const GainGrid& grid,
                                                   const std::vector<ViewTarget>& targets,
                                                   const ShellCandidateOptions& options, Rng& rng);

}  // namespace avp::planning

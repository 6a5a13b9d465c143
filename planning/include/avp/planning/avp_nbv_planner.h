#pragma once

#include <array>
#include <functional>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <avp/planning/candidates.h>
#include <avp/planning/gain_grid.h>
#include <avp/planning/learned_gain.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/view_planner.h>

namespace avp::planning {

/// avp's next-best-view planner (docs/planning.md, "avp-nbv").
///
/// Candidates: 3-D shells around the map's fruit instances, frontier clusters and the ROI centre
/// (GenerateShellCandidates), IK-checked. Gain of a view, summed over rays through every
/// `ray_stride_px`-th pixel of the true camera model, each walked from the optical centre:
///   - visibility p_vis = Π (1 − p_j) over the voxels before (exclusive product): free voxels are
///     transparent, an occupied voxel ends the ray, an unknown voxel of the ROI occludes with
///     `p_unknown` times a Gaussian (σ = `unknown_occlusion_sigma_m`, 0 = flat) of its horizontal
///     distance from the plant's core (PlantCoreDistance: foliage is dense there, the rest of the
///     ROI box is mostly air; 0.05 per 5 mm voxel by default: even the core is mostly air), one
///     outside the ROI with `p_unknown_outside_roi`; both per voxel of `occlusion_voxel_size_m`,
///     rescaled to the map's voxel size (OcclusionPerVoxel);
///   - an unknown voxel adds p_vis · w (bits of H(0.5) = 1): w = `w_predicted_target` on the
///     predicted surface of a detected fruit (a sphere fitted to its voxels: its unseen side),
///     `w_unknown_near_target` within the near-target radius of a fruit voxel; elsewhere in the ROI
///     `w_unknown_roi` times a Gaussian (σ = `roi_axis_sigma_m`) of its horizontal distance from
///     the plant's core, a prior for where unseen fruit hangs; 0 outside the ROI;
///   - the occupied target-class voxel that ends a ray adds p_vis · `w_target_entropy` · H_b(c),
///     its semantic uncertainty;
///   - with `range_weight_ref_m` > 0 (0, off, by default: it favoured distant views of the canopy's
///     front over close ones under it, docs/planning.md), each contribution is scaled by
///     (d / `range_weight_ref_m`)², d the voxel's distance from the camera, for the footprint of
///     the pixel block a ray stands for; voxels closer than `min_gain_range_m` to the camera count
///     nothing (the view would only see them at the edge of the sensor's range).
/// Utility U = G / max G − `w_motion` · |Δq| / max |Δq| + `w_diversity` · min(1, d / `diversity_m`)
/// over the candidate set, d the distance from the candidate's eye to the nearest fused one (the
/// greedy gain alone keeps returning to views like the ones it has, which fared worse than
/// random views in the paper's scenarios); views within
/// 2 cm / 10° of a fused view are never chosen. Stopping rules (both off by default): when the
/// best gain is below `min_gain_bits`, or below `min_gain_fraction` times the best gain of the
/// episode's first plan (view_index 1; scale-free: the same fraction suits a small plant and a
/// wide tree, a 3 mm map and a 10 mm one), the planner asks the loop to stop.
/// The parts of avp-nbv's gain, each the sum of its voxels' weighted contributions.
enum AvpGainTerm : int {
  kGainTargetEntropy = 0,  ///< w_target_entropy: target voxels' semantic entropy
  kGainPredictedTarget,    ///< w_predicted_target: unknown voxels on a fruit's predicted surface
  kGainUnknownNearTarget,  ///< w_unknown_near_target: other unknown voxels near a target voxel
  kGainUnknownRoi,         ///< w_unknown_roi: any other unknown ROI voxel (core prior)
  kGainTermCount
};
/// "target_entropy", "predicted_target", "unknown_near_target", "unknown_roi".
const char* AvpGainTermName(AvpGainTerm term);

struct AvpNbvOptions {
  ShellCandidateOptions candidates;
  GainGridOptions grid;
  int ray_stride_px = 20;
  /// Coarse to fine: every reachable candidate is first scored with the rays of every
  /// `coarse_ray_stride_px`-th pixel (their sum scaled to the fine ray count), and the
  /// `refine_top` best by that utility again with the `ray_stride_px` rays; the others keep the
  /// coarse estimate. 0 (or a stride not above ray_stride_px, or at most refine_top reachable
  /// candidates) scores every candidate with the fine rays.
  int coarse_ray_stride_px = 40;
  int refine_top = 32;
  double max_range_m = 1.0;
  double p_unknown = 0.05;
  double p_unknown_outside_roi = 0.0;
  /// p_unknown and p_unknown_outside_roi are occlusion probabilities per voxel of this edge
  /// (metres). On a map of voxel edge s, an unknown voxel occludes with
  /// OcclusionPerVoxel(p, s, occlusion_voxel_size_m) = 1 − (1 − p)^(s / occlusion_voxel_size_m),
  /// so that the transmittance per metre of unobserved space does not depend on the voxel size.
  /// 0: per voxel of whatever size the map has, as given.
  double occlusion_voxel_size_m = 0.005;
  double unknown_occlusion_sigma_m = 0.07;
  double w_target_entropy = 1.0;
  double w_predicted_target = 1.0;
  double w_unknown_near_target = 0.3;
  double w_unknown_roi = 0.2;
  double roi_axis_sigma_m = 0.15;
  double range_weight_ref_m = 0.0;
  double min_gain_range_m = 0.2;
  double w_motion = 0.1;
  double w_diversity = 0.5;
  double diversity_m = 0.2;
  double min_gain_bits = 0.0;
  /// In [0, 1); 0 disables it.
  double min_gain_fraction = 0.0;
  /// What an unknown voxel is worth to a ray: off (the default), its weight w whatever follows
  /// (a long unobserved path adds up); on, w times the probability that the ray ends there (its
  /// occlusion probability), as a ray shows one surface: the sum along a ray is bounded by the
  /// largest weight. Voxels on a detected fruit's predicted surface count w fully either way.
  bool surface_gain = false;
  /// Keep each candidate's gain by part in ViewCandidate::gain_terms (AvpGainTermName order,
  /// summing to its gain): the data to calibrate the weights on (`--oracle-regret` records them
  /// beside the true gain). Changes no choice.
  bool record_gain_terms = false;
  /// A learned gain (learned_gain.h, docs/planning.md "A learned gain"): empty (the default) for
  /// the hand-written gain above; a model name under <config dir>/models ("learned") or a path to
  /// an .onnx file. With one, each reachable candidate's feature row (view_features.h) goes
  /// through the model and its prediction takes the place of G in the utility; should the model
  /// fail at a step, that step falls back to the hand-written gain with a warning
  /// (PlanResult::warnings).
  std::string gain_model;
  /// Non-myopic choice (0, the default: greedy). With N > 0 and views left after this one, each
  /// of the `lookahead_top` best candidates by utility gets a bonus: the value of the N views
  /// that would best follow it (at most as many as the budget has left), each chosen greedily
  /// among the same candidates with its gain discounted by the share of it the views before it
  /// would already reveal (the voxels each view's coarse rays reach, weighted as in the gain),
  /// times `lookahead_discount`, in the units of G / max G. The plan goes to the first view of
  /// the best sequence under that budget rather than to the best single view.
  int lookahead_views = 0;
  int lookahead_top = 16;
  double lookahead_discount = 0.5;
  Status Validate() const;
};

/// The fields of AvpNbvOptions by name (docs/planning.md): every scalar field ("p_unknown",
/// "w_diversity", "ray_stride_px", ...), the candidate shells' as "candidates.<field>"
/// (ShellCandidateOptionTable) and the gain grid's as "grid.<field>" (GainGridOptionTable).
/// Candidates are scored on avp::Threads() threads (core/parallel.h).
const OptionTable<AvpNbvOptions>& AvpNbvOptionTable();

/// avp-nbv's registry entry (RegisterBuiltinPlanners).
PlannerEntry AvpNbvPlannerEntry();

/// The occlusion probability of one voxel of edge `voxel_size_m` for a probability `p` given per
/// voxel of edge `reference_m`: 1 − (1 − p)^(voxel_size_m / reference_m), the same transmittance
/// per metre; `p` itself when reference_m is 0 or equals voxel_size_m.
double OcclusionPerVoxel(double p, double voxel_size_m, double reference_m);

/// The gain of one ray under `options` (see AvpNbvOptions), walked on `grid`.
double AvpRayGain(const GainGrid& grid, const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                  const AvpNbvOptions& options);
/// The same gain computed the slow way, voxel by voxel from the map (mapping::TraverseRay and
/// ReadGainVoxel): the reference the fast evaluator is tested against.
double AvpRayGainReference(const mapping::SemanticMap& map, const Eigen::Vector3d& from,
                           const Eigen::Vector3d& to, SemanticClass target, const Box3& roi,
                           const AvpNbvOptions& options);
/// Σ AvpRayGain over the rays of a camera at X_WC (RayDirections(K, ray_stride_px), each
/// max_range_m long).
double AvpViewGain(const GainGrid& grid, const RigidTransform& X_WC, const CameraIntrinsics& K,
                   const AvpNbvOptions& options);

/// avp-nbv's gain by part (AvpGainTerm order, summing to the gain) of rays on one grid, for a
/// caller that wants statistics of the same walk: the per-step tables are built once, then
/// WalkRay() is called per ray (from any thread). The learned gain's features include these parts
/// and walk each ray once for both (view_features.h).
class AvpGainEvaluator {
 public:
  /// Called with every voxel a ray walks, in order; returns false to end the walk.
  using Visitor = std::function<bool(const VoxelKey&, const GainVoxel&)>;

  /// `grid` must outlive the evaluator. @throws avp::Error if options.Validate() fails.
  AvpGainEvaluator(const GainGrid& grid, const AvpNbvOptions& options);
  ~AvpGainEvaluator();
  AvpGainEvaluator(AvpGainEvaluator&&) noexcept;
  /// Walks the ray from `eye` to `to` once, clipped to the ROI as the gain is (no voxel when it
  /// misses the ROI's box): adds its gain by part to `terms` (exactly AvpRayGain's parts) and
  /// hands each voxel to `visit`, until `visit` returns false or the clipped end. A walk that
  /// goes on after the gain's ray has ended (an occluded ray) adds nothing more to `terms`.
  void WalkRay(const Eigen::Vector3d& eye, const Eigen::Vector3d& to,
               std::array<double, kGainTermCount>& terms, const Visitor& visit) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

class AvpNbvPlanner final : public ViewPlanner {
 public:
  /// @throws avp::Error if options.Validate() fails, or if options.gain_model names a model that
  /// does not load (the registry's factory returns that error as a status instead).
  explicit AvpNbvPlanner(const AvpNbvOptions& options = {},
                         std::shared_ptr<const LearnedGainModel> model = nullptr);
  std::string_view name() const override { return "avp-nbv"; }
  PlanResult Plan(const PlanningRequest& request, Rng& rng) override;
  const AvpNbvOptions& options() const { return options_; }

 private:
  AvpNbvOptions options_;
  std::shared_ptr<const LearnedGainModel> model_;  ///< options_.gain_model, loaded
  /// The best gain of this episode's first plan (min_gain_fraction); NaN before it.
  double first_max_gain_ = std::numeric_limits<double>::quiet_NaN();
};

}  // namespace avp::planning

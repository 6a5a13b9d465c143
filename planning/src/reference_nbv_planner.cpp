// The reference system's NBV planner (AIRLab-POLIMI/active-vision, av_planning's
// nbv_planning_pipeline.cpp; reference-system.md §4.8) reproduced, with its documented bugs fixed
// (reference-system.md §6, items 9-17 where they concern this planner). Each reproduced
// behaviour is marked "Reference:" and each fix "Fix:" below; docs/planning.md summarises them.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include <avp/core/entropy.h>
#include <avp/core/error.h>
#include <avp/core/parallel.h>
#include <avp/planning/isler_utilities.h>
#include <avp/planning/reference_nbv_planner.h>

namespace avp::planning {

namespace {

Eigen::Matrix3d AxisRotation(const Eigen::Vector3d& axis, double angle_rad) {
  return Eigen::AngleAxisd(angle_rad, axis.normalized()).toRotationMatrix();
}

}  // namespace

const OptionTable<ReferenceNbvOptions>& ReferenceNbvOptionTable() {
  static const auto* table = [] {
    using O = ReferenceNbvOptions;
    auto* t = new OptionTable<O>("reference-nbv option");
    const ValueRange non_negative = ValueRange::AtLeast(0);
    const ValueRange ratio = ValueRange::AtLeast(1);
    t->Integer("grid_size", &O::grid_size, "", ValueRange::Closed(1, 64),
               "positions per axis of the square_random layout");
    t->Real("grid_spacing_m", &O::grid_spacing_m, "m", non_negative, "spacing of the positions");
    t->Real("jitter_m", &O::jitter_m, "m", non_negative, "half-range of the uniform jitter");
    t->Real("tilt_deg", &O::tilt_deg, "deg", ValueRange::HalfOpen(0, 90),
            "tilt of the 4 extra orientations");
    t->Real("max_range_m", &O::max_range_m, "m", ValueRange::LeftOpen(0, 10), "ray length");
    t->Real("depth_ratio", &O::depth_ratio, "", ratio, "full_attention ROI: depth shrink");
    t->Real("width_ratio", &O::width_ratio, "", ratio, "full_attention ROI: width shrink");
    t->Real("height_ratio", &O::height_ratio, "", ratio, "full_attention ROI: height shrink");
    t->Real("confidence_epsilon", &O::confidence_epsilon, "", ValueRange::Open(0, 0.5),
            "confidences are clamped to [eps, 1 - eps] before the entropy");
    t->Real("fused_position_tol_m", &O::fused_position_tol_m, "m", non_negative,
            "candidates this close to a fused view are dropped");
    t->Real("fused_angle_tol_rad", &O::fused_angle_tol_rad, "rad", non_negative,
            "... and this close in angle");
    return t;
  }();
  return *table;
}

Status ReferenceNbvOptions::Validate() const { return ReferenceNbvOptionTable().Validate(*this); }

PlannerEntry ReferenceNbvPlannerEntry() {
  return MakePlannerEntry<ReferenceNbvOptions>(
      "reference-nbv", "the paper's planner with its bugs fixed (docs/planning.md)",
      ReferenceNbvOptionTable(), ReferenceNbvOptions{},
      [](ReferenceNbvOptions o, const PlannerContext&) {
        return Result<std::unique_ptr<ViewPlanner>>(std::make_unique<ReferenceNbvPlanner>(o));
      });
}

std::vector<ViewCandidate> ReferenceCandidatePoses(const RigidTransform& X_WC_start,
                                                   const ReferenceNbvOptions& options, Rng& rng) {
  const Status valid = options.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
  const Eigen::Matrix3d& R = X_WC_start.rotation();
  const Eigen::Vector3d& p0 = X_WC_start.translation();
  // The reference end-effector frame in camera axes: local x = view direction = +z_C, local y =
  // -x_C, local z = -y_C (the flange frame for the default mount).
  const Eigen::Vector3d local_y_C(-1.0, 0.0, 0.0);
  const Eigen::Vector3d local_z_C(0.0, -1.0, 0.0);
  const Eigen::Vector3d local_y_W = R * local_y_C;
  const Eigen::Vector3d local_z_W = R * local_z_C;
  const double tilt = DegToRad(options.tilt_deg);
  // Straight, +-tilt about local Y, +-tilt about local Z (rotations in the camera's own frame).
  const Eigen::Matrix3d orientations[5] = {
      R,
      R * AxisRotation(local_y_C, tilt),
      R * AxisRotation(local_y_C, -tilt),
      R * AxisRotation(local_z_C, tilt),
      R * AxisRotation(local_z_C, -tilt),
  };
  const int n = options.grid_size;
  std::vector<ViewCandidate> out;
  out.reserve(static_cast<size_t>(5 * n * n));
  for (int iz = 0; iz < n; ++iz) {
    for (int iy = 0; iy < n; ++iy) {
      // Reference: positions on a square in base y and z around the start pose, x fixed.
      const double dy = (iy - 0.5 * (n - 1)) * options.grid_spacing_m;
      const double dz = (iz - 0.5 * (n - 1)) * options.grid_spacing_m;
      // Reference: jitter along the pose's local y and z. Fix: from the passed, seeded rng (the
      // reference seeded from the clock).
      const double jy = rng.Uniform(-options.jitter_m, options.jitter_m);
      const double jz = rng.Uniform(-options.jitter_m, options.jitter_m);
      const Eigen::Vector3d p = p0 + Eigen::Vector3d(0.0, dy, dz) + jy * local_y_W + jz * local_z_W;
      for (const Eigen::Matrix3d& Ri : orientations) {
        ViewCandidate c;
        c.X_WC = RigidTransform(Ri, p);
        c.source = "grid";
        out.push_back(std::move(c));
      }
    }
  }
  return out;
}

bool FullAttentionRoi::Contains(const Eigen::Vector3d& p_W) const {
  return box_S.Contains(X_WS.inverse() * p_W);
}

FullAttentionRoi ComputeFullAttentionRoi(const mapping::SemanticMap& map,
                                         const RigidTransform& X_WS,
                                         const ReferenceNbvOptions& options) {
  FullAttentionRoi roi;
  roi.X_WS = X_WS;
  const RigidTransform X_SW = X_WS.inverse();
  const mapping::OccupancyGrid& grid = map.grid();
  const float occupied = grid.occupied_log_odds();
  const double s = grid.voxel_size_m();
  Box3 extent;
  // Reference: the extremes of every occupied voxel (all classes), in the start pose's frame.
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    if (log_odds >= occupied) extent.Extend(X_SW * k.Center(s));
  });
  if (extent.IsEmpty()) return roi;
  // Reference: each extent shrunk to its central 1/ratio (depth z_S, width x_S, height y_S).
  const Eigen::Vector3d ratio(options.width_ratio, options.height_ratio, options.depth_ratio);
  const Eigen::Vector3d c = extent.center();
  const Eigen::Vector3d half = (0.5 * extent.size()).cwiseQuotient(ratio);
  // Fix: the box stays in frame S and Contains() tests points in frame S (the reference compared
  // these bounds with base-frame coordinates).
  roi.box_S = Box3(c - half, c + half);
  return roi;
}

std::vector<ReferenceTarget> ReferenceTargets(const mapping::SemanticMap& map, SemanticClass target,
                                              const FullAttentionRoi& roi) {
  std::vector<ReferenceTarget> out;
  if (roi.box_S.IsEmpty()) return out;
  const double s = map.voxel_size_m();
  const RigidTransform X_SW = roi.X_WS.inverse();
  // Fix: the labelled voxels are collected once per planning step, not scanned per candidate.
  map.grid().ForEachSemanticVoxel([&](const VoxelKey& k, const mapping::SemanticCell& c) {
    if (c.cls() != target) return;
    const Eigen::Vector3d p_W = k.Center(s);
    if (roi.box_S.Contains(X_SW * p_W)) out.push_back({p_W});
  });
  return out;
}

ReferenceViewEvaluation EvaluateReferenceView(const GainGrid& grid, const mapping::SemanticMap& map,
                                              const std::vector<ReferenceTarget>& targets,
                                              const RigidTransform& X_WC, const CameraIntrinsics& K,
                                              const ReferenceNbvOptions& options) {
  ReferenceViewEvaluation e;
  const RigidTransform X_CW = X_WC.inverse();
  // Fix: rays start at the optical centre (the reference used the end-effector link).
  const Eigen::Vector3d origin = X_WC.translation();
  const SemanticClass target = grid.target();
  const double eps = options.confidence_epsilon;
  for (const ReferenceTarget& t : targets) {
    // Fix: the true field of view of K (the reference's Gazebo FOV halved the tangent).
    const std::optional<Eigen::Vector2d> uv = K.Project(X_CW * t.p_W);
    if (!uv || !K.IsInImage(*uv)) continue;
    const Eigen::Vector3d d = t.p_W - origin;
    const double len = d.norm();
    if (!(len > 0.0)) continue;
    ++e.rays;
    // Reference: castRay(ignoreUnknown = true, maxRange = 2 m): the first occupied voxel ends the
    // ray; free and unknown voxels are passed.
    const Eigen::Vector3d to = origin + d * (options.max_range_m / len);
    bool hit_target = false;
    VoxelKey hit_key;
    grid.Walk(origin, to, [&](const VoxelKey& k, const GainVoxel& v) {
      if (v.state != mapping::VoxelState::kOccupied) return true;
      if (v.cls == target) {
        hit_target = true;
        hit_key = k;
      }
      return false;
    });
    if (!hit_target) continue;
    const mapping::SemanticCell* cell = map.Semantic(hit_key);
    const double c = cell != nullptr ? static_cast<double>(cell->confidence) : 0.0;
    // Reference: U += H_b(c) of the hit target voxel. Fix: c clamped into [eps, 1 - eps], so a
    // confidence of exactly 0 or 1 gives a finite entropy (the reference's was NaN).
    e.utility += BinaryEntropyBits(std::clamp(c, eps, 1.0 - eps));
    ++e.target_hits;
  }
  return e;
}

ReferenceNbvPlanner::ReferenceNbvPlanner(const ReferenceNbvOptions& options) : options_(options) {
  const Status valid = options_.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
}

PlanResult ReferenceNbvPlanner::Plan(const PlanningRequest& request, Rng& rng) {
  PlanResult result;
  if (const Status s = ValidateRequest(request); !s.ok()) {
    result.status = s.WithContext(name());
    return result;
  }
  const robot::ArmModel& arm = *request.arm;
  const mapping::SemanticMap& map = *request.map;

  // Reference: candidates around the start pose every step (never the current pose).
  std::vector<ViewCandidate> generated = ReferenceCandidatePoses(request.X_WC_start, options_, rng);
  result.generated = generated.size();

  // Fix: never re-choose a fused view, nor stay where the camera is.
  std::vector<RigidTransform> avoid = request.fused_views;
  avoid.push_back(request.X_WC_current);
  std::vector<ViewCandidate> kept;
  kept.reserve(generated.size());
  size_t near_fused = 0;
  for (ViewCandidate& c : generated) {
    if (IsNearAny(c.X_WC, avoid, options_.fused_position_tol_m, options_.fused_angle_tol_rad)) {
      ++near_fused;
      continue;
    }
    kept.push_back(std::move(c));
  }
  // Reference: IK is the only filter (seeded from the current joints, in generation order).
  size_t reachable = 0;
  for (ViewCandidate& c : kept) {
    const robot::IkResult ik = arm.SolveCameraIk(c.X_WC, request.q_current, rng);
    c.q = ik.q;
    c.reachable = ik.ok() && arm.WithinLimits(ik.q);
    if (c.reachable) c.cost = (ik.q - request.q_current).norm();
  }
  // Extension: with a collision checker, joints in collision are dropped too.
  const size_t in_collision = DropCollidingCandidates(request, kept);
  for (const ViewCandidate& c : kept) reachable += c.reachable ? 1 : 0;

  GainGridOptions grid_options = options_.grid;
  auto grid = GainGrid::Build(map, request.target_class, request.roi, grid_options);
  if (!grid.ok()) {
    result.status = grid.status().WithContext(name());
    return result;
  }
  const FullAttentionRoi roi = ComputeFullAttentionRoi(map, request.X_WC_start, options_);
  const std::vector<ReferenceTarget> targets = ReferenceTargets(map, request.target_class, roi);
  ParallelFor(kept.size(), [&](size_t i) {
    ViewCandidate& c = kept[i];
    if (!c.reachable) return;
    const ReferenceViewEvaluation e =
        EvaluateReferenceView(*grid, map, targets, c.X_WC, request.K, options_);
    c.gain = e.utility;
    c.utility = e.utility;
  });

  const bool any_positive = std::any_of(kept.begin(), kept.end(), [](const ViewCandidate& c) {
    return c.reachable && c.utility > 0.0;
  });
  if (any_positive || reachable == 0) {
    // Reference: arg-max of U. Extension: every reachable candidate is ranked (U <= 0 after the
    // positive ones), so the loop can fall back when a move fails.
    const size_t kept_count = kept.size();
    result = RankCandidates(std::move(kept), generated.size(), name());
    if (!result.status.ok()) {
      result.status = NotFoundError(fmt::format(
          "reference-nbv: no valid candidate: {} generated around the start pose, {} dropped "
          "near a fused view or the current pose, 0 of {} reachable ({} in collision)",
          generated.size(), near_fused, kept_count, in_collision));
      result.in_collision = in_collision;
    }
    return result;
  }
  // Fix: nothing scores above 0 (no target voxel visible from any candidate): rank the reachable
  // candidates in a seeded random order (the reference stayed at the current pose when semantics
  // had been seen, and picked one random candidate otherwise).
  std::vector<ViewCandidate> order;
  for (ViewCandidate& c : kept) {
    if (c.reachable) order.push_back(std::move(c));
  }
  for (size_t i = order.size(); i > 1; --i) {
    const auto j = static_cast<size_t>(rng.UniformInt(0, static_cast<int64_t>(i) - 1));
    std::swap(order[i - 1], order[j]);
  }
  for (ViewCandidate& c : order) c.source = "grid-random";
  result.generated = generated.size();
  result.reachable = order.size();
  result.in_collision = in_collision;
  result.ranked = std::move(order);
  return result;
}

}  // namespace avp::planning

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/core/parallel.h>
#include <avp/planning/avp_nbv_planner.h>
#include <avp/planning/view_features.h>

namespace avp::planning {

namespace {

// The feature row, in order. Plan: the same for every candidate of a step. Geometry: the view
// against the ROI, the start and the fused views. avp: avp-nbv's gain by part with its default
// options, per ray. Rays: statistics of the rays walked through the map up to their first
// occupied voxel or their exit from the ROI (a ray that misses the ROI is not walked), per ray
// (metres are voxel counts times the edge).
// Fruit: the spheres fitted to the target instances seen so far.
enum Feature : int {
  kPlanProgress,      // view_index / views_total
  kRoiKnownFraction,  // known voxels of the ROI / its voxels (sampled)
  kRoiOccupiedLog,    // log(1 + occupied voxels of the ROI) (sampled, scaled to all)
  kRoiTargetLog,      // log(1 + target-class voxels of the ROI) (sampled, scaled to all)
  kTargetInstances,   // target instances with a fitted sphere
  kPlanFeatureCount,
  kEyeRoiDistance = kPlanFeatureCount,  // |eye - ROI centre| / ROI half diagonal
  kEyeRoiHeight,                        // (eye z - ROI bottom) / ROI height
  kEyeCoreDistance,                     // PlantCoreDistance(eye) / ROI half diagonal
  kAxisRoiCos,                          // cos(optical axis, ROI centre - eye)
  kAxisUp,                              // optical axis' z component
  kSideStartCos,        // cos of the horizontal angle at the ROI centre, eye vs start eye
  kFusedEyeDistance,    // nearest fused eye, m
  kFusedAxisCos,        // largest cos(optical axis, a fused view's axis)
  kCurrentEyeDistance,  // |eye - current eye|, m
  kMotionCost,          // |q - q_current|, rad
  kSourceFruit,         // one-hot candidate source
  kSourceFrontier,
  kSourceRoi,
  kAvpTargetEntropy,  // avp-nbv's gain parts per ray (AvpGainTerm order)
  kAvpPredictedTarget,
  kAvpUnknownNearTarget,
  kAvpUnknownRoi,
  kAvpGainRelative,        // avp-nbv's gain / the step's largest
  kRayHitTarget,           // rays ending on a target-class voxel (fraction)
  kRayHitOther,            // rays ending on another occupied voxel
  kRayInRoi,               // rays that enter the ROI
  kRayUnknownM,            // unknown ROI metres per ray
  kRayUnknownBeforeHitM,   // the same, over the rays that end on an occupied voxel
  kRayFreeM,               // free ROI metres per ray
  kRayFirstUnknownM,       // distance to the first unknown ROI voxel (max range if none)
  kRayEndM,                // distance to the end (hit, ROI exit or max range)
  kRayUnknownNearPlantM,   // unknown ROI metres within near_plant_m of an occupied voxel
  kRayUnknownNearTargetM,  // unknown ROI metres near a target voxel (the grid's radius)
  kRayPredictedTargetM,    // unknown metres on a fitted sphere's surface
  kRayUnknownCoreM,        // unknown ROI metres within core_band_m of the plant's core
  kRayUnseenShare,         // unknown / all ROI metres of the rays
  kRayUnknownRelative,     // kRayUnknownM / the step's largest
  kRayNearPlantRelative,   // kRayUnknownNearPlantM / the step's largest
  kFruitNearestM,          // nearest fitted sphere centre, m (2 without spheres)
  kFruitInView,            // sphere centres inside the view's frustum
  kFruitNewSide,           // (1 - cos) / 2 of the newest angle onto a sphere in view
  // Step-relative: each column over the largest of the step's reachable candidates (scale-free:
  // a large plant or a wall gives every view more of everything).
  kRelTargetEntropy,
  kRelPredictedTarget,
  kRelUnknownNearTarget,
  kRelUnknownRoi,
  kRelHitTarget,
  kRelFree,
  kRelUnknownNearTargetM,
  kRelPredictedTargetM,
  kRelUnknownCore,
  kFeatureCount
};

/// The step-relative columns and the column each is relative to.
constexpr auto kRelative = std::to_array<std::pair<Feature, Feature>>({
    {kAvpGainRelative, kAvpGainRelative},
    {kRayUnknownRelative, kRayUnknownM},
    {kRayNearPlantRelative, kRayUnknownNearPlantM},
    {kRelTargetEntropy, kAvpTargetEntropy},
    {kRelPredictedTarget, kAvpPredictedTarget},
    {kRelUnknownNearTarget, kAvpUnknownNearTarget},
    {kRelUnknownRoi, kAvpUnknownRoi},
    {kRelHitTarget, kRayHitTarget},
    {kRelFree, kRayFreeM},
    {kRelUnknownNearTargetM, kRayUnknownNearTargetM},
    {kRelPredictedTargetM, kRayPredictedTargetM},
    {kRelUnknownCore, kRayUnknownCoreM},
});

constexpr std::array<std::string_view, kFeatureCount> kNames = {
    "plan_progress",
    "roi_known_fraction",
    "roi_occupied_log",
    "roi_target_log",
    "target_instances",
    "eye_roi_distance",
    "eye_roi_height",
    "eye_core_distance",
    "axis_roi_cos",
    "axis_up",
    "side_start_cos",
    "fused_eye_distance",
    "fused_axis_cos",
    "current_eye_distance",
    "motion_cost",
    "source_fruit",
    "source_frontier",
    "source_roi",
    "avp_target_entropy",
    "avp_predicted_target",
    "avp_unknown_near_target",
    "avp_unknown_roi",
    "avp_gain_relative",
    "ray_hit_target",
    "ray_hit_other",
    "ray_in_roi",
    "ray_unknown_m",
    "ray_unknown_before_hit_m",
    "ray_free_m",
    "ray_first_unknown_m",
    "ray_end_m",
    "ray_unknown_near_plant_m",
    "ray_unknown_near_target_m",
    "ray_predicted_target_m",
    "ray_unknown_core_m",
    "ray_unseen_share",
    "ray_unknown_relative",
    "ray_near_plant_relative",
    "fruit_nearest_m",
    "fruit_in_view",
    "fruit_new_side",
    "rel_avp_target_entropy",
    "rel_avp_predicted_target",
    "rel_avp_unknown_near_target",
    "rel_avp_unknown_roi",
    "rel_ray_hit_target",
    "rel_ray_free_m",
    "rel_ray_unknown_near_target_m",
    "rel_ray_predicted_target_m",
    "rel_ray_unknown_core_m",
};

/// What one ray saw, summed over a view's rays.
struct RaySums {
  double hit_target = 0, hit_other = 0, in_roi = 0;
  double unknown = 0, unknown_before_hit = 0, hits = 0, free = 0, roi = 0;
  double first_unknown_m = 0, end_m = 0;
  double near_plant = 0, near_target = 0, predicted = 0, core = 0;
};

/// The plan-level counts over the ROI, sampled on a lattice of at most ~2^20 voxels.
std::array<double, 3> CountRoi(const GainGrid& grid) {
  const Box3& roi = grid.roi();
  const double s = grid.voxel_size_m();
  const VoxelKey lo = VoxelKey::FromPoint(roi.min(), s);
  const VoxelKey hi = VoxelKey::FromPoint(roi.max(), s);
  const double n = static_cast<double>(int64_t{hi.x} - lo.x + 1) *
                   static_cast<double>(int64_t{hi.y} - lo.y + 1) *
                   static_cast<double>(int64_t{hi.z} - lo.z + 1);
  const int step = std::max(1, static_cast<int>(std::ceil(std::cbrt(n / double(1 << 20)))));
  double samples = 0, known = 0, occupied = 0, target = 0;
  for (int64_t z = lo.z; z <= hi.z; z += step) {
    for (int64_t y = lo.y; y <= hi.y; y += step) {
      for (int64_t x = lo.x; x <= hi.x; x += step) {
        const GainVoxel v =
            grid.At({static_cast<int32_t>(x), static_cast<int32_t>(y), static_cast<int32_t>(z)});
        ++samples;
        if (v.state == mapping::VoxelState::kUnknown) continue;
        ++known;
        if (v.state == mapping::VoxelState::kOccupied) {
          ++occupied;
          if (v.cls == grid.target()) ++target;
        }
      }
    }
  }
  const double scale = samples > 0 ? n / samples : 0.0;
  return {samples > 0 ? known / samples : 0.0, std::log1p(occupied * scale),
          std::log1p(target * scale)};
}

double HorizontalCos(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const Eigen::Vector2d u = a.head<2>(), v = b.head<2>();
  const double n = u.norm() * v.norm();
  return n > 1e-9 ? u.dot(v) / n : 1.0;
}

}  // namespace

std::span<const std::string_view> ViewFeatureNames() { return kNames; }

size_t ViewFeatureCount() { return kNames.size(); }

std::string ViewFeatureHash() {
  uint64_t h = 14695981039346656037ull;
  const auto add = [&](std::string_view text) {
    for (const char c : text) {
      h ^= static_cast<unsigned char>(c);
      h *= 1099511628211ull;
    }
    h ^= static_cast<unsigned char>('\n');
    h *= 1099511628211ull;
  };
  add(fmt::format("avp-view-features/{}", kViewFeatureVersion));
  for (const std::string_view name : kNames) add(name);
  return fmt::format("{:016x}", h);
}

Result<ViewFeatureExtractor> ViewFeatureExtractor::Build(const PlanningRequest& request,
                                                         const GainGrid& grid,
                                                         const ViewFeatureSampling& sampling) {
  ViewFeatureExtractor x;
  x.request_ = &request;
  x.grid_ = &grid;
  x.sampling_ = sampling;
  AVP_ASSIGN_OR_RETURN(x.proximity_, ProximityField::Build(*request.map, sampling.near_plant_m,
                                                           size_t{1} << 30, grid.roi()));
  x.spheres_ = FitTargetSpheres(*request.map, request.target_class);
  x.dirs_C_ = RayDirections(request.K, sampling.ray_stride_px);
  // avp-nbv's gain with its default options, whatever the planner's (a feature is one thing).
  x.gain_ = std::make_shared<const AvpGainEvaluator>(grid, AvpNbvOptions{});
  x.plan_.assign(kPlanFeatureCount, 0.0f);
  x.plan_[kPlanProgress] =
      static_cast<float>(request.view_index) / static_cast<float>(std::max(1, request.views_total));
  const std::array<double, 3> roi = CountRoi(grid);
  x.plan_[kRoiKnownFraction] = static_cast<float>(roi[0]);
  x.plan_[kRoiOccupiedLog] = static_cast<float>(roi[1]);
  x.plan_[kRoiTargetLog] = static_cast<float>(roi[2]);
  x.plan_[kTargetInstances] = static_cast<float>(x.spheres_.size());
  return x;
}

namespace {

/// The statistics of one ray, voxel by voxel as AvpGainEvaluator::WalkRay hands them over: up to
/// its first occupied voxel or its exit from the ROI.
class RayStatistics {
 public:
  RayStatistics(const GainGrid& grid, const ProximityField& proximity,
                const ViewFeatureSampling& sampling, const Eigen::Vector3d& eye)
      : grid_(grid), proximity_(proximity), sampling_(sampling), eye_(eye) {}

  /// Starts the next ray.
  void Begin() {
    entered_ = hit_ = false;
    unknown_ = free_ = near_plant_ = near_target_ = predicted_ = core_ = 0.0;
    first_unknown_ = end_ = sampling_.max_range_m;
  }

  /// One voxel; false where the ray ends for the statistics.
  bool Visit(const VoxelKey& k, const GainVoxel& v) {
    const double s = grid_.voxel_size_m();
    if (!v.in_roi && entered_) {  // the exit from the ROI
      end_ = (k.Center(s) - eye_).norm();
      return false;
    }
    entered_ = entered_ || v.in_roi;
    switch (v.state) {
      case mapping::VoxelState::kOccupied:
        end_ = (k.Center(s) - eye_).norm();
        hit_ = true;
        (v.cls == grid_.target() ? sums_.hit_target : sums_.hit_other) += 1.0;
        return false;
      case mapping::VoxelState::kFree:
        if (v.in_roi) free_ += s;
        return true;
      case mapping::VoxelState::kUnknown: {
        if (!v.in_roi) return true;
        const Eigen::Vector3d c = k.Center(s);
        if (unknown_ == 0.0) first_unknown_ = (c - eye_).norm();
        unknown_ += s;
        if (proximity_.DistanceToOccupied(k).has_value()) near_plant_ += s;
        if (v.near_target) near_target_ += s;
        if (v.predicted_target) predicted_ += s;
        if (PlantCoreDistance(c, grid_.roi()) <= sampling_.core_band_m) core_ += s;
        return true;
      }
    }
    return true;
  }

  /// Ends the ray: adds it to the sums.
  void End() {
    sums_.in_roi += entered_ ? 1.0 : 0.0;
    sums_.unknown += unknown_;
    if (hit_) {
      sums_.hits += 1.0;
      sums_.unknown_before_hit += unknown_;
    }
    sums_.free += free_;
    sums_.roi += unknown_ + free_;
    sums_.first_unknown_m += first_unknown_;
    sums_.end_m += end_;
    sums_.near_plant += near_plant_;
    sums_.near_target += near_target_;
    sums_.predicted += predicted_;
    sums_.core += core_;
  }

  const RaySums& sums() const { return sums_; }

 private:
  const GainGrid& grid_;
  const ProximityField& proximity_;
  const ViewFeatureSampling& sampling_;
  const Eigen::Vector3d eye_;
  RaySums sums_;
  bool entered_ = false, hit_ = false;
  double unknown_ = 0, free_ = 0, near_plant_ = 0, near_target_ = 0, predicted_ = 0, core_ = 0;
  double first_unknown_ = 0, end_ = 0;
};

}  // namespace

void ViewFeatureExtractor::ComputeRow(const ViewCandidate& c, std::span<float> row) const {
  const PlanningRequest& request = *request_;
  const Box3& roi = grid_->roi();
  const Eigen::Vector3d eye = c.X_WC.translation();
  const Eigen::Vector3d axis = c.X_WC.rotation().col(2);
  const Eigen::Vector3d centre = roi.center();
  const double half_diagonal = std::max(1e-3, 0.5 * roi.size().norm());
  std::copy(plan_.begin(), plan_.end(), row.begin());
  const auto set = [&](Feature f, double value) {
    row[f] = std::isfinite(value) ? static_cast<float>(value) : 0.0f;
  };
  // Geometry.
  set(kEyeRoiDistance, (eye - centre).norm() / half_diagonal);
  set(kEyeRoiHeight, roi.size().z() > 0 ? (eye.z() - roi.min().z()) / roi.size().z() : 0.0);
  set(kEyeCoreDistance, PlantCoreDistance(eye, roi) / half_diagonal);
  set(kAxisRoiCos, axis.dot((centre - eye).normalized()));
  set(kAxisUp, axis.z());
  set(kSideStartCos, HorizontalCos(eye - centre, request.X_WC_start.translation() - centre));
  double fused_d = sampling_.max_range_m * 2.0, fused_cos = -1.0;
  for (const RigidTransform& f : request.fused_views) {
    fused_d = std::min(fused_d, (f.translation() - eye).norm());
    fused_cos = std::max(fused_cos, axis.dot(f.rotation().col(2)));
  }
  set(kFusedEyeDistance, fused_d);
  set(kFusedAxisCos, fused_cos);
  set(kCurrentEyeDistance, (request.X_WC_current.translation() - eye).norm());
  set(kMotionCost, c.cost);
  set(kSourceFruit, c.source == "fruit-shell" ? 1.0 : 0.0);
  set(kSourceFrontier, c.source == "frontier" ? 1.0 : 0.0);
  set(kSourceRoi, c.source == "roi" ? 1.0 : 0.0);
  // avp-nbv's parts (per ray) and the ray statistics, from one walk of each ray.
  const double rays = static_cast<double>(std::max<size_t>(1, dirs_C_.size()));
  std::array<double, kGainTermCount> terms{};
  RayStatistics statistics(*grid_, proximity_, sampling_, eye);
  const AvpGainEvaluator::Visitor visit = [&statistics](const VoxelKey& k, const GainVoxel& v) {
    return statistics.Visit(k, v);
  };
  for (const Eigen::Vector3d& d_C : dirs_C_) {
    statistics.Begin();
    gain_->WalkRay(eye, c.X_WC * (sampling_.max_range_m * d_C), terms, visit);
    statistics.End();
  }
  double total = 0;
  for (int t = 0; t < kGainTermCount; ++t) {
    set(static_cast<Feature>(kAvpTargetEntropy + t), terms[t] / rays);
    total += terms[t];
  }
  set(kAvpGainRelative, total / rays);  // made relative in Compute
  const RaySums& sums = statistics.sums();
  set(kRayHitTarget, sums.hit_target / rays);
  set(kRayHitOther, sums.hit_other / rays);
  set(kRayInRoi, sums.in_roi / rays);
  set(kRayUnknownM, sums.unknown / rays);
  set(kRayUnknownBeforeHitM, sums.hits > 0 ? sums.unknown_before_hit / sums.hits : 0.0);
  set(kRayFreeM, sums.free / rays);
  set(kRayFirstUnknownM, sums.first_unknown_m / rays);
  set(kRayEndM, sums.end_m / rays);
  set(kRayUnknownNearPlantM, sums.near_plant / rays);
  set(kRayUnknownNearTargetM, sums.near_target / rays);
  set(kRayPredictedTargetM, sums.predicted / rays);
  set(kRayUnknownCoreM, sums.core / rays);
  set(kRayUnseenShare, sums.roi > 0 ? sums.unknown / sums.roi : 0.0);
  set(kRayUnknownRelative, sums.unknown / rays);       // made relative in Compute
  set(kRayNearPlantRelative, sums.near_plant / rays);  // made relative in Compute
  // Fruit seen so far.
  double nearest = 2.0, newest = 0.0;
  int in_view = 0;
  const RigidTransform X_CW = c.X_WC.inverse();
  for (const TargetSphere& sphere : spheres_) {
    nearest = std::min(nearest, (sphere.center_W - eye).norm());
    const Eigen::Vector3d p_C = X_CW * sphere.center_W;
    if (p_C.z() <= 0.05 || p_C.z() > sampling_.max_range_m) continue;
    const std::optional<Eigen::Vector2d> uv = request.K.Project(p_C);
    if (!uv || !request.K.IsInImage(*uv)) continue;
    ++in_view;
    const Eigen::Vector3d to_eye = (eye - sphere.center_W).normalized();
    double seen_cos = -1.0;
    for (const RigidTransform& f : request.fused_views) {
      seen_cos = std::max(seen_cos, to_eye.dot((f.translation() - sphere.center_W).normalized()));
    }
    newest = std::max(newest, 0.5 * (1.0 - seen_cos));
  }
  set(kFruitNearestM, nearest);
  set(kFruitInView, in_view);
  set(kFruitNewSide, newest);
}

std::vector<float> ViewFeatureExtractor::Compute(std::span<const ViewCandidate> candidates) const {
  const size_t n = candidates.size(), f = kFeatureCount;
  std::vector<float> rows(n * f, 0.0f);
  ParallelFor(n, [&](size_t i) { ComputeRow(candidates[i], std::span(rows).subspan(i * f, f)); });
  // The step-relative columns: each over the largest of the step's reachable candidates.
  for (const auto& [column, source] : kRelative) {
    float largest = 0.0f;
    for (size_t i = 0; i < n; ++i) {
      if (candidates[i].reachable) largest = std::max(largest, rows[i * f + source]);
    }
    for (size_t i = 0; i < n; ++i) {
      rows[i * f + column] = largest > 0.0f ? rows[i * f + source] / largest : 0.0f;
    }
  }
  return rows;
}

}  // namespace avp::planning

// The volumetric information gain utilities of Isler et al. (ICRA 2016) as ray evaluators over
// the gain grid, their slow reference evaluators, and the IslerPlanner. The visibility is the
// paper's exclusive product p_vis = Π_{j<i} (1 - p_j), not the update p_vis *= p_occ of
// rpg_ig_active_reconstruction (nbv-literature.md §0). See docs/planning.md, "Isler utilities".
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/core/parallel.h>
#include <avp/mapping/ray_traversal.h>
#include <avp/planning/isler_utilities.h>

namespace avp::planning {

namespace {

constexpr uint16_t kFar = 0xffff;
constexpr double kMaxProximityDistance = 0.2;

int32_t IntegerSqrt(int64_t t) {
  auto r = static_cast<int64_t>(std::sqrt(static_cast<double>(t)));
  while (r * r > t) --r;
  while ((r + 1) * (r + 1) <= t) ++r;
  return static_cast<int32_t>(r);
}

/// The per-ray state machine shared (as source, not as code path) by the fast and the slow
/// evaluators: Step() takes the next voxel and returns false when the ray ends there.
template <IslerUtility U>
struct RayAccumulator {
  double p_vis = 1.0;
  double sum = 0.0;
  double run = 0.0;  // RSE: p_vis H_b over the current run of unknown voxels
  int64_t voxels = 0;
  bool previous_unknown = false;
  bool hit = false;

  /// `d_occ` (PC only): distance to the nearest occupied voxel, < 0 when beyond d_max.
  bool Step(const GainVoxel& v, double d_occ, double d_max) {
    const bool occupied = v.state == mapping::VoxelState::kOccupied;
    const bool unknown = v.state == mapping::VoxelState::kUnknown;
    const double p = v.p_occ;
    if constexpr (U == IslerUtility::kAverageEntropy) {
      sum += BinaryEntropyBits(p);
      ++voxels;
    } else if constexpr (U == IslerUtility::kOcclusionAware) {
      sum += p_vis * BinaryEntropyBits(p);
    } else if constexpr (U == IslerUtility::kUnobservedVoxel) {
      if (unknown) sum += p_vis * BinaryEntropyBits(p);
    } else if constexpr (U == IslerUtility::kRearSideVoxel) {
      if (occupied && previous_unknown) sum += 1.0;
    } else if constexpr (U == IslerUtility::kRearSideEntropy) {
      if (unknown) {
        run += p_vis * BinaryEntropyBits(p);
      } else if (occupied) {
        sum = run + p_vis * BinaryEntropyBits(p);
      } else {
        run = 0.0;
      }
    } else if constexpr (U == IslerUtility::kProximityCount) {
      if (unknown && d_occ >= 0.0) sum += d_max - d_occ;
    }
    previous_unknown = unknown;
    p_vis *= 1.0 - p;  // exclusive: x_i's own p only affects the voxels after it
    if (occupied) {
      hit = true;
      return false;
    }
    return true;
  }

  IslerRayGain Result() const {
    IslerRayGain g;
    g.hit = hit;
    if constexpr (U == IslerUtility::kAverageEntropy || U == IslerUtility::kRearSideEntropy) {
      if (!hit) return g;  // only rays that end on an occupied voxel count
    }
    g.gain = sum;
    if constexpr (U == IslerUtility::kAverageEntropy) g.voxels = voxels;
    return g;
  }
};

template <IslerUtility U>
IslerRayGain FastRay(const GainGrid& grid, const ProximityField* proximity,
                     const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  RayAccumulator<U> acc;
  const double d_max = proximity != nullptr ? proximity->max_distance_m() : 0.0;
  grid.Walk(from, to, [&](const VoxelKey& k, const GainVoxel& v) {
    double d_occ = -1.0;
    if constexpr (U == IslerUtility::kProximityCount) {
      if (v.state == mapping::VoxelState::kUnknown) {
        if (const std::optional<double> d = proximity->DistanceToOccupied(k)) d_occ = *d;
      }
    }
    return acc.Step(v, d_occ, d_max);
  });
  return acc.Result();
}

/// d_occ of `k` by scanning the map around it (slow): the smallest centre distance to an occupied
/// voxel within the threshold, or -1.
double SlowDistanceToOccupied(const mapping::SemanticMap& map, const VoxelKey& k,
                              double max_distance_m) {
  const double s = map.voxel_size_m();
  const int64_t threshold = ProximityField::Threshold(max_distance_m, s);
  const int32_t r = IntegerSqrt(threshold);
  int64_t best = std::numeric_limits<int64_t>::max();
  for (int32_t dz = -r; dz <= r; ++dz) {
    for (int32_t dy = -r; dy <= r; ++dy) {
      for (int32_t dx = -r; dx <= r; ++dx) {
        const int64_t d2 = int64_t{dx} * dx + int64_t{dy} * dy + int64_t{dz} * dz;
        if (d2 > threshold || d2 >= best) continue;
        if (map.State({k.x + dx, k.y + dy, k.z + dz}) == mapping::VoxelState::kOccupied) best = d2;
      }
    }
  }
  if (best == std::numeric_limits<int64_t>::max()) return -1.0;
  return s * std::sqrt(static_cast<double>(best));
}

template <IslerUtility U>
IslerRayGain SlowRay(const mapping::SemanticMap& map, SemanticClass target, const Box3& roi,
                     double d_max, const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  std::vector<VoxelKey> keys;
  mapping::TraverseRay(from, to, map.voxel_size_m(), [&](const VoxelKey& k) {
    keys.push_back(k);
    return true;
  });
  if (!keys.empty()) keys.pop_back();  // [from, to): the end point's voxel is not visited
  RayAccumulator<U> acc;
  for (const VoxelKey& k : keys) {
    const GainVoxel v = ReadGainVoxel(map, k, target, roi, 0.0);
    double d_occ = -1.0;
    if constexpr (U == IslerUtility::kProximityCount) {
      if (v.state == mapping::VoxelState::kUnknown) d_occ = SlowDistanceToOccupied(map, k, d_max);
    }
    if (!acc.Step(v, d_occ, d_max)) break;
  }
  return acc.Result();
}

template <typename Eval>
double ViewGainWith(IslerUtility utility, const RigidTransform& X_WC,
                    const std::vector<Eigen::Vector3d>& dirs_C, double max_range_m, Eval&& eval) {
  std::vector<IslerRayGain> rays;
  rays.reserve(dirs_C.size());
  const Eigen::Vector3d& origin = X_WC.translation();
  for (const Eigen::Vector3d& d : dirs_C) {
    rays.push_back(eval(origin, origin + max_range_m * (X_WC.rotation() * d)));
  }
  return CombineIslerRays(utility, rays);
}

}  // namespace

std::string_view ToString(IslerUtility utility) {
  switch (utility) {
    case IslerUtility::kAverageEntropy:
      return "ae";
    case IslerUtility::kOcclusionAware:
      return "oa";
    case IslerUtility::kUnobservedVoxel:
      return "uv";
    case IslerUtility::kRearSideVoxel:
      return "rsv";
    case IslerUtility::kRearSideEntropy:
      return "rse";
    case IslerUtility::kProximityCount:
      return "pc";
  }
  return "?";
}

const std::vector<IslerUtility>& AllIslerUtilities() {
  static const std::vector<IslerUtility> kAll = {
      IslerUtility::kAverageEntropy, IslerUtility::kOcclusionAware,  IslerUtility::kUnobservedVoxel,
      IslerUtility::kRearSideVoxel,  IslerUtility::kRearSideEntropy, IslerUtility::kProximityCount};
  return kAll;
}

std::optional<IslerUtility> IslerUtilityFromString(std::string_view name) {
  for (const IslerUtility u : AllIslerUtilities()) {
    if (name == ToString(u)) return u;
  }
  return std::nullopt;
}

// ---- ProximityField -----------------------------------------------------------------------------

int64_t ProximityField::Threshold(double max_distance_m, double voxel_size_m) {
  const double r = max_distance_m / voxel_size_m;
  return static_cast<int64_t>(std::floor(r * r + 1e-6));
}

namespace {

/// Stamps the ball of squared radius `threshold` (voxel units, at most r voxels) around every
/// voxel of `surface` (by z layer of the field) into the field `d2` (n[0] x n[1] x n[2] cells from
/// key `min`), keeping each cell's smallest squared distance. Slabs of z layers run in parallel,
/// each writing only its own layers (the minimum does not depend on the order).
void StampBalls(const std::vector<std::vector<VoxelKey>>& surface, int64_t threshold, int32_t r,
                const VoxelKey& min, const std::array<int64_t, 3>& n, std::vector<uint16_t>& d2) {
  struct Offset {
    int32_t x, y, z;
    uint16_t d2;
  };
  // The ball's offsets by dz (z outermost): offsets of layer dz are ball[first[dz + r], first[dz +
  // r + 1]).
  std::vector<Offset> ball;
  std::vector<size_t> first;
  for (int32_t z = -r; z <= r; ++z) {
    first.push_back(ball.size());
    for (int32_t y = -r; y <= r; ++y) {
      for (int32_t x = -r; x <= r; ++x) {
        const int64_t q = int64_t{x} * x + int64_t{y} * y + int64_t{z} * z;
        if (q <= threshold) ball.push_back({x, y, z, static_cast<uint16_t>(q)});
      }
    }
  }
  first.push_back(ball.size());
  const int64_t nx = n[0], ny = n[1], nz = n[2];
  constexpr int64_t kSlab = 8;
  const int64_t slabs = (nz + kSlab - 1) / kSlab;
  ParallelFor(static_cast<size_t>(slabs), [&](size_t slab) {
    const int64_t z0 = static_cast<int64_t>(slab) * kSlab, z1 = std::min(nz, z0 + kSlab);
    for (int64_t zs = std::max<int64_t>(0, z0 - r); zs < std::min(nz, z1 + r); ++zs) {
      for (const VoxelKey& k : surface[static_cast<size_t>(zs)]) {
        const int64_t dz_lo = std::max<int64_t>(-r, z0 - zs),
                      dz_hi = std::min<int64_t>(r, z1 - 1 - zs);
        for (size_t i = first[static_cast<size_t>(dz_lo + r)];
             i < first[static_cast<size_t>(dz_hi + r + 1)]; ++i) {
          const Offset& o = ball[i];
          const int64_t x = int64_t{k.x} + o.x - min.x, y = int64_t{k.y} + o.y - min.y,
                        z = int64_t{k.z} + o.z - min.z;
          uint16_t& cell = d2[static_cast<size_t>(x + nx * (y + ny * z))];
          cell = std::min(cell, o.d2);
        }
      }
    }
  });
}

}  // namespace

Result<ProximityField> ProximityField::Build(const mapping::SemanticMap& map, double max_distance_m,
                                             size_t max_bytes, const std::optional<Box3>& region) {
  if (!(max_distance_m >= 0.0 && max_distance_m <= kMaxProximityDistance)) {
    return InvalidArgumentError(
        fmt::format("proximity field: max_distance_m ({}) must be in [0, {}]", max_distance_m,
                    kMaxProximityDistance));
  }
  const mapping::OccupancyGrid& grid = map.grid();
  ProximityField f;
  f.voxel_size_m_ = grid.voxel_size_m();
  f.max_distance_m_ = max_distance_m;
  f.threshold_ = Threshold(max_distance_m, f.voxel_size_m_);
  if (f.threshold_ >= kFar) {
    return InvalidArgumentError(
        fmt::format("proximity field: max_distance_m ({}) is too many voxels of {} m",
                    max_distance_m, f.voxel_size_m_));
  }
  const float occupied = grid.occupied_log_odds();
  // A voxel within max_distance_m of the region has its centre within max_distance_m plus a
  // voxel's half diagonal of it; a whole voxel more is margin.
  Box3 keep;
  if (region && !region->IsEmpty()) {
    const Eigen::Vector3d margin =
        Eigen::Vector3d::Constant(max_distance_m + 2.0 * f.voxel_size_m_);
    keep = Box3(region->min() - margin, region->max() + margin);
  }
  std::vector<VoxelKey> occ;
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    if (log_odds >= occupied && (!region || keep.Contains(k.Center(f.voxel_size_m_)))) {
      occ.push_back(k);
    }
  });
  if (occ.empty()) return f;
  VoxelKey lo = occ.front(), hi = occ.front();
  for (const VoxelKey& k : occ) {
    lo = {std::min(lo.x, k.x), std::min(lo.y, k.y), std::min(lo.z, k.z)};
    hi = {std::max(hi.x, k.x), std::max(hi.y, k.y), std::max(hi.z, k.z)};
  }
  const int32_t r = IntegerSqrt(f.threshold_);
  const int64_t nx = int64_t{hi.x} - lo.x + 1 + 2 * int64_t{r};
  const int64_t ny = int64_t{hi.y} - lo.y + 1 + 2 * int64_t{r};
  const int64_t nz = int64_t{hi.z} - lo.z + 1 + 2 * int64_t{r};
  const double bytes = static_cast<double>(nx) * static_cast<double>(ny) * static_cast<double>(nz) *
                       static_cast<double>(sizeof(uint16_t));
  if (bytes > static_cast<double>(max_bytes)) {
    return InvalidArgumentError(fmt::format(
        "proximity field of {} x {} x {} voxels ({:.1f} MB) exceeds max_bytes ({:.1f} MB)", nx, ny,
        nz, bytes / 1e6, static_cast<double>(max_bytes) / 1e6));
  }
  f.min_ = {lo.x - r, lo.y - r, lo.z - r};
  f.dims_ = Eigen::Vector3i(static_cast<int>(nx), static_cast<int>(ny), static_cast<int>(nz));
  f.d2_.assign(static_cast<size_t>(nx * ny * nz), kFar);
  auto index = [&](int64_t x, int64_t y, int64_t z) {
    return static_cast<size_t>((x - f.min_.x) + nx * ((y - f.min_.y) + ny * (z - f.min_.z)));
  };
  // The surface voxels (an occupied voxel with a 6-neighbour that is not: an interior one is never
  // the nearest to a voxel outside), by z layer of the field.
  static constexpr int kNeighbours[6][3] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                            {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
  std::vector<std::vector<VoxelKey>> surface(static_cast<size_t>(nz));
  for (const VoxelKey& k : occ) {
    f.d2_[index(k.x, k.y, k.z)] = 0;
    for (const auto& d : kNeighbours) {
      if (grid.State({k.x + d[0], k.y + d[1], k.z + d[2]}) != mapping::VoxelState::kOccupied) {
        surface[static_cast<size_t>(int64_t{k.z} - f.min_.z)].push_back(k);
        break;
      }
    }
  }
  StampBalls(surface, f.threshold_, r, f.min_, {nx, ny, nz}, f.d2_);
  return f;
}

std::optional<double> ProximityField::DistanceToOccupied(const VoxelKey& k) const {
  const int64_t x = int64_t{k.x} - min_.x;
  const int64_t y = int64_t{k.y} - min_.y;
  const int64_t z = int64_t{k.z} - min_.z;
  if (x < 0 || y < 0 || z < 0 || x >= dims_.x() || y >= dims_.y() || z >= dims_.z()) {
    return std::nullopt;
  }
  const uint16_t d2 = d2_[static_cast<size_t>(x + dims_.x() * (y + int64_t{dims_.y()} * z))];
  if (d2 == kFar) return std::nullopt;
  return voxel_size_m_ * std::sqrt(static_cast<double>(d2));
}

// ---- Ray and view evaluation ------------------------------------------------------------------

const OptionTable<IslerRayOptions>& IslerRayOptionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<IslerRayOptions>("Isler ray option");
    t->Real("max_range_m", &IslerRayOptions::max_range_m, "m", ValueRange::LeftOpen(0, 10),
            "ray length from the optical centre");
    t->Integer("ray_stride_px", &IslerRayOptions::ray_stride_px, "px", ValueRange::AtLeast(1),
               "a ray through every stride-th pixel");
    t->Real("proximity_max_distance_m", &IslerRayOptions::proximity_max_distance_m, "m",
            ValueRange::Closed(0, kMaxProximityDistance), "proximity count's d_max");
    return t;
  }();
  return *table;
}

Status IslerRayOptions::Validate() const { return IslerRayOptionTable().Validate(*this); }

IslerRayGain EvaluateIslerRay(IslerUtility utility, const GainGrid& grid,
                              const ProximityField* proximity, const Eigen::Vector3d& from,
                              const Eigen::Vector3d& to) {
  switch (utility) {
    case IslerUtility::kAverageEntropy:
      return FastRay<IslerUtility::kAverageEntropy>(grid, proximity, from, to);
    case IslerUtility::kOcclusionAware:
      return FastRay<IslerUtility::kOcclusionAware>(grid, proximity, from, to);
    case IslerUtility::kUnobservedVoxel:
      return FastRay<IslerUtility::kUnobservedVoxel>(grid, proximity, from, to);
    case IslerUtility::kRearSideVoxel:
      return FastRay<IslerUtility::kRearSideVoxel>(grid, proximity, from, to);
    case IslerUtility::kRearSideEntropy:
      return FastRay<IslerUtility::kRearSideEntropy>(grid, proximity, from, to);
    case IslerUtility::kProximityCount:
      AVP_THROW_UNLESS(proximity != nullptr, ToString(utility));
      return FastRay<IslerUtility::kProximityCount>(grid, proximity, from, to);
  }
  return {};
}

IslerRayGain EvaluateIslerRayReference(IslerUtility utility, const mapping::SemanticMap& map,
                                       SemanticClass target, const Box3& roi,
                                       double proximity_max_distance_m, const Eigen::Vector3d& from,
                                       const Eigen::Vector3d& to) {
  const double d = proximity_max_distance_m;
  switch (utility) {
    case IslerUtility::kAverageEntropy:
      return SlowRay<IslerUtility::kAverageEntropy>(map, target, roi, d, from, to);
    case IslerUtility::kOcclusionAware:
      return SlowRay<IslerUtility::kOcclusionAware>(map, target, roi, d, from, to);
    case IslerUtility::kUnobservedVoxel:
      return SlowRay<IslerUtility::kUnobservedVoxel>(map, target, roi, d, from, to);
    case IslerUtility::kRearSideVoxel:
      return SlowRay<IslerUtility::kRearSideVoxel>(map, target, roi, d, from, to);
    case IslerUtility::kRearSideEntropy:
      return SlowRay<IslerUtility::kRearSideEntropy>(map, target, roi, d, from, to);
    case IslerUtility::kProximityCount:
      return SlowRay<IslerUtility::kProximityCount>(map, target, roi, d, from, to);
  }
  return {};
}

double CombineIslerRays(IslerUtility utility, const std::vector<IslerRayGain>& rays) {
  double sum = 0.0;
  int64_t voxels = 0;
  for (const IslerRayGain& r : rays) {
    sum += r.gain;
    voxels += r.voxels;
  }
  if (utility == IslerUtility::kAverageEntropy) {
    return voxels == 0 ? 0.0 : sum / static_cast<double>(voxels);
  }
  return sum;
}

double IslerViewGain(IslerUtility utility, const GainGrid& grid, const ProximityField* proximity,
                     const RigidTransform& X_WC, const CameraIntrinsics& K,
                     const IslerRayOptions& options) {
  const Status valid = options.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
  return ViewGainWith(utility, X_WC, RayDirections(K, options.ray_stride_px), options.max_range_m,
                      [&](const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
                        return EvaluateIslerRay(utility, grid, proximity, from, to);
                      });
}

double IslerViewGainReference(IslerUtility utility, const mapping::SemanticMap& map,
                              SemanticClass target, const Box3& roi, const RigidTransform& X_WC,
                              const CameraIntrinsics& K, const IslerRayOptions& options) {
  const Status valid = options.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
  return ViewGainWith(utility, X_WC, RayDirections(K, options.ray_stride_px), options.max_range_m,
                      [&](const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
                        return EvaluateIslerRayReference(
                            utility, map, target, roi, options.proximity_max_distance_m, from, to);
                      });
}

// ---- IslerPlanner -------------------------------------------------------------------------------

const OptionTable<IslerPlannerOptions>& IslerPlannerOptionTable() {
  static const auto* table = [] {
    using O = IslerPlannerOptions;
    auto* t = new OptionTable<O>("Isler planner option");
    t->Nested("candidates", &O::candidates, ShellCandidateOptionTable());
    t->Nested("grid", &O::grid, GainGridOptionTable());
    t->Nested("rays", &O::rays, IslerRayOptionTable());
    t->Real("gain_weight", &O::gain_weight, "", ValueRange::AtLeast(0), "w_ig of U");
    t->Real("cost_weight", &O::cost_weight, "", ValueRange::AtLeast(0), "w_c of U");
    return t;
  }();
  return *table;
}

Status IslerPlannerOptions::Validate() const { return IslerPlannerOptionTable().Validate(*this); }

std::vector<PlannerEntry> IslerPlannerEntries() {
  // In the order of the enum (AllIslerUtilities).
  const char* const kDescriptions[] = {"average entropy", "occlusion-aware",   "unobserved voxel",
                                       "rear-side voxel", "rear-side entropy", "proximity count"};
  std::vector<PlannerEntry> entries;
  for (const IslerUtility utility : AllIslerUtilities()) {
    IslerPlannerOptions defaults;
    defaults.utility = utility;
    entries.push_back(MakePlannerEntry<IslerPlannerOptions>(
        "isler-" + std::string(ToString(utility)),
        fmt::format("Isler et al.'s {} utility on avp-nbv's candidate shells (a baseline)",
                    kDescriptions[static_cast<size_t>(utility)]),
        IslerPlannerOptionTable(), defaults, [](IslerPlannerOptions o, const PlannerContext&) {
          return Result<std::unique_ptr<ViewPlanner>>(std::make_unique<IslerPlanner>(o));
        }));
  }
  return entries;
}

IslerPlanner::IslerPlanner(const IslerPlannerOptions& options)
    : options_(options), name_("isler-" + std::string(ToString(options.utility))) {
  const Status valid = options_.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
}

PlanResult IslerPlanner::Plan(const PlanningRequest& request, Rng& rng) {
  PlanResult result;
  if (const Status s = ValidateRequest(request); !s.ok()) {
    result.status = s.WithContext(name_);
    return result;
  }
  const mapping::SemanticMap& map = *request.map;
  auto grid = GainGrid::Build(map, request.target_class, request.roi, options_.grid);
  if (!grid.ok()) {
    result.status = grid.status().WithContext(name_);
    return result;
  }
  std::optional<ProximityField> proximity;
  if (options_.utility == IslerUtility::kProximityCount) {
    auto field =
        ProximityField::Build(map, options_.rays.proximity_max_distance_m, options_.grid.max_bytes);
    if (!field.ok()) {
      result.status = field.status().WithContext(name_);
      return result;
    }
    proximity = std::move(field).value();
  }
  const std::vector<ViewTarget> targets = FindViewTargets(request, *grid, options_.candidates);
  std::vector<ViewCandidate> candidates =
      GenerateShellCandidates(request, *grid, targets, options_.candidates, rng);
  const size_t generated = candidates.size();

  const std::vector<Eigen::Vector3d> dirs = RayDirections(request.K, options_.rays.ray_stride_px);
  const ProximityField* prox = proximity ? &*proximity : nullptr;
  ParallelFor(candidates.size(), [&](size_t i) {
    ViewCandidate& c = candidates[i];
    if (!c.reachable) return;
    c.gain = ViewGainWith(options_.utility, c.X_WC, dirs, options_.rays.max_range_m,
                          [&](const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
                            return EvaluateIslerRay(options_.utility, *grid, prox, from, to);
                          });
  });
  // WeightedLinearUtility: each term normalised by its sum over the (reachable) candidate set.
  double sum_gain = 0.0, sum_cost = 0.0;
  for (const ViewCandidate& c : candidates) {
    if (!c.reachable) continue;
    sum_gain += c.gain;
    sum_cost += c.cost;
  }
  for (ViewCandidate& c : candidates) {
    const double g = sum_gain > 0.0 ? c.gain / sum_gain : 0.0;
    const double m = sum_cost > 0.0 ? c.cost / sum_cost : 0.0;
    c.utility = options_.gain_weight * g - options_.cost_weight * m;
  }
  return RankCandidates(std::move(candidates), generated, name_);
}

}  // namespace avp::planning

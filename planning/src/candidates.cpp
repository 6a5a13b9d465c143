#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <utility>

#include <fmt/format.h>

#include <avp/core/parallel.h>
#include <avp/planning/candidates.h>

namespace avp::planning {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

/// Greedy spread choice among weighted points (frontier clusters, unseen cubes): each next one
/// maximises weight x min(1, d / spread), d its distance to the points taken so far and to the
/// targets given at the start; the first of equal scores wins. With spread 0 every score is 0:
/// the first unused point.
class SpreadPicker {
 public:
  SpreadPicker(std::vector<Eigen::Vector3d> points, std::vector<double> weights,
               const std::vector<ViewTarget>& chosen)
      : points_(std::move(points)),
        weights_(std::move(weights)),
        d_min_(points_.size(), std::numeric_limits<double>::infinity()),
        used_(points_.size(), false) {
    for (const ViewTarget& t : chosen) Update(t.p_W);
  }
  void Take(size_t i) {
    used_[i] = true;
    taken_.push_back(i);
    Update(points_[i]);
  }
  /// Takes the best unused point whose score is above `floor`; false when there is none.
  bool TakeBest(double spread, double floor) {
    size_t best = points_.size();
    double best_score = floor;
    for (size_t i = 0; i < points_.size(); ++i) {
      if (used_[i]) continue;
      const double score = spread > 0.0 ? weights_[i] * std::min(1.0, d_min_[i] / spread) : 0.0;
      if (score > best_score) {
        best_score = score;
        best = i;
      }
    }
    if (best == points_.size()) return false;
    Take(best);
    return true;
  }
  /// The indices taken, in order.
  const std::vector<size_t>& taken() const { return taken_; }

 private:
  void Update(const Eigen::Vector3d& p) {
    for (size_t i = 0; i < points_.size(); ++i) {
      d_min_[i] = std::min(d_min_[i], (points_[i] - p).norm());
    }
  }
  std::vector<Eigen::Vector3d> points_;
  std::vector<double> weights_;
  std::vector<double> d_min_;
  std::vector<bool> used_;
  std::vector<size_t> taken_;
};

/// Frontier voxels (free voxels in the ROI with an unknown 6-neighbour), clustered on a coarse
/// lattice; returns cluster centres with their voxel counts (near-target voxels count 3x).
std::vector<ViewTarget> FrontierClusters(const PlanningRequest& request, const GainGrid& grid,
                                         int max_clusters, double spread_m, int spread_after,
                                         int extra, double extra_spread_m,
                                         const std::vector<ViewTarget>& chosen) {
  const double s = grid.voxel_size_m();
  constexpr double kCell = 0.05;
  struct Acc {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double weight = 0.0;
    size_t n = 0;
  };
  std::map<std::tuple<int, int, int>, Acc> cells;
  const Box3& roi = request.roi;
  request.map->grid().ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    if (log_odds >= request.map->grid().occupied_log_odds()) return;  // free voxels only
    const Eigen::Vector3d c = k.Center(s);
    if (!roi.Contains(c)) return;
    static constexpr int kNeighbours[6][3] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                              {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
    bool frontier = false, near = false;
    for (const auto& d : kNeighbours) {
      const GainVoxel v = grid.At({k.x + d[0], k.y + d[1], k.z + d[2]});
      if (v.state == mapping::VoxelState::kUnknown) {
        frontier = true;
        near = near || v.near_target;
      }
    }
    if (!frontier) return;
    const auto key = std::make_tuple(static_cast<int>(std::floor(c.x() / kCell)),
                                     static_cast<int>(std::floor(c.y() / kCell)),
                                     static_cast<int>(std::floor(c.z() / kCell)));
    Acc& a = cells[key];
    a.sum += c;
    a.weight += near ? 3.0 : 1.0;
    ++a.n;
  });
  std::vector<ViewTarget> out;
  for (const auto& [key, a] : cells) {
    if (a.n < 4) continue;
    out.push_back({a.sum / static_cast<double>(a.n), "frontier", a.weight});
  }
  // Heaviest first; the map's ordering of equal weights is deterministic (std::map by cell).
  std::stable_sort(out.begin(), out.end(),
                   [](const ViewTarget& a, const ViewTarget& b) { return a.weight > b.weight; });
  const int standard = std::min(std::max(0, max_clusters), static_cast<int>(out.size()));
  const bool spread = spread_m > 0.0 && static_cast<int>(out.size()) > max_clusters;
  if (!spread && extra <= 0) {  // heaviest first, nothing to spread
    out.resize(static_cast<size_t>(standard));
    return out;
  }
  std::vector<Eigen::Vector3d> points;
  std::vector<double> weights;
  for (const ViewTarget& t : out) {
    points.push_back(t.p_W);
    weights.push_back(t.weight);
  }
  SpreadPicker picker(std::move(points), std::move(weights), chosen);
  if (spread) {
    // The heaviest spread_after clusters first, as without spreading, then spread.
    for (int i = 0; i < std::min(spread_after, standard); ++i) picker.Take(static_cast<size_t>(i));
    while (static_cast<int>(picker.taken().size()) < standard && picker.TakeBest(spread_m, -1.0)) {
    }
  } else {
    for (int i = 0; i < standard; ++i) picker.Take(static_cast<size_t>(i));
  }
  // Extra clusters beyond the budget, spread from everything chosen so far.
  for (int e = 0; e < extra && picker.TakeBest(extra_spread_m, -1.0); ++e) {
  }
  std::vector<ViewTarget> picked;
  for (size_t i : picker.taken()) picked.push_back(out[i]);
  return picked;
}

/// The most ROI cubes UnseenTargets counts voxels in (8 MB of counters).
constexpr size_t kMaxUnseenCubes = size_t{1} << 20;

/// Centres of ROI cubes (edge cell_m, coarser when the ROI would hold more than
/// kMaxUnseenCubes) that hold at most 10 % known voxels and border seen plant
/// (occupied voxels in the 26 cubes around them), up to max_targets: the plant is likely to go
/// on where its seen part ends. Greedy: each next cube maximises its bordering occupied voxels
/// times min(1, d / (3 cell_m)), d its distance to the targets chosen so far (`chosen` first);
/// ties go to the first cube in (z, y, x) order.
std::vector<ViewTarget> UnseenTargets(const PlanningRequest& request, double voxel_size_m,
                                      int max_targets, double requested_cell_m,
                                      const std::vector<ViewTarget>& chosen) {
  std::vector<ViewTarget> out;
  const Box3& roi = request.roi;
  if (max_targets <= 0 || !(requested_cell_m > 0.0) || roi.IsEmpty()) return out;
  const Eigen::Vector3d extent = roi.max() - roi.min();
  // At most kMaxUnseenCubes cubes, whatever the ROI: coarser cubes for a huge one.
  double cell_m = requested_cell_m;
  Eigen::Vector3i n;
  size_t cells = 0;
  while (true) {
    for (int i = 0; i < 3; ++i) {
      n[i] = std::max(1, static_cast<int>(std::min(std::ceil(extent[i] / cell_m - 1e-9),
                                                   double{kMaxUnseenCubes})));
    }
    cells = static_cast<size_t>(n.x()) * n.y() * n.z();
    if (cells <= kMaxUnseenCubes) break;
    cell_m *= 1.25;
  }
  const auto index = [&](int x, int y, int z) {
    return static_cast<size_t>(x) +
           static_cast<size_t>(n.x()) * (static_cast<size_t>(y) + static_cast<size_t>(n.y()) * z);
  };
  const auto cell_of = [&](const Eigen::Vector3d& p) {
    Eigen::Vector3i c;
    for (int i = 0; i < 3; ++i) {
      c[i] = std::clamp(static_cast<int>(std::floor((p[i] - roi.min()[i]) / cell_m)), 0, n[i] - 1);
    }
    return index(c.x(), c.y(), c.z());
  };
  std::vector<uint32_t> known(cells, 0), occupied(cells, 0);
  const float occupied_log_odds = request.map->grid().occupied_log_odds();
  request.map->grid().ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    const Eigen::Vector3d c = k.Center(voxel_size_m);
    if (!roi.Contains(c)) return;
    const size_t i = cell_of(c);
    ++known[i];
    if (log_odds >= occupied_log_odds) ++occupied[i];
  });
  const double voxel_volume = voxel_size_m * voxel_size_m * voxel_size_m;
  std::vector<Eigen::Vector3d> centres;
  std::vector<double> weights;
  for (int z = 0; z < n.z(); ++z) {
    for (int y = 0; y < n.y(); ++y) {
      for (int x = 0; x < n.x(); ++x) {
        const Eigen::Vector3d lo = roi.min() + cell_m * Eigen::Vector3d(x, y, z);
        const Eigen::Vector3d hi = (lo + Eigen::Vector3d::Constant(cell_m)).cwiseMin(roi.max());
        const double volume = (hi - lo).prod();
        // Seen: more than 10 % of its voxels known.
        if (!(volume > 0.0) ||
            static_cast<double>(known[index(x, y, z)]) > 0.1 * volume / voxel_volume) {
          continue;
        }
        double weight = 0.0;
        for (int dz = -1; dz <= 1; ++dz) {
          for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
              const int xx = x + dx, yy = y + dy, zz = z + dz;
              if (xx < 0 || yy < 0 || zz < 0 || xx >= n.x() || yy >= n.y() || zz >= n.z()) continue;
              weight += occupied[index(xx, yy, zz)];
            }
          }
        }
        if (weight <= 0.0) continue;
        centres.push_back(0.5 * (lo + hi));
        weights.push_back(weight);
      }
    }
  }
  SpreadPicker picker(centres, weights, chosen);
  while (static_cast<int>(picker.taken().size()) < max_targets &&
         picker.TakeBest(3.0 * cell_m, 0.0)) {
  }
  for (size_t i : picker.taken()) out.push_back({centres[i], "unseen", weights[i]});
  return out;
}

}  // namespace

std::vector<Eigen::Vector3d> CoreTargets(const Box3& roi, double spacing_m, int max_points) {
  const Eigen::Vector3d c = roi.center();
  const double hx = 0.5 * (roi.max().x() - roi.min().x());
  const double hy = 0.5 * (roi.max().y() - roi.min().y());
  // The medial axis runs along the long side, over its length minus the short side's.
  const double half_axis = std::abs(hx - hy);
  if (!(spacing_m > 0.0) || !(half_axis > 0.0) || max_points <= 1) return {c};
  const Eigen::Vector3d u = hx >= hy ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const int n = std::min(max_points, 1 + static_cast<int>(std::floor(2.0 * half_axis / spacing_m)));
  if (n <= 1) return {c};
  std::vector<Eigen::Vector3d> out;
  for (int i = 0; i < n; ++i) {
    const double t = -half_axis + 2.0 * half_axis * static_cast<double>(i) / (n - 1);
    out.push_back(c + t * u);
  }
  return out;
}

std::vector<ViewTarget> FindViewTargets(const PlanningRequest& request, const GainGrid& grid,
                                        const ShellCandidateOptions& options) {
  std::vector<ViewTarget> targets;
  const int max_targets = std::max(1, options.max_targets);
  // The core's points are always targets (a third of the budget at most); fruit and frontiers
  // share the rest as with the ROI centre alone.
  const std::vector<Eigen::Vector3d> core =
      CoreTargets(request.roi, options.core_target_spacing_m, std::max(1, max_targets / 3));
  const int extra_core = static_cast<int>(core.size()) - 1;
  // Fruit instances, largest first (ties by id: Instances() is in id order).
  std::vector<mapping::InstanceInfo> instances;
  for (const mapping::InstanceInfo& info : request.map->Instances()) {
    if (info.semantic_class == request.target_class && info.voxels >= 5) instances.push_back(info);
  }
  std::stable_sort(instances.begin(), instances.end(),
                   [](const mapping::InstanceInfo& a, const mapping::InstanceInfo& b) {
                     return a.voxels > b.voxels;
                   });
  const int fruit_budget = std::max(0, max_targets - 4 - extra_core);
  for (const mapping::InstanceInfo& info : instances) {
    if (static_cast<int>(targets.size()) >= fruit_budget) break;
    targets.push_back({info.centroid_W, "fruit-shell", static_cast<double>(info.voxels)});
  }
  if (options.unseen_targets > 0) {
    const int room =
        std::max(0, max_targets - static_cast<int>(core.size()) - static_cast<int>(targets.size()));
    std::vector<ViewTarget> chosen = targets;
    for (const Eigen::Vector3d& p : core) chosen.push_back({p, "roi", 1.0});
    for (const ViewTarget& t :
         UnseenTargets(request, grid.voxel_size_m(), std::min(room, options.unseen_targets),
                       options.unseen_cell_m, chosen)) {
      targets.push_back(t);
    }
  }
  const int frontier_budget =
      std::max(0, max_targets - static_cast<int>(core.size()) - static_cast<int>(targets.size()));
  for (const ViewTarget& t : FrontierClusters(
           request, grid, frontier_budget, options.frontier_spread_m, options.frontier_spread_after,
           options.extra_frontier_targets, options.extra_frontier_spread_m, targets)) {
    targets.push_back(t);
  }
  for (const Eigen::Vector3d& p : core) targets.push_back({p, "roi", 1.0});
  return targets;
}

std::vector<ViewCandidate> GenerateShellCandidates(const PlanningRequest& request,
                                                   const GainGrid& grid,
                                                   const std::vector<ViewTarget>& targets,
                                                   const ShellCandidateOptions& options, Rng& rng) {
  std::vector<ViewCandidate> out;
  if (targets.empty()) return out;
  const double s = grid.voxel_size_m();
  // Targets beyond max_targets (extra_frontier_targets) get as many candidates as the others.
  const int per_target =
      std::max(1, options.max_candidates /
                      std::min(static_cast<int>(targets.size()), std::max(1, options.max_targets)));
  const double r_min = *std::min_element(options.radii_m.begin(), options.radii_m.end());
  const double r_max = *std::max_element(options.radii_m.begin(), options.radii_m.end());
  const double el_min =
      *std::min_element(options.elevations_deg.begin(), options.elevations_deg.end());
  const double el_max =
      *std::max_element(options.elevations_deg.begin(), options.elevations_deg.end());
  // Cheap necessary condition before IK: the camera within the arm's reach (plus the camera's
  // offset from the flange) of the base.
  const double reach = request.arm->max_reach_m() + request.arm->X_FC().translation().norm();
  const int clearance = static_cast<int>(std::ceil(options.clearance_m / s));
  for (const ViewTarget& t : targets) {
    // The fan faces the robot base (the arm's origin), from where the arm can look at the plant.
    const double base_az = std::atan2(-t.p_W.y(), -t.p_W.x());
    int made = 0;
    for (int attempt = 0; attempt < 8 * per_target && made < per_target; ++attempt) {
      // Uniform over the shell's band: radius, azimuth in the fan, elevation (area-uniform).
      const double rr = rng.Uniform(r_min, r_max);
      const double az =
          base_az +
          rng.Uniform(-options.azimuth_half_range_deg, options.azimuth_half_range_deg) * kDegToRad;
      const double el =
          std::asin(rng.Uniform(std::sin(el_min * kDegToRad), std::sin(el_max * kDegToRad)));
      const Eigen::Vector3d eye =
          t.p_W + rr * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                       std::sin(el));
      if (eye.norm() > reach || eye.z() < 0.05) continue;
      // No camera in or next to a known obstacle (the map is all the planner knows).
      const VoxelKey ke = VoxelKey::FromPoint(eye, s);
      bool blocked = false;
      for (int dz = -clearance; dz <= clearance && !blocked; ++dz) {
        for (int dy = -clearance; dy <= clearance && !blocked; ++dy) {
          for (int dx = -clearance; dx <= clearance && !blocked; ++dx) {
            blocked =
                grid.At({ke.x + dx, ke.y + dy, ke.z + dz}).state == mapping::VoxelState::kOccupied;
          }
        }
      }
      if (blocked) continue;
      if (options.plant_core_radius_m > 0.0 &&
          PlantCoreDistance(eye, request.roi) < options.plant_core_radius_m &&
          grid.At(ke).state != mapping::VoxelState::kFree) {
        continue;
      }
      const RigidTransform X_WC = RigidTransform::LookAt(eye, t.p_W);
      if (IsNearAny(X_WC, request.fused_views)) continue;
      ViewCandidate c;
      c.X_WC = X_WC;
      c.source = t.source;
      out.push_back(std::move(c));
      ++made;
    }
  }
  // Reachability: IK from the current joints, in parallel; each candidate draws its restarts from
  // its own fork of the generator, so the result does not depend on the thread count.
  const Rng ik_root = rng.Fork("ik");
  robot::IkOptions ik;
  ik.max_restarts = std::max(0, options.ik_restarts);
  ParallelFor(out.size(), [&](size_t i) {
    Rng r = ik_root.Fork(static_cast<uint64_t>(i));
    const robot::IkResult res = request.arm->SolveCameraIk(out[i].X_WC, request.q_current, r, ik);
    if (res.ok()) {
      out[i].q = res.q;
      out[i].reachable = true;
      out[i].cost = (res.q - request.q_current).norm();
    }
  });
  DropCollidingCandidates(request, out);
  return out;
}

const OptionTable<ShellCandidateOptions>& ShellCandidateOptionTable() {
  static const auto* table = [] {
    using O = ShellCandidateOptions;
    auto* t = new OptionTable<O>("candidate shell option");
    t->RealList("radii_m", &O::radii_m, "m", ValueRange::Open(0.05, 3), 1, 16,
                "camera distances from the target, drawn between the smallest and the largest");
    t->RealList("elevations_deg", &O::elevations_deg, "deg", ValueRange::Open(-89, 89), 1, 16,
                "camera elevations above the target, drawn between the smallest and the largest");
    t->Real("azimuth_half_range_deg", &O::azimuth_half_range_deg, "deg", ValueRange::Closed(0, 180),
            "azimuths within this of the direction from the target to the robot base");
    t->Integer("max_targets", &O::max_targets, "", ValueRange::Closed(1, 256),
               "targets: fruit instances, then frontier clusters, then the ROI centre");
    t->Integer("max_candidates", &O::max_candidates, "", ValueRange::Closed(1, 20000),
               "candidates generated before the reachability check");
    t->Real("clearance_m", &O::clearance_m, "m", ValueRange::HalfOpen(0, 0.5),
            "no eye this close to a known occupied voxel");
    t->Real("plant_core_radius_m", &O::plant_core_radius_m, "m", ValueRange::HalfOpen(0, 2),
            "within this of the plant's core an eye must be in known free space (0: off)");
    t->Real("frontier_spread_m", &O::frontier_spread_m, "m", ValueRange::Closed(0, 10),
            "frontier targets spread at least this far apart where they can (0: heaviest first)");
    t->Integer("frontier_spread_after", &O::frontier_spread_after, "", ValueRange::Closed(0, 256),
               "with frontier_spread_m: the heaviest this many frontier targets come first");
    t->Integer("extra_frontier_targets", &O::extra_frontier_targets, "", ValueRange::Closed(0, 64),
               "frontier targets beyond max_targets, spread from all others (0: none)");
    t->Real("extra_frontier_spread_m", &O::extra_frontier_spread_m, "m", ValueRange::Closed(0, 10),
            "spread of the extra frontier targets (0: heaviest next)");
    t->Real("core_target_spacing_m", &O::core_target_spacing_m, "m", ValueRange::Closed(0, 10),
            "targets along the core of a long ROI at least this far apart (0: the ROI centre)");
    t->Integer("unseen_targets", &O::unseen_targets, "", ValueRange::Closed(0, 64),
               "targets spread over ROI cubes no view has seen (0: off)");
    t->Real("unseen_cell_m", &O::unseen_cell_m, "m", ValueRange::Closed(0.01, 2),
            "edge of the ROI cubes for unseen_targets");
    t->Integer("ik_restarts", &O::ik_restarts, "", ValueRange::Closed(0, 32),
               "IK restarts per candidate after the attempt from the current joints");
    return t;
  }();
  return *table;
}

Status ShellCandidateOptions::Validate() const {
  return ShellCandidateOptionTable().Validate(*this);
}

}  // namespace avp::planning

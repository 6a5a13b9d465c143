#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <unordered_set>

#include <Eigen/Dense>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/entropy.h>
#include <avp/core/error.h>
#include <avp/eval/metrics.h>

namespace avp::eval {

namespace {

using KeySet = std::unordered_set<VoxelKey, VoxelKeyHash>;

/// Whether `set` (an unordered set or map keyed by VoxelKey) holds a key within Chebyshev
/// distance t of k.
template <typename Set>
bool HasNeighbour(const Set& set, const VoxelKey& k, int t) {
  if (t == 0) return set.count(k) > 0;
  for (int dz = -t; dz <= t; ++dz) {
    for (int dy = -t; dy <= t; ++dy) {
      for (int dx = -t; dx <= t; ++dx) {
        if (set.count(VoxelKey{k.x + dx, k.y + dy, k.z + dz}) > 0) return true;
      }
    }
  }
  return false;
}

double Ratio(size_t num, size_t den) {
  return den > 0 ? static_cast<double>(num) / static_cast<double>(den) : 0.0;
}

double F1(double p, double r) { return p + r > 0.0 ? 2.0 * p * r / (p + r) : 0.0; }

/// The fruit of the nearest GT voxel in the 26-neighbourhood of k (Euclidean offset, ties to the
/// smaller id); 0 when there is none. GT ids are never 0 for fruits of a scene.
uint16_t NearestGtFruit(const GroundTruth& gt, const VoxelKey& k, bool* found) {
  int best_d2 = 4;  // larger than any offset in the 26-neighbourhood (at most 3)
  uint16_t best_id = 0;
  *found = false;
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const auto it = gt.voxels.find(VoxelKey{k.x + dx, k.y + dy, k.z + dz});
        if (it == gt.voxels.end()) continue;
        const int d2 = dx * dx + dy * dy + dz * dz;
        if (d2 < best_d2 || (d2 == best_d2 && it->second < best_id)) {
          best_d2 = d2;
          best_id = it->second;
          *found = true;
        }
      }
    }
  }
  return best_id;
}

/// Voxel keys whose centre lies in `box`: k in [ceil(min / s - 1/2), floor(max / s - 1/2)].
void RoiKeyRange(const Box3& box, double s, VoxelKey& lo, VoxelKey& hi) {
  const auto first = [s](double v) { return static_cast<int32_t>(std::ceil(v / s - 0.5)); };
  const auto last = [s](double v) { return static_cast<int32_t>(std::floor(v / s - 0.5)); };
  lo = {first(box.min().x()), first(box.min().y()), first(box.min().z())};
  hi = {last(box.max().x()), last(box.max().y()), last(box.max().z())};
}

}  // namespace

Status EvalOptions::Validate() const {
  std::vector<std::string> errors;
  if (target == SemanticClass::kBackground || static_cast<int>(target) >= kNumSemanticClasses) {
    errors.push_back(
        fmt::format("target class ({}) must be a non-background class", static_cast<int>(target)));
  }
  if (!(std::isfinite(found_min_fraction) && found_min_fraction >= 0.0 &&
        found_min_fraction <= 1.0)) {
    errors.push_back(fmt::format("found_min_fraction ({}) must be in [0, 1]", found_min_fraction));
  }
  if (!roi.IsEmpty() && !(roi.min().allFinite() && roi.max().allFinite())) {
    errors.push_back(fmt::format("roi ({}) must be finite", roi.ToString()));
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(fmt::format("invalid eval options: {}", fmt::join(errors, "; ")));
}

VoxelScores ScoreVoxelSets(const std::vector<VoxelKey>& predicted, const GroundTruth& gt,
                           int tolerance_voxels) {
  AVP_THROW_UNLESS(tolerance_voxels >= 0 && tolerance_voxels <= 8, tolerance_voxels);
  const KeySet pred(predicted.begin(), predicted.end());
  VoxelScores s;
  s.predicted = pred.size();
  s.ground_truth = gt.voxels.size();
  size_t pred_matched = 0;
  for (const VoxelKey& k : pred) pred_matched += HasNeighbour(gt.voxels, k, tolerance_voxels);
  size_t gt_recalled = 0;
  for (const auto& [k, id] : gt.voxels) gt_recalled += HasNeighbour(pred, k, tolerance_voxels);
  s.tp = gt_recalled;
  s.fn = s.ground_truth - gt_recalled;
  s.fp = s.predicted - pred_matched;
  s.precision = Ratio(pred_matched, s.predicted);
  s.recall = Ratio(gt_recalled, s.ground_truth);
  s.f1 = F1(s.precision, s.recall);
  return s;
}

SphereFit FitSphere(const std::vector<Eigen::Vector3d>& points) {
  AVP_THROW_UNLESS(!points.empty(), points.size());
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) centroid += p;
  centroid /= static_cast<double>(points.size());
  SphereFit fallback;
  fallback.center = centroid;
  for (const Eigen::Vector3d& p : points) fallback.radius_m += (p - centroid).norm();
  fallback.radius_m /= static_cast<double>(points.size());
  if (points.size() < 10) return fallback;

  // |q|^2 = 2 c.q + d with q = p - centroid, d = r^2 - |c|^2: normal equations of [2q 1] x = |q|^2.
  Eigen::Matrix4d M = Eigen::Matrix4d::Zero();
  Eigen::Vector4d rhs = Eigen::Vector4d::Zero();
  Box3 bounds;
  for (const Eigen::Vector3d& p : points) {
    const Eigen::Vector3d q = p - centroid;
    const Eigen::Vector4d a(2.0 * q.x(), 2.0 * q.y(), 2.0 * q.z(), 1.0);
    M += a * a.transpose();
    rhs += a * q.squaredNorm();
    bounds.Extend(p);
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eigen(M, Eigen::EigenvaluesOnly);
  const Eigen::Vector4d ev = eigen.eigenvalues();  // ascending
  if (eigen.info() != Eigen::Success || !(ev(0) > 1e-12 * ev(3))) return fallback;
  const Eigen::Vector4d x = M.ldlt().solve(rhs);
  const Eigen::Vector3d c = x.head<3>();
  const double r2 = x(3) + c.squaredNorm();
  if (!x.allFinite() || !(r2 > 0.0)) return fallback;
  const double r = std::sqrt(r2);
  if (r > 2.0 * bounds.size().norm()) return fallback;
  SphereFit fit;
  fit.center = centroid + c;
  fit.radius_m = r;
  fit.fitted = true;
  return fit;
}

std::vector<VoxelKey> PredictedVoxels(const mapping::SemanticMap& map, SemanticClass target) {
  std::vector<VoxelKey> predicted;
  map.grid().ForEachSemanticVoxel([&](const VoxelKey& k, const mapping::SemanticCell& cell) {
    if (cell.cls() == target && map.grid().State(k) == mapping::VoxelState::kOccupied) {
      predicted.push_back(k);
    }
  });
  std::sort(predicted.begin(), predicted.end());
  return predicted;
}

namespace {

/// GT voxels per fruit with a predicted voxel in their 26-neighbourhood.
std::map<uint16_t, size_t> RecalledPerFruit(const std::vector<VoxelKey>& predicted,
                                            const GroundTruth& gt) {
  const KeySet pred_set(predicted.begin(), predicted.end());
  std::map<uint16_t, size_t> recalled;
  for (const auto& [k, id] : gt.voxels) {
    if (HasNeighbour(pred_set, k, 1)) ++recalled[id];
  }
  return recalled;
}

size_t ObservableVoxels(const GroundTruth& gt, uint16_t id) {
  const auto it = gt.voxels_per_fruit.find(id);
  return it == gt.voxels_per_fruit.end() ? 0 : it->second;
}

/// FoundFruitIds' rule for one fruit.
bool IsFound(size_t hits, size_t observable, const EvalOptions& options) {
  const double needed = std::max(static_cast<double>(options.found_min_voxels),
                                 options.found_min_fraction * static_cast<double>(observable));
  return observable > 0 && hits > 0 && static_cast<double>(hits) >= needed;
}

}  // namespace

std::vector<uint16_t> FoundFruitIds(const std::vector<VoxelKey>& predicted, const GroundTruth& gt,
                                    const EvalOptions& options) {
  std::vector<uint16_t> found;  // ascending: std::map's order
  for (const auto& [id, hits] : RecalledPerFruit(predicted, gt)) {
    if (IsFound(hits, ObservableVoxels(gt, id), options)) found.push_back(id);
  }
  return found;
}

namespace {

/// The voxels labelled `options.target`: their count and entropy in `m`; returns the occupied
/// ones, sorted (the predicted voxels).
std::vector<VoxelKey> PredictedVoxelsWithEntropy(const mapping::OccupancyGrid& grid,
                                                 const EvalOptions& options, MapMetrics& m) {
  std::vector<VoxelKey> predicted;
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const mapping::SemanticCell& cell) {
    if (cell.cls() != options.target) return;
    ++m.labelled_voxels;
    m.entropy_sum_bits += ClampedBinaryEntropyBits(cell.confidence);
    if (grid.State(k) == mapping::VoxelState::kOccupied) predicted.push_back(k);
  });
  std::sort(predicted.begin(), predicted.end());
  m.entropy_mean_bits =
      m.labelled_voxels > 0 ? m.entropy_sum_bits / static_cast<double>(m.labelled_voxels) : 0.0;
  return predicted;
}

/// One fruit's result: its truth, voxels observable, recalled and matched, found or not, and for
/// a found fruit with matched voxels the sphere fitted to them.
FruitResult ScoreFruit(const sim::FruitTruth& fruit, const GroundTruth& gt,
                       const std::map<uint16_t, size_t>& recalled,
                       const std::map<uint16_t, std::vector<Eigen::Vector3d>>& matched,
                       const EvalOptions& options) {
  FruitResult r;
  r.instance_id = fruit.instance_id;
  r.name = fruit.name;
  r.center_W = fruit.center_W;
  r.radii = fruit.radii;
  r.radius_m = fruit.mean_radius_m();
  if (const auto v = gt.best_visible_fraction.find(fruit.instance_id);
      v != gt.best_visible_fraction.end()) {
    r.best_visible_fraction = v->second;
  }
  r.observable_voxels = ObservableVoxels(gt, fruit.instance_id);
  if (const auto h = recalled.find(fruit.instance_id); h != recalled.end()) {
    r.recalled_voxels = h->second;
  }
  const auto pts = matched.find(fruit.instance_id);
  r.matched_voxels = pts == matched.end() ? 0 : pts->second.size();
  r.found = IsFound(r.recalled_voxels, r.observable_voxels, options);
  if (r.found && r.matched_voxels > 0) {
    const SphereFit fit = FitSphere(pts->second);
    r.estimated = true;
    r.sphere_fitted = fit.fitted;
    r.estimated_center_W = fit.center;
    r.estimated_radius_m = fit.radius_m;
    r.center_error_m = (fit.center - fruit.center_W).norm();
    r.radius_error_m = std::abs(fit.radius_m - r.radius_m);
  }
  return r;
}

/// Fruits: found ones (FoundFruitIds' rule) and matched predicted voxels per fruit, with each
/// fruit's result in `fruits` when given.
void ScoreFruits(const mapping::SemanticMap& map, const GroundTruth& gt,
                 const std::vector<VoxelKey>& predicted, const EvalOptions& options, FruitScores& f,
                 std::vector<FruitResult>* fruits) {
  const double s = map.voxel_size_m();
  const std::map<uint16_t, size_t> recalled = RecalledPerFruit(predicted, gt);
  std::map<uint16_t, std::vector<Eigen::Vector3d>> matched;
  for (const VoxelKey& k : predicted) {  // sorted: the fits see their points in a fixed order
    bool found = false;
    const uint16_t id = NearestGtFruit(gt, k, &found);
    if (found) matched[id].push_back(k.Center(s));
  }
  f.total = gt.fruits.size();
  double center_error_sum = 0.0;
  double radius_error_sum = 0.0;
  size_t fitted = 0;
  if (fruits != nullptr) {
    fruits->clear();
    fruits->reserve(gt.fruits.size());
  }
  for (const sim::FruitTruth& fruit : gt.fruits) {
    FruitResult r = ScoreFruit(fruit, gt, recalled, matched, options);
    if (r.observable_voxels > 0) ++f.observable;
    if (r.found) ++f.found;
    if (r.estimated) {
      center_error_sum += r.center_error_m;
      radius_error_sum += r.radius_error_m;
      ++fitted;
    }
    if (fruits != nullptr) fruits->push_back(std::move(r));
  }
  f.found_fraction = Ratio(f.found, f.total);
  if (fitted > 0) {
    f.mean_center_error_m = center_error_sum / static_cast<double>(fitted);
    f.mean_radius_error_m = radius_error_sum / static_cast<double>(fitted);
  }
  for (const mapping::InstanceInfo& inst : map.Instances()) {
    if (inst.semantic_class == options.target) ++f.map_instances;
  }
}

/// Coverage of the ROI: its voxels, and those known.
void ScoreRoiCoverage(const mapping::OccupancyGrid& grid, const EvalOptions& options, double s,
                      MapMetrics& m) {
  if (options.roi.IsEmpty()) return;
  VoxelKey lo;
  VoxelKey hi;
  RoiKeyRange(options.roi, s, lo, hi);
  if (lo.x > hi.x || lo.y > hi.y || lo.z > hi.z) return;
  m.roi_voxels = static_cast<size_t>(hi.x - lo.x + 1) * static_cast<size_t>(hi.y - lo.y + 1) *
                 static_cast<size_t>(hi.z - lo.z + 1);
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float) {
    if (k.x >= lo.x && k.x <= hi.x && k.y >= lo.y && k.y <= hi.y && k.z >= lo.z && k.z <= hi.z) {
      ++m.roi_known_voxels;
    }
  });
  m.roi_coverage = Ratio(m.roi_known_voxels, m.roi_voxels);
}

}  // namespace

MapMetrics EvaluateMap(const mapping::SemanticMap& map, const GroundTruth& gt,
                       const EvalOptions& options, std::vector<FruitResult>* fruits) {
  const Status valid = options.Validate();
  if (!valid.ok()) ThrowStatus(valid);
  const double s = map.voxel_size_m();
  const double gt_s = gt.voxel_size_m;
  AVP_THROW_UNLESS(std::abs(s - gt_s) <= 1e-9 * s, s, gt_s);
  const mapping::OccupancyGrid& grid = map.grid();

  MapMetrics m;
  const std::vector<VoxelKey> predicted = PredictedVoxelsWithEntropy(grid, options, m);
  m.predicted_voxels = predicted.size();
  m.exact = ScoreVoxelSets(predicted, gt, 0);
  m.tolerant = ScoreVoxelSets(predicted, gt, 1);
  ScoreFruits(map, gt, predicted, options, m.fruits, fruits);
  ScoreRoiCoverage(grid, options, s, m);
  return m;
}

void FruitTracker::AfterView(int view, std::vector<FruitResult> now,
                             const std::optional<std::unordered_map<uint16_t, double>>& visible) {
  if (first_found_.size() != now.size()) {
    first_found_.assign(now.size(), -1);
    found_since_.assign(now.size(), -1);
    best_visible_.assign(now.size(), FruitResult::kNaN);
    best_view_.assign(now.size(), -1);
  }
  for (size_t i = 0; i < now.size(); ++i) {
    if (now[i].found) {
      if (first_found_[i] < 0) first_found_[i] = view;
      if (found_since_[i] < 0) found_since_[i] = view;
    } else {
      found_since_[i] = -1;  // lost (or never found): a later find starts a new run
    }
    if (visible.has_value()) {
      const auto it = visible->find(now[i].instance_id);
      const double v = it == visible->end() ? 0.0 : it->second;
      if (std::isnan(best_visible_[i]) || v > best_visible_[i]) {
        best_visible_[i] = v;
        best_view_[i] = view;
      }
    }
  }
  last_ = std::move(now);
}

std::vector<FruitResult> FruitTracker::Result() const {
  std::vector<FruitResult> out = last_;
  for (size_t i = 0; i < out.size() && i < first_found_.size(); ++i) {
    out[i].found_view = first_found_[i];
    out[i].found_since_view = found_since_[i];
    out[i].episode_visible_fraction = best_visible_[i];
    out[i].episode_best_view = best_view_[i];
  }
  return out;
}

std::vector<FruitResult> EvaluateFruits(const mapping::SemanticMap& map, const GroundTruth& gt,
                                        const EvalOptions& options) {
  std::vector<FruitResult> fruits;
  EvaluateMap(map, gt, options, &fruits);
  return fruits;
}

}  // namespace avp::eval

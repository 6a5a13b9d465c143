#include <algorithm>
#include <cmath>
#include <tuple>
#include <unordered_map>
#include <unordered_set>

#include <avp/core/error.h>
#include <avp/core/parallel.h>
#include <avp/eval/oracle_planner.h>
#include <avp/eval/statistics.h>
#include <avp/mapping/semantic_map.h>
#include <avp/planning/gain_grid.h>
#include <avp/planning/view_features.h>

namespace avp::eval {

namespace {

bool IsTarget(const mapping::SemanticMap& map, const VoxelKey& k, SemanticClass target) {
  if (map.State(k) != mapping::VoxelState::kOccupied) return false;
  const mapping::SemanticCell* cell = map.Semantic(k);
  return cell != nullptr && cell->cls() == target;
}

}  // namespace

OracleNbvPlanner::OracleNbvPlanner(const sim::Scene& scene, const GroundTruth& gt,
                                   const OracleNbvOptions& options)
    : gt_(gt), options_(options) {
  // Candidates are rendered in parallel (ParallelFor), each on one thread.
  renderer_ = std::make_unique<sim::RgbdRenderer>(scene);
}

OracleNbvPlanner::~OracleNbvPlanner() = default;

std::unordered_set<VoxelKey, VoxelKeyHash> OracleNbvPlanner::NewVoxels(
    const mapping::SemanticMap& map, SemanticClass target, const CameraIntrinsics& Ks,
    const RigidTransform& X_WC, std::unordered_map<uint16_t, size_t>* pixels) const {
  const sim::RenderedFrame frame = renderer_->Render(Ks, X_WC);
  const double s = map.voxel_size_m();
  std::unordered_set<VoxelKey, VoxelKeyHash> seen;
  for (int v = 0; v < Ks.height; ++v) {
    for (int u = 0; u < Ks.width; ++u) {
      const float z = frame.rgbd.depth_m.at(u, v);
      if (!(z > 0.0f)) continue;
      if (pixels != nullptr) ++(*pixels)[frame.instance_ids.at(u, v)];
      const Eigen::Vector3d p_C = Ks.BackProject(Eigen::Vector2d(u, v), z);
      const VoxelKey k = VoxelKey::FromPoint(X_WC * p_C, s);
      if (gt_.voxels.count(k) == 0 || IsTarget(map, k, target)) continue;
      seen.insert(k);
    }
  }
  return seen;
}

size_t OracleNbvPlanner::TrueGain(const mapping::SemanticMap& map, SemanticClass target,
                                  const CameraIntrinsics& K, const RigidTransform& X_WC) const {
  return NewVoxels(map, target, K.Scaled(options_.render_scale), X_WC, nullptr).size();
}

std::unordered_set<uint16_t> OracleNbvPlanner::FoundFruits(const mapping::SemanticMap& map,
                                                           SemanticClass target) const {
  EvalOptions rule = options_.found_rule;
  rule.target = target;
  const std::vector<uint16_t> ids = FoundFruitIds(PredictedVoxels(map, target), gt_, rule);
  return {ids.begin(), ids.end()};
}

double OracleNbvPlanner::ExpectedDetectionGain(const mapping::SemanticMap& map,
                                               SemanticClass target, const CameraIntrinsics& K,
                                               const RigidTransform& X_WC,
                                               const std::unordered_set<uint16_t>& found) const {
  const CameraIntrinsics Ks = K.Scaled(options_.render_scale);
  std::unordered_map<uint16_t, size_t> pixels;  // per instance id, pixels with a return
  const std::unordered_set<VoxelKey, VoxelKeyHash> fresh =
      NewVoxels(map, target, Ks, X_WC, &pixels);
  std::unordered_map<uint16_t, size_t> new_of;
  for (const VoxelKey& k : fresh) ++new_of[gt_.voxels.at(k)];
  // Pixels at full resolution: the render has render_scale^2 of them.
  const double to_full =
      static_cast<double>(K.width) * K.height / (static_cast<double>(Ks.width) * Ks.height);
  double gain = 0.0;
  for (const sim::FruitTruth& fruit : gt_.fruits) {
    const auto px = pixels.find(fruit.instance_id);
    if (px == pixels.end()) continue;
    const double full_px = to_full * static_cast<double>(px->second);
    if (full_px < static_cast<double>(options_.detector.min_pixels)) continue;
    const std::optional<double> area = segmentation::ExpectedFruitAreaPx(
        K, X_WC, {fruit.instance_id, fruit.center_W, fruit.mean_radius_m()});
    const double v = area ? std::clamp(full_px / *area, 0.0, 1.0) : 1.0;
    const double p = options_.detector.DetectionProbability(v);
    const auto n = new_of.find(fruit.instance_id);
    const double new_voxels = n == new_of.end() ? 0.0 : static_cast<double>(n->second);
    const double bonus =
        new_voxels > 0.0 && found.count(fruit.instance_id) == 0 ? kFruitValue : 0.0;
    gain += p * (new_voxels + bonus);
  }
  return gain;
}

planning::PlanResult OracleNbvPlanner::Plan(const planning::PlanningRequest& request, Rng& rng) {
  planning::PlanResult result;
  if (Status st = planning::ValidateRequest(request); !st.ok()) {
    result.status = st;
    return result;
  }
  Result<planning::GainGrid> grid =
      planning::GainGrid::Build(*request.map, request.target_class, request.roi);
  if (!grid.ok()) {
    result.status = grid.status();
    return result;
  }
  const auto targets = planning::FindViewTargets(request, *grid, options_.candidates);
  std::vector<planning::ViewCandidate> candidates =
      planning::GenerateShellCandidates(request, *grid, targets, options_.candidates, rng);
  if (options_.observation_view_candidates) {
    const size_t first = candidates.size();
    for (const ObservationView& view : gt_.views) {
      if (planning::IsNearAny(view.X_WC, request.fused_views)) continue;
      planning::ViewCandidate c;
      c.X_WC = view.X_WC;
      c.source = "observation-view";
      candidates.push_back(std::move(c));
    }
    // The ground truth found these reachable from the start joints with IkOptions' default
    // restarts; the same restarts here. Each view draws from its own fork, so the result does not
    // depend on the thread count.
    const Rng ik_root = rng.Fork("observation-view-ik");
    const robot::IkOptions ik;
    ParallelFor(candidates.size() - first, [&](size_t j) {
      planning::ViewCandidate& c = candidates[first + j];
      Rng r = ik_root.Fork(static_cast<uint64_t>(j));
      const robot::IkResult res = request.arm->SolveCameraIk(c.X_WC, request.q_current, r, ik);
      if (!res.ok()) return;
      c.q = res.q;
      c.reachable = true;
      c.cost = (res.q - request.q_current).norm();
    });
  }
  const size_t generated = candidates.size();
  const bool detections = options_.objective == OracleNbvOptions::Objective::kDetections;
  const std::unordered_set<uint16_t> found =
      detections ? FoundFruits(*request.map, request.target_class) : std::unordered_set<uint16_t>{};
  ParallelFor(candidates.size(), [&](size_t i) {
    planning::ViewCandidate& c = candidates[i];
    if (!c.reachable) return;
    c.gain =
        detections
            ? ExpectedDetectionGain(*request.map, request.target_class, request.K, c.X_WC, found)
            : static_cast<double>(TrueGain(*request.map, request.target_class, request.K, c.X_WC));
  });
  double max_gain = 0.0, max_cost = 0.0;
  for (const auto& c : candidates) {
    if (!c.reachable) continue;
    max_gain = std::max(max_gain, c.gain);
    max_cost = std::max(max_cost, c.cost);
  }
  for (auto& c : candidates) {
    c.utility = (max_gain > 0.0 ? c.gain / max_gain : 0.0) -
                options_.w_motion * (max_cost > 0.0 ? c.cost / max_cost : 0.0);
  }
  return planning::RankCandidates(std::move(candidates), generated, name());
}

namespace {

/// The feature rows of `candidates` on a gain grid with the default options.
Result<std::vector<float>> FeatureRows(const planning::PlanningRequest& request,
                                       const std::vector<planning::ViewCandidate>& candidates) {
  AVP_ASSIGN_OR_RETURN(const planning::GainGrid grid,
                       planning::GainGrid::Build(*request.map, request.target_class, request.roi));
  AVP_ASSIGN_OR_RETURN(const planning::ViewFeatureExtractor extractor,
                       planning::ViewFeatureExtractor::Build(request, grid));
  return extractor.Compute(candidates);
}

}  // namespace

planning::PlanResult RegretProbe::Plan(const planning::PlanningRequest& request, Rng& rng) {
  planning::PlanResult result = inner_.Plan(request, rng);
  const int call = calls_++;
  if (!result.status.ok() || result.ranked.empty()) return result;
  std::vector<double> truth(result.ranked.size(), 0.0), predicted(result.ranked.size(), 0.0);
  ParallelFor(result.ranked.size(), [&](size_t i) {
    truth[i] = static_cast<double>(
        oracle_.TrueGain(*request.map, request.target_class, request.K, result.ranked[i].X_WC));
  });
  for (size_t i = 0; i < result.ranked.size(); ++i) predicted[i] = result.ranked[i].gain;
  std::vector<float> features;
  std::string features_error;
  if (record_features_) {
    Result<std::vector<float>> rows = FeatureRows(request, result.ranked);
    if (rows.ok()) {
      features = std::move(*rows);
    } else {
      features_error = rows.status().ToString();
    }
  }
  const size_t width = planning::ViewFeatureCount();
  StepRegret r;
  r.step = call;
  r.candidates = result.ranked.size();
  r.chosen_true_gain = truth.front();
  r.best_true_gain = *std::max_element(truth.begin(), truth.end());
  r.regret = r.best_true_gain > 0.0 ? 1.0 - r.chosen_true_gain / r.best_true_gain : 0.0;
  r.chosen_true_rank =
      1 + static_cast<size_t>(std::count_if(truth.begin(), truth.end(),
                                            [&](double t) { return t > r.chosen_true_gain; }));
  r.rank_correlation = SpearmanRankCorrelation(predicted, truth);
  r.features_error = std::move(features_error);
  if (!features.empty()) {
    r.feature_names.assign(planning::ViewFeatureNames().begin(),
                           planning::ViewFeatureNames().end());
    r.feature_version = planning::kViewFeatureVersion;
    r.feature_hash = planning::ViewFeatureHash();
  }
  r.scored.reserve(result.ranked.size());
  for (size_t i = 0; i < result.ranked.size(); ++i) {
    const planning::ViewCandidate& c = result.ranked[i];
    r.scored.push_back(
        {.eye = c.X_WC.translation(),
         .forward = c.X_WC.rotation().col(2),
         .gain = c.gain,
         .utility = c.utility,
         .cost = c.cost,
         .true_gain = truth[i],
         .source = c.source,
         .gain_terms = c.gain_terms,
         .features =
             features.empty()
                 ? std::vector<float>()
                 : std::vector<float>(features.begin() + static_cast<ptrdiff_t>(i * width),
                                      features.begin() + static_cast<ptrdiff_t>((i + 1) * width))});
  }
  steps_.push_back(std::move(r));
  return result;
}

const OptionTable<OracleNbvOptions>& OracleNbvOptionTable() {
  static const auto* table = [] {
    using O = OracleNbvOptions;
    auto* t = new OptionTable<O>("oracle planner option");
    t->Nested("candidates", &O::candidates, planning::ShellCandidateOptionTable());
    t->Real("render_scale", &O::render_scale, "", ValueRange::LeftOpen(0, 1),
            "candidates are rendered at this fraction of the camera's resolution");
    t->Real("w_motion", &O::w_motion, "", ValueRange::AtLeast(0), "weight of the motion cost");
    return t;
  }();
  return *table;
}

void RegisterOraclePlanners(planning::PlannerRegistry& registry) {
  OracleNbvOptions detect;
  detect.objective = OracleNbvOptions::Objective::kDetections;
  detect.observation_view_candidates = true;
  std::vector<planning::PlannerEntry> entries;
  for (const auto& [name, description, defaults] :
       {std::tuple{"oracle-nbv",
                   "diagnostic upper bound: avp-nbv's candidates scored with the true new fruit "
                   "voxels (uses the ground truth)",
                   OracleNbvOptions{}},
        std::tuple{"oracle-detect",
                   "diagnostic bound on fruits found: views scored by the expected detections "
                   "(uses the ground truth)",
                   detect}}) {
    planning::PlannerEntry e = planning::MakePlannerEntry<OracleNbvOptions>(
        name, description, OracleNbvOptionTable(), defaults,
        [](OracleNbvOptions o,
           const planning::PlannerContext& c) -> Result<std::unique_ptr<planning::ViewPlanner>> {
          const auto* truth = dynamic_cast<const PlannerTruth*>(c.truth);
          if (truth == nullptr) {
            return FailedPreconditionError("the oracle planners need eval::PlannerTruth");
          }
          if (o.objective == OracleNbvOptions::Objective::kDetections) o.detector = truth->detector;
          return std::unique_ptr<planning::ViewPlanner>(
              std::make_unique<OracleNbvPlanner>(truth->scene, truth->gt, o));
        });
    e.needs_ground_truth = true;
    entries.push_back(std::move(e));
  }
  AddAll(registry, std::move(entries));
}

}  // namespace avp::eval

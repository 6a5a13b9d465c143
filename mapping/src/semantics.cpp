#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/mapping/semantics.h>

namespace avp::mapping {
namespace {

/// |log-odds| bound that keeps round(l * kClassLogOddsScale) inside int16.
constexpr float kMaxAbsClassLogOdds = 31.0f;
constexpr uint32_t kMaxInstanceId = 65535;

uint16_t SaturatingIncrement(uint16_t v) { return v == 0xFFFF ? v : static_cast<uint16_t>(v + 1); }

bool IsObjectClass(SemanticClass cls) {
  const int c = static_cast<int>(cls);
  return c >= 1 && c < kNumSemanticClasses;
}

int32_t Quantize(float log_odds) {
  const float bounded = std::clamp(log_odds, -64.0f, 64.0f);
  return static_cast<int32_t>(std::lround(bounded * kClassLogOddsScale));
}

void AddClassLogOdds(SemanticCell& cell, int cls, float delta, const SemanticOptions& options) {
  const int32_t q =
      std::clamp(cell.class_log_odds[cls] + Quantize(delta), Quantize(options.class_log_odds_min),
                 Quantize(options.class_log_odds_max));
  cell.class_log_odds[cls] = static_cast<int16_t>(q);
}

/// semantic_class and confidence from the log-odds (Bayesian policy).
void DeriveBayesianLabel(SemanticCell& cell, const SemanticOptions& options) {
  const std::array<float, kNumSemanticClasses> p = BayesianPosteriors(cell);
  int best = 1;  // integer comparison: exact, ties to the lower class
  for (int c = 2; c < kNumSemanticClasses; ++c) {
    if (cell.class_log_odds[c] > cell.class_log_odds[best]) best = c;
  }
  cell.confidence = p[best];
  cell.semantic_class = p[best] >= options.label_threshold ? static_cast<uint8_t>(best) : 0;
}

int Contest(const SemanticCell& cell) { return cell.flags & kSemanticFlagContestMask; }
void SetContest(SemanticCell& cell, int value) {
  cell.flags = static_cast<uint8_t>((cell.flags & ~kSemanticFlagContestMask) |
                                    (std::min(value, 3) & kSemanticFlagContestMask));
}
void ClearInstance(SemanticCell& cell) {
  cell.instance_id = 0;
  SetContest(cell, 0);
}

/// Sum, sum of squares and count of voxel centres: centroid and radius of gyration.
struct Moments {
  size_t n = 0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double sum_sq = 0.0;

  void Add(const Eigen::Vector3d& p) {
    ++n;
    sum += p;
    sum_sq += p.squaredNorm();
  }
  void Add(const Moments& o) {
    n += o.n;
    sum += o.sum;
    sum_sq += o.sum_sq;
  }
  Eigen::Vector3d Centroid() const {
    return n == 0 ? Eigen::Vector3d::Zero() : Eigen::Vector3d(sum / static_cast<double>(n));
  }
  /// sqrt(mean |p - centroid|^2).
  double Radius() const {
    if (n == 0) return 0.0;
    const double mean_sq = sum_sq / static_cast<double>(n);
    return std::sqrt(std::max(0.0, mean_sq - Centroid().squaredNorm()));
  }
};

/// part >= fraction * whole, forgiving the float rounding of `fraction` (0.1f * 10 counts as 1).
bool AtLeastFraction(size_t part, size_t whole, float fraction) {
  return static_cast<double>(part) >=
         static_cast<double>(fraction) * static_cast<double>(whole) * (1.0 - 1e-6);
}

}  // namespace

// ---- Names and options ------------------------------------------------------------------------

std::string_view ToString(FusionPolicy policy) {
  switch (policy) {
    case FusionPolicy::kReferenceMax:
      return "reference-max";
    case FusionPolicy::kBayesian:
      return "bayesian";
  }
  return "unknown";
}

std::optional<FusionPolicy> FusionPolicyFromString(std::string_view name) {
  if (name == "reference-max") return FusionPolicy::kReferenceMax;
  if (name == "bayesian") return FusionPolicy::kBayesian;
  return std::nullopt;
}

const OptionTable<SemanticOptions>& SemanticOptionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<SemanticOptions>("semantic option");
    const ValueRange fraction = ValueRange::LeftOpen(0, 1);
    t->Choice(
        "policy", &SemanticOptions::policy,
        {{FusionPolicy::kReferenceMax, "reference-max"}, {FusionPolicy::kBayesian, "bayesian"}},
        "how a voxel's evidence is combined over frames (docs/mapping-semantics.md)");
    t->Real("reference_penalty", &SemanticOptions::reference_penalty, "", fraction,
            "reference-max: the conflict and first-observation factor");
    t->Real("class_log_odds_min", &SemanticOptions::class_log_odds_min, "",
            ValueRange::HalfOpen(-kMaxAbsClassLogOdds, 0), "bayesian: lower clamp of a class");
    t->Real("class_log_odds_max", &SemanticOptions::class_log_odds_max, "",
            ValueRange::LeftOpen(0, kMaxAbsClassLogOdds), "bayesian: upper clamp of a class");
    t->Real("miss_log_odds", &SemanticOptions::miss_log_odds, "",
            ValueRange::Closed(0, 2.0 * kMaxAbsClassLogOdds),
            "bayesian: what an endpoint outside every mask takes from each class");
    t->Real("label_threshold", &SemanticOptions::label_threshold, "", fraction,
            "bayesian: posterior at which a voxel takes its best class");
    t->Real("score_epsilon", &SemanticOptions::score_epsilon, "", ValueRange::Open(0, 0.5),
            "bayesian: mask scores are clamped to [eps, 1 - eps]");
    t->Real("instance_join_fraction", &SemanticOptions::instance_join_fraction, "", fraction,
            "share of a mask's labelled votes that joins it to an instance");
    t->Real("instance_min_overlap_fraction", &SemanticOptions::instance_min_overlap_fraction, "",
            fraction, "share of all the mask's voxels an instance must hold to be joined");
    t->Real("instance_merge_fraction", &SemanticOptions::instance_merge_fraction, "", fraction,
            "share of each instance one mask must cover to merge them");
    t->Real("instance_merge_max_separation", &SemanticOptions::instance_merge_max_separation, "",
            ValueRange::AtLeast(0),
            "largest centroid distance of a merge, in sums of radii of gyration (0: no merging)");
    t->Integer("instance_flip_frames", &SemanticOptions::instance_flip_frames, "",
               ValueRange::Closed(1, 3), "frames of contest before a voxel changes instance");
    t->Integer("outlier_min_neighbours", &SemanticOptions::outlier_min_neighbours, "",
               ValueRange::Closed(0, 26),
               "labelled 26-neighbours a label needs to survive outlier removal (0: off)");
    t->Flag("remove_outliers_each_frame", &SemanticOptions::remove_outliers_each_frame,
            "remove outliers after every fused frame");
    return t;
  }();
  return *table;
}

Status SemanticOptions::Validate() const { return SemanticOptionTable().Validate(*this); }

// ---- Per-cell fusion ----------------------------------------------------------------------------

void FuseReferenceMax(SemanticCell& cell, SemanticClass cls, float confidence, float penalty) {
  if (!IsObjectClass(cls) || !std::isfinite(confidence)) return;
  cell.observations = SaturatingIncrement(cell.observations);
  const auto c = static_cast<uint8_t>(cls);
  if (cell.semantic_class == c) {
    cell.confidence = (cell.confidence + confidence) / 2.0f;
  } else if (confidence > cell.confidence) {
    cell.semantic_class = c;
    cell.confidence = penalty * confidence;
  } else {
    cell.confidence = penalty * cell.confidence;
  }
}

void FuseBayesianHit(SemanticCell& cell, SemanticClass cls, float confidence,
                     const SemanticOptions& options) {
  if (!IsObjectClass(cls) || !std::isfinite(confidence)) return;
  cell.observations = SaturatingIncrement(cell.observations);
  const double eps = options.score_epsilon;
  const double s = std::clamp(static_cast<double>(confidence), eps, 1.0 - eps);
  const double delta = std::log(s / (1.0 - s)) + std::log(double{kNumSemanticClasses - 1});
  AddClassLogOdds(cell, static_cast<int>(cls), static_cast<float>(delta), options);
  DeriveBayesianLabel(cell, options);
}

void FuseBayesianMiss(SemanticCell& cell, const SemanticOptions& options) {
  cell.misses = SaturatingIncrement(cell.misses);
  for (int c = 1; c < kNumSemanticClasses; ++c) {
    AddClassLogOdds(cell, c, -options.miss_log_odds, options);
  }
  DeriveBayesianLabel(cell, options);
}

std::array<float, kNumSemanticClasses> BayesianPosteriors(const SemanticCell& cell) {
  std::array<double, kNumSemanticClasses> l{};
  double max_l = 0.0;  // background's log-odds
  for (int c = 1; c < kNumSemanticClasses; ++c) {
    l[c] = cell.class_log_odds[c] / static_cast<double>(kClassLogOddsScale);
    max_l = std::max(max_l, l[c]);
  }
  std::array<double, kNumSemanticClasses> e{};
  double sum = 0.0;
  for (int c = 0; c < kNumSemanticClasses; ++c) {
    e[c] = std::exp(l[c] - max_l);
    sum += e[c];
  }
  std::array<float, kNumSemanticClasses> p{};
  for (int c = 0; c < kNumSemanticClasses; ++c) p[c] = static_cast<float>(e[c] / sum);
  return p;
}

// ---- SemanticFusion -----------------------------------------------------------------------------

SemanticFusion::SemanticFusion(const SemanticOptions& options) : options_(options) {
  const Status valid = options.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
}

void SemanticFusion::FuseHit(SemanticCell& cell, SemanticClass cls, float confidence) const {
  if (options_.rule != nullptr) {
    options_.rule->Hit(cell, cls, confidence);
  } else if (options_.policy == FusionPolicy::kReferenceMax) {
    FuseReferenceMax(cell, cls, confidence, options_.reference_penalty);
  } else {
    FuseBayesianHit(cell, cls, confidence, options_);
  }
}

uint16_t SemanticFusion::NewInstance(uint32_t frame) {
  if (next_instance_id_ > kMaxInstanceId) return 0;
  const auto id = static_cast<uint16_t>(next_instance_id_++);
  if (frames_of_instance_.size() <= id) frames_of_instance_.resize(size_t{id} + 1, {0, 0});
  frames_of_instance_[id] = {frame, frame};
  return id;
}

void SemanticFusion::TouchInstance(uint16_t id, uint32_t frame) {
  if (id == 0) return;
  if (frames_of_instance_.size() <= id) frames_of_instance_.resize(size_t{id} + 1, {0, 0});
  uint32_t& last = frames_of_instance_[id].second;
  last = std::max(last, frame);
}

SemanticFrameStats SemanticFusion::Fuse(OccupancyGrid& grid,
                                        std::span<const VoxelObservation> observations,
                                        const Segmentation& segmentation, uint32_t frame) {
  SemanticFrameStats stats;
  stats.observations = observations.size();

  // Bucket the observations by mask; invalid masks and indices are skipped.
  const size_t num_masks = segmentation.instances.size();
  std::vector<bool> mask_ok(num_masks);
  for (size_t m = 0; m < num_masks; ++m) {
    const InstanceMask& mask = segmentation.instances[m];
    mask_ok[m] = IsObjectClass(mask.semantic_class) && std::isfinite(mask.confidence) &&
                 mask.confidence >= 0.0f && mask.confidence <= 1.0f;
  }
  std::vector<std::vector<VoxelKey>> keys_of_mask(num_masks);
  std::vector<VoxelKey> misses;
  for (const VoxelObservation& obs : observations) {
    if (obs.mask_index == -1) {
      misses.push_back(obs.key);
    } else if (obs.mask_index < 0 || static_cast<size_t>(obs.mask_index) >= num_masks ||
               !mask_ok[static_cast<size_t>(obs.mask_index)]) {
      ++stats.skipped;
    } else {
      keys_of_mask[static_cast<size_t>(obs.mask_index)].push_back(obs.key);
    }
  }

  // Negative evidence first (Bayesian, or a rule that has it; the reference has none), on voxels
  // with evidence.
  const FusionRule* rule = options_.rule.get();
  if (rule != nullptr ? rule->has_negative_evidence()
                      : options_.policy == FusionPolicy::kBayesian) {
    for (const VoxelKey& key : misses) {
      const SemanticCell* existing = grid.Semantic(key);
      if (existing == nullptr || existing->observations == 0) continue;
      SemanticCell* cell = grid.MutableSemantic(key);
      if (cell == nullptr) continue;
      const uint8_t was = cell->semantic_class;
      if (rule != nullptr) {
        rule->Miss(*cell);
      } else {
        FuseBayesianMiss(*cell, options_);
      }
      if (cell->semantic_class != was) ClearInstance(*cell);
      ++stats.miss_updates;
    }
  }

  for (size_t m = 0; m < num_masks; ++m) {
    if (keys_of_mask[m].empty()) continue;
    FuseMask(grid, segmentation.instances[m], keys_of_mask[m], frame, stats);
  }

  if (options_.remove_outliers_each_frame) stats.outliers_removed = RemoveOutliers(grid).removed;
  return stats;
}

namespace {

// ---- FuseMask's stages (docs/mapping-semantics.md, "Instances")

/// Votes: the mask's voxels already labelled with its class `cls`, counted by owning instance.
std::map<uint16_t, size_t> InstanceVotes(const OccupancyGrid& grid, uint8_t cls,
                                         std::span<const VoxelKey> keys) {
  std::map<uint16_t, size_t> votes;
  for (const VoxelKey& key : keys) {
    const SemanticCell* cell = grid.Semantic(key);
    if (cell != nullptr && cell->semantic_class == cls && cell->instance_id != 0) {
      ++votes[cell->instance_id];
    }
  }
  return votes;
}

/// The instances a mask of n voxels spans, and the best of them.
struct SpannedInstances {
  std::vector<uint16_t> ids;  ///< ascending
  uint16_t best = 0;          ///< most votes, ties to the lower id; 0 when none is spanned
};

/// Spanned instances: enough of the votes and of the mask's n voxels; the best one is the target.
SpannedInstances FindSpannedInstances(const std::map<uint16_t, size_t>& votes, size_t n,
                                      const SemanticOptions& options) {
  size_t total_votes = 0;
  for (const auto& [id, count] : votes) total_votes += count;
  SpannedInstances spanned;
  size_t best_votes = 0;
  for (const auto& [id, count] : votes) {
    if (!AtLeastFraction(count, total_votes, options.instance_join_fraction) ||
        !AtLeastFraction(count, n, options.instance_min_overlap_fraction)) {
      continue;
    }
    spanned.ids.push_back(id);
    if (count > best_votes) {  // ties to the lower id
      spanned.best = id;
      best_votes = count;
    }
  }
  return spanned;
}

/// An instance a mask keeps voxels for, with its centroid (used only when there are several).
struct AcceptedInstance {
  uint16_t id;
  Eigen::Vector3d centroid_W;
};

/// The merge decision of a mask that spans several instances.
struct MergeGroup {
  uint16_t target = 0;        ///< the group's lowest id: the instance the group becomes
  std::vector<uint16_t> ids;  ///< the group: the best spanned instance and those merged into it
  /// The group (as target) and the spanned instances kept separate, ascending by id.
  std::vector<AcceptedInstance> accepted;
  /// Labelled voxels of each spanned instance.
  std::map<uint16_t, std::vector<VoxelKey>> members;
};

/// Merge candidates: the moments of every spanned instance (one pass over the labelled voxels);
/// each joins the best one's group when the mask covers enough of both and they are close.
MergeGroup GroupSpannedInstances(const OccupancyGrid& grid, const SpannedInstances& spanned,
                                 const std::map<uint16_t, size_t>& votes,
                                 const SemanticOptions& options) {
  MergeGroup out;
  std::map<uint16_t, Moments> moments;
  for (uint16_t id : spanned.ids) moments[id] = Moments{};
  grid.ForEachSemanticVoxel([&](const VoxelKey& key, const SemanticCell& cell) {
    auto it = moments.find(cell.instance_id);
    if (it == moments.end()) return;
    it->second.Add(grid.CenterOf(key));
    out.members[cell.instance_id].push_back(key);
  });

  const uint16_t best = spanned.best;
  Moments group = moments[best];
  size_t group_votes = votes.at(best);
  out.ids = {best};
  std::vector<uint16_t> separate;
  for (uint16_t j : spanned.ids) {
    if (j == best) continue;
    const Moments& mj = moments[j];
    const bool covers_both = AtLeastFraction(votes.at(j), mj.n, options.instance_merge_fraction) &&
                             AtLeastFraction(group_votes, group.n, options.instance_merge_fraction);
    const double separation = (group.Centroid() - mj.Centroid()).norm();
    const bool close = options.instance_merge_max_separation > 0.0f &&
                       separation <= static_cast<double>(options.instance_merge_max_separation) *
                                         (group.Radius() + mj.Radius());
    if (covers_both && close) {
      group.Add(mj);
      group_votes += votes.at(j);
      out.ids.push_back(j);
    } else {
      separate.push_back(j);
    }
  }
  out.target = *std::min_element(out.ids.begin(), out.ids.end());
  out.accepted.push_back({out.target, group.Centroid()});
  for (uint16_t j : separate) out.accepted.push_back({j, moments[j].Centroid()});
  std::sort(out.accepted.begin(), out.accepted.end(),
            [](const AcceptedInstance& a, const AcceptedInstance& b) { return a.id < b.id; });
  return out;
}

/// The instances a mask keeps voxels for, and the one each of its voxels goes to.
class InstanceChoice {
 public:
  explicit InstanceChoice(std::vector<AcceptedInstance> accepted)
      : accepted_(std::move(accepted)) {}

  bool Accepts(uint16_t id) const {
    return std::any_of(accepted_.begin(), accepted_.end(),
                       [id](const AcceptedInstance& a) { return a.id == id; });
  }

  /// The instance the voxel `key` goes to: the nearest accepted centroid when the mask spans
  /// several separate instances (ties to the lower id), else the target, created on first use by
  /// new_instance() -> uint16_t (0: none could be, and the voxel gets none).
  template <typename NewInstance>
  uint16_t For(const OccupancyGrid& grid, const VoxelKey& key, NewInstance&& new_instance) {
    if (accepted_.empty()) {
      const uint16_t id = new_instance();
      if (id == 0) return 0;
      accepted_.push_back({id, Eigen::Vector3d::Zero()});
    }
    if (accepted_.size() == 1) return accepted_.front().id;
    const Eigen::Vector3d p = grid.CenterOf(key);
    const AcceptedInstance* nearest = &accepted_.front();
    double best_d2 = (p - nearest->centroid_W).squaredNorm();
    for (const AcceptedInstance& a : accepted_) {
      const double d2 = (p - a.centroid_W).squaredNorm();
      if (d2 < best_d2) {
        best_d2 = d2;
        nearest = &a;
      }
    }
    return nearest->id;
  }

 private:
  std::vector<AcceptedInstance> accepted_;
};

}  // namespace

void SemanticFusion::AbsorbInstance(OccupancyGrid& grid, uint16_t id, uint16_t target,
                                    std::span<const VoxelKey> members) {
  for (const VoxelKey& key : members) {
    if (SemanticCell* cell = grid.MutableSemantic(key)) cell->instance_id = target;
  }
  if (id < frames_of_instance_.size()) {
    // The merged instance spans both histories; the retired id keeps none.
    const auto [first, last] = frames_of_instance_[id];
    TouchInstance(target, last);
    uint32_t& target_first = frames_of_instance_[target].first;
    target_first = std::min(target_first, first);
    frames_of_instance_[id] = {0, 0};
  }
}

void SemanticFusion::FuseMask(OccupancyGrid& grid, const InstanceMask& mask,
                              std::span<const VoxelKey> keys, uint32_t frame,
                              SemanticFrameStats& stats) {
  const auto k = static_cast<uint8_t>(mask.semantic_class);
  // 1. Votes; 2. spanned instances, the best one the target.
  const std::map<uint16_t, size_t> votes = InstanceVotes(grid, k, keys);
  const SpannedInstances spanned = FindSpannedInstances(votes, keys.size(), options_);
  std::vector<AcceptedInstance> accepted;
  if (spanned.ids.size() >= 2) {
    MergeGroup group = GroupSpannedInstances(grid, spanned, votes, options_);
    for (uint16_t id : group.ids) {
      if (id == group.target) continue;
      AbsorbInstance(grid, id, group.target, group.members[id]);
      ++stats.merged_instances;
    }
    accepted = std::move(group.accepted);
  } else if (spanned.best != 0) {
    accepted.push_back({spanned.best, Eigen::Vector3d::Zero()});
  }
  InstanceChoice choice(std::move(accepted));
  const auto new_instance = [&] {
    const uint16_t id = NewInstance(frame);
    if (id != 0) ++stats.new_instances;
    return id;
  };

  // 3. Fuse every voxel, then place it.
  for (const VoxelKey& key : keys) {
    SemanticCell* cell = grid.MutableSemantic(key);
    if (cell == nullptr) {
      ++stats.skipped;
      continue;
    }
    const uint8_t was = cell->semantic_class;
    FuseHit(*cell, mask.semantic_class, mask.confidence);
    ++stats.labelled_updates;
    if (cell->semantic_class != was) ClearInstance(*cell);
    if (cell->semantic_class != k) continue;  // the mask lost (reference) or is below threshold

    const uint16_t owner = cell->instance_id;
    if (owner != 0 && choice.Accepts(owner)) {
      SetContest(*cell, 0);
      TouchInstance(owner, frame);
      continue;
    }
    if (owner == 0) {
      const uint16_t id = choice.For(grid, key, new_instance);
      cell->instance_id = id;
      TouchInstance(id, frame);
      continue;
    }
    // Owned by an instance this mask does not span: move only on repeated claims.
    const int contest = Contest(*cell) + 1;
    if (contest < options_.instance_flip_frames) {
      SetContest(*cell, contest);
      continue;
    }
    const uint16_t id = choice.For(grid, key, new_instance);
    if (id == 0) continue;
    cell->instance_id = id;
    SetContest(*cell, 0);
    TouchInstance(id, frame);
    ++stats.reassigned_voxels;
  }
}

OutlierStats SemanticFusion::RemoveOutliers(OccupancyGrid& grid) const {
  OutlierStats stats;
  const int min_neighbours = options_.outlier_min_neighbours;
  std::vector<VoxelKey> remove;
  grid.ForEachSemanticVoxel([&](const VoxelKey& key, const SemanticCell& cell) {
    ++stats.examined;
    if (min_neighbours == 0) return;
    int found = 0;
    for (int dz = -1; dz <= 1; ++dz) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0 && dz == 0) continue;
          const SemanticCell* nb = grid.Semantic({key.x + dx, key.y + dy, key.z + dz});
          if (nb == nullptr || !nb->has_label()) continue;
          const bool same = cell.instance_id != 0 ? nb->instance_id == cell.instance_id
                                                  : nb->semantic_class == cell.semantic_class;
          if (same && ++found >= min_neighbours) return;
        }
      }
    }
    remove.push_back(key);
  });
  for (const VoxelKey& key : remove) {
    SemanticCell* cell = grid.MutableSemantic(key);
    if (cell == nullptr) continue;
    cell->semantic_class = 0;
    cell->confidence = 0.0f;
    cell->class_log_odds.fill(0);
    ClearInstance(*cell);
    ++stats.removed;
  }
  return stats;
}

std::vector<InstanceInfo> SemanticFusion::Instances(const OccupancyGrid& grid) const {
  struct Accumulator {
    std::array<size_t, kNumSemanticClasses> classes{};
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double confidence = 0.0;
    size_t n = 0;
  };
  std::map<uint16_t, Accumulator> by_id;
  grid.ForEachSemanticVoxel([&](const VoxelKey& key, const SemanticCell& cell) {
    if (cell.instance_id == 0) return;
    Accumulator& a = by_id[cell.instance_id];
    ++a.classes[cell.semantic_class < kNumSemanticClasses ? cell.semantic_class : 0];
    a.sum += grid.CenterOf(key);
    a.confidence += cell.confidence;
    ++a.n;
  });
  std::vector<InstanceInfo> out;
  out.reserve(by_id.size());
  for (const auto& [id, a] : by_id) {
    InstanceInfo info;
    info.id = id;
    const auto majority = std::max_element(a.classes.begin(), a.classes.end());
    info.semantic_class = static_cast<SemanticClass>(majority - a.classes.begin());
    info.voxels = a.n;
    info.centroid_W = a.sum / static_cast<double>(a.n);
    info.mean_confidence = a.confidence / static_cast<double>(a.n);
    if (id < frames_of_instance_.size()) {
      info.first_frame = frames_of_instance_[id].first;
      info.last_frame = frames_of_instance_[id].second;
    }
    out.push_back(info);
  }
  return out;
}

void SemanticFusion::ResetFromGrid(const OccupancyGrid& grid) {
  uint16_t max_id = 0;
  grid.ForEachSemanticVoxel([&](const VoxelKey&, const SemanticCell& cell) {
    max_id = std::max(max_id, cell.instance_id);
  });
  next_instance_id_ = uint32_t{max_id} + 1;
  frames_of_instance_.assign(size_t{max_id} + 1, {0, 0});
}

}  // namespace avp::mapping

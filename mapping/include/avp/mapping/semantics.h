#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/core/voxel_key.h>
#include <avp/mapping/semantic_cell.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::mapping {

/// How a voxel's semantic evidence is combined over frames.
enum class FusionPolicy : uint8_t {
  /// The reference system's `setConfidenceMaxFusion`, reproduced exactly (see
  /// docs/mapping-semantics.md): same class -> c = (c_old + c_new) / 2; different class -> the
  /// larger
  /// confidence's class with c = penalty * max(c_old, c_new), ties keep the old class; a fresh
  /// voxel is ("none", 0), so the first observation stores penalty * c. No negative evidence.
  kReferenceMax = 0,
  /// Per-voxel multi-class log-odds (each class against background), clamped; a mask of class k
  /// with calibrated score s adds logit(s) + log(K - 1) to class k; an endpoint seen outside every
  /// mask lowers every class by `miss_log_odds`. From the uniform prior one mask gives the
  /// posterior s exactly (docs/mapping-semantics.md).
  kBayesian = 1,
};
std::string_view ToString(FusionPolicy policy);
/// "reference-max" or "bayesian"; nullopt otherwise.
std::optional<FusionPolicy> FusionPolicyFromString(std::string_view name);

/// A semantic fusion rule of one's own (docs/extending.md, "Adding a map fusion rule"): how one
/// observation changes a voxel's cell. Set SemanticOptions::rule to use it instead of the built-in
/// policy; instance association, outlier removal and the map files are the same for every rule.
class FusionRule {
 public:
  virtual ~FusionRule() = default;
  /// A short name for records ("max-confidence").
  virtual std::string_view name() const = 0;
  /// One observation inside a mask of class `cls` (an object class) with calibrated confidence
  /// `confidence` in [0, 1]. Must count it (SemanticCell::observations) and leave instance_id
  /// alone.
  virtual void Hit(SemanticCell& cell, SemanticClass cls, float confidence) const = 0;
  /// Whether an endpoint seen outside every mask is evidence against the voxel's label.
  virtual bool has_negative_evidence() const { return false; }
  /// One such endpoint on a voxel that has evidence (only when has_negative_evidence()).
  virtual void Miss(SemanticCell& cell) const { (void)cell; }
};

/// One frame's semantic evidence for one voxel: the integrator reduces all of a frame's endpoints
/// in a voxel to one observation (the mask with most pixels there, ties to the higher confidence,
/// then the lower index; or -1 when most pixels were outside every mask).
struct VoxelObservation {
  VoxelKey key;
  int32_t mask_index = -1;  ///< into Segmentation::instances, or -1 (outside every mask)
  uint32_t pixels = 0;      ///< endpoints supporting this observation
};

struct SemanticOptions {
  FusionPolicy policy = FusionPolicy::kBayesian;
  /// A rule of one's own instead of `policy` (code, not configuration: not in the table, and a
  /// saved map records only `policy`). Null: the built-in policy.
  std::shared_ptr<const FusionRule> rule;
  /// kReferenceMax: the conflict / first-observation factor (0.9 in the reference), in (0, 1].
  float reference_penalty = 0.9f;
  /// kBayesian: clamp of each class's log-odds against background; -31 <= min < 0 < max <= 31
  /// (the int16 fixed-point range of SemanticCell::class_log_odds).
  float class_log_odds_min = -4.0f;
  float class_log_odds_max = 6.0f;
  /// kBayesian: how much one "seen outside every mask" endpoint lowers each class's log-odds
  /// (>= 0; 0 disables negative evidence).
  float miss_log_odds = 0.4f;
  /// kBayesian: a voxel is labelled with its best class when that class's posterior reaches this,
  /// in (0, 1].
  float label_threshold = 0.5f;
  /// kBayesian: mask scores are clamped to [eps, 1 - eps] before taking logit(s), in (0, 0.5).
  float score_epsilon = 1e-3f;

  /// Instance association. The mask's voxels already labelled with its class vote for their
  /// instance; an instance is "spanned" by the mask when it holds at least
  /// `instance_join_fraction` of these votes and at least `instance_min_overlap_fraction` of all
  /// the mask's voxels. The mask joins the spanned instance with most votes (ties to the lower
  /// id); with none it starts a new instance. A spanned instance's voxels are never taken away.
  float instance_join_fraction = 0.3f;
  float instance_min_overlap_fraction = 0.1f;
  /// Two instances spanned by one mask merge when the mask covers at least this fraction of each
  /// instance's voxels ...
  float instance_merge_fraction = 0.25f;
  /// ... and their centroids are at most this times the sum of their radii of gyration apart
  /// (the geometric guard: two touching fruits are ~1.15 apart, one fruit seen from opposite
  /// sides ~0.58). 0 disables merging.
  float instance_merge_max_separation = 0.8f;
  /// A voxel owned by an instance that a mask does not span moves to the mask's instance only
  /// after this many frames in which masks of other instances claimed it (1..3; no single weak
  /// vote flips a voxel when > 1). Counted in the low bits of SemanticCell::flags.
  int instance_flip_frames = 2;

  /// Outlier removal: a labelled voxel with fewer than this many labelled 26-neighbours of its own
  /// instance (of its own class when it has no instance) loses its label; 0..26, 0 disables.
  int outlier_min_neighbours = 1;
  /// Run outlier removal after every fused frame.
  bool remove_outliers_each_frame = false;

  /// Names every bad value.
  Status Validate() const;
};

/// The fields of SemanticOptions (every one of them).
const OptionTable<SemanticOptions>& SemanticOptionTable();

/// SemanticCell::flags bits used by SemanticFusion: the ownership-contest counter (frames in
/// which masks of other instances claimed the voxel since its owner last did).
inline constexpr uint8_t kSemanticFlagContestMask = 0x03;

/// Per-instance statistics, recomputed from the voxels (never written back into them).
struct InstanceInfo {
  uint16_t id = 0;
  SemanticClass semantic_class = SemanticClass::kBackground;
  size_t voxels = 0;
  Eigen::Vector3d centroid_W = Eigen::Vector3d::Zero();
  double mean_confidence = 0.0;
  uint32_t first_frame = 0;
  uint32_t last_frame = 0;
};

struct SemanticFrameStats {
  size_t observations = 0;      ///< observations examined (the span's size)
  size_t labelled_updates = 0;  ///< observations inside a mask, fused into a cell
  size_t miss_updates = 0;      ///< negative-evidence updates on voxels that had evidence
  size_t skipped = 0;           ///< bad mask index, invalid or background mask, key not admitted
  size_t new_instances = 0;
  size_t merged_instances = 0;   ///< instances merged into another one (ids retired)
  size_t reassigned_voxels = 0;  ///< voxels moved from one instance to another
  size_t outliers_removed = 0;   ///< labels cleared by remove_outliers_each_frame
};

struct OutlierStats {
  size_t examined = 0;  ///< labelled voxels looked at
  size_t removed = 0;   ///< labels cleared
};

/// Semantic fusion, instance association and outlier removal over an OccupancyGrid's semantic
/// cells. Stateful only in its instance bookkeeping (next id, per-instance first/last frame).
class SemanticFusion {
 public:
  /// @throws avp::Error if options.Validate() fails.
  explicit SemanticFusion(const SemanticOptions& options = {});

  const SemanticOptions& options() const { return options_; }

  /// Fuses one frame. `observations` holds at most one entry per voxel; mask indices refer to
  /// `segmentation`. Observations outside every mask only touch voxels that already have
  /// semantic evidence (observations > 0), and only under kBayesian. `frame` is the grid's frame
  /// number (for instance bookkeeping). Never throws for bad input: an observation whose mask
  /// index is out of range, whose mask is of class background or unknown, or has a non-finite
  /// or out-of-[0, 1] confidence, or whose key the grid does not admit is skipped and counted in
  /// `skipped`. Masks are processed in ascending index order; see docs/mapping-semantics.md for
  /// the instance rules.
  SemanticFrameStats Fuse(OccupancyGrid& grid, std::span<const VoxelObservation> observations,
                          const Segmentation& segmentation, uint32_t frame);

  /// Clears isolated labels (class, instance, confidence, log-odds and contest counter; the
  /// observation and miss counts stay); O(labelled voxels), never creates labels. Decisions are
  /// taken on the map as it was before the call.
  OutlierStats RemoveOutliers(OccupancyGrid& grid) const;

  /// Instances present in the grid's cells, sorted by id.
  std::vector<InstanceInfo> Instances(const OccupancyGrid& grid) const;

  /// Restores the bookkeeping from cells, e.g. after loading a map: the next free id becomes the
  /// largest id in the grid + 1; first/last frames of the ids found are unknown (0).
  void ResetFromGrid(const OccupancyGrid& grid);

 private:
  /// Fuses one mask's voxels and associates them with instances (docs/mapping-semantics.md).
  void FuseMask(OccupancyGrid& grid, const InstanceMask& mask, std::span<const VoxelKey> keys,
                uint32_t frame, SemanticFrameStats& stats);
  void FuseHit(SemanticCell& cell, SemanticClass cls, float confidence) const;
  /// A fresh id (0 when all 65535 are used).
  uint16_t NewInstance(uint32_t frame);
  void TouchInstance(uint16_t id, uint32_t frame);
  /// Merges instance `id` into `target` (FuseMask): relabels its voxels `members` and joins its
  /// first/last frames into the target's; the retired id keeps none.
  void AbsorbInstance(OccupancyGrid& grid, uint16_t id, uint16_t target,
                      std::span<const VoxelKey> members);

  SemanticOptions options_;
  uint32_t next_instance_id_ = 1;  ///< 65536 = ids exhausted (masks then get no instance)
  std::vector<std::pair<uint32_t, uint32_t>> frames_of_instance_;  ///< [id] = (first, last)
};

/// Reference "max fusion" of one observation into a cell (exposed for tests and tools); also counts
/// the observation. No-op for class background / unknown or a non-finite confidence.
void FuseReferenceMax(SemanticCell& cell, SemanticClass cls, float confidence, float penalty);
/// Bayesian update of one in-mask observation / one outside-every-mask observation, then
/// re-derives semantic_class and confidence; they count the observation / miss. The hit is a
/// no-op for class background / unknown or a non-finite confidence. Neither touches instance_id.
void FuseBayesianHit(SemanticCell& cell, SemanticClass cls, float confidence,
                     const SemanticOptions& options);
void FuseBayesianMiss(SemanticCell& cell, const SemanticOptions& options);
/// Posterior of {background, class 1, ..., class K-1} from a cell's class_log_odds (a softmax
/// with background's log-odds 0); sums to 1.
std::array<float, kNumSemanticClasses> BayesianPosteriors(const SemanticCell& cell);

}  // namespace avp::mapping

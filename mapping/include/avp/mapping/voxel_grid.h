#pragma once

#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>
#include <vector>

#include <avp/core/box.h>
#include <avp/core/status.h>
#include <avp/core/voxel_key.h>
#include <avp/mapping/semantic_cell.h>
#include <avp/mapping/sensor_model.h>

namespace avp::mapping {

/// What the map knows about a voxel.
enum class VoxelState : uint8_t {
  kUnknown = 0,   ///< never observed
  kFree = 1,      ///< observed, log-odds below the occupancy threshold
  kOccupied = 2,  ///< observed, log-odds at or above the occupancy threshold
};
std::string_view ToString(VoxelState state);

inline constexpr int kBlockShift = 3;
inline constexpr int kBlockEdge = 1 << kBlockShift;                        // 8
inline constexpr int kBlockVoxels = kBlockEdge * kBlockEdge * kBlockEdge;  // 512
inline constexpr int kBlockWords = kBlockVoxels / 64;                      // 8 bitset words

/// Voxel keys the grid can store: |x|, |y|, |z| < kMaxKeyMagnitude (2^23 voxels, i.e. +-16.7 km at
/// 2 mm). Keys outside are dropped by updates and reported by the integrator.
inline constexpr int32_t kMaxKeyMagnitude = int32_t{1} << 23;

/// Integer coordinates of an 8^3 block: voxel key >> 3 on each axis (floor division).
struct BlockKey {
  int32_t x = 0;
  int32_t y = 0;
  int32_t z = 0;
  friend bool operator==(const BlockKey&, const BlockKey&) = default;
  friend auto operator<=>(const BlockKey&, const BlockKey&) = default;
};

inline BlockKey BlockOf(const VoxelKey& k) {
  return {k.x >> kBlockShift, k.y >> kBlockShift, k.z >> kBlockShift};
}
/// Index of a voxel inside its block: x fastest, then y, then z.
inline int LocalIndex(const VoxelKey& k) {
  return (k.x & (kBlockEdge - 1)) | ((k.y & (kBlockEdge - 1)) << kBlockShift) |
         ((k.z & (kBlockEdge - 1)) << (2 * kBlockShift));
}
inline VoxelKey KeyOf(const BlockKey& b, int local) {
  return {(b.x << kBlockShift) | (local & 7), (b.y << kBlockShift) | ((local >> 3) & 7),
          (b.z << kBlockShift) | ((local >> 6) & 7)};
}
inline bool KeyInRange(const VoxelKey& k) {
  return k.x > -kMaxKeyMagnitude && k.x < kMaxKeyMagnitude && k.y > -kMaxKeyMagnitude &&
         k.y < kMaxKeyMagnitude && k.z > -kMaxKeyMagnitude && k.z < kMaxKeyMagnitude;
}

/// A 512-bit set, one bit per voxel of a block.
struct BlockBits {
  std::array<uint64_t, kBlockWords> words{};

  bool test(int i) const { return (words[i >> 6] >> (i & 63)) & 1u; }
  void set(int i) { words[i >> 6] |= uint64_t{1} << (i & 63); }
  void reset(int i) { words[i >> 6] &= ~(uint64_t{1} << (i & 63)); }
  void clear() { words.fill(0); }
  int count() const {
    int n = 0;
    for (uint64_t w : words) n += std::popcount(w);
    return n;
  }
  bool any() const {
    uint64_t a = 0;
    for (uint64_t w : words) a |= w;
    return a != 0;
  }
  /// Atomically sets bit i; returns true if this call set it (it was clear before).
  bool atomic_test_and_set(int i) {
    std::atomic_ref<uint64_t> w(words[i >> 6]);
    const uint64_t m = uint64_t{1} << (i & 63);
    if (w.load(std::memory_order_relaxed) & m) return false;
    return (w.fetch_or(m, std::memory_order_relaxed) & m) == 0;
  }
  void atomic_set(int i) {
    std::atomic_ref<uint64_t>(words[i >> 6])
        .fetch_or(uint64_t{1} << (i & 63), std::memory_order_relaxed);
  }
  template <typename F>
  void ForEachSet(F&& fn) const {
    for (int w = 0; w < kBlockWords; ++w) {
      uint64_t bits = words[w];
      while (bits) {
        fn(w * 64 + std::countr_zero(bits));
        bits &= bits - 1;
      }
    }
  }
};

/// Semantic payload of a block, allocated the first time one of its voxels gets a label.
using SemanticBlock = std::array<SemanticCell, kBlockVoxels>;

/// One 8^3 block. Occupancy is stored as structure-of-arrays: 4 B of log-odds per voxel plus
/// bitsets, so a block costs about 2.3 KB whatever its content; semantics live in a separate,
/// lazily allocated SemanticBlock because only a small part of a map is ever labelled.
struct OccupancyBlock {
  BlockKey key;
  /// Frame in which `touched` was last valid (see OccupancyGrid::BeginFrame).
  uint32_t touched_frame = 0;
  /// Any `changed` bit set (kept in sync by the grid).
  bool dirty = false;
  std::array<float, kBlockVoxels> log_odds{};  ///< 0 for unknown voxels
  BlockBits known;                             ///< observed at least once
  BlockBits touched;  ///< updated in frame `touched_frame` (one update per voxel per frame)
  BlockBits changed;  ///< updated since the last OccupancyGrid::ClearChanges()
  std::unique_ptr<SemanticBlock> semantics;  ///< null until a voxel gets semantic evidence

  VoxelState state(int i, float occupied_log_odds) const {
    if (!known.test(i)) return VoxelState::kUnknown;
    return log_odds[i] >= occupied_log_odds ? VoxelState::kOccupied : VoxelState::kFree;
  }
};

struct GridOptions {
  /// Voxel edge, 2 - 20 mm.
  double voxel_size_m = 0.005;
  /// When set, voxels whose centre lies outside this box are never stored (updates are dropped).
  std::optional<Box3> roi;
  SensorModel sensor;

  static constexpr double kMinVoxelSize = 0.002;
  static constexpr double kMaxVoxelSize = 0.020;
  /// Names every bad value.
  Status Validate() const;
};

/// The valid voxel edges, [kMinVoxelSize, kMaxVoxelSize] metres: every option that must match a
/// map's voxel size (ground truths, planners' caches) checks against this one range.
ValueRange VoxelSizeRange();

/// The fields of GridOptions: voxel_size_m and sensor.* (the ROI is set by code, not by
/// configuration, and checked by a rule).
const OptionTable<GridOptions>& GridOptionTable();

/// Sparse voxel grid of 8^3 blocks allocated on touch, found through an open-addressing hash
/// table; integer keys on the OctoMap lattice (avp::VoxelKey). Blocks are kept in allocation
/// order, so iteration (and everything written from it) is deterministic.
///
/// Thread safety: const methods may run concurrently. Mutation is single-threaded, except
/// that UpdateOnce through a NoAllocAccessor may run on several threads at once within one frame
/// once every block it reaches exists (the integrator's parallel path).
class OccupancyGrid {
 public:
  /// @throws avp::Error if options.Validate() fails.
  explicit OccupancyGrid(const GridOptions& options = {});
  OccupancyGrid(OccupancyGrid&&) noexcept;
  OccupancyGrid& operator=(OccupancyGrid&&) noexcept;
  ~OccupancyGrid();

  const GridOptions& options() const { return options_; }
  double voxel_size_m() const { return options_.voxel_size_m; }
  const SensorModel& sensor_model() const { return options_.sensor; }
  float hit_log_odds() const { return hit_; }
  float miss_log_odds() const { return miss_; }
  float clamp_min_log_odds() const { return clamp_min_; }
  float clamp_max_log_odds() const { return clamp_max_; }
  float occupied_log_odds() const { return occupied_; }

  VoxelKey KeyOf(const Eigen::Vector3d& p_W) const {
    return VoxelKey::FromPoint(p_W, options_.voxel_size_m);
  }
  Eigen::Vector3d CenterOf(const VoxelKey& k) const { return k.Center(options_.voxel_size_m); }
  /// The key is representable and (if an ROI is set) its centre lies in the ROI.
  bool Admits(const VoxelKey& k) const {
    if (!KeyInRange(k)) return false;
    if (!has_roi_) return true;
    return k.x >= roi_min_.x && k.x <= roi_max_.x && k.y >= roi_min_.y && k.y <= roi_max_.y &&
           k.z >= roi_min_.z && k.z <= roi_max_.z;
  }

  // ---- Queries -----------------------------------------------------------------------------
  VoxelState State(const VoxelKey& k) const;
  /// Log-odds of a known voxel; nullopt when unknown.
  std::optional<float> LogOdds(const VoxelKey& k) const;
  /// Semantic evidence of a voxel, or null when it has none (never inserts anything).
  const SemanticCell* Semantic(const VoxelKey& k) const;

  const OccupancyBlock* FindBlock(const BlockKey& b) const {
    const int32_t i = Lookup(b);
    return i < 0 ? nullptr : blocks_[static_cast<size_t>(i)].get();
  }
  size_t num_blocks() const { return blocks_.size(); }
  /// Blocks holding semantic payload.
  size_t num_semantic_blocks() const { return semantic_blocks_.size(); }
  /// Known (observed) voxels; O(blocks).
  size_t CountKnownVoxels() const;
  /// Occupied voxels; O(known voxels).
  size_t CountOccupiedVoxels() const;
  /// Voxels with a semantic label; O(semantic blocks).
  size_t CountSemanticVoxels() const;
  /// Bounding box of all known voxels (empty box when nothing is known).
  Box3 KnownBounds() const;
  /// Heap bytes held by blocks, semantic payload and the hash table.
  size_t MemoryBytes() const;

  /// fn(const OccupancyBlock&) for every block, in allocation order.
  template <typename F>
  void ForEachBlock(F&& fn) const {
    for (const auto& b : blocks_) fn(*b);
  }
  /// fn(VoxelKey, float log_odds) for every known voxel, block by block in allocation order.
  template <typename F>
  void ForEachKnownVoxel(F&& fn) const {
    for (const auto& b : blocks_) {
      b->known.ForEachSet([&](int i) { fn(mapping::KeyOf(b->key, i), b->log_odds[i]); });
    }
  }
  /// fn(VoxelKey, const SemanticCell&) for every labelled voxel; time proportional to the
  /// semantic blocks, not the map.
  template <typename F>
  void ForEachSemanticVoxel(F&& fn) const {
    for (const uint32_t bi : semantic_blocks_) {
      const OccupancyBlock& b = *blocks_[bi];
      for (int i = 0; i < kBlockVoxels; ++i) {
        const SemanticCell& c = (*b.semantics)[i];
        if (c.has_label()) fn(mapping::KeyOf(b.key, i), c);
      }
    }
  }

  // ---- Change tracking ---------------------------------------------------------------------
  /// Keys of blocks with a voxel updated since the last ClearChanges(), in allocation order.
  std::vector<BlockKey> DirtyBlocks() const;
  /// fn(VoxelKey, float log_odds) for every voxel updated since the last ClearChanges().
  template <typename F>
  void ForEachChangedVoxel(F&& fn) const {
    for (const auto& b : blocks_) {
      if (!b->dirty) continue;
      b->changed.ForEachSet([&](int i) { fn(mapping::KeyOf(b->key, i), b->log_odds[i]); });
    }
  }
  void ClearChanges();

  // ---- Updates -----------------------------------------------------------------------------
  /// Starts a new integration frame: until the next call, each voxel accepts at most one
  /// UpdateOnce (OctoMap's "one update per voxel per scan"). Returns the frame number (>= 1).
  uint32_t BeginFrame();
  uint32_t frame() const { return frame_; }

  /// Adds `delta` to the voxel's log-odds, clamped, unless it was already updated in this frame
  /// or is not admitted. Returns true when applied.
  bool UpdateOnce(const VoxelKey& k, float delta);
  /// Sets a voxel's log-odds (clamped) and marks it known, regardless of frames (file loading,
  /// tests). Returns false if the key is not admitted.
  bool SetLogOdds(const VoxelKey& k, float log_odds);
  /// Mutable semantic cell of a voxel, allocating the block's semantic payload on first use;
  /// null if the key is not admitted. A cell whose class is set to kBackground stops counting.
  SemanticCell* MutableSemantic(const VoxelKey& k);
  /// Removes every voxel and block.
  void Clear();
  /// Frees blocks that hold no known voxel and no semantic payload (e.g. allocated ahead of a
  /// parallel frame but never reached). Returns how many were freed.
  size_t ReleaseEmptyBlocks();

  /// Applies one update to a block voxel (the clamped log-odds sum), marking it known/changed.
  void ApplyUpdate(OccupancyBlock& b, int i, float delta) const {
    float v = b.log_odds[i] + delta;
    if (v < clamp_min_) v = clamp_min_;
    if (v > clamp_max_) v = clamp_max_;
    b.log_odds[i] = v;
  }

  /// Caches the last block: consecutive keys in the same block cost no hash probe. Allocates
  /// blocks on touch. Single-threaded.
  class Accessor {
   public:
    explicit Accessor(OccupancyGrid& grid) : grid_(&grid) {}
    OccupancyBlock* BlockFor(const VoxelKey& k) {
      const BlockKey bk = BlockOf(k);
      if (block_ == nullptr || !(bk == block_->key)) block_ = grid_->GetOrCreateBlock(bk);
      return block_;
    }
    bool UpdateOnce(const VoxelKey& k, float delta) {
      if (!grid_->Admits(k)) return false;
      OccupancyBlock* b = BlockFor(k);
      grid_->PrepareTouched(*b);
      const int i = LocalIndex(k);
      if (b->touched.test(i)) return false;
      b->touched.set(i);
      b->known.set(i);
      b->changed.set(i);
      b->dirty = true;
      grid_->ApplyUpdate(*b, i, delta);
      return true;
    }
    /// Whether the voxel was already updated in the current frame.
    bool TouchedThisFrame(const VoxelKey& k) {
      if (!grid_->Admits(k)) return true;
      const BlockKey bk = BlockOf(k);
      if (block_ == nullptr || !(bk == block_->key)) {
        const int32_t i = grid_->Lookup(bk);
        if (i < 0) return false;
        block_ = grid_->blocks_[static_cast<size_t>(i)].get();
      }
      return block_->touched_frame == grid_->frame_ && block_->touched.test(LocalIndex(k));
    }

   private:
    OccupancyGrid* grid_;
    OccupancyBlock* block_ = nullptr;
  };

  /// Like Accessor::UpdateOnce but never allocates and is safe to use from several threads at
  /// once inside one frame: the voxel's `touched` bit is claimed atomically and only the
  /// claiming thread writes its log-odds. Blocks must exist and be prepared for the frame
  /// (PrepareFrameBlocks); updates to missing or unprepared blocks are not applied: UpdateOnce
  /// returns false and sets last_missing() so the caller can apply them later, single-threaded.
  class NoAllocAccessor {
   public:
    explicit NoAllocAccessor(OccupancyGrid& grid) : grid_(&grid) {}
    bool UpdateOnce(const VoxelKey& k, float delta) {
      last_missing_ = false;
      if (!grid_->Admits(k)) return false;
      const BlockKey bk = BlockOf(k);
      if (block_ == nullptr || !(bk == block_->key)) {
        const int32_t bi = grid_->Lookup(bk);
        if (bi < 0) {
          ++missing_;
          last_missing_ = true;
          block_ = nullptr;
          return false;
        }
        block_ = grid_->blocks_[static_cast<size_t>(bi)].get();
        if (block_->touched_frame != grid_->frame_) {  // not prepared for this frame
          ++missing_;
          last_missing_ = true;
          block_ = nullptr;
          return false;
        }
      }
      const int i = LocalIndex(k);
      if (!block_->touched.atomic_test_and_set(i)) return false;
      block_->known.atomic_set(i);
      block_->changed.atomic_set(i);
      std::atomic_ref<bool>(block_->dirty).store(true, std::memory_order_relaxed);
      grid_->ApplyUpdate(*block_, i, delta);
      return true;
    }
    /// Updates not applied because their block was missing or unprepared.
    size_t missing_blocks() const { return missing_; }
    /// The last UpdateOnce was not applied because its block was missing or unprepared.
    bool last_missing() const { return last_missing_; }

   private:
    OccupancyGrid* grid_;
    OccupancyBlock* block_ = nullptr;
    size_t missing_ = 0;
    bool last_missing_ = false;
  };

  /// Allocates the given blocks if missing (sorted first, so allocation order is deterministic)
  /// and resets their per-frame touched bits. Single-threaded; call after BeginFrame().
  void PrepareFrameBlocks(std::vector<BlockKey>& keys);

  /// Resets a block's touched bits if they belong to an older frame.
  void PrepareTouched(OccupancyBlock& b) const {
    if (b.touched_frame != frame_) {
      b.touched.clear();
      b.touched_frame = frame_;
    }
  }

  OccupancyBlock* GetOrCreateBlock(const BlockKey& b);
  /// The block, or null; never allocates.
  OccupancyBlock* MutableBlock(const BlockKey& b) {
    const int32_t i = Lookup(b);
    return i < 0 ? nullptr : blocks_[static_cast<size_t>(i)].get();
  }
  /// A block key packed into 63 bits (21 per axis, offset by 2^20): the hash table's key.
  static uint64_t Pack(const BlockKey& b) {
    constexpr int64_t kOffset = int64_t{1} << 20;
    constexpr uint64_t kMask = (uint64_t{1} << 21) - 1;
    return (static_cast<uint64_t>(b.x + kOffset) & kMask) |
           ((static_cast<uint64_t>(b.y + kOffset) & kMask) << 21) |
           ((static_cast<uint64_t>(b.z + kOffset) & kMask) << 42);
  }
  /// Index of a block in allocation order, or -1.
  int32_t Lookup(const BlockKey& b) const {
    if (table_keys_.empty()) return -1;
    const uint64_t packed = Pack(b);
    size_t slot = Hash(packed) & table_mask_;
    while (true) {
      const uint64_t k = table_keys_[slot];
      if (k == packed) return table_index_[slot];
      if (k == kEmptySlot) return -1;
      slot = (slot + 1) & table_mask_;
    }
  }

 private:
  static constexpr uint64_t kEmptySlot = ~uint64_t{0};
  static size_t Hash(uint64_t packed) {
    return static_cast<size_t>((packed * 0x9E3779B97F4A7C15ULL) >> 17);
  }
  void Rehash(size_t capacity);
  void InsertIntoTable(uint64_t packed, int32_t index);

  GridOptions options_;
  float hit_, miss_, clamp_min_, clamp_max_, occupied_;
  bool has_roi_ = false;
  VoxelKey roi_min_, roi_max_;
  uint32_t frame_ = 0;
  std::vector<std::unique_ptr<OccupancyBlock>> blocks_;
  std::vector<uint32_t> semantic_blocks_;  ///< indices of blocks with semantic payload
  std::vector<uint64_t> table_keys_;
  std::vector<int32_t> table_index_;
  size_t table_mask_ = 0;
};

}  // namespace avp::mapping

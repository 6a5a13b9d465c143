#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::mapping {

std::string_view ToString(VoxelState state) {
  switch (state) {
    case VoxelState::kUnknown:
      return "unknown";
    case VoxelState::kFree:
      return "free";
    case VoxelState::kOccupied:
      return "occupied";
  }
  return "invalid";
}

ValueRange VoxelSizeRange() {
  return ValueRange::Closed(GridOptions::kMinVoxelSize, GridOptions::kMaxVoxelSize);
}

const OptionTable<GridOptions>& GridOptionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<GridOptions>("map grid option");
    t->Real("voxel_size_m", &GridOptions::voxel_size_m, "m", VoxelSizeRange(), "voxel edge");
    t->Nested("sensor", &GridOptions::sensor, SensorModelTable());
    t->AddRule([](const GridOptions& o, std::vector<std::string>& errors) {
      if (o.roi.has_value() &&
          (o.roi->IsEmpty() || !o.roi->min().allFinite() || !o.roi->max().allFinite())) {
        errors.push_back(
            fmt::format("roi ({}) must be a finite, non-empty box", o.roi->ToString()));
      }
    });
    return t;
  }();
  return *table;
}

Status GridOptions::Validate() const { return GridOptionTable().Validate(*this); }

OccupancyGrid::OccupancyGrid(const GridOptions& options) : options_(options) {
  const Status s = options.Validate();
  if (!s.ok()) throw Error(s.message());
  hit_ = options_.sensor.hit_log_odds();
  miss_ = options_.sensor.miss_log_odds();
  clamp_min_ = options_.sensor.clamp_min_log_odds();
  clamp_max_ = options_.sensor.clamp_max_log_odds();
  occupied_ = options_.sensor.occupied_log_odds();
  if (options_.roi.has_value()) {
    has_roi_ = true;
    // Keys whose centre (k + 0.5) s lies in [min, max]: k >= min/s - 0.5, k <= max/s - 0.5.
    const double s_m = options_.voxel_size_m;
    const Eigen::Vector3d lo = options_.roi->min() / s_m - Eigen::Vector3d::Constant(0.5);
    const Eigen::Vector3d hi = options_.roi->max() / s_m - Eigen::Vector3d::Constant(0.5);
    const auto clamp_key = [](double v) {
      return static_cast<int32_t>(std::clamp(v, -static_cast<double>(kMaxKeyMagnitude),
                                             static_cast<double>(kMaxKeyMagnitude)));
    };
    roi_min_ = {clamp_key(std::ceil(lo.x())), clamp_key(std::ceil(lo.y())),
                clamp_key(std::ceil(lo.z()))};
    roi_max_ = {clamp_key(std::floor(hi.x())), clamp_key(std::floor(hi.y())),
                clamp_key(std::floor(hi.z()))};
  }
}

OccupancyGrid::OccupancyGrid(OccupancyGrid&&) noexcept = default;
OccupancyGrid& OccupancyGrid::operator=(OccupancyGrid&&) noexcept = default;
OccupancyGrid::~OccupancyGrid() = default;

VoxelState OccupancyGrid::State(const VoxelKey& k) const {
  if (!KeyInRange(k)) return VoxelState::kUnknown;
  const OccupancyBlock* b = FindBlock(BlockOf(k));
  if (b == nullptr) return VoxelState::kUnknown;
  return b->state(LocalIndex(k), occupied_);
}

std::optional<float> OccupancyGrid::LogOdds(const VoxelKey& k) const {
  if (!KeyInRange(k)) return std::nullopt;
  const OccupancyBlock* b = FindBlock(BlockOf(k));
  if (b == nullptr) return std::nullopt;
  const int i = LocalIndex(k);
  if (!b->known.test(i)) return std::nullopt;
  return b->log_odds[i];
}

const SemanticCell* OccupancyGrid::Semantic(const VoxelKey& k) const {
  if (!KeyInRange(k)) return nullptr;
  const OccupancyBlock* b = FindBlock(BlockOf(k));
  if (b == nullptr || b->semantics == nullptr) return nullptr;
  const SemanticCell& c = (*b->semantics)[LocalIndex(k)];
  return c.has_label() || c.observations > 0 || c.misses > 0 ? &c : nullptr;
}

size_t OccupancyGrid::CountKnownVoxels() const {
  size_t n = 0;
  for (const auto& b : blocks_) n += static_cast<size_t>(b->known.count());
  return n;
}

size_t OccupancyGrid::CountOccupiedVoxels() const {
  size_t n = 0;
  for (const auto& b : blocks_) {
    b->known.ForEachSet([&](int i) { n += b->log_odds[i] >= occupied_ ? 1 : 0; });
  }
  return n;
}

size_t OccupancyGrid::CountSemanticVoxels() const {
  size_t n = 0;
  ForEachSemanticVoxel([&](const VoxelKey&, const SemanticCell&) { ++n; });
  return n;
}

Box3 OccupancyGrid::KnownBounds() const {
  bool any = false;
  VoxelKey lo{kMaxKeyMagnitude, kMaxKeyMagnitude, kMaxKeyMagnitude};
  VoxelKey hi{-kMaxKeyMagnitude, -kMaxKeyMagnitude, -kMaxKeyMagnitude};
  for (const auto& b : blocks_) {
    if (!b->known.any()) continue;
    b->known.ForEachSet([&](int i) {
      const VoxelKey k = mapping::KeyOf(b->key, i);
      lo = {std::min(lo.x, k.x), std::min(lo.y, k.y), std::min(lo.z, k.z)};
      hi = {std::max(hi.x, k.x), std::max(hi.y, k.y), std::max(hi.z, k.z)};
      any = true;
    });
  }
  if (!any) return Box3();
  const double s = options_.voxel_size_m;
  return Box3(Eigen::Vector3d(lo.x, lo.y, lo.z) * s,
              Eigen::Vector3d(hi.x + 1, hi.y + 1, hi.z + 1) * s);
}

size_t OccupancyGrid::MemoryBytes() const {
  size_t bytes =
      blocks_.capacity() * sizeof(blocks_[0]) + semantic_blocks_.capacity() * sizeof(uint32_t) +
      table_keys_.capacity() * sizeof(uint64_t) + table_index_.capacity() * sizeof(int32_t);
  for (const auto& b : blocks_) {
    bytes += sizeof(OccupancyBlock);
    if (b->semantics) bytes += sizeof(SemanticBlock);
  }
  return bytes;
}

std::vector<BlockKey> OccupancyGrid::DirtyBlocks() const {
  std::vector<BlockKey> out;
  for (const auto& b : blocks_) {
    if (b->dirty) out.push_back(b->key);
  }
  return out;
}

void OccupancyGrid::ClearChanges() {
  for (auto& b : blocks_) {
    if (!b->dirty) continue;
    b->changed.clear();
    b->dirty = false;
  }
}

uint32_t OccupancyGrid::BeginFrame() {
  ++frame_;
  if (frame_ == 0) {
    // 2^32 frames later: make sure no block believes its touched bits are current.
    for (auto& b : blocks_) {
      b->touched.clear();
      b->touched_frame = 0;
    }
    frame_ = 1;
  }
  return frame_;
}

bool OccupancyGrid::UpdateOnce(const VoxelKey& k, float delta) {
  Accessor acc(*this);
  return acc.UpdateOnce(k, delta);
}

bool OccupancyGrid::SetLogOdds(const VoxelKey& k, float log_odds) {
  if (!Admits(k) || !std::isfinite(log_odds)) return false;
  OccupancyBlock* b = GetOrCreateBlock(BlockOf(k));
  const int i = LocalIndex(k);
  b->log_odds[i] = std::clamp(log_odds, clamp_min_, clamp_max_);
  b->known.set(i);
  b->changed.set(i);
  b->dirty = true;
  return true;
}

SemanticCell* OccupancyGrid::MutableSemantic(const VoxelKey& k) {
  if (!Admits(k)) return nullptr;
  const BlockKey bk = BlockOf(k);
  int32_t index = Lookup(bk);
  if (index < 0) {
    GetOrCreateBlock(bk);
    index = Lookup(bk);
  }
  OccupancyBlock& b = *blocks_[static_cast<size_t>(index)];
  if (b.semantics == nullptr) {
    b.semantics = std::make_unique<SemanticBlock>();
    semantic_blocks_.push_back(static_cast<uint32_t>(index));
  }
  return &(*b.semantics)[LocalIndex(k)];
}

void OccupancyGrid::Clear() {
  blocks_.clear();
  semantic_blocks_.clear();
  table_keys_.clear();
  table_index_.clear();
  table_mask_ = 0;
}

size_t OccupancyGrid::ReleaseEmptyBlocks() {
  std::vector<std::unique_ptr<OccupancyBlock>> kept;
  kept.reserve(blocks_.size());
  size_t released = 0;
  for (auto& b : blocks_) {
    if (b->known.any() || b->semantics != nullptr) {
      kept.push_back(std::move(b));
    } else {
      ++released;
    }
  }
  if (released == 0) {
    blocks_ = std::move(kept);
    return 0;
  }
  blocks_ = std::move(kept);
  semantic_blocks_.clear();
  for (size_t i = 0; i < blocks_.size(); ++i) {
    if (blocks_[i]->semantics) semantic_blocks_.push_back(static_cast<uint32_t>(i));
  }
  Rehash(table_keys_.size());
  return released;
}

OccupancyBlock* OccupancyGrid::GetOrCreateBlock(const BlockKey& bk) {
  const int32_t found = Lookup(bk);
  if (found >= 0) return blocks_[static_cast<size_t>(found)].get();
  // Keep the load factor <= 1/2.
  if ((blocks_.size() + 1) * 2 > table_keys_.size()) {
    Rehash(std::max<size_t>(1024, table_keys_.size() * 2));
  }
  auto block = std::make_unique<OccupancyBlock>();
  block->key = bk;
  OccupancyBlock* raw = block.get();
  const auto index = static_cast<int32_t>(blocks_.size());
  blocks_.push_back(std::move(block));
  InsertIntoTable(Pack(bk), index);
  return raw;
}

void OccupancyGrid::InsertIntoTable(uint64_t packed, int32_t index) {
  size_t slot = Hash(packed) & table_mask_;
  while (table_keys_[slot] != kEmptySlot) slot = (slot + 1) & table_mask_;
  table_keys_[slot] = packed;
  table_index_[slot] = index;
}

void OccupancyGrid::Rehash(size_t capacity) {
  size_t cap = 1024;
  while (cap < capacity || cap < blocks_.size() * 2 + 2) cap *= 2;
  table_keys_.assign(cap, kEmptySlot);
  table_index_.assign(cap, -1);
  table_mask_ = cap - 1;
  for (size_t i = 0; i < blocks_.size(); ++i) {
    InsertIntoTable(Pack(blocks_[i]->key), static_cast<int32_t>(i));
  }
}

void OccupancyGrid::PrepareFrameBlocks(std::vector<BlockKey>& keys) {
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  for (const BlockKey& bk : keys) {
    OccupancyBlock* b = GetOrCreateBlock(bk);
    PrepareTouched(*b);
  }
}

}  // namespace avp::mapping

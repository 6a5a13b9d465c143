#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/camera.h>
#include <avp/core/options.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/voxel_key.h>
#include <avp/mapping/ray_traversal.h>
#include <avp/mapping/semantic_map.h>

namespace avp::planning {

/// Allocates blocks of 2 MiB and more 2 MiB-aligned and asks for transparent huge pages
/// (madvise): a gain grid is tens of MB, rebuilt every plan step, and walked in scattered order,
/// so 4 kB pages cost a page fault per 4 kB at Build and TLB misses during the walk.
template <typename T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() = default;
  template <typename U>
  HugePageAllocator(const HugePageAllocator<U>&) {}  // NOLINT(google-explicit-constructor)
  T* allocate(size_t n);
  void deallocate(T* p, size_t n);
  template <typename U>
  bool operator==(const HugePageAllocator<U>&) const {
    return true;
  }
};

/// Implemented in gain_grid.cpp (for uint32_t, the only instantiation).
void* AllocateHugePageBlock(size_t bytes);
void FreeHugePageBlock(void* p, size_t bytes);

template <typename T>
T* HugePageAllocator<T>::allocate(size_t n) {
  return static_cast<T*>(AllocateHugePageBlock(n * sizeof(T)));
}
template <typename T>
void HugePageAllocator<T>::deallocate(T* p, size_t n) {
  FreeHugePageBlock(p, n * sizeof(T));
}

/// What a gain evaluator knows about one voxel, copied from the map for one planning step.
/// Probabilities are quantised to 1/255 (QuantizeProbability), identically in GainGrid and in the
/// slow reference evaluators, so fast and slow results can be compared exactly.
struct GainVoxel {
  mapping::VoxelState state = mapping::VoxelState::kUnknown;
  /// Labelled class of the voxel (kBackground when it carries no label).
  SemanticClass cls = SemanticClass::kBackground;
  /// Occupancy probability: sigmoid(log-odds) for known voxels, 0.5 for unknown ones.
  float p_occ = 0.5f;
  /// Probability that the voxel is of the target class: its confidence when labelled with the
  /// target class, 0 otherwise.
  float p_target = 0.0f;
  /// Within GainGridOptions::near_target_radius_m of a voxel labelled with the target class.
  bool near_target = false;
  /// The voxel centre lies in the planning ROI.
  bool in_roi = false;
  /// The voxel lies on the predicted surface of a target instance (a sphere fitted to its
  /// voxels, FitTargetSpheres): where the unseen side of a detected fruit is expected.
  bool predicted_target = false;
};

/// A sphere fitted to the occupied voxels of one target-class instance.
struct TargetSphere {
  uint16_t instance_id = 0;
  Eigen::Vector3d center_W = Eigen::Vector3d::Zero();
  double radius_m = 0.0;
  size_t voxels = 0;
};

/// Least-squares (algebraic) spheres of the map's target-class instances with at least
/// `min_voxels` occupied voxels, in instance-id order; fits with a radius outside
/// [min_radius_m, max_radius_m] are left out (a fragment, or two merged fruits).
std::vector<TargetSphere> FitTargetSpheres(const mapping::SemanticMap& map, SemanticClass target,
                                           size_t min_voxels = 12, double min_radius_m = 0.01,
                                           double max_radius_m = 0.08);

/// True when the centre of voxel `k` lies within half a voxel (0.6 voxel) of a sphere's
/// surface.
bool OnTargetSphere(const VoxelKey& k, double voxel_size_m,
                    const std::vector<TargetSphere>& spheres);

/// p rounded to the nearest multiple of 1/255 (p clamped into [0, 1]).
float QuantizeProbability(double p);

/// The GainVoxel of key `k`, read from the map directly (the slow path the reference evaluators
/// use). `near_target` is computed by scanning the radius around `k` (slow: for tests).
GainVoxel ReadGainVoxel(const mapping::SemanticMap& map, const VoxelKey& k, SemanticClass target,
                        const Box3& roi, double near_target_radius_m,
                        const std::vector<TargetSphere>* spheres = nullptr);

struct GainGridOptions {
  /// Unknown voxels this close to a target-labelled voxel count as "near the target".
  double near_target_radius_m = 0.04;
  /// Refuse to build grids larger than this: the box's voxels times 4 bytes (the bricked layout
  /// pads each axis to whole bricks, at most brick edge - 1 voxels more, not counted).
  size_t max_bytes = size_t{1} << 30;
  /// Mark the predicted surfaces of the target instances (GainVoxel::predicted_target).
  bool predict_target_surface = true;
  /// log2 of the brick edge in voxels, in [0, 4]: 3 stores the cells in 8 x 8 x 8 bricks (2 kB,
  /// brick-major), so a ray's consecutive voxels share cache lines and pages; 0 is the plain
  /// dense layout (x fastest). Results do not depend on it.
  int brick_shift = 3;
  /// Flag the bricks whose voxels are all known free, for WalkSkippingFree (only with
  /// brick_shift > 0). Results do not depend on it. Off by default: on scenario maps carved
  /// space is interleaved with unknown voxels at the brick scale (< 1 % of the bricks all free),
  /// and the flag test per voxel cost more than the skipping saved (docs/planning.md).
  bool skip_free_bricks = false;
};

/// The configurable fields of GainGridOptions: near_target_radius_m and predict_target_surface
/// (max_bytes, brick_shift and skip_free_bricks are the implementation's, results do not depend
/// on them).
const OptionTable<GainGridOptions>& GainGridOptionTable();

/// A copy of the map over the known voxels' bounding box (inflated by the near-target radius),
/// 4 bytes per voxel in bricks of 2^brick_shift voxels a side, for gain evaluation. Voxels
/// outside it read as unknown, not near the target (exact: everything outside the known bounds is
/// unknown). Read-only after Build; safe to share between threads.
class GainGrid {
 public:
  GainGrid() = default;
  static Result<GainGrid> Build(const mapping::SemanticMap& map, SemanticClass target,
                                const Box3& roi, const GainGridOptions& options = {});

  double voxel_size_m() const { return voxel_size_m_; }
  const Box3& roi() const { return roi_; }
  SemanticClass target() const { return target_; }
  /// The grid's box: keys min_key() + [0, dims()) are stored, every other key reads as unknown.
  const VoxelKey& min_key() const { return min_; }
  const Eigen::Vector3i& dims() const { return dims_; }
  /// Brick edge in voxels (1: the dense layout).
  int brick_edge() const { return 1 << brick_shift_; }
  /// Bricks flagged all-free (WalkSkippingFree jumps over them), and bricks in all.
  size_t free_bricks() const;
  size_t bricks() const { return cells_.size() >> (3 * brick_shift_); }

  /// Equal to ReadGainVoxel(map, k, ...) for the map it was built from. Inline: the gain
  /// evaluators call it once per voxel of every ray.
  GainVoxel At(const VoxelKey& k) const {
    const int64_t i = IndexOf(k);
    return Decode(k, i < 0 || roi_.Contains(k.Center(voxel_size_m_)) ? i : i | kNotInRoi);
  }

  /// Walks the segment [from, to) voxel by voxel (the voxel of `to` is not visited, as
  /// PlanningSnapshot::CastRay), calling visit(const VoxelKey&, const GainVoxel&) -> bool; stops
  /// when it returns false. Returns the voxels visited.
  ///
  /// The walk prefetches each voxel's cell kWalkAhead voxels before visiting it. A ray's cells are
  /// scattered over the grid and their cache misses, not the arithmetic, were the cost (as in
  /// PlanningSnapshot::CastRay); the visits and their order are those of the voxel-by-voxel walk
  /// (RayWalker::ForEachKeyBeforeEnd).
  template <typename Visitor>
  int64_t Walk(const Eigen::Vector3d& from, const Eigen::Vector3d& to, Visitor&& visit) const {
    return Run<false>(from, to, visit);
  }

  /// Walk, except that the free voxels of bricks flagged all-free (GainGridOptions::
  /// skip_free_bricks) are not visited: the walk passes through such a brick without reading
  /// its cells. For visitors to which a free voxel is a no-op (returns true, changes nothing),
  /// such as the avp-nbv gain: every other voxel is visited exactly as by Walk, in the same
  /// order, and the return value is Walk's (the voxels walked through, skipped ones included, up
  /// to the one where visit returned false). Without flags (brick_shift 0, or skipping off) it is
  /// Walk.
  template <typename Visitor>
  int64_t WalkSkippingFree(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                           Visitor&& visit) const {
    if (free_brick_.empty()) return Run<false>(from, to, visit);
    return Run<true>(from, to, visit);
  }

 private:
  static constexpr unsigned kWalkAhead = 64;  // a power of 2

  template <bool kSkipFree, typename Visitor>
  int64_t Run(const Eigen::Vector3d& from, const Eigen::Vector3d& to, Visitor& visit) const {
    const mapping::RayWalker w(from, to, voxel_size_m_);
    if (!w.ok()) return 0;
    const int brick_cell_bits = 3 * brick_shift_;
    // A ring of the last kWalkAhead voxels walked: each is visited kWalkAhead voxels after its
    // cell's prefetch.
    constexpr unsigned kMask = kWalkAhead - 1;
    VoxelKey keys[kWalkAhead];
    int64_t index[kWalkAhead];
    int64_t ordinal[kWalkAhead];  // position in the walk (skipped voxels included)
    unsigned head = 0, tail = 0;  // pushed, visited (wrapping counters)
    int64_t walked = 0;
    int64_t stopped = -1;  // the return value once visit returned false
    auto visit_tail = [&] {
      const unsigned j = tail++ & kMask;
      if (visit(keys[j], Decode(keys[j], index[j]))) return true;
      stopped = ordinal[j] + 1;
      return false;
    };
    const int64_t* const tx = axis_[0].data();
    const int64_t* const ty = axis_[1].data();
    const int64_t* const tz = axis_[2].data();
    const uint64_t nx = static_cast<uint64_t>(dims_.x()), ny = static_cast<uint64_t>(dims_.y()),
                   nz = static_cast<uint64_t>(dims_.z());
    // Copies: the ring's int stores could alias the members, which would be reloaded.
    const int64_t x0 = min_.x, y0 = min_.y, z0 = min_.z;
    const uint8_t* const free_brick = free_brick_.data();
    const uint32_t* const cells = cells_.data();
    w.ForEachKeyBeforeEnd([&](const VoxelKey& k) {
      // Inside the box, the cell index and in_roi from the per-axis tables (axis_).
      const auto rx = static_cast<uint64_t>(int64_t{k.x} - x0);
      const auto ry = static_cast<uint64_t>(int64_t{k.y} - y0);
      const auto rz = static_cast<uint64_t>(int64_t{k.z} - z0);
      int64_t i = -1;
      if (rx < nx && ry < ny && rz < nz) i = tx[rx] + ty[ry] + tz[rz];
      const int64_t at = walked++;
      if constexpr (kSkipFree) {
        if (i >= 0 &&
            free_brick[static_cast<size_t>((i & (kNotInRoi - 1)) >> brick_cell_bits)] != 0) {
          return true;
        }
      }
      if (head - tail == kWalkAhead && !visit_tail()) return false;
      const unsigned j = head++ & kMask;
      keys[j] = k;
      index[j] = i;
      ordinal[j] = at;
      if (i >= 0) __builtin_prefetch(&cells[static_cast<size_t>(i & (kNotInRoi - 1))]);
      return true;
    });
    while (stopped < 0 && tail != head) visit_tail();
    return stopped >= 0 ? stopped : walked;
  }

  /// The index of k's cell, or -1 outside the grid. Brick-major (bricks x fastest), x fastest
  /// inside a brick; brick_shift 0 gives x + nx (y + ny z).
  int64_t IndexOf(const VoxelKey& k) const {
    const int64_t x = int64_t{k.x} - min_.x;
    const int64_t y = int64_t{k.y} - min_.y;
    const int64_t z = int64_t{k.z} - min_.z;
    if (x < 0 || y < 0 || z < 0 || x >= dims_.x() || y >= dims_.y() || z >= dims_.z()) return -1;
    const int b = brick_shift_;
    const int64_t m = (int64_t{1} << b) - 1;
    const int64_t brick = (x >> b) + bdims_.x() * ((y >> b) + int64_t{bdims_.y()} * (z >> b));
    return (brick << (3 * b)) | ((z & m) << (2 * b)) | ((y & m) << b) | (x & m);
  }

  /// The GainVoxel of key k whose cell index is `index` (-1: outside the grid; bit kNotInRoiBit
  /// set: the voxel centre lies outside the ROI, as the axis tables give it).
  GainVoxel Decode(const VoxelKey& k, int64_t index) const {
    GainVoxel v;
    if (index < 0) {
      v.in_roi = roi_.Contains(k.Center(voxel_size_m_));
      return v;
    }
    v.in_roi = index < kNotInRoi;
    const uint32_t c = cells_[static_cast<size_t>(index & (kNotInRoi - 1))];
    v.state = static_cast<mapping::VoxelState>(c & kStateMask);
    v.cls = static_cast<SemanticClass>((c >> kClassShift) & kClassMask);
    v.near_target = (c & kNearTargetBit) != 0;
    v.predicted_target = (c & kPredictedTargetBit) != 0;
    // Unknown voxels read 0.5 exactly (GainVoxel's default), known ones their quantised p.
    if (v.state != mapping::VoxelState::kUnknown) {
      v.p_occ = static_cast<float>((c >> kOccShift) & 0xff) / 255.0f;
    }
    v.p_target = static_cast<float>((c >> kTargetShift) & 0xff) / 255.0f;
    return v;
  }

  /// Build's stages (gain_grid.cpp).
  struct Builder;

  static constexpr uint32_t kStateMask = 0x3;
  static constexpr int kClassShift = 2;
  static constexpr uint32_t kClassMask = 0x7;
  static constexpr uint32_t kNearTargetBit = uint32_t{1} << 5;
  static constexpr uint32_t kPredictedTargetBit = uint32_t{1} << 6;
  static constexpr int kOccShift = 8;
  static constexpr int kTargetShift = 16;
  /// Added to a cell index (by the axis tables, or At) when the voxel centre is outside the ROI.
  static constexpr int64_t kNotInRoi = int64_t{1} << 50;

  double voxel_size_m_ = mapping::GridOptions{}.voxel_size_m;
  SemanticClass target_ = SemanticClass::kFruit;
  Box3 roi_;
  VoxelKey min_;
  Eigen::Vector3i dims_ = Eigen::Vector3i::Zero();
  int brick_shift_ = 0;
  /// Bricks per axis: dims_ rounded up to whole bricks.
  Eigen::Vector3i bdims_ = Eigen::Vector3i::Zero();
  /// Packed per voxel: bits 0-1 state, 2-4 class, 5 near_target, 6 predicted_target; bits 8-15
  /// p_occ * 255; bits 16-23 p_target * 255. In IndexOf's order; the padding of the last bricks
  /// of each axis reads 0 (unknown) and is never addressed.
  std::vector<uint32_t, HugePageAllocator<uint32_t>> cells_;
  /// Per axis, over the box: the cell index contribution of the coordinate (IndexOf is their sum)
  /// plus kNotInRoi when its voxel centre coordinate lies outside the ROI's range on that axis
  /// (Box3::Contains is per axis: in_roi is "no kNotInRoi in the sum").
  std::vector<int64_t> axis_[3];
  /// Per brick: 1 when all its voxels are known free (padding makes a brick not free). Empty
  /// without skipping.
  std::vector<uint8_t> free_brick_;
};

/// Unit ray directions in the camera frame through every `stride`-th pixel centre of K (u, v =
/// stride/2, stride/2 + stride, ...), row by row.
std::vector<Eigen::Vector3d> RayDirections(const CameraIntrinsics& K, int stride);

}  // namespace avp::planning

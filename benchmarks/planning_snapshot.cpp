#include "planning_snapshot.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include <avp/mapping/ray_traversal.h>

namespace avp::mapping {

Result<PlanningSnapshot> PlanningSnapshot::Build(const OccupancyGrid& grid, const Box3& box_W,
                                                 size_t max_bytes) {
  if (box_W.IsEmpty() || !box_W.min().allFinite() || !box_W.max().allFinite()) {
    return InvalidArgumentError(
        fmt::format("planning snapshot box ({}) must be finite and non-empty", box_W.ToString()));
  }
  const double s = grid.voxel_size_m();
  // Voxels whose centre lies in the box.
  const Eigen::Vector3d lo = (box_W.min() / s).array() - 0.5;
  const Eigen::Vector3d hi = (box_W.max() / s).array() - 0.5;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(lo[a]) >= kMaxKeyMagnitude || std::abs(hi[a]) >= kMaxKeyMagnitude) {
      return OutOfRangeError(
          fmt::format("planning snapshot box ({}) exceeds the key range", box_W.ToString()));
    }
  }
  PlanningSnapshot snap;
  snap.voxel_size_m_ = s;
  snap.min_ = {static_cast<int32_t>(std::ceil(lo.x())), static_cast<int32_t>(std::ceil(lo.y())),
               static_cast<int32_t>(std::ceil(lo.z()))};
  const VoxelKey max_key{static_cast<int32_t>(std::floor(hi.x())),
                         static_cast<int32_t>(std::floor(hi.y())),
                         static_cast<int32_t>(std::floor(hi.z()))};
  const int64_t nx = int64_t{max_key.x} - snap.min_.x + 1;
  const int64_t ny = int64_t{max_key.y} - snap.min_.y + 1;
  const int64_t nz = int64_t{max_key.z} - snap.min_.z + 1;
  if (nx <= 0 || ny <= 0 || nz <= 0) {
    return InvalidArgumentError(fmt::format(
        "planning snapshot box ({}) contains no voxel centre at {} m", box_W.ToString(), s));
  }
  const int64_t bx_count = (nx + 7) / 8, by_count = (ny + 7) / 8, bz_count = (nz + 7) / 8;
  const double bytes = static_cast<double>(bx_count) * static_cast<double>(by_count) *
                       static_cast<double>(bz_count) * 512.0;
  if (bytes > static_cast<double>(max_bytes)) {
    return InvalidArgumentError(fmt::format(
        "planning snapshot of {} x {} x {} voxels ({:.0f} MB) exceeds max_bytes ({:.0f} MB): use a "
        "smaller box or a coarser map",
        nx, ny, nz, bytes / 1e6, static_cast<double>(max_bytes) / 1e6));
  }
  snap.dims_ = Eigen::Vector3i(static_cast<int>(nx), static_cast<int>(ny), static_cast<int>(nz));
  snap.sx_ = bx_count;
  snap.sy_ = by_count;
  snap.cells_.assign(static_cast<size_t>(bytes), 0);
  const int64_t n[3] = {nx, ny, nz};
  for (int a = 0; a < 3; ++a) {
    std::vector<int64_t>& t = snap.axis_offsets_[a];
    t.assign(static_cast<size_t>(n[a] + 2 * kPad), kOutsideOffset);
    for (int64_t i = 0; i < n[a]; ++i) {
      t[static_cast<size_t>(i + kPad)] =
          static_cast<int64_t>(snap.Index(a == 0 ? i : 0, a == 1 ? i : 0, a == 2 ? i : 0));
    }
  }

  const float occ = grid.occupied_log_odds();
  grid.ForEachBlock([&](const OccupancyBlock& b) {
    const int64_t bx = int64_t{b.key.x} * kBlockEdge - snap.min_.x;
    const int64_t by = int64_t{b.key.y} * kBlockEdge - snap.min_.y;
    const int64_t bz = int64_t{b.key.z} * kBlockEdge - snap.min_.z;
    if (bx + kBlockEdge <= 0 || by + kBlockEdge <= 0 || bz + kBlockEdge <= 0 || bx >= nx ||
        by >= ny || bz >= nz) {
      return;
    }
    b.known.ForEachSet([&](int i) {
      const int64_t x = bx + (i & 7), y = by + ((i >> 3) & 7), z = bz + (i >> 6);
      if (x < 0 || y < 0 || z < 0 || x >= nx || y >= ny || z >= nz) return;
      uint8_t cell = b.log_odds[i] >= occ ? static_cast<uint8_t>(VoxelState::kOccupied)
                                          : static_cast<uint8_t>(VoxelState::kFree);
      if (b.semantics != nullptr) {
        const uint8_t cls = (*b.semantics)[i].semantic_class;
        cell = static_cast<uint8_t>(cell | (std::min<uint8_t>(cls, 7) << kClassShift));
      }
      snap.cells_[snap.Index(x, y, z)] = cell;
    });
  });
  return snap;
}

Result<PlanningSnapshot> PlanningSnapshot::BuildOverKnown(const OccupancyGrid& grid,
                                                          size_t max_bytes) {
  const Box3 known = grid.KnownBounds();
  if (known.IsEmpty()) {
    return FailedPreconditionError("planning snapshot: the map has no known voxel");
  }
  return Build(grid, known, max_bytes);
}

Box3 PlanningSnapshot::box() const {
  if (cells_.empty()) return Box3();
  const double s = voxel_size_m_;
  return Box3(Eigen::Vector3d(min_.x, min_.y, min_.z) * s,
              Eigen::Vector3d(int64_t{min_.x} + dims_.x(), int64_t{min_.y} + dims_.y(),
                              int64_t{min_.z} + dims_.z()) *
                  s);
}

namespace {

/// RayWalker's decisions on three pairwise differences d_ij = N_i A_j - N_j A_i (axis i steps
/// before j iff d_ij <= 0; a step along i adds 2^16 A_j to d_ij and subtracts it from d_ji), with
/// the key relative to the snapshot's box. No exhaustion guard is needed: an exhausted axis's next
/// crossing lies beyond the end point (t > 1; the t == 1 tie goes to CastRayGuarded), every
/// pending crossing at t <= 1, and the walk stops after exactly remaining() steps.
struct Dda {
  int64_t dxy, dxz, dyz;
  int64_t ax, ay, az;  ///< 2^16 A_i
  int64_t sx, sy, sz;
  int64_t relx, rely, relz;

  [[gnu::always_inline]] void Step() {
    const bool x_first = (dxy <= 0) & (dxz <= 0);
    const bool y_first = !x_first & (dyz <= 0);
    const int64_t mx = -static_cast<int64_t>(x_first), my = -static_cast<int64_t>(y_first),
                  mz = ~(mx | my);
    relx += sx & mx;
    rely += sy & my;
    relz += sz & mz;
    dxy += (ay & mx) - (ax & my);
    dxz += (az & mx) - (ax & mz);
    dyz += (az & my) - (ay & mz);
  }

  /// Each key coordinate is monotone along the ray, so the ray meets the box in one run of voxels
  /// at most: walks up to it. False when the ray never enters the box or `left` runs out first.
  [[gnu::always_inline]] bool WalkToBox(int64_t nx, int64_t ny, int64_t nz, int64_t& left) {
    while (!(static_cast<uint64_t>(relx) < static_cast<uint64_t>(nx) &&
             static_cast<uint64_t>(rely) < static_cast<uint64_t>(ny) &&
             static_cast<uint64_t>(relz) < static_cast<uint64_t>(nz))) {
      // Outside, before the box: stop as soon as one coordinate is outside on the side the ray
      // moves away to (or does not move): it never enters.
      const bool never = (relx < 0 && sx <= 0) || (relx >= nx && sx >= 0) ||
                         (rely < 0 && sy <= 0) || (rely >= ny && sy >= 0) ||
                         (relz < 0 && sz <= 0) || (relz >= nz && sz >= 0);
      if (never || --left == 0) return false;
      Step();
    }
    return true;
  }
};

}  // namespace

PlanningSnapshot::RayCounts PlanningSnapshot::CastRay(const Eigen::Vector3d& from,
                                                      const Eigen::Vector3d& to) const {
  RayCounts c;
  if (cells_.empty()) return c;
  const RayWalker w(from, to, voxel_size_m_);
  if (!w.ok()) return c;
  int64_t left = w.remaining();  // voxels to visit: the start voxel up to (excluding) the end's
  if (left == 0) return c;
  if (w.exhausted_tie_) return CastRayGuarded(w);

  Dda d{w.diff_[0],
        w.diff_[1],
        w.diff_[2],
        w.inc_[1][0],
        w.inc_[0][1],
        w.inc_[0][2],
        w.step_[0],
        w.step_[1],
        w.step_[2],
        int64_t{w.key_[0]} - min_.x,
        int64_t{w.key_[1]} - min_.y,
        int64_t{w.key_[2]} - min_.z};
  const int64_t total = left;
  if (!d.WalkToBox(dims_.x(), dims_.y(), dims_.z(), left)) {
    c.visited = c.unknown = static_cast<uint32_t>(total);
    return c;
  }
  RayWalker::Differences diff = w.differences();
  diff.dxy = d.dxy;
  diff.dxz = d.dxz;
  diff.dyz = d.dyz;
  const int64_t sx = d.sx, sy = d.sy, sz = d.sz;
  const int64_t relx = d.relx, rely = d.rely, relz = d.relz;

  // Inside: the cell offset is a sum of three per-axis table entries, walked by pointer; leaving
  // the box lands on a kOutsideOffset entry, so one compare tests the box. The walk goes in
  // chunks: the offsets of up to kChunk voxels first (the DDA alone, no memory dependence), then
  // their cells, whose loads are independent of each other and overlap.
  const int64_t* px = axis_offsets_[0].data() + kPad + relx;
  const int64_t* py = axis_offsets_[1].data() + kPad + rely;
  const int64_t* pz = axis_offsets_[2].data() + kPad + relz;
  const uint8_t* const cells = cells_.data();
  const uint64_t size = cells_.size();
  uint64_t offsets[kChunk];
  uint32_t free = 0;
  while (true) {
    const int n = static_cast<int>(std::min<int64_t>(left, kChunk));
    for (int i = 0; i < n; ++i) {
      const uint64_t offset = static_cast<uint64_t>(*px + *py + *pz);
      offsets[i] = offset;
      // Start the cell's load now (a prefetch never faults, so offsets past the box are harmless).
      __builtin_prefetch(
          reinterpret_cast<const void*>(reinterpret_cast<uintptr_t>(cells) + offset));
      const auto [mx, my, mz] = diff.Step();
      px += sx & mx;
      py += sy & my;
      pz += sz & mz;
    }
    for (int i = 0; i < n; ++i) {
      const uint64_t offset = offsets[i];
      if (offset >= size) [[unlikely]] {  // left the box: the rest is unknown
        left = 0;
        goto done;
      }
      const uint8_t cell = cells[offset];
      const uint32_t state = cell & kStateMask;
      if (state == static_cast<uint32_t>(VoxelState::kOccupied)) [[unlikely]] {
        c.hit = true;
        c.hit_class = static_cast<uint8_t>(cell >> kClassShift);
        left -= i + 1;
        goto done;
      }
      free += state;  // kFree == 1, kUnknown == 0
    }
    left -= n;
    if (left == 0) break;
  }
done:
  const uint32_t visited = static_cast<uint32_t>(total - left);
  c.free = free;
  c.visited = visited;
  c.unknown = visited - free - (c.hit ? 1u : 0u);
  return c;
}

PlanningSnapshot::RayCounts PlanningSnapshot::CastRayGuarded(const RayWalker& w) const {
  // RayWalker's decisions exactly, exhausted axes included: its own register walk
  // (ForEachKeyBeforeEnd, the keys of Step()), with the position relative to the box as unsigned
  // so that one compare per axis tests 0 <= rel < dim.
  RayCounts c;
  const uint64_t dx = static_cast<uint64_t>(dims_.x()), dy = static_cast<uint64_t>(dims_.y()),
                 dz = static_cast<uint64_t>(dims_.z());
  const uint8_t* cells = cells_.data();
  uint32_t unknown = 0, free = 0, visited = 0;
  w.ForEachKeyBeforeEnd([&](const VoxelKey& k) {
    const int64_t relx = int64_t{k.x} - min_.x, rely = int64_t{k.y} - min_.y,
                  relz = int64_t{k.z} - min_.z;
    const bool inside = static_cast<uint64_t>(relx) < dx && static_cast<uint64_t>(rely) < dy &&
                        static_cast<uint64_t>(relz) < dz;
    const uint8_t cell = inside ? cells[Index(relx, rely, relz)] : uint8_t{0};
    const uint32_t state = cell & kStateMask;
    ++visited;
    if (state == static_cast<uint32_t>(VoxelState::kOccupied)) {
      c.hit = true;
      c.hit_class = static_cast<uint8_t>(cell >> kClassShift);
      return false;
    }
    free += state;  // kFree == 1, kUnknown == 0
    unknown += 1u - state;
    return true;
  });
  c.unknown = unknown;
  c.free = free;
  c.visited = visited;
  return c;
}

}  // namespace avp::mapping

#pragma once

// The avp side of bench_map's NBV view evaluation rows (docs/benchmarks.md, "The planning
// snapshot"): a one-byte-per-voxel copy of the map and a ray cast against it, timed against
// OctoMap's computeRayKeys + search. Not part of the mapping library (the planner reads the map
// through planning's GainGrid). It stays in avp::mapping because RayWalker befriends it: CastRay
// runs the walker's decisions in registers.

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/status.h>
#include <avp/core/voxel_key.h>
#include <avp/mapping/ray_traversal.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::mapping {

/// A dense, read-only copy of the map over a box, one byte per voxel (in 8^3 bricks), for view
/// evaluation:
/// bits 0-1 hold the VoxelState, bits 2-4 the semantic class of labelled voxels (0 = none).
/// Voxels outside the box read as unknown; build the box over KnownBounds() (the default) and
/// that is exact.
class PlanningSnapshot {
 public:
  static constexpr uint8_t kStateMask = 0x3;
  static constexpr int kClassShift = 2;

  /// Counts of one ray: voxels visited before the first occupied one, by state and class.
  struct RayCounts {
    uint32_t unknown = 0;
    uint32_t free = 0;
    /// Visited voxels (unknown + free + the occupied one, if hit).
    uint32_t visited = 0;
    /// The ray stopped at an occupied voxel.
    bool hit = false;
    /// Class of the occupied voxel it stopped at (0 = none / no hit).
    uint8_t hit_class = 0;
  };

  PlanningSnapshot() = default;

  /// Copies `grid` over the voxels whose centres lie in `box_W` (the ROI). Fails with a clear
  /// error when the box is empty or would need more than `max_bytes`.
  static Result<PlanningSnapshot> Build(const OccupancyGrid& grid, const Box3& box_W,
                                        size_t max_bytes = size_t{1} << 30);
  /// Build() over the bounding box of every known voxel (exact: everything outside is unknown).
  static Result<PlanningSnapshot> BuildOverKnown(const OccupancyGrid& grid,
                                                 size_t max_bytes = size_t{1} << 30);

  double voxel_size_m() const { return voxel_size_m_; }
  VoxelKey min_key() const { return min_; }
  /// Voxels per axis.
  Eigen::Vector3i dims() const { return dims_; }
  /// Bytes held (the box rounded up to whole 8^3 bricks).
  size_t bytes() const { return cells_.size(); }
  Box3 box() const;

  uint8_t Cell(const VoxelKey& k) const {
    const int64_t x = int64_t{k.x} - min_.x, y = int64_t{k.y} - min_.y, z = int64_t{k.z} - min_.z;
    if (x < 0 || y < 0 || z < 0 || x >= dims_.x() || y >= dims_.y() || z >= dims_.z()) return 0;
    return cells_[Index(x, y, z)];
  }
  VoxelState State(const VoxelKey& k) const {
    return static_cast<VoxelState>(Cell(k) & kStateMask);
  }

  /// Walks the segment [from, to) like OctoMap's computeRayKeys + search (the voxel of `to` is not
  /// visited), counting unknown and free voxels until the first occupied one (which is counted in
  /// `visited` and stops the ray). Exact integer traversal (RayWalker); voxels outside the box
  /// are unknown and cost no memory access.
  RayCounts CastRay(const Eigen::Vector3d& from, const Eigen::Vector3d& to) const;

 private:
  /// CastRay with RayWalker's exhaustion guards, for the rare rays whose end point lies exactly
  /// on a voxel face that an exhausted axis would cross on a tie.
  RayCounts CastRayGuarded(const RayWalker& w) const;

  double voxel_size_m_ = 0.0;
  VoxelKey min_;
  Eigen::Vector3i dims_ = Eigen::Vector3i::Zero();
  /// Cells are stored in 8^3 bricks of 512 bytes (x fastest inside a brick, bricks x-fastest),
  /// so a ray crossing a brick stays within 8 cache lines.
  size_t Index(int64_t x, int64_t y, int64_t z) const {
    return static_cast<size_t>((((x >> 3) + sx_ * ((y >> 3) + sy_ * (z >> 3))) << 9) | (x & 7) |
                               ((y & 7) << 3) | ((z & 7) << 6));
  }
  int64_t sx_ = 0, sy_ = 0;  ///< bricks along x and y
  std::vector<uint8_t> cells_;
  /// CastRay walks the ray in chunks of this many steps: first the cell offsets (pure integer
  /// work), then the cells (independent loads the CPU overlaps).
  static constexpr int kChunk = 32;
  /// Index(x, y, z) == axis_offsets_[0][x + kPad] + axis_offsets_[1][y + kPad] +
  /// axis_offsets_[2][z + kPad] for coordinates inside the box; the kPad entries on either side
  /// are kOutsideOffset, so any sum that involves one is >= cells_.size() (a one-compare box
  /// test), and a chunk that walks on past the box stays inside the table.
  static constexpr int kPad = kChunk + 1;
  static constexpr int64_t kOutsideOffset = int64_t{1} << 40;
  std::vector<int64_t> axis_offsets_[3];
};

}  // namespace avp::mapping

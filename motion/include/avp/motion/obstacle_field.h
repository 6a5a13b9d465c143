#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/status.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::motion {

/// A sphere (a body's cover in the body's frame, or a region of space in the world frame).
struct Sphere {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double radius = 0.0;
};

/// What the map contributes to the world the planner may not touch.
struct ObstacleFieldOptions {
  /// Edge of the field's cells (metres), 0.002 - 0.1. A cell is an obstacle when any obstacle
  /// voxel overlaps it (so the field over-approximates the obstacles by less than one cell).
  double resolution_m = 0.01;
  /// Unknown voxels inside the region of interest are obstacles: the robot does not know what is
  /// in foliage it has not seen. Unknown voxels outside it are free (the map's empty space).
  bool unknown_is_obstacle = true;
  /// With unknown_is_obstacle: when > 0, only unknown voxels within this distance (metres) of an
  /// occupied one are obstacles (the unseen space next to what the camera saw of the plant);
  /// 0: every unknown voxel in the ROI.
  double unknown_band_m = 0.0;
  /// Unknown space on the robot's side of the episode's first camera position is free: the robot
  /// starts in front of the plant, with nothing of it between the camera and the base
  /// (CollisionChecker::SetStartView). Off: only the space the arm swept is.
  bool unknown_behind_start_is_free = true;
  /// The arm's start pose has at least this much free space (metres) around its bodies: the
  /// operator placed it there, clear of the plant, and the camera cannot see what is that close
  /// (CollisionChecker::MarkStart). 0: only the space the bodies fill is free, and the first
  /// move keeps the start's own clearance from everything unseen.
  double start_clearance_m = 0.02;
  /// Distances are resolved up to this (metres, and at most 4096 cells); beyond it the field
  /// reports this value (a lower bound). The EDT runs over the whole grid whatever the cap.
  double max_distance_m = 0.3;
  /// At most this many cells (memory: 4 bytes each, 5 while building); a larger region is
  /// refused.
  int64_t max_cells = 64'000'000;

  Status Validate() const;
};

/// A Euclidean distance field over the map's obstacles: occupied voxels anywhere in `bounds`, and
/// (unknown_is_obstacle) unknown voxels inside the region of interest, minus the cells the caller
/// declares free (the space the arm itself has occupied: it was there, so nothing is).
///
/// Built once per map update (a dense grid over `bounds` and an exact squared EDT, Felzenszwalb &
/// Huttenlocher's separable lower-envelope pass), then queried in O(1): Distance(p) is a lower
/// bound on the distance from p to the nearest obstacle voxel's surface. Immutable after Build;
/// queries are thread-safe.
class ObstacleField {
 public:
  ObstacleField() = default;

  /// Builds the field over `bounds` (typically the arm's reach, clipped to where the map has
  /// anything) from `grid`. The obstacles are the map voxels (cubes of the map's voxel size) whose
  /// centre lies inside `bounds` and that are occupied, or (unknown_is_obstacle) unknown with the
  /// centre inside `roi` too; a voxel block the map never allocated is unknown throughout. Cells
  /// whose centre lies inside one of `free_space` (world frame: the space the arm has swept) are
  /// never unknown obstacles (occupied voxels there still are). Obstacle voxels outside `bounds`
  /// are ignored: the caller makes the bounds cover everything the robot can reach.
  ///
  /// The cells tile `bounds` grown outward to whole map voxels (so every obstacle voxel lies
  /// inside the grid): origin() is bounds.min() rounded down to the map's voxel lattice and
  /// dims() = ceil((bounds.max() rounded up to the lattice − origin()) / resolution_m). A cell is
  /// an obstacle when any obstacle voxel overlaps it.
  ///
  /// InvalidArgument for bad options, bounds or free-space spheres (naming them),
  /// ResourceExhausted when the bounds need more than max_cells cells.
  /// With `free_halfspace` (n, d; |n| = 1), unknown cells wholly in n·p < d are not obstacles
  /// either (the robot's side of the first view: CollisionChecker::SetStartView).
  static Result<ObstacleField> Build(const mapping::OccupancyGrid& grid, const Box3& roi,
                                     const Box3& bounds, const ObstacleFieldOptions& options,
                                     const std::vector<Sphere>& free_space = {},
                                     const std::optional<Eigen::Vector4d>& free_halfspace = {});

  /// A lower bound on the Euclidean distance (metres) from p_W to the nearest point of any
  /// obstacle voxel, capped at max_distance_m (0 when p_W is in or next to an obstacle).
  ///
  /// Inside the grid: the value of the cell containing p_W (its centre's distance to the nearest
  /// obstacle cell's centre, minus half a cell diagonal) minus |p_W − the cell's centre|, clamped
  /// at 0. Outside the grid: sqrt(d² + L²), where d is the distance from p_W to the grid and L
  /// the value above at the grid point nearest to p_W (every obstacle lies inside the grid, a
  /// convex box, so |p_W − q|² >= d² + |nearest point − q|² for every obstacle point q; adding
  /// d + L would not be a lower bound).
  ///
  /// Accuracy (below max_distance_m): at most res·√3 below the true distance at cell centres,
  /// at most 2·res·√3 elsewhere inside the grid. A default-constructed field, or one built
  /// without any obstacle cell, returns max_distance_m everywhere (no obstacle is known). A
  /// non-finite p_W returns 0.
  double Distance(const Eigen::Vector3d& p_W) const;

  bool empty() const { return cells_.empty(); }
  /// The `bounds` given to Build.
  const Box3& bounds() const { return bounds_; }
  /// Lower corner of cell (0, 0, 0), world frame (see Build).
  const Eigen::Vector3d& origin() const { return origin_; }
  double resolution_m() const { return resolution_m_; }
  Eigen::Vector3i dims() const { return dims_; }
  /// Obstacle cells, and of those the ones that are unknown (not occupied) voxels.
  int64_t obstacle_cells() const { return obstacle_cells_; }
  int64_t unknown_cells() const { return unknown_cells_; }
  /// Wall time of Build, milliseconds.
  double build_ms() const { return build_ms_; }

 private:
  Box3 bounds_;
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  double resolution_m_ = 0.01;
  double max_distance_m_ = 0.3;
  Eigen::Vector3i dims_ = Eigen::Vector3i::Zero();
  /// Per cell (x fastest): the distance from its centre to the nearest obstacle cell's centre,
  /// minus half a cell diagonal (a lower bound on the distance from its centre to any obstacle
  /// voxel), clamped at 0, capped at max_distance_m, rounded down to float.
  std::vector<float> cells_;
  int64_t obstacle_cells_ = 0;
  int64_t unknown_cells_ = 0;
  double build_ms_ = 0.0;
};

}  // namespace avp::motion

#pragma once

#include <avp/mapping/semantics.h>
#include <avp/mapping/voxel_grid.h>

namespace avp::mapping {

struct MapOptions {
  GridOptions grid;
  SemanticOptions semantics;
  Status Validate() const;
};

/// The fields of MapOptions: grid.* and semantics.*.
const OptionTable<MapOptions>& MapOptionTable();

/// The semantic occupancy map: occupancy + semantic cells (OccupancyGrid) and the fusion state
/// that writes the semantic cells (SemanticFusion). Integrator fills it; the planner, evaluation
/// and files read it.
class SemanticMap {
 public:
  /// @throws avp::Error if options.Validate() fails.
  explicit SemanticMap(const MapOptions& options = {})
      : options_(options), grid_(options.grid), semantics_(options.semantics) {}

  const MapOptions& options() const { return options_; }
  OccupancyGrid& grid() { return grid_; }
  const OccupancyGrid& grid() const { return grid_; }
  SemanticFusion& semantics() { return semantics_; }
  const SemanticFusion& semantics() const { return semantics_; }

  double voxel_size_m() const { return grid_.voxel_size_m(); }
  VoxelState State(const VoxelKey& k) const { return grid_.State(k); }
  const SemanticCell* Semantic(const VoxelKey& k) const { return grid_.Semantic(k); }
  std::vector<InstanceInfo> Instances() const { return semantics_.Instances(grid_); }

 private:
  MapOptions options_;
  OccupancyGrid grid_;
  SemanticFusion semantics_;
};

}  // namespace avp::mapping

#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/camera.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/voxel_key.h>
#include <avp/mapping/ray_traversal.h>
#include <avp/mapping/semantic_map.h>

namespace avp::planning {

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
  /// Refuse to build grids larger than this.
  size_t max_bytes = size_t{1} << 30;
  /// Mark the predicted surfaces of the target instances (GainVoxel::predicted_target).
  bool predict_target_surface = true;
};

/// A dense copy of the map over the known voxels' bounding box (inflated by the near-target
/// radius), 4 bytes per voxel, for gain evaluation. Voxels outside it read as unknown, not near
/// the target (exact: everything outside the known bounds is unknown). Read-only after Build;
/// safe to share between threads.
class GainGrid {
 public:
  GainGrid() = default;
  static Result<GainGrid> Build(const mapping::SemanticMap& map, SemanticClass target,
                                const Box3& roi, const GainGridOptions& options = {});

  double voxel_size_m() const { return voxel_size_m_; }
  const Box3& roi() const { return roi_; }
  SemanticClass target() const { return target_; }

  /// Equal to ReadGainVoxel(map, k, ...) for the map it was built from. Inline: the gain
  /// evaluators call it once per voxel of every ray.
  GainVoxel At(const VoxelKey& k) const {
    GainVoxel v;
    v.in_roi = roi_.Contains(k.Center(voxel_size_m_));
    const int64_t x = int64_t{k.x} - min_.x;
    const int64_t y = int64_t{k.y} - min_.y;
    const int64_t z = int64_t{k.z} - min_.z;
    if (x < 0 || y < 0 || z < 0 || x >= dims_.x() || y >= dims_.y() || z >= dims_.z()) return v;
    const uint32_t c = cells_[static_cast<size_t>(x + dims_.x() * (y + int64_t{dims_.y()} * z))];
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

  /// Walks the segment [from, to) voxel by voxel (the voxel of `to` is not visited, as
  /// PlanningSnapshot::CastRay), calling visit(const VoxelKey&, const GainVoxel&) -> bool; stops
  /// when it returns false. Returns the voxels visited.
  ///
  /// The walk goes in chunks of kWalkChunk voxels: their keys first, with a prefetch of each
  /// cell, then the visits. A ray's cells are scattered over the grid and their cache misses,
  /// not the arithmetic, were the cost (as in PlanningSnapshot::CastRay); the visits and their
  /// order are those of the voxel-by-voxel walk.
  template <typename Visitor>
  int64_t Walk(const Eigen::Vector3d& from, const Eigen::Vector3d& to, Visitor&& visit) const {
    mapping::RayWalker w(from, to, voxel_size_m_);
    if (!w.ok()) return 0;
    int64_t visited = 0;
    VoxelKey keys[kWalkChunk];
    while (w.remaining() > 0) {
      int n = 0;
      while (n < kWalkChunk && w.remaining() > 0) {
        keys[n] = w.key();
        if (const uint32_t* cell = CellOf(keys[n])) __builtin_prefetch(cell);
        ++n;
        w.Step();
      }
      for (int i = 0; i < n; ++i) {
        ++visited;
        if (!visit(keys[i], At(keys[i]))) return visited;
      }
    }
    return visited;
  }

 private:
  static constexpr int kWalkChunk = 16;

  /// The packed cell of k, or nullptr outside the grid.
  const uint32_t* CellOf(const VoxelKey& k) const {
    const int64_t x = int64_t{k.x} - min_.x;
    const int64_t y = int64_t{k.y} - min_.y;
    const int64_t z = int64_t{k.z} - min_.z;
    if (x < 0 || y < 0 || z < 0 || x >= dims_.x() || y >= dims_.y() || z >= dims_.z()) {
      return nullptr;
    }
    return &cells_[static_cast<size_t>(x + dims_.x() * (y + int64_t{dims_.y()} * z))];
  }

  static constexpr uint32_t kStateMask = 0x3;
  static constexpr int kClassShift = 2;
  static constexpr uint32_t kClassMask = 0x7;
  static constexpr uint32_t kNearTargetBit = uint32_t{1} << 5;
  static constexpr uint32_t kPredictedTargetBit = uint32_t{1} << 6;
  static constexpr int kOccShift = 8;
  static constexpr int kTargetShift = 16;

  double voxel_size_m_ = 0.005;
  SemanticClass target_ = SemanticClass::kFruit;
  Box3 roi_;
  VoxelKey min_;
  Eigen::Vector3i dims_ = Eigen::Vector3i::Zero();
  /// Packed per voxel: bits 0-1 state, 2-4 class, 5 near_target, 6 predicted_target; bits 8-15
  /// p_occ * 255; bits
  /// 16-23 p_target * 255. x fastest.
  std::vector<uint32_t> cells_;
};

/// Unit ray directions in the camera frame through every `stride`-th pixel centre of K (u, v =
/// stride/2, stride/2 + stride, ...), row by row.
std::vector<Eigen::Vector3d> RayDirections(const CameraIntrinsics& K, int stride);

}  // namespace avp::planning

#pragma once

// A thin harness around Debian's liboctomap (octomap::OcTree) for bench_map, built as its own
// shared library (libavp_octomap_harness.so, hidden visibility). Its .cpp is the only file of
// bench_map that includes OctoMap headers, and it declares the OcTree templates `extern`, so every
// timed OctoMap call runs the code compiled into liboctomap.so (Debian's build, without NDEBUG)
// rather than a copy instantiated with the project's flags (see benchmarks/CMakeLists.txt).

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include <avp/core/voxel_key.h>

/// The harness is a shared library built with hidden visibility; this exports its API.
#define AVP_HARNESS_API __attribute__((visibility("default")))

namespace avp::bench {

/// {unknown, free, occupied}, numerically equal to avp::mapping::VoxelState.
enum class OctoState : uint8_t { kUnknown = 0, kFree = 1, kOccupied = 2 };

/// Counts of one evaluation ray (computeRayKeys + search): voxels before the first occupied one.
struct OctoRayCounts {
  uint32_t unknown = 0;
  uint32_t free = 0;
  uint32_t visited = 0;  ///< searched keys, including the occupied one that stopped the ray
  bool hit = false;
};

/// Our VoxelKey <-> OctoMap key: key = VoxelKey + 32768 on each axis (16-level tree).
inline constexpr int32_t kOctoKeyOffset = 32768;

/// One OctoMap OcTree with the protocol's sensor model: hit 0.7, miss 0.4, clamping 0.12 / 0.97
/// (occupancy threshold 0.5). Abstract so that the two builds (MakeOctoMapHarness,
/// MakeOctoMapHarnessFromHeaders) can live in one process without sharing any OcTree code.
class OctoMapHarness {
 public:
  virtual ~OctoMapHarness() = default;

  /// Converts a cloud to octomap::Pointcloud ahead of time (not part of the timed insertion);
  /// returns its index for Insert().
  virtual size_t AddCloud(std::span<const Eigen::Vector3f> points_W) = 0;
  /// insertPointCloud(cloud, origin, max_range, lazy_eval = false, discretize); returns the wall
  /// time of that call in seconds.
  virtual double Insert(size_t cloud, const Eigen::Vector3f& origin_W, double max_range_m,
                        bool discretize) = 0;
  /// Frees the converted clouds.
  virtual void ReleaseClouds() = 0;

  /// search(key) + isNodeOccupied; keys outside the tree read as unknown.
  virtual OctoState State(const VoxelKey& k) const = 0;
  /// Calls fn(VoxelKey min_corner, int edge_voxels, bool occupied) for every leaf; a leaf at
  /// depth d covers edge_voxels = 2^(16 - d) voxels per axis.
  virtual void ForEachLeaf(const std::function<void(const VoxelKey&, int, bool)>& fn) const = 0;
  /// computeRayKeys(from, to) + search per key, stopping at the first occupied voxel.
  virtual OctoRayCounts CastRay(const Eigen::Vector3f& from, const Eigen::Vector3f& to) const = 0;

  /// coordToKey(p) - 32768 (to check the lattice against VoxelKey::FromPoint).
  virtual VoxelKey KeyOf(const Eigen::Vector3f& p) const = 0;

  /// OcTree::memoryUsage() (nodes and child arrays, without malloc overhead).
  virtual size_t MemoryUsage() const = 0;
  virtual size_t NumLeaves() const = 0;
  virtual size_t NumNodes() const = 0;
};

/// The tree of Debian's liboctomap.so: every timed OcTree member runs the library's own code
/// (libavp_octomap_harness.so).
AVP_HARNESS_API std::unique_ptr<OctoMapHarness> MakeOctoMapHarness(double resolution_m);
/// The same OcTree instantiated from the OctoMap 1.9.7 headers with the project's flags (e.g.
/// -O3 -DNDEBUG), kept private to libavp_octomap_harness_headers.so: what a project-built OctoMap
/// (a ROS build, or a tree type of the project's own) would cost. Only OcTreeNode's non-template
/// members still come from liboctomap.so.
AVP_HARNESS_API std::unique_ptr<OctoMapHarness> MakeOctoMapHarnessFromHeaders(double resolution_m);

/// "1.9.7, OcTree code from liboctomap.so.1.9": the version the headers announce and the file that
/// defines, for the dynamic linker, the OcTree members the benchmark times (insertPointCloud,
/// computeUpdate, updateNode, computeRayKeys, search), naming any that come from elsewhere.
AVP_HARNESS_API std::string OctoMapBuildInfo();
/// True when every timed OcTree member resolves to liboctomap.so (not to a project-compiled copy).
AVP_HARNESS_API bool OctoMapCodeFromLibrary();

}  // namespace avp::bench

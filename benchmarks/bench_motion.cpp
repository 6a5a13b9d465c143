// The map as an obstacle for arm motion: avp's ObstacleField (a Euclidean distance field over the
// voxel grid, queried with the sphere cover of the robot) against FCL 0.7 on the same voxels, in
// the same run (docs/motion.md; shared design note A3).
//
// The map: a seeded synthetic plant of 5 mm voxels in a 0.6 x 0.6 x 1.0 m ROI (a stem, cupped
// leaves, fruits; about 31 k occupied voxels), observed free around the plant and unknown behind
// the leaves and inside the fruits. The field covers the ROI grown by 0.1 m (the arm's reach
// clipped to where the map has anything), at 1 cm unless stated.
//
// One robot state = 6 capsules (r = 5 cm, 20 cm between the cap centres) at random poses around
// the plant: 30 % of their centres in the ROI, the rest in the ROI grown by 0.25 m, so that about
// 70-75 % of the states collide (as in the design note's micro-benchmark). The field checks the
// same capsules as 60 spheres (10 per capsule, radius grown to cover the capsule between them).
// Every method stops at the first colliding capsule (sphere).
//
//   BM_FieldBuild/<unknown>/<res_mm>  ObstacleField::Build (unknown: unknown voxels in the ROI
//                                      are obstacles)
//   BM_FieldQuery/<unknown>/<stop>    60 sphere queries per state (stop 0: no early exit)
//   BM_OcTreeBuild                    octomap::OcTree of the occupied voxels + fcl::OcTree
//   BM_OcTreeQuery                    fcl::collide of 6 capsules against the fcl::OcTree
//   BM_BoxesBuild                     one fcl::Box per occupied voxel in a DynamicAABBTree manager
//   BM_BoxesQuery                     the manager's collide of 6 capsules
//
// Counters: collision_rate (fraction of states found in collision; the field is conservative, so
// higher), x_field (time per state / BM_FieldQuery/0/1's: the same obstacles, occupied only),
// field_missed (BM_OcTreeQuery: states FCL finds in collision that the field, occupied only,
// calls free; must be 0). A summary with every per-state time and ratio is printed at the end.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <benchmark/benchmark.h>
#include <fcl/broadphase/broadphase_dynamic_AABB_tree.h>
#include <fcl/broadphase/default_broadphase_callbacks.h>
#include <fcl/geometry/octree/octree.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/capsule.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/collision_object.h>
#include <octomap/OcTree.h>

#include <avp/core/box.h>
#include <avp/core/rng.h>
#include <avp/core/stopwatch.h>
#include <avp/mapping/voxel_grid.h>
#include <avp/motion/obstacle_field.h>

#include "bench_report.h"

namespace {

using avp::Box3;
using avp::Rng;
using avp::VoxelKey;
using avp::mapping::OccupancyGrid;
using avp::motion::ObstacleField;
using avp::motion::ObstacleFieldOptions;

constexpr double kVoxel = 0.005;
constexpr double kCapsuleRadius = 0.05;
constexpr double kCapsuleLength = 0.2;  // between the centres of the two caps (fcl's lz)
constexpr int kCapsules = 6;
constexpr int kSpheresPerCapsule = 10;
constexpr int kStates = 4096;

/// Whether any sphere of the state is within `radius` of an obstacle (stops at the first).
bool FieldCollides(const ObstacleField& field, const std::vector<Eigen::Vector3d>& centres,
                   double radius) {
  for (const Eigen::Vector3d& c : centres) {
    if (field.Distance(c) <= radius) return true;
  }
  return false;
}

/// The synthetic plant map and the robot states, built once.
struct World {
  OccupancyGrid grid{[] {
    avp::mapping::GridOptions o;
    o.voxel_size_m = kVoxel;
    return o;
  }()};
  Box3 roi{Eigen::Vector3d(-0.3, -0.3, 0.0), Eigen::Vector3d(0.3, 0.3, 1.0)};
  Box3 bounds = roi.Inflated(0.1);
  std::vector<VoxelKey> occupied;
  int64_t unknown_voxels = 0;
  /// Per state, kCapsules poses (capsule axis = local z).
  std::vector<std::vector<Eigen::Isometry3d>> states;
  /// Per state, the sphere centres covering its capsules (world frame).
  std::vector<std::vector<Eigen::Vector3d>> spheres;
  /// Spheres of this radius, kSpheresPerCapsule centres spread over the capsule's segment, cover
  /// it: between two centres d apart the covered radius is sqrt(r'^2 - (d/2)^2) = r.
  double sphere_radius = 0.0;
};

/// Which voxels of the ROI are what: a dense mask (x fastest) over the ROI's voxels.
class RoiMask {
 public:
  enum : uint8_t { kFree = 0, kOccupied = 1, kUnknown = 2 };
  explicit RoiMask(const Box3& roi) : lo_(VoxelKey::FromPoint(roi.min(), kVoxel)) {
    const VoxelKey hi = VoxelKey::FromPoint(roi.max(), kVoxel);
    nx_ = hi.x - lo_.x;
    ny_ = hi.y - lo_.y;
    nz_ = hi.z - lo_.z;
    cells_.assign(static_cast<size_t>(nx_) * static_cast<size_t>(ny_) * static_cast<size_t>(nz_),
                  kFree);
  }
  uint8_t* At(const Eigen::Vector3d& p) {
    const VoxelKey k = VoxelKey::FromPoint(p, kVoxel);
    const int x = k.x - lo_.x, y = k.y - lo_.y, z = k.z - lo_.z;
    if (x < 0 || y < 0 || z < 0 || x >= nx_ || y >= ny_ || z >= nz_) return nullptr;
    return &cells_[static_cast<size_t>(x) +
                   static_cast<size_t>(nx_) * (static_cast<size_t>(y) +
                                               static_cast<size_t>(ny_) * static_cast<size_t>(z))];
  }
  void Set(const Eigen::Vector3d& p, uint8_t value) {
    uint8_t* c = At(p);
    if (c != nullptr && *c != kOccupied) *c = value;
  }
  template <typename F>
  void ForEach(F&& fn) const {
    size_t i = 0;
    for (int z = 0; z < nz_; ++z)
      for (int y = 0; y < ny_; ++y)
        for (int x = 0; x < nx_; ++x) fn(VoxelKey{lo_.x + x, lo_.y + y, lo_.z + z}, cells_[i++]);
  }

 private:
  VoxelKey lo_;
  int nx_ = 0, ny_ = 0, nz_ = 0;
  std::vector<uint8_t> cells_;
};

Eigen::Vector3d UnitVector(Rng& rng) {
  const Eigen::Vector3d v(rng.Normal(), rng.Normal(), rng.Normal());
  return v.normalized();
}

World* MakeWorld() {
  auto* w = new World;
  Rng rng(20261207);
  RoiMask mask(w->roi);
  constexpr double kStep = 0.002;  // surface sampling, well below a voxel
  // Stem: a 6 mm cylinder from the ground to 0.95 m.
  for (double z = 0.0; z < 0.95; z += kStep) {
    for (double a = 0.0; a < 2.0 * M_PI; a += kStep / 0.006) {
      mask.Set({0.006 * std::cos(a), 0.006 * std::sin(a), z}, RoiMask::kOccupied);
    }
  }
  // 70 cupped disc leaves (r = 30-60 mm) on short petioles, tilted up to 40 degrees; the 3 cm
  // behind each leaf is unknown (the camera looks from above and the side).
  for (int leaf = 0; leaf < 70; ++leaf) {
    const double radius = rng.Uniform(0.03, 0.06);
    const double height = rng.Uniform(0.15, 0.95);
    const double azimuth = rng.Uniform(0.0, 2.0 * M_PI);
    const Eigen::Vector3d out(std::cos(azimuth), std::sin(azimuth), 0.0);
    const Eigen::Vector3d centre =
        Eigen::Vector3d(0.0, 0.0, height) + out * (0.01 + radius + rng.Uniform(0.0, 0.08));
    const Eigen::Vector3d tangent(-out.y(), out.x(), 0.0);
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(rng.Uniform(-0.7, 0.7), tangent).toRotationMatrix() *
        Eigen::AngleAxisd(azimuth, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const double cup = rng.Uniform(0.005, 0.015);
    for (double u = -radius; u <= radius; u += kStep) {
      for (double v = -radius; v <= radius; v += kStep) {
        const double r2 = (u * u + v * v) / (radius * radius);
        if (r2 > 1.0) continue;
        const Eigen::Vector3d surface = centre + R * Eigen::Vector3d(u, v, cup * r2);
        mask.Set(surface, RoiMask::kOccupied);
        for (double d = kVoxel; d <= 0.03; d += 0.5 * kVoxel) {
          mask.Set(surface - R.col(2) * d, RoiMask::kUnknown);
        }
      }
    }
  }
  // 10 fruits (r = 22-35 mm): shells occupied, insides unknown.
  for (int fruit = 0; fruit < 10; ++fruit) {
    const double radius = rng.Uniform(0.022, 0.035);
    const double azimuth = rng.Uniform(0.0, 2.0 * M_PI);
    const Eigen::Vector3d centre(0.06 * std::cos(azimuth), 0.06 * std::sin(azimuth),
                                 rng.Uniform(0.2, 0.8));
    const int n = static_cast<int>(4.0 * M_PI * radius * radius / (kStep * kStep));
    for (int i = 0; i < n; ++i) mask.Set(centre + radius * UnitVector(rng), RoiMask::kOccupied);
    for (double r = 0.0; r < radius - kVoxel; r += 0.5 * kVoxel) {
      for (int i = 0; i < 64 + static_cast<int>(4.0 * M_PI * r * r / (kStep * kStep)); ++i) {
        mask.Set(centre + r * UnitVector(rng), RoiMask::kUnknown);
      }
    }
  }
  mask.ForEach([&](const VoxelKey& k, uint8_t value) {
    if (value == RoiMask::kOccupied) {
      w->grid.SetLogOdds(k, 2.0f);
      w->occupied.push_back(k);
    } else if (value == RoiMask::kFree) {
      w->grid.SetLogOdds(k, -2.0f);
    } else {
      ++w->unknown_voxels;
    }
  });

  // Robot states: capsule centres around the plant (30 % inside the ROI), random orientations.
  const double spacing = kCapsuleLength / (kSpheresPerCapsule - 1);
  w->sphere_radius = std::sqrt(kCapsuleRadius * kCapsuleRadius + 0.25 * spacing * spacing);
  const Box3 around = w->roi.Inflated(0.25);
  for (int s = 0; s < kStates; ++s) {
    std::vector<Eigen::Isometry3d> poses;
    std::vector<Eigen::Vector3d> centres;
    for (int c = 0; c < kCapsules; ++c) {
      const Box3& box = rng.Bernoulli(0.3) ? w->roi : around;
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      X.translation() = Eigen::Vector3d(rng.Uniform(box.min().x(), box.max().x()),
                                        rng.Uniform(box.min().y(), box.max().y()),
                                        rng.Uniform(box.min().z(), box.max().z()));
      X.linear() = Eigen::Quaterniond(rng.Normal(), rng.Normal(), rng.Normal(), rng.Normal())
                       .normalized()
                       .toRotationMatrix();
      poses.push_back(X);
      for (int i = 0; i < kSpheresPerCapsule; ++i) {
        centres.push_back(X * Eigen::Vector3d(0.0, 0.0, -0.5 * kCapsuleLength + i * spacing));
      }
    }
    w->states.push_back(std::move(poses));
    w->spheres.push_back(std::move(centres));
  }
  return w;
}

const World& GetWorld() {
  static const World* world = MakeWorld();
  return *world;
}

/// Mean time per state (microseconds) and per build (milliseconds) of each benchmark, for the
/// summary and the x_field counters.
std::map<std::string, double>& Results() {
  static std::map<std::string, double> results;
  return results;
}

ObstacleField BuildField(bool unknown_is_obstacle, double res) {
  const World& w = GetWorld();
  ObstacleFieldOptions o;
  o.unknown_is_obstacle = unknown_is_obstacle;
  o.resolution_m = res;
  auto field = ObstacleField::Build(w.grid, w.roi, w.bounds, o);
  if (!field.ok()) {
    std::fprintf(stderr, "%s\n", field.status().ToString().c_str());
    std::abort();
  }
  return std::move(field).value();
}

void BM_FieldBuild(benchmark::State& state) {
  const bool unknown = state.range(0) != 0;
  const double res = 0.001 * static_cast<double>(state.range(1));
  const World& w = GetWorld();
  ObstacleField field;
  double total_ms = 0.0;
  int64_t builds = 0;
  for (auto _ : state) {
    field = BuildField(unknown, res);
    benchmark::DoNotOptimize(field.obstacle_cells());
    total_ms += field.build_ms();
    ++builds;
  }
  state.counters["cells"] = static_cast<double>(field.dims().prod());
  state.counters["obstacle_cells"] = static_cast<double>(field.obstacle_cells());
  state.counters["unknown_cells"] = static_cast<double>(field.unknown_cells());
  state.counters["occupied_voxels"] = static_cast<double>(w.occupied.size());
  state.counters["unknown_voxels"] = static_cast<double>(w.unknown_voxels);
  Results()["field_build_ms/" + std::to_string(state.range(0)) + "/" +
            std::to_string(state.range(1))] = total_ms / static_cast<double>(builds);
}
BENCHMARK(BM_FieldBuild)->Args({1, 10})->Args({0, 10})->Args({1, 5})->Unit(benchmark::kMillisecond);

/// Times `collides(i)` over the world's states in turn, one per iteration: the mean time per
/// state (µs); sets the collision_rate counter.
template <typename Collides>
double TimeStates(benchmark::State& state, size_t num_states, Collides&& collides) {
  size_t next = 0;
  int64_t states = 0, collisions = 0;
  const auto t0 = avp::SteadyClock::now();
  for (auto _ : state) {
    const bool c = collides(next);
    benchmark::DoNotOptimize(c);
    collisions += c ? 1 : 0;
    ++states;
    next = (next + 1) % num_states;
  }
  state.counters["collision_rate"] = static_cast<double>(collisions) / static_cast<double>(states);
  return 1e3 * avp::MsSince(t0) / static_cast<double>(states);
}

void BM_FieldQuery(benchmark::State& state) {
  const bool unknown = state.range(0) != 0;
  const bool stop_at_first = state.range(1) != 0;
  const World& w = GetWorld();
  const ObstacleField field = BuildField(unknown, 0.01);
  const double us = TimeStates(state, w.spheres.size(), [&](size_t i) {
    if (stop_at_first) return FieldCollides(field, w.spheres[i], w.sphere_radius);
    bool collides = false;
    for (const Eigen::Vector3d& c : w.spheres[i]) collides |= field.Distance(c) <= w.sphere_radius;
    return collides;
  });
  Results()["field_query_us/" + std::to_string(state.range(0)) + "/" +
            std::to_string(state.range(1))] = us;
}
BENCHMARK(BM_FieldQuery)->Args({0, 1})->Args({1, 1})->Args({0, 0})->Unit(benchmark::kMicrosecond);

/// The per-state time of the field on the same obstacles (occupied only), when it ran.
void SetRatioToField(benchmark::State& state, double us) {
  const auto it = Results().find("field_query_us/0/1");
  if (it != Results().end() && it->second > 0.0) state.counters["x_field"] = us / it->second;
}

std::shared_ptr<octomap::OcTree> MakeOcTree(const World& w) {
  auto tree = std::make_shared<octomap::OcTree>(kVoxel);
  for (const VoxelKey& k : w.occupied) {
    // OctoMap's key = avp's key + 32768 (avp/core/voxel_key.h).
    const octomap::OcTreeKey key(static_cast<octomap::key_type>(k.x + 32768),
                                 static_cast<octomap::key_type>(k.y + 32768),
                                 static_cast<octomap::key_type>(k.z + 32768));
    tree->updateNode(key, true, /*lazy_eval=*/true);
  }
  tree->updateInnerOccupancy();
  return tree;
}

std::vector<std::unique_ptr<fcl::CollisionObjectd>> MakeCapsules() {
  std::vector<std::unique_ptr<fcl::CollisionObjectd>> capsules;
  const auto shape = std::make_shared<fcl::Capsuled>(kCapsuleRadius, kCapsuleLength);
  for (int i = 0; i < kCapsules; ++i)
    capsules.push_back(std::make_unique<fcl::CollisionObjectd>(shape));
  return capsules;
}

void BM_OcTreeBuild(benchmark::State& state) {
  const World& w = GetWorld();
  const auto t0 = avp::SteadyClock::now();
  int64_t builds = 0;
  for (auto _ : state) {
    const auto octree = std::make_shared<fcl::OcTreed>(MakeOcTree(w));
    fcl::CollisionObjectd object(octree);
    benchmark::DoNotOptimize(object.getAABB());
    ++builds;
  }
  Results()["octree_build_ms"] = avp::MsSince(t0) / static_cast<double>(builds);
}
BENCHMARK(BM_OcTreeBuild)->Unit(benchmark::kMillisecond);

/// Whether any capsule of the state collides with the octree (stops at the first); a throw of
/// the narrow phase (libccd on touching contact, design note A3) counts as a collision.
bool OcTreeCollides(const fcl::CollisionObjectd& tree,
                    std::vector<std::unique_ptr<fcl::CollisionObjectd>>& capsules,
                    const std::vector<Eigen::Isometry3d>& poses, int64_t& throws) {
  const fcl::CollisionRequestd request;  // one contact, no contact details
  for (size_t c = 0; c < capsules.size(); ++c) {
    fcl::CollisionObjectd& capsule = *capsules[c];
    capsule.setTransform(poses[c]);
    capsule.computeAABB();
    fcl::CollisionResultd result;
    try {
      if (fcl::collide(&capsule, &tree, request, result) > 0) return true;
    } catch (...) {
      ++throws;
      return true;
    }
  }
  return false;
}

void BM_OcTreeQuery(benchmark::State& state) {
  const World& w = GetWorld();
  const fcl::CollisionObjectd tree(std::make_shared<fcl::OcTreed>(MakeOcTree(w)));
  auto capsules = MakeCapsules();
  // Untimed check: the field must find every collision FCL finds.
  int64_t missed = 0, throws = 0;
  {
    const ObstacleField field = BuildField(false, 0.01);
    for (size_t i = 0; i < w.states.size(); ++i) {
      if (OcTreeCollides(tree, capsules, w.states[i], throws) &&
          !FieldCollides(field, w.spheres[i], w.sphere_radius)) {
        ++missed;
      }
    }
  }
  const double us = TimeStates(state, w.states.size(), [&](size_t i) {
    return OcTreeCollides(tree, capsules, w.states[i], throws);
  });
  state.counters["throws"] = static_cast<double>(throws);
  state.counters["field_missed"] = static_cast<double>(missed);
  SetRatioToField(state, us);
  Results()["octree_query_us"] = us;
  Results()["field_missed"] = static_cast<double>(missed);
}
BENCHMARK(BM_OcTreeQuery)->Unit(benchmark::kMicrosecond);

/// One fcl::Box per occupied voxel, registered in a dynamic AABB tree manager.
struct BoxWorld {
  std::vector<std::unique_ptr<fcl::CollisionObjectd>> boxes;
  fcl::DynamicAABBTreeCollisionManagerd manager;
  explicit BoxWorld(const World& w) {
    const auto shape = std::make_shared<fcl::Boxd>(kVoxel, kVoxel, kVoxel);
    std::vector<fcl::CollisionObjectd*> objects;
    for (const VoxelKey& k : w.occupied) {
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      X.translation() = k.Center(kVoxel);
      boxes.push_back(std::make_unique<fcl::CollisionObjectd>(shape, X));
      objects.push_back(boxes.back().get());
    }
    manager.registerObjects(objects);
    manager.setup();
  }
};

void BM_BoxesBuild(benchmark::State& state) {
  const World& w = GetWorld();
  const auto t0 = avp::SteadyClock::now();
  int64_t builds = 0;
  for (auto _ : state) {
    const BoxWorld boxes(w);
    benchmark::DoNotOptimize(boxes.manager.size());
    ++builds;
  }
  Results()["boxes_build_ms"] = avp::MsSince(t0) / static_cast<double>(builds);
}
BENCHMARK(BM_BoxesBuild)->Unit(benchmark::kMillisecond);

void BM_BoxesQuery(benchmark::State& state) {
  const World& w = GetWorld();
  BoxWorld boxes(w);
  auto capsules = MakeCapsules();
  int64_t throws = 0;
  const double us = TimeStates(state, w.states.size(), [&](size_t i) {
    bool collides = false;
    for (int c = 0; c < kCapsules && !collides; ++c) {
      fcl::CollisionObjectd& capsule = *capsules[static_cast<size_t>(c)];
      capsule.setTransform(w.states[i][static_cast<size_t>(c)]);
      capsule.computeAABB();
      fcl::DefaultCollisionData<double> data;
      try {
        boxes.manager.collide(&capsule, &data, fcl::DefaultCollisionFunction<double>);
        collides = data.result.isCollision();
      } catch (...) {
        collides = true;
        ++throws;
      }
    }
    return collides;
  });
  state.counters["throws"] = static_cast<double>(throws);
  SetRatioToField(state, us);
  Results()["boxes_query_us"] = us;
}
BENCHMARK(BM_BoxesQuery)->Unit(benchmark::kMicrosecond);

void PrintSummary() {
  const auto& r = Results();
  const auto get = [&](const std::string& key) {
    const auto it = r.find(key);
    return it == r.end() ? std::nan("") : it->second;
  };
  const double field = get("field_query_us/0/1");
  std::printf(
      "bench_motion summary (%zu occupied voxels; one state = %d capsules = %d spheres):\n"
      "  per state: field %.2f us (with unknown obstacles %.2f us, all 60 spheres %.2f us), "
      "fcl::OcTree %.1f us (%.0fx the field), fcl boxes %.1f us (%.0fx the field)\n"
      "  build: field %.1f ms at 1 cm (with unknown obstacles %.1f ms, at 5 mm %.1f ms), "
      "octomap + fcl::OcTree %.1f ms, fcl boxes %.1f ms\n"
      "  states FCL finds in collision that the field calls free: %.0f (must be 0)\n",
      GetWorld().occupied.size(), kCapsules, kCapsules * kSpheresPerCapsule, field,
      get("field_query_us/1/1"), get("field_query_us/0/0"), get("octree_query_us"),
      get("octree_query_us") / field, get("boxes_query_us"), get("boxes_query_us") / field,
      get("field_build_ms/0/10"), get("field_build_ms/1/10"), get("field_build_ms/1/5"),
      get("octree_build_ms"), get("boxes_build_ms"), get("field_missed"));
}

}  // namespace

int main(int argc, char** argv) {
  const int code = avp::bench::GoogleBenchmarkMain(argc, argv, {});
  if (code == 0) PrintSummary();
  return code;
}

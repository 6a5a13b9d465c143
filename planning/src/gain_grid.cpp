// GainGrid: a bricked 4-byte-per-voxel copy of the semantic map for gain evaluation, and the slow
// per-voxel read (ReadGainVoxel) it is tested against. See docs/planning.md, "Gain grid".
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <map>
#include <new>
#include <utility>
#include <vector>

#include <Eigen/Cholesky>
#include <fmt/format.h>
#include <sys/mman.h>

#include <avp/core/error.h>
#include <avp/mapping/sensor_model.h>
#include <avp/planning/gain_grid.h>

namespace avp::planning {

namespace {

/// p clamped into [0, 1] (NaN -> 0) and rounded to the nearest of 0, 1, ..., 255 (halves away
/// from zero).
uint32_t ProbabilityByte(double p) {
  if (!(p > 0.0)) return 0;
  if (p >= 1.0) return 255;
  return static_cast<uint32_t>(std::lround(p * 255.0));
}

float ByteToProbability(uint32_t b) { return static_cast<float>(b) / 255.0f; }

/// The largest squared centre distance, in voxel units, that counts as "within radius_m": exact
/// integer comparisons, so GainGrid::Build and ReadGainVoxel agree voxel by voxel. The 1e-6
/// (voxel^2) slack keeps a voxel at exactly the radius inside when the radius is a whole number
/// of voxels that the division r / s rounds just below (0.04 / 0.005 and the like).
int64_t NearTargetThreshold(double radius_m, double voxel_size_m) {
  const double r = radius_m / voxel_size_m;
  return static_cast<int64_t>(std::floor(r * r + 1e-6));
}

/// floor(sqrt(t)) for t >= 0, exactly.
int32_t IntegerSqrt(int64_t t) {
  auto r = static_cast<int64_t>(std::sqrt(static_cast<double>(t)));
  while (r * r > t) --r;
  while ((r + 1) * (r + 1) <= t) ++r;
  return static_cast<int32_t>(r);
}

struct Offset {
  int32_t x, y, z;
};

/// Integer offsets with x^2 + y^2 + z^2 <= threshold.
std::vector<Offset> BallOffsets(int64_t threshold) {
  const int32_t r = IntegerSqrt(threshold);
  std::vector<Offset> out;
  for (int32_t z = -r; z <= r; ++z) {
    for (int32_t y = -r; y <= r; ++y) {
      for (int32_t x = -r; x <= r; ++x) {
        if (int64_t{x} * x + int64_t{y} * y + int64_t{z} * z <= threshold) out.push_back({x, y, z});
      }
    }
  }
  return out;
}

Status ValidateOptions(const GainGridOptions& options) {
  if (!std::isfinite(options.near_target_radius_m) || options.near_target_radius_m < 0.0) {
    return InvalidArgumentError(
        fmt::format("invalid gain grid options: near_target_radius_m ({}) must be finite and >= 0",
                    options.near_target_radius_m));
  }
  if (options.brick_shift < 0 || options.brick_shift > 4) {
    return InvalidArgumentError(fmt::format(
        "invalid gain grid options: brick_shift ({}) must be in [0, 4]", options.brick_shift));
  }
  return Status::Ok();
}

}  // namespace

namespace {
constexpr size_t kHugePage = size_t{2} << 20;
}  // namespace

void* AllocateHugePageBlock(size_t bytes) {
  if (bytes < kHugePage) {
    void* p = std::malloc(bytes == 0 ? 1 : bytes);
    if (p == nullptr) throw std::bad_alloc();
    return p;
  }
  const size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
  void* p = std::aligned_alloc(kHugePage, rounded);
  if (p == nullptr) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
  madvise(p, rounded, MADV_HUGEPAGE);  // advice only: failure leaves 4 kB pages
#endif
  return p;
}

void FreeHugePageBlock(void* p, size_t /*bytes*/) { std::free(p); }

float QuantizeProbability(double p) { return ByteToProbability(ProbabilityByte(p)); }

std::vector<TargetSphere> FitTargetSpheres(const mapping::SemanticMap& map, SemanticClass target,
                                           size_t min_voxels, double min_radius_m,
                                           double max_radius_m) {
  const mapping::OccupancyGrid& grid = map.grid();
  const double s = grid.voxel_size_m();
  // Per instance: the normal equations of |p|^2 = 2 c . p + (r^2 - |c|^2), solved in a frame
  // centred on the first voxel for conditioning.
  struct Acc {
    Eigen::Vector3d origin = Eigen::Vector3d::Zero();
    Eigen::Matrix4d AtA = Eigen::Matrix4d::Zero();
    Eigen::Vector4d Atb = Eigen::Vector4d::Zero();
    size_t n = 0;
  };
  std::map<uint16_t, Acc> acc;
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const mapping::SemanticCell& c) {
    if (c.cls() != target || c.instance_id == 0) return;
    if (grid.State(k) != mapping::VoxelState::kOccupied) return;
    Acc& a = acc[c.instance_id];
    if (a.n == 0) a.origin = k.Center(s);
    const Eigen::Vector3d p = k.Center(s) - a.origin;
    const Eigen::Vector4d row(2.0 * p.x(), 2.0 * p.y(), 2.0 * p.z(), 1.0);
    a.AtA += row * row.transpose();
    a.Atb += row * p.squaredNorm();
    ++a.n;
  });
  std::vector<TargetSphere> out;
  for (const auto& [id, a] : acc) {
    if (a.n < min_voxels) continue;
    const Eigen::Vector4d x = a.AtA.ldlt().solve(a.Atb);
    if (!x.allFinite()) continue;
    const double r2 = x[3] + x.head<3>().squaredNorm();
    if (!(r2 > 0.0)) continue;
    const double r = std::sqrt(r2);
    if (r < min_radius_m || r > max_radius_m) continue;
    out.push_back({id, a.origin + x.head<3>(), r, a.n});
  }
  return out;
}

bool OnTargetSphere(const VoxelKey& k, double voxel_size_m,
                    const std::vector<TargetSphere>& spheres) {
  const Eigen::Vector3d c = k.Center(voxel_size_m);
  for (const TargetSphere& sp : spheres) {
    if (std::abs((c - sp.center_W).norm() - sp.radius_m) <= 0.6 * voxel_size_m) return true;
  }
  return false;
}

GainVoxel ReadGainVoxel(const mapping::SemanticMap& map, const VoxelKey& k, SemanticClass target,
                        const Box3& roi, double near_target_radius_m,
                        const std::vector<TargetSphere>* spheres) {
  AVP_THROW_UNLESS(std::isfinite(near_target_radius_m) && near_target_radius_m >= 0.0,
                   near_target_radius_m);
  const mapping::OccupancyGrid& grid = map.grid();
  const double s = grid.voxel_size_m();
  GainVoxel v;
  v.in_roi = roi.Contains(k.Center(s));
  if (const std::optional<float> lo = grid.LogOdds(k)) {
    v.state = *lo >= grid.occupied_log_odds() ? mapping::VoxelState::kOccupied
                                              : mapping::VoxelState::kFree;
    v.p_occ = QuantizeProbability(mapping::Probability(*lo));
  }
  if (const mapping::SemanticCell* c = grid.Semantic(k); c != nullptr && c->has_label()) {
    v.cls = c->cls();
    if (v.cls == target) v.p_target = QuantizeProbability(c->confidence);
  }
  const int64_t threshold = NearTargetThreshold(near_target_radius_m, s);
  const int32_t r = IntegerSqrt(threshold);
  for (int32_t dz = -r; dz <= r && !v.near_target; ++dz) {
    for (int32_t dy = -r; dy <= r && !v.near_target; ++dy) {
      for (int32_t dx = -r; dx <= r && !v.near_target; ++dx) {
        if (int64_t{dx} * dx + int64_t{dy} * dy + int64_t{dz} * dz > threshold) continue;
        const mapping::SemanticCell* c = grid.Semantic({k.x + dx, k.y + dy, k.z + dz});
        if (c != nullptr && c->has_label() && c->cls() == target) v.near_target = true;
      }
    }
  }
  if (spheres != nullptr) v.predicted_target = OnTargetSphere(k, s, *spheres);
  return v;
}

namespace {

/// Key bounds of a set of voxels (empty until the first Extend).
struct KeyBounds {
  static constexpr int32_t kBig = std::numeric_limits<int32_t>::max();
  VoxelKey lo{kBig, kBig, kBig};
  VoxelKey hi{-kBig, -kBig, -kBig};
  bool any = false;

  void Extend(const VoxelKey& k) {
    lo = {std::min(lo.x, k.x), std::min(lo.y, k.y), std::min(lo.z, k.z)};
    hi = {std::max(hi.x, k.x), std::max(hi.y, k.y), std::max(hi.z, k.z)};
    any = true;
  }
};

/// Key bounds of every known voxel (KnownBounds(), in keys) and every labelled voxel (a label may
/// sit on a voxel whose occupancy is unknown), so that everything outside reads exactly as unknown
/// and unlabelled; also collects the keys labelled `target`.
KeyBounds MapKeyBounds(const mapping::OccupancyGrid& grid, SemanticClass target,
                       std::vector<VoxelKey>& target_keys) {
  KeyBounds bounds;
  grid.ForEachBlock([&](const mapping::OccupancyBlock& b) {
    b.known.ForEachSet([&](int i) { bounds.Extend(mapping::KeyOf(b.key, i)); });
  });
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const mapping::SemanticCell& c) {
    bounds.Extend(k);
    if (c.cls() == target) target_keys.push_back(k);
  });
  return bounds;
}

/// The keys of the corners of a sphere's bounding box, grown by one voxel of edge s.
std::pair<VoxelKey, VoxelKey> SphereKeyBox(const TargetSphere& sp, double s) {
  return {VoxelKey::FromPoint(sp.center_W.array() - (sp.radius_m + s), s),
          VoxelKey::FromPoint(sp.center_W.array() + (sp.radius_m + s), s)};
}

}  // namespace

/// GainGrid::Build's stages, on the grid `g` being built. Each is forced inline into Build, where
/// the compiler knows that the cells (a fresh allocation) do not overlap `g`'s own fields. A
/// separate function could not assume it (a uint32_t store may alias an int field), and the index
/// arithmetic of the loops below would reload min_, bdims_, ... after every store to a cell (10 %
/// slower, BM_GainGridBuild).
struct GainGrid::Builder {
  /// Sizes the box [lo - r, hi + r] (keys) in whole bricks and allocates its cells, all unknown;
  /// fails when they would need more than options.max_bytes.
  [[gnu::always_inline]] static Status AllocateCells(GainGrid& g, const VoxelKey& lo,
                                                     const VoxelKey& hi, int32_t r,
                                                     const GainGridOptions& options) {
    const int64_t nx = int64_t{hi.x} - lo.x + 1 + 2 * int64_t{r};
    const int64_t ny = int64_t{hi.y} - lo.y + 1 + 2 * int64_t{r};
    const int64_t nz = int64_t{hi.z} - lo.z + 1 + 2 * int64_t{r};
    const double bytes = static_cast<double>(nx) * static_cast<double>(ny) *
                         static_cast<double>(nz) * static_cast<double>(sizeof(uint32_t));
    if (bytes > static_cast<double>(options.max_bytes)) {
      return InvalidArgumentError(fmt::format(
          "gain grid of {} x {} x {} voxels at {} m ({:.1f} MB over the known voxels inflated by "
          "near_target_radius_m = {} m) exceeds max_bytes ({:.1f} MB): use a coarser map, a "
          "smaller radius or a larger max_bytes",
          nx, ny, nz, g.voxel_size_m_, bytes / 1e6, options.near_target_radius_m,
          static_cast<double>(options.max_bytes) / 1e6));
    }
    g.min_ = {lo.x - r, lo.y - r, lo.z - r};
    g.dims_ = Eigen::Vector3i(static_cast<int>(nx), static_cast<int>(ny), static_cast<int>(nz));
    g.brick_shift_ = options.brick_shift;
    const int64_t edge = int64_t{1} << g.brick_shift_;
    const int64_t bx = (nx + edge - 1) / edge, by = (ny + edge - 1) / edge,
                  bz = (nz + edge - 1) / edge;
    g.bdims_ = Eigen::Vector3i(static_cast<int>(bx), static_cast<int>(by), static_cast<int>(bz));
    g.cells_.assign(static_cast<size_t>(bx * by * bz * edge * edge * edge), 0u);
    return Status::Ok();
  }

  /// The per-axis tables (axis_): IndexOf's terms, and the ROI test of Box3::Contains(Center) per
  /// axis (the same double arithmetic, so in_roi is exactly that of At).
  [[gnu::always_inline]] static void FillAxisTables(GainGrid& g) {
    const double s = g.voxel_size_m_;
    const int shift = g.brick_shift_;
    const int64_t mask = (int64_t{1} << shift) - 1;
    const int64_t brick_stride[3] = {int64_t{1}, g.bdims_.x(),
                                     int64_t{g.bdims_.x()} * g.bdims_.y()};
    for (int a = 0; a < 3; ++a) {
      g.axis_[a].resize(static_cast<size_t>(g.dims_[a]));
      const int32_t lo_key = a == 0 ? g.min_.x : a == 1 ? g.min_.y : g.min_.z;
      for (int64_t u = 0; u < g.dims_[a]; ++u) {
        const double c = (static_cast<int32_t>(lo_key + u) + 0.5) * s;
        const bool inside = c >= g.roi_.min()[a] && c <= g.roi_.max()[a];
        g.axis_[a][static_cast<size_t>(u)] = (((u >> shift) * brick_stride[a]) << (3 * shift)) +
                                             ((u & mask) << (a * shift)) + (inside ? 0 : kNotInRoi);
      }
    }
  }

  /// Each known voxel's state and p_occ, each labelled voxel's class (and p_target for the
  /// target class).
  [[gnu::always_inline]] static void CopyMapCells(GainGrid& g, const mapping::OccupancyGrid& grid) {
    const auto index = [&](const VoxelKey& k) { return static_cast<size_t>(g.IndexOf(k)); };
    const float occupied = grid.occupied_log_odds();
    grid.ForEachBlock([&](const mapping::OccupancyBlock& b) {
      b.known.ForEachSet([&](int i) {
        const float log_odds = b.log_odds[static_cast<size_t>(i)];
        const auto state = static_cast<uint32_t>(
            log_odds >= occupied ? mapping::VoxelState::kOccupied : mapping::VoxelState::kFree);
        g.cells_[index(mapping::KeyOf(b.key, i))] =
            state | (ProbabilityByte(mapping::Probability(log_odds)) << kOccShift);
      });
    });
    grid.ForEachSemanticVoxel([&](const VoxelKey& k, const mapping::SemanticCell& c) {
      uint32_t& cell = g.cells_[index(k)];
      cell |= (static_cast<uint32_t>(c.semantic_class) & kClassMask) << kClassShift;
      if (c.cls() == g.target_) cell |= ProbabilityByte(c.confidence) << kTargetShift;
    });
  }

  /// kNearTargetBit on the voxels within `threshold` (squared voxels) of a target-labelled key:
  /// time proportional to their number times the ball's volume; every offset stays inside the
  /// grid, which is inflated by the ball's radius.
  [[gnu::always_inline]] static void MarkNearTarget(GainGrid& g,
                                                    const std::vector<VoxelKey>& target_keys,
                                                    int64_t threshold) {
    const std::vector<Offset> ball = BallOffsets(threshold);
    for (const VoxelKey& k : target_keys) {
      for (const Offset& d : ball) {
        g.cells_[static_cast<size_t>(g.IndexOf({k.x + d.x, k.y + d.y, k.z + d.z}))] |=
            kNearTargetBit;
      }
    }
  }

  /// kPredictedTargetBit on the voxels on a sphere's surface (OnTargetSphere).
  [[gnu::always_inline]] static void MarkPredictedSurfaces(
      GainGrid& g, const std::vector<TargetSphere>& spheres) {
    const double s = g.voxel_size_m_;
    for (const TargetSphere& sp : spheres) {
      const auto [a, b] = SphereKeyBox(sp, s);
      for (int32_t z = a.z; z <= b.z; ++z) {
        for (int32_t y = a.y; y <= b.y; ++y) {
          for (int32_t x = a.x; x <= b.x; ++x) {
            const VoxelKey k{x, y, z};
            if (std::abs((k.Center(s) - sp.center_W).norm() - sp.radius_m) <= 0.6 * s) {
              g.cells_[static_cast<size_t>(g.IndexOf(k))] |= kPredictedTargetBit;
            }
          }
        }
      }
    }
  }

  /// free_brick_ from the cells (padding cells are unknown: a brick with padding is never
  /// all-free).
  [[gnu::always_inline]] static void FlagFreeBricks(GainGrid& g) {
    const size_t per_brick = size_t{1} << (3 * g.brick_shift_);
    const size_t bricks = g.cells_.size() / per_brick;
    g.free_brick_.assign(bricks, 0);
    const auto free = static_cast<uint32_t>(mapping::VoxelState::kFree);
    for (size_t b = 0; b < bricks; ++b) {
      const uint32_t* c = &g.cells_[b * per_brick];
      g.free_brick_[b] =
          std::all_of(c, c + per_brick, [&](uint32_t v) { return (v & kStateMask) == free; });
    }
  }
};

Result<GainGrid> GainGrid::Build(const mapping::SemanticMap& map, SemanticClass target,
                                 const Box3& roi, const GainGridOptions& options) {
  AVP_RETURN_IF_ERROR(ValidateOptions(options));
  const mapping::OccupancyGrid& grid = map.grid();
  GainGrid out;
  out.voxel_size_m_ = grid.voxel_size_m();
  out.target_ = target;
  out.roi_ = roi;

  std::vector<VoxelKey> target_keys;
  KeyBounds bounds = MapKeyBounds(grid, target, target_keys);
  // An empty map gives an empty grid: every key reads as unknown (p_occ 0.5), unlabelled, not
  // near the target; in_roi still follows `roi`.
  if (!bounds.any) return out;
  // The predicted fruit surfaces: the box covers them too.
  const std::vector<TargetSphere> spheres =
      options.predict_target_surface ? FitTargetSpheres(map, target) : std::vector<TargetSphere>{};
  for (const TargetSphere& sp : spheres) {
    const auto [a, b] = SphereKeyBox(sp, out.voxel_size_m_);
    bounds.Extend(a);
    bounds.Extend(b);
  }

  const int64_t threshold = NearTargetThreshold(options.near_target_radius_m, out.voxel_size_m_);
  AVP_RETURN_IF_ERROR(
      Builder::AllocateCells(out, bounds.lo, bounds.hi, IntegerSqrt(threshold), options));
  Builder::FillAxisTables(out);
  Builder::CopyMapCells(out, grid);
  if (!target_keys.empty()) Builder::MarkNearTarget(out, target_keys, threshold);
  Builder::MarkPredictedSurfaces(out, spheres);
  if (options.skip_free_bricks && out.brick_shift_ > 0) Builder::FlagFreeBricks(out);
  return out;
}

size_t GainGrid::free_bricks() const {
  return static_cast<size_t>(std::count(free_brick_.begin(), free_brick_.end(), uint8_t{1}));
}

std::vector<Eigen::Vector3d> RayDirections(const CameraIntrinsics& K, int stride) {
  AVP_THROW_UNLESS(stride >= 1, stride);
  const Status valid = K.Validate();
  AVP_THROW_UNLESS(valid.ok(), valid.message());
  std::vector<Eigen::Vector3d> dirs;
  const int first = stride / 2;
  for (int v = first; v < K.height; v += stride) {
    for (int u = first; u < K.width; u += stride) {
      dirs.push_back(K.RayDirection(Eigen::Vector2d(u, v)).normalized());
    }
  }
  return dirs;
}

const OptionTable<GainGridOptions>& GainGridOptionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<GainGridOptions>("gain grid option");
    t->Real("near_target_radius_m", &GainGridOptions::near_target_radius_m, "m",
            ValueRange::Closed(0, 0.1),
            "unknown voxels this close to a target voxel are near it (work per voxel grows with "
            "its cube)");
    t->Flag("predict_target_surface", &GainGridOptions::predict_target_surface,
            "mark the predicted surfaces of the target instances (fitted spheres)");
    return t;
  }();
  return *table;
}

}  // namespace avp::planning

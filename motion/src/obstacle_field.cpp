#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <tuple>
#include <vector>

#include <fmt/format.h>

#include <avp/core/stopwatch.h>
#include <avp/motion/obstacle_field.h>

namespace avp::motion {
namespace {

using mapping::BlockKey;
using mapping::kBlockEdge;
using mapping::kBlockShift;
using mapping::OccupancyBlock;

constexpr double kMinResolution = 0.002;
constexpr double kMaxResolution = 0.1;
// Squared distances (in cells) are kept in the float cells as exact integers, which floats hold
// up to 2^24: distances of 4096 cells and more saturate there (still a lower bound).
constexpr double kMaxSquaredCells = 16777216.0;  // 2^24

enum CellFlag : uint8_t { kFreeCell = 0, kUnknownCell = 1, kOccupiedCell = 2 };

/// An inclusive range of indices along one axis.
struct Span {
  int lo = 0;
  int hi = -1;
};

/// Keys k, per axis, whose voxel centre (k + 0.5) s lies in the box; empty() when there is none.
struct KeyRange {
  std::array<int32_t, 3> lo{};
  std::array<int32_t, 3> hi{};
  bool empty() const { return lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2]; }
  bool Contains(int32_t x, int32_t y, int32_t z) const {
    return x >= lo[0] && x <= hi[0] && y >= lo[1] && y <= hi[1] && z >= lo[2] && z <= hi[2];
  }
};

KeyRange CentresIn(const Box3& box, double voxel_m) {
  KeyRange r;
  if (box.IsEmpty()) {
    r.lo.fill(0);
    r.hi.fill(-1);
    return r;
  }
  // The map stores keys with |k| < kMaxKeyMagnitude only.
  constexpr double kKeyLimit = static_cast<double>(mapping::kMaxKeyMagnitude - 1);
  for (int a = 0; a < 3; ++a) {
    const double lo = std::ceil(box.min()[a] / voxel_m - 0.5);
    const double hi = std::floor(box.max()[a] / voxel_m - 0.5);
    r.lo[a] = static_cast<int32_t>(std::clamp(lo, -kKeyLimit, kKeyLimit + 1.0));
    r.hi[a] = static_cast<int32_t>(std::clamp(hi, -kKeyLimit - 1.0, kKeyLimit));
  }
  return r;
}

/// Where the map's voxels fall on the field's cells. Map voxel k spans [k s, (k + 1) s] on each
/// axis; field cell i spans [origin + i res, origin + (i + 1) res] with origin = key0 s.
struct Lattice {
  std::array<double, 3> key0{};
  double ratio = 1.0;  ///< voxel size / cell size
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();

  /// The cells that voxel `key` overlaps along `axis` (a voxel face on a cell boundary counts
  /// for the cell beyond it only), clamped to the grid.
  Span CellsOf(int axis, int32_t key) const {
    const double u = static_cast<double>(key) - key0[static_cast<size_t>(axis)];
    const double last = static_cast<double>(dims[axis] - 1);
    const double lo = std::clamp(std::floor(u * ratio), 0.0, last);
    const double hi = std::clamp(std::ceil((u + 1.0) * ratio) - 1.0, lo, last);
    return {static_cast<int>(lo), static_cast<int>(hi)};
  }
};

/// Raises the flag of every cell in the box of spans to at least `flag`.
void MarkCells(std::vector<uint8_t>& flags, const Eigen::Vector3i& dims, const Span& x,
               const Span& y, const Span& z, uint8_t flag) {
  const size_t nx = static_cast<size_t>(dims.x());
  const size_t nxy = nx * static_cast<size_t>(dims.y());
  for (int k = z.lo; k <= z.hi; ++k) {
    for (int j = y.lo; j <= y.hi; ++j) {
      uint8_t* row = flags.data() + static_cast<size_t>(k) * nxy + static_cast<size_t>(j) * nx;
      for (int i = x.lo; i <= x.hi; ++i) row[i] = std::max(row[i], flag);
    }
  }
}

/// Occupied voxels whose centre lies in `keys` (the bounds), block by block.
void MarkOccupied(const mapping::OccupancyGrid& grid, const KeyRange& keys, const Lattice& lattice,
                  std::vector<uint8_t>& flags) {
  if (keys.empty()) return;
  const float occupied = grid.occupied_log_odds();
  grid.ForEachBlock([&](const OccupancyBlock& b) {
    const std::array<int32_t, 3> first = {b.key.x * kBlockEdge, b.key.y * kBlockEdge,
                                          b.key.z * kBlockEdge};
    for (int a = 0; a < 3; ++a) {
      if (first[static_cast<size_t>(a)] + kBlockEdge - 1 < keys.lo[static_cast<size_t>(a)] ||
          first[static_cast<size_t>(a)] > keys.hi[static_cast<size_t>(a)]) {
        return;
      }
    }
    // Most blocks of a map are observed free: skip them with one vectorisable scan.
    int at_threshold = 0;
    for (const float l : b.log_odds) at_threshold += l >= occupied ? 1 : 0;
    if (at_threshold == 0) return;
    b.known.ForEachSet([&](int i) {
      if (b.log_odds[static_cast<size_t>(i)] < occupied) return;
      const VoxelKey k = mapping::KeyOf(b.key, i);
      if (!keys.Contains(k.x, k.y, k.z)) return;
      MarkCells(flags, lattice.dims, lattice.CellsOf(0, k.x), lattice.CellsOf(1, k.y),
                lattice.CellsOf(2, k.z), kOccupiedCell);
    });
  });
}

/// Unknown voxels whose centre lies in `keys` (the ROI within the bounds): one hash lookup per
/// block; a block the map never allocated is marked as one box of cells.
void MarkUnknown(const mapping::OccupancyGrid& grid, const KeyRange& keys, const Lattice& lattice,
                 std::vector<uint8_t>& flags) {
  if (keys.empty()) return;
  const int32_t bx0 = keys.lo[0] >> kBlockShift, bx1 = keys.hi[0] >> kBlockShift;
  const int32_t by0 = keys.lo[1] >> kBlockShift, by1 = keys.hi[1] >> kBlockShift;
  const int32_t bz0 = keys.lo[2] >> kBlockShift, bz1 = keys.hi[2] >> kBlockShift;
  std::array<std::array<Span, kBlockEdge>, 3> spans;  // per axis, per local index
  for (int32_t bz = bz0; bz <= bz1; ++bz) {
    for (int32_t by = by0; by <= by1; ++by) {
      for (int32_t bx = bx0; bx <= bx1; ++bx) {
        const BlockKey bk{bx, by, bz};
        // The block's voxels inside the range, per axis.
        const std::array<int32_t, 3> base = {bx * kBlockEdge, by * kBlockEdge, bz * kBlockEdge};
        std::array<int32_t, 3> lo{}, hi{};
        for (size_t a = 0; a < 3; ++a) {
          lo[a] = std::max(base[a], keys.lo[a]);
          hi[a] = std::min(base[a] + kBlockEdge - 1, keys.hi[a]);
        }
        const OccupancyBlock* b = grid.FindBlock(bk);
        if (b == nullptr) {
          MarkCells(flags, lattice.dims,
                    {lattice.CellsOf(0, lo[0]).lo, lattice.CellsOf(0, hi[0]).hi},
                    {lattice.CellsOf(1, lo[1]).lo, lattice.CellsOf(1, hi[1]).hi},
                    {lattice.CellsOf(2, lo[2]).lo, lattice.CellsOf(2, hi[2]).hi}, kUnknownCell);
          continue;
        }
        bool all_known = true;
        for (const uint64_t w : b->known.words) all_known = all_known && w == ~uint64_t{0};
        if (all_known) continue;
        for (size_t a = 0; a < 3; ++a) {
          for (int32_t k = lo[a]; k <= hi[a]; ++k) {
            spans[a][static_cast<size_t>(k - base[a])] = lattice.CellsOf(static_cast<int>(a), k);
          }
        }
        for (int32_t z = lo[2]; z <= hi[2]; ++z) {
          const int lz = z - base[2];
          for (int32_t y = lo[1]; y <= hi[1]; ++y) {
            const int ly = y - base[1];
            for (int32_t x = lo[0]; x <= hi[0]; ++x) {
              const int lx = x - base[0];
              if (b->known.test(lx | (ly << kBlockShift) | (lz << (2 * kBlockShift)))) continue;
              MarkCells(flags, lattice.dims, spans[0][static_cast<size_t>(lx)],
                        spans[1][static_cast<size_t>(ly)], spans[2][static_cast<size_t>(lz)],
                        kUnknownCell);
            }
          }
        }
      }
    }
  }
}

/// Clears the unknown-obstacle flag of every cell whose centre lies inside a free-space sphere.
void ClearFreeSpace(const std::vector<Sphere>& free_space, const Eigen::Vector3d& origin,
                    double res, const Eigen::Vector3i& dims, std::vector<uint8_t>& flags) {
  const size_t nx = static_cast<size_t>(dims.x());
  const size_t nxy = nx * static_cast<size_t>(dims.y());
  for (const Sphere& s : free_space) {
    std::array<Span, 3> span;
    bool outside = false;
    for (int a = 0; a < 3; ++a) {
      // Cells whose centre (i + 0.5) res may lie within [c - r, c + r].
      const double lo = std::ceil((s.center[a] - s.radius - origin[a]) / res - 0.5);
      const double hi = std::floor((s.center[a] + s.radius - origin[a]) / res - 0.5);
      const double last = static_cast<double>(dims[a] - 1);
      if (hi < 0.0 || lo > last) outside = true;
      span[static_cast<size_t>(a)] = {static_cast<int>(std::clamp(lo, 0.0, last)),
                                      static_cast<int>(std::clamp(hi, 0.0, last))};
    }
    if (outside) continue;
    const double r2 = s.radius * s.radius;
    for (int k = span[2].lo; k <= span[2].hi; ++k) {
      const double dz = origin.z() + (k + 0.5) * res - s.center.z();
      for (int j = span[1].lo; j <= span[1].hi; ++j) {
        const double dy = origin.y() + (j + 0.5) * res - s.center.y();
        uint8_t* row = flags.data() + static_cast<size_t>(k) * nxy + static_cast<size_t>(j) * nx;
        for (int i = span[0].lo; i <= span[0].hi; ++i) {
          if (row[i] != kUnknownCell) continue;
          const double dx = origin.x() + (i + 0.5) * res - s.center.x();
          if (dx * dx + dy * dy + dz * dz <= r2) row[i] = kFreeCell;
        }
      }
    }
  }
}

/// Scratch space of the 1D transform.
struct EdtScratch {
  std::vector<float> in, out;
  std::vector<float> tile;  ///< a slab of lines, transposed
  std::vector<int> v;       ///< sites of the lower envelope, left to right
  std::vector<double> a;    ///< their in[v] + v²
  void Resize(int n) {
    const size_t size = static_cast<size_t>(n);
    in.resize(size);
    out.resize(size);
    v.resize(size);
    a.resize(size);
  }
};

/// Felzenszwalb & Huttenlocher's 1D squared distance transform of `in` (n samples) into `out`:
/// out[x] = min(cap, min_q in[q] + (x − q)²). Samples >= cap are no sites (they could only give
/// values >= cap). At least one sample must be below cap.
///
/// The parabolas' intersections are compared cross-multiplied instead of divided out, and the
/// scan advances to the next parabola while it is no higher at x: no division, and exact while
/// the products stay below 2^53 (lines of up to ~10^5 cells).
void Edt1d(int n, float cap, EdtScratch& s) {
  const float* f = s.in.data();
  int* v = s.v.data();
  double* a = s.a.data();
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] >= cap) continue;
    const double aq = static_cast<double>(f[q]) + static_cast<double>(q) * q;
    // Pop the last parabola while q's parabola overtakes it no later than it overtook the one
    // before: (aq − ap) / (2 (q − p)) <= (ap − ar) / (2 (p − r)).
    while (k >= 1) {
      const int p = v[k], r = v[k - 1];
      if ((aq - a[k]) * static_cast<double>(p - r) > (a[k] - a[k - 1]) * static_cast<double>(q - p))
        break;
      --k;
    }
    ++k;
    v[k] = q;
    a[k] = aq;
  }
  int j = 0;
  for (int x = 0; x < n; ++x) {
    // The envelope's parabolas cross once each, left to right.
    const auto value = [&](int i) {
      const double dx = x - v[i];
      return dx * dx + static_cast<double>(f[v[i]]);
    };
    double d2 = value(j);
    while (j < k) {
      const double next = value(j + 1);
      if (next > d2) break;
      d2 = next;
      ++j;
    }
    s.out[static_cast<size_t>(x)] = d2 < cap ? static_cast<float>(d2) : cap;
  }
}

/// The first pass of the squared EDT, along x, where every sample is 0 (an obstacle) or `cap`:
/// the squared distance to the nearest obstacle in the row, by a scan each way.
void EdtRows(std::vector<float>& d, const Eigen::Vector3i& dims, float cap) {
  const size_t nx = static_cast<size_t>(dims.x());
  const size_t rows = static_cast<size_t>(dims.y()) * static_cast<size_t>(dims.z());
  constexpr int kNone = std::numeric_limits<int>::max() / 4;
  std::vector<int> gap(nx);
  for (size_t r = 0; r < rows; ++r) {
    float* row = d.data() + r * nx;
    if (std::find(row, row + nx, 0.0f) == row + nx) continue;  // no obstacle: all at the cap
    int since = kNone;  // cells since the last obstacle to the left
    for (size_t x = 0; x < nx; ++x) {
      since = row[x] == 0.0f ? 0 : std::min(since + 1, kNone);
      gap[x] = since;
    }
    since = kNone;
    for (size_t x = nx; x-- > 0;) {
      since = row[x] == 0.0f ? 0 : std::min(since + 1, kNone);
      const double g = std::min(gap[x], since);
      row[x] = g * g < cap ? static_cast<float>(g * g) : cap;
    }
  }
}

/// One separable pass of the squared EDT along `axis` (y or z), in place. The lines are handled
/// a slab at a time (all x for one index of the third axis): the slab's rows are read and
/// written whole, transposed through `tile`, so no line is gathered with a large stride. Lines
/// without a site are left as they are (all at the cap).
void EdtPass(std::vector<float>& d, const Eigen::Vector3i& dims, int axis, float cap,
             EdtScratch& scratch) {
  const size_t nx = static_cast<size_t>(dims.x());
  const size_t nxy = nx * static_cast<size_t>(dims.y());
  const size_t n = static_cast<size_t>(dims[axis]);
  const size_t step = axis == 1 ? nx : nxy;  // between consecutive samples of a line
  const size_t slab_step = axis == 1 ? nxy : nx;
  const int slabs = axis == 1 ? dims.z() : dims.y();
  scratch.Resize(dims[axis]);
  std::vector<float>& tile = scratch.tile;  // [x][t]
  tile.resize(nx * n);
  std::vector<uint8_t> has_site(nx);
  for (int o = 0; o < slabs; ++o) {
    const size_t base = static_cast<size_t>(o) * slab_step;
    std::fill(has_site.begin(), has_site.end(), uint8_t{0});
    for (size_t t = 0; t < n; ++t) {
      const float* row = d.data() + base + t * step;
      for (size_t x = 0; x < nx; ++x) {
        tile[x * n + t] = row[x];
        has_site[x] |= row[x] < cap ? 1 : 0;
      }
    }
    bool any = false;
    for (size_t x = 0; x < nx; ++x) {
      if (!has_site[x]) continue;
      any = true;
      std::copy_n(tile.data() + x * n, n, scratch.in.data());
      Edt1d(dims[axis], cap, scratch);
      std::copy_n(scratch.out.data(), n, tile.data() + x * n);
    }
    if (!any) continue;
    for (size_t t = 0; t < n; ++t) {
      float* row = d.data() + base + t * step;
      for (size_t x = 0; x < nx; ++x) row[x] = tile[x * n + t];
    }
  }
}

/// The largest float not above `v` (v >= 0): stored values stay lower bounds.
/// Unknown cells wholly inside the half-space n·p < d (h = (n, d)) become free.
void ClearHalfspace(const Eigen::Vector4d& h, const Eigen::Vector3d& origin, double res,
                    const Eigen::Vector3i& dims, std::vector<uint8_t>& flags) {
  const Eigen::Vector3d n = h.head<3>();
  // The cell's farthest point along n is its centre plus half the cell's extent projected on n.
  const double reach = 0.5 * res * n.cwiseAbs().sum();
  size_t i = 0;
  for (int z = 0; z < dims.z(); ++z) {
    for (int y = 0; y < dims.y(); ++y) {
      for (int x = 0; x < dims.x(); ++x, ++i) {
        if (flags[i] != kUnknownCell) continue;
        const Eigen::Vector3d c = origin + res * Eigen::Vector3d(x + 0.5, y + 0.5, z + 0.5);
        if (n.dot(c) + reach < h[3]) flags[i] = kFreeCell;
      }
    }
  }
}

/// Unknown cells farther than `band_m` from every occupied cell (centre to centre) become free:
/// only the unseen space next to what the camera saw of the plant stays an obstacle.
void KeepUnknownNearOccupied(double band_m, double res, const Eigen::Vector3i& dims,
                             std::vector<uint8_t>& flags) {
  const double band_cells = band_m / res;
  const float cap =
      static_cast<float>(std::min(std::pow(std::ceil(band_cells) + 1.0, 2.0), kMaxSquaredCells));
  std::vector<float> d(flags.size());
  for (size_t i = 0; i < flags.size(); ++i) d[i] = flags[i] == kOccupiedCell ? 0.0f : cap;
  EdtRows(d, dims, cap);
  EdtScratch scratch;
  EdtPass(d, dims, 1, cap, scratch);
  EdtPass(d, dims, 2, cap, scratch);
  const double band2 = band_cells * band_cells;
  for (size_t i = 0; i < flags.size(); ++i) {
    if (flags[i] == kUnknownCell && static_cast<double>(d[i]) > band2) flags[i] = kFreeCell;
  }
}

/// Obstacle cells, and of those the unknown ones.
std::pair<int64_t, int64_t> CountObstacles(const std::vector<uint8_t>& flags) {
  int64_t obstacles = 0, unknown = 0;
  for (const uint8_t f : flags) {
    obstacles += f != kFreeCell ? 1 : 0;
    unknown += f == kUnknownCell ? 1 : 0;
  }
  return {obstacles, unknown};
}

float FloatBelow(double v) {
  float f = static_cast<float>(v);
  if (static_cast<double>(f) > v) f = std::nextafter(f, 0.0f);
  return f;
}

}  // namespace

Status ObstacleFieldOptions::Validate() const {
  std::vector<std::string> bad;
  if (!(std::isfinite(resolution_m) && resolution_m >= kMinResolution &&
        resolution_m <= kMaxResolution)) {
    bad.push_back(fmt::format("resolution_m ({}) must be in [{}, {}]", resolution_m, kMinResolution,
                              kMaxResolution));
  }
  if (!(std::isfinite(max_distance_m) && max_distance_m > 0.0)) {
    bad.push_back(fmt::format("max_distance_m ({}) must be finite and > 0", max_distance_m));
  }
  if (!(std::isfinite(start_clearance_m) && start_clearance_m >= 0.0)) {
    bad.push_back(fmt::format("start_clearance_m ({}) must be finite and >= 0", start_clearance_m));
  }
  if (!(unknown_band_m >= 0.0) || !std::isfinite(unknown_band_m)) {
    bad.push_back(fmt::format("unknown_band_m ({}) must be finite and >= 0", unknown_band_m));
  }
  if (max_cells < 1) bad.push_back(fmt::format("max_cells ({}) must be >= 1", max_cells));
  if (bad.empty()) return Status::Ok();
  std::string message = "invalid obstacle field options: ";
  for (size_t i = 0; i < bad.size(); ++i) message += (i > 0 ? "; " : "") + bad[i];
  return InvalidArgumentError(message);
}

Result<ObstacleField> ObstacleField::Build(const mapping::OccupancyGrid& grid, const Box3& roi,
                                           const Box3& bounds, const ObstacleFieldOptions& options,
                                           const std::vector<Sphere>& free_space,
                                           const std::optional<Eigen::Vector4d>& free_halfspace) {
  const SteadyClock::time_point t0 = SteadyClock::now();
  AVP_RETURN_IF_ERROR(options.Validate());
  if (bounds.IsEmpty() || !bounds.min().allFinite() || !bounds.max().allFinite()) {
    return InvalidArgumentError(fmt::format(
        "invalid obstacle field bounds: {} must be a finite, non-empty box", bounds.ToString()));
  }
  for (size_t i = 0; i < free_space.size(); ++i) {
    const Sphere& s = free_space[i];
    if (!s.center.allFinite() || !std::isfinite(s.radius) || s.radius < 0.0) {
      return InvalidArgumentError(fmt::format(
          "invalid obstacle field free space: sphere {} (centre ({}, {}, {}), radius {}) must be "
          "finite with radius >= 0",
          i, s.center.x(), s.center.y(), s.center.z(), s.radius));
    }
  }

  // The grid: `bounds` grown outward to whole map voxels, so every voxel whose centre lies in
  // `bounds` lies inside it.
  const double voxel_m = grid.voxel_size_m();
  const double res = options.resolution_m;
  Lattice lattice;
  lattice.ratio = voxel_m / res;
  std::array<double, 3> dims_d{};
  double cells_d = 1.0;
  for (size_t a = 0; a < 3; ++a) {
    const double key_lo = std::floor(bounds.min()[static_cast<Eigen::Index>(a)] / voxel_m);
    const double key_hi = std::ceil(bounds.max()[static_cast<Eigen::Index>(a)] / voxel_m);
    lattice.key0[a] = key_lo;
    dims_d[a] = std::max(1.0, std::ceil((key_hi - key_lo) * lattice.ratio));
    cells_d *= dims_d[a];
  }
  constexpr double kMaxDim = 1 << 30;  // cells along one axis (indices are ints)
  if (cells_d > static_cast<double>(options.max_cells) ||
      std::max({dims_d[0], dims_d[1], dims_d[2]}) > kMaxDim) {
    return ResourceExhaustedError(fmt::format(
        "obstacle field over {} at resolution_m {} needs {:.0f} cells ({:.0f} x {:.0f} x {:.0f}), "
        "more than max_cells ({}){}",
        bounds.ToString(), res, cells_d, dims_d[0], dims_d[1], dims_d[2], options.max_cells,
        cells_d > static_cast<double>(options.max_cells) ? "" : " or 2^30 along one axis"));
  }
  ObstacleField field;
  field.bounds_ = bounds;
  field.resolution_m_ = res;
  field.max_distance_m_ = options.max_distance_m;
  field.dims_ = Eigen::Vector3i(static_cast<int>(dims_d[0]), static_cast<int>(dims_d[1]),
                                static_cast<int>(dims_d[2]));
  field.origin_ = Eigen::Vector3d(lattice.key0[0], lattice.key0[1], lattice.key0[2]) * voxel_m;
  lattice.dims = field.dims_;
  const size_t n = static_cast<size_t>(cells_d);

  // Obstacle cells.
  std::vector<uint8_t> flags(n, kFreeCell);
  MarkOccupied(grid, CentresIn(bounds, voxel_m), lattice, flags);
  if (options.unknown_is_obstacle) {
    MarkUnknown(grid, CentresIn(roi.Intersection(bounds), voxel_m), lattice, flags);
    ClearFreeSpace(free_space, field.origin_, res, field.dims_, flags);
    if (free_halfspace) ClearHalfspace(*free_halfspace, field.origin_, res, field.dims_, flags);
    if (options.unknown_band_m > 0.0)
      KeepUnknownNearOccupied(options.unknown_band_m, res, field.dims_, flags);
  }
  std::tie(field.obstacle_cells_, field.unknown_cells_) = CountObstacles(flags);

  // Distances: the squared EDT in cells², capped, then metres.
  if (field.obstacle_cells_ == 0) {
    field.cells_.assign(n, FloatBelow(options.max_distance_m));
  } else {
    const double half_diagonal = 0.5 * std::sqrt(3.0) * res;
    // Squared distances at or above `cap` (cells²) all map to max_distance_m.
    const double cap_cells = std::ceil((options.max_distance_m + half_diagonal) / res) + 1.0;
    const double cap_d = std::min(cap_cells * cap_cells, kMaxSquaredCells);
    const float cap = static_cast<float>(cap_d);
    field.cells_.resize(n);
    for (size_t i = 0; i < n; ++i) field.cells_[i] = flags[i] != kFreeCell ? 0.0f : cap;
    flags = {};
    EdtRows(field.cells_, field.dims_, cap);
    EdtScratch scratch;
    EdtPass(field.cells_, field.dims_, 1, cap, scratch);
    EdtPass(field.cells_, field.dims_, 2, cap, scratch);
    const auto metres = [&](double d2) {
      return FloatBelow(
          std::clamp(std::sqrt(d2) * res - half_diagonal, 0.0, options.max_distance_m));
    };
    // Squared distances are integers in [0, cap]: a table unless the cap is huge.
    if (cap_d <= 65536.0) {
      std::vector<float> table(static_cast<size_t>(cap_d) + 1);
      for (size_t i = 0; i < table.size(); ++i) table[i] = metres(static_cast<double>(i));
      for (float& c : field.cells_) c = table[static_cast<size_t>(c)];
    } else {
      for (float& c : field.cells_) c = metres(static_cast<double>(c));
    }
  }
  field.build_ms_ = MsSince(t0);
  return field;
}

double ObstacleField::Distance(const Eigen::Vector3d& p_W) const {
  if (cells_.empty() || obstacle_cells_ == 0) return max_distance_m_;
  if (!p_W.allFinite()) return 0.0;
  const Eigen::Vector3d extent = dims_.cast<double>() * resolution_m_;
  const Eigen::Vector3d local = p_W - origin_;
  const Eigen::Vector3d inside = local.cwiseMax(0.0).cwiseMin(extent);
  const Eigen::Vector3i cell =
      (inside / resolution_m_).cast<int>().cwiseMin(dims_ - Eigen::Vector3i::Ones());
  const size_t index = static_cast<size_t>(cell.x()) +
                       static_cast<size_t>(dims_.x()) *
                           (static_cast<size_t>(cell.y()) +
                            static_cast<size_t>(dims_.y()) * static_cast<size_t>(cell.z()));
  const Eigen::Vector3d centre = (cell.cast<double>().array() + 0.5) * resolution_m_;
  const double at_grid =
      std::max(0.0, static_cast<double>(cells_[index]) - (inside - centre).norm());
  const double out2 = (local - inside).squaredNorm();
  const double d = out2 > 0.0 ? std::sqrt(out2 + at_grid * at_grid) : at_grid;
  return std::min(d, max_distance_m_);
}

}  // namespace avp::motion

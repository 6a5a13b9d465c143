#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/core/parallel.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/ray_traversal.h>

namespace avp::mapping {

std::string_view ToString(FreeSpaceCarving carving) {
  switch (carving) {
    case FreeSpaceCarving::kRayCast:
      return "raycast";
    case FreeSpaceCarving::kProjective:
      return "projective";
    case FreeSpaceCarving::kNone:
      return "none";
    case FreeSpaceCarving::kEndVoxelRays:
      return "end-voxel";
  }
  return "invalid";
}

std::optional<FreeSpaceCarving> FreeSpaceCarvingFromString(std::string_view name) {
  for (FreeSpaceCarving c : kFreeSpaceCarvings) {
    if (ToString(c) == name) return c;
  }
  return std::nullopt;
}

std::vector<std::string> FreeSpaceCarvingNames() {
  std::vector<std::string> names;
  for (FreeSpaceCarving c : kFreeSpaceCarvings) names.emplace_back(ToString(c));
  return names;
}

std::vector<std::pair<FreeSpaceCarving, std::string>> FreeSpaceCarvingChoices() {
  std::vector<std::pair<FreeSpaceCarving, std::string>> choices;
  for (FreeSpaceCarving c : kFreeSpaceCarvings) choices.emplace_back(c, std::string(ToString(c)));
  return choices;
}

const OptionTable<IntegratorOptions>& IntegratorOptionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<IntegratorOptions>("integrator option");
    t->Real("max_range_m", &IntegratorOptions::max_range_m, "m", ValueRange::LeftOpen(0, 100),
            "returns beyond it carve free space up to it and mark no endpoint");
    t->Choice("carving", &IntegratorOptions::carving, FreeSpaceCarvingChoices(),
              "how free space is carved (docs/mapping.md)");
    return t;
  }();
  return *table;
}

Status IntegratorOptions::Validate() const {
  AVP_RETURN_IF_ERROR(IntegratorOptionTable().Validate(*this));
  if (pixel_stride < 1 || pixel_stride > 64 ||
      (pixel_stride > 1 && carving == FreeSpaceCarving::kProjective)) {
    return InvalidArgumentError(fmt::format(
        "integrator option pixel_stride ({}) must be in [1, 64], and 1 with projective carving",
        pixel_stride));
  }
  if (clip_box &&
      (clip_box->IsEmpty() || !clip_box->min().allFinite() || !clip_box->max().allFinite())) {
    return InvalidArgumentError(fmt::format(
        "integrator option clip_box ({}) must be finite and non-empty", clip_box->ToString()));
  }
  return Status::Ok();
}

std::string IntegrationStats::ToString() const {
  return fmt::format(
      "pixels {}, invalid depth {}, beyond max range {}, rejected {}, endpoints {}, occupied "
      "updates {}, free updates {}, masked endpoints {}, semantic observations {}, {:.1f} ms",
      pixels, invalid_depth, beyond_max_range, rejected_points, endpoints, occupied_updates,
      free_updates, masked_endpoints, semantics.observations, seconds * 1e3);
}

namespace {

using Clock = std::chrono::steady_clock;

/// One ray of a frame: its end point and whether the end point is a return (a hit) or the
/// max-range truncation of a longer ray (free space only).
struct RayEnd {
  Eigen::Vector3d end;
  bool hit = false;
  int32_t label = -1;  ///< mask index of the pixel (hits only), -1 outside every mask
};

/// Whether a point can have a voxel key at all: beyond 1e5 m it lies outside every key range
/// (and llround's), and RayWalker refuses it.
bool Keyable(const Eigen::Vector3d& p) { return p.cwiseAbs().maxCoeff() < 1e5; }

/// Runs fn(thread_index) on `n` threads (the calling thread is thread 0).
template <typename F>
void RunParallel(int n, F&& fn) {
  if (n <= 1) {
    fn(0);
    return;
  }
  std::atomic<int> next{0};
  RunWorkers(static_cast<size_t>(n), [&] {
    for (int t = next.fetch_add(1); t < n; t = next.fetch_add(1)) fn(t);
  });
}

/// Ray i belongs to thread (i / kChunk) % n: interleaved chunks balance near and far rays.
constexpr size_t kChunk = 512;

/// Marks the endpoints (one hit per voxel per frame) and collects semantic observations.
/// Single-threaded: it allocates the endpoint blocks.
void ApplyHits(const std::vector<RayEnd>& rays, OccupancyGrid& grid, bool collect_semantics,
               IntegrationStats& stats, std::vector<std::pair<VoxelKey, int32_t>>& sem_hits) {
  OccupancyGrid::Accessor acc(grid);
  const double s = grid.voxel_size_m();
  const float hit = grid.hit_log_odds();
  for (const RayEnd& r : rays) {
    if (!r.hit) continue;
    if (!Keyable(r.end)) {
      ++stats.rejected_points;
      continue;
    }
    const VoxelKey k = FixedPointKey(r.end, s);
    if (!grid.Admits(k)) {
      ++stats.rejected_points;
      continue;
    }
    if (acc.UpdateOnce(k, hit)) ++stats.occupied_updates;
    if (!collect_semantics) continue;
    if (r.label >= 0) {
      sem_hits.emplace_back(k, r.label);
    } else {
      const OccupancyBlock* b = acc.BlockFor(k);
      if (b->semantics != nullptr) {
        const SemanticCell& c = (*b->semantics)[LocalIndex(k)];
        if (c.has_label() || c.observations > 0) sem_hits.emplace_back(k, -1);
      }
    }
  }
}

/// The ray through one pixel, for projective carving (CarveProjective).
struct PixelRay {
  Eigen::Vector3d
      inv_dir_W;       ///< 1 / (R_WC (x, y, 1)) per axis: t is the depth along the optical axis
  float t_end = 0.0f;  ///< parameter of the end point (0 for invalid pixels)
  VoxelKey end_key;    ///< voxel of the end point (or of the max-range point)
};

constexpr double kNearRadius = 8.0;  // voxels

bool RayCarvesVoxel(const PixelRay& r, const Eigen::Vector3d& o, const Eigen::Vector3d& lo,
                    const Eigen::Vector3d& hi, const VoxelKey& key) {
  if (r.t_end <= 0.0f || r.end_key == key) return false;
  // Slab test; 1/0 = +-inf makes an axis-parallel ray pass or miss its slab as it should (the
  // NaN of 0 * inf, for an origin exactly on a slab face, is ignored by max/min below).
  double tmin = 0.0, tmax = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    const double inv = r.inv_dir_W[a];
    double t1 = (lo[a] - o[a]) * inv, t2 = (hi[a] - o[a]) * inv;
    if (t1 > t2) std::swap(t1, t2);
    tmin = t1 > tmin ? t1 : tmin;
    tmax = t2 < tmax ? t2 : tmax;
  }
  return tmin < tmax && tmin < static_cast<double>(r.t_end);
}

/// A frame's camera geometry, shared by the projective carving stages.
struct ProjectiveCamera {
  const CameraIntrinsics& K;
  const RigidTransform& X_WC;
  int w = 0, h = 0;  ///< image size (pixels)
  double s = 0.0;    ///< voxel edge (m)
  Eigen::Matrix3d R_CW;
  Eigen::Matrix3d R_WC;
  Eigen::Vector3d t_CW;
  Eigen::Vector3d o;  ///< optical centre, world frame
  /// Half extent along the optical axis of a cube of edge 1 (m per m of edge).
  double z_half_per_edge = 0.0;
};

ProjectiveCamera MakeProjectiveCamera(const RgbdFrame& frame, double voxel_size_m) {
  const RigidTransform X_CW = frame.X_WC.inverse();
  const Eigen::Matrix3d& R_CW = X_CW.rotation();
  return {frame.K,
          frame.X_WC,
          frame.K.width,
          frame.K.height,
          voxel_size_m,
          R_CW,
          frame.X_WC.rotation(),
          X_CW.translation(),
          frame.X_WC.translation(),
          0.5 * (std::abs(R_CW(2, 0)) + std::abs(R_CW(2, 1)) + std::abs(R_CW(2, 2)))};
}

/// The per-pixel rays of a frame (row-major, w x h) and the largest end parameter.
struct PixelRays {
  std::vector<PixelRay> px;
  double far_t = 0.0;  ///< max t_end over the pixels (m along the optical axis)
};

/// Per-pixel rays with the same end points as the ray-cast path (`rays`: one per valid pixel, in
/// row-major order).
PixelRays BuildPixelRays(const ProjectiveCamera& cam, const DepthImage& depth,
                         const std::vector<RayEnd>& rays) {
  const CameraIntrinsics& K = cam.K;
  PixelRays out;
  out.px.resize(static_cast<size_t>(cam.w) * cam.h);
  size_t ray_index = 0;
  for (int v = 0; v < cam.h; ++v) {
    for (int u = 0; u < cam.w; ++u) {
      const float d = depth.at(u, v);
      if (!std::isfinite(d) || d <= 0.0f) continue;
      PixelRay& r = out.px[static_cast<size_t>(v) * cam.w + u];
      const Eigen::Vector3d dir_C((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0);
      r.inv_dir_W = (cam.R_WC * dir_C).cwiseInverse();
      const RayEnd& e = rays[ray_index++];
      r.end_key = VoxelKey::FromPoint(e.end, cam.s);
      r.t_end = static_cast<float>((cam.R_CW * e.end + cam.t_CW).z());
      if (!(r.t_end > 0.0f)) r.t_end = 0.0f;
      out.far_t = std::max(out.far_t, static_cast<double>(r.t_end));
    }
  }
  return out;
}

/// Max pyramid of the pixels' t_end: level l holds the max over 2^l x 2^l pixel tiles (level 0 is
/// t_end itself).
class MaxDepthPyramid {
 public:
  MaxDepthPyramid(const std::vector<PixelRay>& px, int w, int h) {
    std::vector<float> t_end(px.size());
    for (size_t i = 0; i < px.size(); ++i) t_end[i] = px[i].t_end;
    levels_.push_back(std::move(t_end));
    sizes_.emplace_back(w, h);
    while (sizes_.back().first > 1 || sizes_.back().second > 1) {
      const auto [pw, ph] = sizes_.back();
      const int nw = (pw + 1) / 2, nh = (ph + 1) / 2;
      std::vector<float> next(static_cast<size_t>(nw) * nh, 0.0f);
      const std::vector<float>& prev = levels_.back();
      for (int y = 0; y < ph; ++y) {
        for (int x = 0; x < pw; ++x) {
          float& m = next[static_cast<size_t>(y / 2) * nw + x / 2];
          m = std::max(m, prev[static_cast<size_t>(y) * pw + x]);
        }
      }
      levels_.push_back(std::move(next));
      sizes_.emplace_back(nw, nh);
    }
  }

  /// t_end of pixel row y (w values).
  const float* Row(int y) const {
    return levels_[0].data() + static_cast<size_t>(y) * sizes_[0].first;
  }

  /// Max of t_end over the pixel rectangle [u0, u1] x [v0, v1] (clipped, non-empty), conservative.
  float MaxOver(int u0, int v0, int u1, int v1) const {
    int level = 0;
    while ((u1 >> level) - (u0 >> level) > 1 || (v1 >> level) - (v0 >> level) > 1) ++level;
    const auto [pw, ph] = sizes_[static_cast<size_t>(level)];
    const std::vector<float>& p = levels_[static_cast<size_t>(level)];
    float m = 0.0f;
    for (int y = v0 >> level; y <= std::min(v1 >> level, ph - 1); ++y) {
      for (int x = u0 >> level; x <= std::min(u1 >> level, pw - 1); ++x) {
        m = std::max(m, p[static_cast<size_t>(y) * pw + x]);
      }
    }
    return m;
  }

 private:
  std::vector<std::vector<float>> levels_;
  std::vector<std::pair<int, int>> sizes_;  ///< (width, height) per level
};

/// The 8 corners of a voxel of edge s relative to its centre, in the camera frame.
std::array<Eigen::Vector3d, 8> VoxelCornerOffsets(const Eigen::Matrix3d& R_CW, double s) {
  std::array<Eigen::Vector3d, 8> corner_offsets;
  for (int c = 0; c < 8; ++c) {
    corner_offsets[static_cast<size_t>(c)] =
        R_CW *
        (Eigen::Vector3d((c & 1) ? 0.5 : -0.5, (c & 2) ? 0.5 : -0.5, (c & 4) ? 0.5 : -0.5) * s);
  }
  return corner_offsets;
}

/// The voxels within kNearRadius voxels of the optical centre that some ray carves, in a dense
/// cube of nd^3 flags around the centre's voxel.
struct NearCarving {
  VoxelKey centre;  ///< voxel of the optical centre
  int nr = 0;       ///< half edge of the cube (voxels)
  int nd = 0;       ///< edge of the cube (voxels)
  double r2 = 0.0;  ///< squared radius of the near sphere (m^2)
  std::vector<uint8_t> carved;

  size_t Index(const VoxelKey& k) const {
    return static_cast<size_t>((k.x - centre.x + nr) +
                               nd * ((k.y - centre.y + nr) + nd * (k.z - centre.z + nr)));
  }
};

/// Near the optical centre, where a voxel's footprint is unbounded: walks the rays (only while
/// inside the near sphere).
NearCarving CarveNearOpticalCentre(const std::vector<RayEnd>& rays, const Eigen::Vector3d& o,
                                   double s, int threads) {
  NearCarving near;
  near.centre = VoxelKey::FromPoint(o, s);
  near.nr = static_cast<int>(kNearRadius) + 2;
  near.nd = 2 * near.nr + 1;
  near.r2 = (kNearRadius * s) * (kNearRadius * s);
  const auto is_near = [&](const VoxelKey& k) { return (k.Center(s) - o).squaredNorm() < near.r2; };
  std::vector<std::vector<uint8_t>> near_parts(static_cast<size_t>(threads));
  RunParallel(threads, [&](int th) {
    std::vector<uint8_t>& part = near_parts[static_cast<size_t>(th)];
    part.assign(static_cast<size_t>(near.nd) * near.nd * near.nd, 0);
    for (size_t i = static_cast<size_t>(th); i < rays.size(); i += static_cast<size_t>(threads)) {
      RayWalker walker(o, rays[i].end, s);
      if (!walker.ok()) continue;
      while (walker.remaining() > 0) {
        const VoxelKey k = walker.key();
        if (!is_near(k)) break;
        part[near.Index(k)] = 1;
        walker.Step();
      }
    }
  });
  near.carved = std::move(near_parts[0]);
  for (size_t t = 1; t < near_parts.size(); ++t) {
    for (size_t i = 0; i < near.carved.size(); ++i) near.carved[i] |= near_parts[t][i];
  }
  return near;
}

/// The blocks of the axis-aligned box of the frustum up to far_t (the optical centre included).
std::pair<BlockKey, BlockKey> FrustumBlockRange(const ProjectiveCamera& cam, double far_t) {
  const CameraIntrinsics& K = cam.K;
  Box3 aabb;
  aabb.Extend(cam.o);
  const double us[2] = {-0.5, cam.w - 0.5};
  const double vs[2] = {-0.5, cam.h - 0.5};
  for (double u : us) {
    for (double v : vs) {
      aabb.Extend(cam.X_WC * (Eigen::Vector3d((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0) * far_t));
    }
  }
  return {BlockOf(VoxelKey::FromPoint(aabb.min(), cam.s)),
          BlockOf(VoxelKey::FromPoint(aabb.max(), cam.s))};
}

/// A pixel coordinate `v` (already floored or ceiled) as an int in [lo, hi], clamped in double
/// before the cast: a corner near the camera plane projects to a huge or infinite coordinate that
/// no int holds (UBSan found it); NaN gives lo.
int ClampToInt(double v, int lo, int hi) {
  if (!(v >= lo)) return lo;
  if (v > hi) return hi;
  return static_cast<int>(v);
}

/// Whether a block (centre c_C in the camera frame, half depth extent zh) may hold a carved voxel:
/// not entirely behind the camera or beyond far_t, and, when wholly in front of the image plane,
/// its projection (the box of its 8 projected corners) inside the image and not entirely behind
/// every return in it.
bool BlockMayBeCarved(const ProjectiveCamera& cam, const MaxDepthPyramid& pyramid,
                      const std::array<Eigen::Vector3d, 8>& corner_offsets, double far_t,
                      const Eigen::Vector3d& c_C, double zh) {
  const CameraIntrinsics& K = cam.K;
  if (c_C.z() + zh <= 0.0 || c_C.z() - zh >= far_t) return false;
  if (!(c_C.z() - zh > 1e-6)) return true;
  const double zn = c_C.z() - zh;
  double umin = std::numeric_limits<double>::infinity(), umax = -umin;
  double vmin = umin, vmax = -umin;
  for (const Eigen::Vector3d& off : corner_offsets) {
    const Eigen::Vector3d q = c_C + off * kBlockEdge;
    const double cu = K.fx * q.x() / q.z(), cv = K.fy * q.y() / q.z();
    umin = std::min(umin, cu);
    umax = std::max(umax, cu);
    vmin = std::min(vmin, cv);
    vmax = std::max(vmax, cv);
  }
  const int u0 = ClampToInt(std::floor(umin + K.cx), -1, cam.w);
  const int u1 = ClampToInt(std::ceil(umax + K.cx), -1, cam.w);
  const int v0 = ClampToInt(std::floor(vmin + K.cy), -1, cam.h);
  const int v1 = ClampToInt(std::ceil(vmax + K.cy), -1, cam.h);
  if (u1 < 0 || v1 < 0 || u0 >= cam.w || v0 >= cam.h) return false;
  return pyramid.MaxOver(std::max(u0, 0), std::max(v0, 0), std::min(u1, cam.w - 1),
                         std::min(v1, cam.h - 1)) > zn;
}

/// Candidate blocks: in the box of the frustum up to far_t and BlockMayBeCarved, in z, y, x order.
std::vector<BlockKey> CandidateBlocks(const ProjectiveCamera& cam, const MaxDepthPyramid& pyramid,
                                      const std::array<Eigen::Vector3d, 8>& corner_offsets,
                                      double far_t) {
  const auto [blo, bhi] = FrustumBlockRange(cam, far_t);
  std::vector<BlockKey> candidates;
  const double be = kBlockEdge * cam.s;
  for (int32_t bz = blo.z; bz <= bhi.z; ++bz) {
    for (int32_t by = blo.y; by <= bhi.y; ++by) {
      for (int32_t bx = blo.x; bx <= bhi.x; ++bx) {
        const Eigen::Vector3d c_W =
            (Eigen::Vector3d(bx, by, bz) + Eigen::Vector3d::Constant(0.5)) * be;
        const Eigen::Vector3d c_C = cam.R_CW * c_W + cam.t_CW;
        const double zh = cam.z_half_per_edge * be;
        if (BlockMayBeCarved(cam, pyramid, corner_offsets, far_t, c_C, zh)) {
          candidates.push_back({bx, by, bz});
        }
      }
    }
  }
  return candidates;
}

/// Everything the per-voxel carve test reads (no map access).
struct VoxelCarveInputs {
  const ProjectiveCamera& cam;
  const std::vector<PixelRay>& px;
  const MaxDepthPyramid& pyramid;
  const std::array<Eigen::Vector3d, 8>& corner_offsets;
  const NearCarving& near;
  double far_t = 0.0;
  double zh_voxel = 0.0;  ///< half depth extent of a voxel (m)
};

/// Whether a ray through a pixel whose centre may lie in the voxel's projection (the box of its 8
/// projected corners; c_C: voxel centre in the camera frame, zn: its nearest depth) carves it.
bool FootprintCarvesVoxel(const VoxelCarveInputs& in, const VoxelKey& k, const Eigen::Vector3d& c_C,
                          double zn, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  const CameraIntrinsics& K = in.cam.K;
  const int w = in.cam.w, h = in.cam.h;
  double umin = std::numeric_limits<double>::infinity(), umax = -umin;
  double vmin = umin, vmax = -umin;
  for (const Eigen::Vector3d& off : in.corner_offsets) {
    const Eigen::Vector3d q = c_C + off;
    const double iz = 1.0 / q.z();
    const double cu = K.fx * q.x() * iz, cv = K.fy * q.y() * iz;
    umin = std::min(umin, cu);
    umax = std::max(umax, cu);
    vmin = std::min(vmin, cv);
    vmax = std::max(vmax, cv);
  }
  // Clamped before the cast (ClampToInt): out-of-image spans stay empty.
  const int u0 = ClampToInt(std::floor(umin + K.cx), 0, w);
  const int u1 = ClampToInt(std::ceil(umax + K.cx), -1, w - 1);
  const int v0 = ClampToInt(std::floor(vmin + K.cy), 0, h);
  const int v1 = ClampToInt(std::ceil(vmax + K.cy), -1, h - 1);
  if (u0 > u1 || v0 > v1) return false;
  if (in.pyramid.MaxOver(u0, v0, u1, v1) <= zn) return false;
  for (int y = v0; y <= v1; ++y) {
    const float* row = in.pyramid.Row(y);
    for (int x = u0; x <= u1; ++x) {
      if (row[x] <= zn) continue;
      if (RayCarvesVoxel(in.px[static_cast<size_t>(y) * w + x], in.cam.o, lo, hi, k)) return true;
    }
  }
  return false;
}

/// Whether some ray carves voxel k: near the optical centre the walked rays decide; elsewhere
/// first the pixel under the voxel centre, then (FootprintCarvesVoxel) every pixel of its
/// projection.
[[gnu::always_inline]] inline bool VoxelIsCarved(const VoxelCarveInputs& in, const VoxelKey& k) {
  const ProjectiveCamera& cam = in.cam;
  const CameraIntrinsics& K = cam.K;
  const double s = cam.s;
  const Eigen::Vector3d c_W = k.Center(s);
  if ((c_W - cam.o).squaredNorm() < in.near.r2) return in.near.carved[in.near.Index(k)] != 0;
  const Eigen::Vector3d c_C = cam.R_CW * c_W + cam.t_CW;
  const double zn = c_C.z() - in.zh_voxel;
  // Outside the near sphere, a voxel reaching behind the image plane is outside any field of view
  // below 150 degrees (checked in Integrate()).
  if (zn <= 0.0 || zn >= in.far_t) return false;
  const Eigen::Vector3d lo = Eigen::Vector3d(k.x, k.y, k.z) * s;
  const Eigen::Vector3d hi = lo + Eigen::Vector3d::Constant(s);
  const double uc = K.fx * c_C.x() / c_C.z() + K.cx, vc = K.fy * c_C.y() / c_C.z() + K.cy;
  const int pu = static_cast<int>(std::lround(uc)), pv = static_cast<int>(std::lround(vc));
  if (pu >= 0 && pv >= 0 && pu < cam.w && pv < cam.h &&
      RayCarvesVoxel(in.px[static_cast<size_t>(pv) * cam.w + pu], cam.o, lo, hi, k)) {
    return true;
  }
  return FootprintCarvesVoxel(in, k, c_C, zn, lo, hi);
}

/// Per candidate block, the voxels some ray carves (parallel, no map access).
std::vector<BlockBits> CarvedVoxelsPerBlock(const VoxelCarveInputs& in,
                                            const std::vector<BlockKey>& candidates, int threads) {
  std::vector<BlockBits> carve(candidates.size());
  RunParallel(threads, [&](int th) {
    for (size_t ci = static_cast<size_t>(th); ci < candidates.size();
         ci += static_cast<size_t>(threads)) {
      const BlockKey& bk = candidates[ci];
      BlockBits& bits = carve[ci];
      for (int i = 0; i < kBlockVoxels; ++i) {
        if (VoxelIsCarved(in, mapping::KeyOf(bk, i))) bits.set(i);
      }
    }
  });
  return carve;
}

/// Applies the carved voxels of the candidate blocks that lie wholly in the ROI: allocates the
/// blocks with something to carve, then updates them in parallel (each block belongs to one
/// thread; voxels hit in this frame keep their hit). Clears their bits in `carve`.
void ApplyWholeBlocks(const std::vector<BlockKey>& candidates, std::vector<BlockBits>& carve,
                      OccupancyGrid& grid, int threads, IntegrationStats& stats) {
  const float miss = grid.miss_log_odds();
  std::vector<BlockKey> to_prepare;
  std::vector<size_t> carving;
  for (size_t ci = 0; ci < candidates.size(); ++ci) {
    if (!carve[ci].any()) continue;
    const VoxelKey first = mapping::KeyOf(candidates[ci], 0);
    if (!grid.Admits(first) || !grid.Admits(mapping::KeyOf(candidates[ci], kBlockVoxels - 1))) {
      // Partly outside the ROI: applied voxel by voxel (ApplyRemainingVoxels).
      continue;
    }
    to_prepare.push_back(candidates[ci]);
    carving.push_back(ci);
  }
  grid.PrepareFrameBlocks(to_prepare);
  std::vector<size_t> applied(static_cast<size_t>(threads), 0);
  RunParallel(threads, [&](int th) {
    size_t n = 0;
    for (size_t j = static_cast<size_t>(th); j < carving.size();
         j += static_cast<size_t>(threads)) {
      const size_t ci = carving[j];
      OccupancyBlock& b = *grid.MutableBlock(candidates[ci]);
      carve[ci].ForEachSet([&](int i) {
        if (b.touched.test(i)) return;
        b.touched.set(i);
        b.known.set(i);
        b.changed.set(i);
        grid.ApplyUpdate(b, i, miss);
        ++n;
      });
      b.dirty = true;
      carve[ci].clear();
    }
    applied[static_cast<size_t>(th)] = n;
  });
  for (size_t n : applied) stats.free_updates += n;
}

/// Applies, voxel by voxel, what ApplyWholeBlocks left: the carved voxels of blocks partly outside
/// the ROI, then the near voxels outside every candidate block (e.g. behind the image plane).
void ApplyRemainingVoxels(const std::vector<BlockKey>& candidates,
                          const std::vector<BlockBits>& carve, const NearCarving& near,
                          OccupancyGrid& grid, IntegrationStats& stats) {
  const float miss = grid.miss_log_odds();
  OccupancyGrid::Accessor acc(grid);
  for (size_t ci = 0; ci < candidates.size(); ++ci) {
    if (!carve[ci].any()) continue;
    carve[ci].ForEachSet([&](int i) {
      const VoxelKey k = mapping::KeyOf(candidates[ci], i);
      if (grid.Admits(k) && acc.UpdateOnce(k, miss)) ++stats.free_updates;
    });
  }
  const int nd = near.nd, nr = near.nr;
  for (int z = 0; z < nd; ++z) {
    for (int y = 0; y < nd; ++y) {
      for (int x = 0; x < nd; ++x) {
        if (!near.carved[static_cast<size_t>(x + nd * (y + nd * z))]) continue;
        const VoxelKey k{near.centre.x + x - nr, near.centre.y + y - nr, near.centre.z + z - nr};
        if (grid.Admits(k) && acc.UpdateOnce(k, miss)) ++stats.free_updates;
      }
    }
  }
}

/// The box of voxels holding the origin's and every ray's end voxel (as RayWalker floors them):
/// every voxel of every walk.
std::pair<VoxelKey, VoxelKey> RayVoxelBox(const std::vector<RayEnd>& rays,
                                          const std::vector<Eigen::Vector3d>* starts,
                                          const Eigen::Vector3d& origin, double s) {
  VoxelKey lo = FixedPointKey(starts != nullptr && !starts->empty() ? starts->front() : origin, s);
  VoxelKey hi = lo;
  const auto grow = [&](const Eigen::Vector3d& p) {
    const VoxelKey k = FixedPointKey(p, s);
    lo = {std::min(lo.x, k.x), std::min(lo.y, k.y), std::min(lo.z, k.z)};
    hi = {std::max(hi.x, k.x), std::max(hi.y, k.y), std::max(hi.z, k.z)};
  };
  for (size_t i = 0; i < rays.size(); ++i) {
    if (!Keyable(rays[i].end)) continue;  // not walked (RayWalker is not ok())
    grow(rays[i].end);
    if (starts != nullptr) grow((*starts)[i]);
  }
  return {lo, hi};
}

/// The voxels a frame's rays pass through, as one dense bit map over their box of blocks,
/// block-major (a block's 512 bits are 8 consecutive words, in LocalIndex order), so that a
/// voxel's bit is the sum of one table entry per axis and a walk marks its voxels without a
/// lookup: the walk's decisions and the marking stay in registers (RayWalker::differences()).
class FrameBitmap {
 public:
  /// At most 2^28 bits (32 MiB): a 1.5 m max range at 5 mm needs 216 M at worst (3 m box).
  static constexpr uint64_t kMaxBits = uint64_t{1} << 28;

  /// Nothing when the box of blocks holding [lo, hi] exceeds kMaxBits.
  static std::optional<FrameBitmap> ForBox(const VoxelKey& lo, const VoxelKey& hi) {
    const BlockKey b0 = BlockOf(lo), b1 = BlockOf(hi);
    const int64_t nx = int64_t{b1.x} - b0.x + 1, ny = int64_t{b1.y} - b0.y + 1,
                  nz = int64_t{b1.z} - b0.z + 1;
    const uint64_t blocks =
        static_cast<uint64_t>(nx) * static_cast<uint64_t>(ny) * static_cast<uint64_t>(nz);
    if (nx > (1 << 20) || ny > (1 << 20) || nz > (1 << 20) || blocks * kBlockVoxels > kMaxBits) {
      return std::nullopt;
    }
    return FrameBitmap(b0, nx, ny, nz);
  }

  /// The table entry of key coordinate `k` on `axis`; sums of three are bit indices.
  const int64_t* Entry(int axis, int32_t k) const {
    const size_t a = static_cast<size_t>(axis);
    return tables_[a].data() + kPad + (int64_t{k} - int64_t{origin_[a]} * kBlockEdge);
  }
  /// A walk in progress over the bit map: its decisions (RayWalker::differences()), its key as
  /// pointers into the per-axis tables, and the steps left.
  struct Cursor {
    RayWalker::Differences d{};
    const int64_t *px = nullptr, *py = nullptr, *pz = nullptr;
    int64_t left = 0;  ///< 0: a finished (or no) walk, never dereferenced

    uint64_t Offset() const { return static_cast<uint64_t>(*px + *py + *pz); }
    [[gnu::always_inline]] void Step() {
      const auto [mx, my, mz] = d.Step();
      px += d.step_x & mx;
      py += d.step_y & my;
      pz += d.step_z & mz;
    }
  };

  /// The cursor of `w`'s walk, or nothing when its last steps follow the exhausted-axis rule
  /// (exhausted_tie(): MarkWalk walks those).
  std::optional<Cursor> CursorOf(const RayWalker& w) const {
    if (w.exhausted_tie()) return std::nullopt;
    const VoxelKey k = w.key();
    return Cursor{w.differences(), Entry(0, k.x), Entry(1, k.y), Entry(2, k.z), w.remaining()};
  }

  /// Marks the voxels of `w`'s walk up to, not including, its end voxel.
  void MarkWalk(const RayWalker& w) {
    if (std::optional<Cursor> c = CursorOf(w)) {
      MarkWalks(*c, Cursor{});
      return;
    }
    w.ForEachKeyBeforeEnd([&](const VoxelKey& v) {
      const uint64_t bit = static_cast<uint64_t>(*Entry(0, v.x) + *Entry(1, v.y) + *Entry(2, v.z));
      Mark(&bit, 1);
      return true;
    });
  }

  /// Marks two walks' voxels, their steps interleaved while both go on: two independent chains
  /// of decisions keep the core busier than one.
  void MarkWalks(Cursor a, Cursor b) {
    constexpr int kSteps = 32;
    uint64_t offsets[2 * kSteps];
    while (a.left > 0 || b.left > 0) {
      // The offsets of a chunk first (the decisions alone), then their bits.
      int n = 0;
      if (a.left > 0 && b.left > 0) {
        const int both = static_cast<int>(std::min({a.left, b.left, int64_t{kSteps}}));
        for (int i = 0; i < both; ++i) {
          offsets[n++] = a.Offset();
          a.Step();
          offsets[n++] = b.Offset();
          b.Step();
        }
        a.left -= both;
        b.left -= both;
      } else {
        Cursor& c = a.left > 0 ? a : b;
        const int one = static_cast<int>(std::min<int64_t>(c.left, kSteps));
        for (int i = 0; i < one; ++i) {
          offsets[n++] = c.Offset();
          c.Step();
        }
        c.left -= one;
      }
      Mark(offsets, n);
    }
  }

  uint64_t bits() const { return words_.size() * 64; }
  /// Sets the bits `offsets[0, n)`; an offset past the map (a key outside the box) sets none.
  void Mark(const uint64_t* offsets, int n) {
    uint64_t* const words = words_.data();
    const uint64_t size = bits();
    for (int i = 0; i < n; ++i) {
      const uint64_t bit = offsets[i];
      if (bit < size) [[likely]]
        words[bit >> 6] |= uint64_t{1} << (bit & 63);
    }
  }
  /// Adds every voxel of `other` (same box).
  void Merge(const FrameBitmap& other) {
    for (size_t i = 0; i < words_.size(); ++i) words_[i] |= other.words_[i];
  }
  /// The blocks with a marked voxel, in key order, and their bits.
  std::pair<std::vector<BlockKey>, std::vector<BlockBits>> Blocks() const {
    std::pair<std::vector<BlockKey>, std::vector<BlockBits>> out;
    for (int64_t x = 0; x < n_[0]; ++x) {
      for (int64_t y = 0; y < n_[1]; ++y) {
        for (int64_t z = 0; z < n_[2]; ++z) {
          const size_t first = static_cast<size_t>((x + n_[0] * (y + n_[1] * z)) * kBlockWords);
          BlockBits b;
          bool any = false;
          for (int w = 0; w < kBlockWords; ++w) {
            b.words[w] = words_[first + static_cast<size_t>(w)];
            any |= b.words[w] != 0;
          }
          if (!any) continue;
          out.first.push_back({static_cast<int32_t>(origin_[0] + x),
                               static_cast<int32_t>(origin_[1] + y),
                               static_cast<int32_t>(origin_[2] + z)});
          out.second.push_back(b);
        }
      }
    }
    return out;
  }

 private:
  /// Entries beyond the box on either side (never used by a walk inside it) hold kOutside, so a
  /// stray key would give a bit index past the map instead of another voxel's.
  static constexpr int64_t kPad = 2;
  static constexpr int64_t kOutside = int64_t{1} << 40;

  FrameBitmap(const BlockKey& b0, int64_t nx, int64_t ny, int64_t nz)
      : origin_{int64_t{b0.x}, int64_t{b0.y}, int64_t{b0.z}}, n_{nx, ny, nz} {
    words_.assign(static_cast<size_t>(nx * ny * nz * kBlockWords), 0);
    // Block-major: bit = ((bx + nx (by + ny bz)) << 9) + lx + 8 ly + 64 lz.
    const std::array<int64_t, 3> block_stride{1, nx, nx * ny};
    for (int a = 0; a < 3; ++a) {
      const size_t axis = static_cast<size_t>(a);
      const int64_t voxels = n_[axis] * kBlockEdge;
      std::vector<int64_t>& t = tables_[axis];
      t.assign(static_cast<size_t>(voxels + 2 * kPad), kOutside);
      for (int64_t v = 0; v < voxels; ++v) {
        t[static_cast<size_t>(v + kPad)] =
            (v / kBlockEdge) * block_stride[axis] * kBlockVoxels + (v % kBlockEdge << (3 * a));
      }
    }
  }

  std::array<int64_t, 3> origin_;  ///< the box's first block
  std::array<int64_t, 3> n_;       ///< blocks per axis
  std::array<std::vector<int64_t>, 3> tables_;
  std::vector<uint64_t> words_;
};

/// Free space by ray casting: every voxel from the origin's (or the ray's own start, `starts`)
/// up to (excluding) the end point's.
/// The rays' voxels are marked in a dense bit map of their box (FrameBitmap; each thread its own
/// map and an interleaved share of the rays), merged and applied once per voxel, voxels hit in
/// this frame keeping their hit. A box too large for the bit map (a long max range) is walked
/// voxel by voxel through the grid. The result does not depend on the thread count.
void CarveRays(const std::vector<RayEnd>& rays, const std::vector<Eigen::Vector3d>* starts,
               const Eigen::Vector3d& origin, OccupancyGrid& grid, int threads,
               IntegrationStats& stats) {
  const double s = grid.voxel_size_m();
  const auto start = [&](size_t i) -> const Eigen::Vector3d& {
    return starts != nullptr ? (*starts)[i] : origin;
  };
  const auto [lo, hi] = RayVoxelBox(rays, starts, origin, s);
  std::optional<FrameBitmap> first = FrameBitmap::ForBox(lo, hi);
  if (!first) {
    OccupancyGrid::Accessor acc(grid);
    const float miss = grid.miss_log_odds();
    for (size_t i = 0; i < rays.size(); ++i) {
      const RayWalker w(start(i), rays[i].end, s);
      if (!w.ok()) continue;
      w.ForEachKeyBeforeEnd([&](const VoxelKey& k) {
        if (grid.Admits(k) && acc.UpdateOnce(k, miss)) ++stats.free_updates;
        return true;
      });
    }
    return;
  }
  // One map per thread, within 2^29 bits (64 MiB) in all.
  const int markers = static_cast<int>(
      std::clamp<uint64_t>((uint64_t{1} << 29) / first->bits(), 1, static_cast<uint64_t>(threads)));
  std::vector<FrameBitmap> maps;
  maps.push_back(std::move(*first));
  for (int t = 1; t < markers; ++t) maps.push_back(maps[0]);
  RunParallel(markers, [&](int t) {
    FrameBitmap& map = maps[static_cast<size_t>(t)];
    for (size_t i = static_cast<size_t>(t) * kChunk; i < rays.size();
         i += static_cast<size_t>(markers) * kChunk) {
      const size_t stop = std::min(rays.size(), i + kChunk);
      std::optional<FrameBitmap::Cursor> pending;  // walks go in pairs
      for (size_t j = i; j < stop; ++j) {
        const RayWalker w(start(j), rays[j].end, s);
        if (!w.ok()) continue;
        std::optional<FrameBitmap::Cursor> c = map.CursorOf(w);
        if (!c) {
          map.MarkWalk(w);
        } else if (pending) {
          map.MarkWalks(*pending, *c);
          pending.reset();
        } else {
          pending = c;
        }
      }
      if (pending) map.MarkWalks(*pending, FrameBitmap::Cursor{});
    }
  });
  for (size_t t = 1; t < maps.size(); ++t) maps[0].Merge(maps[t]);
  auto [blocks, carve] = maps[0].Blocks();
  maps.clear();
  ApplyWholeBlocks(blocks, carve, grid, threads, stats);
  ApplyRemainingVoxels(blocks, carve, NearCarving{}, grid, stats);
}

/// Free space by projection, with ray casting's result. A ray through pixel p (direction D_p from
/// the optical centre o, parameter t = camera z) carves voxel V iff it passes through V before its
/// end point and the end point is not in V (OctoMap's computeRayKeys excludes the end voxel). This
/// visits voxels instead of rays: for each voxel of the frustum it looks for one pixel whose ray
/// carves it, first the pixel under the voxel centre (which settles almost every free voxel),
/// then, unless a max-depth pyramid proves no ray in the voxel's footprint gets that far, every
/// pixel of the footprint. Voxels within kNearRadius voxels of the optical centre, whose
/// footprint is unbounded, are carved by walking the rays themselves. The result equals ray
/// casting up to floating-point ties at voxel edges (see bench_map).
void CarveProjective(const RgbdFrame& frame, const std::vector<RayEnd>& rays, OccupancyGrid& grid,
                     int threads, IntegrationStats& stats) {
  const ProjectiveCamera cam = MakeProjectiveCamera(frame, grid.voxel_size_m());
  const PixelRays pixels = BuildPixelRays(cam, frame.depth_m, rays);
  if (pixels.far_t <= 0.0) return;
  const MaxDepthPyramid pyramid(pixels.px, cam.w, cam.h);
  const std::array<Eigen::Vector3d, 8> corner_offsets = VoxelCornerOffsets(cam.R_CW, cam.s);
  // 1. Near the optical centre: walk the rays.
  const NearCarving near = CarveNearOpticalCentre(rays, cam.o, cam.s, threads);
  // 2. Candidate blocks: in the frustum up to far_t, not entirely behind the camera or the returns.
  const std::vector<BlockKey> candidates =
      CandidateBlocks(cam, pyramid, corner_offsets, pixels.far_t);
  // 3. Per candidate block, the voxels some ray carves.
  const VoxelCarveInputs inputs{
      cam, pixels.px, pyramid, corner_offsets, near, pixels.far_t, cam.z_half_per_edge * cam.s};
  std::vector<BlockBits> carve = CarvedVoxelsPerBlock(inputs, candidates, threads);
  // 4. Apply.
  ApplyWholeBlocks(candidates, carve, grid, threads, stats);
  ApplyRemainingVoxels(candidates, carve, near, grid, stats);
}

/// Reduces a frame's (voxel, mask) pairs to one observation per voxel: the label with most
/// pixels; ties go to the higher mask confidence (outside-every-mask counts as 0), then to the
/// lower mask index.
std::vector<VoxelObservation> ReduceObservations(std::vector<std::pair<VoxelKey, int32_t>>& hits,
                                                 const Segmentation& seg) {
  std::sort(hits.begin(), hits.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first < b.first : a.second < b.second;
  });
  std::vector<VoxelObservation> out;
  size_t i = 0;
  while (i < hits.size()) {
    const VoxelKey key = hits[i].first;
    VoxelObservation best{key, -1, 0};
    float best_conf = -1.0f;
    while (i < hits.size() && hits[i].first == key) {
      const int32_t label = hits[i].second;
      uint32_t n = 0;
      while (i < hits.size() && hits[i].first == key && hits[i].second == label) {
        ++n;
        ++i;
      }
      const float conf = label >= 0 ? seg.instances[static_cast<size_t>(label)].confidence : 0.0f;
      if (n > best.pixels || (n == best.pixels && conf > best_conf)) {
        best.mask_index = label;
        best.pixels = n;
        best_conf = conf;
      }
    }
    out.push_back(best);
  }
  return out;
}

/// Rays must fit RayWalker's length limit and start inside the key range; otherwise they would be
/// skipped, so the frame is refused with a clear error instead.
Status CheckRayLimits(const IntegratorOptions& options, const OccupancyGrid& grid,
                      const Eigen::Vector3d& origin) {
  const double s = grid.voxel_size_m();
  if (options.max_range_m / s > static_cast<double>(RayWalker::kMaxLengthVoxels - 2)) {
    return InvalidArgumentError(fmt::format(
        "max_range_m ({}) spans {:.0f} voxels of {} m, more than the ray traversal's limit of {}: "
        "use a shorter max range or a coarser map",
        options.max_range_m, options.max_range_m / s, s, RayWalker::kMaxLengthVoxels - 2));
  }
  if (!Keyable(origin) || !KeyInRange(VoxelKey::FromPoint(origin, s))) {
    return OutOfRangeError(fmt::format("sensor origin ({}, {}, {}) is outside the map's key range",
                                       origin.x(), origin.y(), origin.z()));
  }
  return Status::Ok();
}

/// Projective carving leaves voxels near the image plane to ray walking (kNearRadius), which is
/// complete only for fields of view below 150 degrees (see CarveProjective).
Status CheckProjectiveFieldOfView(const RgbdFrame& frame, int w, int h) {
  double max_tan = 0.0;
  for (double u : {-0.5, w - 0.5}) {
    for (double v : {-0.5, h - 0.5}) {
      max_tan = std::max(max_tan,
                         std::hypot((u - frame.K.cx) / frame.K.fx, (v - frame.K.cy) / frame.K.fy));
    }
  }
  if (std::atan(max_tan) * 2.0 > 150.0 * M_PI / 180.0) {
    return InvalidArgumentError(fmt::format(
        "projective carving needs a diagonal field of view below 150 deg, this camera has {:.1f} "
        "deg: use carving raycast",
        std::atan(max_tan) * 360.0 / M_PI));
  }
  return Status::Ok();
}

/// Per-pixel mask label: the most confident mask containing the pixel (lower index on ties), -1
/// for none; empty without masks.
std::vector<int32_t> PixelMaskLabels(const Segmentation* segmentation, size_t pixels) {
  std::vector<int32_t> label;
  if (segmentation == nullptr || segmentation->instances.empty()) return label;
  label.assign(pixels, -1);
  for (size_t m = 0; m < segmentation->instances.size(); ++m) {
    const InstanceMask& inst = segmentation->instances[m];
    const auto mask = inst.mask.data();
    for (size_t p = 0; p < mask.size(); ++p) {
      if (mask[p] == 0) continue;
      const int32_t cur = label[p];
      if (cur < 0 ||
          inst.confidence > segmentation->instances[static_cast<size_t>(cur)].confidence) {
        label[p] = static_cast<int32_t>(m);
      }
    }
  }
  return label;
}

/// One ray per pixel of valid depth, from the sensor origin to its point (a hit, with its mask
/// label) or cut at max_range (no hit); the pixel counts in `stats`.
std::vector<RayEnd> BackProjectRays(const RgbdFrame& frame, const std::vector<int32_t>& label,
                                    double max_range, int stride, IntegrationStats& stats) {
  const int w = frame.depth_m.width(), h = frame.depth_m.height();
  const CameraIntrinsics& K = frame.K;
  const Eigen::Vector3d origin = frame.X_WC.translation();
  std::vector<RayEnd> rays;
  rays.reserve(stats.pixels);
  for (int v = 0; v < h; v += stride) {
    for (int u = 0; u < w; u += stride) {
      const float d = frame.depth_m.at(u, v);
      if (!std::isfinite(d) || d <= 0.0f) {
        ++stats.invalid_depth;
        continue;
      }
      const Eigen::Vector3d p_C((u - K.cx) / K.fx * d, (v - K.cy) / K.fy * d, d);
      const Eigen::Vector3d p_W = frame.X_WC * p_C;
      const double range = (p_W - origin).norm();
      RayEnd r;
      if (range > max_range) {
        ++stats.beyond_max_range;
        r.end = origin + (p_W - origin) * (max_range / range);
        r.hit = false;
      } else {
        ++stats.endpoints;
        r.end = p_W;
        r.hit = true;
        if (!label.empty()) {
          r.label = label[static_cast<size_t>(v) * w + u];
          if (r.label >= 0) ++stats.masked_endpoints;
        }
      }
      rays.push_back(r);
    }
  }
  return rays;
}

/// Returns outside `box` mark nothing: their hits are dropped (counted as rejected points).
void DropHitsOutside(std::vector<RayEnd>& rays, const Box3& box, IntegrationStats& stats) {
  for (RayEnd& r : rays) {
    if (!r.hit || box.Contains(r.end)) continue;
    r.hit = false;
    --stats.endpoints;
    if (r.label >= 0) --stats.masked_endpoints;
    ++stats.rejected_points;
  }
}

/// The rays to carve, from `origin`, cut to `box` (slabs): each ray's part inside it, from
/// where it enters (its start, in `starts`) to its end, or to where it leaves (that voxel, on
/// the box's boundary, then not carved); rays that miss the box are dropped.
std::vector<RayEnd> ClipToBox(const std::vector<RayEnd>& rays, const Eigen::Vector3d& origin,
                              const Box3& box, std::vector<Eigen::Vector3d>& starts) {
  std::vector<RayEnd> out;
  out.reserve(rays.size());
  starts.clear();
  starts.reserve(rays.size());
  for (const RayEnd& r : rays) {
    if (!Keyable(r.end)) continue;
    const Eigen::Vector3d d = r.end - origin;
    double t0 = 0.0, t1 = 1.0;
    for (int a = 0; a < 3 && t0 < t1; ++a) {
      if (d[a] == 0.0) {
        if (origin[a] < box.min()[a] || origin[a] > box.max()[a]) t1 = -1.0;
        continue;
      }
      double ta = (box.min()[a] - origin[a]) / d[a];
      double tb = (box.max()[a] - origin[a]) / d[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    if (!(t0 < t1)) continue;
    starts.push_back(origin + t0 * d);
    out.push_back(RayEnd{t1 < 1.0 ? Eigen::Vector3d(origin + t1 * d) : r.end});
  }
  return out;
}

/// Carves `carve` from `origin` (CarveRays), only inside `clip` when it is given (ClipToBox).
void CarveRaysWithin(const std::vector<RayEnd>& carve, const Eigen::Vector3d& origin,
                     const std::optional<Box3>& clip, OccupancyGrid& grid, int threads,
                     IntegrationStats& stats) {
  if (!clip) {
    CarveRays(carve, nullptr, origin, grid, threads, stats);
    return;
  }
  std::vector<Eigen::Vector3d> starts;
  const std::vector<RayEnd> inside = ClipToBox(carve, origin, *clip, starts);
  CarveRays(inside, &starts, origin, grid, threads, stats);
}

/// kEndVoxelRays, OctoMap's insertPointCloud(discretize = true): `rays` arrive with their raw end
/// points, every return a hit. Each return keeps its hit only if its voxel's centre lies within
/// max_range (the counts in `stats` follow); the rays to carve are returned, one per distinct
/// voxel, to its centre or cut at max_range towards it. A return too far for any key (beyond the
/// ray traversal's range as well) is rejected and carves nothing.
std::vector<RayEnd> EndVoxelRays(std::vector<RayEnd>& rays, const Eigen::Vector3d& origin,
                                 double max_range, double s, IntegrationStats& stats) {
  std::vector<RayEnd> carve;
  // An insert-only open-addressing set of the voxels seen (no key in range is kNoKey), at most
  // half full; a voxel holds many returns, so it starts small.
  constexpr VoxelKey kNoKey{kMaxKeyMagnitude, kMaxKeyMagnitude, kMaxKeyMagnitude};
  std::vector<VoxelKey> seen(std::bit_ceil(rays.size() / 8 + 1024), kNoKey);
  auto slot_of = [&](const VoxelKey& k) {
    const size_t mask = seen.size() - 1;
    size_t slot = VoxelKeyHash{}(k)&mask;
    while (!(seen[slot] == k) && !(seen[slot] == kNoKey)) slot = (slot + 1) & mask;
    return slot;
  };
  auto insert = [&](const VoxelKey& k) {
    const size_t slot = slot_of(k);
    if (seen[slot] == k) return false;
    seen[slot] = k;
    if (2 * (carve.size() + 1) > seen.size()) {  // carve holds one ray per key inserted
      std::vector<VoxelKey> old(seen.size() * 2, kNoKey);
      old.swap(seen);
      for (const VoxelKey& o : old) {
        if (!(o == kNoKey)) seen[slot_of(o)] = o;
      }
    }
    return true;
  };
  std::optional<VoxelKey> prev;  // neighbouring pixels mostly share a voxel: skip the set then
  bool prev_hit = false;
  for (RayEnd& r : rays) {
    if (!r.hit) continue;
    bool hit = false;
    const bool keyed = Keyable(r.end);
    const VoxelKey k = keyed ? FixedPointKey(r.end, s) : VoxelKey{};
    if (keyed && KeyInRange(k)) {
      if (prev && *prev == k) {
        hit = prev_hit;
      } else {
        const Eigen::Vector3d c = k.Center(s);
        const double range = (c - origin).norm();
        hit = range <= max_range;
        if (insert(k)) {
          carve.push_back(hit ? RayEnd{c, true}
                              : RayEnd{origin + (c - origin) * (max_range / range)});
        }
        prev = k;
        prev_hit = hit;
      }
      if (!hit) ++stats.beyond_max_range;
    } else {
      ++stats.rejected_points;
    }
    if (hit) continue;
    --stats.endpoints;
    if (r.label >= 0) --stats.masked_endpoints;
    r.hit = false;
  }
  return carve;
}

}  // namespace

Integrator::Integrator(const IntegratorOptions& options) : options_(options) {
  const Status s = options.Validate();
  if (!s.ok()) throw Error(s.message());
}

Result<IntegrationStats> Integrator::Integrate(const RgbdFrame& frame,
                                               const Segmentation* segmentation,
                                               SemanticMap& map) const {
  const auto t0 = Clock::now();
  AVP_RETURN_IF_ERROR(frame.Validate());
  if (!frame.X_WC.translation().allFinite() || !frame.X_WC.rotation().allFinite()) {
    return InvalidArgumentError("frame pose X_WC is not finite: " + frame.X_WC.ToString());
  }
  const int w = frame.depth_m.width(), h = frame.depth_m.height();
  if (segmentation != nullptr) {
    AVP_RETURN_IF_ERROR(segmentation->ValidateFor(w, h));
  }
  if (options_.carving == FreeSpaceCarving::kProjective) {
    AVP_RETURN_IF_ERROR(CheckProjectiveFieldOfView(frame, w, h));
  }
  OccupancyGrid& grid = map.grid();
  const Eigen::Vector3d origin = frame.X_WC.translation();
  AVP_RETURN_IF_ERROR(CheckRayLimits(options_, grid, origin));
  IntegrationStats stats;
  const int n = options_.pixel_stride;
  stats.pixels = static_cast<size_t>((w + n - 1) / n) * static_cast<size_t>((h + n - 1) / n);
  const std::vector<int32_t> label =
      PixelMaskLabels(segmentation, static_cast<size_t>(w) * static_cast<size_t>(h));
  const bool end_voxels = options_.carving == FreeSpaceCarving::kEndVoxelRays;
  // End-voxel rays decide max range per voxel: back-project every return as a hit first.
  std::vector<RayEnd> rays = BackProjectRays(
      frame, label, end_voxels ? std::numeric_limits<double>::infinity() : options_.max_range_m, n,
      stats);
  const std::vector<RayEnd> voxel_rays =
      end_voxels ? EndVoxelRays(rays, origin, options_.max_range_m, grid.voxel_size_m(), stats)
                 : std::vector<RayEnd>{};

  const uint32_t frame_number = grid.BeginFrame();
  const bool semantics = segmentation != nullptr;
  std::vector<std::pair<VoxelKey, int32_t>> sem_hits;
  if (options_.clip_box) DropHitsOutside(rays, *options_.clip_box, stats);
  ApplyHits(rays, grid, semantics, stats, sem_hits);
  const int threads = Threads();
  switch (options_.carving) {
    case FreeSpaceCarving::kRayCast:
      CarveRaysWithin(rays, origin, options_.clip_box, grid, threads, stats);
      break;
    case FreeSpaceCarving::kProjective:
      CarveProjective(frame, rays, grid, threads, stats);
      break;
    case FreeSpaceCarving::kEndVoxelRays:
      CarveRaysWithin(voxel_rays, origin, options_.clip_box, grid, threads, stats);
      break;
    case FreeSpaceCarving::kNone:
      break;
  }
  if (semantics) {
    const std::vector<VoxelObservation> obs = ReduceObservations(sem_hits, *segmentation);
    stats.semantics = map.semantics().Fuse(grid, obs, *segmentation, frame_number);
    if (map.semantics().options().remove_outliers_each_frame) {
      map.semantics().RemoveOutliers(grid);
    }
  }
  stats.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return stats;
}

Result<IntegrationStats> Integrator::IntegratePointCloud(std::span<const Eigen::Vector3f> points_W,
                                                         const Eigen::Vector3d& origin_W,
                                                         OccupancyGrid& grid) const {
  const auto t0 = Clock::now();
  if (!origin_W.allFinite()) {
    return InvalidArgumentError(fmt::format("sensor origin ({}, {}, {}) is not finite",
                                            origin_W.x(), origin_W.y(), origin_W.z()));
  }
  if (options_.carving == FreeSpaceCarving::kProjective) {
    return InvalidArgumentError(
        "projective carving needs a depth image: use Integrate(), or carving raycast/none");
  }
  AVP_RETURN_IF_ERROR(CheckRayLimits(options_, grid, origin_W));
  IntegrationStats stats;
  stats.pixels = points_W.size();
  std::vector<RayEnd> rays;
  rays.reserve(points_W.size());
  const bool end_voxels = options_.carving == FreeSpaceCarving::kEndVoxelRays;
  // End-voxel rays decide max range per voxel: every return is a hit first.
  const double max_range =
      end_voxels ? std::numeric_limits<double>::infinity() : options_.max_range_m;
  for (const Eigen::Vector3f& pf : points_W) {
    if (!pf.allFinite()) {
      ++stats.invalid_depth;
      continue;
    }
    const Eigen::Vector3d p = pf.cast<double>();
    const double range = (p - origin_W).norm();
    RayEnd r;
    if (range > max_range) {
      ++stats.beyond_max_range;
      r.end = origin_W + (p - origin_W) * (max_range / range);
    } else {
      ++stats.endpoints;
      r.end = p;
      r.hit = true;
    }
    rays.push_back(r);
  }
  const std::vector<RayEnd> voxel_rays =
      end_voxels ? EndVoxelRays(rays, origin_W, options_.max_range_m, grid.voxel_size_m(), stats)
                 : std::vector<RayEnd>{};
  grid.BeginFrame();
  std::vector<std::pair<VoxelKey, int32_t>> unused;
  if (options_.clip_box) DropHitsOutside(rays, *options_.clip_box, stats);
  ApplyHits(rays, grid, false, stats, unused);
  if (options_.carving == FreeSpaceCarving::kRayCast) {
    CarveRaysWithin(rays, origin_W, options_.clip_box, grid, Threads(), stats);
  } else if (end_voxels) {
    CarveRaysWithin(voxel_rays, origin_W, options_.clip_box, grid, Threads(), stats);
  }
  stats.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return stats;
}

}  // namespace avp::mapping

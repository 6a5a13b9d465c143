// Embree-based RGB-D + label camera.
//
// Geometry: one Embree triangle geometry per mesh object (geomID -> object table) and one Embree
// user geometry holding every ellipsoid as a primitive (primID -> ellipsoid -> object). Embree
// builds one BVH over all geometries of a (non-instanced) scene; bench_render's
// MergedPerClass case (one mesh per class) was no faster beyond the +-10 % noise of the shared
// build machine, so the simpler per-object layout stays. Ellipsoids are intersected exactly, in
// double precision, in the user-geometry callbacks.
//
// Packets: 8 rays (4x2 pixels, rtcIntersect8) by default; on the AVX2 build machine, single rays
// cost 1.8x and packets of 4 1.3x as much CPU per frame, packets of 16 the same as 8.
//
// Rays: the camera ray through pixel (u, v) has optical-frame direction ((u-cx)/fx, (v-cy)/fy, 1),
// so the ray parameter t *is* the z-depth. Rays run over t in [0, max_depth_m]: a first hit closer
// than min_depth_m occludes what lies behind it and reads as "no return" (depth 0, labels 0,
// background colour), as on a real stereo camera; anything beyond max_depth_m is never found.
//
// Colour: an object's albedo times a per-instance tint (base_rgb, computed once). A mesh with
// colours of its own (TriangleMesh::texture or face_albedo) looks its colour up per hit instead:
// the texture bilinearly sampled at the texture coordinates interpolated with Embree's barycentric
// (u, v), or the triangle's colour, times the same tint; then the same lighting. Objects without
// colours of their own take the original path, bit for bit.
//
// Threads: the image is cut into bands of kBandRows rows, handed out by an atomic counter. Each
// pixel's result depends only on the pixel (fixed packet layout), so output is bit-identical for
// any thread count.

#include <embree3/rtcore.h>
#include <fmt/format.h>
#if defined(__SSE__) || defined(__x86_64__)
#include <xmmintrin.h>
#endif

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <avp/core/error.h>
#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/sim/rgbd_renderer.h>

namespace avp::sim {
namespace {

constexpr int kBandRows = 8;  // divisible by every packet height (1, 2, 4)

// ---- Analytic ellipsoids ---------------------------------------------------------------------

struct EllipsoidPrim {
  Eigen::Vector3d center_W;
  /// World -> unit-sphere frame: q = A (p - c); the surface is |q| = 1.
  Eigen::Matrix3d A;
  RTCBounds bounds;
};

/// Smallest root t in [t_near, t_far] of |A (o + t d - c)| = 1, solved in double precision with
/// the numerically careful discriminant of Haines et al. ("Precision improvements for ray/sphere
/// intersection", Ray Tracing Gems, ch. 7). Both surfaces count (a camera inside sees the inside).
bool IntersectEllipsoid(const EllipsoidPrim& e, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                        double t_near, double t_far, double* t_hit, Eigen::Vector3d* normal) {
  const Eigen::Vector3d op = e.A * (o - e.center_W);
  const Eigen::Vector3d dp = e.A * d;
  const double a = dp.squaredNorm();
  if (!(a > 0.0)) return false;
  const double b = op.dot(dp);  // half the linear coefficient
  const double c = op.squaredNorm() - 1.0;
  const Eigen::Vector3d l = op - (b / a) * dp;  // op's component perpendicular to dp
  const double disc = a * (1.0 - l.squaredNorm());
  if (disc < 0.0) return false;
  const double q = -(b + std::copysign(std::sqrt(disc), b));
  double t0;
  double t1;
  if (q == 0.0) {
    t0 = t1 = -b / a;
  } else {
    t0 = c / q;
    t1 = q / a;
    if (t0 > t1) std::swap(t0, t1);
  }
  double t;
  if (t0 >= t_near && t0 <= t_far) {
    t = t0;
  } else if (t1 >= t_near && t1 <= t_far) {
    t = t1;
  } else {
    return false;
  }
  *t_hit = t;
  *normal = e.A.transpose() * (op + t * dp);  // gradient of |q|^2 / 2
  return true;
}

const std::vector<EllipsoidPrim>& PrimsOf(void* user_ptr) {
  return *static_cast<const std::vector<EllipsoidPrim>*>(user_ptr);
}

void EllipsoidBoundsFunc(const RTCBoundsFunctionArguments* args) {
  *args->bounds_o = PrimsOf(args->geometryUserPtr)[args->primID].bounds;
}

void EllipsoidIntersectFunc(const RTCIntersectFunctionNArguments* args) {
  const EllipsoidPrim& e = PrimsOf(args->geometryUserPtr)[args->primID];
  const unsigned n = args->N;
  RTCRayN* ray = RTCRayHitN_RayN(args->rayhit, n);
  RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, n);
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] == 0) continue;
    const Eigen::Vector3d o(RTCRayN_org_x(ray, n, i), RTCRayN_org_y(ray, n, i),
                            RTCRayN_org_z(ray, n, i));
    const Eigen::Vector3d d(RTCRayN_dir_x(ray, n, i), RTCRayN_dir_y(ray, n, i),
                            RTCRayN_dir_z(ray, n, i));
    double t;
    Eigen::Vector3d normal;
    if (!IntersectEllipsoid(e, o, d, RTCRayN_tnear(ray, n, i), RTCRayN_tfar(ray, n, i), &t,
                            &normal)) {
      continue;
    }
    // Rounding is monotone, so float(t) stays within [tnear, tfar] (both floats).
    RTCRayN_tfar(ray, n, i) = static_cast<float>(t);
    RTCHitN_Ng_x(hit, n, i) = static_cast<float>(normal.x());
    RTCHitN_Ng_y(hit, n, i) = static_cast<float>(normal.y());
    RTCHitN_Ng_z(hit, n, i) = static_cast<float>(normal.z());
    RTCHitN_u(hit, n, i) = 0.0f;
    RTCHitN_v(hit, n, i) = 0.0f;
    RTCHitN_primID(hit, n, i) = args->primID;
    RTCHitN_geomID(hit, n, i) = args->geomID;
    RTCHitN_instID(hit, n, i, 0) = args->context->instID[0];
  }
}

void EllipsoidOccludedFunc(const RTCOccludedFunctionNArguments* args) {
  const EllipsoidPrim& e = PrimsOf(args->geometryUserPtr)[args->primID];
  const unsigned n = args->N;
  RTCRayN* ray = args->ray;
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] == 0) continue;
    const Eigen::Vector3d o(RTCRayN_org_x(ray, n, i), RTCRayN_org_y(ray, n, i),
                            RTCRayN_org_z(ray, n, i));
    const Eigen::Vector3d d(RTCRayN_dir_x(ray, n, i), RTCRayN_dir_y(ray, n, i),
                            RTCRayN_dir_z(ray, n, i));
    double t;
    Eigen::Vector3d normal;
    if (IntersectEllipsoid(e, o, d, RTCRayN_tnear(ray, n, i), RTCRayN_tfar(ray, n, i), &t,
                           &normal)) {
      RTCRayN_tfar(ray, n, i) = -std::numeric_limits<float>::infinity();
    }
  }
}

// ---- Shading ---------------------------------------------------------------------------------

/// Linear [0, 1] -> 8-bit sRGB, 4096 entries (a pow() per channel would cost more than tracing).
const std::array<uint8_t, 4096>& SrgbLut() {
  static const std::array<uint8_t, 4096> lut = [] {
    std::array<uint8_t, 4096> t{};
    for (size_t i = 0; i < t.size(); ++i) {
      const double x = static_cast<double>(i) / (t.size() - 1);
      const double s = x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1.0 / 2.4) - 0.055;
      t[i] = static_cast<uint8_t>(std::lround(std::clamp(s, 0.0, 1.0) * 255.0));
    }
    return t;
  }();
  return lut;
}

inline uint8_t ToSrgb8(float linear, const std::array<uint8_t, 4096>& lut) {
  const float x = std::min(std::max(linear, 0.0f), 1.0f);  // branch-free (minss / maxss)
  return lut[static_cast<size_t>(x * 4095.0f + 0.5f)];
}

/// Uniform in [-1, 1) from a hash of `key` (the SplitMix64 finaliser, inlined: it runs per pixel).
inline float HashSigned(uint64_t key) {
  key += 0x9e3779b97f4a7c15ULL;
  key = (key ^ (key >> 30)) * 0xbf58476d1ce4e5b9ULL;
  key = (key ^ (key >> 27)) * 0x94d049bb133111ebULL;
  key ^= key >> 31;
  return static_cast<float>(key >> 40) * 0x1.0p-23f - 1.0f;
}

// Lighting: ambient + a head-light at the camera + a sun from above (world z up). Normals are
// flipped towards the viewer (both sides of a leaf are lit alike).
constexpr float kAmbient = 0.28f;
constexpr float kHeadLight = 0.55f;
constexpr float kSun = 0.35f;
// Per-instance brightness +-10 % and hue +-4 % per channel; per-triangle brightness +-6 %.
constexpr float kInstanceBrightness = 0.10f;
constexpr float kInstanceHue = 0.04f;
constexpr float kTriangleBrightness = 0.06f;

struct ObjectInfo {
  uint16_t instance_id = 0;
  uint8_t class_id = 0;
  Eigen::Vector3f base_rgb = Eigen::Vector3f::Zero();  ///< albedo x per-instance tint, linear
  bool is_mesh = false;
  /// Index into Impl::surfaces for a mesh with colours of its own (texture, per-triangle
  /// colours), -1 otherwise (base_rgb everywhere).
  int32_t surface = -1;
};

/// The colours of a mesh with colours of its own, per triangle, with the object's tint applied as
/// to base_rgb: (colour x hue) x brightness, clamped to [0, 1].
struct SurfaceColors {
  /// Textured: the triangle's three texture coordinates, in vertex order.
  std::shared_ptr<const Texture> texture;
  std::vector<std::array<Eigen::Vector2f, 3>> triangle_uvs;
  /// Per-triangle colours, tint applied (when not textured).
  std::vector<Eigen::Vector3f> face_rgb;
  Eigen::Vector3f hue = Eigen::Vector3f::Ones();
  float brightness = 1.0f;

  /// Base colour at barycentric (u, v) of triangle `prim` (Embree: p = (1-u-v) p0 + u p1 + v p2).
  Eigen::Vector3f BaseColor(unsigned prim, float u, float v) const {
    if (texture == nullptr) return face_rgb[prim];
    const std::array<Eigen::Vector2f, 3>& st = triangle_uvs[prim];
    const Eigen::Vector2f uv = (1.0f - u - v) * st[0] + u * st[1] + v * st[2];
    return (texture->Sample(uv).cwiseProduct(hue) * brightness).cwiseMax(0.0f).cwiseMin(1.0f);
  }
};

/// An object's per-instance tint: colour x hue, x brightness.
struct InstanceTint {
  Eigen::Vector3f hue;
  float brightness;
};

InstanceTint TintOf(uint16_t instance_id) {
  const uint64_t key = MixSeed(0xA1BED0ULL ^ instance_id);
  const float brightness = 1.0f + kInstanceBrightness * HashSigned(key);
  const Eigen::Vector3f hue(1.0f + kInstanceHue * HashSigned(key + 1),
                            1.0f + kInstanceHue * HashSigned(key + 2),
                            1.0f + kInstanceHue * HashSigned(key + 3));
  return {hue, brightness};
}

/// `c` with the tint applied, clamped to [0, 1].
Eigen::Vector3f Tinted(const Eigen::Vector3f& c, const InstanceTint& tint) {
  return (c.cwiseProduct(tint.hue) * tint.brightness).cwiseMax(0.0f).cwiseMin(1.0f);
}

/// Textured or per-triangle colours of a mesh, shaded per hit (Shade).
SurfaceColors MeshSurface(const TriangleMesh& mesh, const InstanceTint& tint) {
  SurfaceColors surface;
  surface.hue = tint.hue;
  surface.brightness = tint.brightness;
  if (mesh.texture != nullptr) {
    surface.texture = mesh.texture;
    surface.triangle_uvs.reserve(mesh.triangles.size());
    for (const Eigen::Vector3i& t : mesh.triangles) {
      surface.triangle_uvs.push_back({mesh.uvs[t[0]], mesh.uvs[t[1]], mesh.uvs[t[2]]});
    }
  } else {
    surface.face_rgb.reserve(mesh.face_albedo.size());
    for (const Eigen::Vector3f& c : mesh.face_albedo) surface.face_rgb.push_back(Tinted(c, tint));
  }
  return surface;
}

/// The user-geometry primitive of an ellipsoid, its float box rounded outwards so it contains
/// the double one.
EllipsoidPrim MakeEllipsoidPrim(const Ellipsoid& e) {
  EllipsoidPrim prim;
  prim.center_W = e.center_W;
  prim.A = e.radii.cwiseInverse().asDiagonal() * e.R_WE.transpose();
  const Box3 box = e.Bounds();
  constexpr float kInf = std::numeric_limits<float>::infinity();
  prim.bounds.lower_x = std::nextafter(static_cast<float>(box.min().x()), -kInf);
  prim.bounds.lower_y = std::nextafter(static_cast<float>(box.min().y()), -kInf);
  prim.bounds.lower_z = std::nextafter(static_cast<float>(box.min().z()), -kInf);
  prim.bounds.upper_x = std::nextafter(static_cast<float>(box.max().x()), kInf);
  prim.bounds.upper_y = std::nextafter(static_cast<float>(box.max().y()), kInf);
  prim.bounds.upper_z = std::nextafter(static_cast<float>(box.max().z()), kInf);
  prim.bounds.align0 = prim.bounds.align1 = 0.0f;
  return prim;
}

/// One traced pixel, as Embree left it.
struct PixelHit {
  float t;
  unsigned geom_id;
  unsigned prim_id;
  float ng[3];
  float u;  ///< barycentric coordinates of the hit on a triangle
  float v;
};

/// Raw views of the output images (each thread writes disjoint pixels).
struct FrameOut {
  float* depth;
  uint16_t* instance;
  uint8_t* cls;
  uint8_t* rgb;
};

/// Per-frame ray set-up: the optical-frame direction of pixel (u, v) is (xn[u], yn[v], 1).
struct FrameRays {
  Eigen::Matrix3d R_WC;
  Eigen::Vector3f origin_W;
  std::vector<double> xn;
  std::vector<double> yn;
  float t_far;
  float min_depth;
  int width;
  int height;

  /// Row base R (0, yn, 1) in double; the pixel direction adds R.col(0) xn[u] before rounding.
  Eigen::Vector3d RowBase(int v) const { return R_WC.col(1) * yn[v] + R_WC.col(2); }
  Eigen::Vector3f Direction(const Eigen::Vector3d& row_base, int u) const {
    return (row_base + R_WC.col(0) * xn[u]).cast<float>();
  }
};

/// Flush-to-zero and denormals-are-zero for the calling thread while in scope (Embree's advice
/// for tracing speed), restored afterwards so the caller's floating-point mode is untouched.
/// Every thread of a render uses the same mode, so results do not depend on the thread count.
class ScopedFlushDenormals {
 public:
  ScopedFlushDenormals() {
#if defined(__SSE__) || defined(__x86_64__)
    saved_ = _mm_getcsr();
    _mm_setcsr(saved_ | 0x8040u);  // FTZ (bit 15) | DAZ (bit 6)
#endif
  }
  ~ScopedFlushDenormals() {
#if defined(__SSE__) || defined(__x86_64__)
    _mm_setcsr(saved_);
#endif
  }
  ScopedFlushDenormals(const ScopedFlushDenormals&) = delete;
  ScopedFlushDenormals& operator=(const ScopedFlushDenormals&) = delete;

 private:
  [[maybe_unused]] unsigned saved_ = 0;
};

}  // namespace

// ---- Impl ------------------------------------------------------------------------------------

struct RgbdRenderer::Impl {
  RendererOptions options;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::vector<ObjectInfo> objects;
  /// Object index for each Embree geomID; ellipsoid_geom_id maps through ellipsoid_objects.
  std::vector<int32_t> geom_to_object;
  unsigned ellipsoid_geom_id = RTC_INVALID_GEOMETRY_ID;
  std::vector<EllipsoidPrim> ellipsoids;  // referenced by the user geometry: never resized later
  std::vector<int32_t> ellipsoid_objects;
  std::vector<SurfaceColors> surfaces;
  size_t num_triangles = 0;
  std::array<uint8_t, 3> background_srgb{};
  const std::array<uint8_t, 4096>* srgb_lut = &SrgbLut();
  Eigen::Vector3f sun_W = Eigen::Vector3f(0.35f, 0.25f, 1.0f).normalized();

  Impl() = default;
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;
  ~Impl() {
    if (scene != nullptr) rtcReleaseScene(scene);
    if (device != nullptr) rtcReleaseDevice(device);
  }

  void ThrowOnDeviceError(const char* what) const {
    const RTCError err = rtcGetDeviceError(device);
    if (err != RTC_ERROR_NONE) {
      throw Error(
          fmt::format("RgbdRenderer: Embree error {} while {}", static_cast<int>(err), what));
    }
  }

  const ObjectInfo* ObjectOf(unsigned geom_id, unsigned prim_id) const {
    if (geom_id == RTC_INVALID_GEOMETRY_ID) return nullptr;  // no hit
    if (geom_id == ellipsoid_geom_id) return &objects[ellipsoid_objects[prim_id]];
    return &objects[geom_to_object[geom_id]];
  }

  /// The Embree device and an empty scene (robust triangle tests, high-quality BVH).
  void CreateScene();
  /// One scene object: its shading info, and its triangles or ellipsoid (attached later).
  void AddObject(const SceneObject& object);
  /// A non-empty mesh as an Embree triangle geometry of object `object_index`.
  void AddMesh(const SceneObject& object, const TriangleMesh& mesh, int32_t object_index);
  /// Every ellipsoid as one Embree user geometry.
  void AttachEllipsoids();

  void Shade(const PixelHit& h, const Eigen::Vector3f& dir_W, float min_depth, size_t idx,
             const FrameOut& out) const;
  template <int kN>
  void TraceBand(int band, const FrameRays& rays, const FrameOut& out) const;
};

void RgbdRenderer::Impl::Shade(const PixelHit& h, const Eigen::Vector3f& dir_W, float min_depth,
                               size_t idx, const FrameOut& out) const {
  uint8_t* rgb = out.rgb + 3 * idx;
  const ObjectInfo* obj = ObjectOf(h.geom_id, h.prim_id);
  if (obj == nullptr || h.t < min_depth) {
    out.depth[idx] = 0.0f;
    out.instance[idx] = 0;
    out.cls[idx] = 0;
    rgb[0] = background_srgb[0];
    rgb[1] = background_srgb[1];
    rgb[2] = background_srgb[2];
    return;
  }
  out.depth[idx] = h.t;
  out.instance[idx] = obj->instance_id;
  out.cls[idx] = obj->class_id;

  const Eigen::Vector3f n(h.ng[0], h.ng[1], h.ng[2]);
  const float nn = n.squaredNorm();
  float cos_view = 1.0f;
  float cos_sun = 0.0f;
  if (nn > 0.0f && nn < std::numeric_limits<float>::infinity()) {
    const float inv_n = 1.0f / std::sqrt(nn);
    const float nd = n.dot(dir_W) * inv_n / std::sqrt(dir_W.squaredNorm());
    cos_view = std::abs(nd);
    // The normal turned towards the viewer (both sides of a leaf are lit alike).
    const float toward_viewer = nd > 0.0f ? -inv_n : inv_n;
    cos_sun = std::max(0.0f, n.dot(sun_W) * toward_viewer);
  }
  float light = kAmbient + kHeadLight * cos_view + kSun * cos_sun;
  if (obj->is_mesh) {
    light *= 1.0f + kTriangleBrightness *
                        HashSigned((static_cast<uint64_t>(obj->instance_id) << 32) | h.prim_id);
  }
  const Eigen::Vector3f base =
      obj->surface < 0 ? obj->base_rgb : surfaces[obj->surface].BaseColor(h.prim_id, h.u, h.v);
  const auto& lut = *srgb_lut;
  rgb[0] = ToSrgb8(base.x() * light, lut);
  rgb[1] = ToSrgb8(base.y() * light, lut);
  rgb[2] = ToSrgb8(base.z() * light, lut);
}

namespace {

// Packet types by width; kN = 1 uses rtcIntersect1. Packets of any width work with any Embree
// ISA (non-native widths are split internally); the user-geometry callbacks handle any N.
template <int kN>
struct PacketTraits;
template <>
struct PacketTraits<4> {
  using RayHit = RTCRayHit4;
  static constexpr int kW = 2, kH = 2;
  static void Intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* r) {
    rtcIntersect4(valid, s, c, r);
  }
};
template <>
struct PacketTraits<8> {
  using RayHit = RTCRayHit8;
  static constexpr int kW = 4, kH = 2;
  static void Intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* r) {
    rtcIntersect8(valid, s, c, r);
  }
};
template <>
struct PacketTraits<16> {
  using RayHit = RTCRayHit16;
  static constexpr int kW = 4, kH = 4;
  static void Intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* r) {
    rtcIntersect16(valid, s, c, r);
  }
};

}  // namespace

template <int kN>
void RgbdRenderer::Impl::TraceBand(int band, const FrameRays& rays, const FrameOut& out) const {
  const Eigen::Vector3f& o = rays.origin_W;
  const int v_begin = band * kBandRows;
  const int v_end = std::min(rays.height, v_begin + kBandRows);
  const int width = rays.width;

  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;

  if constexpr (kN == 1) {
    for (int v = v_begin; v < v_end; ++v) {
      const Eigen::Vector3d row = rays.RowBase(v);
      for (int u = 0; u < width; ++u) {
        const Eigen::Vector3f d = rays.Direction(row, u);
        RTCRayHit rh;
        rh.ray.org_x = o.x();
        rh.ray.org_y = o.y();
        rh.ray.org_z = o.z();
        rh.ray.tnear = 0.0f;
        rh.ray.dir_x = d.x();
        rh.ray.dir_y = d.y();
        rh.ray.dir_z = d.z();
        rh.ray.time = 0.0f;
        rh.ray.tfar = rays.t_far;
        rh.ray.mask = 0xFFFFFFFFu;
        rh.ray.id = 0;
        rh.ray.flags = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene, &context, &rh);
        const PixelHit h{rh.ray.tfar,   rh.hit.geomID,
                         rh.hit.primID, {rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z},
                         rh.hit.u,      rh.hit.v};
        Shade(h, d, rays.min_depth, static_cast<size_t>(v) * width + u, out);
      }
    }
  } else {
    using Traits = PacketTraits<kN>;
    for (int v0 = v_begin; v0 < v_end; v0 += Traits::kH) {
      Eigen::Vector3d rows[Traits::kH];
      for (int j = 0; j < Traits::kH; ++j) rows[j] = rays.RowBase(std::min(v0 + j, v_end - 1));
      for (int u0 = 0; u0 < width; u0 += Traits::kW) {
        typename Traits::RayHit rh;
        alignas(64) int valid[kN];
        Eigen::Vector3f dirs[kN];
        for (int i = 0; i < kN; ++i) {
          const int u = u0 + i % Traits::kW;
          const int v = v0 + i / Traits::kW;
          const bool inside = u < width && v < v_end;
          valid[i] = inside ? -1 : 0;
          const Eigen::Vector3f d =
              inside ? rays.Direction(rows[i / Traits::kW], u) : Eigen::Vector3f::UnitZ().eval();
          dirs[i] = d;
          rh.ray.org_x[i] = o.x();
          rh.ray.org_y[i] = o.y();
          rh.ray.org_z[i] = o.z();
          rh.ray.tnear[i] = 0.0f;
          rh.ray.dir_x[i] = d.x();
          rh.ray.dir_y[i] = d.y();
          rh.ray.dir_z[i] = d.z();
          rh.ray.time[i] = 0.0f;
          rh.ray.tfar[i] = rays.t_far;
          rh.ray.mask[i] = 0xFFFFFFFFu;
          rh.ray.id[i] = 0;
          rh.ray.flags[i] = 0;
          rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
          rh.hit.primID[i] = RTC_INVALID_GEOMETRY_ID;
          rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
        }
        Traits::Intersect(valid, scene, &context, &rh);
        for (int i = 0; i < kN; ++i) {
          if (valid[i] == 0) continue;
          const int u = u0 + i % Traits::kW;
          const int v = v0 + i / Traits::kW;
          const PixelHit h{rh.ray.tfar[i],   rh.hit.geomID[i],
                           rh.hit.primID[i], {rh.hit.Ng_x[i], rh.hit.Ng_y[i], rh.hit.Ng_z[i]},
                           rh.hit.u[i],      rh.hit.v[i]};
          Shade(h, dirs[i], rays.min_depth, static_cast<size_t>(v) * width + u, out);
        }
      }
    }
  }
}

// ---- RgbdRenderer ----------------------------------------------------------------------------

void RgbdRenderer::Impl::CreateScene() {
  device = rtcNewDevice(nullptr);
  if (device == nullptr) {
    throw Error(fmt::format("RgbdRenderer: rtcNewDevice failed (Embree error {})",
                            static_cast<int>(rtcGetDeviceError(nullptr))));
  }
  scene = rtcNewScene(device);
  // Robust (watertight) triangle tests: no cracks along shared edges of a mesh.
  rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
}

void RgbdRenderer::Impl::AddMesh(const SceneObject& object, const TriangleMesh& mesh,
                                 int32_t object_index) {
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.vertices.size()));
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0,
                                                            RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                                            mesh.triangles.size()));
  if (vb == nullptr || ib == nullptr) {
    rtcReleaseGeometry(geom);
    ThrowOnDeviceError(fmt::format("allocating buffers for '{}'", object.name).c_str());
    throw Error("RgbdRenderer: Embree buffer allocation failed for '" + object.name + "'");
  }
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    vb[3 * i + 0] = mesh.vertices[i].x();
    vb[3 * i + 1] = mesh.vertices[i].y();
    vb[3 * i + 2] = mesh.vertices[i].z();
  }
  for (size_t i = 0; i < mesh.triangles.size(); ++i) {
    ib[3 * i + 0] = static_cast<unsigned>(mesh.triangles[i].x());
    ib[3 * i + 1] = static_cast<unsigned>(mesh.triangles[i].y());
    ib[3 * i + 2] = static_cast<unsigned>(mesh.triangles[i].z());
  }
  rtcCommitGeometry(geom);
  const unsigned geom_id = rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);
  if (geom_id >= geom_to_object.size()) geom_to_object.resize(geom_id + 1, -1);
  geom_to_object[geom_id] = object_index;
  num_triangles += mesh.triangles.size();
}

void RgbdRenderer::Impl::AddObject(const SceneObject& object) {
  ObjectInfo info;
  info.instance_id = object.instance_id;
  info.class_id = static_cast<uint8_t>(object.semantic_class);
  const InstanceTint tint = TintOf(object.instance_id);
  info.base_rgb = Tinted(object.albedo, tint);
  const int32_t object_index = static_cast<int32_t>(objects.size());
  if (const auto* mesh = std::get_if<TriangleMesh>(&object.shape)) {
    if (mesh->empty()) return;
    info.is_mesh = true;
    AddMesh(object, *mesh, object_index);
    if (mesh->has_own_colors()) {
      // Textured or per-triangle colours: shaded per hit (Shade); base_rgb stays the albedo's.
      info.surface = static_cast<int32_t>(surfaces.size());
      surfaces.push_back(MeshSurface(*mesh, tint));
    }
  } else {
    const Ellipsoid& e = std::get<Ellipsoid>(object.shape);
    // Ellipsoid::Bounds() (and so the BVH) assumes R_WE is a rotation.
    AVP_THROW_UNLESS(IsRotationMatrix(e.R_WE, 1e-6), object.name, e.R_WE);
    ellipsoids.push_back(MakeEllipsoidPrim(e));
    ellipsoid_objects.push_back(object_index);
  }
  objects.push_back(info);
}

void RgbdRenderer::Impl::AttachEllipsoids() {
  if (ellipsoids.empty()) return;
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
  rtcSetGeometryUserPrimitiveCount(geom, static_cast<unsigned>(ellipsoids.size()));
  rtcSetGeometryUserData(geom, &ellipsoids);
  rtcSetGeometryBoundsFunction(geom, EllipsoidBoundsFunc, nullptr);
  rtcSetGeometryIntersectFunction(geom, EllipsoidIntersectFunc);
  rtcSetGeometryOccludedFunction(geom, EllipsoidOccludedFunc);
  rtcCommitGeometry(geom);
  ellipsoid_geom_id = rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);
}

RgbdRenderer::RgbdRenderer(const Scene& scene, RendererOptions options)
    : impl_(std::make_unique<Impl>()) {
  const Status valid = scene.Validate();
  if (!valid.ok()) throw Error("RgbdRenderer: invalid scene: " + valid.ToString());
  AVP_THROW_UNLESS(options.ray_packet_size == 1 || options.ray_packet_size == 4 ||
                       options.ray_packet_size == 8 || options.ray_packet_size == 16,
                   options.ray_packet_size);
  AVP_THROW_UNLESS(options.background_rgb.allFinite(), options.background_rgb.transpose());
  Impl& m = *impl_;
  m.options = options;
  m.CreateScene();
  const auto& lut = SrgbLut();
  m.background_srgb = {ToSrgb8(options.background_rgb.x(), lut),
                       ToSrgb8(options.background_rgb.y(), lut),
                       ToSrgb8(options.background_rgb.z(), lut)};
  for (const SceneObject& object : scene.objects) m.AddObject(object);
  m.AttachEllipsoids();
  rtcCommitScene(m.scene);
  m.ThrowOnDeviceError("building the scene BVH");
}

RgbdRenderer::~RgbdRenderer() = default;
RgbdRenderer::RgbdRenderer(RgbdRenderer&&) noexcept = default;
RgbdRenderer& RgbdRenderer::operator=(RgbdRenderer&&) noexcept = default;

size_t RgbdRenderer::num_triangles() const { return impl_->num_triangles; }
size_t RgbdRenderer::num_ellipsoids() const { return impl_->ellipsoids.size(); }
int RgbdRenderer::ray_packet_size() const { return impl_->options.ray_packet_size; }

RenderedFrame RgbdRenderer::Render(const CameraIntrinsics& K, const RigidTransform& X_WC,
                                   int64_t stamp_ns) const {
  AVP_THROW_UNLESS(impl_ != nullptr, "Render() on a moved-from RgbdRenderer");
  const Status valid = K.Validate();
  if (!valid.ok()) throw Error("RgbdRenderer::Render: " + valid.message());
  AVP_THROW_UNLESS(static_cast<int64_t>(K.width) * K.height <= kMaxPixels, K.width, K.height,
                   kMaxPixels);
  AVP_THROW_UNLESS(X_WC.translation().allFinite() && X_WC.rotation().allFinite(), X_WC);
  const Impl& m = *impl_;

  RenderedFrame out;
  out.rgbd.K = K;
  out.rgbd.X_WC = X_WC;
  out.rgbd.stamp_ns = stamp_ns;
  out.rgbd.rgb = ImageRgb8(K.width, K.height);
  out.rgbd.depth_m = DepthImage(K.width, K.height);
  out.instance_ids = InstanceImage(K.width, K.height);
  out.class_ids = ClassImage(K.width, K.height);

  FrameRays rays;
  rays.R_WC = X_WC.rotation();
  rays.origin_W = X_WC.translation().cast<float>();
  rays.xn.resize(K.width);
  rays.yn.resize(K.height);
  for (int u = 0; u < K.width; ++u) rays.xn[u] = (u - K.cx) / K.fx;
  for (int v = 0; v < K.height; ++v) rays.yn[v] = (v - K.cy) / K.fy;
  rays.t_far = static_cast<float>(K.max_depth_m);
  rays.min_depth = static_cast<float>(K.min_depth_m);
  rays.width = K.width;
  rays.height = K.height;
  const FrameOut frame_out{out.rgbd.depth_m.data().data(), out.instance_ids.data().data(),
                           out.class_ids.data().data(), out.rgbd.rgb.data().data()};

  const int num_bands = (K.height + kBandRows - 1) / kBandRows;
  std::atomic<int> next_band{0};
  auto work = [&] {
    const ScopedFlushDenormals flush_denormals;
    for (int band = next_band.fetch_add(1); band < num_bands; band = next_band.fetch_add(1)) {
      switch (m.options.ray_packet_size) {
        case 4:
          m.TraceBand<4>(band, rays, frame_out);
          break;
        case 8:
          m.TraceBand<8>(band, rays, frame_out);
          break;
        case 16:
          m.TraceBand<16>(band, rays, frame_out);
          break;
        default:
          m.TraceBand<1>(band, rays, frame_out);
          break;
      }
    }
  };
  RunWorkers(static_cast<size_t>(num_bands), work);
  return out;
}

}  // namespace avp::sim

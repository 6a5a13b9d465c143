#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <thread>
#include <unordered_map>
#include <utility>
#include <variant>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/core/semantic_class.h>
#include <avp/eval/ground_truth.h>
#include <avp/mapping/map_reader.h>
#include <avp/mapping/octomap_io.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/sim/rgbd_renderer.h>

namespace avp::eval {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

using KeyAndId = std::pair<VoxelKey, uint16_t>;

/// A pixel rectangle [u0, u1] x [v0, v1] (inclusive); empty when u0 > u1 or v0 > v1.
struct PixelRect {
  int u0 = std::numeric_limits<int>::max();
  int v0 = std::numeric_limits<int>::max();
  int u1 = std::numeric_limits<int>::min();
  int v1 = std::numeric_limits<int>::min();

  bool empty() const { return u0 > u1 || v0 > v1; }
  int64_t area() const { return empty() ? 0 : int64_t{u1 - u0 + 1} * (v1 - v0 + 1); }
  PixelRect Union(const PixelRect& o) const {
    return {std::min(u0, o.u0), std::min(v0, o.v0), std::max(u1, o.u1), std::max(v1, o.v1)};
  }
};

/// Merges rectangles while a merge costs little: two are replaced by their union when it is at
/// most 5/4 of their summed areas. Fewer, larger windows save per-render overhead; the cap keeps
/// the union from covering much empty image between distant fruits.
void MergeRects(std::vector<PixelRect>& rects) {
  bool merged = true;
  while (merged) {
    merged = false;
    for (size_t i = 0; i < rects.size() && !merged; ++i) {
      for (size_t j = i + 1; j < rects.size() && !merged; ++j) {
        const PixelRect u = rects[i].Union(rects[j]);
        if (4 * u.area() <= 5 * (rects[i].area() + rects[j].area())) {
          rects[i] = u;
          rects.erase(rects.begin() + static_cast<std::ptrdiff_t>(j));
          merged = true;
        }
      }
    }
  }
}

PixelRect FullImage(const CameraIntrinsics& K) { return {0, 0, K.width - 1, K.height - 1}; }

/// A sphere around one fruit object (world frame).
struct BoundingSphere {
  Eigen::Vector3d center_W;
  double radius_m = 0.0;
};

BoundingSphere FruitBoundingSphere(const sim::SceneObject& o) {
  if (const auto* e = std::get_if<sim::Ellipsoid>(&o.shape)) {
    return {e->center_W, e->radii.maxCoeff()};
  }
  const Box3 box = o.Bounds();
  return {box.center(), 0.5 * box.size().norm()};
}

/// The pixels whose centres can see into the sphere from a camera at X_CW (inverse pose): the
/// exact bounds of the sphere's image plus one pixel, clipped to the image. The extreme columns
/// are where planes x = t z through the optical centre touch the sphere, i.e. the tangents from
/// the origin to the circle (x0, z0; r) in the x-z plane; rows likewise in y-z. Empty when the
/// sphere is behind the camera or beyond the depth range or `max_range_m`; the whole image when
/// it reaches the camera plane.
PixelRect ProjectedRect(const BoundingSphere& sphere, const RigidTransform& X_CW,
                        const CameraIntrinsics& K, double max_range_m) {
  const Eigen::Vector3d p = X_CW * sphere.center_W;
  const double r = sphere.radius_m;
  if (p.z() + r <= 0.0) return {};             // wholly behind the camera
  if (p.norm() - r > max_range_m) return {};   // beyond max range
  if (p.z() - r > K.max_depth_m) return {};    // beyond the depth range
  if (p.z() - r <= 1e-6) return FullImage(K);  // reaches the camera plane
  const auto extent = [r](double a, double z, double f, double c, int size, int& lo, int& hi) {
    const double theta = std::atan2(a, z);
    const double alpha = std::asin(std::min(1.0, r / std::hypot(a, z)));
    // z - r > 0 keeps theta +- alpha inside (-pi/2, pi/2); clamp in double before the cast.
    const double first = std::clamp(f * std::tan(theta - alpha) + c, -2.0, size + 1.0);
    const double last = std::clamp(f * std::tan(theta + alpha) + c, -2.0, size + 1.0);
    lo = std::max(0, static_cast<int>(std::floor(first)) - 1);
    hi = std::min(size - 1, static_cast<int>(std::ceil(last)) + 1);
  };
  PixelRect rect;
  extent(p.x(), p.z(), K.fx, K.cx, K.width, rect.u0, rect.u1);
  extent(p.y(), p.z(), K.fy, K.cy, K.height, rect.v0, rect.v1);
  return rect;
}

/// The sub-window `r` of a camera: pixel (u, v) of the window is pixel (u + u0, v + v0) of K.
CameraIntrinsics Window(const CameraIntrinsics& K, const PixelRect& r) {
  CameraIntrinsics w = K;
  w.width = r.u1 - r.u0 + 1;
  w.height = r.v1 - r.v0 + 1;
  w.cx = K.cx - r.u0;
  w.cy = K.cy - r.v0;
  return w;
}

/// Fruit-surface voxels of one rendered window `rect` of a view: every fruit pixel with a valid
/// depth whose point is within `max_range_m` of the camera (the integrator's back-projection, in
/// double). The same pixels are counted per instance id in `pixels`, each view pixel once:
/// `seen_by` (the view's width x height, row-major) marks those already counted, as windows may
/// overlap, and ClearRect resets it for the next view.
void CollectFruitVoxels(const sim::RenderedFrame& frame, const PixelRect& rect, int view_width,
                        double voxel_size_m, double max_range_m, std::vector<KeyAndId>& out,
                        std::vector<uint8_t>& seen_by,
                        std::unordered_map<uint16_t, size_t>& pixels) {
  const CameraIntrinsics& K = frame.rgbd.K;
  const RigidTransform& X_WC = frame.rgbd.X_WC;
  const Eigen::Vector3d origin = X_WC.translation();
  const auto fruit = static_cast<uint8_t>(SemanticClass::kFruit);
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      if (frame.class_ids.at(u, v) != fruit) continue;
      const float d = frame.rgbd.depth_m.at(u, v);
      if (!std::isfinite(d) || d <= 0.0f) continue;
      const Eigen::Vector3d p_C((u - K.cx) / K.fx * d, (v - K.cy) / K.fy * d, d);
      const Eigen::Vector3d p_W = X_WC * p_C;
      if ((p_W - origin).norm() > max_range_m) continue;
      const uint16_t id = frame.instance_ids.at(u, v);
      out.emplace_back(VoxelKey::FromPoint(p_W, voxel_size_m), id);
      uint8_t& mark = seen_by[static_cast<size_t>(v + rect.v0) * view_width + (u + rect.u0)];
      if (mark != 0) continue;
      mark = 1;
      ++pixels[id];
    }
  }
}

void ClearRect(const PixelRect& rect, int view_width, std::vector<uint8_t>& seen_by) {
  for (int v = rect.v0; v <= rect.v1; ++v) {
    std::fill_n(seen_by.begin() + static_cast<std::ptrdiff_t>(v) * view_width + rect.u0,
                rect.u1 - rect.u0 + 1, uint8_t{0});
  }
}

/// Sorts, keeps the smaller id of duplicate keys and builds the map in key order (so that its
/// iteration order is a function of its content).
void BuildVoxelMap(std::vector<KeyAndId>& pairs, GroundTruth& gt) {
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end(),
                          [](const KeyAndId& a, const KeyAndId& b) { return a.first == b.first; }),
              pairs.end());
  gt.voxels.reserve(pairs.size());
  for (const auto& [key, id] : pairs) gt.voxels.emplace(key, id);
  gt.voxels_per_fruit.clear();
  for (const sim::FruitTruth& f : gt.fruits) gt.voxels_per_fruit[f.instance_id] = 0;
  if (gt.fruits.empty()) return;
  for (const auto& [key, id] : pairs) ++gt.voxels_per_fruit[id];
}

}  // namespace

const OptionTable<GroundTruthOptions>& GroundTruthOptionTable() {
  static const auto* table = [] {
    using G = GroundTruthOptions;
    auto* t = new OptionTable<G>("ground-truth option");
    t->RealList("radii_m", &G::radii_m, "m", ValueRange::LeftOpen(0, 3), 1, 16,
                "distances of the observation views from each fruit");
    t->Integer("azimuths", &G::azimuths, "", ValueRange::Closed(1, 360),
               "azimuths per radius and elevation");
    t->RealList("elevations_deg", &G::elevations_deg, "deg", ValueRange::Open(-89, 89), 1, 16,
                "elevations above the fruit's horizontal plane");
    t->Real("azimuth_half_range_deg", &G::azimuth_half_range_deg, "deg", ValueRange::Closed(0, 180),
            "half-width of the fan facing the robot base");
    t->Integer("image_width", &G::image_width, "px", ValueRange::Closed(1, 8192),
               "render width of the observation views");
    t->Integer("image_height", &G::image_height, "px", ValueRange::Closed(1, 8192),
               "render height of the observation views");
    t->AddRule([](const G& o, std::vector<std::string>& errors) {
      if (!(std::isfinite(o.voxel_size_m) && mapping::VoxelSizeRange().Contains(o.voxel_size_m))) {
        errors.push_back(fmt::format("voxel_size_m ({} m) must be {}", o.voxel_size_m,
                                     mapping::VoxelSizeRange().Requirement()));
      }
      if (!(std::isfinite(o.max_range_m) && o.max_range_m > 0.0 && o.max_range_m <= 100.0)) {
        errors.push_back(fmt::format("max_range_m ({}) must be in (0, 100]", o.max_range_m));
      }
    });
    return t;
  }();
  return *table;
}

Status GroundTruthOptions::Validate() const { return GroundTruthOptionTable().Validate(*this); }

std::vector<VoxelKey> GroundTruth::SortedKeys() const {
  std::vector<VoxelKey> keys;
  keys.reserve(voxels.size());
  for (const auto& [key, id] : voxels) keys.push_back(key);
  std::sort(keys.begin(), keys.end());
  return keys;
}

size_t GroundTruth::ObservableFruits() const {
  size_t n = 0;
  for (const auto& [id, count] : voxels_per_fruit) n += count > 0 ? 1 : 0;
  return n;
}

size_t GroundTruth::FruitsVisibleAtLeast(double fraction) const {
  size_t n = 0;
  for (const auto& [id, v] : best_visible_fraction) n += v >= fraction ? 1 : 0;
  return n;
}

std::vector<ObservationView> ObservationViews(const std::vector<sim::FruitTruth>& fruits,
                                              const GroundTruthOptions& options) {
  const Status valid = options.Validate();
  if (!valid.ok()) ThrowStatus(valid);
  std::vector<ObservationView> views;
  for (const sim::FruitTruth& fruit : fruits) {
    const Eigen::Vector3d& c = fruit.center_W;
    // The fan is centred on the direction from the fruit to the robot base.
    const double centre_deg =
        c.head<2>().norm() > 1e-9 ? std::atan2(-c.y(), -c.x()) / kDegToRad : 180.0;
    for (double radius : options.radii_m) {
      for (double elevation : options.elevations_deg) {
        for (int i = 0; i < options.azimuths; ++i) {
          const double offset =
              options.azimuths == 1
                  ? 0.0
                  : options.azimuth_half_range_deg *
                        (2.0 * static_cast<double>(i) / (options.azimuths - 1) - 1.0);
          const double az = (centre_deg + offset) * kDegToRad;
          const double el = elevation * kDegToRad;
          const Eigen::Vector3d eye =
              c + radius * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                           std::sin(el));
          if (eye.z() <= 0.0) continue;
          ObservationView view;
          view.fruit_id = fruit.instance_id;
          view.radius_m = radius;
          view.azimuth_deg = centre_deg + offset;
          view.elevation_deg = elevation;
          view.X_WC = RigidTransform::LookAt(eye, c, Eigen::Vector3d::UnitZ());
          views.push_back(view);
        }
      }
    }
  }
  return views;
}

CameraIntrinsics ObservationIntrinsics(const CameraIntrinsics& K,
                                       const GroundTruthOptions& options) {
  const double sx = static_cast<double>(options.image_width) / K.width;
  const double sy = static_cast<double>(options.image_height) / K.height;
  CameraIntrinsics out = K;
  out.width = options.image_width;
  out.height = options.image_height;
  out.fx = K.fx * sx;
  out.fy = K.fy * sy;
  // Pixel centres at integers: the image edge -0.5 maps to -0.5.
  out.cx = (K.cx + 0.5) * sx - 0.5;
  out.cy = (K.cy + 0.5) * sy - 0.5;
  return out;
}

namespace {

/// What every view of ObservableGroundTruth shares.
struct ViewContext {
  const CameraIntrinsics& K_view;
  const GroundTruthOptions& options;
  const std::vector<BoundingSphere>& fruit_spheres;
  const sim::RgbdRenderer& renderer;
  const std::unordered_map<uint16_t, GroundTruthFruit>& truth;
};

/// One worker's findings and scratch space.
struct ViewWorker {
  std::vector<KeyAndId> found;
  /// Each fruit's largest visible fraction so far (merged with max: thread-count free).
  std::unordered_map<uint16_t, double> best;
  /// Fruit pixels of the current view (windows may overlap: each pixel counts once).
  std::vector<uint8_t> seen_by;
  std::unordered_map<uint16_t, size_t> pixels;
};

/// The fruit voxels a reachable view sees, and each fruit's visible fraction in it. Only pixels
/// that can see a fruit are rendered: the fruits' projected boxes, merged.
void ObserveView(const ObservationView& view, const ViewContext& ctx, ViewWorker& w) {
  const CameraIntrinsics& K_view = ctx.K_view;
  const RigidTransform X_CW = view.X_WC.inverse();
  std::vector<PixelRect> rects;
  for (const BoundingSphere& sphere : ctx.fruit_spheres) {
    const PixelRect r = ProjectedRect(sphere, X_CW, K_view, ctx.options.max_range_m);
    if (!r.empty()) rects.push_back(r);
  }
  MergeRects(rects);
  const size_t before = w.found.size();
  w.pixels.clear();
  for (const PixelRect& rect : rects) {
    const sim::RenderedFrame frame = ctx.renderer.Render(Window(K_view, rect), view.X_WC);
    CollectFruitVoxels(frame, rect, K_view.width, ctx.options.voxel_size_m, ctx.options.max_range_m,
                       w.found, w.seen_by, w.pixels);
  }
  for (const PixelRect& rect : rects) ClearRect(rect, K_view.width, w.seen_by);
  for (const auto& [id, n] : w.pixels) {
    const auto t = ctx.truth.find(id);
    if (t == ctx.truth.end()) continue;
    const std::optional<double> area =
        segmentation::ExpectedFruitAreaPx(K_view, view.X_WC, t->second);
    const double v = area ? std::clamp(static_cast<double>(n) / *area, 0.0, 1.0) : 1.0;
    double& b = w.best[id];
    b = std::max(b, v);
  }
  // Keep the per-worker list small: drop the duplicates this view added to itself.
  std::sort(w.found.begin() + static_cast<std::ptrdiff_t>(before), w.found.end());
  w.found.erase(std::unique(w.found.begin() + static_cast<std::ptrdiff_t>(before), w.found.end()),
                w.found.end());
}

/// The workers' findings into `gt`: voxels, best visible fractions, reachable views.
void MergeWorkers(const std::vector<ViewWorker>& workers, const std::vector<uint8_t>& reachable,
                  const std::vector<ObservationView>& views, GroundTruth& gt) {
  std::vector<KeyAndId> pairs;
  for (const ViewWorker& w : workers) pairs.insert(pairs.end(), w.found.begin(), w.found.end());
  for (const sim::FruitTruth& f : gt.fruits) gt.best_visible_fraction[f.instance_id] = 0.0;
  for (const ViewWorker& w : workers) {
    for (const auto& [id, v] : w.best) {
      double& b = gt.best_visible_fraction[id];
      b = std::max(b, v);
    }
  }
  for (size_t i = 0; i < views.size(); ++i) {
    if (reachable[i] != 0) gt.views.push_back(views[i]);
  }
  gt.views_reachable = gt.views.size();
  BuildVoxelMap(pairs, gt);
}

}  // namespace

Result<GroundTruth> ObservableGroundTruth(const sim::Scene& scene, const robot::ArmModel& arm,
                                          const Eigen::VectorXd& q_start, const CameraIntrinsics& K,
                                          const GroundTruthOptions& options) {
  AVP_RETURN_IF_ERROR(options.Validate());
  AVP_RETURN_IF_ERROR(K.Validate());
  AVP_RETURN_IF_ERROR(scene.Validate().WithContext(fmt::format("scene '{}'", scene.name)));
  if (q_start.size() != arm.num_joints() || !q_start.allFinite()) {
    return InvalidArgumentError(fmt::format(
        "start joints ({}) must be {} finite values",
        fmt::join(q_start.data(), q_start.data() + q_start.size(), ", "), arm.num_joints()));
  }

  GroundTruth gt;
  gt.voxel_size_m = options.voxel_size_m;
  gt.fruits = scene.Fruits();
  gt.source = "observable:" + scene.name;
  std::vector<BoundingSphere> fruit_spheres;
  for (const sim::SceneObject& o : scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) fruit_spheres.push_back(FruitBoundingSphere(o));
  }
  const std::vector<ObservationView> views = ObservationViews(gt.fruits, options);
  gt.views_tried = views.size();
  const CameraIntrinsics K_view = ObservationIntrinsics(K, options);
  AVP_RETURN_IF_ERROR(K_view.Validate().WithContext("observation view intrinsics"));

  const sim::RgbdRenderer renderer(scene);  // one view per worker: each renders serially
  const Rng views_rng = Rng(options.seed).Fork("observable-ground-truth");
  std::unordered_map<uint16_t, GroundTruthFruit> truth;
  for (const sim::FruitTruth& f : gt.fruits) {
    truth[f.instance_id] = {f.instance_id, f.center_W, f.mean_radius_m()};
  }
  const ViewContext ctx{K_view, options, fruit_spheres, renderer, truth};

  const size_t threads =
      std::min(static_cast<size_t>(Threads()), std::max<size_t>(views.size(), 1));
  std::vector<ViewWorker> workers(threads);
  std::vector<uint8_t> reachable(views.size(), 0);  // written by the view's worker only
  std::atomic<size_t> next{0};
  const auto work = [&](size_t worker) {
    ViewWorker& w = workers[worker];
    w.seen_by.assign(static_cast<size_t>(K_view.width) * K_view.height, 0);
    while (true) {
      const size_t i = next.fetch_add(1, std::memory_order_relaxed);
      if (i >= views.size()) return;
      Rng rng = views_rng.Fork(static_cast<uint64_t>(i));
      if (!arm.SolveCameraIk(views[i].X_WC, q_start, rng).ok()) continue;
      reachable[i] = 1;
      ObserveView(views[i], ctx, w);
    }
  };
  std::atomic<size_t> next_worker{0};
  RunWorkers(threads, [&] { work(next_worker.fetch_add(1)); });
  MergeWorkers(workers, reachable, views, gt);
  return gt;
}

Result<GroundTruth> GroundTruthFromOctomapFile(const std::filesystem::path& bt,
                                               const sim::Scene* scene) {
  // Any map file (mapping::LoadAnyMap): an OctoMap .bt / .ot gives its occupied voxels, a map
  // that carries classes (.avpmap, a ColorOcTree in avp's class colours) its fruit voxels.
  AVP_ASSIGN_OR_RETURN(const mapping::LoadedMap loaded, mapping::LoadAnyMap(bt));
  bool used_labels = false;
  const mapping::VoxelSet set =
      mapping::GroundTruthVoxels(loaded, SemanticClass::kFruit, &used_labels);
  GroundTruth gt;
  gt.voxel_size_m = set.resolution_m;
  gt.source = "file:" + bt.string();
  if (used_labels) gt.source += " (its fruit voxels)";
  if (scene != nullptr) gt.fruits = scene->Fruits();
  std::vector<KeyAndId> pairs;
  pairs.reserve(set.keys.size());
  for (const VoxelKey& key : set.keys) {
    const Eigen::Vector3d p = key.Center(set.resolution_m);
    uint16_t best_id = 0;
    double best = std::numeric_limits<double>::infinity();
    for (const sim::FruitTruth& f : gt.fruits) {  // in id order: ties keep the smaller id
      const double d = std::abs((p - f.center_W).norm() - f.mean_radius_m());
      if (d < best) {
        best = d;
        best_id = f.instance_id;
      }
    }
    pairs.emplace_back(key, best_id);
  }
  BuildVoxelMap(pairs, gt);
  return gt;
}

}  // namespace avp::eval

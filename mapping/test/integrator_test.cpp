// Integrator: analytic scenes rendered by avp::sim (a sphere, a wall, a far wall beyond max range)
// integrated and checked against the geometry, against OctoMap's insertPointCloud, across thread
// counts and carving modes, plus input validation and semantic masks.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/ray_traversal.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scene.h>

namespace avp::mapping {
namespace {

using ::testing::HasSubstr;

constexpr double kVoxel = 0.005;
const double kHalfDiagonal = 0.5 * std::sqrt(3.0) * kVoxel;
constexpr double kEps = 1e-5;

// ---- The analytic scene
// --------------------------------------------------------------------------

/// A fruit sphere at ~0.45 m, a wall at x = 0.7012 m covering the y < 0.05 half of the view, and a
/// far wall at x = 1.3 m (beyond the tests' 1.0 m max range, within the camera's 3 m). Faces are
/// kept off the voxel lattice so that rendered points never sit exactly on a voxel face.
struct AnalyticScene {
  Eigen::Vector3d sphere_c{0.45, 0.03, -0.02};
  double sphere_r = 0.04;
  Box3 wall{Eigen::Vector3d(0.7012, -0.8, -0.8), Eigen::Vector3d(0.7212, 0.0513, 0.8)};
  Box3 far_wall{Eigen::Vector3d(1.3, -2.0, -2.0), Eigen::Vector3d(1.32, 2.0, 2.0)};
  sim::Scene scene;
  uint16_t fruit_id = 0;

  AnalyticScene() {
    sim::SceneObject fruit;
    fruit.name = "fruit";
    fruit.semantic_class = SemanticClass::kFruit;
    sim::Ellipsoid e;
    e.center_W = sphere_c;
    e.radii = Eigen::Vector3d::Constant(sphere_r);
    fruit.shape = e;
    fruit_id = scene.Add(fruit);
    scene.Add("wall", SemanticClass::kSupport, Eigen::Vector3f(0.5f, 0.5f, 0.5f),
              sim::MakeBox(wall));
    scene.Add("far wall", SemanticClass::kOther, Eigen::Vector3f(0.3f, 0.3f, 0.3f),
              sim::MakeBox(far_wall));
  }

  /// Distance from p to the visible surfaces (sphere, near wall).
  double SurfaceDistance(const Eigen::Vector3d& p) const {
    return std::min(std::abs((p - sphere_c).norm() - sphere_r), BoxSurfaceDistance(p, wall));
  }
  static double BoxSurfaceDistance(const Eigen::Vector3d& p, const Box3& b) {
    const Eigen::Vector3d out =
        (b.min() - p).cwiseMax(p - b.max()).cwiseMax(Eigen::Vector3d::Zero());
    if (out.squaredNorm() > 0.0) return out.norm();
    const Eigen::Vector3d in = (p - b.min()).cwiseMin(b.max() - p);
    return in.minCoeff();
  }
  /// Signed distance to the near wall box (negative inside).
  static double BoxSignedDistance(const Eigen::Vector3d& p, const Box3& b) {
    const double d = BoxSurfaceDistance(p, b);
    return b.Contains(p) ? -d : d;
  }

  /// Smallest t > 0 where o + t dir meets a solid (sphere, wall or far wall), or nullopt.
  std::optional<double> Hit(const Eigen::Vector3d& o, const Eigen::Vector3d& dir,
                            bool* hits_far_wall = nullptr, bool* hits_sphere = nullptr) const {
    std::optional<double> best;
    int which = -1;
    const auto consider = [&](std::optional<double> t, int id) {
      if (t && *t > 0.0 && (!best || *t < *best)) {
        best = t;
        which = id;
      }
    };
    // Sphere.
    const Eigen::Vector3d oc = o - sphere_c;
    const double a = dir.squaredNorm(), b = oc.dot(dir), c = oc.squaredNorm() - sphere_r * sphere_r;
    const double disc = b * b - a * c;
    if (disc >= 0.0) consider((-b - std::sqrt(disc)) / a, 0);
    consider(SlabHit(o, dir, wall), 1);
    consider(SlabHit(o, dir, far_wall), 2);
    if (hits_far_wall != nullptr) *hits_far_wall = which == 2;
    if (hits_sphere != nullptr) *hits_sphere = which == 0;
    return best;
  }
  static std::optional<double> SlabHit(const Eigen::Vector3d& o, const Eigen::Vector3d& dir,
                                       const Box3& box) {
    double t0 = 0.0, t1 = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 3; ++i) {
      if (dir[i] == 0.0) {
        if (o[i] < box.min()[i] || o[i] > box.max()[i]) return std::nullopt;
        continue;
      }
      double a = (box.min()[i] - o[i]) / dir[i], b = (box.max()[i] - o[i]) / dir[i];
      if (a > b) std::swap(a, b);
      t0 = std::max(t0, a);
      t1 = std::min(t1, b);
    }
    if (t0 > t1) return std::nullopt;
    return t0;
  }
};

constexpr int kWidth = 112;
constexpr int kHeight = 84;
constexpr size_t kPixels = static_cast<size_t>(kWidth) * kHeight;
constexpr double kMaxRange = 1.0;

CameraIntrinsics SmallCamera() {
  return CameraIntrinsics::FromHorizontalFov(kWidth, kHeight, 50.0, 0.1, 3.0);
}

std::vector<RigidTransform> Poses() {
  return {RigidTransform::LookAt({0.02, -0.01, 0.015}, {1.0, 0.05, -0.03}),
          RigidTransform::LookAt({0.05, 0.2, 0.1}, {0.45, 0.03, -0.02}),
          RigidTransform::LookAt({0.0, -0.25, -0.05}, {0.5, 0.0, 0.0}),
          RigidTransform::LookAt({0.1, 0.05, 0.3}, {0.45, 0.0, -0.05})};
}

MapOptions DefaultMap() {
  MapOptions o;
  o.grid.voxel_size_m = kVoxel;
  return o;
}

IntegratorOptions Options(FreeSpaceCarving carving = FreeSpaceCarving::kRayCast) {
  IntegratorOptions o;
  o.max_range_m = kMaxRange;
  o.carving = carving;
  return o;
}

/// Integrator(Options(carving)) whose calls run on `threads` threads (avp's one parallelism
/// setting, a ThreadScope: core/parallel.h).
class ThreadedIntegrator {
 public:
  ThreadedIntegrator(FreeSpaceCarving carving, int threads)
      : integrator_(Options(carving)), threads_(threads) {}
  template <typename... Args>
  auto Integrate(Args&&... args) const {
    const ThreadScope scope(threads_);
    return integrator_.Integrate(std::forward<Args>(args)...);
  }
  template <typename... Args>
  auto IntegratePointCloud(Args&&... args) const {
    const ThreadScope scope(threads_);
    return integrator_.IntegratePointCloud(std::forward<Args>(args)...);
  }

 private:
  Integrator integrator_;
  int threads_;
};

using VoxelList = std::vector<std::pair<VoxelKey, float>>;

/// Every known voxel with its log-odds, sorted by key.
VoxelList Contents(const OccupancyGrid& grid) {
  VoxelList out;
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float v) { out.emplace_back(k, v); });
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  return out;
}

/// World points of the valid pixels of a frame (double, as the integrator computes them).
std::vector<Eigen::Vector3d> WorldPoints(const RgbdFrame& f) {
  std::vector<Eigen::Vector3d> out;
  for (int v = 0; v < f.depth_m.height(); ++v) {
    for (int u = 0; u < f.depth_m.width(); ++u) {
      const float d = f.depth_m.at(u, v);
      if (!(std::isfinite(d) && d > 0.0f)) continue;
      out.push_back(f.X_WC * f.K.BackProject(Eigen::Vector2d(u, v), d));
    }
  }
  return out;
}

class IntegratorSceneTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new AnalyticScene();
    renderer_ = new sim::RgbdRenderer(scene_->scene);
  }
  static void TearDownTestSuite() {
    delete renderer_;
    delete scene_;
    renderer_ = nullptr;
    scene_ = nullptr;
  }
  static sim::RenderedFrame Render(const RigidTransform& X_WC) {
    return renderer_->Render(SmallCamera(), X_WC);
  }
  static AnalyticScene* scene_;
  static sim::RgbdRenderer* renderer_;
};
AnalyticScene* IntegratorSceneTest::scene_ = nullptr;
sim::RgbdRenderer* IntegratorSceneTest::renderer_ = nullptr;

// ---- Geometry ----------------------------------------------------------------------------------

/// Stats add up; the scene has all three kinds of pixel.
void ExpectStatsAddUp(const IntegrationStats& stats, const OccupancyGrid& grid) {
  EXPECT_EQ(stats.pixels, kPixels);
  EXPECT_EQ(stats.invalid_depth + stats.beyond_max_range + stats.endpoints, stats.pixels);
  EXPECT_EQ(stats.invalid_depth, 0u);
  EXPECT_GT(stats.beyond_max_range, 2000u);
  EXPECT_GT(stats.endpoints, 2000u);
  EXPECT_EQ(stats.rejected_points, 0u);
  EXPECT_EQ(stats.masked_endpoints, 0u);
  EXPECT_EQ(stats.occupied_updates, grid.CountOccupiedVoxels());
  EXPECT_EQ(stats.free_updates, grid.CountKnownVoxels() - grid.CountOccupiedVoxels());
  EXPECT_EQ(grid.frame(), 1u);
}

/// Occupied voxels lie on the surface; no known voxel lies behind a surface or beyond range.
void ExpectKnownVoxelsOnOrBeforeSurfaces(const OccupancyGrid& grid, const AnalyticScene& sc,
                                         const Eigen::Vector3d& o) {
  size_t occupied = 0;
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float v) {
    const Eigen::Vector3d c = k.Center(kVoxel);
    if (v >= 0.0f) {
      ++occupied;
      EXPECT_LE(sc.SurfaceDistance(c), kHalfDiagonal + kEps) << c.transpose();
      EXPECT_LE((c - o).norm(), kMaxRange + kHalfDiagonal + kEps);
    }
    EXPECT_GE((c - sc.sphere_c).norm(), sc.sphere_r - kHalfDiagonal - kEps) << c.transpose();
    EXPECT_GE(AnalyticScene::BoxSignedDistance(c, sc.wall), -kHalfDiagonal - kEps) << c.transpose();
    EXPECT_LE((c - o).norm(), kMaxRange + 2 * kHalfDiagonal + kEps) << c.transpose();
  });
  EXPECT_GT(occupied, 2000u);
}

/// What the pixel survey of OneFrameMatchesTheAnalyticGeometry counts: points sampled along the
/// analytic rays of every other pixel, and the states the map gives them.
struct PixelSurvey {
  size_t surface = 0, surface_occupied = 0, front = 0, front_free = 0, front_occupied = 0;
  size_t shadow = 0, shadow_known = 0, ranged = 0, ranged_free = 0, beyond = 0, beyond_known = 0;
};

/// Points well in front of the surface along `dir` (hit at `range`), away from surfaces and the
/// range limit.
void SurveyFront(const OccupancyGrid& grid, const AnalyticScene& sc, const Eigen::Vector3d& o,
                 const Eigen::Vector3d& dir, double range, Rng& rng, PixelSurvey& s) {
  const double free_until = std::min(range, kMaxRange);
  for (int i = 0; i < 6; ++i) {
    const double r = rng.Uniform(0.0, free_until);
    const Eigen::Vector3d q = o + dir.normalized() * r;
    const VoxelKey k = grid.KeyOf(q);
    const Eigen::Vector3d c = k.Center(kVoxel);
    if (sc.SurfaceDistance(c) <= kHalfDiagonal + kEps) continue;  // a surface voxel
    if ((c - o).norm() >= kMaxRange - kHalfDiagonal) continue;    // at the range limit
    ++s.front;
    s.front_free += grid.State(k) == VoxelState::kFree;
    s.front_occupied += grid.State(k) == VoxelState::kOccupied;
  }
}

/// Rays well inside the sphere's silhouette: behind the sphere, before the wall, is shadow.
void SurveyShadow(const OccupancyGrid& grid, const AnalyticScene& sc, const Eigen::Vector3d& o,
                  const Eigen::Vector3d& dir, double range, Rng& rng, PixelSurvey& s) {
  const Eigen::Vector3d oc = o - sc.sphere_c;
  const double margin = sc.sphere_r - (oc - oc.dot(dir.normalized()) * dir.normalized()).norm();
  if (margin < 3 * kVoxel) return;
  for (int i = 0; i < 6; ++i) {
    const double r = rng.Uniform(range, range + 0.3);
    const Eigen::Vector3d q = o + dir.normalized() * r;
    const VoxelKey k = grid.KeyOf(q);
    const Eigen::Vector3d c = k.Center(kVoxel);
    if ((c - sc.sphere_c).norm() <= sc.sphere_r + kHalfDiagonal + kEps) continue;
    if (AnalyticScene::BoxSignedDistance(c, sc.wall) <= kHalfDiagonal + kEps) continue;
    ++s.shadow;
    s.shadow_known += grid.State(k) != VoxelState::kUnknown;
  }
}

/// Pixel by pixel: the analytic hit's voxel (sphere, wall), points in front of the surface,
/// points in the sphere's shadow, and on rays to the far wall the points before and beyond max
/// range.
void SurveyPixels(const OccupancyGrid& grid, const AnalyticScene& sc, const RigidTransform& X_WC,
                  const CameraIntrinsics& K, PixelSurvey& s) {
  const Eigen::Vector3d o = X_WC.translation();
  Rng rng(5);
  for (int v = 0; v < K.height; v += 2) {
    for (int u = 0; u < K.width; u += 2) {
      const Eigen::Vector3d dir = X_WC.rotation() * K.RayDirection(Eigen::Vector2d(u, v));
      bool far = false, sphere = false;
      const auto t = sc.Hit(o, dir, &far, &sphere);
      ASSERT_TRUE(t.has_value());
      const Eigen::Vector3d hit = o + *t * dir;
      const double range = (hit - o).norm();
      if (!far) {
        ++s.surface;
        s.surface_occupied += grid.State(grid.KeyOf(hit)) == VoxelState::kOccupied;
      }
      SurveyFront(grid, sc, o, dir, range, rng, s);
      if (far) {
        for (const double r : {0.90, 0.95}) {
          ++s.ranged;
          s.ranged_free += grid.State(grid.KeyOf(o + dir.normalized() * r)) == VoxelState::kFree;
        }
        for (const double r : {1.05, 1.15, 1.25}) {
          ++s.beyond;
          s.beyond_known +=
              grid.State(grid.KeyOf(o + dir.normalized() * r)) != VoxelState::kUnknown;
        }
      }
      if (sphere) SurveyShadow(grid, sc, o, dir, range, rng, s);
    }
  }
}

TEST_F(IntegratorSceneTest, OneFrameMatchesTheAnalyticGeometry) {
  const AnalyticScene& sc = *scene_;
  const RigidTransform X_WC = Poses()[0];
  const sim::RenderedFrame f = Render(X_WC);
  SemanticMap map(DefaultMap());
  const Integrator integrator(Options());
  const auto stats = integrator.Integrate(f.rgbd, nullptr, map);
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  const OccupancyGrid& grid = map.grid();
  ExpectStatsAddUp(*stats, grid);
  ExpectKnownVoxelsOnOrBeforeSurfaces(grid, sc, X_WC.translation());

  // The analytic hit's voxel is occupied (sphere, wall); points well in front of the surface are
  // free; points in the sphere's shadow stay unknown; rays to the far wall are free up to max
  // range and unknown beyond.
  PixelSurvey s;
  ASSERT_NO_FATAL_FAILURE(SurveyPixels(grid, sc, X_WC, SmallCamera(), s));
  std::printf(
      "[ surface voxels occupied %zu/%zu, free in front %zu/%zu, shadow known %zu/%zu, "
      "free before max range %zu/%zu, known beyond %zu/%zu ]\n",
      s.surface_occupied, s.surface, s.front_free, s.front, s.shadow_known, s.shadow, s.ranged_free,
      s.ranged, s.beyond_known, s.beyond);
  EXPECT_GT(s.surface, 800u);
  EXPECT_GE(s.surface_occupied, s.surface * 99 / 100);
  EXPECT_GT(s.front, 10000u);
  EXPECT_EQ(s.front_occupied, 0u);
  EXPECT_GE(s.front_free, s.front * 999 / 1000);
  EXPECT_GT(s.shadow, 100u);
  EXPECT_EQ(s.shadow_known, 0u);
  EXPECT_GT(s.ranged, 2000u);
  EXPECT_GE(s.ranged_free, s.ranged * 999 / 1000);
  EXPECT_EQ(s.beyond_known, 0u);
}

TEST_F(IntegratorSceneTest, InteriorOfTheSphereAndBehindTheWallStayUnknownOverManyFrames) {
  const AnalyticScene& sc = *scene_;
  SemanticMap map(DefaultMap());
  const Integrator integrator(Options());
  for (const RigidTransform& X : Poses()) {
    ASSERT_TRUE(integrator.Integrate(Render(X).rgbd, nullptr, map).ok());
  }
  const OccupancyGrid& grid = map.grid();
  EXPECT_EQ(grid.frame(), 4u);
  // Every voxel deeper than two voxels inside the sphere, or behind the wall's front face.
  const VoxelKey lo = grid.KeyOf(sc.sphere_c - Eigen::Vector3d::Constant(sc.sphere_r));
  const VoxelKey hi = grid.KeyOf(sc.sphere_c + Eigen::Vector3d::Constant(sc.sphere_r));
  size_t inside = 0;
  for (int32_t z = lo.z; z <= hi.z; ++z) {
    for (int32_t y = lo.y; y <= hi.y; ++y) {
      for (int32_t x = lo.x; x <= hi.x; ++x) {
        const VoxelKey k{x, y, z};
        if ((k.Center(kVoxel) - sc.sphere_c).norm() >= sc.sphere_r - 2 * kVoxel) continue;
        ++inside;
        ASSERT_EQ(grid.State(k), VoxelState::kUnknown) << x << " " << y << " " << z;
      }
    }
  }
  EXPECT_GT(inside, 800u);
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float) {
    const Eigen::Vector3d c = k.Center(kVoxel);
    EXPECT_GE(AnalyticScene::BoxSignedDistance(c, sc.wall), -kHalfDiagonal - kEps);
  });
}

// ---- Invalid input -----------------------------------------------------------------------------

TEST_F(IntegratorSceneTest, InvalidDepthPixelsAreSkippedAndCounted) {
  const sim::RenderedFrame f = Render(Poses()[0]);
  RgbdFrame bad = f.rgbd;
  RgbdFrame zeroed = f.rgbd;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const float values[] = {nan, 0.0f, -0.5f, inf, -inf, -0.0f};
  Rng rng(3);
  size_t changed = 0;
  for (int i = 0; i < 3000; ++i) {
    const int u = static_cast<int>(rng.UniformInt(0, kWidth - 1));
    const int v = static_cast<int>(rng.UniformInt(0, kHeight - 1));
    if (zeroed.depth_m.at(u, v) == 0.0f) continue;  // already skipped
    bad.depth_m.at(u, v) = values[i % 6];
    zeroed.depth_m.at(u, v) = 0.0f;
    ++changed;
  }
  ASSERT_GT(changed, 2000u);
  SemanticMap a(DefaultMap()), b(DefaultMap());
  const Integrator integrator(Options());
  const auto sa = integrator.Integrate(bad, nullptr, a);
  const auto sb = integrator.Integrate(zeroed, nullptr, b);
  ASSERT_TRUE(sa.ok()) << sa.status().ToString();
  ASSERT_TRUE(sb.ok());
  EXPECT_EQ(sa->invalid_depth, changed);
  EXPECT_EQ(sa->invalid_depth, sb->invalid_depth);
  EXPECT_EQ(sa->endpoints + sa->beyond_max_range + sa->invalid_depth, sa->pixels);
  EXPECT_EQ(Contents(a.grid()), Contents(b.grid()));
  // A frame with no valid pixel leaves the map empty but counts every pixel.
  RgbdFrame none = f.rgbd;
  none.depth_m.Fill(nan);
  SemanticMap c(DefaultMap());
  const auto sc = integrator.Integrate(none, nullptr, c);
  ASSERT_TRUE(sc.ok());
  EXPECT_EQ(sc->invalid_depth, kPixels);
  EXPECT_EQ(c.grid().CountKnownVoxels(), 0u);
}

TEST_F(IntegratorSceneTest, BadFramesAndSegmentationsAreRejectedAndTheMapIsUntouched) {
  const sim::RenderedFrame f = Render(Poses()[0]);
  SemanticMap map(DefaultMap());
  const Integrator integrator(Options());
  ASSERT_TRUE(integrator.Integrate(f.rgbd, nullptr, map).ok());
  const auto before = Contents(map.grid());
  const uint32_t frame_before = map.grid().frame();
  const size_t blocks_before = map.grid().num_blocks();

  // Segmentation of another size: the error names both sizes.
  Segmentation small;
  small.width = 80;
  small.height = 60;
  auto r = integrator.Integrate(f.rgbd, &small, map);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("80x60"));
  EXPECT_THAT(r.status().message(), HasSubstr("112x84"));
  // Right size but a mask of the wrong size.
  Segmentation wrong_mask;
  wrong_mask.width = kWidth;
  wrong_mask.height = kHeight;
  wrong_mask.instances.push_back({MaskImage(kWidth, kHeight - 1, 1), SemanticClass::kFruit, 0.9f,
                                  "fruit", std::nullopt, -1.0f});
  r = integrator.Integrate(f.rgbd, &wrong_mask, map);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("112x83"));

  // Invalid intrinsics.
  RgbdFrame bad_k = f.rgbd;
  bad_k.K.fx = -1.0;
  r = integrator.Integrate(bad_k, nullptr, map);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("fx"));
  // Depth of another size than K.
  RgbdFrame bad_depth = f.rgbd;
  bad_depth.depth_m = DepthImage(100, 100, 1.0f);
  r = integrator.Integrate(bad_depth, nullptr, map);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("100x100"));

  // A non-finite camera position.
  RgbdFrame bad_pose = f.rgbd;
  bad_pose.X_WC = RigidTransform(Eigen::Vector3d(std::nan(""), 0.0, 0.0));
  r = integrator.Integrate(bad_pose, nullptr, map);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("X_WC"));

  EXPECT_EQ(map.grid().frame(), frame_before);
  EXPECT_EQ(map.grid().num_blocks(), blocks_before);
  EXPECT_EQ(Contents(map.grid()), before);
}

TEST(IntegratorTest, OptionsValidation) {
  EXPECT_TRUE(IntegratorOptions{}.Validate().ok());
  IntegratorOptions o;
  o.max_range_m = 0.0;
  EXPECT_THAT(o.Validate().message(), HasSubstr("max_range_m (0 m)"));
  o.max_range_m = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(o.Validate().message(), HasSubstr("max_range_m (nan)"));
  EXPECT_THROW(Integrator{o}, Error);
  for (const FreeSpaceCarving c : kFreeSpaceCarvings) {
    EXPECT_EQ(FreeSpaceCarvingFromString(ToString(c)), c);
  }
  EXPECT_EQ(FreeSpaceCarvingNames(),
            (std::vector<std::string>{"projective", "raycast", "end-voxel", "none"}));
  EXPECT_EQ(ToString(FreeSpaceCarving::kRayCast), "raycast");
  IntegratorOptions parsed;
  ASSERT_TRUE(IntegratorOptionTable().Set(parsed, "carving", "end-voxel").ok());
  EXPECT_EQ(parsed.carving, FreeSpaceCarving::kEndVoxelRays);
  EXPECT_FALSE(FreeSpaceCarvingFromString("octomap").has_value());
}

TEST(IntegratorTest, RaysLongerThanTheWalkerLimitAreNotSilentlyDropped) {
  // At 2 mm the walker takes at most 2^14 voxels (32.8 m); max_range_m accepts up to 100 m. A
  // 35 m return must either carve its 17,500 free voxels (as OctoMap's insertPointCloud does) or
  // be refused with an error -- not be accepted with its endpoint marked and no free space.
  GridOptions g;
  g.voxel_size_m = 0.002;
  OccupancyGrid grid(g);
  IntegratorOptions o;
  o.max_range_m = 40.0;
  const Eigen::Vector3d origin(0.0011, 0.0013, 0.0017);
  const std::vector<Eigen::Vector3f> points = {{35.0011f, 0.0013f, 0.0017f}};
  const auto r = Integrator(o).IntegratePointCloud(points, origin, grid);
  if (!r.ok()) {
    SUCCEED() << r.status().ToString();
    return;
  }
  octomap::OcTree tree(0.002);
  octomap::Pointcloud cloud;
  cloud.push_back(points[0].x(), points[0].y(), points[0].z());
  tree.insertPointCloud(cloud, octomap::point3d(0.0011f, 0.0013f, 0.0017f), 40.0);
  size_t octomap_free = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!tree.isNodeOccupied(*it)) octomap_free += size_t{1} << (3 * (16 - it.getDepth()));
  }
  EXPECT_EQ(octomap_free, 17500u);
  EXPECT_EQ(r->free_updates, octomap_free) << "the 35 m ray carved no free space";
  EXPECT_EQ(grid.State(grid.KeyOf({10.0, 0.0013, 0.0017})), VoxelState::kFree);
  EXPECT_EQ(grid.CountKnownVoxels() - grid.CountOccupiedVoxels(), octomap_free);
}

TEST(IntegratorTest, RaysSpanningAHugeBoxAreCarvedVoxelByVoxel) {
  // Rays of 30 m along three axes at 2 mm span a box of 15 000^3 voxels, too large for the
  // frame's dense bit map: the voxels are then walked one by one through the grid, with the same
  // result (every voxel of every walk, once).
  GridOptions g;
  g.voxel_size_m = 0.002;
  OccupancyGrid grid(g);
  IntegratorOptions o;
  o.max_range_m = 32.0;  // 16 000 voxels: within the ray traversal's limit
  o.carving = FreeSpaceCarving::kRayCast;
  const Eigen::Vector3d origin(0.0011, 0.0013, 0.0017);
  const std::vector<Eigen::Vector3f> points = {
      {30.0011f, 0.0013f, 0.0017f},
      {0.0011f, -30.0013f, 0.0017f},
      {0.0011f, 0.0013f, 30.0017f},
      {0.2011f, 0.1013f, 0.0517f}};  // and a short one that crosses the others' first voxels
  std::set<std::tuple<int32_t, int32_t, int32_t>> expected;
  for (const Eigen::Vector3f& p : points) {
    const RayWalker w(origin, p.cast<double>(), 0.002);
    ASSERT_TRUE(w.ok());
    w.ForEachKeyBeforeEnd([&](const VoxelKey& k) {
      expected.insert({k.x, k.y, k.z});
      return true;
    });
  }
  const auto r = Integrator(o).IntegratePointCloud(points, origin, grid);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->free_updates, expected.size());
  EXPECT_GT(expected.size(), 44000u);
  EXPECT_EQ(grid.CountKnownVoxels() - grid.CountOccupiedVoxels(), expected.size());
  EXPECT_EQ(grid.State(grid.KeyOf({15.0, 0.0013, 0.0017})), VoxelState::kFree);
}

TEST(IntegratorTest, PointCloudInputValidation) {
  OccupancyGrid grid;
  const std::vector<Eigen::Vector3f> points = {
      {0.1f, 0.0f, 0.0f},
      {std::numeric_limits<float>::quiet_NaN(), 0.0f, 0.0f},
      {0.0f, std::numeric_limits<float>::infinity(), 0.0f},
      {0.0f, 0.2f, 0.0f}};
  const auto projective = Integrator(Options(FreeSpaceCarving::kProjective))
                              .IntegratePointCloud(points, Eigen::Vector3d::Zero(), grid);
  EXPECT_FALSE(projective.ok());
  const auto bad_origin =
      Integrator(Options()).IntegratePointCloud(points, Eigen::Vector3d(std::nan(""), 0, 0), grid);
  EXPECT_FALSE(bad_origin.ok());
  EXPECT_EQ(grid.num_blocks(), 0u);
  const auto ok = Integrator(Options()).IntegratePointCloud(points, Eigen::Vector3d::Zero(), grid);
  ASSERT_TRUE(ok.ok());
  EXPECT_EQ(ok->pixels, 4u);
  EXPECT_EQ(ok->invalid_depth, 2u);
  EXPECT_EQ(ok->endpoints, 2u);
  EXPECT_EQ(ok->occupied_updates, 2u);
  // 0.1 m along x at 5 mm: voxels 0..19 free then 20 occupied; 0.2 m along y: 0..39 then 40.
  EXPECT_EQ(grid.State({20, 0, 0}), VoxelState::kOccupied);
  EXPECT_EQ(grid.State({40, 0, 0}), VoxelState::kUnknown);
  EXPECT_EQ(grid.State({0, 40, 0}), VoxelState::kOccupied);
  for (int i = 1; i < 20; ++i) EXPECT_EQ(grid.State({i, 0, 0}), VoxelState::kFree) << i;
  for (int i = 1; i < 40; ++i) EXPECT_EQ(grid.State({0, i, 0}), VoxelState::kFree) << i;
  EXPECT_EQ(grid.State({0, 0, 0}), VoxelState::kFree);
  EXPECT_EQ(ok->free_updates, 1u + 19u + 39u);
}

// ---- OctoMap and internal consistency ---------------------------------------------------------

struct Agreement {
  size_t union_size = 0;
  size_t same_state = 0;
  size_t same_log_odds = 0;
  size_t only_ours = 0;
  size_t only_octomap = 0;
};

/// Compares every voxel known to either map (the tree is expanded to full depth first).
Agreement Compare(const OccupancyGrid& grid, octomap::OcTree& tree) {
  tree.expand();
  VoxelList octo;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    EXPECT_EQ(it.getDepth(), 16u);
    const octomap::OcTreeKey k = it.getKey();
    octo.emplace_back(
        VoxelKey{static_cast<int32_t>(k[0]) - 32768, static_cast<int32_t>(k[1]) - 32768,
                 static_cast<int32_t>(k[2]) - 32768},
        it->getLogOdds());
  }
  std::sort(octo.begin(), octo.end(),
            [](const auto& x, const auto& y) { return x.first < y.first; });
  const VoxelList ours = Contents(grid);
  Agreement a;
  size_t i = 0, j = 0;
  while (i < ours.size() || j < octo.size()) {
    ++a.union_size;
    if (j == octo.size() || (i < ours.size() && ours[i].first < octo[j].first)) {
      ++a.only_ours;
      ++i;
    } else if (i == ours.size() || octo[j].first < ours[i].first) {
      ++a.only_octomap;
      ++j;
    } else {
      a.same_state += (ours[i].second >= 0.0f) == (octo[j].second >= 0.0f);
      a.same_log_odds += ours[i].second == octo[j].second;
      ++i;
      ++j;
    }
  }
  return a;
}

octomap::OcTree MakeOctree() {
  octomap::OcTree tree(kVoxel);
  tree.setProbHit(0.7);
  tree.setProbMiss(0.4);
  tree.setClampingThresMin(0.12);
  tree.setClampingThresMax(0.97);
  tree.setOccupancyThres(0.5);
  return tree;
}

/// The voxels of a point cloud inserted into OctoMap with insertPointCloud(discretize), as
/// (key, log-odds) sorted by key.
VoxelList OctomapContents(const std::vector<Eigen::Vector3f>& points, const Eigen::Vector3f& origin,
                          double max_range, bool discretize) {
  octomap::OcTree tree = MakeOctree();
  octomap::Pointcloud cloud;
  for (const Eigen::Vector3f& q : points) cloud.push_back(q.x(), q.y(), q.z());
  tree.insertPointCloud(cloud, octomap::point3d(origin.x(), origin.y(), origin.z()), max_range,
                        /*lazy_eval=*/false, discretize);
  tree.expand();
  VoxelList out;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const octomap::OcTreeKey k = it.getKey();
    out.emplace_back(
        VoxelKey{static_cast<int32_t>(k[0]) - 32768, static_cast<int32_t>(k[1]) - 32768,
                 static_cast<int32_t>(k[2]) - 32768},
        it->getLogOdds());
  }
  std::sort(out.begin(), out.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
  return out;
}

TEST(IntegratorTest, EndVoxelRaysCastOneRayPerVoxelToItsCentre) {
  // Three returns in voxel (20, 1, 0), seen from the centre of voxel (0, 0, 0). One ray to the
  // voxel's centre (0.1025, 0.0075, 0.0025) m rises one voxel in y at x = 0.0525 m (voxel 10):
  // free are (0..10, 0, 0) and (10..19, 1, 0), 21 voxels, whatever the returns' own rays cross.
  // The ray to the first return itself rises at x = 0.0355 m (voxel 7), so per-point ray casting
  // also frees (7..9, 1, 0).
  const Eigen::Vector3f origin(0.0025f, 0.0025f, 0.0025f);
  const std::vector<Eigen::Vector3f> points = {
      {0.1001f, 0.0099f, 0.0025f}, {0.1049f, 0.0051f, 0.0049f}, {0.1030f, 0.0080f, 0.0001f}};
  OccupancyGrid voxel_rays, per_point;
  const auto r = Integrator(Options(FreeSpaceCarving::kEndVoxelRays))
                     .IntegratePointCloud(points, origin.cast<double>(), voxel_rays);
  const auto p =
      Integrator(Options()).IntegratePointCloud(points, origin.cast<double>(), per_point);
  ASSERT_TRUE(r.ok() && p.ok());
  EXPECT_EQ(r->endpoints, 3u);
  EXPECT_EQ(r->occupied_updates, 1u);
  EXPECT_EQ(r->free_updates, 21u);
  EXPECT_EQ(voxel_rays.State({20, 1, 0}), VoxelState::kOccupied);
  for (int x = 0; x <= 10; ++x) EXPECT_EQ(voxel_rays.State({x, 0, 0}), VoxelState::kFree) << x;
  for (int x = 10; x <= 19; ++x) EXPECT_EQ(voxel_rays.State({x, 1, 0}), VoxelState::kFree) << x;
  EXPECT_EQ(voxel_rays.CountKnownVoxels(), 22u);
  for (int x = 7; x <= 9; ++x) {
    EXPECT_EQ(voxel_rays.State({x, 1, 0}), VoxelState::kUnknown) << x;
    EXPECT_EQ(per_point.State({x, 1, 0}), VoxelState::kFree) << x;
  }
  // OctoMap's discretized insertion builds the same map, log-odds for log-odds.
  EXPECT_EQ(Contents(voxel_rays), OctomapContents(points, origin, kMaxRange, true));
}

TEST(IntegratorTest, EndVoxelRaysDecideMaxRangeByTheVoxelCentre) {
  // A return 0.0985 m away, within the 0.099 m max range, in voxel (20, 0, 0) whose centre is
  // 0.1 m away: as in OctoMap's discretized insertion it carves up to max range (voxels 0..19)
  // and marks nothing; per-point ray casting marks the voxel.
  IntegratorOptions o = Options(FreeSpaceCarving::kEndVoxelRays);
  o.max_range_m = 0.099;
  const Eigen::Vector3f origin(0.0025f, 0.0025f, 0.0025f);
  const std::vector<Eigen::Vector3f> points = {{0.1010f, 0.0025f, 0.0025f}};
  OccupancyGrid grid;
  const auto r = Integrator(o).IntegratePointCloud(points, origin.cast<double>(), grid);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->endpoints, 0u);
  EXPECT_EQ(r->beyond_max_range, 1u);
  EXPECT_EQ(r->occupied_updates, 0u);
  EXPECT_EQ(r->free_updates, 20u);
  EXPECT_EQ(grid.State({20, 0, 0}), VoxelState::kUnknown);
  EXPECT_EQ(grid.State({19, 0, 0}), VoxelState::kFree);
  EXPECT_EQ(Contents(grid), OctomapContents(points, origin, o.max_range_m, true));
  o.carving = FreeSpaceCarving::kRayCast;
  OccupancyGrid per_point;
  ASSERT_TRUE(Integrator(o).IntegratePointCloud(points, origin.cast<double>(), per_point).ok());
  EXPECT_EQ(per_point.State({20, 0, 0}), VoxelState::kOccupied);
}

TEST_F(IntegratorSceneTest, EndVoxelRaysMatchOctomapDiscretizedInsertion) {
  // Every pixel of two frames (OctoMap's discretized insertion casts one ray per voxel, so it is
  // fast enough for the whole image), image and cloud input, 1 and 2 threads. The fixture's eyes
  // lie on voxel corners, from where rays to voxel centres cross voxel edges exactly (ties, which
  // OctoMap breaks in float arithmetic and avp by axis order: 0.4 % of the voxels differ); a real
  // camera's eye is anywhere, so the eyes are moved off the lattice.
  const Eigen::Vector3d off_lattice(0.0013, 0.0007, 0.0011);
  OccupancyGrid from_cloud(DefaultMap().grid);
  SemanticMap from_image(DefaultMap()), two_threads(DefaultMap());
  octomap::OcTree tree = MakeOctree();
  const ThreadedIntegrator one(FreeSpaceCarving::kEndVoxelRays, 1);
  const ThreadedIntegrator two(FreeSpaceCarving::kEndVoxelRays, 2);
  size_t rays = 0, returns = 0;
  for (size_t p = 0; p < 2; ++p) {
    const RigidTransform X(Poses()[p].rotation(), Poses()[p].translation() + off_lattice);
    const sim::RenderedFrame f = Render(X);
    std::vector<Eigen::Vector3f> points;
    octomap::Pointcloud cloud;
    for (const Eigen::Vector3d& q : WorldPoints(f.rgbd)) {
      points.push_back(q.cast<float>());
      cloud.push_back(static_cast<float>(q.x()), static_cast<float>(q.y()),
                      static_cast<float>(q.z()));
    }
    const Eigen::Vector3d o = X.translation().cast<float>().cast<double>();
    const auto c = one.IntegratePointCloud(points, o, from_cloud);
    const auto i1 = one.Integrate(f.rgbd, nullptr, from_image);
    const auto i2 = two.Integrate(f.rgbd, nullptr, two_threads);
    ASSERT_TRUE(c.ok() && i1.ok() && i2.ok());
    EXPECT_GT(c->beyond_max_range, 0u);
    EXPECT_EQ(i1->free_updates, i2->free_updates);
    EXPECT_EQ(i1->occupied_updates, i2->occupied_updates);
    rays += c->occupied_updates;
    returns += c->endpoints;
    tree.insertPointCloud(cloud,
                          octomap::point3d(static_cast<float>(o.x()), static_cast<float>(o.y()),
                                           static_cast<float>(o.z())),
                          kMaxRange, /*lazy_eval=*/false, /*discretize=*/true);
  }
  EXPECT_GT(returns, rays) << "some voxels hold several returns";
  const Agreement a = Compare(from_cloud, tree);
  const double state = static_cast<double>(a.same_state) / a.union_size;
  const double exact = static_cast<double>(a.same_log_odds) / a.union_size;
  std::printf(
      "[ end-voxel rays vs OctoMap insertPointCloud(discretize) (2 frames): %zu voxels known to "
      "either (%zu only to us, %zu only to OctoMap), same state %.4f %%, same log-odds %.4f %% ]\n",
      a.union_size, a.only_ours, a.only_octomap, 100.0 * state, 100.0 * exact);
  EXPECT_GT(a.union_size, 100000u);
  EXPECT_GE(state, 0.999);
  EXPECT_GE(exact, 0.999);
  // Threads change nothing (image and cloud input give the same map when the cloud holds the
  // image's points exactly: PointCloudAndDepthImageGiveIdenticalMaps).
  const VoxelList image = Contents(from_image.grid());
  EXPECT_GT(image.size(), 100000u);
  EXPECT_EQ(image, Contents(two_threads.grid()));
}

TEST_F(IntegratorSceneTest, RayCastingMatchesOctomapInsertPointCloud) {
  OccupancyGrid ours(DefaultMap().grid);
  octomap::OcTree tree = MakeOctree();
  const Integrator integrator(Options());
  for (size_t p = 0; p < 2; ++p) {
    const RigidTransform X = Poses()[p];
    const sim::RenderedFrame f = Render(X);
    std::vector<Eigen::Vector3f> points;
    octomap::Pointcloud cloud;
    const std::vector<Eigen::Vector3d> all = WorldPoints(f.rgbd);
    for (size_t i = 0; i < all.size(); i += 3) {  // every third pixel: OctoMap is slow
      const Eigen::Vector3d& q = all[i];
      points.push_back(q.cast<float>());
      cloud.push_back(static_cast<float>(q.x()), static_cast<float>(q.y()),
                      static_cast<float>(q.z()));
    }
    const Eigen::Vector3f of = X.translation().cast<float>();
    const auto stats = integrator.IntegratePointCloud(points, of.cast<double>(), ours);
    ASSERT_TRUE(stats.ok()) << stats.status().ToString();
    EXPECT_GT(stats->beyond_max_range, 0u);
    tree.insertPointCloud(cloud, octomap::point3d(of.x(), of.y(), of.z()), kMaxRange);
  }
  const Agreement a = Compare(ours, tree);
  const double state = static_cast<double>(a.same_state) / a.union_size;
  const double exact = static_cast<double>(a.same_log_odds) / a.union_size;
  std::printf(
      "[ IntegratePointCloud vs OctoMap insertPointCloud (2 frames): %zu voxels known to "
      "either (%zu only to us, %zu only to OctoMap), same state %.4f %%, same log-odds %.4f %% ]\n",
      a.union_size, a.only_ours, a.only_octomap, 100.0 * state, 100.0 * exact);
  RecordProperty("octomap_state_agreement_percent", std::to_string(100.0 * state));
  EXPECT_GT(a.union_size, 100000u);
  EXPECT_GE(state, 0.999);
  EXPECT_GE(exact, 0.999);
}

TEST(IntegratorTest, PointCloudAndDepthImageGiveIdenticalMaps) {
  // Intrinsics, pose and depths chosen so that every back-projected point is exactly a float:
  // fx = fy = 128, an axis-permutation rotation, dyadic depths and translation.
  CameraIntrinsics K;
  K.width = 160;
  K.height = 120;
  K.fx = K.fy = 128.0;
  K.cx = 79.5;
  K.cy = 59.5;
  Eigen::Matrix3d R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;  // optical z along world +x
  RgbdFrame f;
  f.K = K;
  f.X_WC = RigidTransform(R, Eigen::Vector3d(0.125, -0.0625, 0.25));
  f.rgb = ImageRgb8(160, 120);
  f.depth_m = DepthImage(160, 120);
  for (int v = 0; v < 120; ++v) {
    for (int u = 0; u < 160; ++u) {
      float d = 0.5f + static_cast<float>(u % 7) / 64.0f + static_cast<float>(v % 5) / 128.0f;
      if ((u / 16 + v / 16) % 5 == 0) d = 1.25f;  // beyond max range
      if ((u * 7 + v * 3) % 97 == 0) d = 0.0f;    // no return
      f.depth_m.at(u, v) = d;
    }
  }
  std::vector<Eigen::Vector3f> points;
  for (const Eigen::Vector3d& q : WorldPoints(f)) {
    points.push_back(q.cast<float>());
    ASSERT_EQ(points.back().cast<double>(), q) << "not exact in float";
  }
  for (const auto& [carving, threads] :
       {std::pair{FreeSpaceCarving::kRayCast, 1}, std::pair{FreeSpaceCarving::kRayCast, 2},
        std::pair{FreeSpaceCarving::kEndVoxelRays, 1},
        std::pair{FreeSpaceCarving::kEndVoxelRays, 2}}) {
    SCOPED_TRACE(fmt::format("{}, threads {}", ToString(carving), threads));
    const ThreadedIntegrator integrator(carving, threads);
    SemanticMap from_image(DefaultMap());
    OccupancyGrid from_cloud(DefaultMap().grid);
    for (int frame = 0; frame < 2; ++frame) {
      const auto a = integrator.Integrate(f, nullptr, from_image);
      const auto b = integrator.IntegratePointCloud(points, f.X_WC.translation(), from_cloud);
      ASSERT_TRUE(a.ok() && b.ok());
      EXPECT_EQ(a->endpoints, b->endpoints);
      EXPECT_EQ(a->beyond_max_range, b->beyond_max_range);
      EXPECT_EQ(a->occupied_updates, b->occupied_updates);
      EXPECT_EQ(a->free_updates, b->free_updates);
      EXPECT_EQ(a->invalid_depth, b->invalid_depth + (160u * 120u - points.size()));
      EXPECT_GT(a->beyond_max_range, 1000u);
    }
    const auto ca = Contents(from_image.grid());
    EXPECT_GT(ca.size(), 10000u);
    EXPECT_EQ(ca, Contents(from_cloud));
  }
}

TEST_F(IntegratorSceneTest, ThreadCountDoesNotChangeTheMap) {
  SemanticMap one(DefaultMap()), two(DefaultMap()), all(DefaultMap());
  const ThreadedIntegrator i1(FreeSpaceCarving::kRayCast, 1);
  const ThreadedIntegrator i2(FreeSpaceCarving::kRayCast, 2);
  const ThreadedIntegrator i0(FreeSpaceCarving::kRayCast, 0);
  for (const RigidTransform& X : Poses()) {
    const sim::RenderedFrame f = Render(X);
    const auto s1 = i1.Integrate(f.rgbd, nullptr, one);
    const auto s2 = i2.Integrate(f.rgbd, nullptr, two);
    const auto s0 = i0.Integrate(f.rgbd, nullptr, all);
    ASSERT_TRUE(s1.ok() && s2.ok() && s0.ok());
    EXPECT_EQ(s1->free_updates, s2->free_updates);
    EXPECT_EQ(s1->occupied_updates, s2->occupied_updates);
    EXPECT_EQ(s1->free_updates, s0->free_updates);
  }
  const auto c1 = Contents(one.grid());
  EXPECT_GT(c1.size(), 100000u);
  EXPECT_EQ(c1, Contents(two.grid()));  // float ==: bit-identical log-odds of every voxel
  EXPECT_EQ(c1, Contents(all.grid()));
  // The parallel path may allocate blocks no voxel reached; once released, the layouts agree.
  two.grid().ReleaseEmptyBlocks();
  EXPECT_EQ(one.grid().ReleaseEmptyBlocks(), 0u);
  EXPECT_EQ(one.grid().num_blocks(), two.grid().num_blocks());
}

TEST_F(IntegratorSceneTest, ThreadCountDoesNotChangeTheMapFile) {
  // `avp map build --threads 1` and `--threads 2` must write the same bytes: the parallel path
  // allocates blocks in another order and some that no voxel reaches (issue 15).
  for (const FreeSpaceCarving carving :
       {FreeSpaceCarving::kRayCast, FreeSpaceCarving::kProjective}) {
    SemanticMap one(DefaultMap()), two(DefaultMap()), four(DefaultMap());
    const ThreadedIntegrator i1(carving, 1);
    const ThreadedIntegrator i2(carving, 2);
    const ThreadedIntegrator i4(carving, 4);
    for (const RigidTransform& X : Poses()) {
      const sim::RenderedFrame f = Render(X);
      ASSERT_TRUE(i1.Integrate(f.rgbd, nullptr, one).ok());
      ASSERT_TRUE(i2.Integrate(f.rgbd, nullptr, two).ok());
      ASSERT_TRUE(i4.Integrate(f.rgbd, nullptr, four).ok());
    }
    const Result<std::vector<uint8_t>> b1 = SerializeMap(one);
    const Result<std::vector<uint8_t>> b2 = SerializeMap(two);
    const Result<std::vector<uint8_t>> b4 = SerializeMap(four);
    ASSERT_TRUE(b1.ok() && b2.ok() && b4.ok());
    EXPECT_GT(b1->size(), 100000u);
    EXPECT_TRUE(*b1 == *b2) << ToString(carving) << ": " << b1->size() << " vs " << b2->size()
                            << " bytes";
    EXPECT_TRUE(*b1 == *b4) << ToString(carving);
    // The file holds no empty block, and loading it gives the same bytes again.
    MapFileInfo info;
    Result<SemanticMap> loaded = DeserializeMap(*b2, &info);
    ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
    EXPECT_EQ(loaded->grid().ReleaseEmptyBlocks(), 0u);
    EXPECT_EQ(info.num_blocks, loaded->grid().num_blocks());
    EXPECT_TRUE(*SerializeMap(*loaded) == *b1);
  }
}

/// How deep (metres from the nearest face) any pixel ray of `f` gets inside voxel k before the
/// ray's end point, excluding rays that end in k; <= 0 when none enters it. Rays that only graze
/// a face, an edge or a corner (ties between the two carving methods) stay within ~1e-7 m.
double DeepestCrossing(const RgbdFrame& f, double max_range, const VoxelKey& k) {
  const Eigen::Vector3d o = f.X_WC.translation();
  const Eigen::Vector3d lo = Eigen::Vector3d(k.x, k.y, k.z) * kVoxel;
  const Eigen::Vector3d hi = lo + Eigen::Vector3d::Constant(kVoxel);
  double best = -1.0;
  for (int v = 0; v < f.depth_m.height(); ++v) {
    for (int u = 0; u < f.depth_m.width(); ++u) {
      const float d = f.depth_m.at(u, v);
      if (!(std::isfinite(d) && d > 0.0f)) continue;
      const Eigen::Vector3d dir =
          f.X_WC.rotation() * Eigen::Vector3d((u - f.K.cx) / f.K.fx, (v - f.K.cy) / f.K.fy, 1.0);
      const Eigen::Vector3d p = o + dir * static_cast<double>(d);
      const double range = (p - o).norm();
      const double t_end = range > max_range ? d * max_range / range : d;
      if (VoxelKey::FromPoint(o + dir * t_end, kVoxel) == k) continue;
      double t0 = 0.0, t1 = t_end;
      for (int a = 0; a < 3; ++a) {
        if (dir[a] == 0.0) {
          if (o[a] < lo[a] || o[a] > hi[a]) t1 = -1.0;
          continue;
        }
        double ta = (lo[a] - o[a]) / dir[a], tb = (hi[a] - o[a]) / dir[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
      }
      if (t1 < t0) continue;
      for (int i = 0; i <= 16; ++i) {
        const Eigen::Vector3d q = o + dir * (t0 + (t1 - t0) * i / 16.0);
        best = std::max(best, (q - lo).cwiseMin(hi - q).minCoeff());
      }
    }
  }
  return best;
}

struct CarvingDifference {
  size_t compared = 0;     ///< voxels known to either map
  size_t differences = 0;  ///< known to one only, or different log-odds
  size_t non_ties = 0;     ///< differences where some ray really passes through the voxel
  std::string first_non_tie;
};

/// Ray casting and projective carving of one frame into fresh maps: every difference must be a
/// tie (no ray passes more than 1 um inside the voxel).
CarvingDifference CompareCarving(const RgbdFrame& f, int threads = 1) {
  SemanticMap rc(DefaultMap()), pj(DefaultMap());
  EXPECT_TRUE(
      ThreadedIntegrator(FreeSpaceCarving::kRayCast, threads).Integrate(f, nullptr, rc).ok());
  const auto sp =
      ThreadedIntegrator(FreeSpaceCarving::kProjective, threads).Integrate(f, nullptr, pj);
  EXPECT_TRUE(sp.ok()) << sp.status().ToString();
  const VoxelList a = Contents(rc.grid()), b = Contents(pj.grid());
  CarvingDifference out;
  size_t i = 0, j = 0;
  const auto differ = [&](const VoxelKey& k, bool carved_by_raycast) {
    ++out.differences;
    const double depth = DeepestCrossing(f, kMaxRange, k);
    if (depth > 1e-6) {
      ++out.non_ties;
      if (out.first_non_tie.empty()) {
        const Eigen::Vector3d c = f.X_WC.inverse() * k.Center(kVoxel);
        std::ostringstream os;
        os << "voxel (" << k.x << ", " << k.y << ", " << k.z << ") "
           << (carved_by_raycast ? "carved by ray casting only" : "carved by projection only")
           << ", a ray passes " << depth << " m inside it, centre in the camera frame ("
           << c.transpose() << ") projects to pixel (" << f.K.fx * c.x() / c.z() + f.K.cx << ", "
           << f.K.fy * c.y() / c.z() + f.K.cy << ")";
        out.first_non_tie = os.str();
      }
    }
  };
  while (i < a.size() || j < b.size()) {
    ++out.compared;
    if (j == b.size() || (i < a.size() && a[i].first < b[j].first)) {
      differ(a[i++].first, true);
    } else if (i == a.size() || b[j].first < a[i].first) {
      differ(b[j++].first, false);
    } else {
      if (a[i].second != b[j].second) differ(a[i].first, a[i].second < b[j].second);
      ++i;
      ++j;
    }
  }
  return out;
}

TEST_F(IntegratorSceneTest, ProjectiveCarvingEqualsRayCastingUpToTies) {
  for (size_t p = 0; p < 2; ++p) {
    SCOPED_TRACE("pose " + std::to_string(p));
    const sim::RenderedFrame f = Render(Poses()[p]);
    const CarvingDifference d = CompareCarving(f.rgbd, p == 0 ? 1 : 2);
    std::printf(
        "[ projective vs ray-cast carving, pose %zu: %zu voxels, %zu differ, %zu not on a "
        "tie ]\n",
        p, d.compared, d.differences, d.non_ties);
    EXPECT_GT(d.compared, 100000u);
    EXPECT_EQ(d.non_ties, 0u) << d.first_non_tie;
    EXPECT_LE(d.differences, d.compared / 10000);
  }
  // Endpoints are the same in all three modes; kNone carves nothing.
  const sim::RenderedFrame f = Render(Poses()[0]);
  SemanticMap rc(DefaultMap()), pj(DefaultMap()), none(DefaultMap());
  ASSERT_TRUE(Integrator(Options(FreeSpaceCarving::kRayCast)).Integrate(f.rgbd, nullptr, rc).ok());
  const auto sp = Integrator(Options(FreeSpaceCarving::kProjective)).Integrate(f.rgbd, nullptr, pj);
  const auto sn = Integrator(Options(FreeSpaceCarving::kNone)).Integrate(f.rgbd, nullptr, none);
  ASSERT_TRUE(sp.ok() && sn.ok());
  const auto occupied = [](const OccupancyGrid& g) {
    VoxelList out;
    for (const auto& e : Contents(g)) {
      if (e.second >= 0.0f) out.push_back(e);
    }
    return out;
  };
  const VoxelList occ = occupied(rc.grid());
  EXPECT_GT(occ.size(), 1000u);
  EXPECT_EQ(occupied(pj.grid()), occ);
  EXPECT_EQ(Contents(none.grid()), occ);  // nothing but the endpoints
  EXPECT_EQ(sn->free_updates, 0u);
  EXPECT_EQ(none.grid().CountKnownVoxels(), none.grid().CountOccupiedVoxels());
  EXPECT_EQ(sp->free_updates, pj.grid().CountKnownVoxels() - pj.grid().CountOccupiedVoxels());
  EXPECT_EQ(sp->occupied_updates, occ.size());
}

TEST_F(IntegratorSceneTest, ProjectiveCarvingEqualsRayCastingWithAWideFieldOfView) {
  // A 130 deg (horizontal) camera close to the wall: voxels just outside the near sphere at the
  // image border project far off-centre, where a voxel's footprint is stretched by ~1/cos^2 of
  // the off-axis angle. Poses are off the voxel lattice, so exact ties are rare.
  const CameraIntrinsics K = CameraIntrinsics::FromHorizontalFov(64, 48, 130.0, 0.01, 3.0);
  const Eigen::Vector3d jitter(0.00123, -0.00071, 0.00037);
  const std::vector<RigidTransform> poses = {
      RigidTransform::LookAt(Eigen::Vector3d(0.55, -0.2, 0.0) + jitter, {0.7, -0.25, 0.05}),
      RigidTransform::LookAt(Eigen::Vector3d(0.60, -0.3, 0.1) + jitter, {0.7, -0.1, -0.1}),
      RigidTransform::LookAt(Eigen::Vector3d(0.38, 0.03, -0.02) + jitter, {0.45, 0.031, -0.022})};
  for (size_t p = 0; p < poses.size(); ++p) {
    SCOPED_TRACE("wide pose " + std::to_string(p));
    const sim::RenderedFrame f = renderer_->Render(K, poses[p]);
    const CarvingDifference d = CompareCarving(f.rgbd);
    std::printf(
        "[ projective vs ray-cast carving, 130 deg camera, pose %zu: %zu voxels, %zu "
        "differ, %zu not on a tie ]\n",
        p, d.compared, d.differences, d.non_ties);
    EXPECT_EQ(d.non_ties, 0u) << d.first_non_tie;
  }
  // Beyond 150 deg (diagonal) projective carving refuses the frame.
  const CameraIntrinsics fisheye = CameraIntrinsics::FromHorizontalFov(64, 48, 160.0, 0.01, 3.0);
  SemanticMap map(DefaultMap());
  const auto r = Integrator(Options(FreeSpaceCarving::kProjective))
                     .Integrate(renderer_->Render(fisheye, poses[0]).rgbd, nullptr, map);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("field of view"));
  EXPECT_EQ(map.grid().num_blocks(), 0u);
}

TEST_F(IntegratorSceneTest, RoiRejectsEndpointsOutsideIt) {
  GridOptions g = DefaultMap().grid;
  g.roi = Box3(Eigen::Vector3d(0.0, -0.3, -0.3), Eigen::Vector3d(0.6, 0.3, 0.3));  // no wall
  MapOptions m = DefaultMap();
  m.grid = g;
  SemanticMap map(m);
  const sim::RenderedFrame f = Render(Poses()[0]);
  const auto s = ThreadedIntegrator(FreeSpaceCarving::kRayCast, 1).Integrate(f.rgbd, nullptr, map);
  ASSERT_TRUE(s.ok());
  // Every endpoint on the wall (x = 0.7012) is rejected; those on the sphere are kept.
  size_t wall_points = 0;
  const Eigen::Vector3d o = Poses()[0].translation();
  for (const Eigen::Vector3d& q : WorldPoints(f.rgbd)) {
    if ((q - o).norm() > kMaxRange) continue;
    wall_points += !g.roi->Contains(map.grid().CenterOf(map.grid().KeyOf(q)));
  }
  EXPECT_GT(wall_points, 1000u);
  EXPECT_EQ(s->rejected_points, wall_points);
  map.grid().ForEachKnownVoxel(
      [&](const VoxelKey& k, float) { EXPECT_TRUE(g.roi->Contains(map.grid().CenterOf(k))); });
  EXPECT_GT(map.grid().CountOccupiedVoxels(), 150u);
  // The parallel path honours the ROI the same way.
  SemanticMap parallel(m);
  const auto s2 =
      ThreadedIntegrator(FreeSpaceCarving::kRayCast, 2).Integrate(f.rgbd, nullptr, parallel);
  ASSERT_TRUE(s2.ok());
  EXPECT_EQ(s2->rejected_points, s->rejected_points);
  EXPECT_EQ(s2->free_updates, s->free_updates);
  EXPECT_EQ(Contents(parallel.grid()), Contents(map.grid()));
}

TEST_F(IntegratorSceneTest, ClipBoxUpdatesOnlyTheBoxAndEqualsTheWholeFrameInside) {
  // The sphere's region, not the wall: what fusion during motion does with the planning ROI.
  const Box3 box(Eigen::Vector3d(0.0, -0.3, -0.3), Eigen::Vector3d(0.6, 0.3, 0.3));
  // A camera off the voxel lattice (Poses()[0] stands on a voxel corner, where rays to voxel
  // centres run through edges: a walk started elsewhere on the line may break those ties the
  // other way, for ~0.1 % of the voxels).
  const sim::RenderedFrame f =
      Render(RigidTransform::LookAt({0.0213, -0.0117, 0.0161}, {1.0, 0.05, -0.03}));
  for (const FreeSpaceCarving carving :
       {FreeSpaceCarving::kRayCast, FreeSpaceCarving::kEndVoxelRays}) {
    SCOPED_TRACE(std::string(ToString(carving)));
    SemanticMap whole(DefaultMap()), clipped(DefaultMap());
    ASSERT_TRUE(Integrator(Options(carving)).Integrate(f.rgbd, nullptr, whole).ok());
    IntegratorOptions o = Options(carving);
    o.clip_box = box;
    const auto s = Integrator(o).Integrate(f.rgbd, nullptr, clipped);
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    // Nothing outside the box (its entry voxels straddle the boundary: half a voxel of slack);
    // every return on the wall is dropped.
    const Box3 slack = box.Inflated(0.5 * kVoxel + 1e-9);
    clipped.grid().ForEachKnownVoxel([&](const VoxelKey& k, float) {
      EXPECT_TRUE(slack.Contains(k.Center(kVoxel))) << k.Center(kVoxel).transpose();
    });
    EXPECT_GT(s->rejected_points, 1000u);
    // Inside, away from the boundary, the same log-odds voxel for voxel (the walk from where a
    // ray enters visits the voxels the whole walk visits there).
    const Box3 interior = box.Inflated(-1.5 * kVoxel);
    const auto inside = [&](const OccupancyGrid& g) {
      VoxelList out;
      for (const auto& [k, v] : Contents(g)) {
        if (interior.Contains(k.Center(kVoxel))) out.emplace_back(k, v);
      }
      return out;
    };
    const VoxelList a = inside(whole.grid()), b = inside(clipped.grid());
    EXPECT_GT(a.size(), 20000u);
    EXPECT_EQ(a, b);
  }
  // Bad boxes are named.
  IntegratorOptions bad = Options(FreeSpaceCarving::kEndVoxelRays);
  bad.clip_box = Box3();  // empty
  EXPECT_NE(bad.Validate().message().find("clip_box"), std::string::npos);
}

TEST_F(IntegratorSceneTest, PixelStrideFusesTheSubsampledImage) {
  // Every 2nd pixel of every 2nd row equals fusing the subsampled image with K halved (pixel
  // centres at integer coordinates: pixel i of the half image is pixel 2i of the whole).
  const sim::RenderedFrame f = Render(Poses()[1]);
  RgbdFrame half = f.rgbd;
  const int w = (f.rgbd.depth_m.width() + 1) / 2, h = (f.rgbd.depth_m.height() + 1) / 2;
  half.depth_m = DepthImage(w, h, 0.0f);
  half.rgb = ImageRgb8(w, h, 0);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) half.depth_m.at(u, v) = f.rgbd.depth_m.at(2 * u, 2 * v);
  }
  half.K.width = w;
  half.K.height = h;
  half.K.fx /= 2.0;
  half.K.fy /= 2.0;
  half.K.cx /= 2.0;
  half.K.cy /= 2.0;
  for (const FreeSpaceCarving carving :
       {FreeSpaceCarving::kRayCast, FreeSpaceCarving::kEndVoxelRays}) {
    SCOPED_TRACE(std::string(ToString(carving)));
    IntegratorOptions o = Options(carving);
    o.pixel_stride = 2;
    SemanticMap strided(DefaultMap()), reference(DefaultMap());
    const auto s = Integrator(o).Integrate(f.rgbd, nullptr, strided);
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    ASSERT_TRUE(Integrator(Options(carving)).Integrate(half, nullptr, reference).ok());
    EXPECT_EQ(s->pixels, static_cast<size_t>(w) * static_cast<size_t>(h));
    EXPECT_GT(strided.grid().CountOccupiedVoxels(), 500u);
    EXPECT_EQ(Contents(strided.grid()), Contents(reference.grid()));
  }
  IntegratorOptions projective = Options(FreeSpaceCarving::kProjective);
  projective.pixel_stride = 2;
  EXPECT_NE(projective.Validate().message().find("pixel_stride"), std::string::npos);
}

// ---- Semantics ---------------------------------------------------------------------------------

TEST_F(IntegratorSceneTest, FruitMasksLabelVoxelsOnTheFruitOnly) {
  const AnalyticScene& sc = *scene_;
  SemanticMap map(DefaultMap());
  SemanticMap plain(DefaultMap());
  const Integrator integrator(Options());
  size_t labelled_total = 0;
  for (size_t p = 0; p < 2; ++p) {
    const RigidTransform X = Poses()[p];
    const sim::RenderedFrame f = Render(X);
    const Segmentation seg = Segmentation::FromLabelImages(f.instance_ids, f.class_ids, 0.9f);
    ASSERT_EQ(seg.instances.size(), 1u);  // the fruit; wall and far wall are not fruit
    size_t mask_in_range = 0;
    for (int v = 0; v < kHeight; ++v) {
      for (int u = 0; u < kWidth; ++u) {
        if (seg.instances[0].mask.at(u, v) == 0) continue;
        const float d = f.rgbd.depth_m.at(u, v);
        if (!(std::isfinite(d) && d > 0.0f)) continue;
        const Eigen::Vector3d q = X * f.rgbd.K.BackProject(Eigen::Vector2d(u, v), d);
        mask_in_range += (q - X.translation()).norm() <= kMaxRange;
      }
    }
    ASSERT_GT(mask_in_range, 200u);
    const auto s = integrator.Integrate(f.rgbd, &seg, map);
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    EXPECT_EQ(s->masked_endpoints, mask_in_range);
    EXPECT_GT(s->semantics.observations, 0u);
    const auto sp = integrator.Integrate(f.rgbd, nullptr, plain);
    ASSERT_TRUE(sp.ok());
    EXPECT_EQ(sp->masked_endpoints, 0u);
    // Semantics do not change occupancy.
    EXPECT_EQ(Contents(map.grid()), Contents(plain.grid()));
  }
  map.grid().ForEachSemanticVoxel([&](const VoxelKey& k, const SemanticCell& c) {
    ++labelled_total;
    const Eigen::Vector3d centre = k.Center(kVoxel);
    EXPECT_EQ(c.cls(), SemanticClass::kFruit);
    EXPECT_LE(std::abs((centre - sc.sphere_c).norm() - sc.sphere_r), kHalfDiagonal + kEps)
        << centre.transpose();
    EXPECT_GT(AnalyticScene::BoxSurfaceDistance(centre, sc.wall), 0.05);  // not on the wall
  });
  EXPECT_GT(labelled_total, 100u);
  EXPECT_EQ(plain.grid().CountSemanticVoxels(), 0u);
  EXPECT_EQ(plain.grid().num_semantic_blocks(), 0u);
}

}  // namespace
}  // namespace avp::mapping

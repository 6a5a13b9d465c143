#include <cmath>
#include <optional>
#include <set>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/sim/rgbd_renderer.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;

// ---- Scene helpers ---------------------------------------------------------------------------

/// A planar quad a-b-c-d (counter-clockwise) as two triangles.
TriangleMesh Quad(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                  const Eigen::Vector3d& d) {
  TriangleMesh m;
  m.vertices = {a.cast<float>(), b.cast<float>(), c.cast<float>(), d.cast<float>()};
  m.triangles = {Eigen::Vector3i(0, 1, 2), Eigen::Vector3i(0, 2, 3)};
  return m;
}

SceneObject MeshObject(std::string name, SemanticClass cls, TriangleMesh mesh,
                       Eigen::Vector3f albedo = Eigen::Vector3f(0.2f, 0.6f, 0.2f)) {
  SceneObject o;
  o.name = std::move(name);
  o.semantic_class = cls;
  o.albedo = albedo;
  o.shape = std::move(mesh);
  return o;
}

SceneObject SphereObject(std::string name, const Eigen::Vector3d& centre, double radius,
                         const Eigen::Matrix3d& R = Eigen::Matrix3d::Identity()) {
  SceneObject o;
  o.name = std::move(name);
  o.semantic_class = SemanticClass::kFruit;
  o.albedo = Eigen::Vector3f(0.8f, 0.1f, 0.05f);
  Ellipsoid e;
  e.center_W = centre;
  e.radii = Eigen::Vector3d::Constant(radius);
  e.R_WE = R;
  o.shape = e;
  return o;
}

/// A small plant-like scene: a tessellated ground, a stem, leaves, fruits.
Scene SmallPlant() {
  Scene scene;
  scene.name = "small-plant";
  TriangleMesh ground;
  const int n = 20;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      ground.vertices.emplace_back(-1.0f + 2.0f * i / n, -1.0f + 2.0f * j / n, 0.0f);
    }
  }
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i;
      ground.triangles.emplace_back(a, a + 1, a + n + 2);
      ground.triangles.emplace_back(a, a + n + 2, a + n + 1);
    }
  }
  scene.Add(MeshObject("ground", SemanticClass::kGround, ground, {0.4f, 0.3f, 0.2f}));
  // Stem: a thin square prism.
  TriangleMesh stem;
  const float r = 0.006f;
  for (int k = 0; k < 2; ++k) {
    const float z = k * 0.8f;
    stem.vertices.emplace_back(-r, -r, z);
    stem.vertices.emplace_back(r, -r, z);
    stem.vertices.emplace_back(r, r, z);
    stem.vertices.emplace_back(-r, r, z);
  }
  for (int s = 0; s < 4; ++s) {
    const int a = s;
    const int b = (s + 1) % 4;
    stem.triangles.emplace_back(a, b, b + 4);
    stem.triangles.emplace_back(a, b + 4, a + 4);
  }
  scene.Add(MeshObject("stem", SemanticClass::kStem, stem, {0.3f, 0.5f, 0.2f}));
  Rng rng(7);
  for (int i = 0; i < 12; ++i) {
    const double z = 0.15 + 0.05 * i;
    const double angle = 2.4 * i;
    const Eigen::Vector3d dir(std::cos(angle), std::sin(angle), 0.0);
    const Eigen::Vector3d side(-dir.y(), dir.x(), 0.0);
    const Eigen::Vector3d base = Eigen::Vector3d(0, 0, z);
    const Eigen::Vector3d tip = base + 0.12 * dir + Eigen::Vector3d(0, 0, rng.Uniform(-0.03, 0.03));
    TriangleMesh leaf;
    // A fan of 8 triangles, slightly curled.
    leaf.vertices.push_back(base.cast<float>());
    for (int k = 0; k <= 8; ++k) {
      const double t = k / 8.0;
      const Eigen::Vector3d p = base + t * (tip - base) +
                                0.04 * std::sin(M_PI * t) * (k % 2 ? side : -side) +
                                Eigen::Vector3d(0, 0, 0.01 * std::sin(M_PI * t));
      leaf.vertices.push_back(p.cast<float>());
    }
    for (int k = 1; k <= 8; ++k) leaf.triangles.emplace_back(0, k, k + 1);
    scene.Add(MeshObject("leaf" + std::to_string(i), SemanticClass::kLeaf, leaf));
  }
  for (int i = 0; i < 4; ++i) {
    const double angle = 1.3 + 1.7 * i;
    scene.Add(SphereObject(
        "fruit" + std::to_string(i),
        Eigen::Vector3d(0.08 * std::cos(angle), 0.08 * std::sin(angle), 0.25 + 0.1 * i),
        0.025 + 0.003 * i));
  }
  scene.UpdatePlantBounds();
  return scene;
}

CameraIntrinsics SmallCamera(double min_depth = 0.1, double max_depth = 3.0) {
  return CameraIntrinsics::FromHorizontalFov(160, 120, 60.0, min_depth, max_depth);
}

// ---- Analytic references (double precision) --------------------------------------------------

Eigen::Vector3d PixelRayW(const CameraIntrinsics& K, const RigidTransform& X_WC, int u, int v) {
  return X_WC.rotation() * K.RayDirection(Eigen::Vector2d(u, v));  // z = 1 in the optical frame
}

struct SphereRayResult {
  std::optional<double> t;  ///< smallest t >= 0 (the z-depth, as the direction has z_C = 1)
  double margin_m = 0.0;    ///< radius minus the distance from the centre to the ray's line
};

SphereRayResult RaySphere(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                          const Eigen::Vector3d& c, double r) {
  SphereRayResult res;
  const Eigen::Vector3d oc = o - c;
  const double a = d.squaredNorm();
  const double b = oc.dot(d);
  const Eigen::Vector3d perp = oc - (b / a) * d;
  res.margin_m = r - perp.norm();
  if (res.margin_m < 0.0) return res;
  const double half_chord = std::sqrt(r * r - perp.squaredNorm());
  const double t_mid = -b / a;
  const double dt = half_chord / std::sqrt(a);
  if (t_mid - dt >= 0.0) {
    res.t = t_mid - dt;
  } else if (t_mid + dt >= 0.0) {
    res.t = t_mid + dt;
  }
  return res;
}

int CountIf(const InstanceImage& img, uint16_t id) {
  int n = 0;
  for (uint16_t x : img.data()) n += x == id;
  return n;
}

// ---- Geometry: depth and labels against analytic ground truth --------------------------------

// The label of a pixel is the sphere iff its ray hits the analytic sphere. Float rounding of the
// ray (Embree traces float rays) can flip pixels whose ray grazes the silhouette: we allow at most
// 2 such pixels per image, and only where the analytic ray passes within 1e-6 m of the silhouette.
constexpr int kMaxBoundaryMismatches = 2;
constexpr double kBoundaryBandM = 1e-6;

TEST(RgbdRendererTest, SphereDepthMatchesAnalyticZDepthAtSeveralPoses) {
  const Eigen::Vector3d c(0.3, -0.1, 0.9);
  const double r = 0.04;
  Scene scene;
  // A rotated frame must not matter for equal radii.
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const uint16_t id = scene.Add(SphereObject("fruit", c, r, R));
  const RgbdRenderer renderer(scene);
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();

  const std::vector<RigidTransform> poses = {
      RigidTransform::LookAt(c + Eigen::Vector3d(-0.5, 0, 0), c),
      RigidTransform::LookAt(c + Eigen::Vector3d(0.2, -0.25, 0.1),
                             c + Eigen::Vector3d(0.01, 0.02, 0)),
      RigidTransform::LookAt(c + Eigen::Vector3d(-0.9, 0.7, 0.5), c + Eigen::Vector3d(0, 0.1, 0)),
      RigidTransform::LookAt(c + Eigen::Vector3d(0.06, 0.03, -0.13), c),  // close: 0.106 m
  };
  for (size_t p = 0; p < poses.size(); ++p) {
    SCOPED_TRACE("pose " + std::to_string(p));
    const RigidTransform& X_WC = poses[p];
    const RenderedFrame f = renderer.Render(K, X_WC);
    int hits = 0;
    int mismatches = 0;
    double max_err = 0.0;
    for (int v = 0; v < K.height; ++v) {
      for (int u = 0; u < K.width; ++u) {
        const SphereRayResult ref = RaySphere(X_WC.translation(), PixelRayW(K, X_WC, u, v), c, r);
        const bool ref_hit = ref.t.has_value();
        const bool got_hit = f.instance_ids(u, v) == id;
        if (ref_hit != got_hit) {
          ++mismatches;
          EXPECT_LT(std::abs(ref.margin_m), kBoundaryBandM) << "u=" << u << " v=" << v;
          continue;
        }
        if (!ref_hit) {
          EXPECT_EQ(f.rgbd.depth_m(u, v), 0.0f);
          continue;
        }
        ++hits;
        EXPECT_EQ(f.class_ids(u, v), static_cast<uint8_t>(SemanticClass::kFruit));
        const double err = std::abs(f.rgbd.depth_m(u, v) - *ref.t);
        max_err = std::max(max_err, err);
        ASSERT_LE(err, 1e-4) << "u=" << u << " v=" << v << " ref=" << *ref.t;
      }
    }
    EXPECT_GT(hits, 1000);
    EXPECT_LE(mismatches, kMaxBoundaryMismatches);
    // Float rays, double intersection: the error is float rounding of the ray, ~1e-7 relative.
    EXPECT_LT(max_err, 1e-5);
  }
}

TEST(RgbdRendererTest, RotatedEllipsoidDepthMatchesAnalytic) {
  Scene scene;
  SceneObject o = SphereObject("ellipsoid", Eigen::Vector3d(0.0, 0.0, 0.5), 1.0);
  Ellipsoid& e = std::get<Ellipsoid>(o.shape);
  e.radii = Eigen::Vector3d(0.05, 0.03, 0.02);
  e.R_WE = Eigen::AngleAxisd(0.5, Eigen::Vector3d(0.3, -1, 0.2).normalized()).toRotationMatrix();
  const Ellipsoid ell = e;
  const uint16_t id = scene.Add(o);
  const RgbdRenderer renderer(scene);
  const CameraIntrinsics K = SmallCamera();
  const RigidTransform X_WC = RigidTransform::LookAt(Eigen::Vector3d(0.1, -0.15, 0.3), ell.center_W,
                                                     Eigen::Vector3d::UnitX());
  const RenderedFrame f = renderer.Render(K, X_WC);
  // Reference: the ray in the ellipsoid's unit-sphere frame.
  const Eigen::Matrix3d A = ell.radii.cwiseInverse().asDiagonal() * ell.R_WE.transpose();
  int hits = 0;
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      const Eigen::Vector3d o_unit = A * (X_WC.translation() - ell.center_W);
      const Eigen::Vector3d d_unit = A * PixelRayW(K, X_WC, u, v);
      const SphereRayResult ref = RaySphere(o_unit, d_unit, Eigen::Vector3d::Zero(), 1.0);
      if (ref.t.has_value() != (f.instance_ids(u, v) == id)) {
        EXPECT_LT(std::abs(ref.margin_m), 1e-5);
        continue;
      }
      if (!ref.t) continue;
      ++hits;
      EXPECT_NEAR(f.rgbd.depth_m(u, v), *ref.t, 1e-4) << u << "," << v;
    }
  }
  EXPECT_GT(hits, 200);
}

TEST(RgbdRendererTest, PlaneDepthMatchesAnalyticZDepth) {
  // A tilted 0.6 m x 0.4 m quad, seen obliquely.
  const Eigen::Vector3d centre(1.0, 0.2, 0.5);
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(0.6, Eigen::Vector3d(0.2, 1.0, 0.4).normalized()).toRotationMatrix();
  const Eigen::Vector3d ex = R.col(0) * 0.3;
  const Eigen::Vector3d ey = R.col(1) * 0.2;
  const Eigen::Vector3d n = R.col(2);
  Scene scene;
  const uint16_t id = scene.Add(
      MeshObject("plane", SemanticClass::kSupport,
                 Quad(centre - ex - ey, centre + ex - ey, centre + ex + ey, centre - ex + ey)));
  const RgbdRenderer renderer(scene);
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  for (const Eigen::Vector3d& eye :
       {Eigen::Vector3d(0.2, 0.1, 0.6), Eigen::Vector3d(0.6, -0.3, 0.9)}) {
    const RigidTransform X_WC = RigidTransform::LookAt(eye, centre);
    const RenderedFrame f = renderer.Render(K, X_WC);
    int hits = 0;
    int mismatches = 0;
    for (int v = 0; v < K.height; ++v) {
      for (int u = 0; u < K.width; ++u) {
        const Eigen::Vector3d d = PixelRayW(K, X_WC, u, v);
        const double t = n.dot(centre - eye) / n.dot(d);
        const Eigen::Vector3d local = R.transpose() * (eye + t * d - centre);
        // Distance inside the quad's border (negative outside).
        const double inside = std::min(0.3 - std::abs(local.x()), 0.2 - std::abs(local.y()));
        const bool ref_hit = t > 0 && inside >= 0.0;
        const bool got_hit = f.instance_ids(u, v) == id;
        if (ref_hit != got_hit) {
          ++mismatches;
          EXPECT_LT(std::abs(inside), 1e-6) << u << "," << v;
          continue;
        }
        if (!ref_hit) continue;
        ++hits;
        ASSERT_NEAR(f.rgbd.depth_m(u, v), t, 1e-4) << u << "," << v;
      }
    }
    EXPECT_GT(hits, 10000);
    EXPECT_LE(mismatches, kMaxBoundaryMismatches);
  }
}

TEST(RgbdRendererTest, SphereOccludesPlaneBehindIt) {
  Scene scene;
  const Eigen::Vector3d c(0.0, 0.0, 0.6);
  const double r = 0.05;
  const uint16_t wall = scene.Add(MeshObject(
      "wall", SemanticClass::kOther, Quad({-1, -1, 1.0}, {1, -1, 1.0}, {1, 1, 1.0}, {-1, 1, 1.0})));
  const uint16_t fruit = scene.Add(SphereObject("fruit", c, r));
  const RgbdRenderer renderer(scene);
  const CameraIntrinsics K = SmallCamera();
  // Camera at the origin looking along +z (world z = optical z).
  const RigidTransform X_WC = RigidTransform::Identity();
  const RenderedFrame f = renderer.Render(K, X_WC);
  int fruit_pixels = 0;
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      const SphereRayResult ref =
          RaySphere(Eigen::Vector3d::Zero(), PixelRayW(K, X_WC, u, v), c, r);
      if (ref.t) {
        ++fruit_pixels;
        EXPECT_EQ(f.instance_ids(u, v), fruit);
        EXPECT_NEAR(f.rgbd.depth_m(u, v), *ref.t, 1e-4);
        EXPECT_LT(f.rgbd.depth_m(u, v), 0.6f);
      } else if (std::abs(ref.margin_m) > kBoundaryBandM) {
        EXPECT_EQ(f.instance_ids(u, v), wall);
        EXPECT_NEAR(f.rgbd.depth_m(u, v), 1.0, 1e-6);  // fronto-parallel wall: z = 1 everywhere
      }
    }
  }
  EXPECT_GT(fruit_pixels, 100);
}

TEST(RgbdRendererTest, ReturnsOutsideTheDepthRangeAreNoReturn) {
  // A sphere straddling max_depth (centre at 1.05, r = 0.1, max 1.0) and, in front of a wall,
  // a sphere nearer than min_depth: it occludes the wall and reads as no return.
  Scene scene;
  const uint16_t far_fruit = scene.Add(SphereObject("far", Eigen::Vector3d(0.15, 0, 1.05), 0.1));
  scene.Add(SphereObject("near", Eigen::Vector3d(-0.04, 0, 0.2), 0.03));
  scene.Add(MeshObject("wall", SemanticClass::kOther,
                       Quad({-1, -1, 0.5}, {0, -1, 0.5}, {0, 1, 0.5}, {-1, 1, 0.5})));
  RendererOptions options;
  options.background_rgb = Eigen::Vector3f(0.0f, 0.0f, 1.0f);  // pure blue
  const RgbdRenderer renderer(scene, options);
  const CameraIntrinsics K = SmallCamera(/*min_depth=*/0.25, /*max_depth=*/1.0);
  const RigidTransform X_WC = RigidTransform::Identity();
  const RenderedFrame f = renderer.Render(K, X_WC);
  int gated_far = 0;
  int kept_far = 0;
  int gated_near = 0;
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      const float z = f.rgbd.depth_m(u, v);
      if (z != 0.0f) {
        EXPECT_GE(z, K.min_depth_m);
        EXPECT_LE(z, K.max_depth_m);
        EXPECT_NE(f.instance_ids(u, v), 0);
      } else {
        EXPECT_EQ(f.instance_ids(u, v), 0);
        EXPECT_EQ(f.class_ids(u, v), 0);
        EXPECT_EQ(f.rgbd.rgb(u, v, 0), 0);
        EXPECT_EQ(f.rgbd.rgb(u, v, 1), 0);
        EXPECT_EQ(f.rgbd.rgb(u, v, 2), 255);
      }
      const Eigen::Vector3d d = PixelRayW(K, X_WC, u, v);
      const SphereRayResult far = RaySphere(Eigen::Vector3d::Zero(), d, {0.15, 0, 1.05}, 0.1);
      const SphereRayResult near = RaySphere(Eigen::Vector3d::Zero(), d, {-0.04, 0, 0.2}, 0.03);
      if (near.t && std::abs(near.margin_m) > kBoundaryBandM) {
        EXPECT_EQ(z, 0.0f) << "a surface nearer than min_depth must occlude, not vanish";
        ++gated_near;
      } else if (far.t && std::abs(far.margin_m) > kBoundaryBandM && d.x() > 0.0) {
        if (*far.t > 1.0 + 1e-5) {
          EXPECT_EQ(z, 0.0f);
          ++gated_far;
        } else if (*far.t < 1.0 - 1e-5) {
          EXPECT_EQ(f.instance_ids(u, v), far_fruit);
          ++kept_far;
        }
      }
    }
  }
  EXPECT_GT(gated_far, 50);
  EXPECT_GT(kept_far, 50);
  EXPECT_GT(gated_near, 50);
}

TEST(RgbdRendererTest, InstanceAndClassIdsFollowTheScene) {
  const Scene scene = SmallPlant();
  const RgbdRenderer renderer(scene);
  EXPECT_EQ(renderer.num_triangles(), scene.num_triangles());
  EXPECT_EQ(renderer.num_ellipsoids(), 4u);
  const CameraIntrinsics K = CameraIntrinsics::FromHorizontalFov(320, 240, 70.0);
  const RigidTransform X_WC =
      RigidTransform::LookAt(Eigen::Vector3d(0.6, 0.2, 0.5), Eigen::Vector3d(0, 0, 0.35));
  const RenderedFrame f = renderer.Render(K, X_WC, 1234);
  EXPECT_EQ(f.rgbd.stamp_ns, 1234);
  EXPECT_EQ(f.rgbd.K, K);
  EXPECT_TRUE(f.rgbd.X_WC.IsNearlyEqualTo(X_WC, 1e-12, 1e-12));
  EXPECT_TRUE(f.rgbd.Validate().ok()) << f.rgbd.Validate().ToString();

  std::set<SemanticClass> classes_seen;
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      const uint16_t id = f.instance_ids(u, v);
      if (id == 0) {
        EXPECT_EQ(f.class_ids(u, v), 0);
        EXPECT_EQ(f.rgbd.depth_m(u, v), 0.0f);
        continue;
      }
      const SceneObject* o = scene.FindInstance(id);
      ASSERT_NE(o, nullptr) << id;
      EXPECT_EQ(f.class_ids(u, v), static_cast<uint8_t>(o->semantic_class));
      classes_seen.insert(o->semantic_class);
      // The hit point lies on (within rounding of) the labelled object's bounds.
      const Eigen::Vector3d p_W = X_WC * K.BackProject(Eigen::Vector2d(u, v), f.rgbd.depth_m(u, v));
      EXPECT_TRUE(o->Bounds().Inflated(1e-4).Contains(p_W)) << o->name << " " << p_W.transpose();
    }
  }
  EXPECT_EQ(classes_seen, (std::set<SemanticClass>{SemanticClass::kGround, SemanticClass::kStem,
                                                   SemanticClass::kLeaf, SemanticClass::kFruit}));
}

// ---- Shading --------------------------------------------------------------------------------

TEST(RgbdRendererTest, ShadingFollowsAlbedoAndIncidence) {
  Scene scene;
  // Left half: a wall facing the camera; right half: the same albedo tilted 70 degrees.
  const Eigen::Vector3f grey(0.5f, 0.5f, 0.5f);
  const uint16_t facing =
      scene.Add(MeshObject("facing", SemanticClass::kOther,
                           Quad({-1, -1, 1}, {-0.01, -1, 1}, {-0.01, 1, 1}, {-1, 1, 1}), grey));
  const double tilt = DegToRad(70);
  const Eigen::Vector3d ax(std::cos(tilt), 0, std::sin(tilt));
  const Eigen::Vector3d p0(0.01, 0, 1);
  const uint16_t tilted =
      scene.Add(MeshObject("tilted", SemanticClass::kOther,
                           Quad(p0 + Eigen::Vector3d(0, -1, 0), p0 + ax + Eigen::Vector3d(0, -1, 0),
                                p0 + ax + Eigen::Vector3d(0, 1, 0), p0 + Eigen::Vector3d(0, 1, 0)),
                           grey));
  const uint16_t red = scene.Add(SphereObject("fruit", Eigen::Vector3d(-0.2, 0.0, 0.7), 0.05));
  const RgbdRenderer renderer(scene);
  const CameraIntrinsics K = SmallCamera();
  const RenderedFrame f = renderer.Render(K, RigidTransform::Identity());
  double facing_sum = 0;
  double tilted_sum = 0;
  int facing_n = 0;
  int tilted_n = 0;
  std::set<int> facing_colours;
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      const auto px = f.rgbd.rgb.pixel(u, v);
      const uint16_t id = f.instance_ids(u, v);
      if (id == facing) {
        facing_sum += px[1];
        ++facing_n;
        facing_colours.insert(px[0] << 16 | px[1] << 8 | px[2]);
      } else if (id == tilted) {
        tilted_sum += px[1];
        ++tilted_n;
      } else if (id == red) {
        EXPECT_GT(px[0], 2 * px[1]) << "fruit albedo is red";
      }
    }
  }
  ASSERT_GT(facing_n, 100);
  ASSERT_GT(tilted_n, 100);
  EXPECT_GT(facing_sum / facing_n, 1.15 * tilted_sum / tilted_n) << "Lambert head-light";
  // Per-triangle tint: the two triangles of the facing quad differ slightly.
  EXPECT_GE(facing_colours.size(), 2u);
}

TEST(RgbdRendererTest, EmptySceneIsAllBackground) {
  const RgbdRenderer renderer{Scene{}};
  EXPECT_EQ(renderer.num_triangles(), 0u);
  const CameraIntrinsics K = SmallCamera();
  const RenderedFrame f = renderer.Render(K, RigidTransform::Identity());
  for (float z : f.rgbd.depth_m.data()) ASSERT_EQ(z, 0.0f);
  for (uint16_t id : f.instance_ids.data()) ASSERT_EQ(id, 0);
  // Default background (0.80, 0.86, 0.93) linear -> sRGB (231, 239, 247).
  EXPECT_EQ(f.rgbd.rgb(0, 0, 0), 231);
  EXPECT_EQ(f.rgbd.rgb(0, 0, 1), 239);
  EXPECT_EQ(f.rgbd.rgb(0, 0, 2), 247);
}

TEST(RgbdRendererTest, CameraInsideAFruitSeesItsInside) {
  Scene scene;
  const uint16_t id = scene.Add(SphereObject("fruit", Eigen::Vector3d(0, 0, 0), 0.5));
  const RgbdRenderer renderer(scene);
  const CameraIntrinsics K = SmallCamera();
  const RenderedFrame f = renderer.Render(K, RigidTransform::Identity());
  // Centre pixel (80, 60) is off-axis by half a pixel: z = 0.5 / |d| with d = ((u - cx)/fx, ...).
  const Eigen::Vector3d d = K.RayDirection(Eigen::Vector2d(80, 60));
  EXPECT_EQ(f.instance_ids(80, 60), id);
  EXPECT_NEAR(f.rgbd.depth_m(80, 60), 0.5 / d.norm(), 1e-6);
}

// ---- Errors ---------------------------------------------------------------------------------

TEST(RgbdRendererTest, BadIntrinsicsThrowNamingTheBadValue) {
  const RgbdRenderer renderer(SmallPlant());
  CameraIntrinsics K = SmallCamera();
  K.fx = -1.0;
  EXPECT_THAT([&] { (void)renderer.Render(K, RigidTransform::Identity()); },
              ::testing::ThrowsMessage<Error>(HasSubstr("fx (-1) must be > 0")));
  K = SmallCamera();
  K.width = 0;
  K.max_depth_m = 0.05;  // below min_depth
  EXPECT_THAT([&] { (void)renderer.Render(K, RigidTransform::Identity()); },
              ::testing::ThrowsMessage<Error>(::testing::AllOf(HasSubstr("width (0) must be > 0"),
                                                               HasSubstr("max_depth_m (0.05)"))));
  K = SmallCamera();
  K.width = 100000;
  K.height = 100000;
  EXPECT_THAT([&] { (void)renderer.Render(K, RigidTransform::Identity()); },
              ::testing::ThrowsMessage<Error>(HasSubstr("K.width = 100000")));
  const RigidTransform bad_pose(Eigen::Vector3d(std::nan(""), 0, 0));
  EXPECT_THROW((void)renderer.Render(SmallCamera(), bad_pose), Error);
}

TEST(RgbdRendererTest, BadSceneOrOptionsThrow) {
  Scene scene = SmallPlant();
  scene.objects[1].instance_id = scene.objects[0].instance_id;
  EXPECT_THAT([&] { RgbdRenderer r(scene); },
              ::testing::ThrowsMessage<Error>(HasSubstr("is used twice")));
  Scene sheared;
  SceneObject fruit = SphereObject("sheared-fruit", Eigen::Vector3d(0, 0, 1), 0.03);
  std::get<Ellipsoid>(fruit.shape).R_WE(0, 1) = 0.5;  // not a rotation
  sheared.Add(fruit);
  EXPECT_THAT([&] { RgbdRenderer r(sheared); },
              ::testing::ThrowsMessage<Error>(HasSubstr("object.name = sheared-fruit")));
  RendererOptions options;
  options.ray_packet_size = 3;
  EXPECT_THAT([&] { RgbdRenderer r(SmallPlant(), options); },
              ::testing::ThrowsMessage<Error>(HasSubstr("options.ray_packet_size = 3")));
}

// ---- Determinism, threads, packets -----------------------------------------------------------

void ExpectIdentical(const RenderedFrame& a, const RenderedFrame& b) {
  EXPECT_TRUE(a.rgbd.depth_m == b.rgbd.depth_m);
  EXPECT_TRUE(a.rgbd.rgb == b.rgbd.rgb);
  EXPECT_TRUE(a.instance_ids == b.instance_ids);
  EXPECT_TRUE(a.class_ids == b.class_ids);
}

TEST(RgbdRendererTest, OutputIsBitIdenticalForAnyThreadCount) {
  const Scene scene = SmallPlant();
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  const RigidTransform X_WC =
      RigidTransform::LookAt(Eigen::Vector3d(0.5, -0.3, 0.6), Eigen::Vector3d(0, 0, 0.35));
  const RgbdRenderer shared(scene);
  const RenderedFrame reference = [&] {
    const ThreadScope one(1);
    return shared.Render(K, X_WC);
  }();
  for (int threads : {2, 3, 7}) {
    const ThreadScope many(threads);
    SCOPED_TRACE(threads);
    ExpectIdentical(reference, shared.Render(K, X_WC));
  }
  // And from two caller threads at once on one renderer (Render() is const and thread-safe).
  RenderedFrame a;
  RenderedFrame b;
  std::thread ta([&] { a = shared.Render(K, X_WC); });
  std::thread tb([&] { b = shared.Render(K, X_WC); });
  ta.join();
  tb.join();
  ExpectIdentical(reference, a);
  ExpectIdentical(reference, b);
}

TEST(RgbdRendererTest, PacketSizesAgreeUpToRounding) {
  const Scene scene = SmallPlant();
  const CameraIntrinsics K = CameraIntrinsics::FromHorizontalFov(320, 240, 70.0);
  const RigidTransform X_WC =
      RigidTransform::LookAt(Eigen::Vector3d(-0.4, 0.5, 0.7), Eigen::Vector3d(0, 0, 0.3));
  RendererOptions options;
  options.ray_packet_size = 1;
  const RenderedFrame single = RgbdRenderer(scene, options).Render(K, X_WC);
  for (int packet : {4, 8, 16}) {
    SCOPED_TRACE(packet);
    options.ray_packet_size = packet;
    const RgbdRenderer renderer(scene, options);
    const RenderedFrame f = renderer.Render(K, X_WC);
    size_t label_diff = 0;
    for (size_t i = 0; i < f.instance_ids.num_pixels(); ++i) {
      if (f.instance_ids.data()[i] != single.instance_ids.data()[i]) {
        ++label_diff;
      } else {
        EXPECT_NEAR(f.rgbd.depth_m.data()[i], single.rgbd.depth_m.data()[i], 1e-5);
      }
    }
    EXPECT_LE(label_diff, 3u);
  }
}

TEST(RgbdRendererTest, MovedRendererStillRenders) {
  RgbdRenderer a(SmallPlant());
  const RgbdRenderer b(std::move(a));
  const RenderedFrame f =
      b.Render(SmallCamera(),
               RigidTransform::LookAt(Eigen::Vector3d(0.6, 0, 0.4), Eigen::Vector3d(0, 0, 0.35)));
  EXPECT_GT(CountIf(f.instance_ids, 2), 0);  // the stem
}

}  // namespace
}  // namespace avp::sim

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/sensor_noise.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;

SceneObject Wall(double z) {
  TriangleMesh m;
  m.vertices = {Eigen::Vector3f(-5, -5, z), Eigen::Vector3f(5, -5, z), Eigen::Vector3f(5, 5, z),
                Eigen::Vector3f(-5, 5, z)};
  m.triangles = {Eigen::Vector3i(0, 1, 2), Eigen::Vector3i(0, 2, 3)};
  SceneObject o;
  o.name = "wall";
  o.semantic_class = SemanticClass::kOther;
  o.shape = m;
  return o;
}

/// A fronto-parallel wall at z (camera at the origin looking along +z): every pixel reads z.
RenderedFrame RenderWall(double z) {
  Scene scene;
  scene.Add(Wall(z));
  return RgbdRenderer(scene).Render(CameraIntrinsics::RealSenseD435(), RigidTransform::Identity());
}

/// A sphere 0.4 m in front of a wall at 1 m, plus sky (no return) in the top rows.
RenderedFrame RenderSphereBeforeWall() {
  Scene scene;
  SceneObject wall = Wall(1.0);
  auto& mesh = std::get<TriangleMesh>(wall.shape);
  for (auto& v : mesh.vertices) v.y() = std::max(v.y(), -0.2f);  // wall ends above: sky
  scene.Add(wall);
  SceneObject fruit;
  fruit.name = "fruit";
  fruit.semantic_class = SemanticClass::kFruit;
  Ellipsoid e;
  e.center_W = Eigen::Vector3d(0.05, 0.0, 0.6);
  e.radii = Eigen::Vector3d::Constant(0.08);
  fruit.shape = e;
  scene.Add(fruit);
  return RgbdRenderer(scene).Render(CameraIntrinsics::RealSenseD435(), RigidTransform::Identity());
}

DepthNoiseConfig OnlyAxial() {
  DepthNoiseConfig c;
  c.enabled = true;
  c.edge_dropout_probability = 0.0;
  c.invalid_pixel_probability = 0.0;
  c.quantization_m = 0.0;
  return c;
}

struct Stats {
  double mean = 0;
  double stddev = 0;
  size_t n = 0;
};

Stats ErrorStats(const RenderedFrame& noisy, double z_true) {
  Stats s;
  double sum = 0;
  double sum2 = 0;
  for (float z : noisy.rgbd.depth_m.data()) {
    if (z == 0.0f) continue;
    const double e = z - z_true;
    sum += e;
    sum2 += e * e;
    ++s.n;
  }
  s.mean = sum / s.n;
  s.stddev = std::sqrt(sum2 / s.n - s.mean * s.mean);
  return s;
}

double StereoSigma(const DepthNoiseConfig& c, double z) {
  return z * z * c.disparity_sigma_px / (CameraIntrinsics::RealSenseD435().fx * c.baseline_m);
}

TEST(SensorNoiseTest, AxialSigmaOnAFlatWallFollowsTheStereoLaw) {
  for (double z : {0.5, 1.0}) {
    SCOPED_TRACE(z);
    RenderedFrame f = RenderWall(z);
    ASSERT_EQ(f.rgbd.depth_m(320, 240), static_cast<float>(z));
    const DepthNoiseConfig config = OnlyAxial();
    Rng rng(42);
    ApplyDepthNoise(config, f, rng);
    const Stats s = ErrorStats(f, z);
    const double expected = StereoSigma(config, z);  // 0.65 mm at 0.5 m, 2.6 mm at 1 m
    EXPECT_EQ(s.n, f.rgbd.depth_m.num_pixels());
    EXPECT_NEAR(s.stddev, expected, 0.10 * expected);
    // With 307 200 samples the estimate is far tighter than 10 %: 3 %.
    EXPECT_NEAR(s.stddev, expected, 0.03 * expected);
    EXPECT_LT(std::abs(s.mean), 5.0 * expected / std::sqrt(static_cast<double>(s.n)));
  }
}

TEST(SensorNoiseTest, QuantisationGivesMillimetreStepsAndKeepsSigma) {
  RenderedFrame f = RenderWall(1.0);
  DepthNoiseConfig config = OnlyAxial();
  config.quantization_m = 0.001;
  Rng rng(3);
  ApplyDepthNoise(config, f, rng);
  for (float z : f.rgbd.depth_m.data()) {
    const double mm = z * 1000.0;
    ASSERT_NEAR(mm, std::round(mm), 1e-3) << z;
  }
  // Quantisation adds q^2 / 12 of variance: sqrt(2.6^2 + 1/12) mm is 0.6 % above the law.
  const double expected = StereoSigma(config, 1.0);
  EXPECT_NEAR(ErrorStats(f, 1.0).stddev, expected, 0.10 * expected);
}

TEST(SensorNoiseTest, EdgeDropoutOnlyAtDepthDiscontinuities) {
  const RenderedFrame clean = RenderSphereBeforeWall();
  const DepthImage& z = clean.rgbd.depth_m;
  // Reference edge mask: a 4-neighbour jumps by more than edge_jump_m or has no return.
  DepthNoiseConfig config;
  config.enabled = true;
  config.disparity_sigma_px = 0.0;
  config.invalid_pixel_probability = 0.0;
  config.quantization_m = 0.0;
  config.edge_dropout_probability = 1.0;
  auto is_edge = [&](int u, int v) {
    if (!IsValidDepth(z(u, v))) return false;
    const int du[4] = {-1, 1, 0, 0};
    const int dv[4] = {0, 0, -1, 1};
    for (int k = 0; k < 4; ++k) {
      const int uu = u + du[k];
      const int vv = v + dv[k];
      if (!z.Contains(uu, vv)) continue;
      if (!IsValidDepth(z(uu, vv)) || std::abs(z(uu, vv) - z(u, v)) > config.edge_jump_m) {
        return true;
      }
    }
    return false;
  };
  int edges = 0;
  for (int v = 0; v < z.height(); ++v) {
    for (int u = 0; u < z.width(); ++u) edges += is_edge(u, v);
  }
  ASSERT_GT(edges, 1000);  // sphere silhouette (both sides) + wall/sky border

  // p = 1: exactly the edge pixels vanish, everything else is untouched.
  {
    RenderedFrame f = clean;
    Rng rng(1);
    ApplyDepthNoise(config, f, rng);
    for (int v = 0; v < z.height(); ++v) {
      for (int u = 0; u < z.width(); ++u) {
        ASSERT_EQ(f.rgbd.depth_m(u, v), is_edge(u, v) ? 0.0f : z(u, v)) << u << "," << v;
      }
    }
    EXPECT_TRUE(f.instance_ids == clean.instance_ids) << "labels are ground truth: kept";
  }
  // p = 0.5: about half of the edge pixels, and nothing else.
  {
    config.edge_dropout_probability = 0.5;
    RenderedFrame f = clean;
    Rng rng(2);
    ApplyDepthNoise(config, f, rng);
    int dropped = 0;
    for (int v = 0; v < z.height(); ++v) {
      for (int u = 0; u < z.width(); ++u) {
        if (f.rgbd.depth_m(u, v) == z(u, v)) continue;
        ASSERT_TRUE(is_edge(u, v)) << u << "," << v;
        ASSERT_EQ(f.rgbd.depth_m(u, v), 0.0f);
        ++dropped;
      }
    }
    const double sd = std::sqrt(edges * 0.25);
    EXPECT_NEAR(dropped, 0.5 * edges, 5.0 * sd);
  }
}

TEST(SensorNoiseTest, RandomHolesAtTheConfiguredRate) {
  RenderedFrame f = RenderWall(0.7);
  DepthNoiseConfig config = OnlyAxial();
  config.disparity_sigma_px = 0.0;
  config.invalid_pixel_probability = 0.02;
  Rng rng(11);
  ApplyDepthNoise(config, f, rng);
  size_t holes = 0;
  for (float z : f.rgbd.depth_m.data()) {
    if (z == 0.0f) {
      ++holes;
    } else {
      ASSERT_EQ(z, 0.7f);
    }
  }
  const double n = static_cast<double>(f.rgbd.depth_m.num_pixels());
  EXPECT_NEAR(holes, 0.02 * n, 5.0 * std::sqrt(n * 0.02 * 0.98));
}

TEST(SensorNoiseTest, SameSeedSameNoiseDifferentSeedDifferentNoise) {
  const RenderedFrame clean = RenderSphereBeforeWall();
  DepthNoiseConfig config;
  config.enabled = true;  // every effect on, defaults
  RenderedFrame a = clean;
  RenderedFrame b = clean;
  RenderedFrame c = clean;
  Rng ra(5);
  Rng rb(5);
  Rng rc(6);
  ApplyDepthNoise(config, a, ra);
  ApplyDepthNoise(config, b, rb);
  ApplyDepthNoise(config, c, rc);
  EXPECT_TRUE(a.rgbd.depth_m == b.rgbd.depth_m);
  EXPECT_FALSE(a.rgbd.depth_m == c.rgbd.depth_m);
  EXPECT_FALSE(a.rgbd.depth_m == clean.rgbd.depth_m);
  // The generator advances: a second frame from the same Rng gets different noise.
  RenderedFrame a2 = clean;
  ApplyDepthNoise(config, a2, ra);
  EXPECT_FALSE(a.rgbd.depth_m == a2.rgbd.depth_m);
}

TEST(SensorNoiseTest, DisabledLeavesTheFrameUnchanged) {
  const RenderedFrame clean = RenderSphereBeforeWall();
  RenderedFrame f = clean;
  DepthNoiseConfig config;
  config.enabled = false;
  config.invalid_pixel_probability = 1.0;
  config.disparity_sigma_px = 5.0;
  Rng rng(1);
  ApplyDepthNoise(config, f, rng);
  EXPECT_TRUE(f.rgbd.depth_m == clean.rgbd.depth_m);
  EXPECT_TRUE(f.rgbd.rgb == clean.rgbd.rgb);
  EXPECT_TRUE(f.instance_ids == clean.instance_ids);
  EXPECT_EQ(rng.NextU64(), Rng(1).NextU64()) << "a disabled model draws no numbers";
}

TEST(SensorNoiseTest, ValidateReportsEveryBadField) {
  DepthNoiseConfig ok;
  EXPECT_TRUE(ok.Validate().ok());
  DepthNoiseConfig bad;
  bad.baseline_m = -0.05;
  bad.disparity_sigma_px = std::nan("");
  bad.edge_jump_m = 0.0;
  bad.edge_dropout_probability = 1.5;
  bad.invalid_pixel_probability = -0.1;
  bad.quantization_m = std::numeric_limits<double>::infinity();
  const Status s = bad.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(
      s.message(),
      ::testing::AllOf(
          HasSubstr("invalid depth noise options"), HasSubstr("baseline_m (-0.05 m) must be > 0"),
          HasSubstr("disparity_sigma_px (nan)"), HasSubstr("edge_jump_m (0 m)"),
          HasSubstr("edge_dropout_probability (1.5) must be in [0, 1]"),
          HasSubstr("invalid_pixel_probability (-0.1)"), HasSubstr("quantization_m (inf)")));
  // Applying an invalid, enabled config throws the same message.
  bad.enabled = true;
  RenderedFrame f = RenderWall(0.5);
  Rng rng(1);
  EXPECT_THAT([&] { ApplyDepthNoise(bad, f, rng); },
              ::testing::ThrowsMessage<Error>(HasSubstr("baseline_m (-0.05 m)")));
}

}  // namespace
}  // namespace avp::sim

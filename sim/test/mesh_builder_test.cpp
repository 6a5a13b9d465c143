#include <array>
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>
#include <avp/sim/mesh_builder.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;

constexpr double kPi = 3.14159265358979323846;

template <typename F>
std::string ThrownMessage(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "<no exception>";
}

/// Area of a regular n-gon of circumradius r.
double PolygonArea(int n, double r) { return 0.5 * n * r * r * std::sin(2.0 * kPi / n); }

/// Every triangle's normal has a positive dot product with `direction`.
bool AllNormalsAlong(const TriangleMesh& mesh, const Eigen::Vector3d& direction) {
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[t[1]].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[t[2]].cast<double>();
    if ((b - a).cross(c - a).dot(direction) <= 0.0) return false;
  }
  return true;
}

TEST(MeshBuilderTest, CubicBezierHitsItsEndsAndMidpoint) {
  const Eigen::Vector3d p0(0, 0, 0), p1(1, 0, 0), p2(1, 1, 0), p3(0, 1, 1);
  const std::vector<Eigen::Vector3d> pts = SampleCubicBezier(p0, p1, p2, p3, 5);
  ASSERT_EQ(pts.size(), 5u);
  EXPECT_TRUE(pts.front().isApprox(p0));
  EXPECT_TRUE(pts.back().isApprox(p3));
  // B(1/2) = (p0 + 3 p1 + 3 p2 + p3) / 8.
  EXPECT_TRUE(pts[2].isApprox((p0 + 3 * p1 + 3 * p2 + p3) / 8.0, 1e-12));
  EXPECT_THAT(ThrownMessage([&] { (void)SampleCubicBezier(p0, p1, p2, p3, 1); }),
              HasSubstr("num_points = 1"));
}

TEST(MeshBuilderTest, LinearRadiiInterpolates) {
  const std::vector<double> r = LinearRadii(4.0, 2.0, 3);
  EXPECT_EQ(r, (std::vector<double>{4.0, 3.0, 2.0}));
}

TEST(MeshBuilderTest, StraightTubeIsAClosedPrism) {
  const int sides = 8;
  const std::vector<Eigen::Vector3d> line = {{0, 0, 0}, {0, 0, 0.5}, {0, 0, 1.0}};
  const std::vector<double> radii = {0.1, 0.1, 0.1};
  const TriangleMesh tube = MakeTube(line, radii, sides, true);
  EXPECT_EQ(tube.num_triangles(), static_cast<size_t>(2 * sides * 2 + 2 * (sides - 2)));
  EXPECT_TRUE(tube.Validate().ok());
  EXPECT_TRUE(IsClosed(tube));
  // Outward orientation: positive volume equal to the octagonal prism's.
  EXPECT_NEAR(SignedVolume(tube), PolygonArea(sides, 0.1) * 1.0, 1e-6);
  const Box3 b = tube.Bounds();
  EXPECT_NEAR(b.min().z(), 0.0, 1e-6);
  EXPECT_NEAR(b.max().z(), 1.0, 1e-6);
  EXPECT_NEAR(b.max().x(), 0.1, 1e-6);

  const TriangleMesh open = MakeTube(line, radii, sides, false);
  EXPECT_EQ(open.num_triangles(), static_cast<size_t>(2 * sides * 2));
  EXPECT_FALSE(IsClosed(open));
}

TEST(MeshBuilderTest, CurvedTubeKeepsItsCrossSection) {
  // A quarter circle of radius 0.5 with a taper: every ring stays at its radius from its centre
  // (parallel transport, no pinching) and the volume follows Pappus within the taper's average.
  std::vector<Eigen::Vector3d> line;
  std::vector<double> radii;
  const int n = 41;
  for (int i = 0; i < n; ++i) {
    const double a = 0.5 * kPi * i / (n - 1);
    line.emplace_back(0.5 * std::cos(a), 0.5 * std::sin(a), 0.1 * a);
    radii.push_back(0.03);
  }
  const int sides = 10;
  const TriangleMesh tube = MakeTube(line, radii, sides, true);
  EXPECT_TRUE(IsClosed(tube));
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < sides; ++k) {
      const double d = (tube.vertices[i * sides + k].cast<double>() - line[i]).norm();
      ASSERT_NEAR(d, 0.03, 1e-6) << "ring " << i << " vertex " << k;
    }
  }
  double length = 0.0;
  for (int i = 1; i < n; ++i) length += (line[i] - line[i - 1]).norm();
  EXPECT_NEAR(SignedVolume(tube), PolygonArea(sides, 0.03) * length,
              0.02 * PolygonArea(sides, 0.03) * length);
}

TEST(MeshBuilderTest, TubeRejectsBadInput) {
  const std::vector<Eigen::Vector3d> line = {{0, 0, 0}, {0, 0, 1}};
  const std::vector<double> one = {0.1};
  EXPECT_THAT(ThrownMessage([&] { (void)MakeTube(line, one); }), HasSubstr("radii_m.size() = 1"));
  const std::vector<double> negative = {0.1, -0.2};
  EXPECT_THAT(ThrownMessage([&] { (void)MakeTube(line, negative); }), HasSubstr("-0.2"));
  const std::vector<Eigen::Vector3d> repeated = {{0, 0, 0}, {0, 0, 0}};
  const std::vector<double> two = {0.1, 0.1};
  EXPECT_THAT(ThrownMessage([&] { (void)MakeTube(repeated, two); }), HasSubstr("step"));
  EXPECT_THAT(ThrownMessage([&] { (void)MakeTube(line, two, 2); }), HasSubstr("sides = 2"));
}

TEST(MeshBuilderTest, FlatLeafBladeHasTheExpectedOutline) {
  LeafBladeParams p;
  p.length_m = 0.1;
  p.width_m = 0.05;
  p.midrib_bend_rad = 0.0;
  p.cup = 0.0;
  p.twist_rad = 0.0;
  const TriangleMesh blade = MakeLeafBlade(p);
  EXPECT_EQ(blade.num_triangles(), static_cast<size_t>(p.num_triangles()));
  EXPECT_EQ(p.num_triangles(), 2 * 3 * (2 * 8 - 1));  // 90: within the 40-120 budget
  EXPECT_TRUE(blade.Validate().ok());
  const Box3 b = blade.Bounds();
  EXPECT_NEAR(b.min().x(), 0.0, 1e-7);
  EXPECT_NEAR(b.max().x(), 0.1, 1e-6);  // the tip
  EXPECT_NEAR(b.max().y(), 0.025, 0.001);
  EXPECT_NEAR(b.min().y(), -0.025, 0.001);
  EXPECT_NEAR(b.size().z(), 0.0, 1e-7);  // flat
  // A sine-bump outline covers about 2/pi of its bounding rectangle.
  EXPECT_NEAR(SurfaceArea(blade) / (0.1 * 0.05), 2.0 / kPi, 0.06);
  EXPECT_TRUE(AllNormalsAlong(blade, Eigen::Vector3d::UnitZ()));  // upper side faces +z
  // Widest at 40 % of the length.
  double widest_x = 0.0;
  double widest = 0.0;
  for (const Eigen::Vector3f& v : blade.vertices) {
    if (v.y() > widest) {
      widest = v.y();
      widest_x = v.x();
    }
  }
  EXPECT_NEAR(widest_x, 0.04, 0.0126);  // one segment (1/8 of the length)
}

TEST(MeshBuilderTest, BentCuppedLeafBladeCurvesDownAndUp) {
  LeafBladeParams p;
  p.midrib_bend_rad = 0.8;
  p.cup = 0.3;
  p.twist_rad = 0.4;
  const TriangleMesh blade = MakeLeafBlade(p);
  // The tip is the last vertex; bending pulls it below the base plane, shortening the reach.
  const Eigen::Vector3f tip = blade.vertices.back();
  EXPECT_LT(tip.z(), -0.01);
  EXPECT_LT(tip.x(), p.length_m);
  EXPECT_GT(tip.x(), 0.8 * p.length_m);
  // Arc length along the midrib is preserved by the bend.
  const int columns = 2 * p.segments_across + 1;
  double arc = 0.0;
  Eigen::Vector3f previous = blade.vertices[p.segments_across];
  for (int i = 1; i <= p.segments_along; ++i) {
    const Eigen::Vector3f mid =
        i == p.segments_along ? tip : blade.vertices[i * columns + p.segments_across];
    arc += (mid - previous).norm();
    previous = mid;
  }
  EXPECT_NEAR(arc, p.length_m, 1e-4);
}

TEST(MeshBuilderTest, LeafBladeValidateNamesEveryBadField) {
  LeafBladeParams p;
  p.length_m = -1.0;
  p.segments_along = 1;
  p.widest_at = 1.5;
  const Status s = p.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("length_m (-1)"));
  EXPECT_THAT(s.message(), HasSubstr("segments_along (1)"));
  EXPECT_THAT(s.message(), HasSubstr("widest_at (1.5)"));
  EXPECT_THAT(ThrownMessage([&] { (void)MakeLeafBlade(p); }), HasSubstr("length_m (-1)"));
}

TEST(MeshBuilderTest, BoxIsClosedWithTheRightVolume) {
  const TriangleMesh box = MakeBox(Eigen::Vector3d(0.1, 0.2, 0.3));
  EXPECT_EQ(box.num_triangles(), 12u);
  EXPECT_TRUE(IsClosed(box));
  EXPECT_NEAR(SignedVolume(box), 0.2 * 0.4 * 0.6, 1e-7);
  EXPECT_NEAR(SurfaceArea(box), 2 * (0.2 * 0.4 + 0.2 * 0.6 + 0.4 * 0.6), 1e-6);
  const TriangleMesh placed = MakeBox(Box3({1, 2, 3}, {2, 4, 6}));
  EXPECT_TRUE(placed.Bounds().min().isApprox(Eigen::Vector3d(1, 2, 3), 1e-7));
  EXPECT_TRUE(placed.Bounds().max().isApprox(Eigen::Vector3d(2, 4, 6), 1e-7));
  EXPECT_NEAR(SignedVolume(placed), 6.0, 1e-5);
  EXPECT_THAT(ThrownMessage([] { (void)MakeBox(Eigen::Vector3d(0.1, 0.0, 0.1)); }),
              HasSubstr("half_size_m"));
}

TEST(MeshBuilderTest, QuadAndDiscAreFlatAndFaceUp) {
  const TriangleMesh quad = MakeQuad(2.0, 1.0);
  EXPECT_EQ(quad.num_triangles(), 2u);
  EXPECT_NEAR(SurfaceArea(quad), 8.0, 1e-6);
  EXPECT_TRUE(AllNormalsAlong(quad, Eigen::Vector3d::UnitZ()));
  EXPECT_FALSE(IsClosed(quad));
  const TriangleMesh disc = MakeDisc(0.5, 32);
  EXPECT_EQ(disc.num_triangles(), 32u);
  EXPECT_NEAR(SurfaceArea(disc), PolygonArea(32, 0.5), 1e-6);
  EXPECT_TRUE(AllNormalsAlong(disc, Eigen::Vector3d::UnitZ()));
}

TEST(MeshBuilderTest, IcosphereConvergesToTheSphere) {
  for (int level = 0; level <= 3; ++level) {
    const TriangleMesh s = MakeIcosphere(0.2, level);
    EXPECT_EQ(s.num_triangles(), static_cast<size_t>(20 * (1 << (2 * level))));
    EXPECT_TRUE(IsClosed(s)) << level;
    for (const Eigen::Vector3f& v : s.vertices) ASSERT_NEAR(v.norm(), 0.2, 1e-6);
  }
  const double sphere = 4.0 / 3.0 * kPi * 0.2 * 0.2 * 0.2;
  EXPECT_NEAR(SignedVolume(MakeIcosphere(0.2, 3)), sphere, 0.01 * sphere);
  EXPECT_LT(SignedVolume(MakeIcosphere(0.2, 1)), SignedVolume(MakeIcosphere(0.2, 2)));
}

TEST(MeshBuilderTest, TessellatedEllipsoidLiesOnItsSurface) {
  Ellipsoid e;
  e.center_W = Eigen::Vector3d(1, -2, 0.5);
  e.radii = Eigen::Vector3d(0.03, 0.02, 0.025);
  e.R_WE = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const TriangleMesh mesh = TessellateEllipsoid(e, 2);
  EXPECT_TRUE(IsClosed(mesh));
  for (const Eigen::Vector3f& v : mesh.vertices) {
    ASSERT_NEAR(e.Implicit(v.cast<double>()), 0.0, 1e-4);
  }
  // Centrally symmetric: the bounding box is centred on the ellipsoid.
  EXPECT_LT((mesh.Bounds().center() - e.center_W).norm(), 1e-6);
  const double volume = 4.0 / 3.0 * kPi * e.radii.prod();
  EXPECT_NEAR(SignedVolume(TessellateEllipsoid(e, 3)), volume, 0.01 * volume);
}

TEST(MeshBuilderTest, IsClosedDetectsHolesAndFlips) {
  TriangleMesh box = MakeBox(Eigen::Vector3d::Constant(1.0));
  ASSERT_TRUE(IsClosed(box));
  TriangleMesh holed = box;
  holed.triangles.pop_back();
  EXPECT_FALSE(IsClosed(holed));
  TriangleMesh flipped = box;
  std::swap(flipped.triangles[0][1], flipped.triangles[0][2]);
  EXPECT_FALSE(IsClosed(flipped));
  EXPECT_FALSE(IsClosed(TriangleMesh{}));
}

TEST(MeshBuilderTest, ConnectedComponentsSplitsByIndexAndPosition) {
  TriangleMesh two = MakeIcosphere(0.1, 1);
  two.Append(MakeIcosphere(0.1, 1), RigidTransform(Eigen::Vector3d(1, 0, 0)));
  std::vector<TriangleMesh> parts = ConnectedComponents(two);
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_EQ(parts[0].num_triangles(), 80u);
  EXPECT_EQ(parts[0].vertices.size(), 42u);  // compacted
  EXPECT_NEAR(parts[1].Bounds().center().x(), 1.0, 1e-6);
  EXPECT_TRUE(IsClosed(parts[1]));

  // An unwelded quad: two triangles with their own vertices, sharing positions only.
  TriangleMesh soup;
  soup.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  soup.triangles = {{0, 1, 2}, {3, 4, 5}};
  EXPECT_EQ(ConnectedComponents(soup).size(), 1u);
  soup.vertices[3] = {0, 0, 1e-3};
  soup.vertices[4] = {1, 1, 1e-3};
  EXPECT_EQ(ConnectedComponents(soup).size(), 2u);
}

TEST(MeshBuilderTest, FibonacciSphereIsUnitAndBalanced) {
  const std::vector<Eigen::Vector3d> pts = FibonacciSphere(500);
  ASSERT_EQ(pts.size(), 500u);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : pts) {
    ASSERT_NEAR(p.norm(), 1.0, 1e-12);
    mean += p / 500.0;
  }
  EXPECT_LT(mean.norm(), 0.01);
}

TEST(MeshBuilderTest, SegmentOcclusionTesterFindsCrossings) {
  SegmentOcclusionTester tester;
  tester.Add(MakeQuad(1.0, 1.0));  // z = 0, |x|, |y| <= 1
  EXPECT_EQ(tester.num_triangles(), 2u);
  EXPECT_TRUE(tester.IsBlocked({0.3, 0.2, 1.0}, {0.3, 0.2, -1.0}));
  EXPECT_TRUE(tester.IsBlocked({-0.9, 0.9, -1.0}, {-0.9, 0.9, 0.5}));
  EXPECT_FALSE(tester.IsBlocked({1.5, 0.0, 1.0}, {1.5, 0.0, -1.0}));  // beside the quad
  EXPECT_FALSE(tester.IsBlocked({0.0, 0.0, 1.0}, {0.0, 0.0, 0.2}));   // stops short
  EXPECT_FALSE(tester.IsBlocked({0.0, 0.0, 1.0}, {0.0, 0.0, 0.0}));   // ends on it
  // Many random segments agree with the analytic answer.
  Rng rng(3);
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d a(rng.Uniform(-2, 2), rng.Uniform(-2, 2), rng.Uniform(0.01, 2));
    const Eigen::Vector3d b(rng.Uniform(-2, 2), rng.Uniform(-2, 2), rng.Uniform(-2, -0.01));
    const double t = a.z() / (a.z() - b.z());
    const Eigen::Vector3d hit = a + t * (b - a);
    const bool inside = std::abs(hit.x()) <= 1.0 && std::abs(hit.y()) <= 1.0;
    if (std::abs(std::abs(hit.x()) - 1.0) < 1e-6 || std::abs(std::abs(hit.y()) - 1.0) < 1e-6) {
      continue;
    }
    ASSERT_EQ(tester.IsBlocked(a, b), inside) << i;
  }
}

TEST(MeshBuilderTest, FruitVisibilityHonoursOccludersAndTheViewCone) {
  OcclusionScreen screen;
  screen.enabled = true;
  screen.eye_W = Eigen::Vector3d(0, 0, 0);
  screen.view_direction_W = Eigen::Vector3d::UnitX();
  screen.cone_half_angle_deg = 30.0;
  screen.samples_per_fruit = 200;
  Ellipsoid fruit;
  fruit.center_W = Eigen::Vector3d(1, 0, 0);
  fruit.radii = Eigen::Vector3d::Constant(0.05);
  Ellipsoid behind = fruit;  // outside the cone
  behind.center_W = Eigen::Vector3d(-1, 0, 0);
  const std::array<Ellipsoid, 2> fruits = {fruit, behind};
  FruitVisibility visibility(screen, fruits);
  // Only the half of the first fruit facing the eye is sampled.
  EXPECT_GT(visibility.num_samples(), 80u);
  EXPECT_LT(visibility.num_samples(), 110u);
  const auto visible = visibility.FindVisible();
  ASSERT_TRUE(visible.has_value());
  EXPECT_EQ(visible->second, 0u);
  EXPECT_LT(visible->first.x(), 1.0);  // on the near side
  EXPECT_EQ(visibility.CountVisible(), static_cast<int>(visibility.num_samples()));

  // A wall at x = 0.5 hides everything.
  TriangleMesh wall = MakeQuad(1.0, 1.0);
  wall.Transform(RigidTransform(
      Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix(), {0.5, 0, 0}));
  visibility.AddOccluder(wall);
  EXPECT_FALSE(visibility.FindVisible().has_value());
  EXPECT_EQ(visibility.CountVisible(), 0);

  screen.cone_half_angle_deg = 0.0;
  EXPECT_THAT(ThrownMessage([&] { FruitVisibility bad(screen, fruits); }),
              HasSubstr("cone_half_angle_deg (0)"));
}

TEST(MeshBuilderTest, FramesAreRotations) {
  const Eigen::Matrix3d Rz = RotationWithZAxis({1, 2, 3});
  EXPECT_TRUE(IsRotationMatrix(Rz, 1e-12));
  EXPECT_TRUE(Rz.col(2).isApprox(Eigen::Vector3d(1, 2, 3).normalized()));
  const Eigen::Matrix3d Rx = RotationWithXAxis({1, 1, 0}, {0, 0, 1});
  EXPECT_TRUE(IsRotationMatrix(Rx, 1e-12));
  EXPECT_TRUE(Rx.col(0).isApprox(Eigen::Vector3d(1, 1, 0).normalized()));
  EXPECT_TRUE(Rx.col(2).isApprox(Eigen::Vector3d::UnitZ()));
  // Parallel hint: still a rotation.
  EXPECT_TRUE(IsRotationMatrix(RotationWithXAxis({0, 0, 2}, {0, 0, 1}), 1e-12));
  EXPECT_THAT(ThrownMessage([] { (void)RotationWithZAxis(Eigen::Vector3d::Zero()); }),
              HasSubstr("direction"));
}

TEST(MeshBuilderTest, VaryAlbedoIsSeededAndBounded) {
  const Eigen::Vector3f base(0.2f, 0.5f, 0.9f);
  Rng a(11);
  Rng b(11);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3f x = VaryAlbedo(base, 0.2, a);
    EXPECT_EQ(x, VaryAlbedo(base, 0.2, b));
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(x[k], base[k] * 0.8f * 0.9f - 1e-6f);
      EXPECT_LE(x[k], std::min(1.0f, base[k] * 1.2f * 1.1f + 1e-6f));
    }
  }
}

}  // namespace
}  // namespace avp::sim

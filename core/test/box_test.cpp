#include <cmath>
#include <limits>
#include <optional>
#include <utility>

#include <Eigen/Core>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/box.h>
#include <avp/core/error.h>
#include <avp/core/ray.h>
#include <avp/core/rng.h>

namespace avp {
namespace {

using ::testing::HasSubstr;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

const Box3 kUnit({0, 0, 0}, {1, 1, 1});

void ExpectHit(const Box3& box, const Ray& ray, double t_enter, double t_exit) {
  const auto hit = box.Intersect(ray);
  ASSERT_TRUE(hit.has_value()) << "ray from " << ray.origin.transpose() << " along "
                               << ray.direction.transpose() << " misses " << box.ToString();
  EXPECT_NEAR(hit->first, t_enter, 1e-12);
  EXPECT_NEAR(hit->second, t_exit, 1e-12);
}

void ExpectMiss(const Box3& box, const Ray& ray) {
  const auto hit = box.Intersect(ray);
  EXPECT_FALSE(hit.has_value()) << "ray from " << ray.origin.transpose() << " along "
                                << ray.direction.transpose() << " hits " << box.ToString()
                                << " at [" << hit->first << ", " << hit->second << "]";
}

TEST(BoxTest, DefaultBoxIsEmpty) {
  const Box3 empty;
  EXPECT_TRUE(empty.IsEmpty());
  EXPECT_EQ(empty.size(), Eigen::Vector3d::Zero());
  EXPECT_EQ(empty.Volume(), 0.0);
  EXPECT_FALSE(empty.Contains({0, 0, 0}));
  EXPECT_FALSE(empty.Intersects(kUnit));
  EXPECT_FALSE(kUnit.Intersects(empty));
  EXPECT_FALSE(empty.Intersects(empty));
  EXPECT_FALSE(empty.Intersect(Ray{}).has_value());
  EXPECT_TRUE(empty.Inflated(1.0).IsEmpty());
  EXPECT_TRUE(empty.Intersection(kUnit).IsEmpty());
  EXPECT_EQ(empty.ToString(), "[empty box]");
}

TEST(BoxTest, SizeCenterVolume) {
  const Box3 box({-1, 0, 2}, {3, 0.5, 5});
  EXPECT_FALSE(box.IsEmpty());
  EXPECT_EQ(box.size(), Eigen::Vector3d(4, 0.5, 3));
  EXPECT_EQ(box.center(), Eigen::Vector3d(1, 0.25, 3.5));
  EXPECT_EQ(box.Volume(), 6.0);
  EXPECT_EQ(box.ToString(), "[(-1, 0, 2) .. (3, 0.5, 5)] m");
  const Box3 same = Box3::FromCenterAndHalfSize({1, 0.25, 3.5}, {2, 0.25, 1.5});
  EXPECT_EQ(same.min(), box.min());
  EXPECT_EQ(same.max(), box.max());
}

TEST(BoxTest, DegenerateBoxIsNotEmpty) {
  const Box3 point({1, 2, 3}, {1, 2, 3});
  EXPECT_FALSE(point.IsEmpty());
  EXPECT_EQ(point.Volume(), 0.0);
  EXPECT_TRUE(point.Contains({1, 2, 3}));
  EXPECT_FALSE(point.Contains({1, 2, 3.000001}));
}

TEST(BoxTest, ConstructorRejectsInvertedOrNonFiniteBounds) {
  try {
    const Box3 box({0, 2, 0}, {1, 1, 1});
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("min.transpose() = 0 2 0"));
    EXPECT_THAT(e.what(), HasSubstr("max.transpose() = 1 1 1"));
  }
  EXPECT_THROW(Box3({0, 0, kNaN}, {1, 1, 1}), Error);
  EXPECT_THROW(Box3({0, 0, 0}, {1, kInf, 1}), Error);
  EXPECT_THROW(Box3::FromCenterAndHalfSize({0, 0, 0}, {1, -0.5, 1}), Error);
}

TEST(BoxTest, ContainsIsClosed) {
  EXPECT_TRUE(kUnit.Contains({0.5, 0.5, 0.5}));
  EXPECT_TRUE(kUnit.Contains({0, 0, 0}));
  EXPECT_TRUE(kUnit.Contains({1, 1, 1}));
  EXPECT_TRUE(kUnit.Contains({1, 0.5, 0}));
  EXPECT_FALSE(kUnit.Contains({1 + 1e-12, 0.5, 0.5}));
  EXPECT_FALSE(kUnit.Contains({0.5, -1e-12, 0.5}));
  EXPECT_FALSE(kUnit.Contains({0.5, 0.5, 2}));
  EXPECT_FALSE(kUnit.Contains({kNaN, 0.5, 0.5}));
}

TEST(BoxTest, IntersectsBoxes) {
  EXPECT_TRUE(kUnit.Intersects(kUnit));
  EXPECT_TRUE(kUnit.Intersects(Box3({0.5, 0.5, 0.5}, {2, 2, 2})));
  EXPECT_TRUE(kUnit.Intersects(Box3({0.2, 0.2, 0.2}, {0.3, 0.3, 0.3})));  // nested
  EXPECT_TRUE(Box3({0.2, 0.2, 0.2}, {0.3, 0.3, 0.3}).Intersects(kUnit));
  EXPECT_TRUE(kUnit.Intersects(Box3({1, 0, 0}, {2, 1, 1})));  // touching faces
  EXPECT_TRUE(kUnit.Intersects(Box3({1, 1, 1}, {2, 2, 2})));  // touching corners
  EXPECT_FALSE(kUnit.Intersects(Box3({1.01, 0, 0}, {2, 1, 1})));
  // Overlapping on two axes but separated on the third.
  EXPECT_FALSE(kUnit.Intersects(Box3({0, 0, -2}, {1, 1, -0.5})));
  EXPECT_FALSE(Box3({0, 0, -2}, {1, 1, -0.5}).Intersects(kUnit));
}

TEST(BoxTest, Intersection) {
  const Box3 overlap = kUnit.Intersection(Box3({0.5, -1, 0.25}, {2, 0.5, 0.75}));
  EXPECT_EQ(overlap.min(), Eigen::Vector3d(0.5, 0, 0.25));
  EXPECT_EQ(overlap.max(), Eigen::Vector3d(1, 0.5, 0.75));
  EXPECT_DOUBLE_EQ(overlap.Volume(), 0.5 * 0.5 * 0.5);
  EXPECT_TRUE(kUnit.Intersection(Box3({2, 2, 2}, {3, 3, 3})).IsEmpty());
  EXPECT_EQ(kUnit.Intersection(Box3({2, 2, 2}, {3, 3, 3})).Volume(), 0.0);
  EXPECT_TRUE(kUnit.Intersection(Box3()).IsEmpty());
}

TEST(BoxTest, ExtendGrowsToIncludePointsAndBoxes) {
  Box3 box;
  box.Extend(Eigen::Vector3d(1, 2, 3));
  EXPECT_FALSE(box.IsEmpty());
  EXPECT_EQ(box.min(), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(box.max(), Eigen::Vector3d(1, 2, 3));
  box.Extend(Eigen::Vector3d(-1, 5, 3));
  EXPECT_EQ(box.min(), Eigen::Vector3d(-1, 2, 3));
  EXPECT_EQ(box.max(), Eigen::Vector3d(1, 5, 3));
  box.Extend(Box3());  // no-op
  EXPECT_EQ(box.min(), Eigen::Vector3d(-1, 2, 3));
  EXPECT_EQ(box.max(), Eigen::Vector3d(1, 5, 3));
  box.Extend(Box3({0, 0, 0}, {0.5, 0.5, 4}));
  EXPECT_EQ(box.min(), Eigen::Vector3d(-1, 0, 0));
  EXPECT_EQ(box.max(), Eigen::Vector3d(1, 5, 4));
}

TEST(BoxTest, Inflated) {
  const Box3 grown = kUnit.Inflated(0.5);
  EXPECT_EQ(grown.min(), Eigen::Vector3d(-0.5, -0.5, -0.5));
  EXPECT_EQ(grown.max(), Eigen::Vector3d(1.5, 1.5, 1.5));
  const Box3 shrunk = kUnit.Inflated(-0.25);
  EXPECT_EQ(shrunk.min(), Eigen::Vector3d(0.25, 0.25, 0.25));
  EXPECT_EQ(shrunk.max(), Eigen::Vector3d(0.75, 0.75, 0.75));
  EXPECT_FALSE(kUnit.Inflated(-0.5).IsEmpty());  // shrinks to the centre point
  EXPECT_TRUE(kUnit.Inflated(-0.6).IsEmpty());
  EXPECT_FALSE(kUnit.Inflated(-0.6).Contains({0.5, 0.5, 0.5}));
  EXPECT_EQ(kUnit.Inflated(-0.6).Volume(), 0.0);
}

// ---- Ray slab test -----------------------------------------------------------------------------

TEST(BoxTest, RayAlongAnAxisThroughTheBox) {
  ExpectHit(kUnit, Ray{{-1, 0.5, 0.5}, {1, 0, 0}}, 1, 2);
  ExpectHit(kUnit, Ray{{0.5, 3, 0.5}, {0, -1, 0}}, 2, 3);
  ExpectHit(kUnit, Ray{{0.5, 0.5, -4}, {0, 0, 2}}, 2, 2.5);  // t scales with |direction|
}

TEST(BoxTest, AxisParallelRayOutsideTheSlabMisses) {
  // Parallel to x, but outside the box in y or z: must miss (the 1 / 0 slab case).
  ExpectMiss(kUnit, Ray{{-1, 1.5, 0.5}, {1, 0, 0}});
  ExpectMiss(kUnit, Ray{{-1, 0.5, -0.001}, {1, 0, 0}});
  ExpectMiss(kUnit, Ray{{0.5, -1, 2}, {0, 1, 0}});
  // Direction with a negative zero component.
  ExpectMiss(kUnit, Ray{{-1, 1.5, 0.5}, {1, -0.0, 0}});
}

TEST(BoxTest, AxisParallelRayOnAFaceHits) {
  ExpectHit(kUnit, Ray{{-1, 1, 0.5}, {1, 0, 0}}, 1, 2);
  ExpectHit(kUnit, Ray{{-1, 0, 0}, {1, 0, 0}}, 1, 2);  // along an edge
}

TEST(BoxTest, RayStartingInsideIsClippedToTMin) {
  ExpectHit(kUnit, Ray{{0.5, 0.5, 0.5}, {1, 0, 0}}, 0, 0.5);
  ExpectHit(kUnit, Ray{{0.25, 0.5, 0.5}, {-1, 0, 0}}, 0, 0.25);
  Ray late{{-1, 0.5, 0.5}, {1, 0, 0}};
  late.t_min = 1.5;
  ExpectHit(kUnit, late, 1.5, 2);
}

TEST(BoxTest, RayPointingAwayMisses) {
  ExpectMiss(kUnit, Ray{{2, 0.5, 0.5}, {1, 0, 0}});
  ExpectMiss(kUnit, Ray{{-1, 0.5, 0.5}, {-1, 0, 0}});
  // The line hits the box but behind the origin.
  ExpectMiss(kUnit, Ray{{2, 2, 2}, Eigen::Vector3d(1, 1, 1).normalized()});
  ExpectHit(kUnit, Ray{{2, 0.5, 0.5}, {-1, 0, 0}}, 1, 2);
}

TEST(BoxTest, DiagonalRays) {
  // Between (-1,-1,-1) and (2,2,2): enters at the corner (0,0,0), leaves at (1,1,1).
  const double s3 = std::sqrt(3.0);
  ExpectHit(kUnit, Ray::Between({-1, -1, -1}, {2, 2, 2}), s3, 2 * s3);
  // A diagonal in the xy plane that passes beside the box.
  ExpectMiss(kUnit, Ray::FromDirection({-1, 0.5, 0.5}, {1, 1, 0}));
  // Enters through the x = 0 face, leaves through y = 1: t in [1, 1.5] for direction (1, 1, 0)
  // from (-1, -0.5, 0.5), scaled by |d| = sqrt 2.
  ExpectHit(kUnit, Ray::FromDirection({-1, -0.5, 0.5}, {1, 1, 0}), std::sqrt(2.0),
            1.5 * std::sqrt(2.0));
}

TEST(BoxTest, RaySegmentsAreClippedToTMax) {
  ExpectHit(kUnit, Ray::Between({-1, 0.5, 0.5}, {0.5, 0.5, 0.5}), 1, 1.5);
  ExpectMiss(kUnit, Ray::Between({-2, 0.5, 0.5}, {-0.5, 0.5, 0.5}));    // ends before the box
  ExpectHit(kUnit, Ray::Between({-1, 0.5, 0.5}, {0, 0.5, 0.5}), 1, 1);  // ends on the face
  ExpectMiss(kUnit, Ray::FromDirection({-1, 0.5, 0.5}, {2, 0, 0}, 0.99));
}

TEST(BoxTest, IntersectMatchesDenseSamplingOnRandomRays) {
  // Slow reference: sample the segment densely and compare with the slab interval.
  Rng rng(4);
  const Box3 box({-0.3, 0.1, 0.2}, {0.4, 0.9, 0.5});
  const Box3 shrunk = box.Inflated(-1e-9);
  const Box3 grown = box.Inflated(1e-9);
  int hits = 0;
  int misses = 0;
  for (int i = 0; i < 300; ++i) {
    Eigen::Vector3d origin(rng.Uniform(-1.5, 1.5), rng.Uniform(-1.5, 1.5), rng.Uniform(-1.5, 1.5));
    // Aim near the box so that hits and misses are both common.
    const Eigen::Vector3d aim(rng.Uniform(-0.6, 0.7), rng.Uniform(-0.2, 1.2), rng.Uniform(0, 0.7));
    Eigen::Vector3d d = aim - origin;
    // Every fourth ray is parallel to a coordinate plane, and its origin then lies inside the
    // box's slab on that axis half of the time.
    if (i % 4 == 0) {
      const int axis = (i / 4) % 3;
      d[axis] = 0.0;
      if (i % 8 == 0) origin[axis] = rng.Uniform(box.min()[axis], box.max()[axis]);
    }
    if (d.norm() < 1e-3) continue;
    const Ray ray = Ray::FromDirection(origin, d, rng.Uniform(0.5, 4.0));
    const auto hit = box.Intersect(ray);
    (hit ? hits : misses) += 1;
    constexpr int kSamples = 500;
    for (int s = 0; s <= kSamples; ++s) {
      const double t = ray.t_max * s / kSamples;
      const Eigen::Vector3d p = ray.At(t);
      const bool inside_interval = hit && t >= hit->first - 1e-9 && t <= hit->second + 1e-9;
      if (shrunk.Contains(p)) {
        ASSERT_TRUE(inside_interval) << "ray " << i << " t " << t;
      }
      if (inside_interval) {
        ASSERT_TRUE(grown.Contains(p)) << "ray " << i << " t " << t;
      }
    }
    if (hit) {
      EXPECT_LE(hit->first, hit->second);
      EXPECT_GE(hit->first, ray.t_min);
      EXPECT_LE(hit->second, ray.t_max);
    }
  }
  EXPECT_GT(hits, 75);
  EXPECT_GT(misses, 75);
}

TEST(BoxTest, RayFactories) {
  const Ray r = Ray::Between({1, 1, 1}, {1, 4, 5});
  EXPECT_EQ(r.origin, Eigen::Vector3d(1, 1, 1));
  EXPECT_NEAR((r.direction - Eigen::Vector3d(0, 0.6, 0.8)).norm(), 0.0, 1e-15);
  EXPECT_EQ(r.t_min, 0.0);
  EXPECT_EQ(r.t_max, 5.0);
  EXPECT_NEAR((r.At(5.0) - Eigen::Vector3d(1, 4, 5)).norm(), 0.0, 1e-14);
  const Ray f = Ray::FromDirection({0, 0, 0}, {0, 0, -3});
  EXPECT_EQ(f.direction, Eigen::Vector3d(0, 0, -1));
  EXPECT_EQ(f.t_max, kInf);
  EXPECT_THROW(Ray::Between({1, 2, 3}, {1, 2, 3}), Error);
  EXPECT_THROW(Ray::FromDirection({0, 0, 0}, {0, 0, 0}), Error);
  EXPECT_THROW(Ray::FromDirection({0, 0, 0}, {1, 0, 0}, -1.0), Error);
  EXPECT_THROW(Ray::FromDirection({kNaN, 0, 0}, {1, 0, 0}), Error);
}

}  // namespace
}  // namespace avp

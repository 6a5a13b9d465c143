#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include <Eigen/Core>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/box.h>
#include <avp/core/camera.h>
#include <avp/core/error.h>
#include <avp/core/frustum.h>
#include <avp/core/rng.h>
#include <avp/core/transform.h>

namespace avp {
namespace {

using ::testing::HasSubstr;

constexpr double kPi = std::numbers::pi;

// 64 x 48 pixels, 90 deg horizontal FOV: fx = fy = 32, cx = 31.5, cy = 23.5, so the image edges
// are at x / z = +-1 and y / z = +-0.75. Depth range 0.5 - 4 m.
CameraIntrinsics TestCamera() {
  return CameraIntrinsics::FromHorizontalFov(64, 48, 90.0, 0.5, 4.0);
}

// Slow reference: in front, within the depth range and on the image (edges included).
bool ReferenceContains(const CameraIntrinsics& K, const RigidTransform& X_CW,
                       const Eigen::Vector3d& p_W) {
  const Eigen::Vector3d p_C = X_CW * p_W;
  if (p_C.z() < K.min_depth_m || p_C.z() > K.max_depth_m) return false;
  const Eigen::Vector2d uv = *K.Project(p_C);
  return uv.x() >= -0.5 && uv.x() <= K.width - 0.5 && uv.y() >= -0.5 && uv.y() <= K.height - 0.5;
}

// Distance-like margin of p_W to the reference frustum boundary, to skip points too close to a
// face for either test to be trusted.
double BoundaryMargin(const CameraIntrinsics& K, const RigidTransform& X_CW,
                      const Eigen::Vector3d& p_W) {
  const Eigen::Vector3d p_C = X_CW * p_W;
  double margin = std::min(std::abs(p_C.z() - K.min_depth_m), std::abs(p_C.z() - K.max_depth_m));
  if (p_C.z() > 0) {
    const Eigen::Vector2d uv = *K.Project(p_C);
    const double px = std::min({std::abs(uv.x() + 0.5), std::abs(uv.x() - K.width + 0.5),
                                std::abs(uv.y() + 0.5), std::abs(uv.y() - K.height + 0.5)});
    margin = std::min(margin, px / K.fx * p_C.z());
  }
  return margin;
}

TEST(FrustumTest, CornersAtIdentityPose) {
  const Frustum f(TestCamera(), RigidTransform());
  const auto& c = f.corners();
  // Near plane z = 0.5: x = +-0.5, y = +-0.375; far plane z = 4: x = +-4, y = +-3.
  // Order: tl, tr, br, bl (top = negative y in the optical frame).
  const Eigen::Vector3d expected[8] = {{-0.5, -0.375, 0.5}, {0.5, -0.375, 0.5}, {0.5, 0.375, 0.5},
                                       {-0.5, 0.375, 0.5},  {-4, -3, 4},        {4, -3, 4},
                                       {4, 3, 4},           {-4, 3, 4}};
  for (int i = 0; i < 8; ++i) {
    EXPECT_LT((c[i] - expected[i]).norm(), 1e-12) << "corner " << i << ": " << c[i].transpose();
  }
  const Box3 box = f.BoundingBox();
  EXPECT_LT((box.min() - Eigen::Vector3d(-4, -3, 0.5)).norm(), 1e-12);
  EXPECT_LT((box.max() - Eigen::Vector3d(4, 3, 4)).norm(), 1e-12);
}

TEST(FrustumTest, CornersFollowThePose) {
  const CameraIntrinsics K = TestCamera();
  const RigidTransform X_WC = RigidTransform::LookAt({1, -2, 1.5}, {0.5, 0.5, 0.8});
  const Frustum at_origin(K, RigidTransform());
  const Frustum posed(K, X_WC);
  for (int i = 0; i < 8; ++i) {
    EXPECT_LT((posed.corners()[i] - X_WC * at_origin.corners()[i]).norm(), 1e-12);
  }
  // Each corner projects onto the matching image corner at the near or far depth.
  const Eigen::Vector2d image_corners[4] = {{-0.5, -0.5}, {63.5, -0.5}, {63.5, 47.5}, {-0.5, 47.5}};
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d p_C = X_WC.inverse() * posed.corners()[i];
    EXPECT_NEAR(p_C.z(), i < 4 ? 0.5 : 4.0, 1e-12);
    EXPECT_LT((*K.Project(p_C) - image_corners[i % 4]).norm(), 1e-9);
  }
}

TEST(FrustumTest, ContainsHandPickedPoints) {
  const Frustum f(TestCamera(), RigidTransform());
  EXPECT_TRUE(f.Contains({0, 0, 1}));
  EXPECT_TRUE(f.Contains({0, 0, 0.5}));  // on the near plane
  EXPECT_TRUE(f.Contains({0, 0, 4}));    // on the far plane
  EXPECT_FALSE(f.Contains({0, 0, 0.49}));
  EXPECT_FALSE(f.Contains({0, 0, 4.01}));
  EXPECT_FALSE(f.Contains({0, 0, -1}));  // behind
  EXPECT_FALSE(f.Contains({0, 0, 0}));   // the optical centre is before the near plane
  // Sides at x = +-z and y = +-0.75 z.
  EXPECT_TRUE(f.Contains({1.98, 0, 2}));
  EXPECT_FALSE(f.Contains({2.02, 0, 2}));
  EXPECT_TRUE(f.Contains({-1.98, 0, 2}));
  EXPECT_FALSE(f.Contains({-2.02, 0, 2}));
  EXPECT_TRUE(f.Contains({0, 1.49, 2}));
  EXPECT_FALSE(f.Contains({0, 1.51, 2}));
  EXPECT_TRUE(f.Contains({0, -1.49, 2}));
  EXPECT_FALSE(f.Contains({0, -1.51, 2}));
  EXPECT_TRUE(f.Contains({3.9, 2.9, 3.95}));  // near the far corner
  EXPECT_FALSE(f.Contains({3.9, 3.1, 3.95}));
}

TEST(FrustumTest, ContainsMatchesProjectionOnRandomPoints) {
  Rng rng(31);
  const CameraIntrinsics K = TestCamera();
  for (int pose = 0; pose < 10; ++pose) {
    const RigidTransform X_WC = RigidTransform::FromRpy(
        rng.Uniform(-kPi, kPi), rng.Uniform(-1.5, 1.5), rng.Uniform(-kPi, kPi),
        Eigen::Vector3d(rng.Uniform(-2, 2), rng.Uniform(-2, 2), rng.Uniform(-2, 2)));
    const RigidTransform X_CW = X_WC.inverse();
    const Frustum f(K, X_WC);
    int inside = 0;
    for (int i = 0; i < 1000; ++i) {
      const Eigen::Vector3d p_C(rng.Uniform(-5, 5), rng.Uniform(-4, 4), rng.Uniform(-1, 5));
      const Eigen::Vector3d p_W = X_WC * p_C;
      if (BoundaryMargin(K, X_CW, p_W) < 1e-9) continue;
      const bool expected = ReferenceContains(K, X_CW, p_W);
      inside += expected ? 1 : 0;
      ASSERT_EQ(f.Contains(p_W), expected) << "p_C " << p_C.transpose();
    }
    EXPECT_GT(inside, 50);  // the sample exercises both outcomes
    EXPECT_LT(inside, 950);
  }
}

TEST(FrustumTest, MayIntersectHandPickedBoxes) {
  const Frustum f(TestCamera(), RigidTransform());
  EXPECT_TRUE(f.MayIntersect(Box3({-0.1, -0.1, 1}, {0.1, 0.1, 1.2})));    // inside
  EXPECT_TRUE(f.MayIntersect(Box3({-10, -10, -10}, {10, 10, 10})));       // contains all
  EXPECT_TRUE(f.MayIntersect(Box3({-0.1, -0.1, 0.3}, {0.1, 0.1, 0.6})));  // crosses near
  EXPECT_TRUE(f.MayIntersect(Box3({1.9, -0.1, 1.9}, {2.5, 0.1, 2.1})));   // crosses a side
  EXPECT_FALSE(f.MayIntersect(Box3({-1, -1, -3}, {1, 1, -0.1})));         // behind
  EXPECT_FALSE(f.MayIntersect(Box3({-1, -1, 0.1}, {1, 1, 0.4})));         // before near
  EXPECT_FALSE(f.MayIntersect(Box3({-1, -1, 4.5}, {1, 1, 6})));           // beyond far
  EXPECT_FALSE(f.MayIntersect(Box3({5, -1, 1}, {6, 1, 2})));              // off to the right
  EXPECT_FALSE(f.MayIntersect(Box3({-1, -3, 1}, {1, -2, 2})));            // above the top
  EXPECT_FALSE(f.MayIntersect(Box3()));                                   // empty
}

TEST(FrustumTest, MayIntersectIsConservative) {
  // Never false for a box that holds a point of the frustum; checked by sampling each box.
  Rng rng(77);
  const CameraIntrinsics K = TestCamera();
  const RigidTransform X_WC = RigidTransform::LookAt({0, -3, 1}, {0.2, 0, 0.9});
  const RigidTransform X_CW = X_WC.inverse();
  const Frustum f(K, X_WC);
  int rejected = 0;
  for (int i = 0; i < 400; ++i) {
    const Eigen::Vector3d center(rng.Uniform(-5, 5), rng.Uniform(-5, 3), rng.Uniform(-3, 5));
    const Eigen::Vector3d half(rng.Uniform(0, 1), rng.Uniform(0, 1), rng.Uniform(0, 1));
    const Box3 box = Box3::FromCenterAndHalfSize(center, half);
    bool holds_frustum_point = false;
    for (int s = 0; s < 100 && !holds_frustum_point; ++s) {
      const Eigen::Vector3d p =
          center + Eigen::Vector3d(rng.Uniform(-1, 1) * half.x(), rng.Uniform(-1, 1) * half.y(),
                                   rng.Uniform(-1, 1) * half.z());
      holds_frustum_point = ReferenceContains(K, X_CW, p);
    }
    // Any frustum corner inside the box also counts.
    for (const Eigen::Vector3d& c : f.corners()) holds_frustum_point |= box.Contains(c);
    const bool may = f.MayIntersect(box);
    if (holds_frustum_point) {
      ASSERT_TRUE(may) << box.ToString();
    }
    rejected += may ? 0 : 1;
  }
  EXPECT_GT(rejected, 120);  // and it does prune
}

TEST(FrustumTest, RejectsInvalidIntrinsics) {
  CameraIntrinsics K = TestCamera();
  K.width = -13;
  try {
    const Frustum f(K, RigidTransform());
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("width (-13) must be > 0"));
  }
}

}  // namespace
}  // namespace avp

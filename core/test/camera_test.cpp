#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/camera.h>
#include <avp/core/error.h>
#include <avp/core/rng.h>

namespace avp {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

double AngleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / std::numbers::pi;
}

TEST(CameraTest, RealSenseD435Values) {
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  EXPECT_EQ(K.width, 640);
  EXPECT_EQ(K.height, 480);
  EXPECT_EQ(K.fx, 615.0);
  EXPECT_EQ(K.fy, 615.0);
  EXPECT_EQ(K.cx, 319.5);  // centred: (640 - 1) / 2
  EXPECT_EQ(K.cy, 239.5);
  EXPECT_EQ(K.min_depth_m, 0.1);
  EXPECT_EQ(K.max_depth_m, 3.0);
  EXPECT_TRUE(K.Validate().ok()) << K.Validate().ToString();
  // 2 atan(320 / 615) = 54.978 deg, 2 atan(240 / 615) = 42.636 deg.
  EXPECT_NEAR(K.fov_x_deg(), 54.978, 1e-3);
  EXPECT_NEAR(K.fov_y_deg(), 42.636, 1e-3);
}

TEST(CameraTest, FromHorizontalFovNinetyDegrees) {
  const CameraIntrinsics K = CameraIntrinsics::FromHorizontalFov(640, 480, 90.0, 0.2, 5.0);
  EXPECT_EQ(K.width, 640);
  EXPECT_EQ(K.height, 480);
  EXPECT_NEAR(K.fx, 320.0, 1e-12);  // half width / tan(45 deg)
  EXPECT_EQ(K.fy, K.fx);
  EXPECT_EQ(K.cx, 319.5);
  EXPECT_EQ(K.cy, 239.5);
  EXPECT_EQ(K.min_depth_m, 0.2);
  EXPECT_EQ(K.max_depth_m, 5.0);
  EXPECT_NEAR(K.fov_x_deg(), 90.0, 1e-12);
  EXPECT_NEAR(K.fov_y_deg(), 73.7397952916880, 1e-9);  // 2 atan(240 / 320)
}

TEST(CameraTest, FromHorizontalFovGivesTheStatedFovBetweenImageEdges) {
  for (const double fov : {10.0, 30.0, 60.0, 69.4, 87.0, 120.0, 170.0}) {
    for (const int width : {1, 64, 641, 1920}) {
      const CameraIntrinsics K = CameraIntrinsics::FromHorizontalFov(width, 100, fov);
      EXPECT_NEAR(K.fov_x_deg(), fov, 1e-9) << "width " << width;
      // The rays through the outer edges of the first and last pixel span exactly the FOV.
      const Eigen::Vector3d left = K.RayDirection({-0.5, K.cy});
      const Eigen::Vector3d right = K.RayDirection({width - 0.5, K.cy});
      EXPECT_NEAR(AngleBetweenDeg(left, right), fov, 1e-9) << "width " << width;
      EXPECT_NEAR(AngleBetweenDeg(left, Eigen::Vector3d::UnitZ()), fov / 2, 1e-9);
    }
  }
}

TEST(CameraTest, FromHorizontalFovRejectsBadArguments) {
  try {
    (void)CameraIntrinsics::FromHorizontalFov(640, 480, 180.0);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("fov_x_deg = 180"));
  }
  try {
    (void)CameraIntrinsics::FromHorizontalFov(0, -4, 60.0);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("width = 0, height = -4"));
  }
  EXPECT_THROW((void)CameraIntrinsics::FromHorizontalFov(640, 480, 0.0), Error);
  EXPECT_THROW((void)CameraIntrinsics::FromHorizontalFov(640, 480, kNaN), Error);
}

TEST(CameraTest, PrincipalRayHitsThePrincipalPoint) {
  CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  K.cx = 322.25;  // off-centre, as in a real calibration
  K.cy = 236.75;
  for (const double z : {0.1, 1.0, 2.5}) {
    const auto uv = K.Project({0, 0, z});
    ASSERT_TRUE(uv.has_value());
    EXPECT_EQ(*uv, Eigen::Vector2d(322.25, 236.75));
  }
  EXPECT_EQ(K.BackProject({322.25, 236.75}, 2.0), Eigen::Vector3d(0, 0, 2));
  EXPECT_EQ(K.RayDirection({322.25, 236.75}), Eigen::Vector3d(0, 0, 1));
}

TEST(CameraTest, ProjectHandComputedPoint) {
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  // u = 615 * 0.1 / 2 + 319.5 = 350.25, v = 615 * -0.2 / 2 + 239.5 = 178: right of and above
  // the centre for x > 0 (right) and y < 0 (up).
  const auto uv = K.Project({0.1, -0.2, 2.0});
  ASSERT_TRUE(uv.has_value());
  EXPECT_NEAR(uv->x(), 350.25, 1e-12);
  EXPECT_NEAR(uv->y(), 178.0, 1e-12);
  // BackProject takes z-depth, not ray length.
  const Eigen::Vector3d p = K.BackProject({350.25, 178.0}, 2.0);
  EXPECT_NEAR(p.x(), 0.1, 1e-12);
  EXPECT_NEAR(p.y(), -0.2, 1e-12);
  EXPECT_EQ(p.z(), 2.0);
  const Eigen::Vector3d d = K.RayDirection({350.25, 178.0});
  EXPECT_EQ(d.z(), 1.0);
  EXPECT_NEAR(d.x(), 0.05, 1e-15);
}

TEST(CameraTest, ProjectRejectsPointsAtOrBehindTheCamera) {
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  EXPECT_FALSE(K.Project({0.1, 0.1, 0.0}).has_value());
  EXPECT_FALSE(K.Project({0.1, 0.1, -1.0}).has_value());
  EXPECT_FALSE(K.Project({0.1, 0.1, kNaN}).has_value());
  EXPECT_TRUE(K.Project({0.1, 0.1, 1e-9}).has_value());
}

TEST(CameraTest, ProjectBackProjectRoundTripOnRandomPoints) {
  Rng rng(2024);
  CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  K.fy = 611.5;
  K.cx = 317.3;
  K.cy = 244.9;
  for (int i = 0; i < 2000; ++i) {
    const double z = rng.Uniform(0.05, 8.0);
    const Eigen::Vector3d p_C(rng.Uniform(-z, z), rng.Uniform(-z, z), z);
    const auto uv = K.Project(p_C);
    ASSERT_TRUE(uv.has_value());
    const Eigen::Vector3d back = K.BackProject(*uv, z);
    EXPECT_LT((back - p_C).norm(), 1e-12 * z) << p_C.transpose();
    // The ray direction through uv, scaled to unit z, is p_C / z.
    EXPECT_LT((K.RayDirection(*uv) - p_C / z).norm(), 1e-12);
  }
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector2d uv(rng.Uniform(-0.5, 639.5), rng.Uniform(-0.5, 479.5));
    const double depth = rng.Uniform(0.1, 3.0);
    const Eigen::Vector3d p_C = K.BackProject(uv, depth);
    EXPECT_EQ(p_C.z(), depth);
    const auto back = K.Project(p_C);
    ASSERT_TRUE(back.has_value());
    EXPECT_LT((*back - uv).norm(), 1e-9) << uv.transpose();
  }
}

TEST(CameraTest, ImageSpansMinusHalfToSizeMinusHalf) {
  const CameraIntrinsics K = CameraIntrinsics::FromHorizontalFov(64, 48, 60.0);
  EXPECT_TRUE(K.IsInImage({-0.5, -0.5}));        // outer corner of pixel (0, 0)
  EXPECT_TRUE(K.IsInImage({0.0, 0.0}));          // centre of pixel (0, 0)
  EXPECT_TRUE(K.IsInImage({63.0, 47.0}));        // centre of the last pixel
  EXPECT_TRUE(K.IsInImage({63.4999, 47.4999}));  // just inside its outer corner
  EXPECT_FALSE(K.IsInImage({63.5, 0.0}));        // half-open on the far side
  EXPECT_FALSE(K.IsInImage({0.0, 47.5}));
  EXPECT_FALSE(K.IsInImage({-0.5001, 10.0}));
  EXPECT_FALSE(K.IsInImage({10.0, -0.5001}));
  EXPECT_FALSE(K.IsInImage({kNaN, 10.0}));
  // The image centre is the centred principal point.
  EXPECT_EQ(K.cx, (64 - 1) / 2.0);
  EXPECT_EQ(K.cy, (48 - 1) / 2.0);
  // A 3D point on the ray through the top-left image corner projects onto that corner.
  const auto corner = K.Project(K.BackProject({-0.5, -0.5}, 1.7));
  ASSERT_TRUE(corner.has_value());
  EXPECT_NEAR(corner->x(), -0.5, 1e-12);
  EXPECT_NEAR(corner->y(), -0.5, 1e-12);
}

TEST(CameraTest, KMatrix) {
  CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  K.fy = 610.0;
  Eigen::Matrix3d expected;
  expected << 615, 0, 319.5, 0, 610, 239.5, 0, 0, 1;
  EXPECT_EQ(K.K(), expected);
  // K maps a point to homogeneous pixel coordinates, consistently with Project.
  const Eigen::Vector3d p_C(0.3, -0.1, 1.2);
  const Eigen::Vector3d h = K.K() * p_C;
  EXPECT_LT((h.hnormalized() - *K.Project(p_C)).norm(), 1e-12);
}

TEST(CameraTest, ValidateAcceptsGoodIntrinsics) {
  EXPECT_TRUE(CameraIntrinsics::RealSenseD435().Validate().ok());
  EXPECT_TRUE(CameraIntrinsics::FromHorizontalFov(1, 1, 1.0).Validate().ok());
  CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  K.min_depth_m = 0.0;  // >= 0 allowed
  EXPECT_TRUE(K.Validate().ok());
}

TEST(CameraTest, AbsurdFocalLengthsAndPrincipalPointsAreNamed) {
  // A request's intrinsics as a hostile client sends them: finite, yet no camera's.
  CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  K.fx = 1e-300;
  K.cx = 1e300;
  const std::string message = K.Validate().message();
  EXPECT_THAT(message, HasSubstr("fx (1e-300 px) must be in [0.01, 1e+06] px"));
  EXPECT_THAT(message, HasSubstr("cx (1e+300 px) must be in [-1e+06, 1e+06] px"));
  // A crop's principal point may lie outside its window.
  CameraIntrinsics crop = CameraIntrinsics::RealSenseD435();
  crop.width = 8;
  crop.height = 8;
  crop.cx = -300.0;
  EXPECT_TRUE(crop.Validate().ok());
}

TEST(CameraTest, ValidateListsEveryBadFieldWithItsValue) {
  CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  K.width = -13;
  K.fx = kInf;
  const Status status = K.Validate();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(),
            "invalid camera intrinsics: width (-13) must be > 0; fx (inf) must be finite");

  CameraIntrinsics all_bad;
  all_bad.width = 0;
  all_bad.height = -2;
  all_bad.fx = -1.5;
  all_bad.fy = kNaN;
  all_bad.cx = kInf;
  all_bad.cy = -kInf;
  all_bad.min_depth_m = -0.25;
  all_bad.max_depth_m = -1.0;
  const std::string message = all_bad.Validate().message();
  EXPECT_THAT(message, StartsWith("invalid camera intrinsics: "));
  EXPECT_THAT(message, HasSubstr("width (0) must be > 0"));
  EXPECT_THAT(message, HasSubstr("height (-2) must be > 0"));
  EXPECT_THAT(message, HasSubstr("fx (-1.5)"));
  EXPECT_THAT(message, HasSubstr("fy (nan)"));
  EXPECT_THAT(message, HasSubstr("cx (inf)"));
  EXPECT_THAT(message, HasSubstr("cy (-inf)"));
  EXPECT_THAT(message, HasSubstr("min_depth_m (-0.25 m)"));
  EXPECT_THAT(message, HasSubstr("max_depth_m (-1) must be finite and > min_depth_m (-0.25)"));
  // Eight separate complaints.
  size_t separators = 0;
  for (size_t pos = message.find("; "); pos != std::string::npos;
       pos = message.find("; ", pos + 1)) {
    ++separators;
  }
  EXPECT_EQ(separators, 7u) << message;
}

TEST(CameraTest, ValidateRejectsDefaultFocalLengthAndInvertedRange) {
  const CameraIntrinsics defaults;  // fx = fy = 0 until set
  EXPECT_THAT(defaults.Validate().message(), HasSubstr("fx (0) must be > 0"));
  CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  K.min_depth_m = 3.0;
  K.max_depth_m = 3.0;
  EXPECT_THAT(K.Validate().message(),
              HasSubstr("max_depth_m (3) must be finite and > min_depth_m (3)"));
}

TEST(CameraTest, ScaledKeepsTheFieldOfViewAndPixelConvention) {
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  const CameraIntrinsics half = K.Scaled(0.5);
  EXPECT_EQ(half.width, 320);
  EXPECT_EQ(half.height, 240);
  EXPECT_EQ(half.fx, 307.5);
  EXPECT_EQ(half.cx, 159.5);  // still centred: (320 - 1) / 2
  EXPECT_EQ(half.cy, 119.5);
  EXPECT_EQ(half.min_depth_m, K.min_depth_m);
  EXPECT_EQ(half.max_depth_m, K.max_depth_m);
  EXPECT_NEAR(half.fov_x_deg(), K.fov_x_deg(), 1e-12);
  EXPECT_NEAR(half.fov_y_deg(), K.fov_y_deg(), 1e-12);

  const CameraIntrinsics twice = K.Scaled(2.0);
  EXPECT_EQ(twice.width, 1280);
  EXPECT_EQ(twice.cx, 639.5);
  EXPECT_NEAR(twice.fov_x_deg(), K.fov_x_deg(), 1e-12);

  // Every 3D point lands on the same relative image position: (u + 0.5) scales by the factor.
  Rng rng(9);
  CameraIntrinsics off = K;
  off.cx = 301.2;
  off.cy = 250.7;
  const CameraIntrinsics quarter = off.Scaled(0.25);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d p(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(0.5, 3));
    const Eigen::Vector2d uv = *off.Project(p);
    const Eigen::Vector2d uv_quarter = *quarter.Project(p);
    EXPECT_LT(((uv.array() + 0.5) * 0.25 - 0.5 - uv_quarter.array()).matrix().norm(), 1e-10);
  }
  EXPECT_TRUE(quarter.Validate().ok());
}

TEST(CameraTest, ScaledRejectsBadFactors) {
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  try {
    (void)K.Scaled(-2.0);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("factor = -2"));
  }
  EXPECT_THROW((void)K.Scaled(0.0), Error);
  EXPECT_THROW((void)K.Scaled(kNaN), Error);
}

TEST(CameraTest, EqualityAndToString) {
  CameraIntrinsics a = CameraIntrinsics::RealSenseD435();
  CameraIntrinsics b = a;
  EXPECT_EQ(a, b);
  b.cy += 1e-9;
  EXPECT_NE(a, b);
  EXPECT_EQ(ToString(a), "640x480 fx=615.000 fy=615.000 cx=319.500 cy=239.500 range=[0.1, 3] m");
}

}  // namespace
}  // namespace avp

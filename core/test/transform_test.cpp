#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <sstream>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>
#include <avp/core/transform.h>

namespace avp {
namespace {

using ::testing::ContainsRegex;
using ::testing::HasSubstr;

constexpr double kPi = std::numbers::pi;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

::testing::AssertionResult MatrixNear(const Eigen::MatrixXd& actual,
                                      const Eigen::MatrixXd& expected, double tolerance) {
  if (actual.rows() != expected.rows() || actual.cols() != expected.cols()) {
    return ::testing::AssertionFailure() << "size " << actual.rows() << "x" << actual.cols()
                                         << " != " << expected.rows() << "x" << expected.cols();
  }
  const double error = (actual - expected).cwiseAbs().maxCoeff();
  if (error <= tolerance) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure()
         << "max |difference| " << error << " > " << tolerance << "\nactual:\n"
         << actual << "\nexpected:\n"
         << expected;
}

// Elementary rotations written out by hand (right-handed, active), independent of Eigen's
// AngleAxis, which RigidTransform uses.
Eigen::Matrix3d Rx(double a) {
  Eigen::Matrix3d R;
  R << 1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a);
  return R;
}
Eigen::Matrix3d Ry(double a) {
  Eigen::Matrix3d R;
  R << std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a);
  return R;
}
Eigen::Matrix3d Rz(double a) {
  Eigen::Matrix3d R;
  R << std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1;
  return R;
}

Eigen::Matrix3d Mat(double a, double b, double c, double d, double e, double f, double g, double h,
                    double i) {
  Eigen::Matrix3d R;
  R << a, b, c, d, e, f, g, h, i;
  return R;
}

RigidTransform RandomTransform(Rng& rng) {
  const Eigen::Vector3d rpy(rng.Uniform(-kPi, kPi), rng.Uniform(-kPi / 2, kPi / 2),
                            rng.Uniform(-kPi, kPi));
  const Eigen::Vector3d p(rng.Uniform(-5, 5), rng.Uniform(-5, 5), rng.Uniform(-5, 5));
  return RigidTransform::FromRpy(rpy, p);
}

std::string ThrownMessage(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected avp::Error";
  return "";
}

// ---- FromRpy: URDF convention R = Rz(yaw) Ry(pitch) Rx(roll) ------------------------------------

TEST(TransformTest, DefaultIsIdentity) {
  const RigidTransform X;
  EXPECT_EQ(X.rotation(), Eigen::Matrix3d::Identity());
  EXPECT_EQ(X.translation(), Eigen::Vector3d::Zero());
  EXPECT_EQ(X * Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(1, 2, 3));
}

TEST(TransformTest, FromRpyQuarterTurnsMatchHandWrittenMatrices) {
  // Roll +90 deg about x: y -> z, z -> -y.
  EXPECT_TRUE(MatrixNear(RigidTransform::FromRpy(kPi / 2, 0, 0, {0, 0, 0}).rotation(),
                         Mat(1, 0, 0, 0, 0, -1, 0, 1, 0), 1e-15));
  // Pitch +90 deg about y: z -> x, x -> -z.
  EXPECT_TRUE(MatrixNear(RigidTransform::FromRpy(0, kPi / 2, 0, {0, 0, 0}).rotation(),
                         Mat(0, 0, 1, 0, 1, 0, -1, 0, 0), 1e-15));
  // Yaw +90 deg about z: x -> y, y -> -x.
  EXPECT_TRUE(MatrixNear(RigidTransform::FromRpy(0, 0, kPi / 2, {0, 0, 0}).rotation(),
                         Mat(0, -1, 0, 1, 0, 0, 0, 0, 1), 1e-15));
}

TEST(TransformTest, FromRpyAppliesRollFirstThenPitchThenYawAboutFixedAxes) {
  // Rz(90) * Rx(90) = [[0,0,1],[1,0,0],[0,1,0]]; the other order, Rx(90) * Rz(90), would give
  // [[0,-1,0],[0,0,-1],[1,0,0]].
  EXPECT_TRUE(MatrixNear(RigidTransform::FromRpy(kPi / 2, 0, kPi / 2, {0, 0, 0}).rotation(),
                         Mat(0, 0, 1, 1, 0, 0, 0, 1, 0), 1e-15));
  // The ROS camera link -> optical frame joint, rpy = (-90, 0, -90) deg: optical z (forward) is
  // the link's x, optical x (right) is the link's -y, optical y (down) is the link's -z.
  const Eigen::Matrix3d R_LO = RigidTransform::FromRpy(-kPi / 2, 0, -kPi / 2, {0, 0, 0}).rotation();
  EXPECT_TRUE(MatrixNear(R_LO, Mat(0, 0, 1, -1, 0, 0, 0, -1, 0), 1e-15));
}

TEST(TransformTest, FromRpyGeneralAnglesMatchHandComposedProduct) {
  for (const Eigen::Vector3d& rpy :
       {Eigen::Vector3d(0.1, 0.2, 0.3), Eigen::Vector3d(-2.5, 1.2, 3.0),
        Eigen::Vector3d(3.1, -1.5, -0.7)}) {
    const RigidTransform X = RigidTransform::FromRpy(rpy, Eigen::Vector3d(1, -2, 0.5));
    EXPECT_TRUE(MatrixNear(X.rotation(), Rz(rpy.z()) * Ry(rpy.y()) * Rx(rpy.x()), 1e-14))
        << rpy.transpose();
    EXPECT_EQ(X.translation(), Eigen::Vector3d(1, -2, 0.5));
  }
  // Numbers worked out by hand: cos 0.1 = 0.995004165, sin 0.1 = 0.0998334166,
  // cos 0.2 = 0.980066578, sin 0.2 = 0.198669331, cos 0.3 = 0.955336489;
  // R(0, 0) = cos(yaw) cos(pitch) = 0.955336489 * 0.980066578.
  const RigidTransform X = RigidTransform::FromRpy(0.1, 0.2, 0.3, {0, 0, 0});
  EXPECT_NEAR(X.rotation()(0, 0), 0.936293363, 1e-9);
  EXPECT_NEAR(X.rotation()(2, 0), -0.198669331, 1e-9);  // -sin(pitch)
  EXPECT_NEAR(X.rotation()(2, 1), 0.0978433950, 1e-9);  // cos(pitch) sin(roll)
}

TEST(TransformTest, PointMappingIsRotateThenTranslate) {
  // Yaw 90 deg then translate: p_W = Rz(90) p_C + t.
  const RigidTransform X_WC = RigidTransform::FromRpy(0, 0, kPi / 2, {10, 20, 30});
  EXPECT_TRUE(MatrixNear(X_WC * Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(8, 21, 33), 1e-14));
  EXPECT_TRUE(
      MatrixNear(X_WC.inverse() * Eigen::Vector3d(8, 21, 33), Eigen::Vector3d(1, 2, 3), 1e-14));
}

// ---- rpy() -------------------------------------------------------------------------------------

TEST(TransformTest, RpyRoundTripOnRandomAngles) {
  Rng rng(101);
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d rpy(rng.Uniform(-kPi, kPi), rng.Uniform(-1.55, 1.55),
                              rng.Uniform(-kPi, kPi));
    const Eigen::Vector3d back = RigidTransform::FromRpy(rpy, Eigen::Vector3d::Zero()).rpy();
    ASSERT_TRUE(MatrixNear(back, rpy, 1e-12)) << "rpy " << rpy.transpose();
  }
}

TEST(TransformTest, RpyIsInCanonicalRanges) {
  // Pitch beyond 90 deg is represented by the equivalent angles with |pitch| <= 90 deg.
  const RigidTransform X = RigidTransform::FromRpy(0.3, 2.0, -0.4, {0, 0, 0});
  const Eigen::Vector3d rpy = X.rpy();
  EXPECT_LE(std::abs(rpy.y()), kPi / 2);
  EXPECT_LE(std::abs(rpy.x()), kPi);
  EXPECT_LE(std::abs(rpy.z()), kPi);
  EXPECT_NEAR(rpy.y(), kPi - 2.0, 1e-12);
  EXPECT_TRUE(MatrixNear(RigidTransform::FromRpy(rpy, {0, 0, 0}).rotation(), X.rotation(), 1e-14));
}

TEST(TransformTest, RpyAtExactGimbalLockPutsEverythingIntoYaw) {
  // Hand-derived: at pitch +90 deg, R = [[0, sin(r - y), cos(r - y)], [0, cos(r - y),
  // -sin(r - y)], [-1, 0, 0]], so only yaw - roll is observable and the canonical answer is
  // (0, 90 deg, yaw - roll). At pitch -90 deg, R = [[0, -sin(r + y), -cos(r + y)],
  // [0, cos(r + y), -sin(r + y)], [1, 0, 0]] and the answer is (0, -90 deg, yaw + roll).
  const double a = 1.5;  // r - y
  const RigidTransform up(Mat(0, std::sin(a), std::cos(a), 0, std::cos(a), -std::sin(a), -1, 0, 0),
                          Eigen::Vector3d::Zero());
  EXPECT_TRUE(MatrixNear(up.rpy(), Eigen::Vector3d(0, kPi / 2, -a), 1e-15));
  const double b = -0.7;  // r + y
  const RigidTransform down(
      Mat(0, -std::sin(b), -std::cos(b), 0, std::cos(b), -std::sin(b), 1, 0, 0),
      Eigen::Vector3d::Zero());
  EXPECT_TRUE(MatrixNear(down.rpy(), Eigen::Vector3d(0, -kPi / 2, b), 1e-15));
}

TEST(TransformTest, RpyAtGimbalLockKeepsTheObservableAngle) {
  // From FromRpy the "zero" entries are rounding noise, so roll itself is arbitrary; pitch and
  // yaw -/+ roll are not.
  const double roll = 0.4;
  const double yaw = -1.1;
  const Eigen::Vector3d up = RigidTransform::FromRpy(roll, kPi / 2, yaw, {0, 0, 0}).rpy();
  EXPECT_NEAR(up.y(), kPi / 2, 1e-12);
  EXPECT_NEAR(std::remainder(up.z() - up.x() - (yaw - roll), 2 * kPi), 0.0, 1e-12);
  const Eigen::Vector3d down = RigidTransform::FromRpy(roll, -kPi / 2, yaw, {0, 0, 0}).rpy();
  EXPECT_NEAR(down.y(), -kPi / 2, 1e-12);
  EXPECT_NEAR(std::remainder(down.z() + down.x() - (yaw + roll), 2 * kPi), 0.0, 1e-12);
}

TEST(TransformTest, RpyNearGimbalLockRoundTripsTheRotation) {
  Rng rng(7);
  for (const double sign : {1.0, -1.0}) {
    for (const double delta : {1e-2, 1e-4, 1e-6, 1e-7, 1e-8, 3e-9, 1e-9, 1e-10, 1e-12, 0.0}) {
      for (int i = 0; i < 20; ++i) {
        const double roll = rng.Uniform(-kPi, kPi);
        const double yaw = rng.Uniform(-kPi, kPi);
        const double pitch = sign * (kPi / 2 - delta);
        const RigidTransform X = RigidTransform::FromRpy(roll, pitch, yaw, {0, 0, 0});
        const Eigen::Vector3d rpy = X.rpy();
        ASSERT_TRUE(rpy.allFinite());
        EXPECT_TRUE(
            MatrixNear(RigidTransform::FromRpy(rpy, {0, 0, 0}).rotation(), X.rotation(), 2e-15))
            << "roll " << roll << " pitch = " << sign << " * (pi/2 - " << delta << ") yaw " << yaw
            << " -> rpy " << rpy.transpose();
      }
    }
  }
}

// ---- Inverse and composition -------------------------------------------------------------------

TEST(TransformTest, InverseTimesTransformIsIdentity) {
  Rng rng(11);
  for (int i = 0; i < 200; ++i) {
    const RigidTransform X = RandomTransform(rng);
    EXPECT_TRUE(MatrixNear((X.inverse() * X).ToMatrix4(), Eigen::Matrix4d::Identity(), 1e-14));
    EXPECT_TRUE(MatrixNear((X * X.inverse()).ToMatrix4(), Eigen::Matrix4d::Identity(), 1e-14));
    EXPECT_TRUE(MatrixNear(X.inverse().ToMatrix4(), X.ToMatrix4().inverse(), 1e-13));
    EXPECT_TRUE(MatrixNear(X.inverse().inverse().ToMatrix4(), X.ToMatrix4(), 1e-14));
  }
}

TEST(TransformTest, CompositionIsAssociativeAndMatchesMatrixProduct) {
  Rng rng(12);
  for (int i = 0; i < 200; ++i) {
    const RigidTransform A = RandomTransform(rng);
    const RigidTransform B = RandomTransform(rng);
    const RigidTransform C = RandomTransform(rng);
    EXPECT_TRUE(MatrixNear(((A * B) * C).ToMatrix4(), (A * (B * C)).ToMatrix4(), 1e-13));
    EXPECT_TRUE(MatrixNear((A * B).ToMatrix4(), A.ToMatrix4() * B.ToMatrix4(), 1e-13));
    const Eigen::Vector3d p(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1));
    EXPECT_TRUE(MatrixNear((A * B) * p, A * (B * p), 1e-13));
  }
}

TEST(TransformTest, ComposedFramesMatchHandComputedPoses) {
  // A sits 1 m along W's x, turned 90 deg about z; B sits 2 m along A's y; C sits 3 m above B,
  // turned back by -90 deg.
  const RigidTransform X_WA = RigidTransform::FromRpy(0, 0, kPi / 2, {1, 0, 0});
  const RigidTransform X_AB(Eigen::Vector3d(0, 2, 0));
  const RigidTransform X_BC = RigidTransform::FromRpy(0, 0, -kPi / 2, {0, 0, 3});
  // A's y axis is W's -x, so B is at (1 - 2, 0, 0) = (-1, 0, 0), still turned 90 deg.
  const RigidTransform X_WB = X_WA * X_AB;
  EXPECT_TRUE(MatrixNear(X_WB.translation(), Eigen::Vector3d(-1, 0, 0), 1e-15));
  EXPECT_TRUE(MatrixNear(X_WB.rotation(), Mat(0, -1, 0, 1, 0, 0, 0, 0, 1), 1e-15));
  // C is 3 m above B and aligned with W.
  const RigidTransform X_WC = X_WB * X_BC;
  EXPECT_TRUE(MatrixNear(X_WC.translation(), Eigen::Vector3d(-1, 0, 3), 1e-15));
  EXPECT_TRUE(MatrixNear(X_WC.rotation(), Eigen::Matrix3d::Identity(), 1e-15));
  // A point 1 m along B's x is 1 m along W's y from B.
  EXPECT_TRUE(MatrixNear(X_WB * Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(-1, 1, 0), 1e-15));
  // And the relative pose recovered from the world poses.
  const RigidTransform X_AC = X_WA.inverse() * X_WC;
  EXPECT_TRUE(MatrixNear(X_AC.ToMatrix4(), (X_AB * X_BC).ToMatrix4(), 1e-15));
  EXPECT_TRUE(MatrixNear(X_AC.translation(), Eigen::Vector3d(0, 2, 3), 1e-15));
}

TEST(TransformTest, QuaternionConstructorNormalisesAndMatchesRotation) {
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 2).normalized()));
  const RigidTransform X(Eigen::Quaterniond(2 * q.w(), 2 * q.x(), 2 * q.y(), 2 * q.z()),
                         Eigen::Vector3d(1, 2, 3));
  EXPECT_TRUE(MatrixNear(X.rotation(), q.toRotationMatrix(), 1e-15));
  EXPECT_NEAR(X.quaternion().angularDistance(q), 0.0, 1e-12);
  EXPECT_NEAR(X.AngleTo(RigidTransform()), 0.7, 1e-12);
}

TEST(TransformTest, Matrix4AndIsometryRoundTrip) {
  Rng rng(3);
  const RigidTransform X = RandomTransform(rng);
  const Eigen::Matrix4d M = X.ToMatrix4();
  EXPECT_EQ(M.row(3), Eigen::RowVector4d(0, 0, 0, 1));
  EXPECT_EQ(Eigen::Matrix3d(M.topLeftCorner<3, 3>()), X.rotation());
  EXPECT_EQ(Eigen::Vector3d(M.topRightCorner<3, 1>()), X.translation());
  EXPECT_TRUE(MatrixNear(RigidTransform::FromMatrix4(M).ToMatrix4(), M, 0.0));
  EXPECT_TRUE(MatrixNear(X.ToIsometry().matrix(), M, 0.0));
}

TEST(TransformTest, AngleAndDistance) {
  const RigidTransform A = RigidTransform::FromRpy(0, 0, 0.3, {0, 0, 0});
  const RigidTransform B = RigidTransform::FromRpy(0, 0, -0.2, {3, 4, 0});
  EXPECT_NEAR(A.AngleTo(B), 0.5, 1e-12);
  EXPECT_NEAR(B.AngleTo(A), 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(A.TranslationDistanceTo(B), 5.0);
  EXPECT_NEAR(A.AngleTo(RigidTransform::FromRpy(kPi, 0, 0.3, {0, 0, 0})), kPi, 1e-7);
  EXPECT_TRUE(A.IsNearlyEqualTo(A, 0.0, 1e-12));
  EXPECT_TRUE(
      A.IsNearlyEqualTo(RigidTransform::FromRpy(0, 0, 0.3 + 1e-6, {1e-4, 0, 0}), 2e-4, 2e-6));
  EXPECT_FALSE(A.IsNearlyEqualTo(RigidTransform::FromRpy(0, 0, 0.3 + 1e-3, {0, 0, 0}), 1, 1e-4));
  EXPECT_FALSE(A.IsNearlyEqualTo(RigidTransform::FromRpy(0, 0, 0.3, {0.1, 0, 0}), 0.05, 1));
}

TEST(TransformTest, SmallAnglesAreResolved) {
  // A 1 microradian rotation must not be lost to rounding (acos of ~1 alone resolves ~1e-8).
  const RigidTransform A = RigidTransform::FromRpy(0.2, -0.4, 1.0, {0, 0, 0});
  const RigidTransform B = A * RigidTransform::FromRpy(1e-6, 0, 0, {0, 0, 0});
  EXPECT_NEAR(A.AngleTo(B), 1e-6, 1e-12);
  EXPECT_NEAR(A.AngleTo(A), 0.0, 1e-12);
}

TEST(TransformTest, ToStringPrintsTranslationAndRpy) {
  const RigidTransform X = RigidTransform::FromRpy(0, 0, kPi / 2, {0.1, 0.2, 0.3});
  EXPECT_EQ(X.ToString(), "xyz [0.1, 0.2, 0.3] m, rpy [0, 0, 1.5708] rad");
  std::ostringstream os;
  os << X;
  EXPECT_EQ(os.str(), X.ToString());
}

TEST(TransformTest, DegreesAndRadians) {
  EXPECT_DOUBLE_EQ(DegToRad(180.0), kPi);
  EXPECT_DOUBLE_EQ(DegToRad(-45.0), -kPi / 4);
  EXPECT_DOUBLE_EQ(RadToDeg(kPi / 2), 90.0);
  EXPECT_DOUBLE_EQ(RadToDeg(DegToRad(37.5)), 37.5);
}

// ---- LookAt ------------------------------------------------------------------------------------

TEST(TransformTest, LookAtAlongWorldXWithZUp) {
  // Looking along +x with z up: forward = +x, image right = -y (y points left), image down = -z.
  const RigidTransform X_WC =
      RigidTransform::LookAt({0, 0, 1}, {2, 0, 1}, Eigen::Vector3d::UnitZ());
  EXPECT_TRUE(MatrixNear(X_WC.rotation(), Mat(0, 0, 1, -1, 0, 0, 0, -1, 0), 1e-15));
  EXPECT_EQ(X_WC.translation(), Eigen::Vector3d(0, 0, 1));
  // The same rotation as the ROS link -> optical frame joint.
  EXPECT_TRUE(MatrixNear(X_WC.rotation(),
                         RigidTransform::FromRpy(-kPi / 2, 0, -kPi / 2, {0, 0, 0}).rotation(),
                         1e-15));
}

TEST(TransformTest, LookAtPointsZAtTargetWithImageUpAlongUpVector) {
  Rng rng(5);
  for (int i = 0; i < 500; ++i) {
    const Eigen::Vector3d eye(rng.Uniform(-3, 3), rng.Uniform(-3, 3), rng.Uniform(-3, 3));
    const Eigen::Vector3d target(rng.Uniform(-3, 3), rng.Uniform(-3, 3), rng.Uniform(-3, 3));
    Eigen::Vector3d up(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1));
    const Eigen::Vector3d forward = (target - eye).normalized();
    if ((target - eye).norm() < 0.1 || up.norm() < 0.1 ||
        forward.cross(up.normalized()).norm() < 0.1) {
      continue;
    }
    const RigidTransform X_WC = RigidTransform::LookAt(eye, target, up);
    const Eigen::Matrix3d& R = X_WC.rotation();
    ASSERT_TRUE(IsRotationMatrix(R, 1e-12));  // orthonormal and right-handed
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    EXPECT_TRUE(MatrixNear(R.col(2), forward, 1e-12));
    // Image up (-y) is the unit vector perpendicular to the view closest to `up`.
    const Eigen::Vector3d up_perp = (up - up.dot(forward) * forward).normalized();
    EXPECT_TRUE(MatrixNear(-R.col(1), up_perp, 1e-12));
    EXPECT_GT(up.dot(-R.col(1)), 0.0);
    EXPECT_TRUE(MatrixNear(R.col(0), R.col(1).cross(R.col(2)), 1e-12));  // x = y cross z
    // The target lies on the optical axis in front of the camera.
    const Eigen::Vector3d target_C = X_WC.inverse() * target;
    EXPECT_TRUE(MatrixNear(target_C, Eigen::Vector3d(0, 0, (target - eye).norm()), 1e-12));
  }
}

TEST(TransformTest, LookAtPutsWorldUpAtTheTopOfTheImage) {
  // Camera 2 m in front of a plant looking horizontally along +y; z is up.
  const RigidTransform X_WC = RigidTransform::LookAt({0, -2, 1}, {0, 0, 1});
  const RigidTransform X_CW = X_WC.inverse();
  // A point above the target is above the image centre (negative optical y).
  EXPECT_LT((X_CW * Eigen::Vector3d(0, 0, 1.5)).y(), 0.0);
  // Looking along +y with z up, +x is to the right (positive optical x).
  EXPECT_GT((X_CW * Eigen::Vector3d(0.5, 0, 1)).x(), 0.0);
  EXPECT_NEAR((X_CW * Eigen::Vector3d(0.5, 0, 1)).x(), 0.5, 1e-15);
}

TEST(TransformTest, LookAtRejectsDegenerateInput) {
  const std::string same = ThrownMessage([] {
    (void)RigidTransform::LookAt({1, 2, 3}, {1, 2, 3}, Eigen::Vector3d::UnitZ());
  });
  EXPECT_THAT(same, HasSubstr("requirement failed"));
  EXPECT_THAT(same, HasSubstr("p_WEye.transpose() = 1 2 3, p_WTarget.transpose() = 1 2 3"));
  const std::string parallel = ThrownMessage([] {
    (void)RigidTransform::LookAt({0, 0, 0}, {0, 0, -2}, Eigen::Vector3d::UnitZ());
  });
  EXPECT_THAT(parallel, HasSubstr("up_W.transpose() = 0 0 1"));
  EXPECT_THAT(parallel, HasSubstr("z.transpose() = "));
}

// ---- Bad input ---------------------------------------------------------------------------------

TEST(TransformTest, NonRotationMatrixThrowsWithItsValues) {
  const std::string scaled = ThrownMessage(
      [] { (void)RigidTransform(Mat(1, 0, 0, 0, 1, 0, 0, 0, 2.5), Eigen::Vector3d::Zero()); });
  EXPECT_THAT(scaled, HasSubstr("IsRotationMatrix"));
  EXPECT_THAT(scaled, HasSubstr("R.determinant() = 2.5"));
  EXPECT_THAT(scaled, ContainsRegex("R\\.row\\(2\\) = +0 +0 +2\\.5"));

  // A reflection is orthonormal but has determinant -1.
  const std::string mirror = ThrownMessage(
      [] { (void)RigidTransform(Mat(1, 0, 0, 0, 1, 0, 0, 0, -1), Eigen::Vector3d::Zero()); });
  EXPECT_THAT(mirror, HasSubstr("R.determinant() = -1"));

  const std::string nan = ThrownMessage(
      [] { (void)RigidTransform(Mat(1, 0, 0, 0, kNaN, 0, 0, 0, 1), Eigen::Vector3d::Zero()); });
  EXPECT_THAT(nan, HasSubstr("nan"));

  const std::string bad_p = ThrownMessage(
      [] { (void)RigidTransform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(1, kInf, 3)); });
  EXPECT_THAT(bad_p, ContainsRegex("p\\.transpose\\(\\) = +1 +inf +3"));
}

TEST(TransformTest, NonFiniteAnglesThrowWithTheirValues) {
  const std::string message = ThrownMessage([] {
    (void)RigidTransform::FromRpy(0.25, kNaN, -1.5, {0, 0, 0});
  });
  EXPECT_THAT(message, HasSubstr("roll = 0.25, pitch = nan, yaw = -1.5"));
  EXPECT_THROW((void)RigidTransform::FromRpy(0, 0, kInf, {0, 0, 0}), Error);
  EXPECT_THROW((void)RigidTransform::FromRpy(0, 0, 0, {kNaN, 0, 0}), Error);
}

TEST(TransformTest, BadQuaternionAndMatrix4Throw) {
  EXPECT_THAT(ThrownMessage([] {
                (void)RigidTransform(Eigen::Quaterniond(0, 0, 0, 0), {0, 0, 0});
              }),
              HasSubstr("q.coeffs().transpose() = 0 0 0 0"));
  EXPECT_THROW((void)RigidTransform(Eigen::Quaterniond(kNaN, 0, 0, 1), {0, 0, 0}), Error);
  Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
  M(3, 0) = 0.5;
  EXPECT_THAT(ThrownMessage([&] { (void)RigidTransform::FromMatrix4(M); }),
              ContainsRegex("last = +0\\.5 +0 +0 +1"));
  M = Eigen::Matrix4d::Identity();
  M(0, 1) = 0.1;
  EXPECT_THROW((void)RigidTransform::FromMatrix4(M), Error);
}

TEST(TransformTest, IsRotationMatrixTolerance) {
  EXPECT_TRUE(IsRotationMatrix(Rz(0.3) * Rx(-1.2)));
  EXPECT_TRUE(IsRotationMatrix(Eigen::Matrix3d::Identity() * (1 + 1e-8)));
  EXPECT_FALSE(IsRotationMatrix(Eigen::Matrix3d::Identity() * (1 + 1e-4)));
  EXPECT_TRUE(IsRotationMatrix(Eigen::Matrix3d::Identity() * (1 + 1e-4), 1e-3));
  EXPECT_FALSE(IsRotationMatrix(-Eigen::Matrix3d::Identity()));
  EXPECT_FALSE(IsRotationMatrix(Eigen::Matrix3d::Zero()));
  EXPECT_FALSE(IsRotationMatrix(Mat(1, 0, 0, 0, 1, 0, 0, 0, kInf)));
}

}  // namespace
}  // namespace avp

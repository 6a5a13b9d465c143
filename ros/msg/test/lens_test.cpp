// Lens models from CameraInfo and the rectification of raw frames (lens.h): each model read and
// refused by name and count; a synthetic 640x480 scene (a checkerboard on a tilted plane) rendered
// pinhole, distorted through plumb_bob, rational_polynomial and equidistant lenses and rectified
// back agrees with itself within a pixel, while the raw image is measurably off; depth is taken
// from the nearest pixel (no value invented, 0 kept, outside = 0); P and R honoured.
#include "avp/ros/msg/lens.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>
#include <numbers>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/ros/msg/images.h>

namespace avp::ros::msg {
namespace {

using ::testing::HasSubstr;

constexpr int kWidth = 640;
constexpr int kHeight = 480;

CameraIntrinsics Pinhole(double fx, double fy, double cx, double cy) {
  CameraIntrinsics K;
  K.width = kWidth;
  K.height = kHeight;
  K.fx = fx;
  K.fy = fy;
  K.cx = cx;
  K.cy = cy;
  K.min_depth_m = 0.2;
  K.max_depth_m = 4.0;
  return K;
}

/// The raw camera of every test: fx = fy = 600, centred.
CameraIntrinsics RawK() { return Pinhole(600.0, 600.0, 319.5, 239.5); }

CameraInfo Info(std::string model, std::vector<double> d, const CameraIntrinsics& K = RawK()) {
  Header header;
  header.frame_id = "kinect_rgb_optical_frame";
  CameraInfo info = ToCameraInfo(K, header);
  info.distortion_model = std::move(model);
  info.d = std::move(d);
  return info;
}

LensModel ModelOf(const CameraInfo& info) {
  Result<LensModel> model = LensModelFromCameraInfo(info, 0.2, 4.0);
  EXPECT_TRUE(model.ok()) << model.status().ToString();
  return model.ok() ? *model : LensModel{};
}

const std::vector<double> kPlumbBob = {-0.2, 0.05, 0.001, -0.001, 0.0};
const std::vector<double> kRational = {-0.1, 0.02, 0.001, -0.001, 0.0, 0.1, 0.0, 0.0};
const std::vector<double> kEquidistant = {0.05, 0.01, 0.0, 0.0};

/// The scene, in the camera's optical frame: a plane z = 1 + 0.6 x + 0.2 y (tilted, 1 m ahead)
/// carrying a checkerboard of 0.04 (normalised image units, 24 px at fx = 600) squares.
RgbdFrame RenderScene(const CameraIntrinsics& K) {
  RgbdFrame frame;
  frame.K = K;
  frame.rgb = ImageRgb8(K.width, K.height);
  frame.depth_m = DepthImage(K.width, K.height);
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      const double x = (u - K.cx) / K.fx, y = (v - K.cy) / K.fy;
      const bool dark =
          ((static_cast<int>(std::floor(x / 0.04)) + static_cast<int>(std::floor(y / 0.04))) & 1) !=
          0;
      frame.rgb.at(u, v, 0) = dark ? 30 : 220;
      frame.rgb.at(u, v, 1) = dark ? 60 : 200;
      frame.rgb.at(u, v, 2) = dark ? 120 : 40;
      frame.depth_m.at(u, v) = static_cast<float>(1.0 / (1.0 - 0.6 * x - 0.2 * y));
    }
  }
  return frame;
}

/// How well `got` matches `want`: the fraction of the pixels compared (`use`) whose colour (each
/// channel, +-8) and depth (+-1e-6 m) lie within the range of `want`'s 3x3 neighbourhood (i.e.
/// `want` within one pixel), and the mean depth error in mm.
struct Agreement {
  double color = 0.0;
  double depth = 0.0;
  double depth_error_mm = 0.0;
  size_t pixels = 0;
};
Agreement Compare(const RgbdFrame& got, const RgbdFrame& want,
                  const std::function<bool(int, int)>& use) {
  size_t n = 0, color_ok = 0, depth_ok = 0;
  double depth_error = 0.0;
  for (int v = 1; v < want.K.height - 1; ++v) {
    for (int u = 1; u < want.K.width - 1; ++u) {
      if (!use(u, v)) continue;
      ++n;
      bool c_ok = true;
      for (int c = 0; c < 3; ++c) {
        int lo = 255, hi = 0;
        for (int dv = -1; dv <= 1; ++dv) {
          for (int du = -1; du <= 1; ++du) {
            lo = std::min<int>(lo, want.rgb.at(u + du, v + dv, c));
            hi = std::max<int>(hi, want.rgb.at(u + du, v + dv, c));
          }
        }
        const int g = got.rgb.at(u, v, c);
        c_ok = c_ok && g >= lo - 8 && g <= hi + 8;
      }
      float lo = std::numeric_limits<float>::infinity(), hi = -lo;
      for (int dv = -1; dv <= 1; ++dv) {
        for (int du = -1; du <= 1; ++du) {
          lo = std::min(lo, want.depth_m.at(u + du, v + dv));
          hi = std::max(hi, want.depth_m.at(u + du, v + dv));
        }
      }
      const float z = got.depth_m.at(u, v);
      color_ok += c_ok;
      depth_ok += z >= lo - 1e-6f && z <= hi + 1e-6f;
      depth_error += std::abs(static_cast<double>(z) - want.depth_m.at(u, v));
    }
  }
  const double count = static_cast<double>(n);
  return {static_cast<double>(color_ok) / count, static_cast<double>(depth_ok) / count,
          1e3 * depth_error / count, n};
}

/// The largest displacement, in raw pixels, of the four rectified corners through the lens.
double CornerDisplacement(const LensModel& model) {
  double worst = 0.0;
  const double w = model.rectified.width - 1, h = model.rectified.height - 1;
  for (const Eigen::Vector2d& c : {Eigen::Vector2d(0, 0), Eigen::Vector2d(w, 0),
                                   Eigen::Vector2d(0, h), Eigen::Vector2d(w, h)}) {
    worst = std::max(worst, (RawPixelOf(model, c) - c).norm());
  }
  return worst;
}

/// Renders the scene at the rectified camera, distorts it, rectifies it back and checks both.
void ExpectRoundTrip(const LensModel& model, const std::string& name) {
  SCOPED_TRACE(name);
  RgbdFrame original = RenderScene(model.rectified);
  original.X_WC = RigidTransform::FromRpy(0.1, -0.2, 0.3, Eigen::Vector3d(1, 2, 3));
  Result<RgbdFrame> raw = Distort(original, model);
  ASSERT_TRUE(raw.ok()) << raw.status().ToString();
  EXPECT_EQ(raw->K.fx, model.K.fx);
  const Rectifier rectifier(model);
  ASSERT_FALSE(rectifier.identity());
  RgbdFrame rectified = *raw;
  ASSERT_TRUE(rectifier.Rectify(rectified).ok());
  EXPECT_EQ(rectified.K.fx, model.rectified.fx);
  EXPECT_EQ(rectified.K.cx, model.rectified.cx);
  EXPECT_EQ(rectified.K.min_depth_m, original.K.min_depth_m);
  EXPECT_TRUE(rectified.X_WC.IsNearlyEqualTo(original.X_WC, 1e-12, 1e-9));

  // The rectified pixels the raw camera sees (2 px inside its image): the others are no return.
  std::vector<bool> seen_mask(static_cast<size_t>(kWidth * kHeight));
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      const Eigen::Vector2d p = RawPixelOf(model, Eigen::Vector2d(u, v));
      seen_mask[static_cast<size_t>(v * kWidth + u)] = p.x() >= 2.0 && p.y() >= 2.0 &&
                                                       p.x() <= model.K.width - 3.0 &&
                                                       p.y() <= model.K.height - 3.0;
    }
  }
  const auto seen = [&](int u, int v) { return seen_mask[static_cast<size_t>(v * kWidth + u)]; };
  const Agreement fixed = Compare(rectified, original, seen);
  // Ignoring the lens: the raw image taken as the rectified one, outside a 200 px radius (where
  // the raw image has a return).
  RgbdFrame ignored = *raw;
  ignored.K = original.K;
  const Agreement off = Compare(ignored, original, [&](int u, int v) {
    return seen(u, v) && ignored.depth_m.at(u, v) > 0.0f &&
           std::hypot(u - original.K.cx, v - original.K.cy) >= 200.0;
  });
  const double corner = CornerDisplacement(model);
  std::printf(
      "%-20s corner displacement %.1f px; rectified within 1 px (%zu px seen): colour %.2f %%, "
      "depth %.2f %% (mean depth error %.3f mm); raw as is (r > 200 px): colour %.1f %%, depth "
      "%.1f %% (mean depth error %.2f mm)\n",
      name.c_str(), corner, fixed.pixels, 100 * fixed.color, 100 * fixed.depth,
      fixed.depth_error_mm, 100 * off.color, 100 * off.depth, off.depth_error_mm);
  EXPECT_GT(fixed.color, 0.99);
  EXPECT_GT(fixed.depth, 0.99);
  EXPECT_LT(fixed.depth_error_mm, 0.5);
  EXPECT_GT(corner, 4.0);
  EXPECT_LT(off.color, 0.8);
  EXPECT_LT(off.depth, 0.5);
}

TEST(LensModelTest, ReadsEachModel) {
  const LensModel plumb = ModelOf(Info("plumb_bob", kPlumbBob));
  EXPECT_EQ(plumb.kind, LensModel::Kind::kPlumbBob);
  EXPECT_EQ(plumb.d, kPlumbBob);
  EXPECT_EQ(plumb.K, RawK());
  EXPECT_EQ(plumb.rectified, RawK());  // P = [K | 0]
  EXPECT_EQ(plumb.R, Eigen::Matrix3d::Identity());
  EXPECT_FALSE(plumb.IsIdentity());
  EXPECT_EQ(ModelOf(Info("plumb_bob", {-0.2, 0.05, 0.001, -0.001})).d.size(), 4u);
  for (const size_t n : {8u, 12u, 14u}) {
    std::vector<double> d(n, 0.001);
    const LensModel rational = ModelOf(Info("rational_polynomial", d));
    EXPECT_EQ(rational.kind, LensModel::Kind::kRationalPolynomial);
    EXPECT_EQ(rational.d, d);
  }
  const LensModel fisheye = ModelOf(Info("equidistant", kEquidistant));
  EXPECT_EQ(fisheye.kind, LensModel::Kind::kEquidistant);
  EXPECT_EQ(ToString(fisheye.kind), "equidistant");
  EXPECT_EQ(ToString(LensModel::Kind::kNone), "none");
  // An unset P (all zero): the rectified camera is K.
  CameraInfo info = Info("plumb_bob", kPlumbBob);
  info.p = {};
  info.r = {};
  EXPECT_EQ(ModelOf(info).rectified, RawK());
  EXPECT_EQ(ModelOf(info).R, Eigen::Matrix3d::Identity());
}

TEST(LensModelTest, NoDistortionIsTheIdentity) {
  for (const CameraInfo& info : {Info("plumb_bob", {0, 0, 0, 0, 0}), Info("", {}), Info("none", {}),
                                 Info("rational_polynomial", std::vector<double>(8, 0.0)),
                                 Info("equidistant", {}), Info("plumb_bob", {0, 0, 0})}) {
    SCOPED_TRACE(info.distortion_model);
    const LensModel model = ModelOf(info);
    EXPECT_EQ(model.kind, LensModel::Kind::kNone);
    EXPECT_TRUE(model.d.empty());
    EXPECT_TRUE(model.IsIdentity());
    const Rectifier rectifier(model);
    EXPECT_TRUE(rectifier.identity());
    RgbdFrame frame = RenderScene(RawK());
    frame.depth_m.at(5, 5) = std::numeric_limits<float>::quiet_NaN();
    const RgbdFrame before = frame;
    const uint8_t* rgb = frame.rgb.data().data();
    const float* depth = frame.depth_m.data().data();
    ASSERT_TRUE(rectifier.Rectify(frame).ok());
    EXPECT_EQ(frame.rgb, before.rgb);
    EXPECT_EQ(frame.rgb.data().data(), rgb);  // nothing copied
    EXPECT_EQ(frame.depth_m.data().data(), depth);
    EXPECT_EQ(std::memcmp(frame.depth_m.data().data(), before.depth_m.data().data(),
                          frame.depth_m.data().size_bytes()),
              0);  // bit-identical, NaN included
    EXPECT_EQ(frame.K, before.K);
  }
  EXPECT_TRUE(Rectifier().identity());
}

TEST(LensModelTest, RefusesUnknownModelsByName) {
  for (const std::string name : {"kannala_brandt", "fov", "Plumb_Bob"}) {
    Result<LensModel> model = LensModelFromCameraInfo(Info(name, {0.1, 0.0, 0.0, 0.0}), 0.2, 4.0);
    ASSERT_FALSE(model.ok()) << name;
    EXPECT_EQ(model.status().code(), StatusCode::kInvalidArgument);
    const std::string m = model.status().message();
    EXPECT_THAT(m, HasSubstr("'" + name + "' is not supported"));
    EXPECT_THAT(m, HasSubstr("kinect_rgb_optical_frame"));
    EXPECT_THAT(m, HasSubstr("plumb_bob (4 or 5"));
    EXPECT_THAT(m, HasSubstr("rational_polynomial (8, 12 or 14)"));
    EXPECT_THAT(m, HasSubstr("equidistant (4)"));
  }
}

TEST(LensModelTest, RefusesWrongCoefficients) {
  const auto error = [](const CameraInfo& info) {
    Result<LensModel> model = LensModelFromCameraInfo(info, 0.2, 4.0);
    EXPECT_FALSE(model.ok());
    return model.ok() ? std::string() : model.status().message();
  };
  EXPECT_THAT(error(Info("plumb_bob", {-0.2, 0.05, 0.001})),
              HasSubstr("distortion model 'plumb_bob' with 3 coefficients [-0.2, 0.05, 0.001]: "
                        "the model takes 4 or 5"));
  EXPECT_THAT(error(Info("equidistant", {0.1, 0.0, 0.0, 0.0, 0.0})),
              HasSubstr("'equidistant' with 5 coefficients [0.1, 0, 0, 0, 0]: the model takes 4"));
  EXPECT_THAT(error(Info("rational_polynomial", kPlumbBob)),
              HasSubstr("with 5 coefficients [-0.2, 0.05, 0.001, -0.001, 0]: the model takes 8, "
                        "12 or 14"));
  EXPECT_THAT(error(Info("none", {0.1})), HasSubstr("the model takes none"));
  EXPECT_THAT(error(Info("plumb_bob", {-0.2, std::nan(""), 0.0, 0.0, 0.0})),
              HasSubstr("'plumb_bob' with 5 coefficients [-0.2, nan, 0, 0, 0]: a coefficient "
                        "is not finite"));
  // K's checks are FromCameraInfo's.
  CameraInfo info = Info("plumb_bob", kPlumbBob);
  info.k[0] = 0.0;
  EXPECT_THAT(error(info), HasSubstr("invalid intrinsics"));
  info = Info("plumb_bob", kPlumbBob);
  info.p[5] = -1.0;
  EXPECT_THAT(error(info), HasSubstr("gives invalid rectified intrinsics"));
  info = Info("plumb_bob", kPlumbBob);
  info.r[0] = 2.0;
  EXPECT_THAT(error(info), HasSubstr("is not a rotation"));
}

TEST(LensRectifyTest, PlumbBobRationalAndEquidistantRoundTrip) {
  ExpectRoundTrip(ModelOf(Info("plumb_bob", kPlumbBob)), "plumb_bob");
  ExpectRoundTrip(ModelOf(Info("rational_polynomial", kRational)), "rational_polynomial");
  ExpectRoundTrip(ModelOf(Info("equidistant", kEquidistant)), "equidistant");
}

TEST(LensRectifyTest, HonoursPAndR) {
  // P: a rectified camera with another focal length and principal point than K.
  CameraInfo info = Info("plumb_bob", kPlumbBob);
  info.p = {520.0, 0.0, 330.0, 0.0, 0.0, 530.0, 235.0, 0.0, 0.0, 0.0, 1.0, 0.0};
  const LensModel model = ModelOf(info);
  EXPECT_EQ(model.rectified, Pinhole(520.0, 530.0, 330.0, 235.0));
  EXPECT_EQ(model.K, RawK());
  ExpectRoundTrip(model, "plumb_bob, P != K");
  // R: a stereo rectification turning the camera 2 degrees about y and 1 about x.
  const Eigen::Matrix3d R =
      (Eigen::AngleAxisd(2.0 * std::numbers::pi / 180, Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(1.0 * std::numbers::pi / 180, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  for (int i = 0; i < 9; ++i) info.r[static_cast<size_t>(i)] = R(i / 3, i % 3);
  const LensModel rotated = ModelOf(info);
  EXPECT_TRUE(rotated.R.isApprox(R, 1e-12));
  ExpectRoundTrip(rotated, "plumb_bob, P != K, R");
  // No distortion, but R and P: still a remap.
  info.d = {0, 0, 0, 0, 0};
  const LensModel undistorted = ModelOf(info);
  EXPECT_EQ(undistorted.kind, LensModel::Kind::kNone);
  EXPECT_FALSE(undistorted.IsIdentity());
  ExpectRoundTrip(undistorted, "none, P != K, R");
}

TEST(LensRectifyTest, DepthIsTakenFromTheNearestPixel) {
  const LensModel model = ModelOf(Info("plumb_bob", kPlumbBob));
  // A raw depth image of steps: a near box, a far background, a no-return hole, a NaN.
  DepthImage raw(kWidth, kHeight);
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      const bool box = u >= 200 && u < 300 && v >= 150 && v < 260;
      const bool hole = u >= 400 && u < 440 && v >= 300 && v < 340;
      raw.at(u, v) = hole  ? 0.0f
                     : box ? 0.5f + 0.001f * static_cast<float>(u % 7)
                           : 2.0f + 0.01f * static_cast<float>((u + v) % 13);
    }
  }
  raw.at(320, 240) = std::numeric_limits<float>::quiet_NaN();
  std::set<uint32_t> values;
  for (const float z : raw.data()) values.insert(std::bit_cast<uint32_t>(z));
  const Rectifier rectifier(model);
  Result<DepthImage> rectified = rectifier.RectifyDepth(raw);
  ASSERT_TRUE(rectified.ok());
  size_t nan = 0, mismatched = 0;
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      const float z = rectified->at(u, v);
      EXPECT_TRUE(values.count(std::bit_cast<uint32_t>(z))) << u << "," << v << ": " << z;
      if (std::isnan(z)) {
        ++nan;
        EXPECT_LT((RawPixelOf(model, Eigen::Vector2d(u, v)) - Eigen::Vector2d(320, 240)).norm(),
                  1.0);
      }
      // The raw pixel nearest to where the lens puts this one.
      const Eigen::Vector2d p = RawPixelOf(model, Eigen::Vector2d(u, v));
      const int nu = static_cast<int>(std::floor(p.x() + 0.5));
      const int nv = static_cast<int>(std::floor(p.y() + 0.5));
      const float want = raw.Contains(nu, nv) ? raw.at(nu, nv) : 0.0f;
      mismatched += std::bit_cast<uint32_t>(want) != std::bit_cast<uint32_t>(z);
    }
  }
  EXPECT_GE(nan, 1u);
  EXPECT_LE(nan, 2u);  // the NaN does not spread: at most the pixels whose nearest it is
  // The float maps round as the double model does but for a few pixels on a half-pixel boundary.
  EXPECT_LT(mismatched, 50u) << "of " << kWidth * kHeight;
  std::printf("nearest-pixel depth: %zu of %d pixels differ from the double-precision model's\n",
              mismatched, kWidth * kHeight);
  // The no-return hole stays 0: the rectified pixels over its middle.
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      const Eigen::Vector2d p = RawPixelOf(model, Eigen::Vector2d(u, v));
      if (p.x() > 402 && p.x() < 437 && p.y() > 302 && p.y() < 337) {
        EXPECT_EQ(rectified->at(u, v), 0.0f);
      }
    }
  }
}

TEST(LensRectifyTest, RawPixelOfIsWhereTheMapsLook) {
  // Each raw pixel's depth is 1 + its index: the rectified depth names the raw pixel taken.
  DepthImage raw(kWidth, kHeight);
  for (int i = 0; i < kWidth * kHeight; ++i) raw.data()[static_cast<size_t>(i)] = 1.0f + i;
  std::vector<double> tilted = std::vector<double>(14, 0.0);
  std::copy(kRational.begin(), kRational.end(), tilted.begin());
  tilted[8] = 0.001;    // s1
  tilted[11] = -0.002;  // s4
  std::vector<double> tilt = tilted;
  tilt[12] = 0.01;  // tau_x, rad
  tilt[13] = -0.005;
  for (const CameraInfo& info :
       {Info("plumb_bob", kPlumbBob), Info("plumb_bob", {0.1, -0.05, 0.002, 0.001}),
        Info("rational_polynomial", kRational), Info("rational_polynomial", tilted),
        Info("rational_polynomial", tilt), Info("equidistant", kEquidistant)}) {
    const LensModel model = ModelOf(info);
    SCOPED_TRACE(fmt::format("{} {}", info.distortion_model, info.d.size()));
    Result<DepthImage> rectified = Rectifier(model).RectifyDepth(raw);
    ASSERT_TRUE(rectified.ok());
    double worst = 0.0;
    size_t taken = 0, inside = 0;
    for (int v = 0; v < kHeight; v += 2) {  // every other pixel each way: a tilt costs 2 us each
      for (int u = 0; u < kWidth; u += 2) {
        const Eigen::Vector2d p = RawPixelOf(model, Eigen::Vector2d(u, v));
        inside += p.x() >= -0.5 && p.y() >= -0.5 && p.x() < kWidth - 0.5 && p.y() < kHeight - 0.5;
        const float z = rectified->at(u, v);
        if (z == 0.0f) continue;
        ++taken;
        const int i = static_cast<int>(z) - 1;
        const Eigen::Vector2d d = p - Eigen::Vector2d(i % kWidth, i / kWidth);
        worst = std::max(worst, d.cwiseAbs().maxCoeff());
      }
    }
    EXPECT_GT(taken, 62000u);
    EXPECT_NEAR(static_cast<double>(taken), static_cast<double>(inside), 10.0);
    EXPECT_LE(worst, 0.501);  // the nearest raw pixel to where the lens puts it
  }
}

TEST(LensRectifyTest, PixelsOutsideTheRawImageAreNoReturn) {
  // Pincushion: the rectified corners look past the raw image.
  const LensModel model = ModelOf(Info("plumb_bob", {0.3, 0.1, 0.0, 0.0, 0.0}));
  RgbdFrame frame;
  frame.K = model.K;
  frame.rgb = ImageRgb8(kWidth, kHeight, 200);
  frame.depth_m = DepthImage(kWidth, kHeight, 1.5f);
  ASSERT_TRUE(Rectifier(model).Rectify(frame).ok());
  size_t outside = 0, zero = 0, disagree = 0;
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      const Eigen::Vector2d p = RawPixelOf(model, Eigen::Vector2d(u, v));
      const bool out =
          p.x() < -0.5 || p.x() >= kWidth - 0.5 || p.y() < -0.5 || p.y() >= kHeight - 0.5;
      const bool far_out = p.x() < -1.0 || p.x() > kWidth || p.y() < -1.0 || p.y() > kHeight;
      outside += out;
      zero += frame.depth_m.at(u, v) == 0.0f;
      disagree += out != (frame.depth_m.at(u, v) == 0.0f);
      if (far_out) {
        EXPECT_EQ(frame.rgb.at(u, v, 1), 0);
      }
      if (!out) {
        EXPECT_EQ(frame.depth_m.at(u, v), 1.5f);
      }
    }
  }
  std::printf("pincushion: %zu rectified pixels look outside the raw image, %zu have depth 0\n",
              outside, zero);
  EXPECT_GT(outside, 1000u);
  EXPECT_LT(disagree, 20u);
  EXPECT_EQ(frame.depth_m.at(0, 0), 0.0f);
  EXPECT_EQ(frame.rgb.at(0, 0, 0), 0);
}

TEST(LensRectifyTest, RefusesFramesOfAnotherCamera) {
  const Rectifier rectifier(ModelOf(Info("plumb_bob", kPlumbBob)));
  RgbdFrame small = RenderScene(Pinhole(300.0, 300.0, 159.5, 119.5));
  small.K.width = 320;
  Status s = rectifier.Rectify(small);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("are not the lens model's"));
  RgbdFrame frame = RenderScene(RawK());
  frame.rgb = ImageRgb8(320, 240);
  s = rectifier.Rectify(frame);
  EXPECT_THAT(s.message(), HasSubstr("image size 320x240 is not the camera's 640x480"));
  EXPECT_FALSE(rectifier.RectifyColor(ImageRgb8(320, 240)).ok());
  // Distort wants the rectified camera.
  const LensModel model = ModelOf(Info("plumb_bob", kPlumbBob));
  EXPECT_FALSE(Distort(RenderScene(Pinhole(500.0, 500.0, 319.5, 239.5)), model).ok());
}

TEST(LensRectifyTest, ColourAndDepthAloneAsInTheFrame) {
  const LensModel model = ModelOf(Info("equidistant", kEquidistant));
  const Rectifier rectifier(model);
  RgbdFrame frame = RenderScene(RawK());
  Result<ImageRgb8> rgb = rectifier.RectifyColor(frame.rgb);
  Result<DepthImage> depth = rectifier.RectifyDepth(frame.depth_m);
  ASSERT_TRUE(rgb.ok() && depth.ok());
  ASSERT_TRUE(rectifier.Rectify(frame).ok());
  EXPECT_EQ(*rgb, frame.rgb);
  EXPECT_EQ(*depth, frame.depth_m);
  const Rectifier copy = rectifier;  // shares the maps
  EXPECT_FALSE(copy.identity());
  EXPECT_EQ(copy.model().d, kEquidistant);
}

}  // namespace
}  // namespace avp::ros::msg

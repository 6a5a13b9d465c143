#include "avp/ros/msg/lens.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <avp/core/text.h>
#include <avp/core/transform.h>
#include <avp/ros/msg/images.h>

namespace avp::ros::msg {
namespace {

/// The coefficient counts each model takes.
struct ModelSpec {
  std::string_view name;
  LensModel::Kind kind;
  std::array<size_t, 3> counts;  ///< 0 = unused slot (kNone takes none)
};
constexpr std::array<ModelSpec, 5> kSpecs = {{
    {"plumb_bob", LensModel::Kind::kPlumbBob, {4, 5, 0}},
    {"rational_polynomial", LensModel::Kind::kRationalPolynomial, {8, 12, 14}},
    {"equidistant", LensModel::Kind::kEquidistant, {4, 0, 0}},
    {"", LensModel::Kind::kNone, {0, 0, 0}},
    {"none", LensModel::Kind::kNone, {0, 0, 0}},
}};

/// R and P are optional in a CameraInfo: all zero = unset.
template <size_t N>
bool AllZero(const std::array<double, N>& a) {
  return std::all_of(a.begin(), a.end(), [](double x) { return x == 0.0; });
}

/// At most the first 16 coefficients, "[k1, k2, ...]".
std::string FormatCoefficients(const std::vector<double>& d) {
  const size_t n = std::min<size_t>(d.size(), 16);
  return fmt::format("[{}{}]", fmt::join(d.begin(), d.begin() + static_cast<ptrdiff_t>(n), ", "),
                     d.size() > n ? ", ..." : "");
}

/// "4 or 5", "8, 12 or 14", "none".
std::string CountsOf(const ModelSpec& spec) {
  std::vector<size_t> counts;
  for (const size_t n : spec.counts) {
    if (n != 0) counts.push_back(n);
  }
  if (counts.empty()) return "none";
  if (counts.size() == 1) return fmt::format("{}", counts[0]);
  return fmt::format("{} or {}", fmt::join(counts.begin(), counts.end() - 1, ", "), counts.back());
}

Status DistortionOf(const CameraInfo& info, LensModel& model) {
  const std::string frame = QuoteText(info.header.frame_id);
  const auto spec = std::find_if(kSpecs.begin(), kSpecs.end(), [&](const ModelSpec& s) {
    return s.name == info.distortion_model;
  });
  if (spec == kSpecs.end()) {
    return InvalidArgumentError(
        fmt::format("CameraInfo (frame {}): distortion model {} is not supported ({})", frame,
                    QuoteText(info.distortion_model), kLensModels));
  }
  const std::vector<double>& d = info.d;
  const auto bad = [&](std::string_view what) {
    return InvalidArgumentError(
        fmt::format("CameraInfo (frame {}): distortion model {} with {} coefficients {}: {}", frame,
                    QuoteText(info.distortion_model), d.size(), FormatCoefficients(d), what));
  };
  if (!std::all_of(d.begin(), d.end(), [](double x) { return std::isfinite(x); })) {
    return bad("a coefficient is not finite");
  }
  model.kind = LensModel::Kind::kNone;
  model.d.clear();
  if (std::all_of(d.begin(), d.end(), [](double x) { return x == 0.0; })) return Status::Ok();
  if (std::find(spec->counts.begin(), spec->counts.end(), d.size()) == spec->counts.end()) {
    return bad(fmt::format("the model takes {}", CountsOf(*spec)));
  }
  model.kind = spec->kind;
  model.d = d;
  return Status::Ok();
}

Result<Eigen::Matrix3d> RotationOf(const CameraInfo& info) {
  if (AllZero(info.r)) return Eigen::Matrix3d(Eigen::Matrix3d::Identity());
  const Eigen::Matrix3d R =
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(info.r.data());
  if (!R.allFinite() || !IsRotationMatrix(R, 1e-5)) {
    return InvalidArgumentError(fmt::format("CameraInfo (frame {}): R [{}] is not a rotation",
                                            QuoteText(info.header.frame_id),
                                            fmt::join(info.r, ", ")));
  }
  if ((R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <= 1e-12) {
    return Eigen::Matrix3d(Eigen::Matrix3d::Identity());
  }
  return Eigen::Quaterniond(R).normalized().toRotationMatrix();
}

Result<CameraIntrinsics> RectifiedOf(const CameraInfo& info, const CameraIntrinsics& K) {
  CameraIntrinsics rectified = K;
  if (AllZero(info.p)) return rectified;
  rectified.fx = info.p[0];
  rectified.fy = info.p[5];
  rectified.cx = info.p[2];
  rectified.cy = info.p[6];
  if (Status s = rectified.Validate(); !s.ok()) {
    return InvalidArgumentError(
        fmt::format("CameraInfo (frame {}): P [{}] gives invalid rectified intrinsics: {}",
                    QuoteText(info.header.frame_id), fmt::join(info.p, ", "), s.message()));
  }
  return rectified;
}

/// Same size and pinhole (fx, fy, cx, cy within 1e-6 px); the depth range is not compared.
bool SameGeometry(const CameraIntrinsics& a, const CameraIntrinsics& b) {
  constexpr double kTol = 1e-6;
  return a.width == b.width && a.height == b.height && std::abs(a.fx - b.fx) <= kTol &&
         std::abs(a.fy - b.fy) <= kTol && std::abs(a.cx - b.cx) <= kTol &&
         std::abs(a.cy - b.cy) <= kTol;
}

Status CheckCamera(const CameraIntrinsics& got, const CameraIntrinsics& want,
                   std::string_view what) {
  if (SameGeometry(got, want)) return Status::Ok();
  return InvalidArgumentError(fmt::format("{}: frame intrinsics {} are not the lens model's {}",
                                          what, ToString(got), ToString(want)));
}

template <class T, int C>
Status CheckSize(const ::avp::Image<T, C>& image, const CameraIntrinsics& K,
                 std::string_view what) {
  if (image.SameSizeAs(K.width, K.height)) return Status::Ok();
  return InvalidArgumentError(fmt::format("{}: image size {}x{} is not the camera's {}x{}", what,
                                          image.width(), image.height(), K.width, K.height));
}

cv::Mat CameraMatrix(const CameraIntrinsics& K) {
  return (cv::Mat_<double>(3, 3) << K.fx, 0.0, K.cx, 0.0, K.fy, K.cy, 0.0, 0.0, 1.0);
}

cv::Mat Coefficients(const LensModel& model) {
  if (model.kind == LensModel::Kind::kNone) return cv::Mat();
  return cv::Mat(1, static_cast<int>(model.d.size()), CV_64F, const_cast<double*>(model.d.data()))
      .clone();
}

cv::Mat RotationMatrix(const Eigen::Matrix3d& R) {
  cv::Mat m(3, 3, CV_64F);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m.at<double>(i, j) = R(i, j);
  }
  return m;
}

/// The raw pixel under continuous coordinates (x, y), or -1 when they fall outside the image
/// ([-0.5, size - 0.5) each way; NaN too).
int32_t NearestIndex(float x, float y, int w, int h) {
  if (!(x >= -0.5f && x < static_cast<float>(w) - 0.5f && y >= -0.5f &&
        y < static_cast<float>(h) - 0.5f)) {
    return -1;
  }
  const int u = std::min(static_cast<int>(std::floor(x + 0.5f)), w - 1);
  const int v = std::min(static_cast<int>(std::floor(y + 0.5f)), h - 1);
  return v * w + u;
}

/// Per output pixel, the source position (CV_32FC1 x and y maps) as a bilinear fixed-point map
/// for the colour and a nearest-pixel index table for the depth.
struct PixelMaps {
  cv::Mat color1, color2;        ///< CV_16SC2 + CV_16UC1 (cv::convertMaps)
  std::vector<int32_t> nearest;  ///< source pixel index, or -1 outside the source
};

PixelMaps MakePixelMaps(const cv::Mat& map_x, const cv::Mat& map_y, int source_w, int source_h) {
  PixelMaps maps;
  cv::convertMaps(map_x, map_y, maps.color1, maps.color2, CV_16SC2);
  maps.nearest.resize(static_cast<size_t>(map_x.rows) * static_cast<size_t>(map_x.cols));
  for (int v = 0; v < map_x.rows; ++v) {
    const float* xs = map_x.ptr<float>(v);
    const float* ys = map_y.ptr<float>(v);
    int32_t* out = maps.nearest.data() + static_cast<size_t>(v) * static_cast<size_t>(map_x.cols);
    for (int u = 0; u < map_x.cols; ++u) out[u] = NearestIndex(xs[u], ys[u], source_w, source_h);
  }
  return maps;
}

ImageRgb8 RemapColor(const ImageRgb8& source, const PixelMaps& maps) {
  ImageRgb8 out(maps.color1.cols, maps.color1.rows);
  const cv::Mat src(source.height(), source.width(), CV_8UC3,
                    const_cast<uint8_t*>(source.data().data()));
  cv::Mat dst(out.height(), out.width(), CV_8UC3, out.data().data());
  cv::remap(src, dst, maps.color1, maps.color2, cv::INTER_LINEAR, cv::BORDER_CONSTANT,
            cv::Scalar::all(0));
  return out;
}

DepthImage RemapDepth(const DepthImage& source, const PixelMaps& maps) {
  DepthImage out(maps.color1.cols, maps.color1.rows);
  const std::span<const float> in = source.data();
  const std::span<float> dst = out.data();
  for (size_t i = 0; i < dst.size(); ++i) {
    const int32_t j = maps.nearest[i];
    dst[i] = j < 0 ? 0.0f : in[static_cast<size_t>(j)];
  }
  return out;
}

/// Raw pixel positions of rays in the raw camera's frame (z > 0), through the lens.
std::vector<cv::Point2d> ProjectThroughLens(const LensModel& model,
                                            const std::vector<cv::Point3d>& rays) {
  std::vector<cv::Point2d> pixels;
  if (rays.empty()) return pixels;
  const cv::Mat zero = cv::Mat::zeros(3, 1, CV_64F);
  if (model.kind == LensModel::Kind::kEquidistant) {
    cv::fisheye::projectPoints(rays, pixels, zero, zero, CameraMatrix(model.K),
                               Coefficients(model));
  } else {
    cv::projectPoints(rays, zero, zero, CameraMatrix(model.K), Coefficients(model), pixels);
  }
  return pixels;
}

/// A normalised point (x, y, 1) through the lens, by OpenCV's formulas (cv::projectPoints,
/// cv::fisheye::projectPoints) less the sensor tilt of 14 coefficients.
Eigen::Vector2d DistortNormalised(const LensModel& model, double x, double y) {
  const auto k = [&](size_t i) { return i < model.d.size() ? model.d[i] : 0.0; };
  const double r2 = x * x + y * y;
  if (model.kind == LensModel::Kind::kNone) return {x, y};
  if (model.kind == LensModel::Kind::kEquidistant) {
    const double r = std::sqrt(r2);
    if (r < 1e-8) return {x, y};
    const double theta = std::atan(r), t2 = theta * theta;
    const double theta_d = theta * (1.0 + t2 * (k(0) + t2 * (k(1) + t2 * (k(2) + t2 * k(3)))));
    return {x * theta_d / r, y * theta_d / r};
  }
  const double r4 = r2 * r2, r6 = r4 * r2;
  const double radial =
      (1.0 + k(0) * r2 + k(1) * r4 + k(4) * r6) / (1.0 + k(5) * r2 + k(6) * r4 + k(7) * r6);
  const double p1 = k(2), p2 = k(3);
  return {x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) + k(8) * r2 + k(9) * r4,
          y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y + k(10) * r2 + k(11) * r4};
}

}  // namespace

struct Rectifier::Maps : PixelMaps {};

bool LensModel::IsIdentity() const {
  return kind == Kind::kNone && R == Eigen::Matrix3d::Identity() && SameGeometry(rectified, K);
}

bool LensModel::SameLensAs(const LensModel& other) const {
  return kind == other.kind && d == other.d && R == other.R && SameGeometry(K, other.K) &&
         SameGeometry(rectified, other.rectified);
}

std::string_view ToString(LensModel::Kind kind) {
  for (const ModelSpec& s : kSpecs) {
    if (s.kind == kind && !s.name.empty()) return s.name;
  }
  return "none";
}

Result<LensModel> LensModelFromCameraInfo(const CameraInfo& info, double min_depth_m,
                                          double max_depth_m) {
  LensModel model;
  AVP_ASSIGN_OR_RETURN(model.K, FromCameraInfo(info, min_depth_m, max_depth_m));
  AVP_RETURN_IF_ERROR(DistortionOf(info, model));
  AVP_ASSIGN_OR_RETURN(model.R, RotationOf(info));
  AVP_ASSIGN_OR_RETURN(model.rectified, RectifiedOf(info, model.K));
  return model;
}

Eigen::Vector2d RawPixelOf(const LensModel& model, const Eigen::Vector2d& rectified_uv) {
  const CameraIntrinsics& P = model.rectified;
  const Eigen::Vector3d ray_rect((rectified_uv.x() - P.cx) / P.fx, (rectified_uv.y() - P.cy) / P.fy,
                                 1.0);
  const Eigen::Vector3d ray = model.R.transpose() * ray_rect;
  if (!(ray.z() > 0.0)) return Eigen::Vector2d::Constant(std::nan(""));
  if (model.d.size() == 14 && (model.d[12] != 0.0 || model.d[13] != 0.0)) {
    // A tilted sensor: OpenCV's projection (a few microseconds).
    const std::vector<cv::Point2d> pixel =
        ProjectThroughLens(model, {cv::Point3d(ray.x(), ray.y(), ray.z())});
    return {pixel[0].x, pixel[0].y};
  }
  const Eigen::Vector2d xy = DistortNormalised(model, ray.x() / ray.z(), ray.y() / ray.z());
  return {model.K.fx * xy.x() + model.K.cx, model.K.fy * xy.y() + model.K.cy};
}

Rectifier::Rectifier() = default;

Rectifier::Rectifier(LensModel model) : model_(std::move(model)) {
  if (model_.IsIdentity()) return;
  const CameraIntrinsics& K = model_.K;
  const cv::Size size(model_.rectified.width, model_.rectified.height);
  cv::Mat map_x, map_y;
  if (model_.kind == LensModel::Kind::kEquidistant) {
    cv::fisheye::initUndistortRectifyMap(CameraMatrix(K), Coefficients(model_),
                                         RotationMatrix(model_.R), CameraMatrix(model_.rectified),
                                         size, CV_32FC1, map_x, map_y);
  } else {
    cv::initUndistortRectifyMap(CameraMatrix(K), Coefficients(model_), RotationMatrix(model_.R),
                                CameraMatrix(model_.rectified), size, CV_32FC1, map_x, map_y);
  }
  maps_ = std::make_shared<const Maps>(Maps{MakePixelMaps(map_x, map_y, K.width, K.height)});
}

Result<ImageRgb8> Rectifier::RectifyColor(const ImageRgb8& raw) const {
  AVP_RETURN_IF_ERROR(CheckSize(raw, model_.K, "rectify colour"));
  if (identity()) return raw;
  return RemapColor(raw, *maps_);
}

Result<DepthImage> Rectifier::RectifyDepth(const DepthImage& raw) const {
  AVP_RETURN_IF_ERROR(CheckSize(raw, model_.K, "rectify depth"));
  if (identity()) return raw;
  return RemapDepth(raw, *maps_);
}

Status Rectifier::Rectify(RgbdFrame& frame) const {
  AVP_RETURN_IF_ERROR(CheckCamera(frame.K, model_.K, "rectify"));
  AVP_RETURN_IF_ERROR(CheckSize(frame.rgb, model_.K, "rectify colour"));
  AVP_RETURN_IF_ERROR(CheckSize(frame.depth_m, model_.K, "rectify depth"));
  if (identity()) return Status::Ok();
  frame.rgb = RemapColor(frame.rgb, *maps_);
  frame.depth_m = RemapDepth(frame.depth_m, *maps_);
  const double min_depth_m = frame.K.min_depth_m, max_depth_m = frame.K.max_depth_m;
  frame.K = model_.rectified;
  frame.K.min_depth_m = min_depth_m;
  frame.K.max_depth_m = max_depth_m;
  if (model_.R != Eigen::Matrix3d::Identity()) {
    frame.X_WC = frame.X_WC * RigidTransform(model_.R.transpose(), Eigen::Vector3d::Zero());
  }
  return Status::Ok();
}

namespace {

/// A map position far outside any image: no colour (bilinear taps all outside) and no depth.
constexpr float kOutside = -100.0f;

/// Per raw pixel, its position in the rectified image (CV_32FC1 x and y maps); kOutside where
/// the undistortion does not return to the pixel through the lens (beyond the model's range).
std::pair<cv::Mat, cv::Mat> UndistortionMaps(const LensModel& model) {
  const int w = model.K.width, h = model.K.height;
  std::vector<cv::Point2d> raw;
  raw.reserve(static_cast<size_t>(w) * static_cast<size_t>(h));
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) raw.emplace_back(u, v);
  }
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-10);
  const cv::Mat K = CameraMatrix(model.K), D = Coefficients(model), R = RotationMatrix(model.R);
  const cv::Mat P = CameraMatrix(model.rectified);
  std::vector<cv::Point2d> rect;
  if (model.kind == LensModel::Kind::kEquidistant) {
    cv::fisheye::undistortPoints(raw, rect, K, D, R, P, criteria);
  } else {
    cv::undistortPoints(raw, rect, K, D, R, P, criteria);
  }
  // Back through the lens: the rays of the rectified positions must land on their raw pixels.
  const CameraIntrinsics& Pi = model.rectified;
  const Eigen::Matrix3d Rt = model.R.transpose();
  std::vector<cv::Point3d> rays(rect.size());
  for (size_t i = 0; i < rect.size(); ++i) {
    const Eigen::Vector3d r =
        Rt * Eigen::Vector3d((rect[i].x - Pi.cx) / Pi.fx, (rect[i].y - Pi.cy) / Pi.fy, 1.0);
    rays[i] = r.z() > 0.0 ? cv::Point3d(r.x(), r.y(), r.z()) : cv::Point3d(0.0, 0.0, -1.0);
  }
  const std::vector<cv::Point2d> back = ProjectThroughLens(model, rays);
  cv::Mat map_x(h, w, CV_32FC1), map_y(h, w, CV_32FC1);
  for (size_t i = 0; i < rect.size(); ++i) {
    const bool ok =
        rays[i].z > 0.0 && std::hypot(back[i].x - raw[i].x, back[i].y - raw[i].y) < 1e-3;
    const int u = static_cast<int>(i % static_cast<size_t>(w));
    const int v = static_cast<int>(i / static_cast<size_t>(w));
    map_x.at<float>(v, u) = ok ? static_cast<float>(rect[i].x) : kOutside;
    map_y.at<float>(v, u) = ok ? static_cast<float>(rect[i].y) : kOutside;
  }
  return {map_x, map_y};
}

}  // namespace

Result<RgbdFrame> Distort(const RgbdFrame& rectified, const LensModel& model) {
  AVP_RETURN_IF_ERROR(CheckCamera(rectified.K, model.rectified, "distort"));
  AVP_RETURN_IF_ERROR(CheckSize(rectified.rgb, model.rectified, "distort colour"));
  AVP_RETURN_IF_ERROR(CheckSize(rectified.depth_m, model.rectified, "distort depth"));
  RgbdFrame raw = rectified;
  raw.K = model.K;
  raw.K.min_depth_m = rectified.K.min_depth_m;
  raw.K.max_depth_m = rectified.K.max_depth_m;
  if (model.IsIdentity()) return raw;
  const auto [map_x, map_y] = UndistortionMaps(model);
  const PixelMaps maps = MakePixelMaps(map_x, map_y, model.rectified.width, model.rectified.height);
  raw.rgb = RemapColor(rectified.rgb, maps);
  raw.depth_m = RemapDepth(rectified.depth_m, maps);
  if (model.R != Eigen::Matrix3d::Identity()) {
    raw.X_WC = rectified.X_WC * RigidTransform(model.R, Eigen::Vector3d::Zero());
  }
  return raw;
}

}  // namespace avp::ros::msg

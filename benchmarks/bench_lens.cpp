// Lens rectification of raw RGB-D frames (ros/msg/lens.h), per frame, against the alternative of
// projecting depth through the lens model.
//
// Cases (args: width, height; plumb_bob k1 = -0.2, k2 = 0.05, p1 = 0.001, p2 = -0.001, fx = fy
// = 0.9375 width, centred):
//   BM_BuildRectifier        the maps, once per camera (cv::initUndistortRectifyMap + tables)
//   BM_Rectify               one raw frame rectified in place: colour bilinear, depth nearest
//   BM_RectifyColor          the colour remap alone (cv::remap, fixed-point maps)
//   BM_RectifyDepth          the depth gather alone (nearest-pixel index table)
//   BM_BuildRayTable         the alternative's table: each raw pixel's undistorted ray (x, y, 1),
//                            once per camera (cv::undistortPoints)
//   BM_BackProjectPinhole    the integrator's back-projection of a rectified frame:
//                            p = ((u - cx) / fx z, (v - cy) / fy z, z)
//   BM_BackProjectRayTable   the same through the ray table: p = (x[i] z, y[i] z, z); the
//                            difference to BM_BackProjectPinhole is what projecting through the
//                            model costs per frame (the integrator's carving, which projects
//                            voxels into the image, would need the forward model too)
//   BM_RawPixelOf            the forward model for one point (closed form)
//   BM_Distort               the inverse, for simulation only (iterative undistortion per pixel)
// cv::remap runs on OpenCV's own threads (OPENCV_FOR_THREADS_NUM=1 for one). BM_Rectify writes
// into freshly allocated images, so it includes the page faults of new memory where the
// allocator hands large blocks back to the system after each frame (glibc's defaults); the colour
// and depth cases alone reuse the memory of the previous iteration.

#include <vector>

#include <Eigen/Core>
#include <benchmark/benchmark.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <avp/core/rgbd_frame.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/lens.h>

#include "bench_report.h"

namespace avp::ros::msg {
namespace {

LensModel Model(const benchmark::State& state) {
  CameraIntrinsics K;
  K.width = static_cast<int>(state.range(0));
  K.height = static_cast<int>(state.range(1));
  K.fx = K.fy = 0.9375 * K.width;  // 600 px at 640 wide
  K.cx = (K.width - 1) / 2.0;
  K.cy = (K.height - 1) / 2.0;
  CameraInfo info = ToCameraInfo(K, Header{});
  info.d = {-0.2, 0.05, 0.001, -0.001, 0.0};
  return LensModelFromCameraInfo(info, 0.1, 5.0).value();
}

/// A raw frame of the model's camera: a gradient and depth 0.5 - 2.5 m, a tenth no return.
RgbdFrame RawFrame(const LensModel& model) {
  RgbdFrame frame;
  frame.K = model.K;
  frame.rgb = ImageRgb8(model.K.width, model.K.height);
  frame.depth_m = DepthImage(model.K.width, model.K.height);
  for (int v = 0; v < model.K.height; ++v) {
    for (int u = 0; u < model.K.width; ++u) {
      for (int c = 0; c < 3; ++c) frame.rgb.at(u, v, c) = static_cast<uint8_t>((u + v * c) & 255);
      frame.depth_m.at(u, v) = (u + v) % 10 == 0 ? 0.0f
                                                 : 0.5f + 2.0f * static_cast<float>(u) /
                                                              static_cast<float>(model.K.width);
    }
  }
  return frame;
}

void SetPixels(benchmark::State& state) {
  state.counters["Mpx/s"] =
      benchmark::Counter(static_cast<double>(state.range(0) * state.range(1)) * 1e-6,
                         benchmark::Counter::kIsIterationInvariantRate);
}

void BM_BuildRectifier(benchmark::State& state) {
  const LensModel model = Model(state);
  for (auto _ : state) {
    const Rectifier rectifier(model);
    benchmark::DoNotOptimize(&rectifier);
  }
}

void BM_Rectify(benchmark::State& state) {
  const LensModel model = Model(state);
  const Rectifier rectifier(model);
  const RgbdFrame raw = RawFrame(model);
  for (auto _ : state) {
    state.PauseTiming();
    RgbdFrame frame = raw;
    state.ResumeTiming();
    if (!rectifier.Rectify(frame).ok()) state.SkipWithError("Rectify failed");
    benchmark::DoNotOptimize(frame.depth_m.data().data());
  }
  SetPixels(state);
}

void BM_RectifyColor(benchmark::State& state) {
  const LensModel model = Model(state);
  const Rectifier rectifier(model);
  const RgbdFrame raw = RawFrame(model);
  for (auto _ : state) {
    Result<ImageRgb8> rgb = rectifier.RectifyColor(raw.rgb);
    benchmark::DoNotOptimize(rgb.value().data().data());
  }
  SetPixels(state);
}

void BM_RectifyDepth(benchmark::State& state) {
  const LensModel model = Model(state);
  const Rectifier rectifier(model);
  const RgbdFrame raw = RawFrame(model);
  for (auto _ : state) {
    Result<DepthImage> depth = rectifier.RectifyDepth(raw.depth_m);
    benchmark::DoNotOptimize(depth.value().data().data());
  }
  SetPixels(state);
}

/// Each raw pixel's undistorted ray (x, y, 1), as (x, y) pairs, row-major.
std::vector<cv::Point2f> RayTable(const LensModel& model) {
  std::vector<cv::Point2f> pixels;
  for (int v = 0; v < model.K.height; ++v) {
    for (int u = 0; u < model.K.width; ++u) {
      pixels.emplace_back(static_cast<float>(u), static_cast<float>(v));
    }
  }
  const cv::Mat K =
      (cv::Mat_<double>(3, 3) << model.K.fx, 0, model.K.cx, 0, model.K.fy, model.K.cy, 0, 0, 1);
  std::vector<cv::Point2f> rays;
  cv::undistortPoints(pixels, rays, K, model.d);
  return rays;
}

void BM_BuildRayTable(benchmark::State& state) {
  const LensModel model = Model(state);
  for (auto _ : state) {
    std::vector<cv::Point2f> table = RayTable(model);
    benchmark::DoNotOptimize(table.data());
  }
}

void BM_BackProjectPinhole(benchmark::State& state) {
  const LensModel model = Model(state);
  const DepthImage depth = RawFrame(model).depth_m;
  const CameraIntrinsics& K = model.rectified;
  std::vector<Eigen::Vector3f> points;
  points.reserve(depth.num_pixels());
  for (auto _ : state) {
    points.clear();
    for (int v = 0; v < depth.height(); ++v) {
      for (int u = 0; u < depth.width(); ++u) {
        const float z = depth.at(u, v);
        if (!(z > 0.0f)) continue;
        points.emplace_back(static_cast<float>((u - K.cx) / K.fx) * z,
                            static_cast<float>((v - K.cy) / K.fy) * z, z);
      }
    }
    benchmark::DoNotOptimize(points.data());
  }
  SetPixels(state);
}

void BM_BackProjectRayTable(benchmark::State& state) {
  const LensModel model = Model(state);
  const DepthImage depth = RawFrame(model).depth_m;
  const std::vector<cv::Point2f> table = RayTable(model);
  std::vector<Eigen::Vector3f> points;
  points.reserve(depth.num_pixels());
  for (auto _ : state) {
    points.clear();
    const std::span<const float> z = depth.data();
    for (size_t i = 0; i < z.size(); ++i) {
      if (!(z[i] > 0.0f)) continue;
      points.emplace_back(table[i].x * z[i], table[i].y * z[i], z[i]);
    }
    benchmark::DoNotOptimize(points.data());
  }
  SetPixels(state);
}

void BM_Distort(benchmark::State& state) {
  const LensModel model = Model(state);
  RgbdFrame rectified = RawFrame(model);
  rectified.K = model.rectified;
  for (auto _ : state) {
    Result<RgbdFrame> raw = Distort(rectified, model);
    benchmark::DoNotOptimize(raw.value().depth_m.data().data());
  }
}

void BM_RawPixelOf(benchmark::State& state) {
  const LensModel model = Model(state);
  double u = 0.0;
  for (auto _ : state) {
    const Eigen::Vector2d p = RawPixelOf(model, Eigen::Vector2d(u, 100.0));
    benchmark::DoNotOptimize(p.data());
    u = u < 600.0 ? u + 1.0 : 0.0;
  }
}

void Sizes(benchmark::internal::Benchmark* b) {
  b->Args({640, 480})->Args({1280, 720})->Unit(benchmark::kMillisecond);
}

BENCHMARK(BM_BuildRectifier)->Apply(Sizes);
BENCHMARK(BM_Rectify)->Apply(Sizes);
BENCHMARK(BM_RectifyColor)->Apply(Sizes);
BENCHMARK(BM_RectifyDepth)->Apply(Sizes);
BENCHMARK(BM_BuildRayTable)->Apply(Sizes);
BENCHMARK(BM_BackProjectPinhole)->Apply(Sizes);
BENCHMARK(BM_BackProjectRayTable)->Apply(Sizes);
BENCHMARK(BM_RawPixelOf)->Args({640, 480});
BENCHMARK(BM_Distort)->Args({640, 480})->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace avp::ros::msg

int main(int argc, char** argv) { return avp::bench::GoogleBenchmarkMain(argc, argv, {}); }

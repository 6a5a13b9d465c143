// make_robot_bag: writes a synthetic robot's bag for the replay memory test and benchmark
// (ros/bag/test/replay_memory_test.py, benchmarks/bench_replay.cpp): N frames at 30 Hz of W x H
// rgb8 colour and 16UC1 depth (a wall 0.6 m ahead with a red disc), CameraInfo, /tf_static and a
// /tf at 100 Hz of a camera turning slowly about the vertical.
// Usage: make_robot_bag --out F.mcap --frames N [--width W --height H --compression zstd|lz4]
#include <cstdio>
#include <cstdlib>
#include <string>

#include "robot_bag_writer.h"

namespace {

int Fail(const avp::Status& s) {
  std::fprintf(stderr, "make_robot_bag: %s\n", s.ToString().c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace avp;
  std::string out, compression;
  int frames = 90, width = 640, height = 480;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--out") out = v;
    if (k == "--frames") frames = std::atoi(v.c_str());
    if (k == "--width") width = std::atoi(v.c_str());
    if (k == "--height") height = std::atoi(v.c_str());
    if (k == "--compression") compression = v;
  }
  if (out.empty() || frames < 1 || width < 8 || height < 8) {
    std::fprintf(stderr,
                 "usage: make_robot_bag --out F --frames N [--width W --height H "
                 "--compression zstd|lz4]\n");
    return 2;
  }
  auto w = ros::bag::testing::RobotBagWriter::Open(out, compression);
  if (!w.ok()) return Fail(w.status());
  auto& bag = **w;
  using Writer = ros::bag::testing::RobotBagWriter;
  const int64_t t0 = 1'700'000'000'000'000'000;
  const RigidTransform link_to_optical =
      RigidTransform::LookAt({0, 0, 0}, {1, 0, 0}, Eigen::Vector3d::UnitZ());
  if (Status s = bag.Tf({Writer::Edge("igus_rebel_base_link", "mount",
                                      RigidTransform(Eigen::Vector3d(0, 0, 0.4)), t0),
                         Writer::Edge("link", "camera_color_optical_frame", link_to_optical, t0)},
                        t0, true);
      !s.ok()) {
    return Fail(s);
  }
  const CameraIntrinsics K = ros::bag::testing::SyntheticIntrinsics(width, height);
  const ros::msg::CameraInfo info = ros::msg::ToCameraInfo(K, {});
  ImageRgb8 rgb(width, height);
  DepthImage depth(width, height);
  const int64_t period = 33'333'333, tf_period = 10'000'000;
  int64_t next_tf = t0 - 2 * tf_period;
  for (int i = 0; i < frames; ++i) {
    const int64_t t = t0 + i * period;
    for (; next_tf <= t + 2 * tf_period; next_tf += tf_period) {
      const double s = static_cast<double>(next_tf - t0) * 1e-9;
      const Status st =
          bag.Tf({Writer::Edge("mount", "link", RigidTransform::FromRpy(0, 0, 0.05 * s, {0, 0, 0}),
                               next_tf)},
                 next_tf, false);
      if (!st.ok()) return Fail(st);
    }
    ros::bag::testing::DrawWallAndDisc(rgb, depth, -(i % 20));
    if (Status s = bag.Frame(t, rgb, depth, info, "camera_color_optical_frame"); !s.ok()) {
      return Fail(s);
    }
  }
  if (Status s = bag.Close(); !s.ok()) return Fail(s);
  std::printf("wrote %s: %d frames of %d x %d\n", out.c_str(), frames, width, height);
  return 0;
}

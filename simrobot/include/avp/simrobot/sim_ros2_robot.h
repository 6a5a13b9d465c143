#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>
#include <vector>

#include <Eigen/Core>

#include <avp/core/camera.h>
#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/live/tf_listener.h>
#include <avp/robot/arm_model.h>
#include <avp/ros2/node.h>
#include <avp/rosmsg/messages.h>
#include <avp/sim/scene.h>
#include <avp/sim/sensor_noise.h>
#include <avp/sim/sim_rgbd_source.h>

namespace avp::simrobot {

/// What the simulated robot publishes and obeys (docs/ros2.md, "The simulator as a ROS 2 robot").
/// Topic and frame names default to the seed system's RealSense + ReBeL, as avp live expects.
struct SimRobotOptions {
  std::string color_topic = "/camera/camera/color/image_raw";
  std::string depth_topic = "/camera/camera/aligned_depth_to_color/image_raw";
  std::string camera_info_topic = "/camera/camera/color/camera_info";
  std::string joint_states_topic = "/joint_states";
  std::string trajectory_topic = "/joint_trajectory_controller/joint_trajectory";
  /// Simulator labels (instance and class images with the colour image's stamp, the fruit as
  /// latched markers) for the oracle segmenter; empty: not published.
  std::string labels_prefix = "/avp/sim/labels";
  std::string base_frame = "igus_rebel_base_link";
  std::string flange_frame = "igus_rebel_flange";
  std::string camera_frame = "camera_color_optical_frame";
  /// "32FC1" (metres, exact) or "16UC1" (millimetres, as a RealSense).
  std::string depth_encoding = "32FC1";
  /// Images are published at this rate while the arm rests (none while it moves).
  double camera_rate_hz = 15.0;
  /// Joint states and /tf at this rate.
  double joint_state_rate_hz = 50.0;
  /// Trajectories take their time_from_start times this (0: the arm jumps to the goal).
  double time_scale = 1.0;
  /// Images with the sensor-data QoS (best effort), as camera drivers publish; false: reliable.
  bool best_effort = true;
  /// Joint states and goals in the reference system's convention (configs/arms), not the URDF's.
  bool reference_joints = false;
};
const OptionTable<SimRobotOptions>& SimRobotOptionTable();

/// Counters of what the simulated robot did.
struct SimRobotCounters {
  uint64_t frames_rendered = 0;
  uint64_t images_published = 0;
  uint64_t joint_states_published = 0;
  uint64_t goals_received = 0;
  uint64_t goals_refused = 0;
  uint64_t arrivals = 0;
  std::string last_problem;
};

/// The simulator as a ROS 2 robot: the scene rendered by sim::SimRgbdSource at the arm's camera
/// pose and published as a RealSense would (colour rgb8, aligned depth, CameraInfo), the arm's
/// joint states and /tf (base → flange; /tf_static flange → camera optical frame), obeying
/// trajectory_msgs/JointTrajectory goals (the last point, reached linearly over its
/// time_from_start). Frame k rendered at the k-th resting pose uses depth-noise draw k, so a
/// loop that captures once per resting pose sees the frames `avp run` sees.
class SimRos2Robot {
 public:
  /// The scene must outlive the robot. q0: the start joints.
  static Result<std::unique_ptr<SimRos2Robot>> Create(
      ros2::Node& node, const sim::Scene& scene, robot::ArmModel model, const Eigen::VectorXd& q0,
      const CameraIntrinsics& camera, const sim::DepthNoiseConfig& noise, uint64_t seed,
      const SimRobotOptions& options);
  ~SimRos2Robot();

  /// Publishes and obeys until `stop` is requested (or `max_seconds` > 0 pass).
  Status Run(std::stop_token stop, double max_seconds = 0.0);
  SimRobotCounters counters() const;

 private:
  SimRos2Robot(const sim::Scene& scene, robot::ArmModel model, const Eigen::VectorXd& q0,
               const CameraIntrinsics& camera, const sim::DepthNoiseConfig& noise, uint64_t seed,
               const SimRobotOptions& options);
  void OnTrajectory(const rosmsg::JointTrajectory& msg);
  Status RenderAtRest(int64_t stamp_ns);
  Status PublishImages(int64_t stamp_ns);
  Status PublishState(int64_t stamp_ns);

  struct Goal {
    Eigen::VectorXd q;
    double duration_s = 0.0;
  };
  struct Motion {
    Eigen::VectorXd from, to;
    int64_t start_ns = 0;
    int64_t duration_ns = 0;
  };

  const sim::Scene& scene_;
  robot::ArmModel model_;
  SimRobotOptions options_;
  CameraIntrinsics camera_;
  sim::SimRgbdSource source_;
  Eigen::VectorXd q_;
  std::optional<Motion> motion_;
  bool rendered_ = false;
  rosmsg::Image color_, depth_, instance_, class_;
  rosmsg::CameraInfo info_;

  mutable std::mutex mutex_;
  std::optional<Goal> pending_;
  SimRobotCounters counters_;

  std::unique_ptr<ros2::Publisher<rosmsg::Image>> color_pub_, depth_pub_, instance_pub_, class_pub_;
  std::unique_ptr<ros2::Publisher<rosmsg::CameraInfo>> info_pub_;
  std::unique_ptr<ros2::Publisher<rosmsg::JointState>> joints_pub_;
  std::unique_ptr<ros2::Publisher<rosmsg::MarkerArray>> fruits_pub_;
  std::unique_ptr<live::TfBroadcaster> tf_;
  std::unique_ptr<ros2::Subscription<rosmsg::JointTrajectory>> trajectory_sub_;
};

}  // namespace avp::simrobot

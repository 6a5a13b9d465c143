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
#include <avp/robot/arm_model.h>
#include <avp/ros/dds/node.h>
#include <avp/ros/live/tf_listener.h>
#include <avp/ros/msg/camera_topics.h>
#include <avp/ros/msg/messages.h>
#include <avp/sim/scene.h>
#include <avp/sim/sensor_noise.h>
#include <avp/sim/sim_rgbd_source.h>

namespace avp::ros::simrobot {

/// What the simulated robot publishes and obeys (docs/ros2.md, "The simulator as a ROS 2 robot").
/// Topic and frame names default to the seed system's RealSense + ReBeL, as avp live expects.
/// The camera's topics and frames, /tf and /tf_static are the ones `avp live` and `avp replay`
/// read (ros::msg::CameraTopics, the same keys and defaults).
struct SimRobotOptions : ros::msg::CameraTopics {
  std::string joint_states_topic = "/joint_states";
  std::string trajectory_topic = "/joint_trajectory_controller/joint_trajectory";
  /// Simulator labels (instance and class images with the colour image's stamp, the fruit as
  /// latched markers) for the oracle segmenter, at ros::msg::kSimLabelsPrefix; empty: not
  /// published.
  std::string labels_prefix{ros::msg::kSimLabelsPrefix};
  std::string flange_frame = "igus_rebel_flange";
  /// "32FC1" (metres, exact) or "16UC1" (millimetres, as a RealSense).
  std::string depth_encoding = "32FC1";
  /// Images are published at this rate while the arm rests.
  double camera_rate_hz = 15.0;
  /// While the arm moves (time_scale > 0), a frame is rendered where the arm is at each 1 /
  /// moving_rate_hz of the trajectory's time (robot::FramesAlong's times, so `avp live` with
  /// fusion during motion sees the frames `avp run` renders) and published with that stamp and
  /// its /tf; a slow render holds the arm rather than skip a frame. 0: none while moving.
  double moving_rate_hz = 30.0;
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
      ros::dds::Node& node, const sim::Scene& scene, robot::ArmModel model,
      const Eigen::VectorXd& q0, const CameraIntrinsics& camera, const sim::DepthNoiseConfig& noise,
      uint64_t seed, const SimRobotOptions& options);
  ~SimRos2Robot();

  /// Publishes and obeys until `stop` is requested (or `max_seconds` > 0 pass).
  Status Run(std::stop_token stop, double max_seconds = 0.0);
  SimRobotCounters counters() const;

 private:
  SimRos2Robot(const sim::Scene& scene, robot::ArmModel model, const Eigen::VectorXd& q0,
               const CameraIntrinsics& camera, const sim::DepthNoiseConfig& noise, uint64_t seed,
               const SimRobotOptions& options);
  void OnTrajectory(const ros::msg::JointTrajectory& msg);
  /// Renders the camera where the arm is (`moving`: from the moving frames' noise stream).
  Status Render(int64_t stamp_ns, bool moving);
  Status PublishImages(int64_t stamp_ns);
  Status PublishState(int64_t stamp_ns);

  /// A trajectory's points (URDF joints) and their times (time_from_start, nanoseconds).
  struct Goal {
    std::vector<Eigen::VectorXd> q;
    std::vector<int64_t> t_ns;
  };
  /// The motion under way: from the joints at its start through the goal's points, linearly
  /// between consecutive points in time (robot::JointsAt), in the trajectory's time (wall time
  /// over time_scale).
  struct Motion {
    std::vector<Eigen::VectorXd> q;  ///< q[0]: where the arm was when the goal came
    std::vector<int64_t> t_ns;       ///< t_ns[0] = 0
    int64_t start_ns = 0;            ///< wall clock at the start; frames are stamped from it
    std::vector<int64_t> frames_ns;  ///< the moving frames' times
    size_t next_frame = 0;
    int64_t t = 0;  ///< the motion's clock at the last tick
    int64_t duration_ns() const { return t_ns.back(); }
    /// The joints `at_ns` after the start.
    Eigen::VectorXd At(int64_t at_ns) const;
  };

  robot::ArmModel model_;
  SimRobotOptions options_;
  CameraIntrinsics camera_;
  sim::SimRgbdSource source_;
  Eigen::VectorXd q_;
  std::optional<Motion> motion_;
  bool rendered_ = false;
  ros::msg::Image color_, depth_, instance_, class_;
  ros::msg::CameraInfo info_;

  mutable std::mutex mutex_;
  std::optional<Goal> pending_;
  SimRobotCounters counters_;

  std::unique_ptr<ros::dds::Publisher<ros::msg::Image>> color_pub_, depth_pub_, instance_pub_,
      class_pub_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::CameraInfo>> info_pub_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::JointState>> joints_pub_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::MarkerArray>> fruits_pub_;
  std::unique_ptr<ros::live::TfBroadcaster> tf_;
  std::unique_ptr<ros::dds::Subscription<ros::msg::JointTrajectory>> trajectory_sub_;
};

}  // namespace avp::ros::simrobot

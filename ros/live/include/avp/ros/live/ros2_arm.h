#pragma once

#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>

#include <Eigen/Core>

#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/robot/arm.h>
#include <avp/ros/dds/node.h>
#include <avp/ros/live/tf_listener.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::live {

/// How avp moves a live arm and knows it arrived (docs/ros2.md).
struct ArmTopicsOptions {
  std::string joint_states_topic = "/joint_states";
  /// The move as trajectory_msgs/JointTrajectory, as a ros2_control JointTrajectoryController
  /// takes it: the planned collision-free trajectory (docs/motion.md), or with motion planning
  /// off the IK joint goal as one point; empty: publish only the view (e.g. for MoveIt through
  /// examples/ros2/next_view_to_moveit.py) and wait for the arm to arrive.
  std::string trajectory_topic = "/joint_trajectory_controller/joint_trajectory";
  /// The chosen camera pose (PoseStamped of the optical frame in the base frame).
  std::string next_view_topic = "/avp/next_view";
  std::string base_frame = "igus_rebel_base_link";
  std::string camera_frame = "camera_color_optical_frame";
  /// Arrived when every joint is this close to the goal ...
  double joint_tolerance_rad = 0.01;
  /// ... or the camera's transform is this close to the goal's.
  double pose_tolerance_m = 0.01;
  double pose_tolerance_deg = 1.0;
  /// The trajectory's duration: the largest joint change at this speed (at least min_duration_s).
  double max_joint_speed_rad_s = 0.5;
  double min_duration_s = 0.5;
  /// Beyond the trajectory's duration, wait at most this long for the arm to arrive.
  double arrival_timeout_s = 10.0;
  /// Joint states older than this count as "the arm stopped answering".
  double state_timeout_s = 5.0;
  /// The robot's joint values are in the reference system's convention (configs/arms:
  /// reference_convention; e.g. AIRLab-POLIMI/ros2-igus-rebel's description) rather than the
  /// URDF's: /joint_states are converted in, goals out.
  bool reference_joints = false;
};
const OptionTable<ArmTopicsOptions>& ArmTopicsOptionTable();

/// A robot::Arm on ROS 2 topics: its joints from /joint_states (by name, in the model's order);
/// a move publishes the view on next_view_topic and the joint goal on trajectory_topic, then
/// waits until the joints (or the camera's TF) are within tolerance of the goal. A move that
/// does not arrive is DeadlineExceeded naming the joint farthest from its goal; joint states
/// that stop are Unavailable; a stop request is Cancelled (the episode then ends: the loop never
/// sends another goal to an arm whose position it does not know).
class Ros2Arm final : public robot::Arm {
 public:
  /// Subscribes and waits (state_timeout_s) for joint states that name every joint of `model`.
  static Result<std::unique_ptr<Ros2Arm>> Create(ros::dds::Node& node, ros::msg::TfBuffer& tf,
                                                 robot::ArmModel model,
                                                 const ArmTopicsOptions& options,
                                                 std::stop_token stop = {});
  ~Ros2Arm() override;

  /// Joint states received, and how many could not be used (missing joints, NaN).
  uint64_t joint_states_received() const;
  uint64_t goals_sent() const { return goals_sent_; }

 protected:
  Eigen::VectorXd DoCurrentJoints() const override;
  robot::MoveResult DoMoveToJoints(const Eigen::VectorXd& q) override;
  /// Publishes the whole trajectory (every point's positions, velocities and time_from_start)
  /// and waits for the arm to arrive at its last point, as DoMoveToJoints does.
  robot::MoveResult DoFollowTrajectory(const robot::JointTrajectory& trajectory) override;

 private:
  /// trajectory_msgs/JointTrajectory of `trajectory` (in the reference convention when
  /// reference_joints), stamp 0: start now.
  ros::msg::JointTrajectory ToMessage(const robot::JointTrajectory& trajectory) const;
  /// Publishes the view and the trajectory, then waits for the arm to reach its last point.
  robot::MoveResult SendAndWait(const robot::JointTrajectory& trajectory,
                                const Eigen::VectorXd& q_before);
  Ros2Arm(ros::msg::TfBuffer& tf, robot::ArmModel model, const ArmTopicsOptions& options,
          std::stop_token stop);
  void OnJointState(const ros::msg::JointState& msg);
  /// Why the arm is not at `goal` yet (empty when it is); mutex_ held.
  std::string Distance(const Eigen::VectorXd& goal, const RigidTransform& X_WC_goal) const;

  ros::msg::TfBuffer& tf_;
  ArmTopicsOptions options_;
  std::stop_token stop_;
  mutable std::mutex mutex_;
  std::condition_variable_any cv_;
  std::optional<Eigen::VectorXd> q_;  ///< the latest joint state, model order
  int64_t q_received_ns_ = 0;         ///< steady clock
  uint64_t received_ = 0;
  uint64_t unusable_ = 0;
  std::string last_problem_;
  uint64_t goals_sent_ = 0;
  std::unique_ptr<ros::dds::Subscription<ros::msg::JointState>> joint_sub_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::JointTrajectory>> trajectory_pub_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::PoseStamped>> view_pub_;
};

}  // namespace avp::ros::live

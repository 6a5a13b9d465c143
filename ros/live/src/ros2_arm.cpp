#include <chrono>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include <avp/ros/live/ros2_arm.h>
#include <avp/ros/live/ros2_rgbd_source.h>
#include <avp/ros/msg/convert.h>

namespace avp::ros::live {

namespace {

using SteadyClock = std::chrono::steady_clock;

int64_t SteadyNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(SteadyClock::now().time_since_epoch())
      .count();
}

}  // namespace

const OptionTable<ArmTopicsOptions>& ArmTopicsOptionTable() {
  static const auto* table = [] {
    using O = ArmTopicsOptions;
    auto* t = new OptionTable<O>("arm topic option");
    t->Text("joint_states_topic", &O::joint_states_topic, "sensor_msgs/JointState of the arm");
    t->Text("trajectory_topic", &O::trajectory_topic,
            "the joint goal as trajectory_msgs/JointTrajectory (empty: none)");
    t->Text("next_view_topic", &O::next_view_topic, "the chosen camera pose (PoseStamped)");
    t->Text("base_frame", &O::base_frame, "the arm's base frame");
    t->Text("camera_frame", &O::camera_frame, "the camera's optical frame");
    t->Real("joint_tolerance_rad", &O::joint_tolerance_rad, "rad", ValueRange::LeftOpen(0, 1),
            "arrived when every joint is this close to the goal");
    t->Real("pose_tolerance_m", &O::pose_tolerance_m, "m", ValueRange::LeftOpen(0, 1),
            "or the camera's transform this close to the goal's");
    t->Real("pose_tolerance_deg", &O::pose_tolerance_deg, "deg", ValueRange::LeftOpen(0, 90),
            "and turned at most this much from it");
    t->Real("max_joint_speed_rad_s", &O::max_joint_speed_rad_s, "rad/s",
            ValueRange::LeftOpen(0, 100), "the trajectory's duration: largest joint change / this");
    t->Real("min_duration_s", &O::min_duration_s, "s", ValueRange::Closed(0, 600),
            "the trajectory lasts at least this long");
    t->Real("arrival_timeout_s", &O::arrival_timeout_s, "s", ValueRange::LeftOpen(0, 3600),
            "beyond the trajectory's duration, wait at most this long to arrive");
    t->Real("state_timeout_s", &O::state_timeout_s, "s", ValueRange::LeftOpen(0, 600),
            "joint states older than this: the arm stopped answering");
    t->Flag("reference_joints", &O::reference_joints,
            "the robot's joints are in the reference convention (configs/arms), not the URDF's");
    t->AddRule([](const O& o, std::vector<std::string>& errors) {
      if (o.joint_states_topic.empty()) errors.push_back("joint_states_topic is empty");
      if (o.next_view_topic.empty()) errors.push_back("next_view_topic is empty");
      if (o.base_frame.empty()) errors.push_back("base_frame is empty");
    });
    return t;
  }();
  return *table;
}

Ros2Arm::Ros2Arm(ros::msg::TfBuffer& tf, robot::ArmModel model, const ArmTopicsOptions& options,
                 std::stop_token stop)
    : robot::Arm(std::move(model)), tf_(tf), options_(options), stop_(std::move(stop)) {}

Ros2Arm::~Ros2Arm() { joint_sub_.reset(); }

Result<std::unique_ptr<Ros2Arm>> Ros2Arm::Create(ros::dds::Node& node, ros::msg::TfBuffer& tf,
                                                 robot::ArmModel model,
                                                 const ArmTopicsOptions& options,
                                                 std::stop_token stop) {
  AVP_RETURN_IF_ERROR(ArmTopicsOptionTable().Validate(options));
  std::unique_ptr<Ros2Arm> arm(new Ros2Arm(tf, std::move(model), options, stop));
  Ros2Arm* self = arm.get();
  AVP_ASSIGN_OR_RETURN(arm->joint_sub_,
                       node.CreateSubscription<ros::msg::JointState>(
                           options.joint_states_topic, ros::dds::QosProfile::SensorData(),
                           [self](ros::msg::JointState&& m, const ros::dds::SampleInfo&) {
                             self->OnJointState(m);
                           }));
  if (!options.trajectory_topic.empty()) {
    AVP_ASSIGN_OR_RETURN(arm->trajectory_pub_,
                         node.CreatePublisher<ros::msg::JointTrajectory>(
                             options.trajectory_topic, ros::dds::QosProfile::Default()));
  }
  AVP_ASSIGN_OR_RETURN(
      arm->view_pub_, node.CreatePublisher<ros::msg::PoseStamped>(options.next_view_topic,
                                                                  ros::dds::QosProfile::Default()));
  std::unique_lock lock(arm->mutex_);
  arm->cv_.wait_until(lock, stop, SteadyClock::now() + Seconds(options.state_timeout_s),
                      [&] { return arm->q_.has_value(); });
  if (stop.stop_requested()) return CancelledError("stopped while waiting for joint states");
  if (!arm->q_) {
    return UnavailableError(fmt::format(
        "no usable joint states on {} within {} s ({} received{}{}; {} publisher(s) matched): is "
        "the arm's driver running, on ROS_DOMAIN_ID {}?",
        options.joint_states_topic, options.state_timeout_s, arm->received_,
        arm->last_problem_.empty() ? "" : "; last problem: ", arm->last_problem_,
        arm->joint_sub_->matched_publishers(), node.domain_id()));
  }
  return arm;
}

void Ros2Arm::OnJointState(const ros::msg::JointState& msg) {
  const std::vector<std::string>& names = model().joint_names();
  Eigen::VectorXd q(static_cast<Eigen::Index>(names.size()));
  std::string problem;
  if (msg.position.size() != msg.name.size()) {
    problem = fmt::format("{}: {} names but {} positions", options_.joint_states_topic,
                          msg.name.size(), msg.position.size());
  }
  for (size_t j = 0; j < names.size() && problem.empty(); ++j) {
    size_t k = 0;
    while (k < msg.name.size() && msg.name[k] != names[j]) ++k;
    if (k == msg.name.size()) {
      problem = fmt::format("{}: joint '{}' is missing (the message names: {})",
                            options_.joint_states_topic, names[j], fmt::join(msg.name, ", "));
    } else if (!std::isfinite(msg.position[k])) {
      problem = fmt::format("{}: joint '{}' is at {}", options_.joint_states_topic, names[j],
                            msg.position[k]);
    } else {
      q[static_cast<Eigen::Index>(j)] = msg.position[k];
    }
  }
  if (problem.empty() && options_.reference_joints) q = model().FromReferenceJoints(q);
  std::lock_guard lock(mutex_);
  ++received_;
  if (!problem.empty()) {
    ++unusable_;
    last_problem_ = problem;
    return;
  }
  q_ = q;
  q_received_ns_ = SteadyNs();
  cv_.notify_all();
}

uint64_t Ros2Arm::joint_states_received() const {
  std::lock_guard lock(mutex_);
  return received_;
}

Eigen::VectorXd Ros2Arm::DoCurrentJoints() const {
  std::lock_guard lock(mutex_);
  return *q_;
}

std::string Ros2Arm::Distance(const Eigen::VectorXd& goal, const RigidTransform& X_WC_goal) const {
  // Joints first.
  Eigen::Index worst = 0;
  const Eigen::VectorXd d = (*q_ - goal).cwiseAbs();
  d.maxCoeff(&worst);
  if (d[worst] <= options_.joint_tolerance_rad) return "";
  // Then the camera's transform, when TF has it.
  std::string camera;
  Result<int64_t> latest = tf_.LatestCommonTime(options_.base_frame, options_.camera_frame);
  if (latest.ok()) {
    const int64_t t = std::min(*latest, NowNs());
    Result<RigidTransform> X = tf_.Lookup(options_.base_frame, options_.camera_frame, t);
    if (X.ok()) {
      const double dp = X->TranslationDistanceTo(X_WC_goal);
      const double da = X->AngleTo(X_WC_goal) * 180.0 / std::numbers::pi;
      if (dp <= options_.pose_tolerance_m && da <= options_.pose_tolerance_deg) return "";
      camera = fmt::format("; the camera is {:.1f} cm / {:.1f} deg from the goal", dp * 100, da);
    }
  }
  return fmt::format("joint '{}' at {:.4f} rad, goal {:.4f} (tolerance {}){}",
                     model().joint_names()[static_cast<size_t>(worst)], (*q_)[worst], goal[worst],
                     options_.joint_tolerance_rad, camera);
}

robot::MoveResult Ros2Arm::DoMoveToJoints(const Eigen::VectorXd& q) {
  const Eigen::VectorXd q_before = DoCurrentJoints();
  const double largest = (q - q_before).cwiseAbs().maxCoeff();
  const double duration_s =
      std::max(options_.min_duration_s, largest / options_.max_joint_speed_rad_s);
  robot::JointTrajectory one;
  one.joint_names = model().joint_names();
  one.points.push_back({q, Eigen::VectorXd(), duration_s});
  robot::MoveResult result = SendAndWait(one, q_before);
  if (result.ok()) result.joint_path_length = (result.q - q_before).norm();
  return result;
}

robot::MoveResult Ros2Arm::DoFollowTrajectory(const robot::JointTrajectory& trajectory) {
  const Eigen::VectorXd q_before = DoCurrentJoints();
  robot::MoveResult result = SendAndWait(trajectory, q_before);
  if (!result.ok()) return result;
  for (size_t i = 1; i < trajectory.points.size(); ++i) {
    result.joint_path_length += (trajectory.points[i].q - trajectory.points[i - 1].q).norm();
  }
  result.execution_s = trajectory.duration_s();
  return result;
}

ros::msg::JointTrajectory Ros2Arm::ToMessage(const robot::JointTrajectory& trajectory) const {
  ros::msg::JointTrajectory traj;
  traj.header.frame_id = options_.base_frame;  // stamp 0: start now (JointTrajectoryController)
  traj.joint_names = model().joint_names();
  for (const robot::TrajectoryPoint& p : trajectory.points) {
    ros::msg::JointTrajectoryPoint point;
    const Eigen::VectorXd q_out = options_.reference_joints ? model().ToReferenceJoints(p.q) : p.q;
    point.positions.assign(q_out.data(), q_out.data() + q_out.size());
    if (p.qd.size() == q_out.size()) {
      // The reference convention flips signs only: velocities follow the positions' signs.
      const Eigen::VectorXd qd_out =
          options_.reference_joints
              ? Eigen::VectorXd(model().ToReferenceJoints(p.qd) -
                                model().ToReferenceJoints(Eigen::VectorXd::Zero(p.qd.size())))
              : p.qd;
      point.velocities.assign(qd_out.data(), qd_out.data() + qd_out.size());
    }
    point.time_from_start = ros::msg::Duration::FromNanoseconds(robot::TimeNs(p));
    traj.points.push_back(std::move(point));
  }
  return traj;
}

robot::MoveResult Ros2Arm::SendAndWait(const robot::JointTrajectory& trajectory,
                                       const Eigen::VectorXd& q_before) {
  robot::MoveResult result;
  result.q = q_before;
  const Eigen::VectorXd& q = trajectory.points.back().q;
  const double duration_s = trajectory.duration_s();
  const RigidTransform X_WC_goal = model().CameraPose(q);
  const ros::msg::Time now = ros::msg::Time::FromNanoseconds(NowNs());

  ros::msg::PoseStamped view;
  view.header.stamp = now;
  view.header.frame_id = options_.base_frame;
  view.pose = ros::msg::ToPoseMsg(X_WC_goal);
  if (Status s = view_pub_->Publish(view); !s.ok()) {
    result.status = UnavailableError(
        fmt::format("publishing the view on {} failed: {}", options_.next_view_topic, s.message()));
    return result;
  }
  if (trajectory_pub_ != nullptr) {
    if (Status s = trajectory_pub_->Publish(ToMessage(trajectory)); !s.ok()) {
      result.status = UnavailableError(fmt::format("publishing the joint goal on {} failed: {}",
                                                   options_.trajectory_topic, s.message()));
      return result;
    }
  }
  ++goals_sent_;

  const auto deadline = SteadyClock::now() + Seconds(duration_s + options_.arrival_timeout_s);
  std::unique_lock lock(mutex_);
  std::string distance = Distance(q, X_WC_goal);
  while (!distance.empty()) {
    const auto stale_at = SteadyClock::time_point(std::chrono::nanoseconds(q_received_ns_)) +
                          Seconds(options_.state_timeout_s);
    const auto wake =
        std::min({deadline, stale_at, SteadyClock::now() + std::chrono::milliseconds(20)});
    cv_.wait_until(lock, stop_, wake, [] { return false; });
    if (stop_.stop_requested()) {
      result.status = CancelledError("stopped while the arm was moving: " + distance);
      return result;
    }
    distance = Distance(q, X_WC_goal);
    if (distance.empty()) break;
    if (SteadyClock::now() >= stale_at) {
      result.status = UnavailableError(
          fmt::format("no joint states on {} for {} s while moving: {}",
                      options_.joint_states_topic, options_.state_timeout_s, distance));
      return result;
    }
    if (SteadyClock::now() >= deadline) {
      result.status = DeadlineExceededError(
          fmt::format("the arm did not arrive within {:.1f} s (a {:.1f} s trajectory + {} s): {}",
                      duration_s + options_.arrival_timeout_s, duration_s,
                      options_.arrival_timeout_s, distance));
      return result;
    }
  }
  result.q = *q_;
  result.status = Status::Ok();
  return result;
}

}  // namespace avp::ros::live

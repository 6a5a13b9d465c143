#include <chrono>
#include <cmath>
#include <thread>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/robot/trajectory.h>
#include <avp/ros/live/ros2_rgbd_source.h>
#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/markers.h>
#include <avp/ros/simrobot/sim_ros2_robot.h>

namespace avp::ros::simrobot {

namespace {

/// The longest trajectory obeyed (its time_from_start; times time_scale <= 100 it stays far from
/// int64 nanoseconds).
constexpr double kMaxTrajectorySeconds = 3600.0;

}  // namespace

const OptionTable<SimRobotOptions>& SimRobotOptionTable() {
  static const auto* table = [] {
    using O = SimRobotOptions;
    auto* t = new OptionTable<O>("simulated robot option");
    ros::msg::AddCameraTopicNames(*t);
    t->Text("joint_states_topic", &O::joint_states_topic, "the arm's joint states");
    t->Text("trajectory_topic", &O::trajectory_topic, "joint goals (JointTrajectory) obeyed");
    t->Text("labels_prefix", &O::labels_prefix,
            "simulator labels for the oracle segmenter (empty: none)");
    t->Text("flange_frame", &O::flange_frame, "the arm's flange frame");
    t->Text("depth_encoding", &O::depth_encoding, "32FC1 (metres) or 16UC1 (millimetres)");
    t->Real("camera_rate_hz", &O::camera_rate_hz, "Hz", ValueRange::LeftOpen(0, 200),
            "images per second while the arm rests");
    t->Real("moving_rate_hz", &O::moving_rate_hz, "Hz", ValueRange::Closed(0, 120),
            "images per second while the arm moves, each rendered where the arm is then "
            "(0: none)");
    t->Real("joint_state_rate_hz", &O::joint_state_rate_hz, "Hz", ValueRange::LeftOpen(0, 1000),
            "joint states and /tf per second");
    t->Real("time_scale", &O::time_scale, "", ValueRange::Closed(0, 100),
            "trajectories take time_from_start times this (0: jump)");
    t->Flag("best_effort", &O::best_effort, "images best-effort (sensor data QoS)");
    t->Flag("reference_joints", &O::reference_joints,
            "joint states and goals in the reference convention (configs/arms)");
    t->AddRule([](const O& o, std::vector<std::string>& errors) {
      if (o.camera_frame.empty()) errors.push_back("camera_frame is empty");
      if (o.depth_encoding != "32FC1" && o.depth_encoding != "16UC1") {
        errors.push_back(
            fmt::format("depth_encoding ('{}') must be 32FC1 or 16UC1", o.depth_encoding));
      }
    });
    return t;
  }();
  return *table;
}

SimRos2Robot::SimRos2Robot(const sim::Scene& scene, robot::ArmModel model,
                           const Eigen::VectorXd& q0, const CameraIntrinsics& camera,
                           const sim::DepthNoiseConfig& noise, uint64_t seed,
                           const SimRobotOptions& options)
    : model_(std::move(model)),
      options_(options),
      camera_(camera),
      source_(scene, camera, noise, seed),
      q_(q0) {}

SimRos2Robot::~SimRos2Robot() { trajectory_sub_.reset(); }

Result<std::unique_ptr<SimRos2Robot>> SimRos2Robot::Create(
    ros::dds::Node& node, const sim::Scene& scene, robot::ArmModel model, const Eigen::VectorXd& q0,
    const CameraIntrinsics& camera, const sim::DepthNoiseConfig& noise, uint64_t seed,
    const SimRobotOptions& options) {
  AVP_RETURN_IF_ERROR(SimRobotOptionTable().Validate(options));
  AVP_RETURN_IF_ERROR(model.CheckJoints(q0));
  AVP_RETURN_IF_ERROR(camera.Validate());
  std::unique_ptr<SimRos2Robot> r;
  try {
    r.reset(new SimRos2Robot(scene, std::move(model), q0, camera, noise, seed, options));
  } catch (const std::exception& e) {
    return InvalidArgumentError(fmt::format("the simulated camera: {}", e.what()));
  }
  const ros::dds::QosProfile images =
      options.best_effort ? ros::dds::QosProfile::SensorData() : ros::dds::QosProfile::Default();
  AVP_ASSIGN_OR_RETURN(r->color_pub_,
                       node.CreatePublisher<ros::msg::Image>(options.color_topic, images));
  AVP_ASSIGN_OR_RETURN(r->depth_pub_,
                       node.CreatePublisher<ros::msg::Image>(options.depth_topic, images));
  AVP_ASSIGN_OR_RETURN(
      r->info_pub_, node.CreatePublisher<ros::msg::CameraInfo>(options.camera_info_topic, images));
  AVP_ASSIGN_OR_RETURN(r->joints_pub_,
                       node.CreatePublisher<ros::msg::JointState>(
                           options.joint_states_topic, ros::dds::QosProfile::SensorData()));
  if (!options.labels_prefix.empty()) {
    AVP_ASSIGN_OR_RETURN(r->instance_pub_, node.CreatePublisher<ros::msg::Image>(
                                               options.labels_prefix + "/instance", images));
    AVP_ASSIGN_OR_RETURN(r->class_pub_, node.CreatePublisher<ros::msg::Image>(
                                            options.labels_prefix + "/class", images));
    AVP_ASSIGN_OR_RETURN(r->fruits_pub_,
                         node.CreatePublisher<ros::msg::MarkerArray>(
                             options.labels_prefix + "/fruits", ros::dds::QosProfile::Latched()));
  }
  AVP_ASSIGN_OR_RETURN(
      r->tf_, ros::live::TfBroadcaster::Create(node, options.tf_topic, options.tf_static_topic));
  SimRos2Robot* self = r.get();
  AVP_ASSIGN_OR_RETURN(r->trajectory_sub_,
                       node.CreateSubscription<ros::msg::JointTrajectory>(
                           options.trajectory_topic, ros::dds::QosProfile::Default(),
                           [self](ros::msg::JointTrajectory&& m, const ros::dds::SampleInfo&) {
                             self->OnTrajectory(m);
                           }));
  // The camera's mount and the fruit: published once, latched.
  const int64_t now = ros::live::NowNs();
  ros::msg::TransformStamped mount;
  mount.header.stamp = ros::msg::Time::FromNanoseconds(now);
  mount.header.frame_id = options.flange_frame;
  mount.child_frame_id = options.camera_frame;
  mount.transform = ros::msg::ToTransformMsg(r->model_.X_FC());
  AVP_RETURN_IF_ERROR(r->tf_->SendStatic({mount}));
  if (r->fruits_pub_ != nullptr) {
    std::vector<GroundTruthFruit> fruits;
    for (const sim::FruitTruth& f : scene.Fruits()) {
      fruits.push_back({f.instance_id, f.center_W, f.mean_radius_m()});
    }
    ros::msg::Header header;
    header.stamp = mount.header.stamp;
    header.frame_id = options.base_frame;
    AVP_RETURN_IF_ERROR(r->fruits_pub_->Publish(ros::msg::FruitMarkers(fruits, header)));
  }
  // CameraInfo: the pinhole intrinsics, no distortion (the recorder's builder).
  ros::msg::Header header;
  header.frame_id = options.camera_frame;
  r->info_ = ros::msg::ToCameraInfo(camera, header);
  return r;
}

Eigen::VectorXd SimRos2Robot::Motion::At(int64_t at_ns) const {
  return robot::JointsAt(q, t_ns, at_ns);
}

void SimRos2Robot::OnTrajectory(const ros::msg::JointTrajectory& msg) {
  std::string problem;
  Goal goal;
  const std::vector<std::string>& names = model_.joint_names();
  if (msg.points.empty()) problem = "the trajectory has no point";
  // Every point, in order (a planned trajectory is followed point by point).
  std::vector<size_t> column(names.size(), 0);
  for (size_t j = 0; j < names.size() && problem.empty(); ++j) {
    size_t k = 0;
    while (k < msg.joint_names.size() && msg.joint_names[k] != names[j]) ++k;
    if (k == msg.joint_names.size()) {
      problem = fmt::format("joint '{}' is missing (given: {})", names[j],
                            fmt::join(msg.joint_names, ", "));
    }
    column[j] = k;
  }
  double previous_t = 0.0;
  for (size_t p = 0; p < msg.points.size() && problem.empty(); ++p) {
    const ros::msg::JointTrajectoryPoint& point = msg.points[p];
    if (point.positions.size() != msg.joint_names.size()) {
      problem = fmt::format("point {}: {} joint names but {} positions", p, msg.joint_names.size(),
                            point.positions.size());
      break;
    }
    Eigen::VectorXd q(static_cast<Eigen::Index>(names.size()));
    for (size_t j = 0; j < names.size(); ++j) {
      q[static_cast<Eigen::Index>(j)] = point.positions[column[j]];
    }
    if (options_.reference_joints) q = model_.FromReferenceJoints(q);
    const double t = static_cast<double>(point.time_from_start.ToNanoseconds()) * 1e-9;
    if (!(t >= previous_t && t <= kMaxTrajectorySeconds)) {
      problem = fmt::format("point {}: time_from_start {} s is outside [{}, {}] s", p, t,
                            previous_t, kMaxTrajectorySeconds);
      break;
    }
    if (Status s = model_.CheckJoints(q); !s.ok()) {
      problem = fmt::format("point {}: {}", p, s.message());
      break;
    }
    previous_t = t;
    goal.q.push_back(std::move(q));
    goal.t_ns.push_back(point.time_from_start.ToNanoseconds());
  }
  std::lock_guard lock(mutex_);
  ++counters_.goals_received;
  if (!problem.empty()) {
    ++counters_.goals_refused;
    counters_.last_problem =
        fmt::format("{}: refused a goal: {}", options_.trajectory_topic, problem);
    spdlog::warn("{}", counters_.last_problem);
    return;
  }
  pending_ = goal;
}

Status SimRos2Robot::Render(int64_t stamp_ns, bool moving) {
  Result<robot::Observation> obs = moving ? source_.CaptureMoving(model_.CameraPose(q_), stamp_ns)
                                          : source_.Capture(model_.CameraPose(q_), stamp_ns);
  if (!obs.ok()) return obs.status();
  ros::msg::Header header;
  header.frame_id = options_.camera_frame;
  color_ = ros::msg::ToColorImage(obs->frame.rgb, header);
  depth_ =
      ros::msg::ToDepthImage(obs->frame.depth_m, header,
                             options_.depth_encoding == "16UC1" ? ros::msg::DepthEncoding::k16UC1
                                                                : ros::msg::DepthEncoding::k32FC1);
  if (instance_pub_ != nullptr && obs->labels) {
    instance_ = ros::msg::ToInstanceIdImage(obs->labels->instance_ids, "16UC1", header);
    class_ = ros::msg::ToClassIdImage(obs->labels->class_ids, header);
  }
  rendered_ = true;
  std::lock_guard lock(mutex_);
  ++counters_.frames_rendered;
  return Status::Ok();
}

Status SimRos2Robot::PublishImages(int64_t stamp_ns) {
  const ros::msg::Time stamp = ros::msg::Time::FromNanoseconds(stamp_ns);
  color_.header.stamp = depth_.header.stamp = info_.header.stamp = stamp;
  // Labels first, then depth, then colour: a reader that pairs on the colour finds the rest.
  if (instance_pub_ != nullptr) {
    instance_.header.stamp = class_.header.stamp = stamp;
    AVP_RETURN_IF_ERROR(instance_pub_->Publish(instance_));
    AVP_RETURN_IF_ERROR(class_pub_->Publish(class_));
  }
  AVP_RETURN_IF_ERROR(info_pub_->Publish(info_));
  AVP_RETURN_IF_ERROR(depth_pub_->Publish(depth_));
  AVP_RETURN_IF_ERROR(color_pub_->Publish(color_));
  std::lock_guard lock(mutex_);
  ++counters_.images_published;
  return Status::Ok();
}

Status SimRos2Robot::PublishState(int64_t stamp_ns) {
  const ros::msg::Time stamp = ros::msg::Time::FromNanoseconds(stamp_ns);
  ros::msg::JointState js;
  js.header.stamp = stamp;
  js.name = model_.joint_names();
  const Eigen::VectorXd q = options_.reference_joints ? model_.ToReferenceJoints(q_) : q_;
  js.position.assign(q.data(), q.data() + q.size());
  AVP_RETURN_IF_ERROR(joints_pub_->Publish(js));
  ros::msg::TFMessage tf;
  ros::msg::TransformStamped t;
  t.header.stamp = stamp;
  t.header.frame_id = options_.base_frame;
  t.child_frame_id = options_.flange_frame;
  t.transform = ros::msg::ToTransformMsg(model_.ForwardKinematics(q_));
  tf.transforms.push_back(t);
  AVP_RETURN_IF_ERROR(tf_->Send(tf));
  std::lock_guard lock(mutex_);
  ++counters_.joint_states_published;
  return Status::Ok();
}

Status SimRos2Robot::Run(std::stop_token stop, double max_seconds) {
  using Clock = std::chrono::steady_clock;
  const auto t_end = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(max_seconds));
  const auto state_period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / options_.joint_state_rate_hz));
  const auto image_period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / options_.camera_rate_hz));
  auto next_state = Clock::now();
  auto next_image = Clock::now();
  while (!stop.stop_requested() && (max_seconds <= 0.0 || Clock::now() < t_end)) {
    const auto tick = Clock::now();
    // A new goal replaces the motion, starting from where the arm is.
    {
      std::lock_guard lock(mutex_);
      if (pending_) {
        Motion m;
        m.q.push_back(q_);
        m.t_ns.push_back(0);
        for (size_t i = 0; i < pending_->q.size(); ++i) {
          m.q.push_back(pending_->q[i]);
          m.t_ns.push_back(std::max<int64_t>(0, pending_->t_ns[i]));
        }
        m.start_ns = ros::live::NowNs();
        if (options_.time_scale > 0.0 && options_.moving_rate_hz > 0.0) {
          // The frames a camera at moving_rate_hz takes on the way (robot::FramesAlong's times).
          m.frames_ns = robot::FrameTimesNs(m.duration_ns(), options_.moving_rate_hz);
        }
        motion_ = std::move(m);
        pending_.reset();
      }
    }
    if (motion_) {
      // The motion's clock (trajectory time): wall time over time_scale, held at the next frame
      // until that frame is rendered (a slow render delays the arm, never skips a frame).
      const int64_t wall = ros::live::NowNs() - motion_->start_ns;
      int64_t t = options_.time_scale > 0.0
                      ? static_cast<int64_t>(static_cast<double>(wall) / options_.time_scale)
                      : motion_->duration_ns();
      const bool frame_due = motion_->next_frame < motion_->frames_ns.size() &&
                             t >= motion_->frames_ns[motion_->next_frame];
      if (motion_->next_frame < motion_->frames_ns.size()) {
        t = std::min(t, motion_->frames_ns[motion_->next_frame]);
      }
      if (t >= motion_->duration_ns()) {
        q_ = motion_->q.back();  // exactly the goal
        motion_.reset();
        rendered_ = false;
        std::lock_guard lock(mutex_);
        ++counters_.arrivals;
      } else {
        motion_->t = t;
        q_ = motion_->At(t);
        if (frame_due) {
          // The state at the frame's stamp first (its TF), then the images.
          const int64_t stamp = motion_->start_ns + t;
          AVP_RETURN_IF_ERROR(PublishState(stamp));
          AVP_RETURN_IF_ERROR(Render(stamp, true));
          AVP_RETURN_IF_ERROR(PublishImages(stamp));
          ++motion_->next_frame;
          next_state = Clock::now() + state_period;
        }
      }
    }
    if (tick >= next_state || (!motion_ && !rendered_)) {
      AVP_RETURN_IF_ERROR(
          PublishState(motion_ ? motion_->start_ns + motion_->t : ros::live::NowNs()));
      next_state = tick + state_period;
    }
    if (!motion_) {
      if (!rendered_) {
        AVP_RETURN_IF_ERROR(Render(ros::live::NowNs(), false));
        next_image = Clock::now();
      }
      if (Clock::now() >= next_image) {
        AVP_RETURN_IF_ERROR(PublishImages(ros::live::NowNs()));
        next_image += image_period;
        if (next_image < Clock::now()) next_image = Clock::now() + image_period;
      }
    }
    const auto wake = motion_ ? next_state : std::min(next_state, next_image);
    std::this_thread::sleep_until(std::min(wake, Clock::now() + std::chrono::milliseconds(5)));
  }
  return Status::Ok();
}

SimRobotCounters SimRos2Robot::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

}  // namespace avp::ros::simrobot

#pragma once

// Tests and benchmarks: a robot's bag as the RealSense driver, robot_state_publisher and
// joint_state_broadcaster write it (rosbag2 MCAP, `cdr` payloads, the RealSense topic names):
// colour, aligned depth and CameraInfo per frame, /tf and /tf_static, /joint_states.

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <avp/core/camera.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/ros/mcap/mcap.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::bag::testing {

/// A synthetic RealSense view: a green wall 0.6 m ahead with a red disc 5 cm nearer, its centre
/// `shift` pixels right of the image's (the images' sizes are kept).
inline void DrawWallAndDisc(ImageRgb8& rgb, DepthImage& depth_m, int shift = 0) {
  const int w = rgb.width(), h = rgb.height(), r2 = (h / 5) * (h / 5);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const int du = u - w / 2 - shift, dv = v - h / 2;
      const bool disc = du * du + dv * dv < r2;
      rgb(u, v, 0) = disc ? 210 : 40;
      rgb(u, v, 1) = disc ? 20 : 160;
      rgb(u, v, 2) = disc ? 30 : 40;
      depth_m(u, v) = disc ? 0.55f : 0.6f;
    }
  }
}

/// A camera of `width` x `height` pixels with a RealSense-like field of view (f = 0.9 width).
inline CameraIntrinsics SyntheticIntrinsics(int width, int height) {
  CameraIntrinsics K;
  K.width = width;
  K.height = height;
  K.fx = K.fy = 0.9 * width;
  K.cx = (width - 1) / 2.0;
  K.cy = (height - 1) / 2.0;
  return K;
}

class RobotBagWriter {
 public:
  static Result<std::unique_ptr<RobotBagWriter>> Open(const std::filesystem::path& path,
                                                      std::string compression = "") {
    AVP_ASSIGN_OR_RETURN(std::unique_ptr<ros::mcap::Writer> w,
                         ros::mcap::Writer::Open(path, {.compression = std::move(compression)}));
    auto out = std::unique_ptr<RobotBagWriter>(new RobotBagWriter(std::move(w)));
    AVP_RETURN_IF_ERROR(out->AddChannels());
    return out;
  }

  /// A TransformStamped of X (the pose of `child` in `parent`) at `t`.
  static ros::msg::TransformStamped Edge(const std::string& parent, const std::string& child,
                                         const RigidTransform& X, int64_t t) {
    ros::msg::TransformStamped e;
    e.header = {ros::msg::Time::FromNanoseconds(t), parent};
    e.child_frame_id = child;
    e.transform.translation = {X.translation().x(), X.translation().y(), X.translation().z()};
    const Eigen::Quaterniond q = X.quaternion();
    e.transform.rotation = {q.x(), q.y(), q.z(), q.w()};
    return e;
  }

  Status Tf(const std::vector<ros::msg::TransformStamped>& edges, int64_t t, bool is_static) {
    return Put(is_static ? tf_static_ : tf_, t, ros::msg::Encode(ros::msg::TFMessage{edges}));
  }

  Status Joints(const std::vector<std::string>& names, const Eigen::VectorXd& q, int64_t t) {
    ros::msg::JointState js;
    js.header = {ros::msg::Time::FromNanoseconds(t), ""};
    js.name = names;
    js.position.assign(q.data(), q.data() + q.size());
    return Put(joints_, t, ros::msg::Encode(js));
  }

  /// One frame: colour (rgb8), depth (16UC1 millimetres, as the RealSense driver) and its
  /// CameraInfo (`info`; its header is set here), stamped and logged at `t`.
  Status Frame(int64_t t, const ImageRgb8& rgb, const DepthImage& depth_m,
               ros::msg::CameraInfo info, const std::string& frame_id) {
    const ros::msg::Header header{ros::msg::Time::FromNanoseconds(t), frame_id};
    info.header = header;
    AVP_RETURN_IF_ERROR(Put(info_, t, ros::msg::Encode(info)));
    AVP_RETURN_IF_ERROR(Put(depth_, t,
                            ros::msg::Encode(ros::msg::ToDepthImage(
                                depth_m, header, ros::msg::DepthEncoding::k16UC1))));
    return Put(color_, t, ros::msg::Encode(ros::msg::ToColorImage(rgb, header)));
  }

  Status Close() { return w_->Close(); }

 private:
  explicit RobotBagWriter(std::unique_ptr<ros::mcap::Writer> w) : w_(std::move(w)) {}

  template <class M>
  Result<uint16_t> Channel(const std::string& topic) {
    AVP_ASSIGN_OR_RETURN(
        const uint16_t schema,
        w_->AddSchema(ros::msg::MessageTraits<M>::kRosName, "ros2msg", ros::msg::Definition<M>()));
    return w_->AddChannel(schema, topic, "cdr",
                          {{"offered_qos_profiles", ros::mcap::OfferedQosProfiles()}});
  }

  Status AddChannels() {
    AVP_ASSIGN_OR_RETURN(color_, Channel<ros::msg::Image>("/camera/camera/color/image_raw"));
    AVP_ASSIGN_OR_RETURN(
        depth_, Channel<ros::msg::Image>("/camera/camera/aligned_depth_to_color/image_raw"));
    AVP_ASSIGN_OR_RETURN(info_, Channel<ros::msg::CameraInfo>("/camera/camera/color/camera_info"));
    AVP_ASSIGN_OR_RETURN(tf_, Channel<ros::msg::TFMessage>("/tf"));
    AVP_ASSIGN_OR_RETURN(tf_static_, Channel<ros::msg::TFMessage>("/tf_static"));
    AVP_ASSIGN_OR_RETURN(joints_, Channel<ros::msg::JointState>("/joint_states"));
    return Status::Ok();
  }

  Status Put(uint16_t channel, int64_t t, const std::vector<uint8_t>& bytes) {
    return w_->Write(channel, seq_++, static_cast<uint64_t>(t), static_cast<uint64_t>(t), bytes);
  }

  std::unique_ptr<ros::mcap::Writer> w_;
  uint16_t color_ = 0, depth_ = 0, info_ = 0, tf_ = 0, tf_static_ = 0, joints_ = 0;
  uint32_t seq_ = 0;
};

}  // namespace avp::ros::bag::testing

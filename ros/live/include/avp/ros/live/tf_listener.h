#pragma once

#include <atomic>
#include <memory>
#include <mutex>
#include <string>

#include <avp/core/status.h>
#include <avp/ros/dds/node.h>
#include <avp/ros/msg/messages.h>
#include <avp/ros/msg/tf_buffer.h>

namespace avp::ros::live {

/// Fills a TfBuffer from /tf (reliable, keep-last 100) and /tf_static (reliable, transient
/// local), as tf2_ros::TransformListener does: TfBuffer::Add(TransformStamped). Transforms that
/// TfBuffer refuses are counted and the last reason kept; they never stop the listener.
class TfListener {
 public:
  static Result<std::unique_ptr<TfListener>> Create(
      ros::dds::Node& node, ros::msg::TfBuffer& buffer, const std::string& tf_topic = "/tf",
      const std::string& tf_static_topic = "/tf_static");
  uint64_t received() const { return received_; }
  uint64_t refused() const { return refused_; }
  std::string last_problem() const;

 private:
  explicit TfListener(ros::msg::TfBuffer& buffer) : buffer_(buffer) {}
  void OnMessage(const ros::msg::TFMessage& msg, bool is_static);

  ros::msg::TfBuffer& buffer_;
  std::atomic<uint64_t> received_{0};
  std::atomic<uint64_t> refused_{0};
  mutable std::mutex mutex_;
  std::string last_problem_;
  std::unique_ptr<ros::dds::Subscription<ros::msg::TFMessage>> tf_sub_, static_sub_;
};

/// Publishes transforms on /tf and /tf_static (tf2_ros::TransformBroadcaster and
/// StaticTransformBroadcaster).
class TfBroadcaster {
 public:
  static Result<std::unique_ptr<TfBroadcaster>> Create(
      ros::dds::Node& node, const std::string& tf_topic = "/tf",
      const std::string& tf_static_topic = "/tf_static");
  Status Send(const ros::msg::TFMessage& msg);
  /// Static transforms are latched: every call sends all static transforms given so far.
  Status SendStatic(const std::vector<ros::msg::TransformStamped>& transforms);

 private:
  std::unique_ptr<ros::dds::Publisher<ros::msg::TFMessage>> tf_, static_;
  std::vector<ros::msg::TransformStamped> statics_;
};

}  // namespace avp::ros::live

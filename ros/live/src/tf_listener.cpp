#include <fmt/format.h>

#include <avp/ros/live/tf_listener.h>

namespace avp::ros::live {

Result<std::unique_ptr<TfListener>> TfListener::Create(ros::dds::Node& node,
                                                       ros::msg::TfBuffer& buffer,
                                                       const std::string& tf_topic,
                                                       const std::string& tf_static_topic) {
  std::unique_ptr<TfListener> l(new TfListener(buffer));
  TfListener* self = l.get();
  AVP_ASSIGN_OR_RETURN(l->tf_sub_,
                       node.CreateSubscription<ros::msg::TFMessage>(
                           tf_topic, ros::dds::QosProfile::Tf(),
                           [self](ros::msg::TFMessage&& m, const ros::dds::SampleInfo&) {
                             self->OnMessage(m, false);
                           }));
  AVP_ASSIGN_OR_RETURN(l->static_sub_,
                       node.CreateSubscription<ros::msg::TFMessage>(
                           tf_static_topic, ros::dds::QosProfile::TfStatic(),
                           [self](ros::msg::TFMessage&& m, const ros::dds::SampleInfo&) {
                             self->OnMessage(m, true);
                           }));
  return l;
}

void TfListener::OnMessage(const ros::msg::TFMessage& msg, bool is_static) {
  for (const ros::msg::TransformStamped& t : msg.transforms) {
    ++received_;
    if (Status s = buffer_.Add(t, is_static); !s.ok()) {
      ++refused_;
      std::lock_guard lock(mutex_);
      last_problem_ = s.message();
    }
  }
}

std::string TfListener::last_problem() const {
  std::lock_guard lock(mutex_);
  return last_problem_;
}

Result<std::unique_ptr<TfBroadcaster>> TfBroadcaster::Create(ros::dds::Node& node,
                                                             const std::string& tf_topic,
                                                             const std::string& tf_static_topic) {
  auto b = std::make_unique<TfBroadcaster>();
  AVP_ASSIGN_OR_RETURN(
      b->tf_, node.CreatePublisher<ros::msg::TFMessage>(tf_topic, ros::dds::QosProfile::Tf()));
  AVP_ASSIGN_OR_RETURN(b->static_, node.CreatePublisher<ros::msg::TFMessage>(
                                       tf_static_topic, ros::dds::QosProfile::TfStatic()));
  return b;
}

Status TfBroadcaster::Send(const ros::msg::TFMessage& msg) { return tf_->Publish(msg); }

Status TfBroadcaster::SendStatic(const std::vector<ros::msg::TransformStamped>& transforms) {
  for (const ros::msg::TransformStamped& t : transforms) {
    bool replaced = false;
    for (ros::msg::TransformStamped& s : statics_) {
      if (s.child_frame_id == t.child_frame_id) {
        s = t;
        replaced = true;
      }
    }
    if (!replaced) statics_.push_back(t);
  }
  ros::msg::TFMessage msg;
  msg.transforms = statics_;
  return static_->Publish(msg);
}

}  // namespace avp::ros::live

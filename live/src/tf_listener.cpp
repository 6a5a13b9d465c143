#include <fmt/format.h>

#include <avp/live/tf_listener.h>

namespace avp::live {

Result<std::unique_ptr<TfListener>> TfListener::Create(ros2::Node& node, TfBuffer& buffer,
                                                       const std::string& tf_topic,
                                                       const std::string& tf_static_topic) {
  std::unique_ptr<TfListener> l(new TfListener(buffer));
  TfListener* self = l.get();
  AVP_ASSIGN_OR_RETURN(l->tf_sub_, node.CreateSubscription<rosmsg::TFMessage>(
                                       tf_topic, ros2::QosProfile::Tf(),
                                       [self](rosmsg::TFMessage&& m, const ros2::SampleInfo&) {
                                         self->OnMessage(m, false);
                                       }));
  AVP_ASSIGN_OR_RETURN(l->static_sub_, node.CreateSubscription<rosmsg::TFMessage>(
                                           tf_static_topic, ros2::QosProfile::TfStatic(),
                                           [self](rosmsg::TFMessage&& m, const ros2::SampleInfo&) {
                                             self->OnMessage(m, true);
                                           }));
  return l;
}

void TfListener::OnMessage(const rosmsg::TFMessage& msg, bool is_static) {
  for (const rosmsg::TransformStamped& t : msg.transforms) {
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

Result<std::unique_ptr<TfBroadcaster>> TfBroadcaster::Create(ros2::Node& node) {
  auto b = std::make_unique<TfBroadcaster>();
  AVP_ASSIGN_OR_RETURN(b->tf_,
                       node.CreatePublisher<rosmsg::TFMessage>("/tf", ros2::QosProfile::Tf()));
  AVP_ASSIGN_OR_RETURN(b->static_, node.CreatePublisher<rosmsg::TFMessage>(
                                       "/tf_static", ros2::QosProfile::TfStatic()));
  return b;
}

Status TfBroadcaster::Send(const rosmsg::TFMessage& msg) { return tf_->Publish(msg); }

Status TfBroadcaster::SendStatic(const std::vector<rosmsg::TransformStamped>& transforms) {
  for (const rosmsg::TransformStamped& t : transforms) {
    bool replaced = false;
    for (rosmsg::TransformStamped& s : statics_) {
      if (s.child_frame_id == t.child_frame_id) {
        s = t;
        replaced = true;
      }
    }
    if (!replaced) statics_.push_back(t);
  }
  rosmsg::TFMessage msg;
  msg.transforms = statics_;
  return static_->Publish(msg);
}

}  // namespace avp::live

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/mask_codec.h>
#include <avp/ros/bag/bag_reader.h>
#include <avp/ros/bag/encode.h>
#include <avp/ros/bag/layout.h>
#include <avp/ros/mcap/mcap.h>
#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/tf_buffer.h>

namespace avp::ros::bag {

// ---- Options ------------------------------------------------------------------------------------

const OptionTable<BagReadOptions>& BagReadOptionTable() {
  static const auto* table = [] {
    using O = BagReadOptions;
    auto* t = new OptionTable<O>("bag option");
    ros::msg::AddCameraTopicOptions(*t);
    t->Text("labels_prefix", &O::labels_prefix,
            "simulator label images PREFIX/instance, PREFIX/class (empty: none)");
    t->Real("tf_tolerance_ms", &O::tf_tolerance_ms, "ms", ValueRange::Closed(0, 10000),
            "outside a TF edge's samples, its nearest one within this much is used");
    t->Real("frame_rate_hz", &O::frame_rate_hz, "Hz", ValueRange::Closed(0, 1000),
            "real bags: fuse at most this many frames per second of bag time (0: every pair)");
    t->Integer("max_views", &O::max_views, "", ValueRange::Closed(0, 1000000),
               "fuse at most this many views (0: all)");
    t->Real("max_decoded_mb", &O::max_decoded_mb, "MB", ValueRange::Above(0),
            "the views are decoded in memory: at most this much");
    t->Flag("as_robot_bag", &O::as_robot_bag,
            "read an avp recording like a robot's bag (images, CameraInfo, TF; no /avp/step)");
    t->AddRule([](const O& o, std::vector<std::string>& errors) {
      if (!(o.min_depth_m > 0.0) || !(o.max_depth_m > o.min_depth_m) ||
          !std::isfinite(o.max_depth_m)) {
        errors.push_back(fmt::format("depth range [{}, {}] m must satisfy 0 < min < max",
                                     o.min_depth_m, o.max_depth_m));
      }
    });
    return t;
  }();
  return *table;
}

// ---- Reading ------------------------------------------------------------------------------------

namespace {

constexpr size_t kMaxSkippedKept = 10;

/// The messages of one topic, by log time.
struct TopicMessages {
  std::string schema;
  std::vector<const ros::mcap::Message*> messages;
  /// The message logged at exactly `t`, or null.
  const ros::mcap::Message* At(uint64_t t) const {
    auto it =
        std::lower_bound(messages.begin(), messages.end(), t,
                         [](const ros::mcap::Message* m, uint64_t x) { return m->log_time < x; });
    return it != messages.end() && (*it)->log_time == t ? *it : nullptr;
  }
};

class Reader {
 public:
  Reader(const BagReadOptions& options, Bag& bag)
      : o_(options),
        bag_(bag),
        // The whole bag is kept; its tolerance on both sides of an edge's samples.
        tf_(ros::msg::TfBuffer::Options{.cache_s = 0.0,
                                        .extrapolation_s = options.tf_tolerance_ms * 1e-3}) {}

  /// Keeps `view`, unless the views would then hold more than max_decoded_mb.
  Status Keep(BagView view) {
    const RgbdFrame& f = view.observation.frame;
    decoded_bytes_ += f.rgb.data().size() + f.depth_m.data().size() * sizeof(float) +
                      (view.observation.labels ? f.rgb.data().size() : 0);
    if (view.segmentation) {
      for (const InstanceMask& m : view.segmentation->instances)
        decoded_bytes_ += m.mask.data().size();
    }
    if (static_cast<double>(decoded_bytes_) > o_.max_decoded_mb * 1e6) {
      return ResourceExhaustedError(fmt::format(
          "{}: the views to fuse need more than max_decoded_mb = {} MB decoded (at view {}, stamp "
          "{}): fuse fewer frames (--fps, --max-views) or raise the limit",
          bag_.path.string(), o_.max_decoded_mb, bag_.views.size() + 1,
          ros::msg::FormatStamp(f.stamp_ns)));
    }
    bag_.views.push_back(std::move(view));
    return Status::Ok();
  }

  void Skip(std::string why) {
    if (bag_.skipped.size() < kMaxSkippedKept) bag_.skipped.push_back(std::move(why));
    ++bag_.skipped_count;
  }

  Status Index(const ros::mcap::File& file) {
    std::map<uint16_t, std::string> schema_names;
    for (const ros::mcap::Schema& s : file.schemas) schema_names[s.id] = s.name;
    std::map<uint16_t, const ros::mcap::Channel*> channels;
    for (const ros::mcap::Channel& c : file.channels) channels[c.id] = &c;
    for (const ros::mcap::Message& m : file.messages) {
      auto c = channels.find(m.channel_id);
      if (c == channels.end()) continue;  // the reader refuses these; defensive
      TopicMessages& t = topics_[c->second->topic];
      if (t.messages.empty()) {
        auto s = schema_names.find(c->second->schema_id);
        t.schema = s == schema_names.end() ? std::string() : s->second;
        if (c->second->message_encoding != "cdr") {
          return InvalidArgumentError(fmt::format(
              "{}: topic {} has message encoding {}, not cdr (a ROS 2 bag)", bag_.path.string(),
              QuoteText(c->second->topic), QuoteText(c->second->message_encoding)));
        }
      }
      t.messages.push_back(&m);
    }
    for (auto& [topic, t] : topics_) {
      std::stable_sort(t.messages.begin(), t.messages.end(),
                       [](const ros::mcap::Message* a, const ros::mcap::Message* b) {
                         return a->log_time < b->log_time;
                       });
      bag_.topic_messages[topic] = t.messages.size();
    }
    return Status::Ok();
  }

  std::string TopicList() const {
    std::vector<std::string> names;
    for (const auto& [topic, t] : topics_) {
      names.push_back(
          fmt::format("{} ({}, {})", topic, t.schema.empty() ? "?" : t.schema, t.messages.size()));
    }
    return EscapeText(fmt::format("{}", fmt::join(names, ", ")), 800);
  }

  /// The topic's messages, checking its type; NotFound listing the bag's topics.
  Result<const TopicMessages*> Topic(const std::string& topic, std::string_view type,
                                     bool required) {
    auto it = topics_.find(topic);
    if (it == topics_.end() || it->second.messages.empty()) {
      if (!required) return static_cast<const TopicMessages*>(nullptr);
      return NotFoundError(fmt::format("{}: no messages on {} (the bag's topics: {}){}",
                                       bag_.path.string(), QuoteText(topic), TopicList(),
                                       bag_.damage.ok() ? "" : " in the intact part"));
    }
    if (it->second.schema != type) {
      return InvalidArgumentError(fmt::format("{}: topic {} carries {}, not {}", bag_.path.string(),
                                              QuoteText(topic), QuoteText(it->second.schema),
                                              type));
    }
    return &it->second;
  }

  /// Both TF topics into the tree; bad transforms are skipped and noted.
  Status ReadTf() {
    for (const auto& [topic, is_static] :
         {std::pair{o_.tf_static_topic, true}, std::pair{o_.tf_topic, false}}) {
      if (topic.empty()) continue;
      AVP_ASSIGN_OR_RETURN(const TopicMessages* t,
                           Topic(topic, "tf2_msgs/msg/TFMessage", /*required=*/false));
      if (t == nullptr) continue;
      for (const ros::mcap::Message* m : t->messages) {
        Result<ros::msg::TFMessage> tf = ros::msg::Decode<ros::msg::TFMessage>(m->data);
        if (!tf.ok()) {
          Skip(fmt::format("{} message at {}: {}", topic,
                           ros::msg::FormatStamp(static_cast<int64_t>(m->log_time)),
                           tf.status().message()));
          continue;
        }
        for (const ros::msg::TransformStamped& x : tf->transforms) {
          if (Status s = tf_.Add(x, is_static); !s.ok())
            Skip(fmt::format("{}: {}", topic, s.message()));
        }
      }
    }
    return Status::Ok();
  }

  Result<RigidTransform> CameraPose(const std::string& camera_frame, int64_t stamp_ns) const {
    if (tf_.empty()) {
      return NotFoundError(fmt::format("no transforms on {} or {}", QuoteText(o_.tf_topic),
                                       QuoteText(o_.tf_static_topic)));
    }
    return tf_.Lookup(o_.base_frame, camera_frame, stamp_ns);
  }

  /// The CameraInfo nearest in time to `stamp_ns` (the latest at or before it, else the first
  /// after it) as intrinsics.
  Result<CameraIntrinsics> Intrinsics(const TopicMessages& infos, int64_t stamp_ns) {
    // Decoded once; CameraInfo messages are small.
    if (infos_.empty()) {
      for (const ros::mcap::Message* m : infos.messages) {
        Result<ros::msg::CameraInfo> info = ros::msg::Decode<ros::msg::CameraInfo>(m->data);
        if (!info.ok()) {
          Skip(fmt::format("{} at {}: {}", o_.camera_info_topic,
                           ros::msg::FormatStamp(static_cast<int64_t>(m->log_time)),
                           info.status().message()));
          continue;
        }
        infos_.emplace_back(info->header.stamp.ToNanoseconds(), std::move(*info));
      }
      std::stable_sort(infos_.begin(), infos_.end(),
                       [](const auto& a, const auto& b) { return a.first < b.first; });
    }
    if (infos_.empty()) {
      return InvalidArgumentError(fmt::format("{}: no CameraInfo on {} could be decoded",
                                              bag_.path.string(), QuoteText(o_.camera_info_topic)));
    }
    auto it = std::upper_bound(infos_.begin(), infos_.end(), stamp_ns,
                               [](int64_t t, const auto& x) { return t < x.first; });
    const ros::msg::CameraInfo& info = it == infos_.begin() ? it->second : std::prev(it)->second;
    return ros::msg::FromCameraInfo(info, o_.min_depth_m, o_.max_depth_m);
  }

  /// Simulator labels at log time `t` (both images), when the bag has them.
  Result<std::optional<SimulatorLabels>> Labels(uint64_t t, int width, int height) {
    if (o_.labels_prefix.empty()) return std::optional<SimulatorLabels>();
    const std::string inst_topic = o_.labels_prefix + "/instance";
    const std::string class_topic = o_.labels_prefix + "/class";
    AVP_ASSIGN_OR_RETURN(const TopicMessages* inst,
                         Topic(inst_topic, "sensor_msgs/msg/Image", /*required=*/false));
    AVP_ASSIGN_OR_RETURN(const TopicMessages* cls,
                         Topic(class_topic, "sensor_msgs/msg/Image", /*required=*/false));
    if (inst == nullptr || cls == nullptr) return std::optional<SimulatorLabels>();
    const ros::mcap::Message* mi = inst->At(t);
    const ros::mcap::Message* mc = cls->At(t);
    if (mi == nullptr || mc == nullptr) return std::optional<SimulatorLabels>();
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image i, ros::msg::Decode<ros::msg::Image>(mi->data));
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image c, ros::msg::Decode<ros::msg::Image>(mc->data));
    AVP_ASSIGN_OR_RETURN(SimulatorLabels labels,
                         ros::msg::LabelsFromImages(i, c, width, height, o_.labels_prefix));
    return std::optional<SimulatorLabels>(std::move(labels));
  }

  /// Colour + depth + intrinsics of one frame, `color` and `depth` already decoded.
  Result<RgbdFrame> Frame(const ros::msg::Image& color, const ros::msg::Image& depth,
                          const TopicMessages& infos) {
    RgbdFrame frame;
    AVP_ASSIGN_OR_RETURN(frame.rgb, ros::msg::ColorFromImage(color, o_.color_topic));
    AVP_ASSIGN_OR_RETURN(frame.depth_m, ros::msg::DepthFromImage(depth, o_.depth_topic));
    frame.stamp_ns = color.header.stamp.ToNanoseconds();
    AVP_ASSIGN_OR_RETURN(frame.K, Intrinsics(infos, frame.stamp_ns));
    if (!frame.depth_m.SameSizeAs(frame.rgb) || frame.K.width != frame.rgb.width() ||
        frame.K.height != frame.rgb.height()) {
      return InvalidArgumentError(fmt::format(
          "colour {}x{}, depth {}x{} and CameraInfo {}x{} differ in size (depth must be aligned "
          "to colour)",
          frame.rgb.width(), frame.rgb.height(), frame.depth_m.width(), frame.depth_m.height(),
          frame.K.width, frame.K.height));
    }
    frame.frame_id = o_.camera_frame.empty() ? color.header.frame_id : o_.camera_frame;
    return frame;
  }

  Status ReadAvpSteps(const TopicMessages& steps) {
    AVP_ASSIGN_OR_RETURN(const TopicMessages* color,
                         Topic(o_.color_topic, "sensor_msgs/msg/Image", true));
    AVP_ASSIGN_OR_RETURN(const TopicMessages* depth,
                         Topic(o_.depth_topic, "sensor_msgs/msg/Image", true));
    AVP_ASSIGN_OR_RETURN(const TopicMessages* infos,
                         Topic(o_.camera_info_topic, "sensor_msgs/msg/CameraInfo", true));
    AVP_ASSIGN_OR_RETURN(const TopicMessages* instances,
                         Topic(std::string(kInstancesTopic), "std_msgs/msg/String", false));
    for (const ros::mcap::Message* m : steps.messages) {
      if (o_.max_views > 0 && static_cast<int>(bag_.views.size()) >= o_.max_views) break;
      Result<BagView> view = AvpStep(*m, *color, *depth, *infos, instances);
      if (!view.ok()) {
        Skip(fmt::format("step at {}: {}", ros::msg::FormatStamp(static_cast<int64_t>(m->log_time)),
                         view.status().message()));
        continue;
      }
      AVP_RETURN_IF_ERROR(Keep(std::move(*view)));
    }
    return Status::Ok();
  }

  Result<BagView> AvpStep(const ros::mcap::Message& m, const TopicMessages& colors,
                          const TopicMessages& depths, const TopicMessages& infos,
                          const TopicMessages* instances) {
    AVP_ASSIGN_OR_RETURN(const ros::msg::String text, ros::msg::Decode<ros::msg::String>(m.data));
    BagView view;
    try {
      view.step = nlohmann::json::parse(text.data);
    } catch (const nlohmann::json::parse_error& e) {
      return InvalidArgumentError(
          fmt::format("{}: malformed JSON: {}", kStepTopic, EscapeText(e.what(), 200)));
    }
    if (!view.step.is_object()) {
      return InvalidArgumentError(fmt::format("{}: not a JSON object", kStepTopic));
    }
    if (auto v = view.step.find("view"); v != view.step.end() && v->is_number_integer()) {
      view.index = v->get<int>();
    } else {
      view.index = static_cast<int>(bag_.views.size());
    }
    const uint64_t t = m.log_time;
    const ros::mcap::Message* mc = colors.At(t);
    const ros::mcap::Message* md = depths.At(t);
    if (mc == nullptr || md == nullptr) {
      return NotFoundError(fmt::format("no {} image logged at the step's time",
                                       mc == nullptr ? o_.color_topic : o_.depth_topic));
    }
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image color, ros::msg::Decode<ros::msg::Image>(mc->data));
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image depth, ros::msg::Decode<ros::msg::Image>(md->data));
    AVP_ASSIGN_OR_RETURN(view.observation.frame, Frame(color, depth, infos));
    RgbdFrame& frame = view.observation.frame;
    // The exact pose from the step (TF's quaternion does not round-trip bit for bit). The step's
    // pose is the arm's; the frame's (TF) is what was fused: they agree in simulation, while a
    // live robot's camera pose comes from its TF, so a TF pose that differs is used instead.
    Result<RigidTransform> tf_pose = CameraPose(frame.frame_id, frame.stamp_ns);
    if (auto x = view.step.find("X_WC"); x != view.step.end()) {
      Result<RigidTransform> step_pose = PoseFromJson(*x);
      if (!step_pose.ok())
        return step_pose.status().WithContext(std::string(kStepTopic) + ": X_WC");
      frame.X_WC = *step_pose;
      if (tf_pose.ok() && !tf_pose->IsNearlyEqualTo(*step_pose, 1e-6, 1e-6)) frame.X_WC = *tf_pose;
    } else if (tf_pose.ok()) {
      frame.X_WC = *tf_pose;
    } else {
      return tf_pose.status();
    }
    if (auto q = view.step.find("q"); q != view.step.end() && q->is_array()) {
      view.q.resize(static_cast<Eigen::Index>(q->size()));
      for (size_t i = 0; i < q->size(); ++i) {
        if (!(*q)[i].is_number()) {
          return InvalidArgumentError(fmt::format("{}: q[{}] is {}, not a number", kStepTopic, i,
                                                  EscapeText((*q)[i].dump())));
        }
        view.q[static_cast<Eigen::Index>(i)] = (*q)[i].get<double>();
      }
    }
    AVP_ASSIGN_OR_RETURN(view.observation.labels, Labels(t, frame.rgb.width(), frame.rgb.height()));
    if (instances != nullptr) {
      if (const ros::mcap::Message* mi = instances->At(t); mi != nullptr) {
        AVP_ASSIGN_OR_RETURN(const ros::msg::String s,
                             ros::msg::Decode<ros::msg::String>(mi->data));
        nlohmann::json j;
        try {
          j = nlohmann::json::parse(s.data);
        } catch (const nlohmann::json::parse_error& e) {
          return InvalidArgumentError(
              fmt::format("{}: malformed JSON: {}", kInstancesTopic, EscapeText(e.what(), 200)));
        }
        Result<Segmentation> seg = InstancesFromJson(j);
        if (!seg.ok()) return seg.status().WithContext(std::string(kInstancesTopic));
        if (Status v = seg->ValidateFor(frame.rgb.width(), frame.rgb.height()); !v.ok()) {
          return v.WithContext(std::string(kInstancesTopic));
        }
        view.segmentation = std::move(*seg);
      }
    }
    return view;
  }

  Status ReadRobotBag() {
    AVP_ASSIGN_OR_RETURN(const TopicMessages* colors,
                         Topic(o_.color_topic, "sensor_msgs/msg/Image", true));
    AVP_ASSIGN_OR_RETURN(const TopicMessages* depths,
                         Topic(o_.depth_topic, "sensor_msgs/msg/Image", true));
    AVP_ASSIGN_OR_RETURN(const TopicMessages* infos,
                         Topic(o_.camera_info_topic, "sensor_msgs/msg/CameraInfo", true));
    // Stamps first (each image decoded once here, and again only when it is used).
    auto stamps = [&](const TopicMessages& t, const std::string& topic) {
      std::vector<std::pair<int64_t, const ros::mcap::Message*>> out;
      for (const ros::mcap::Message* m : t.messages) {
        Result<ros::msg::Image> image = ros::msg::Decode<ros::msg::Image>(m->data);
        if (!image.ok()) {
          Skip(fmt::format("{} at {}: {}", topic,
                           ros::msg::FormatStamp(static_cast<int64_t>(m->log_time)),
                           image.status().message()));
          continue;
        }
        out.emplace_back(image->header.stamp.ToNanoseconds(), m);
      }
      std::stable_sort(out.begin(), out.end(),
                       [](const auto& a, const auto& b) { return a.first < b.first; });
      return out;
    };
    const auto color_stamps = stamps(*colors, o_.color_topic);
    const auto depth_stamps = stamps(*depths, o_.depth_topic);
    const auto skew_ns = static_cast<int64_t>(std::llround(o_.max_pair_skew_ms * 1e6));
    const int64_t period_ns =
        o_.frame_rate_hz > 0.0 ? static_cast<int64_t>(std::llround(1e9 / o_.frame_rate_hz)) : 0;
    // Thinning: the first pair at or after each instant first + k / rate, or up to 1 % of a
    // period before it (a 30 Hz camera's 30th frame is stamped 10 ns short of 1 s).
    std::optional<int64_t> first_stamp;
    int64_t next_ns = 0;
    const int64_t early_ns = period_ns / 100;
    int pair_index = 0;
    for (const auto& [stamp, mc] : color_stamps) {
      auto it = std::lower_bound(depth_stamps.begin(), depth_stamps.end(), stamp,
                                 [](const auto& x, int64_t t) { return x.first < t; });
      const ros::mcap::Message* md = nullptr;
      int64_t best = std::numeric_limits<int64_t>::max();
      for (auto c : {it, it == depth_stamps.begin() ? it : std::prev(it)}) {
        if (c == depth_stamps.end()) continue;
        const int64_t d = std::abs(c->first - stamp);
        if (d < best) {
          best = d;
          md = c->second;
        }
      }
      if (md == nullptr || best > skew_ns) continue;
      const int index = pair_index++;
      ++bag_.pairs;
      if ((first_stamp && stamp < next_ns - early_ns) ||
          (o_.max_views > 0 && static_cast<int>(bag_.views.size()) >= o_.max_views)) {
        ++bag_.pairs_thinned;
        continue;
      }
      Result<BagView> view = RobotView(index, *mc, *md, *infos);
      if (!view.ok()) {
        Skip(fmt::format("frame at {}: {}", ros::msg::FormatStamp(stamp), view.status().message()));
        continue;
      }
      if (period_ns > 0) {
        if (!first_stamp) first_stamp = stamp;
        next_ns = *first_stamp + ((stamp - *first_stamp + early_ns) / period_ns + 1) * period_ns;
      }
      AVP_RETURN_IF_ERROR(Keep(std::move(*view)));
    }
    if (bag_.pairs == 0) {
      return NotFoundError(fmt::format(
          "{}: no colour image on {} has a depth image on {} within {} ms ({} colour, {} depth "
          "images)",
          bag_.path.string(), QuoteText(o_.color_topic), QuoteText(o_.depth_topic),
          o_.max_pair_skew_ms, color_stamps.size(), depth_stamps.size()));
    }
    return Status::Ok();
  }

  Result<BagView> RobotView(int index, const ros::mcap::Message& mc, const ros::mcap::Message& md,
                            const TopicMessages& infos) {
    BagView view;
    view.index = index;
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image color, ros::msg::Decode<ros::msg::Image>(mc.data));
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image depth, ros::msg::Decode<ros::msg::Image>(md.data));
    AVP_ASSIGN_OR_RETURN(view.observation.frame, Frame(color, depth, infos));
    RgbdFrame& frame = view.observation.frame;
    if (frame.frame_id.empty()) {
      return InvalidArgumentError(fmt::format(
          "{}: the image has no frame_id; give the camera frame (camera_frame)", o_.color_topic));
    }
    AVP_ASSIGN_OR_RETURN(frame.X_WC, CameraPose(frame.frame_id, frame.stamp_ns));
    AVP_ASSIGN_OR_RETURN(view.observation.labels,
                         Labels(mc.log_time, frame.rgb.width(), frame.rgb.height()));
    return view;
  }

  const BagReadOptions& o_;
  Bag& bag_;
  std::map<std::string, TopicMessages> topics_;
  ros::msg::TfBuffer tf_;
  std::vector<std::pair<int64_t, ros::msg::CameraInfo>> infos_;
  uint64_t decoded_bytes_ = 0;
};

}  // namespace

Result<Bag> ReadBag(const std::filesystem::path& path, const BagReadOptions& options) {
  AVP_RETURN_IF_ERROR(BagReadOptionTable().Validate(options));
  Bag bag;
  bag.path = path;
  ros::mcap::StreamResult stream = ros::mcap::ReadStreaming(path);
  if (!stream.status.ok() && stream.file.messages.empty()) {
    return stream.status;
  }
  bag.damage = stream.status;
  bag.intact_bytes = stream.intact_bytes;
  std::error_code ec;
  bag.file_bytes = std::filesystem::file_size(path, ec);
  for (const ros::mcap::Metadata& m : stream.file.metadata) {
    if (m.name == kMetadataName) bag.avp_metadata = m.metadata;
  }
  for (const ros::mcap::Attachment& a : stream.file.attachments) {
    if (a.name != kGroundTruthAttachment) continue;
    try {
      bag.ground_truth = nlohmann::json::parse(a.data);
    } catch (const nlohmann::json::parse_error& e) {
      return InvalidArgumentError(fmt::format("{}: attachment {}: malformed JSON: {}",
                                              path.string(), kGroundTruthAttachment,
                                              EscapeText(e.what(), 200)));
    }
  }
  Reader reader(options, bag);
  AVP_RETURN_IF_ERROR(reader.Index(stream.file));
  AVP_RETURN_IF_ERROR(reader.ReadTf());
  AVP_ASSIGN_OR_RETURN(const TopicMessages* steps,
                       reader.Topic(std::string(kStepTopic), "std_msgs/msg/String", false));
  if (steps != nullptr && !options.as_robot_bag) {
    bag.avp_recording = true;
    AVP_RETURN_IF_ERROR(reader.ReadAvpSteps(*steps));
  } else {
    AVP_RETURN_IF_ERROR(reader.ReadRobotBag());
  }
  if (bag.views.empty()) {
    std::string why = bag.skipped.empty() ? std::string("nothing to fuse") : bag.skipped.front();
    return InvalidArgumentError(fmt::format("{}: no view could be read{}: {}", path.string(),
                                            bag.damage.ok() ? "" : " (the file is damaged)", why));
  }
  return bag;
}

}  // namespace avp::ros::bag

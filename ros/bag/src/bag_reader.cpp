#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <utility>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/mask_codec.h>
#include <avp/robot/arm_model.h>
#include <avp/ros/bag/bag_reader.h>
#include <avp/ros/bag/encode.h>
#include <avp/ros/bag/layout.h>
#include <avp/ros/mcap/mcap.h>
#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/lens.h>
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
    t->Text("joint_states_topic", &O::joint_states_topic,
            "without a TF transform to the camera: the arm's joints (sensor_msgs/JointState)");
    t->Text("arm", &O::arm,
            "the arm's YAML for the joints' camera pose (empty: avp's default arm)");
    t->Text("distortion", &O::distortion,
            "lens distortion: rectify (colour bilinear, depth nearest) or ignore");
    t->Flag("as_robot_bag", &O::as_robot_bag,
            "read an avp recording like a robot's bag (images, CameraInfo, TF; no /avp/step)");
    t->AddRule([](const O& o, std::vector<std::string>& errors) {
      if (o.distortion != "rectify" && o.distortion != "ignore") {
        errors.push_back(
            fmt::format("distortion = {}: rectify or ignore", QuoteText(o.distortion)));
      }
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

const OptionTable<FrameSelection>& FrameSelectionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<FrameSelection>("replay key");
    AddFrameSelectionOptions(*t);
    return t;
  }();
  return *table;
}

size_t FrameAccount::skipped_count() const {
  size_t n = 0;
  for (const auto& [reason, count] : skipped_by_reason) n += count;
  return n;
}

size_t FrameAccount::left_out_count() const {
  size_t n = 0;
  for (const auto& [reason, count] : left_out) n += count;
  return n;
}

// ---- Reading ------------------------------------------------------------------------------------

namespace {

constexpr size_t kMaxSkippedKept = 10;
/// Images kept waiting for their partner (colour or depth) at most; beyond, the oldest goes.
constexpr size_t kMaxQueued = 64;
/// Joint states kept at most (60 s at 1 kHz).
constexpr size_t kMaxJointStates = 60'000;
/// CameraInfo messages kept (the nearest in time to an image is used).
constexpr size_t kMaxInfos = 16;
/// TF and joint-state history kept, seconds of bag time.
constexpr double kHistoryS = 60.0;
/// A pair waits for TF (and a CameraInfo) at most this long in bag time beyond tf_tolerance_ms.
constexpr int64_t kPoseWaitNs = 250'000'000;

/// The stamp and frame_id at the start of a CDR-encoded message with a std_msgs/Header (Image,
/// CameraInfo, JointState), read without decoding the rest; nullopt when it is not one.
struct PeekedHeader {
  int64_t stamp_ns = 0;
  std::string frame_id;
};

std::optional<PeekedHeader> PeekHeader(std::span<const uint8_t> d) {
  if (d.size() < 16 || d[0] != 0 || d[1] > 1) return std::nullopt;
  const bool le = d[1] == 1;
  auto u32 = [&](size_t at) {
    uint32_t v = 0;
    for (size_t i = 0; i < 4; ++i) {
      const uint32_t b = d[at + (le ? i : 3 - i)];
      v |= b << (8 * i);
    }
    return v;
  };
  const auto sec = static_cast<int32_t>(u32(4));
  const uint32_t nsec = u32(8);
  const uint32_t len = u32(12);
  if (nsec >= 1'000'000'000u || len == 0 || len > d.size() - 16) return std::nullopt;
  PeekedHeader h;
  h.stamp_ns = int64_t{sec} * 1'000'000'000 + nsec;
  h.frame_id.assign(reinterpret_cast<const char*>(d.data()) + 16, len - 1);
  return h;
}

/// A colour or depth image as it came, waiting for its partner.
struct RawImage {
  int64_t stamp_ns = 0;
  uint64_t log_time = 0;
  std::string frame_id;
  std::vector<uint8_t> data;
};

/// A colour/depth pair waiting for its pose (TF at its stamp may come later in the bag).
struct PendingPair {
  int index = 0;
  RawImage color, depth;
};

/// The rectifier of the camera a bag's CameraInfo describes, rebuilt only when the lens changes
/// (LensModel::SameLensAs: not for a new stamp).
class LensCache {
 public:
  /// Rectifies `frame` (raw images, K, pose set) by `info`'s lens, unless options.distortion is
  /// "ignore". Errors: the lens model's (an unknown model, wrong coefficients).
  Status Apply(const ros::msg::CameraInfo& info, const BagReadOptions& o, RgbdFrame& frame) {
    if (o.distortion == "ignore") return Status::Ok();
    AVP_ASSIGN_OR_RETURN(ros::msg::LensModel model,
                         ros::msg::LensModelFromCameraInfo(info, o.min_depth_m, o.max_depth_m));
    if (!rectifier_.model().SameLensAs(model)) rectifier_ = ros::msg::Rectifier(std::move(model));
    if (rectifier_.identity()) return Status::Ok();
    return rectifier_.Rectify(frame);
  }

 private:
  ros::msg::Rectifier rectifier_;
};

std::string StampText(int64_t stamp_ns) { return ros::msg::FormatStamp(stamp_ns); }

/// "/tf (tf2_msgs/msg/TFMessage, 300), ..." for messages that list a bag's topics.
std::string FormatTopics(const std::map<std::string, uint64_t>& counts,
                         const std::map<std::string, std::string>& types) {
  std::vector<std::string> names;
  for (const auto& [topic, n] : counts) {
    auto t = types.find(topic);
    names.push_back(fmt::format("{} ({}, {})", topic,
                                t == types.end() || t->second.empty() ? "?" : t->second, n));
  }
  return EscapeText(fmt::format("{}", fmt::join(names, ", ")), 800);
}

}  // namespace

struct BagReader::Impl {
  explicit Impl(const BagReadOptions& options)
      : o(options),
        tf(ros::msg::TfBuffer::Options{.cache_s = kHistoryS,
                                       .extrapolation_s = options.tf_tolerance_ms * 1e-3}) {}

  BagReadOptions o;
  FrameSelection selection;
  std::filesystem::path path;
  std::unique_ptr<MessageSource> source;
  bool avp_recording = false;
  std::map<std::string, std::string> avp_metadata;
  std::optional<nlohmann::json> ground_truth;
  Status damage;
  FrameAccount account;
  std::map<std::string, uint64_t> topic_messages;
  std::map<std::string, std::string> topic_types;  ///< as met
  bool started = false, ended = false, done = false;
  uint64_t latest_log_time = 0;
  std::deque<BagView> ready;
  // Poses, intrinsics, labels.
  ros::msg::TfBuffer tf;
  std::deque<std::pair<int64_t, ros::msg::CameraInfo>> infos;
  std::optional<robot::ArmModel> arm;
  Status arm_status;
  std::deque<std::pair<int64_t, Eigen::VectorXd>> joints;  ///< stamp, the arm's joints
  std::map<std::string, std::deque<std::pair<uint64_t, std::vector<uint8_t>>>> labels;
  // Robot bags: pairing and selection.
  std::deque<RawImage> colors, depths;
  std::deque<PendingPair> pending;
  std::optional<int64_t> first_color_ns, latest_depth_ns;
  int pair_index = 0;
  size_t passed_rest = 0;
  std::optional<int64_t> fps_first_ns;
  int64_t fps_next_ns = 0;
  // avp recordings: the messages of the current log time.
  uint64_t moment_time = 0;
  std::map<std::string, std::vector<uint8_t>> moment;

  std::string Where() const { return path.string(); }

  // ---- Accounting ----

  void Skip(int index, int64_t stamp_ns, const std::string& reason, const std::string& why) {
    ++account.skipped_by_reason[reason];
    if (account.skipped.size() < kMaxSkippedKept) {
      account.skipped.push_back(fmt::format("stamp {}: {}", StampText(stamp_ns), why));
    }
    Record(index, stamp_ns, "skipped: " + why);
  }

  void Record(int index, int64_t stamp_ns, std::string what) {
    if (account.frames.size() < FrameAccount::kMaxFrames) {
      account.frames.push_back({index, stamp_ns, std::move(what)});
    }
  }

  void Keep(BagView view) {
    ++account.fused;
    Record(view.index, view.observation.frame.stamp_ns, "fused");
    ready.push_back(std::move(view));
    if (selection.max_views > 0 && static_cast<int>(account.fused) >= selection.max_views) {
      done = true;  // nothing after it is read
    }
  }

  // ---- Topics ----

  std::string TopicList() const { return FormatTopics(topic_messages, topic_types); }

  /// The first message of a topic avp reads: its type and encoding checked.
  Status CheckTopic(const BagMessage& m, std::string_view type) {
    if (m.encoding != "cdr") {
      return InvalidArgumentError(
          fmt::format("{}: topic {} has message encoding {}, not cdr (a ROS 2 bag)", Where(),
                      QuoteText(m.topic), QuoteText(m.encoding)));
    }
    if (!m.type.empty() && m.type != type) {
      return InvalidArgumentError(fmt::format("{}: topic {} carries {}, not {}", Where(),
                                              QuoteText(m.topic), QuoteText(m.type), type));
    }
    return Status::Ok();
  }

  // ---- The loop ----

  /// Reads messages until a view is ready or the bag ends.
  Status Fill() {
    while (ready.empty() && !ended) {
      if (done) {
        ended = true;
        break;
      }
      Result<std::optional<BagMessage>> m = source->Next();
      if (!m.ok() || !*m) {
        if (!m.ok()) damage = m.status();
        ended = true;
        AVP_RETURN_IF_ERROR(Flush());
        break;
      }
      AVP_RETURN_IF_ERROR(Dispatch(std::move(**m)));
    }
    return Status::Ok();
  }

  Status Dispatch(BagMessage m) {
    if (++topic_messages[m.topic] == 1) topic_types.emplace(m.topic, m.type);
    latest_log_time = std::max(latest_log_time, m.log_time);
    if (m.topic == o.tf_topic || m.topic == o.tf_static_topic) {
      if (topic_messages[m.topic] == 1)
        AVP_RETURN_IF_ERROR(CheckTopic(m, "tf2_msgs/msg/TFMessage"));
      AddTf(m, m.topic == o.tf_static_topic);
    } else if (m.topic == o.camera_info_topic) {
      if (topic_messages[m.topic] == 1)
        AVP_RETURN_IF_ERROR(CheckTopic(m, "sensor_msgs/msg/CameraInfo"));
      AddCameraInfo(m);
    } else if (m.topic == o.joint_states_topic && !avp_recording) {
      AddJoints(m);
    }
    return avp_recording ? DispatchAvp(std::move(m)) : DispatchRobot(std::move(m));
  }

  /// The end of the bag (or of its intact part): what waits is finished.
  Status Flush() {
    if (avp_recording) return EndMoment();
    if (!done) Pair(/*at_end=*/true);
    return Resolve(/*at_end=*/true);
  }

  // ---- TF, CameraInfo, joints, labels ----

  void AddTf(const BagMessage& m, bool is_static) {
    Result<ros::msg::TFMessage> tfm = ros::msg::Decode<ros::msg::TFMessage>(m.data);
    if (!tfm.ok()) {
      Skip(-1, static_cast<int64_t>(m.log_time), "bad TF message",
           fmt::format("{}: {}", m.topic, tfm.status().message()));
      return;
    }
    for (const ros::msg::TransformStamped& x : tfm->transforms) {
      if (Status s = tf.Add(x, is_static); !s.ok()) {
        Skip(-1, x.header.stamp.ToNanoseconds(), "bad transform",
             fmt::format("{}: {}", m.topic, s.message()));
      }
    }
  }

  void AddCameraInfo(const BagMessage& m) {
    Result<ros::msg::CameraInfo> info = ros::msg::Decode<ros::msg::CameraInfo>(m.data);
    if (!info.ok()) {
      Skip(-1, static_cast<int64_t>(m.log_time), "bad CameraInfo",
           fmt::format("{}: {}", m.topic, info.status().message()));
      return;
    }
    const int64_t stamp = info->header.stamp.ToNanoseconds();
    auto at = std::upper_bound(infos.begin(), infos.end(), stamp,
                               [](int64_t t, const auto& x) { return t < x.first; });
    infos.emplace(at, stamp, std::move(*info));
    if (infos.size() > kMaxInfos) infos.pop_front();
  }

  /// The CameraInfo nearest in time: the latest at or before the stamp, else the first after.
  const ros::msg::CameraInfo* InfoAt(int64_t stamp_ns) const {
    if (infos.empty()) return nullptr;
    auto it = std::upper_bound(infos.begin(), infos.end(), stamp_ns,
                               [](int64_t t, const auto& x) { return t < x.first; });
    return it == infos.begin() ? &it->second : &std::prev(it)->second;
  }

  void AddJoints(const BagMessage& m) {
    if (!arm && arm_status.ok()) {
      Result<robot::ArmModel> a = o.arm.empty() ? robot::LoadDefaultArm() : robot::LoadArm(o.arm);
      if (!a.ok()) {
        arm_status = a.status();
        return;
      }
      arm = std::move(*a);
    }
    if (!arm) return;
    Result<ros::msg::JointState> js = ros::msg::Decode<ros::msg::JointState>(m.data);
    if (!js.ok() || js->name.size() != js->position.size()) return;
    Eigen::VectorXd q(arm->num_joints());
    for (int j = 0; j < arm->num_joints(); ++j) {
      const auto& name = arm->joint_names()[static_cast<size_t>(j)];
      const auto it = std::find(js->name.begin(), js->name.end(), name);
      if (it == js->name.end()) {
        if (arm_status.ok()) {
          arm_status = NotFoundError(
              fmt::format("{} has no joint {} of the arm's URDF (it has: {})", o.joint_states_topic,
                          QuoteText(name), fmt::join(js->name, ", ")));
        }
        return;
      }
      q[j] = js->position[static_cast<size_t>(it - js->name.begin())];
    }
    const int64_t stamp = js->header.stamp.ToNanoseconds();
    if (!joints.empty() && stamp < joints.back().first) return;  // out of order: dropped
    joints.emplace_back(stamp, std::move(q));
    // kHistoryS of them, and at most kMaxJointStates however fast (or stuck) their stamps run.
    const auto keep_ns = static_cast<int64_t>(kHistoryS * 1e9);
    while (joints.size() > 2 &&
           (joints.front().first < stamp - keep_ns || joints.size() > kMaxJointStates)) {
      joints.pop_front();
    }
  }

  /// The camera pose from the arm's joints interpolated at `stamp_ns`.
  Result<RigidTransform> PoseFromJoints(int64_t stamp_ns) const {
    if (!arm_status.ok()) return arm_status;
    if (joints.empty()) {
      return NotFoundError(fmt::format("no joint states on {}", QuoteText(o.joint_states_topic)));
    }
    const auto tol = static_cast<int64_t>(o.tf_tolerance_ms * 1e6);
    auto it = std::lower_bound(joints.begin(), joints.end(), stamp_ns,
                               [](const auto& x, int64_t t) { return x.first < t; });
    Eigen::VectorXd q;
    if (it != joints.end() && it->first == stamp_ns) {
      q = it->second;
    } else if (it != joints.begin() && it != joints.end()) {
      const auto& a = *std::prev(it);
      const double f =
          static_cast<double>(stamp_ns - a.first) / static_cast<double>(it->first - a.first);
      q = a.second + f * (it->second - a.second);
    } else {
      const auto& near = it == joints.end() ? joints.back() : joints.front();
      if (std::abs(near.first - stamp_ns) > tol) {
        return OutOfRangeError(
            fmt::format("no joint state within {} ms of the image (nearest at {})",
                        o.tf_tolerance_ms, StampText(near.first)));
      }
      q = near.second;
    }
    return arm->CameraPose(q);
  }

  void AddLabel(const BagMessage& m) {
    auto& q = labels[m.topic];
    q.emplace_back(m.log_time, m.data);
    while (q.size() > 8) q.pop_front();
  }

  /// Simulator labels logged at `log_time` (both images), when the bag has them.
  Result<std::optional<SimulatorLabels>> LabelsAt(uint64_t log_time, int width, int height) {
    if (o.labels_prefix.empty()) return std::optional<SimulatorLabels>();
    auto find = [&](const std::string& topic) -> const std::vector<uint8_t>* {
      auto q = labels.find(topic);
      if (q == labels.end()) return nullptr;
      for (const auto& [t, data] : q->second)
        if (t == log_time) return &data;
      return nullptr;
    };
    const std::vector<uint8_t>* mi = find(o.labels_prefix + "/instance");
    const std::vector<uint8_t>* mc = find(o.labels_prefix + "/class");
    if (mi == nullptr || mc == nullptr) return std::optional<SimulatorLabels>();
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image i, ros::msg::Decode<ros::msg::Image>(*mi));
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image c, ros::msg::Decode<ros::msg::Image>(*mc));
    AVP_ASSIGN_OR_RETURN(SimulatorLabels l,
                         ros::msg::LabelsFromImages(i, c, width, height, o.labels_prefix));
    return std::optional<SimulatorLabels>(std::move(l));
  }

  bool IsLabelTopic(const std::string& topic) const {
    return !o.labels_prefix.empty() &&
           (topic == o.labels_prefix + "/instance" || topic == o.labels_prefix + "/class");
  }

  // ---- Frames ----

  /// Colour + depth + intrinsics (the CameraInfo nearest in time, its lens rectified).
  Result<RgbdFrame> Frame(std::span<const uint8_t> color_data,
                          std::span<const uint8_t> depth_data) {
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image color,
                         ros::msg::Decode<ros::msg::Image>(color_data));
    AVP_ASSIGN_OR_RETURN(const ros::msg::Image depth,
                         ros::msg::Decode<ros::msg::Image>(depth_data));
    RgbdFrame frame;
    AVP_ASSIGN_OR_RETURN(frame.rgb, ros::msg::ColorFromImage(color, o.color_topic));
    AVP_ASSIGN_OR_RETURN(frame.depth_m, ros::msg::DepthFromImage(depth, o.depth_topic));
    frame.stamp_ns = color.header.stamp.ToNanoseconds();
    frame.frame_id = o.camera_frame.empty() ? color.header.frame_id : o.camera_frame;
    const ros::msg::CameraInfo* info = InfoAt(frame.stamp_ns);
    if (info == nullptr) {
      return NotFoundError(
          fmt::format("no CameraInfo on {} before or near it", QuoteText(o.camera_info_topic)));
    }
    AVP_ASSIGN_OR_RETURN(frame.K, ros::msg::FromCameraInfo(*info, o.min_depth_m, o.max_depth_m));
    if (!frame.depth_m.SameSizeAs(frame.rgb) || frame.K.width != frame.rgb.width() ||
        frame.K.height != frame.rgb.height()) {
      return InvalidArgumentError(fmt::format(
          "colour {}x{}, depth {}x{} and CameraInfo {}x{} differ in size (depth must be aligned "
          "to colour)",
          frame.rgb.width(), frame.rgb.height(), frame.depth_m.width(), frame.depth_m.height(),
          frame.K.width, frame.K.height));
    }
    return frame;
  }

  /// The lens of the CameraInfo the frame was read with, rectified (after its pose is set).
  Status Rectify(RgbdFrame& frame) {
    const ros::msg::CameraInfo* info = InfoAt(frame.stamp_ns);
    return info == nullptr ? Status::Ok() : lens.Apply(*info, o, frame);
  }

  /// The camera pose at `stamp_ns`: TF (interpolated), else the arm's joints through its URDF.
  Result<RigidTransform> PoseAt(const std::string& camera_frame, int64_t stamp_ns) const {
    if (tf.empty() && joints.empty()) {
      if (!arm_status.ok()) {
        return NotFoundError(
            fmt::format("no transforms on {} or {}, and the joint states on {} give no pose: {}",
                        QuoteText(o.tf_topic), QuoteText(o.tf_static_topic),
                        QuoteText(o.joint_states_topic), arm_status.message()));
      }
      return NotFoundError(fmt::format("no transforms on {} or {} and no joint states on {}",
                                       QuoteText(o.tf_topic), QuoteText(o.tf_static_topic),
                                       QuoteText(o.joint_states_topic)));
    }
    Result<RigidTransform> pose = tf.empty() ? Result<RigidTransform>(NotFoundError("no TF"))
                                             : tf.Lookup(o.base_frame, camera_frame, stamp_ns);
    if (pose.ok() || pose.status().code() != StatusCode::kNotFound || joints.empty()) return pose;
    Result<RigidTransform> from_joints = PoseFromJoints(stamp_ns);
    if (from_joints.ok()) return from_joints;
    return NotFoundError(fmt::format("{}; and from {}: {}", pose.status().message(),
                                     o.joint_states_topic, from_joints.status().message()));
  }

  LensCache lens;

  // ---- Robot bags ----

  Status DispatchRobot(BagMessage m) {
    if (IsLabelTopic(m.topic)) {
      AddLabel(m);
      return Status::Ok();
    }
    const bool is_color = m.topic == o.color_topic;
    if (!is_color && m.topic != o.depth_topic) return Resolve(/*at_end=*/false);
    if (topic_messages[m.topic] == 1) AVP_RETURN_IF_ERROR(CheckTopic(m, "sensor_msgs/msg/Image"));
    const std::optional<PeekedHeader> h = PeekHeader(m.data);
    if (!h) {
      Skip(-1, static_cast<int64_t>(m.log_time), "bad image",
           fmt::format("{} at log time {}: not a CDR sensor_msgs/Image", m.topic,
                       StampText(static_cast<int64_t>(m.log_time))));
      return Status::Ok();
    }
    RawImage image{h->stamp_ns, m.log_time, h->frame_id, std::move(m.data)};
    if (is_color) {
      if (!first_color_ns) first_color_ns = image.stamp_ns;
      colors.push_back(std::move(image));
    } else {
      latest_depth_ns = std::max(latest_depth_ns.value_or(image.stamp_ns), image.stamp_ns);
      depths.push_back(std::move(image));
      if (depths.size() > kMaxQueued) depths.pop_front();
    }
    Pair(/*at_end=*/false);
    return Resolve(/*at_end=*/false);
  }

  /// Pairs each colour image with the depth image nearest in stamp (within max_pair_skew_ms)
  /// once no later depth image can be nearer; the pairs go through the time window.
  void Pair(bool at_end) {
    const auto skew = static_cast<int64_t>(std::llround(o.max_pair_skew_ms * 1e6));
    while (!colors.empty()) {
      RawImage& c = colors.front();
      const bool decided = at_end || colors.size() > kMaxQueued ||
                           (latest_depth_ns && *latest_depth_ns > c.stamp_ns + skew);
      if (!decided) break;
      auto best = depths.end();
      int64_t best_d = std::numeric_limits<int64_t>::max();
      for (auto it = depths.begin(); it != depths.end(); ++it) {
        const int64_t d = std::abs(it->stamp_ns - c.stamp_ns);
        if (d < best_d) {
          best_d = d;
          best = it;
        }
      }
      if (best == depths.end() || best_d > skew) {
        Skip(-1, c.stamp_ns, "no depth within max_pair_skew_ms",
             fmt::format("no depth image on {} within {} ms of the colour image",
                         QuoteText(o.depth_topic), o.max_pair_skew_ms));
      } else {
        PendingPair p{pair_index++, std::move(c), std::move(*best)};
        depths.erase(depths.begin(), std::next(best));
        ++account.pairs;
        Window(std::move(p));
      }
      colors.pop_front();
    }
  }

  /// The time window; the pairs in it wait for their pose.
  void Window(PendingPair p) {
    // 1 us of slack: a 30 Hz camera's 30th frame is stamped 10 ns short of 1 s.
    const double t = static_cast<double>(p.color.stamp_ns - first_color_ns.value_or(0)) * 1e-9;
    if (t < selection.start_s - 1e-6) {
      ++account.left_out["before start_s"];
    } else if (selection.end_s > 0.0 && t > selection.end_s + 1e-6) {
      ++account.left_out["after end_s"];
      done = true;  // the bag's later pairs are later still
    } else {
      pending.push_back(std::move(p));
    }
  }

  /// Pairs whose pose can be known now (or never will be) are selected and decoded.
  Status Resolve(bool at_end) {
    const auto wait = static_cast<int64_t>(o.tf_tolerance_ms * 1e6) + kPoseWaitNs;
    while (!pending.empty() && !done) {
      PendingPair& p = pending.front();
      const std::string frame = o.camera_frame.empty() ? p.color.frame_id : o.camera_frame;
      Result<RigidTransform> pose = PoseAt(frame, p.color.stamp_ns);
      // Bounded however the bag's log times run (a bag whose log times never advance must not
      // hold every pair): beyond kMaxQueued waiting pairs, the oldest is decided now.
      const bool may_come =
          !at_end && pending.size() <= kMaxQueued &&
          static_cast<int64_t>(latest_log_time) < static_cast<int64_t>(p.color.log_time) + wait;
      if (may_come && (!pose.ok() || infos.empty())) break;
      PendingPair pair = std::move(p);
      pending.pop_front();
      Select(std::move(pair), std::move(pose), frame);
    }
    return Status::Ok();
  }

  /// At rest, every Nth, fps, max views; then the view.
  void Select(PendingPair p, Result<RigidTransform> pose, const std::string& frame) {
    const int64_t stamp = p.color.stamp_ns;
    if (!pose.ok()) {
      Skip(p.index, stamp, "no camera pose", pose.status().message());
      return;
    }
    if (selection.at_rest_only) {
      Result<bool> moving = Moving(frame, stamp, *pose);
      if (!moving.ok()) {
        Skip(p.index, stamp, "no camera pose", "at rest? " + moving.status().message());
        return;
      }
      if (*moving) {
        ++account.left_out["moving"];
        return;
      }
    }
    if (passed_rest++ % static_cast<size_t>(selection.every_nth) != 0) {
      ++account.left_out["every_nth"];
      return;
    }
    if (!PassesFps(stamp)) {
      ++account.left_out["fps"];
      return;
    }
    Result<BagView> view = RobotView(p, *pose);
    if (!view.ok()) {
      Skip(p.index, stamp, ReasonOf(view.status()), view.status().message());
      return;
    }
    if (fps_period_ns() > 0) {
      if (!fps_first_ns) fps_first_ns = stamp;
      const int64_t period = fps_period_ns();
      const int64_t early = period / 100;
      fps_next_ns = *fps_first_ns + ((stamp - *fps_first_ns + early) / period + 1) * period;
    }
    Keep(std::move(*view));
  }

  int64_t fps_period_ns() const {
    return selection.fps > 0.0 ? static_cast<int64_t>(std::llround(1e9 / selection.fps)) : 0;
  }

  /// The first pair at or after each instant first + k / fps, or up to 1 % of a period before it
  /// (a 30 Hz camera's 30th frame is stamped 10 ns short of 1 s).
  bool PassesFps(int64_t stamp) const {
    return !fps_first_ns || stamp >= fps_next_ns - fps_period_ns() / 100;
  }

  /// Whether the camera moved faster than at rest over the window before `stamp`.
  Result<bool> Moving(const std::string& frame, int64_t stamp, const RigidTransform& X) const {
    const auto w = static_cast<int64_t>(selection.at_rest_window_s * 1e9);
    AVP_ASSIGN_OR_RETURN(const RigidTransform before, PoseAt(frame, stamp - w));
    const double dt = selection.at_rest_window_s;
    const double speed = X.TranslationDistanceTo(before) / dt;
    const double turn = X.AngleTo(before) * 180.0 / M_PI / dt;
    return speed > selection.at_rest_m_s || turn > selection.at_rest_deg_s;
  }

  static std::string ReasonOf(const Status& s) {
    const std::string& m = s.message();
    if (m.find("CameraInfo") != std::string::npos) return "no CameraInfo";
    if (m.find("distortion") != std::string::npos || m.find("coefficient") != std::string::npos)
      return "lens model";
    return "bad image";
  }

  Result<BagView> RobotView(const PendingPair& p, const RigidTransform& pose) {
    BagView view;
    view.index = p.index;
    AVP_ASSIGN_OR_RETURN(view.observation.frame, Frame(p.color.data, p.depth.data));
    RgbdFrame& frame = view.observation.frame;
    if (frame.frame_id.empty()) {
      return InvalidArgumentError(fmt::format(
          "{}: the image has no frame_id; give the camera frame (camera_frame)", o.color_topic));
    }
    frame.X_WC = pose;
    AVP_RETURN_IF_ERROR(Rectify(frame));
    AVP_ASSIGN_OR_RETURN(view.observation.labels,
                         LabelsAt(p.color.log_time, frame.rgb.width(), frame.rgb.height()));
    return view;
  }

  // ---- avp recordings ----

  /// The messages of one log time are gathered; a step's view is made when the time moves on.
  Status DispatchAvp(BagMessage m) {
    if (m.log_time != moment_time) {
      AVP_RETURN_IF_ERROR(EndMoment());
      moment_time = m.log_time;
    }
    if (m.topic == kStepTopic || m.topic == kMovingFrameTopic || m.topic == o.color_topic ||
        m.topic == o.depth_topic || m.topic == kInstancesTopic || IsLabelTopic(m.topic)) {
      if (topic_messages[m.topic] == 1) {
        const bool text =
            m.topic == kStepTopic || m.topic == kMovingFrameTopic || m.topic == kInstancesTopic;
        AVP_RETURN_IF_ERROR(CheckTopic(m, text ? "std_msgs/msg/String" : "sensor_msgs/msg/Image"));
      }
      if (IsLabelTopic(m.topic)) AddLabel(m);
      moment[m.topic] = std::move(m.data);
    }
    return Status::Ok();
  }

  Status EndMoment() {
    if (moment.contains(std::string(kMovingFrameTopic)) &&
        !moment.contains(std::string(kStepTopic)) && !done) {
      Result<BagView> view = AvpMovingFrame();
      if (view.ok()) {
        ++account.moving_frames;
        ready.push_back(std::move(*view));
      } else {
        Skip(static_cast<int>(account.pairs), static_cast<int64_t>(moment_time),
             ReasonOf(view.status()), view.status().message());
      }
    }
    if (moment.contains(std::string(kStepTopic)) && !done) {
      ++account.pairs;
      Result<BagView> view = AvpStep();
      if (view.ok()) {
        Keep(std::move(*view));
      } else {
        Skip(static_cast<int>(account.pairs) - 1, static_cast<int64_t>(moment_time),
             ReasonOf(view.status()), view.status().message());
      }
    }
    moment.clear();
    return Status::Ok();
  }

  Result<BagView> AvpStep() {
    AVP_ASSIGN_OR_RETURN(const ros::msg::String text,
                         ros::msg::Decode<ros::msg::String>(moment.at(std::string(kStepTopic))));
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
      view.index = static_cast<int>(account.pairs) - 1;
    }
    AVP_RETURN_IF_ERROR(MomentFrame(view, "the step's time"));
    return view;
  }

  /// The moment's frame into `view` (its JSON already in view.step): colour and depth (logged at
  /// `when`), the exact pose, the lens rectified, the simulator labels and the recorded masks.
  Status MomentFrame(BagView& view, std::string_view when) {
    const auto mc = moment.find(o.color_topic);
    const auto md = moment.find(o.depth_topic);
    if (mc == moment.end() || md == moment.end()) {
      return NotFoundError(fmt::format("no {} image logged at {}",
                                       mc == moment.end() ? o.color_topic : o.depth_topic, when));
    }
    AVP_ASSIGN_OR_RETURN(view.observation.frame, Frame(mc->second, md->second));
    AVP_RETURN_IF_ERROR(StepPoseAndJoints(view));
    AVP_RETURN_IF_ERROR(Rectify(view.observation.frame));
    const RgbdFrame& frame = view.observation.frame;
    AVP_ASSIGN_OR_RETURN(view.observation.labels,
                         LabelsAt(moment_time, frame.rgb.width(), frame.rgb.height()));
    if (auto mi = moment.find(std::string(kInstancesTopic)); mi != moment.end()) {
      AVP_ASSIGN_OR_RETURN(view.segmentation, RecordedMasks(mi->second, frame));
    }
    return Status::Ok();
  }

  /// A frame fused while the arm moved: its images, labels and masks, its exact pose.
  Result<BagView> AvpMovingFrame() {
    AVP_ASSIGN_OR_RETURN(
        const ros::msg::String text,
        ros::msg::Decode<ros::msg::String>(moment.at(std::string(kMovingFrameTopic))));
    BagView view;
    view.moving = true;
    try {
      view.step = nlohmann::json::parse(text.data);
    } catch (const nlohmann::json::parse_error& e) {
      return InvalidArgumentError(
          fmt::format("{}: malformed JSON: {}", kMovingFrameTopic, EscapeText(e.what(), 200)));
    }
    const auto number = [&](const char* key) -> std::optional<int> {
      const auto it = view.step.is_object() ? view.step.find(key) : view.step.end();
      if (it == view.step.end() || !it->is_number_integer()) return std::nullopt;
      return it->get<int>();
    };
    const std::optional<int> v = number("view"), k = number("k");
    if (!v || !k || *v < 1 || *k < 1) {
      return InvalidArgumentError(fmt::format("{}: needs whole numbers view >= 1 and k >= 1: {}",
                                              kMovingFrameTopic, EscapeText(text.data, 200)));
    }
    view.index = *v - 1;
    view.moving_k = *k;
    AVP_RETURN_IF_ERROR(MomentFrame(view, "the moving frame's time"));
    return view;
  }

  /// The exact pose from the step (TF's quaternion does not round-trip bit for bit). The step's
  /// pose is the arm's; the frame's (TF) is what was fused: they agree in simulation, while a
  /// live robot's camera pose comes from its TF, so a TF pose that differs is used instead.
  Status StepPoseAndJoints(BagView& view) const {
    RgbdFrame& frame = view.observation.frame;
    Result<RigidTransform> tf_pose = PoseAt(frame.frame_id, frame.stamp_ns);
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
    return Status::Ok();
  }

  static Result<Segmentation> RecordedMasks(std::span<const uint8_t> data, const RgbdFrame& frame) {
    AVP_ASSIGN_OR_RETURN(const ros::msg::String s, ros::msg::Decode<ros::msg::String>(data));
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
    return std::move(*seg);
  }

  // ---- The end ----

  /// Why a bag gave no view at all, and its damage when it has some.
  Status NothingToFuse() const {
    if (!damage.ok() && topic_messages.empty()) {
      return Status(damage.code(), fmt::format("no view could be read: {}", damage.message()));
    }
    Status s = WhyNothing();
    if (damage.ok()) return s;
    return Status(s.code(),
                  fmt::format("{} (the bag is damaged: {})", s.message(), damage.message()));
  }

  Status WhyNothing() const {
    const bool avp = avp_recording;
    for (const std::string& topic :
         avp ? std::vector<std::string>{std::string(kStepTopic), o.color_topic, o.depth_topic,
                                        o.camera_info_topic}
             : std::vector<std::string>{o.color_topic, o.depth_topic, o.camera_info_topic}) {
      if (!topic_messages.contains(topic)) {
        return NotFoundError(fmt::format("{}: no messages on {} (the bag's topics: {}){}", Where(),
                                         QuoteText(topic), TopicList(),
                                         damage.ok() ? "" : " in the intact part"));
      }
    }
    if (!avp && account.pairs == 0) {
      return NotFoundError(fmt::format(
          "{}: no colour image on {} has a depth image on {} within {} ms ({} colour, {} depth "
          "images)",
          Where(), QuoteText(o.color_topic), QuoteText(o.depth_topic), o.max_pair_skew_ms,
          topic_messages.at(o.color_topic), topic_messages.at(o.depth_topic)));
    }
    std::string why =
        account.skipped.empty()
            ? fmt::format("every pair was left out by the frame selection ({})", LeftOutText())
            : account.skipped.front();
    return InvalidArgumentError(fmt::format("{}: no view could be read{}: {}", Where(),
                                            damage.ok() ? "" : " (the file is damaged)", why));
  }

  std::string LeftOutText() const {
    std::vector<std::string> parts;
    for (const auto& [reason, n] : account.left_out)
      parts.push_back(fmt::format("{} {}", n, reason));
    return parts.empty() ? std::string("none") : fmt::format("{}", fmt::join(parts, ", "));
  }
};

BagReader::BagReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
BagReader::~BagReader() = default;

namespace {

/// The bag's "avp" metadata and ground_truth.json attachment.
Status ReadAvpRecords(const BagInfo& info, const std::filesystem::path& path,
                      std::map<std::string, std::string>& metadata,
                      std::optional<nlohmann::json>& ground_truth) {
  if (auto m = info.metadata.find(std::string(kMetadataName)); m != info.metadata.end()) {
    metadata = m->second;
  }
  for (const BagAttachment& a : info.attachments) {
    if (a.name != kGroundTruthAttachment) continue;
    try {
      ground_truth = nlohmann::json::parse(a.data);
    } catch (const nlohmann::json::parse_error& e) {
      return InvalidArgumentError(fmt::format("{}: attachment {}: malformed JSON: {}",
                                              path.string(), kGroundTruthAttachment,
                                              EscapeText(e.what(), 200)));
    }
  }
  return Status::Ok();
}

}  // namespace

Result<std::unique_ptr<BagReader>> BagReader::Open(const std::filesystem::path& path,
                                                   const BagReadOptions& options) {
  AVP_RETURN_IF_ERROR(BagReadOptionTable().Validate(options));
  auto impl = std::make_unique<Impl>(options);
  // "bag/" names the folder "bag" (its file name, in messages and the report).
  impl->path = path.has_filename() ? path : path.parent_path();
  AVP_ASSIGN_OR_RETURN(impl->source, OpenBag(path));
  const BagInfo& info = impl->source->info();
  AVP_RETURN_IF_ERROR(ReadAvpRecords(info, path, impl->avp_metadata, impl->ground_truth));
  impl->avp_recording =
      !options.as_robot_bag && (info.topic_types.contains(std::string(kStepTopic)) ||
                                info.metadata.contains(std::string(kMetadataName)));
  // A bag whose index lists every topic and not the colour one has nothing to fuse: say so now.
  if (!info.topic_counts.empty() && !info.topic_counts.contains(options.color_topic)) {
    return NotFoundError(fmt::format("{}: no messages on {} (the bag's topics: {})", path.string(),
                                     QuoteText(options.color_topic),
                                     FormatTopics(info.topic_counts, info.topic_types)));
  }
  return std::unique_ptr<BagReader>(new BagReader(std::move(impl)));
}

Status BagReader::SetSelection(const FrameSelection& selection) {
  if (impl_->started) {
    return FailedPreconditionError("BagReader::SetSelection after the first view was read");
  }
  AVP_RETURN_IF_ERROR(FrameSelectionTable().Validate(selection));
  impl_->selection = selection;
  return Status::Ok();
}

Result<std::optional<BagView>> BagReader::Next() {
  impl_->started = true;
  AVP_RETURN_IF_ERROR(impl_->Fill());
  if (impl_->ready.empty()) {
    if (impl_->account.fused == 0) return impl_->NothingToFuse();
    return std::optional<BagView>();
  }
  BagView view = std::move(impl_->ready.front());
  impl_->ready.pop_front();
  return std::optional<BagView>(std::move(view));
}

const std::filesystem::path& BagReader::path() const { return impl_->path; }
const BagInfo& BagReader::info() const { return impl_->source->info(); }
bool BagReader::avp_recording() const { return impl_->avp_recording; }
const std::map<std::string, std::string>& BagReader::avp_metadata() const {
  return impl_->avp_metadata;
}
const std::optional<nlohmann::json>& BagReader::ground_truth() const { return impl_->ground_truth; }
bool BagReader::HasTopic(std::string_view topic) const {
  const std::string t(topic);
  return impl_->source->info().topic_types.contains(t) || impl_->topic_messages.contains(t);
}
bool BagReader::HasSimulatorLabels() const {
  return !impl_->o.labels_prefix.empty() && HasTopic(impl_->o.labels_prefix + "/instance");
}
const Status& BagReader::damage() const { return impl_->damage; }
uint64_t BagReader::bytes_read() const { return impl_->source->bytes_read(); }
const FrameAccount& BagReader::account() const { return impl_->account; }
const std::map<std::string, uint64_t>& BagReader::topic_messages() const {
  return impl_->topic_messages;
}

Result<Bag> ReadBag(const std::filesystem::path& path, const BagReadOptions& options,
                    const FrameSelection& selection) {
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<BagReader> reader, BagReader::Open(path, options));
  AVP_RETURN_IF_ERROR(reader->SetSelection(selection));
  Bag bag;
  while (true) {
    AVP_ASSIGN_OR_RETURN(std::optional<BagView> view, reader->Next());
    if (!view) break;
    bag.views.push_back(std::move(*view));
  }
  bag.path = path;
  bag.info = reader->info();
  bag.avp_recording = reader->avp_recording();
  bag.avp_metadata = reader->avp_metadata();
  bag.ground_truth = reader->ground_truth();
  bag.damage = reader->damage();
  bag.account = reader->account();
  bag.topic_messages = reader->topic_messages();
  return bag;
}

}  // namespace avp::ros::bag

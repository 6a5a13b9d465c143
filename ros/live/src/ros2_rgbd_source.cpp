#include <algorithm>
#include <chrono>
#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/io/image_limits.h>
#include <avp/ros/live/ros2_rgbd_source.h>
#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/markers.h>

namespace avp::ros::live {

namespace {

using SteadyClock = std::chrono::steady_clock;

int64_t StampNs(const ros::msg::Header& h) { return h.stamp.ToNanoseconds(); }

/// The check on arrival: the encoding and layout, and for 32FC1 depth every value
/// (ros/msg/images.h), so that a refused image is counted and never waits for a partner.
Status CheckImage(const ros::msg::Image& msg, std::string_view topic, bool is_color) {
  return is_color ? ros::msg::CheckColorImage(msg, topic) : ros::msg::CheckDepthImage(msg, topic);
}

}  // namespace

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

const OptionTable<CameraTopicsOptions>& CameraTopicsOptionTable() {
  static const auto* table = [] {
    using O = CameraTopicsOptions;
    auto* t = new OptionTable<O>("camera topic option");
    ros::msg::AddCameraTopicOptions(*t);
    t->Flag("best_effort", &O::best_effort,
            "subscribe to images best-effort (sensor data QoS); false: reliable");
    t->Real("frame_timeout_s", &O::frame_timeout_s, "s", ValueRange::LeftOpen(0, 600),
            "wait at most this long for a frame pair");
    t->Real("tf_timeout_s", &O::tf_timeout_s, "s", ValueRange::Closed(0, 600),
            "then at most this long for the transform at its stamp");
    t->Real("settle_s", &O::settle_s, "s", ValueRange::Closed(0, 60),
            "use frames stamped this long after the capture was asked for");
    t->Text("labels_prefix", &O::labels_prefix,
            "simulator label topics for the oracle segmenter (empty: none)");
    t->Integer("queue", &O::queue, "", ValueRange::Closed(2, 120),
               "frames of each topic kept while waiting for a partner");
    return t;
  }();
  return *table;
}

Ros2RgbdSource::Ros2RgbdSource(ros::dds::Node& node, ros::msg::TfBuffer& tf,
                               const CameraTopicsOptions& options, const CameraIntrinsics& camera,
                               std::stop_token stop)
    : node_(node), tf_(tf), options_(options), camera_(camera), stop_(std::move(stop)) {}

Ros2RgbdSource::~Ros2RgbdSource() {
  // Subscriptions first: their callbacks touch the members below.
  color_sub_.reset();
  depth_sub_.reset();
  instance_sub_.reset();
  class_sub_.reset();
  info_sub_.reset();
  fruits_sub_.reset();
}

Result<std::unique_ptr<Ros2RgbdSource>> Ros2RgbdSource::Create(ros::dds::Node& node,
                                                               ros::msg::TfBuffer& tf,
                                                               const CameraTopicsOptions& options,
                                                               const CameraIntrinsics& camera,
                                                               std::stop_token stop) {
  AVP_RETURN_IF_ERROR(CameraTopicsOptionTable().Validate(options));
  std::unique_ptr<Ros2RgbdSource> source(new Ros2RgbdSource(node, tf, options, camera, stop));
  AVP_RETURN_IF_ERROR(source->Subscribe());
  // The intrinsics before anything else: the planner needs them.
  std::unique_lock lock(source->mutex_);
  const auto deadline = SteadyClock::now() + Seconds(options.frame_timeout_s);
  source->cv_.wait_until(lock, stop, deadline, [&] { return source->K_.has_value(); });
  if (stop.stop_requested()) return CancelledError("stopped while waiting for CameraInfo");
  if (!source->K_) {
    return DeadlineExceededError(fmt::format(
        "no usable CameraInfo on {} within {} s ({} received, {} publisher(s) matched{}{}): is "
        "the camera driver running, on ROS_DOMAIN_ID {}?",
        options.camera_info_topic, options.frame_timeout_s, source->counters_.camera_info,
        source->info_sub_->matched_publishers(),
        source->counters_.last_problem.empty() ? "" : "; last problem: ",
        source->counters_.last_problem, node.domain_id()));
  }
  return source;
}

Status Ros2RgbdSource::Subscribe() {
  const ros::dds::QosProfile images =
      options_.best_effort ? ros::dds::QosProfile::SensorData() : ros::dds::QosProfile::Default();
  AVP_ASSIGN_OR_RETURN(color_sub_, node_.CreateSubscription<ros::msg::Image>(
                                       options_.color_topic, images,
                                       [this](ros::msg::Image&& m, const ros::dds::SampleInfo&) {
                                         OnImage(std::move(m), true);
                                       }));
  AVP_ASSIGN_OR_RETURN(depth_sub_, node_.CreateSubscription<ros::msg::Image>(
                                       options_.depth_topic, images,
                                       [this](ros::msg::Image&& m, const ros::dds::SampleInfo&) {
                                         OnImage(std::move(m), false);
                                       }));
  AVP_ASSIGN_OR_RETURN(info_sub_,
                       node_.CreateSubscription<ros::msg::CameraInfo>(
                           options_.camera_info_topic, images,
                           [this](ros::msg::CameraInfo&& m, const ros::dds::SampleInfo&) {
                             OnCameraInfo(std::move(m));
                           }));
  if (!options_.labels_prefix.empty()) {
    AVP_ASSIGN_OR_RETURN(instance_sub_,
                         node_.CreateSubscription<ros::msg::Image>(
                             options_.labels_prefix + "/instance", images,
                             [this](ros::msg::Image&& m, const ros::dds::SampleInfo&) {
                               OnLabel(std::move(m), true);
                             }));
    AVP_ASSIGN_OR_RETURN(class_sub_, node_.CreateSubscription<ros::msg::Image>(
                                         options_.labels_prefix + "/class", images,
                                         [this](ros::msg::Image&& m, const ros::dds::SampleInfo&) {
                                           OnLabel(std::move(m), false);
                                         }));
    AVP_ASSIGN_OR_RETURN(fruits_sub_,
                         node_.CreateSubscription<ros::msg::MarkerArray>(
                             options_.labels_prefix + "/fruits", ros::dds::QosProfile::Latched(),
                             [this](ros::msg::MarkerArray&& m, const ros::dds::SampleInfo&) {
                               OnFruits(std::move(m));
                             }));
  }
  return Status::Ok();
}

void Ros2RgbdSource::OnCameraInfo(ros::msg::CameraInfo&& msg) {
  // The lens (ros/msg/lens.h): K is the raw camera's; a distorted lens is rectified per frame.
  Result<ros::msg::LensModel> lens =
      ros::msg::LensModelFromCameraInfo(msg, camera_.min_depth_m, camera_.max_depth_m);
  // A new lens's maps are built outside the lock (tens of ms), and only for a camera whose
  // images max_image_pixels admits (a CameraInfo alone must not make avp allocate gigabytes).
  std::shared_ptr<const ros::msg::Rectifier> current;
  {
    std::lock_guard lock(mutex_);
    current = rectifier_;
  }
  std::shared_ptr<const ros::msg::Rectifier> built;
  if (lens.ok() && (!current || !current->model().SameLensAs(*lens))) {
    if (const Status size = io::CheckImageSize(static_cast<uint64_t>(lens->K.width),
                                               static_cast<uint64_t>(lens->K.height),
                                               options_.camera_info_topic + " (CameraInfo)");
        !size.ok()) {
      lens = size;
    } else {
      if (!lens->IsIdentity()) {
        spdlog::info("{}: distortion model '{}' ({} coefficients): the images are rectified",
                     options_.camera_info_topic, msg.distortion_model, msg.d.size());
      }
      built = std::make_shared<const ros::msg::Rectifier>(*lens);
    }
  }
  std::lock_guard lock(mutex_);
  ++counters_.camera_info;
  if (!lens.ok()) {
    counters_.last_problem =
        fmt::format("{}: {}", options_.camera_info_topic, lens.status().message());
    return;
  }
  const CameraIntrinsics& K = lens->K;
  if (!K_ && (K.width != camera_.width || K.height != camera_.height)) {
    spdlog::info("{}: the camera is {}x{} (the configured camera: {}x{})",
                 options_.camera_info_topic, K.width, K.height, camera_.width, camera_.height);
  }
  K_ = K;
  if (built) rectifier_ = std::move(built);
  cv_.notify_all();
}

void Ros2RgbdSource::OnImage(ros::msg::Image&& msg, bool is_color) {
  const Status problem =
      CheckImage(msg, is_color ? options_.color_topic : options_.depth_topic, is_color);
  std::lock_guard lock(mutex_);
  ++(is_color ? counters_.color : counters_.depth);
  if (!problem.ok()) {
    ++counters_.refused;
    if (counters_.last_problem != problem.message()) {
      spdlog::warn("{}", problem.message());
      counters_.last_problem = problem.message();
    }
    return;
  }
  std::deque<ros::msg::Image>& q = is_color ? color_ : depth_;
  // Keep the queue sorted by stamp (frames may arrive out of order).
  const int64_t t = StampNs(msg.header);
  auto pos = std::upper_bound(q.begin(), q.end(), t, [](int64_t s, const ros::msg::Image& m) {
    return s < StampNs(m.header);
  });
  q.insert(pos, std::move(msg));
  while (q.size() > static_cast<size_t>(options_.queue)) {
    if (is_color && active_stream_ != nullptr) TellTrimmed(StampNs(q.front().header));
    q.pop_front();
  }
  ++generation_;
  cv_.notify_all();
}

void Ros2RgbdSource::OnLabel(ros::msg::Image&& msg, bool is_instance) {
  std::lock_guard lock(mutex_);
  std::deque<ros::msg::Image>& q = is_instance ? instance_ : class_;
  q.push_back(std::move(msg));
  while (q.size() > static_cast<size_t>(options_.queue)) q.pop_front();
  ++generation_;
  cv_.notify_all();
}

void Ros2RgbdSource::OnFruits(ros::msg::MarkerArray&& msg) {
  std::vector<GroundTruthFruit> fruits = ros::msg::FruitsFromMarkers(msg);
  std::lock_guard lock(mutex_);
  fruits_ = std::move(fruits);
  have_fruits_ = true;
  cv_.notify_all();
}

std::optional<std::pair<size_t, size_t>> Ros2RgbdSource::FindPair(int64_t not_before_ns,
                                                                  bool with_labels) const {
  const int64_t skew = static_cast<int64_t>(options_.max_pair_skew_ms * 1e6);
  const auto has_stamp = [](const std::deque<ros::msg::Image>& q, int64_t t) {
    return std::any_of(q.begin(), q.end(), [&](const auto& m) { return StampNs(m.header) == t; });
  };
  if (with_labels && !have_fruits_) return std::nullopt;
  for (size_t i = 0; i < color_.size(); ++i) {
    const int64_t tc = StampNs(color_[i].header);
    if (tc < not_before_ns) continue;
    if (with_labels && !(has_stamp(instance_, tc) && has_stamp(class_, tc))) continue;
    for (size_t j = 0; j < depth_.size(); ++j) {
      const int64_t td = StampNs(depth_[j].header);
      if (std::abs(td - tc) <= skew) return std::pair{i, j};
    }
  }
  return std::nullopt;
}

Result<robot::Observation> Ros2RgbdSource::Capture(const RigidTransform& X_WC, int64_t) {
  const int64_t not_before = NowNs() + static_cast<int64_t>(options_.settle_s * 1e9);
  const auto deadline = SteadyClock::now() + Seconds(options_.frame_timeout_s + options_.settle_s);
  std::unique_lock lock(mutex_);
  std::optional<std::pair<size_t, size_t>> pair;
  const bool labels = !options_.labels_prefix.empty();
  cv_.wait_until(lock, stop_, deadline, [&] {
    pair = FindPair(not_before, labels);
    return pair.has_value();
  });
  if (stop_.stop_requested()) return CancelledError("stopped while waiting for a camera frame");
  if (!pair && !FindPair(not_before, false)) {
    const auto newest = [](const std::deque<ros::msg::Image>& q) {
      return q.empty() ? std::string("none") : ros::msg::FormatStamp(StampNs(q.back().header));
    };
    return DeadlineExceededError(fmt::format(
        "no colour/depth pair stamped after {} within {} s on {} and {} (received {} colour, {} "
        "depth, {} refused; newest colour {}, depth {}; pairs need stamps within {} ms{}{})",
        ros::msg::FormatStamp(not_before), options_.frame_timeout_s, options_.color_topic,
        options_.depth_topic, counters_.color, counters_.depth, counters_.refused, newest(color_),
        newest(depth_), options_.max_pair_skew_ms,
        counters_.last_problem.empty() ? "" : "; last problem: ", counters_.last_problem));
  }
  if (!pair) {
    return DeadlineExceededError(fmt::format(
        "a frame pair arrived but not its simulator labels on {}/instance, /class and /fruits "
        "within {} s",
        options_.labels_prefix, options_.frame_timeout_s));
  }
  const ros::msg::Image color = color_[pair->first];
  const ros::msg::Image depth = depth_[pair->second];
  (void)X_WC;
  ++counters_.pairs_used;
  return Assemble(color, depth, lock);
}

Result<robot::Observation> Ros2RgbdSource::Assemble(const ros::msg::Image& color,
                                                    const ros::msg::Image& depth,
                                                    std::unique_lock<std::mutex>& lock) {
  const int64_t t = StampNs(color.header);
  const CameraIntrinsics K = *K_;
  const std::shared_ptr<const ros::msg::Rectifier> rectifier = rectifier_;
  std::optional<ros::msg::Image> instance, cls;
  if (!options_.labels_prefix.empty()) {
    for (const auto& m : instance_) {
      if (StampNs(m.header) == t) instance = m;
    }
    for (const auto& m : class_) {
      if (StampNs(m.header) == t) cls = m;
    }
  }
  const std::vector<GroundTruthFruit> fruits = fruits_;
  lock.unlock();

  const std::string camera_frame =
      options_.camera_frame.empty() ? color.header.frame_id : options_.camera_frame;
  // The transform at the pair's stamp: wait (bounded) while it is not there yet.
  Result<RigidTransform> X_WC = tf_.Lookup(options_.base_frame, camera_frame, t);
  const auto tf_deadline = SteadyClock::now() + Seconds(options_.tf_timeout_s);
  while (!X_WC.ok() && SteadyClock::now() < tf_deadline && !stop_.stop_requested()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    X_WC = tf_.Lookup(options_.base_frame, camera_frame, t);
  }
  if (stop_.stop_requested()) return CancelledError("stopped while waiting for a transform");
  if (!X_WC.ok()) {
    return Status(X_WC.status().code(),
                  fmt::format("no transform {} -> {} at the frame's stamp {} within {} s: {}",
                              options_.base_frame, camera_frame, ros::msg::FormatStamp(t),
                              options_.tf_timeout_s, X_WC.status().message()));
  }
  AVP_ASSIGN_OR_RETURN(ImageRgb8 rgb, ros::msg::ColorFromImage(color, options_.color_topic));
  AVP_ASSIGN_OR_RETURN(DepthImage depth_m, ros::msg::DepthFromImage(depth, options_.depth_topic));
  if (!rgb.SameSizeAs(depth_m) || !rgb.SameSizeAs(K.width, K.height)) {
    return InvalidArgumentError(fmt::format(
        "colour {}x{}, depth {}x{} and CameraInfo {}x{} differ: is the depth aligned to colour "
        "(realsense2_camera align_depth.enable:=true)?",
        rgb.width(), rgb.height(), depth_m.width(), depth_m.height(), K.width, K.height));
  }
  robot::Observation obs;
  obs.frame.rgb = std::move(rgb);
  obs.frame.depth_m = std::move(depth_m);
  obs.frame.K = K;
  obs.frame.X_WC = *X_WC;
  obs.frame.stamp_ns = t;
  obs.frame.frame_id = camera_frame;
  if (rectifier && !rectifier->identity()) AVP_RETURN_IF_ERROR(rectifier->Rectify(obs.frame));
  if (instance && cls) {
    AVP_ASSIGN_OR_RETURN(
        SimulatorLabels labels,
        ros::msg::LabelsFromImages(*instance, *cls, K.width, K.height, options_.labels_prefix));
    labels.fruits = fruits;
    obs.labels = std::move(labels);
  }
  return obs;
}

/// Ros2RgbdSource's stream of one move: the pairs stamped in [start, end), in stamp order.
class LiveMoveStream final : public robot::MoveStream {
 public:
  LiveMoveStream(Ros2RgbdSource& source, const robot::MoveStreamRequest& request)
      : s_(source),
        start_ns_(NowNs()),
        period_ns_(static_cast<int64_t>(1e9 / request.rate_hz)),
        max_pending_(static_cast<size_t>(std::max(1, request.max_pending))),
        from_(request.X_WC_from),
        to_(request.X_WC_to),
        last_ns_(start_ns_ - 1) {
    std::lock_guard lock(s_.mutex_);
    s_.active_stream_ = this;
  }
  ~LiveMoveStream() override {
    std::lock_guard lock(s_.mutex_);
    if (s_.active_stream_ == this) s_.active_stream_ = nullptr;
  }
  LiveMoveStream(const LiveMoveStream&) = delete;
  LiveMoveStream& operator=(const LiveMoveStream&) = delete;

  /// A colour frame stamped `t` left the queue: dropped if it was one of the move's and not
  /// handed over (the map fell more than the queue behind). Called with the mutex held.
  void Trimmed(int64_t t) {
    if (t <= last_ns_ || t < start_ns_ || (end_ns_ && t >= *end_ns_)) return;
    ++counters_.dropped;
    ++s_.counters_.moving_dropped;
  }

  Result<std::optional<robot::Observation>> Next() override {
    std::unique_lock lock(s_.mutex_);
    const bool labels = !s_.options_.labels_prefix.empty();
    const auto timeout = Seconds(s_.options_.frame_timeout_s);
    auto deadline = SteadyClock::now() + timeout;
    while (true) {
      if (s_.stop_.stop_requested()) return CancelledError("stopped while streaming a move");
      std::vector<std::pair<size_t, size_t>> pending = Pending(labels);
      if (!pending.empty()) {
        Thin(pending);
        if (!pending.empty()) {
          const auto [ci, di] = pending.front();
          last_ns_ = StampNs(s_.color_[ci].header);
          const ros::msg::Image color = s_.color_[ci];
          const ros::msg::Image depth = s_.depth_[di];
          Result<robot::Observation> obs = s_.Assemble(color, depth, lock);
          lock.lock();
          if (!obs.ok()) {
            ++counters_.failed;
            return obs.status();
          }
          if (AtRest(obs->frame.X_WC)) {
            // Before the arm started or after it arrived: the views' pose, not the move's.
            ++counters_.skipped;
            ++s_.counters_.moving_skipped;
            continue;
          }
          ++counters_.delivered;
          ++s_.counters_.moving_pairs;
          return std::optional<robot::Observation>(std::move(*obs));
        }
      }
      if (end_ns_) {
        // Done once a colour frame stamped at or after the arrival came (the earlier ones came
        // before it: one publisher, in order), or nothing more comes.
        if (!*moved_ || NewestColor() >= *end_ns_ || SteadyClock::now() >= deadline) {
          return std::optional<robot::Observation>();
        }
      } else if (SteadyClock::now() >= deadline) {
        deadline = SteadyClock::now() + timeout;  // a long move: keep waiting, End() will come
      }
      const uint64_t seen = s_.generation_;
      s_.cv_.wait_until(lock, s_.stop_, deadline, [&] { return s_.generation_ != seen; });
    }
  }

  void End(bool moved) override {
    std::lock_guard lock(s_.mutex_);
    end_ns_ = NowNs();
    moved_ = moved;
    ++s_.generation_;
    s_.cv_.notify_all();
  }

  robot::MoveStreamCounters counters() const override {
    std::lock_guard lock(s_.mutex_);
    return counters_;
  }

 private:
  /// Pairs stamped after the last one handed over and inside the move, oldest first (with
  /// labels: only colour frames whose labels came). Call with the source's mutex held.
  std::vector<std::pair<size_t, size_t>> Pending(bool labels) const {
    std::vector<std::pair<size_t, size_t>> out;
    const int64_t skew = static_cast<int64_t>(s_.options_.max_pair_skew_ms * 1e6);
    const auto has_stamp = [](const std::deque<ros::msg::Image>& q, int64_t t) {
      return std::any_of(q.begin(), q.end(), [&](const auto& m) { return StampNs(m.header) == t; });
    };
    for (size_t i = 0; i < s_.color_.size(); ++i) {
      const int64_t tc = StampNs(s_.color_[i].header);
      if (tc <= last_ns_ || (end_ns_ && tc >= *end_ns_)) continue;
      if (labels && !(has_stamp(s_.instance_, tc) && has_stamp(s_.class_, tc))) continue;
      for (size_t j = 0; j < s_.depth_.size(); ++j) {
        if (std::abs(StampNs(s_.depth_[j].header) - tc) <= skew) {
          out.emplace_back(i, j);
          break;
        }
      }
    }
    return out;
  }

  /// Drops what is above the rate and, past max_pending, the oldest; counts both.
  void Thin(std::vector<std::pair<size_t, size_t>>& pending) {
    std::vector<std::pair<size_t, size_t>> kept;
    int64_t last = last_ns_;
    for (const auto& p : pending) {
      const int64_t t = StampNs(s_.color_[p.first].header);
      if (last >= start_ns_ && t - last < period_ns_ * 3 / 4) {
        ++counters_.skipped;
        ++s_.counters_.moving_skipped;
        last_ns_ = std::max(last_ns_, t);
        continue;
      }
      kept.push_back(p);
      last = t;
    }
    if (kept.size() > max_pending_) {
      const size_t drop = kept.size() - max_pending_;
      counters_.dropped += static_cast<int>(drop);
      s_.counters_.moving_dropped += drop;
      last_ns_ = std::max(last_ns_, StampNs(s_.color_[kept[drop - 1].first].header));
      if (!warned_) {
        spdlog::warn(
            "fusion during motion: the map fell behind the camera; dropped {} frame(s) "
            "(more than max_pending = {} waiting)",
            drop, max_pending_);
        warned_ = true;
      }
      kept.erase(kept.begin(), kept.begin() + static_cast<std::ptrdiff_t>(drop));
    }
    pending = std::move(kept);
  }

  int64_t NewestColor() const {
    return s_.color_.empty() ? INT64_MIN : StampNs(s_.color_.back().header);
  }

  /// The camera stands where the move starts or ends (within 1 µm and 1 µrad: a simulator's
  /// rest frames; a real arm's jitter is larger, and its frames at rest are fused, harmlessly).
  bool AtRest(const RigidTransform& X_WC) const {
    const auto same = [&](const RigidTransform& X) {
      return (X.translation() - X_WC.translation()).norm() < 1e-6 &&
             Eigen::AngleAxisd(X.rotation().transpose() * X_WC.rotation()).angle() < 1e-6;
    };
    return same(from_) || same(to_);
  }

  Ros2RgbdSource& s_;
  int64_t start_ns_;
  int64_t period_ns_;
  size_t max_pending_;
  RigidTransform from_, to_;
  int64_t last_ns_;
  std::optional<int64_t> end_ns_;
  std::optional<bool> moved_;
  robot::MoveStreamCounters counters_;
  bool warned_ = false;
};

void Ros2RgbdSource::TellTrimmed(int64_t stamp_ns) { active_stream_->Trimmed(stamp_ns); }

std::unique_ptr<robot::MoveStream> Ros2RgbdSource::StreamMove(
    const robot::MoveStreamRequest& request) {
  return std::make_unique<LiveMoveStream>(*this, request);
}

CameraIntrinsics Ros2RgbdSource::intrinsics() const {
  std::lock_guard lock(mutex_);
  return K_ ? *K_ : camera_;
}

SourceCounters Ros2RgbdSource::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

}  // namespace avp::ros::live

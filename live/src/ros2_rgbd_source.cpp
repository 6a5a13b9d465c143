#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/live/ros2_rgbd_source.h>
#include <avp/rosmsg/convert.h>

namespace avp::live {

namespace {

using SteadyClock = std::chrono::steady_clock;

int64_t StampNs(const rosmsg::Header& h) { return h.stamp.ToNanoseconds(); }

/// Checks an image's size, step and data length for `bytes_per_pixel`.
Status CheckLayout(const rosmsg::Image& msg, std::string_view topic, int bytes_per_pixel) {
  if (msg.width == 0 || msg.height == 0 || msg.width > 16384 || msg.height > 16384) {
    return InvalidArgumentError(fmt::format("{}: image size {}x{} is out of range (1..16384)",
                                            topic, msg.width, msg.height));
  }
  const uint64_t row = uint64_t{msg.width} * static_cast<uint64_t>(bytes_per_pixel);
  if (msg.step < row) {
    return InvalidArgumentError(
        fmt::format("{}: step {} is shorter than a row of {} '{}' pixels ({} bytes)", topic,
                    msg.step, msg.width, msg.encoding, row));
  }
  const uint64_t expected = uint64_t{msg.step} * msg.height;
  if (msg.data.size() != expected) {
    return InvalidArgumentError(fmt::format("{}: data holds {} bytes, but step {} x height {} = {}",
                                            topic, msg.data.size(), msg.step, msg.height,
                                            expected));
  }
  return Status::Ok();
}

/// A colour (rgb8, bgr8) or depth (16UC1/mono16 mm, 32FC1 m) image avp can use: its encoding,
/// then its size, step and data length. Checked once on arrival and again on conversion.
Status CheckImage(const rosmsg::Image& msg, std::string_view topic, bool is_color) {
  if (is_color) {
    if (msg.encoding != "rgb8" && msg.encoding != "bgr8") {
      return InvalidArgumentError(fmt::format(
          "{}: colour encoding '{}' is not supported (rgb8, bgr8)", topic, msg.encoding));
    }
    return CheckLayout(msg, topic, 3);
  }
  const bool mm = msg.encoding == "16UC1" || msg.encoding == "mono16";
  if (!mm && msg.encoding != "32FC1") {
    return InvalidArgumentError(fmt::format(
        "{}: depth encoding '{}' is not supported (16UC1 in millimetres, 32FC1 in metres)", topic,
        msg.encoding));
  }
  return CheckLayout(msg, topic, mm ? 2 : 4);
}

}  // namespace

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string FormatStamp(int64_t ns) {
  return fmt::format("{}.{:09d}", ns / 1'000'000'000, std::abs(ns % 1'000'000'000));
}

Result<RigidTransform> ToRigidTransform(const rosmsg::Transform& t, std::string_view what) {
  const rosmsg::Quaternion& q = t.rotation;
  const double norm = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  if (std::isfinite(norm) && std::abs(norm - 1.0) > 1e-3) {
    return InvalidArgumentError(fmt::format(
        "{}: the quaternion ({}, {}, {}, {}) has norm {}, not 1", what, q.x, q.y, q.z, q.w, norm));
  }
  Result<RigidTransform> X = rosmsg::FromTransformMsg(t);
  if (!X.ok()) return X.status().WithContext(what);
  return X;
}

const OptionTable<CameraTopicsOptions>& CameraTopicsOptionTable() {
  static const auto* table = [] {
    using O = CameraTopicsOptions;
    auto* t = new OptionTable<O>("camera topic option");
    t->Text("color_topic", &O::color_topic, "colour image (rgb8, bgr8)");
    t->Text("depth_topic", &O::depth_topic, "depth aligned to colour (16UC1 mm, 32FC1 m)");
    t->Text("camera_info_topic", &O::camera_info_topic, "the colour camera's CameraInfo");
    t->Text("base_frame", &O::base_frame, "the map's frame: the arm's base");
    t->Text("camera_frame", &O::camera_frame,
            "the camera's optical frame (empty: the colour image's frame_id)");
    t->Flag("best_effort", &O::best_effort,
            "subscribe to images best-effort (sensor data QoS); false: reliable");
    t->Real("max_pair_skew_ms", &O::max_pair_skew_ms, "ms", ValueRange::Closed(0, 1000),
            "colour and depth stamps may differ by this much");
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
    t->AddRule([](const O& o, std::vector<std::string>& errors) {
      for (const auto& [key, value] : {std::pair{"color_topic", &o.color_topic},
                                       {"depth_topic", &o.depth_topic},
                                       {"camera_info_topic", &o.camera_info_topic},
                                       {"base_frame", &o.base_frame}}) {
        if (value->empty()) errors.push_back(fmt::format("{} is empty", key));
      }
    });
    return t;
  }();
  return *table;
}

Ros2RgbdSource::Ros2RgbdSource(ros2::Node& node, TfBuffer& tf, const CameraTopicsOptions& options,
                               const CameraIntrinsics& camera, std::stop_token stop)
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

Result<std::unique_ptr<Ros2RgbdSource>> Ros2RgbdSource::Create(ros2::Node& node, TfBuffer& tf,
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
  const ros2::QosProfile images =
      options_.best_effort ? ros2::QosProfile::SensorData() : ros2::QosProfile::Default();
  AVP_ASSIGN_OR_RETURN(color_sub_, node_.CreateSubscription<rosmsg::Image>(
                                       options_.color_topic, images,
                                       [this](rosmsg::Image&& m, const ros2::SampleInfo&) {
                                         OnImage(std::move(m), true);
                                       }));
  AVP_ASSIGN_OR_RETURN(depth_sub_, node_.CreateSubscription<rosmsg::Image>(
                                       options_.depth_topic, images,
                                       [this](rosmsg::Image&& m, const ros2::SampleInfo&) {
                                         OnImage(std::move(m), false);
                                       }));
  AVP_ASSIGN_OR_RETURN(info_sub_, node_.CreateSubscription<rosmsg::CameraInfo>(
                                      options_.camera_info_topic, images,
                                      [this](rosmsg::CameraInfo&& m, const ros2::SampleInfo&) {
                                        OnCameraInfo(std::move(m));
                                      }));
  if (!options_.labels_prefix.empty()) {
    AVP_ASSIGN_OR_RETURN(instance_sub_, node_.CreateSubscription<rosmsg::Image>(
                                            options_.labels_prefix + "/instance", images,
                                            [this](rosmsg::Image&& m, const ros2::SampleInfo&) {
                                              OnLabel(std::move(m), true);
                                            }));
    AVP_ASSIGN_OR_RETURN(class_sub_, node_.CreateSubscription<rosmsg::Image>(
                                         options_.labels_prefix + "/class", images,
                                         [this](rosmsg::Image&& m, const ros2::SampleInfo&) {
                                           OnLabel(std::move(m), false);
                                         }));
    AVP_ASSIGN_OR_RETURN(
        fruits_sub_,
        node_.CreateSubscription<rosmsg::MarkerArray>(
            options_.labels_prefix + "/fruits", ros2::QosProfile::Latched(),
            [this](rosmsg::MarkerArray&& m, const ros2::SampleInfo&) { OnFruits(std::move(m)); }));
  }
  return Status::Ok();
}

Result<ImageRgb8> Ros2RgbdSource::ColorFromMessage(const rosmsg::Image& msg,
                                                   std::string_view topic) {
  AVP_RETURN_IF_ERROR(CheckImage(msg, topic, /*is_color=*/true));
  const bool rgb = msg.encoding == "rgb8";
  const int w = static_cast<int>(msg.width);
  const int h = static_cast<int>(msg.height);
  ImageRgb8 out(w, h);
  for (int v = 0; v < h; ++v) {
    const uint8_t* row = msg.data.data() + static_cast<size_t>(v) * msg.step;
    for (int u = 0; u < w; ++u) {
      const uint8_t* p = row + 3 * u;
      out.at(u, v, 0) = rgb ? p[0] : p[2];
      out.at(u, v, 1) = p[1];
      out.at(u, v, 2) = rgb ? p[2] : p[0];
    }
  }
  return out;
}

Result<DepthImage> Ros2RgbdSource::DepthFromMessage(const rosmsg::Image& msg,
                                                    std::string_view topic) {
  AVP_RETURN_IF_ERROR(CheckImage(msg, topic, /*is_color=*/false));
  const bool mm = msg.encoding == "16UC1" || msg.encoding == "mono16";
  const int w = static_cast<int>(msg.width);
  const int h = static_cast<int>(msg.height);
  DepthImage out(w, h);
  const bool swap = msg.is_bigendian != 0;
  for (int v = 0; v < h; ++v) {
    const uint8_t* row = msg.data.data() + static_cast<size_t>(v) * msg.step;
    for (int u = 0; u < w; ++u) {
      float z = 0.0f;
      if (mm) {
        const uint8_t* p = row + 2 * u;
        const uint16_t raw = swap ? static_cast<uint16_t>((p[0] << 8) | p[1])
                                  : static_cast<uint16_t>(p[0] | (p[1] << 8));
        z = static_cast<float>(raw) * 0.001f;
      } else {
        uint8_t b[4];
        std::memcpy(b, row + 4 * u, 4);
        if (swap) {
          std::swap(b[0], b[3]);
          std::swap(b[1], b[2]);
        }
        std::memcpy(&z, b, 4);
      }
      out.at(u, v) = std::isfinite(z) && z > 0.0f ? z : 0.0f;
    }
  }
  return out;
}

Result<CameraIntrinsics> Ros2RgbdSource::IntrinsicsFromCameraInfo(const rosmsg::CameraInfo& info,
                                                                  const CameraIntrinsics& range) {
  if (info.width == 0 || info.height == 0 || info.width > 16384 || info.height > 16384) {
    return InvalidArgumentError(
        fmt::format("CameraInfo (frame '{}'): size {}x{} is out of range (1..16384)",
                    info.header.frame_id, info.width, info.height));
  }
  CameraIntrinsics K;
  K.width = static_cast<int>(info.width);
  K.height = static_cast<int>(info.height);
  K.fx = info.k[0];
  K.fy = info.k[4];
  K.cx = info.k[2];
  K.cy = info.k[5];
  K.min_depth_m = range.min_depth_m;
  K.max_depth_m = range.max_depth_m;
  if (Status s = K.Validate(); !s.ok()) {
    return InvalidArgumentError(fmt::format("CameraInfo (frame '{}') gives invalid intrinsics: {}",
                                            info.header.frame_id, s.message()));
  }
  if (info.binning_x > 1 || info.binning_y > 1 || info.roi.width != 0 || info.roi.height != 0) {
    return InvalidArgumentError(fmt::format(
        "CameraInfo (frame '{}'): binning {}x{} or a region of interest {}x{} is not supported",
        info.header.frame_id, info.binning_x, info.binning_y, info.roi.width, info.roi.height));
  }
  return K;
}

void Ros2RgbdSource::OnCameraInfo(rosmsg::CameraInfo&& msg) {
  Result<CameraIntrinsics> K = IntrinsicsFromCameraInfo(msg, camera_);
  std::lock_guard lock(mutex_);
  ++counters_.camera_info;
  if (!K.ok()) {
    counters_.last_problem =
        fmt::format("{}: {}", options_.camera_info_topic, K.status().message());
    return;
  }
  const bool distorted =
      std::any_of(msg.d.begin(), msg.d.end(), [](double d) { return std::abs(d) > 1e-9; });
  if (distorted && !warned_distortion_) {
    warned_distortion_ = true;
    spdlog::warn(
        "{}: distortion model '{}' with non-zero coefficients: avp treats the images as "
        "undistorted (RealSense colour and aligned depth are)",
        options_.camera_info_topic, msg.distortion_model);
  }
  if (!K_) {
    if (K->width != camera_.width || K->height != camera_.height) {
      spdlog::info("{}: the camera is {}x{} (the configured camera: {}x{})",
                   options_.camera_info_topic, K->width, K->height, camera_.width, camera_.height);
    }
  }
  K_ = *K;
  cv_.notify_all();
}

void Ros2RgbdSource::OnImage(rosmsg::Image&& msg, bool is_color) {
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
  std::deque<rosmsg::Image>& q = is_color ? color_ : depth_;
  // Keep the queue sorted by stamp (frames may arrive out of order).
  const int64_t t = StampNs(msg.header);
  auto pos = std::upper_bound(q.begin(), q.end(), t, [](int64_t s, const rosmsg::Image& m) {
    return s < StampNs(m.header);
  });
  q.insert(pos, std::move(msg));
  while (q.size() > static_cast<size_t>(options_.queue)) q.pop_front();
  cv_.notify_all();
}

void Ros2RgbdSource::OnLabel(rosmsg::Image&& msg, bool is_instance) {
  std::lock_guard lock(mutex_);
  std::deque<rosmsg::Image>& q = is_instance ? instance_ : class_;
  q.push_back(std::move(msg));
  while (q.size() > static_cast<size_t>(options_.queue)) q.pop_front();
  cv_.notify_all();
}

void Ros2RgbdSource::OnFruits(rosmsg::MarkerArray&& msg) {
  std::vector<GroundTruthFruit> fruits;
  for (const rosmsg::Marker& m : msg.markers) {
    if (m.id <= 0 || m.id > 65535) continue;
    fruits.push_back({static_cast<uint16_t>(m.id),
                      Eigen::Vector3d(m.pose.position.x, m.pose.position.y, m.pose.position.z),
                      0.5 * m.scale.x});
  }
  std::lock_guard lock(mutex_);
  fruits_ = std::move(fruits);
  have_fruits_ = true;
  cv_.notify_all();
}

std::optional<std::pair<size_t, size_t>> Ros2RgbdSource::FindPair(int64_t not_before_ns) const {
  const int64_t skew = static_cast<int64_t>(options_.max_pair_skew_ms * 1e6);
  for (size_t i = 0; i < color_.size(); ++i) {
    const int64_t tc = StampNs(color_[i].header);
    if (tc < not_before_ns) continue;
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
  auto ready = [&] {
    pair = FindPair(not_before);
    if (!pair) return false;
    if (!labels) return true;
    const int64_t t = StampNs(color_[pair->first].header);
    const auto at = [&](const std::deque<rosmsg::Image>& q) {
      return std::any_of(q.begin(), q.end(), [&](const auto& m) { return StampNs(m.header) == t; });
    };
    return have_fruits_ && at(instance_) && at(class_);
  };
  cv_.wait_until(lock, stop_, deadline, ready);
  if (stop_.stop_requested()) return CancelledError("stopped while waiting for a camera frame");
  if (!pair) {
    const auto newest = [](const std::deque<rosmsg::Image>& q) {
      return q.empty() ? std::string("none") : FormatStamp(StampNs(q.back().header));
    };
    return DeadlineExceededError(fmt::format(
        "no colour/depth pair stamped after {} within {} s on {} and {} (received {} colour, {} "
        "depth, {} refused; newest colour {}, depth {}; pairs need stamps within {} ms{}{})",
        FormatStamp(not_before), options_.frame_timeout_s, options_.color_topic,
        options_.depth_topic, counters_.color, counters_.depth, counters_.refused, newest(color_),
        newest(depth_), options_.max_pair_skew_ms,
        counters_.last_problem.empty() ? "" : "; last problem: ", counters_.last_problem));
  }
  if (!ready()) {
    return DeadlineExceededError(fmt::format(
        "a frame pair arrived but not its simulator labels on {}/instance, /class and /fruits "
        "within {} s",
        options_.labels_prefix, options_.frame_timeout_s));
  }
  const rosmsg::Image color = color_[pair->first];
  const rosmsg::Image depth = depth_[pair->second];
  (void)X_WC;
  return Assemble(color, depth, lock);
}

Result<robot::Observation> Ros2RgbdSource::Assemble(const rosmsg::Image& color,
                                                    const rosmsg::Image& depth,
                                                    std::unique_lock<std::mutex>& lock) {
  const int64_t t = StampNs(color.header);
  const CameraIntrinsics K = *K_;
  std::optional<rosmsg::Image> instance, cls;
  if (!options_.labels_prefix.empty()) {
    for (const auto& m : instance_) {
      if (StampNs(m.header) == t) instance = m;
    }
    for (const auto& m : class_) {
      if (StampNs(m.header) == t) cls = m;
    }
  }
  const std::vector<GroundTruthFruit> fruits = fruits_;
  ++counters_.pairs_used;
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
                              options_.base_frame, camera_frame, FormatStamp(t),
                              options_.tf_timeout_s, X_WC.status().message()));
  }
  AVP_ASSIGN_OR_RETURN(ImageRgb8 rgb, ColorFromMessage(color, options_.color_topic));
  AVP_ASSIGN_OR_RETURN(DepthImage depth_m, DepthFromMessage(depth, options_.depth_topic));
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
  if (instance && cls) {
    SimulatorLabels labels;
    if (instance->encoding != "16UC1" || cls->encoding != "mono8" ||
        !CheckLayout(*instance, options_.labels_prefix, 2).ok() ||
        !CheckLayout(*cls, options_.labels_prefix, 1).ok() || instance->width != color.width ||
        instance->height != color.height || cls->width != color.width ||
        cls->height != color.height) {
      return InvalidArgumentError(fmt::format(
          "{}: label images must be 16UC1 (instance) and mono8 (class) of the colour size",
          options_.labels_prefix));
    }
    labels.instance_ids = InstanceImage(K.width, K.height);
    labels.class_ids = ClassImage(K.width, K.height);
    for (int v = 0; v < K.height; ++v) {
      const uint8_t* ir = instance->data.data() + static_cast<size_t>(v) * instance->step;
      const uint8_t* cr = cls->data.data() + static_cast<size_t>(v) * cls->step;
      for (int u = 0; u < K.width; ++u) {
        labels.instance_ids.at(u, v) = static_cast<uint16_t>(ir[2 * u] | (ir[2 * u + 1] << 8));
        labels.class_ids.at(u, v) = cr[u];
      }
    }
    labels.fruits = fruits;
    obs.labels = std::move(labels);
  }
  return obs;
}

CameraIntrinsics Ros2RgbdSource::intrinsics() const {
  std::lock_guard lock(mutex_);
  return K_ ? *K_ : camera_;
}

SourceCounters Ros2RgbdSource::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

}  // namespace avp::live

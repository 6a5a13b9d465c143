#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/tf_buffer.h>

namespace avp::ros::msg {

namespace {

/// A frame name as tf2 keys it: without a leading '/' (ROS 1 bags and old drivers write one).
std::string_view FrameName(std::string_view name) {
  return !name.empty() && name.front() == '/' ? name.substr(1) : name;
}

int64_t Nanoseconds(double s) { return static_cast<int64_t>(std::llround(s * 1e9)); }

RigidTransform Interpolate(const RigidTransform& a, const RigidTransform& b, double t) {
  const Eigen::Quaterniond qa = a.quaternion();
  const Eigen::Quaterniond qb = b.quaternion();
  const Eigen::Vector3d p = (1.0 - t) * a.translation() + t * b.translation();
  return RigidTransform(qa.slerp(t, qb).normalized(), p);
}

}  // namespace

Status TfBuffer::Add(const TransformStamped& t, bool is_static) {
  const int64_t stamp_ns = t.header.stamp.ToNanoseconds();
  const std::string what =
      fmt::format("{} {} -> {} at {}", is_static ? "/tf_static" : "/tf",
                  QuoteText(FrameName(t.header.frame_id)), QuoteText(FrameName(t.child_frame_id)),
                  FormatStamp(stamp_ns));
  const Quaternion& q = t.transform.rotation;
  const double norm = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  if (std::isfinite(norm) && std::abs(norm - 1.0) > 1e-3) {
    return InvalidArgumentError(fmt::format(
        "{}: the quaternion ({}, {}, {}, {}) has norm {}, not 1", what, q.x, q.y, q.z, q.w, norm));
  }
  Result<RigidTransform> X = FromTransformMsg(t.transform);
  if (!X.ok()) return X.status().WithContext(what);
  return Add(t.header.frame_id, t.child_frame_id, *X, stamp_ns, is_static);
}

Status TfBuffer::Add(std::string_view parent_name, std::string_view child_name,
                     const RigidTransform& X_PC, int64_t stamp_ns, bool is_static) {
  const std::string_view parent = FrameName(parent_name);
  const std::string_view child = FrameName(child_name);
  if (parent.empty() || child.empty()) {
    return InvalidArgumentError(fmt::format("transform {} -> {}: a frame name is empty",
                                            QuoteText(parent), QuoteText(child)));
  }
  if (parent == child) {
    return InvalidArgumentError(fmt::format("transform {} -> {}: a frame cannot be its own parent",
                                            QuoteText(parent), QuoteText(child)));
  }
  if (!X_PC.translation().allFinite() || !X_PC.rotation().allFinite()) {
    return InvalidArgumentError(fmt::format("transform {} -> {} at {}: not finite",
                                            QuoteText(parent), QuoteText(child),
                                            FormatStamp(stamp_ns)));
  }
  std::lock_guard lock(mutex_);
  // A loop: the new parent's chain must not pass through the child.
  for (std::string f(parent);;) {
    if (f == child) {
      return InvalidArgumentError(
          fmt::format("transform {} -> {} would close a loop in the transform tree",
                      QuoteText(parent), QuoteText(child)));
    }
    auto it = edges_.find(f);
    if (it == edges_.end()) break;
    f = it->second.parent;
  }
  auto [it, inserted] = edges_.try_emplace(std::string(child));
  Edge& edge = it->second;
  if (inserted) {
    edge.parent = std::string(parent);
    edge.is_static = is_static;
  } else if (edge.parent != parent) {
    return InvalidArgumentError(
        fmt::format("frame {} already has parent {}; refusing {} as its parent (tf2 would warn "
                    "of a frame published by two sources)",
                    QuoteText(child), QuoteText(edge.parent), QuoteText(parent)));
  }
  if (is_static || edge.is_static) {
    edge.is_static = true;
    edge.samples.assign(1, Sample{stamp_ns, X_PC});
    return Status::Ok();
  }
  std::vector<Sample>& s = edge.samples;
  const bool keep_all = !(options_.cache_s > 0.0);
  const int64_t cache_ns = keep_all ? 0 : Nanoseconds(options_.cache_s);
  if (!s.empty() && stamp_ns < s.back().stamp_ns) {
    if (!keep_all && stamp_ns < s.back().stamp_ns - cache_ns) {
      return OutOfRangeError(
          fmt::format("transform {} -> {} at {} is older than the {} s kept (newest {})",
                      QuoteText(parent), QuoteText(child), FormatStamp(stamp_ns), options_.cache_s,
                      FormatStamp(s.back().stamp_ns)));
    }
    // Out of order: insert in place (a replay or two publishers).
    auto pos = std::upper_bound(s.begin(), s.end(), stamp_ns,
                                [](int64_t t, const Sample& x) { return t < x.stamp_ns; });
    s.insert(pos, Sample{stamp_ns, X_PC});
  } else if (!s.empty() && stamp_ns == s.back().stamp_ns) {
    s.back().X_PC = X_PC;
  } else {
    s.push_back(Sample{stamp_ns, X_PC});
  }
  if (keep_all) return Status::Ok();
  // Drop what is older than the cache, keeping at least two samples.
  const int64_t oldest = s.back().stamp_ns - cache_ns;
  size_t drop = 0;
  while (drop + 2 < s.size() && s[drop + 1].stamp_ns <= oldest) ++drop;
  s.erase(s.begin(), s.begin() + static_cast<std::ptrdiff_t>(drop));
  return Status::Ok();
}

std::vector<std::pair<std::string, const TfBuffer::Edge*>> TfBuffer::ChainToRoot(
    const std::string& frame) const {
  std::vector<std::pair<std::string, const Edge*>> chain;
  std::string f = frame;
  for (size_t guard = 0; guard <= edges_.size(); ++guard) {
    auto it = edges_.find(f);
    if (it == edges_.end()) break;
    chain.emplace_back(f, &it->second);
    f = it->second.parent;
  }
  return chain;
}

Result<RigidTransform> TfBuffer::EdgeAt(const std::string& child, const Edge& edge,
                                        int64_t stamp_ns) const {
  const std::vector<Sample>& s = edge.samples;
  if (edge.is_static) return s.front().X_PC;
  const int64_t extrapolation_ns = Nanoseconds(options_.extrapolation_s);
  if (stamp_ns > s.back().stamp_ns) {
    const int64_t gap = stamp_ns - s.back().stamp_ns;
    if (gap <= extrapolation_ns) return s.back().X_PC;
    return DeadlineExceededError(
        fmt::format("transform {} -> {} at {} is not available yet: the newest is {} ({:.1f} ms "
                    "earlier, beyond the tolerance of {:.1f} ms)",
                    QuoteText(edge.parent), QuoteText(child), FormatStamp(stamp_ns),
                    FormatStamp(s.back().stamp_ns), static_cast<double>(gap) / 1e6,
                    static_cast<double>(extrapolation_ns) / 1e6));
  }
  if (stamp_ns < s.front().stamp_ns) {
    const int64_t gap = s.front().stamp_ns - stamp_ns;
    if (gap <= extrapolation_ns) return s.front().X_PC;
    return OutOfRangeError(
        fmt::format("transform {} -> {} at {} is older than the oldest kept ({}, {:.1f} ms "
                    "later, beyond the tolerance of {:.1f} ms)",
                    QuoteText(edge.parent), QuoteText(child), FormatStamp(stamp_ns),
                    FormatStamp(s.front().stamp_ns), static_cast<double>(gap) / 1e6,
                    static_cast<double>(extrapolation_ns) / 1e6));
  }
  auto hi = std::lower_bound(s.begin(), s.end(), stamp_ns,
                             [](const Sample& x, int64_t t) { return x.stamp_ns < t; });
  if (hi->stamp_ns == stamp_ns || hi == s.begin()) return hi->X_PC;
  auto lo = hi - 1;
  // A frame at rest publishes the same transform again: return it exactly.
  if (lo->X_PC.translation() == hi->X_PC.translation() &&
      lo->X_PC.rotation() == hi->X_PC.rotation()) {
    return lo->X_PC;
  }
  const double t = static_cast<double>(stamp_ns - lo->stamp_ns) /
                   static_cast<double>(hi->stamp_ns - lo->stamp_ns);
  return Interpolate(lo->X_PC, hi->X_PC, t);
}

Result<RigidTransform> TfBuffer::Lookup(std::string_view target_name, std::string_view source_name,
                                        int64_t stamp_ns) const {
  const std::string_view target = FrameName(target_name);
  const std::string_view source = FrameName(source_name);
  if (target == source) return RigidTransform::Identity();
  std::lock_guard lock(mutex_);
  const auto KnownFrames = [&] {
    return EscapeText(fmt::format("{}", fmt::join(FramesLocked(), ", ")), 400);
  };
  const auto up_source = ChainToRoot(std::string(source));
  const auto up_target = ChainToRoot(std::string(target));
  const std::string root_s =
      up_source.empty() ? std::string(source) : up_source.back().second->parent;
  const std::string root_t =
      up_target.empty() ? std::string(target) : up_target.back().second->parent;
  if (up_source.empty() && edges_.find(source) == edges_.end() &&
      std::none_of(edges_.begin(), edges_.end(),
                   [&](const auto& e) { return e.second.parent == source; })) {
    return NotFoundError(fmt::format("frame {} is not in the transform tree (known: {})",
                                     QuoteText(source), KnownFrames()));
  }
  if (up_target.empty() && edges_.find(target) == edges_.end() &&
      std::none_of(edges_.begin(), edges_.end(),
                   [&](const auto& e) { return e.second.parent == target; })) {
    return NotFoundError(fmt::format("frame {} is not in the transform tree (known: {})",
                                     QuoteText(target), KnownFrames()));
  }
  if (root_s != root_t) {
    return NotFoundError(
        fmt::format("frames {} and {} are not connected: their trees have roots {} and {}",
                    QuoteText(target), QuoteText(source), QuoteText(root_t), QuoteText(root_s)));
  }
  // X_RS and X_RT through the common root, dropping the shared part of the chains.
  size_t common = 0;
  while (common < up_source.size() && common < up_target.size() &&
         up_source[up_source.size() - 1 - common].first ==
             up_target[up_target.size() - 1 - common].first) {
    ++common;
  }
  RigidTransform X_AS;  // source in the lowest common ancestor A
  for (size_t i = up_source.size() - common; i-- > 0;) {
    AVP_ASSIGN_OR_RETURN(const RigidTransform X_PC,
                         EdgeAt(up_source[i].first, *up_source[i].second, stamp_ns));
    X_AS = X_AS * X_PC;
  }
  RigidTransform X_AT;
  for (size_t i = up_target.size() - common; i-- > 0;) {
    AVP_ASSIGN_OR_RETURN(const RigidTransform X_PC,
                         EdgeAt(up_target[i].first, *up_target[i].second, stamp_ns));
    X_AT = X_AT * X_PC;
  }
  return X_AT.inverse() * X_AS;
}

Result<int64_t> TfBuffer::LatestCommonTime(std::string_view target_name,
                                           std::string_view source_name) const {
  const std::string_view target = FrameName(target_name);
  const std::string_view source = FrameName(source_name);
  std::lock_guard lock(mutex_);
  int64_t latest = std::numeric_limits<int64_t>::max();
  bool any = false;
  for (const std::string_view f : {source, target}) {
    for (const auto& [child, edge] : ChainToRoot(std::string(f))) {
      any = true;
      if (!edge->is_static) latest = std::min(latest, edge->samples.back().stamp_ns);
    }
  }
  if (!any && target != source) {
    return NotFoundError(
        fmt::format("no transform between {} and {}", QuoteText(target), QuoteText(source)));
  }
  return latest;
}

std::vector<std::string> TfBuffer::FramesLocked() const {
  std::vector<std::string> frames;
  for (const auto& [child, edge] : edges_) {
    frames.push_back(child);
    frames.push_back(edge.parent);
  }
  std::sort(frames.begin(), frames.end());
  frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
  return frames;
}

std::vector<std::string> TfBuffer::Frames() const {
  std::lock_guard lock(mutex_);
  return FramesLocked();
}

bool TfBuffer::empty() const {
  std::lock_guard lock(mutex_);
  return edges_.empty();
}

}  // namespace avp::ros::msg

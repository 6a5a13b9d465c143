#pragma once

// The visitors MessageTraits<T>::VisitFields drives to encode and decode (internal).

#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>

#include <avp/ros/msg/cdr.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::msg::internal {

class EncodeVisitor {
 public:
  EncodeVisitor(CdrWriter& writer, RosDistro distro) : w_(writer), distro_(distro) {}
  RosDistro distro() const { return distro_; }

  template <class F>
  void operator()(std::string_view /*name*/, const F& field) {
    Put(field);
  }
  void FixedBytes(std::string_view /*name*/, const std::array<uint8_t, 24>& data, size_t n) {
    w_.WriteArray(std::span<const uint8_t>(data.data(), n));
  }
  void BoundedString(std::string_view /*name*/, const std::string& s, size_t /*bound*/) {
    w_.WriteString(s);
  }

 private:
  template <CdrPrimitive P>
  void Put(P value) {
    w_.Write(value);
  }
  void Put(const std::string& s) { w_.WriteString(s); }
  template <CdrPrimitive P>
  void Put(const std::vector<P>& values) {
    w_.WriteSequenceLength(values.size());
    w_.WriteArray(std::span<const P>(values));
  }
  void Put(const std::vector<std::string>& values) {
    w_.WriteSequenceLength(values.size());
    for (const std::string& s : values) w_.WriteString(s);
  }
  template <CdrPrimitive P, size_t N>
  void Put(const std::array<P, N>& values) {
    w_.WriteArray(std::span<const P>(values));
  }
  template <RosMessage M>
  void Put(const M& msg) {
    MessageTraits<M>::VisitFields(*this, msg);
  }
  template <RosMessage M>
  void Put(const std::vector<M>& values) {
    w_.WriteSequenceLength(values.size());
    for (const M& m : values) Put(m);
  }

  CdrWriter& w_;
  RosDistro distro_;
};

/// Reads fields in order; the first error sticks (later calls do nothing) and is reported with the
/// type name and the path of the field that failed ("markers[2].points[0].x").
class DecodeVisitor {
 public:
  DecodeVisitor(CdrReader& reader, RosDistro distro, std::string_view type)
      : r_(reader), distro_(distro), type_(type) {}
  RosDistro distro() const { return distro_; }
  const Status& status() const { return status_; }

  template <class F>
  void operator()(std::string_view name, F& field) {
    if (!status_.ok()) return;
    path_.push_back({name, kNoIndex});
    Get(field);
    path_.pop_back();
  }
  void FixedBytes(std::string_view name, std::array<uint8_t, 24>& data, size_t n) {
    if (!status_.ok()) return;
    path_.push_back({name, kNoIndex});
    data.fill(0);
    Check(r_.ReadArray(std::span<uint8_t>(data.data(), n)));
    path_.pop_back();
  }
  void BoundedString(std::string_view name, std::string& s, size_t bound) {
    if (!status_.ok()) return;
    path_.push_back({name, kNoIndex});
    Check(r_.ReadString(s, bound));
    path_.pop_back();
  }

 private:
  static constexpr size_t kNoIndex = std::numeric_limits<size_t>::max();
  struct PathElement {
    std::string_view name;
    size_t index;
  };

  void Check(const Status& s) {
    if (s.ok() || !status_.ok()) return;
    std::string path;
    for (const PathElement& e : path_) {
      if (!path.empty()) path += '.';
      path += e.name;
      if (e.index != kNoIndex) path += fmt::format("[{}]", e.index);
    }
    status_ = Status(s.code(), fmt::format("{}: {}: {}", type_, path, s.message()));
  }

  template <CdrPrimitive P>
  void Get(P& value) {
    Check(r_.Read(value));
  }
  void Get(std::string& s) { Check(r_.ReadString(s)); }
  template <CdrPrimitive P>
  void Get(std::vector<P>& values) {
    uint32_t n = 0;
    const std::string what = sizeof(P) == 1 && !std::is_same_v<P, bool>
                                 ? std::string("bytes")
                                 : fmt::format("{} values", CdrReader::PrimitiveName<P>());
    Check(r_.ReadSequenceLength(n, sizeof(P), what));
    if (!status_.ok()) return;
    values.resize(n);  // n * sizeof(P) <= remaining bytes
    Check(r_.ReadArray(std::span<P>(values)));
  }
  void Get(std::vector<std::string>& values) {
    uint32_t n = 0;
    // Each string takes at least its 4-byte length.
    Check(r_.ReadSequenceLength(n, 4, "strings"));
    values.clear();
    for (uint32_t i = 0; i < n && status_.ok(); ++i) {
      path_.back().index = i;
      Check(r_.ReadString(values.emplace_back()));
    }
    path_.back().index = kNoIndex;
  }
  template <CdrPrimitive P, size_t N>
  void Get(std::array<P, N>& values) {
    Check(r_.ReadArray(std::span<P>(values)));
  }
  template <RosMessage M>
  void Get(M& msg) {
    MessageTraits<M>::VisitFields(*this, msg);
  }
  template <RosMessage M>
  void Get(std::vector<M>& values) {
    uint32_t n = 0;
    // Each element takes at least one byte; no reserve, so memory grows only with bytes read.
    Check(r_.ReadSequenceLength(n, 1, "elements"));
    values.clear();
    for (uint32_t i = 0; i < n && status_.ok(); ++i) {
      path_.back().index = i;
      Get(values.emplace_back());
    }
    if (status_.ok()) path_.back().index = kNoIndex;
  }

  CdrReader& r_;
  RosDistro distro_;
  std::string_view type_;
  std::vector<PathElement> path_;
  Status status_;
};

}  // namespace avp::ros::msg::internal

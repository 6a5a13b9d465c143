// avp.Recording: an MCAP recording or a robot's rosbag2 bag (MCAP, .db3, a bag folder) as a
// stream of messages, with the images, masks, maps and steps avp writes decoded to numpy.
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <avp/mapping/map_reader.h>
#include <avp/mapping/octomap_io.h>
#include <avp/ros/bag/message_source.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/messages.h>

#include "bindings.h"

namespace avp::python {

namespace {

using ros::bag::BagMessage;
namespace msg = ros::msg;

/// "/avp/map at 1.25 s": a message in errors.
std::string Where(const BagMessage& m) {
  return fmt::format("{} at {:.3f} s", m.topic, static_cast<double>(m.log_time) * 1e-9);
}

template <typename T>
T DecodeAs(const BagMessage& m) {
  if (m.type != msg::MessageTraits<T>::kRosName) {
    throw py::value_error(fmt::format("{}: a {} message, not a {}", Where(m), m.type,
                                      msg::MessageTraits<T>::kRosName));
  }
  if (m.encoding != "cdr") {
    throw py::value_error(
        fmt::format("{}: encoding {}, only cdr is decoded", Where(m), m.encoding));
  }
  Result<T> decoded = msg::Decode<T>(std::span<const uint8_t>(m.data));
  if (!decoded.ok()) ThrowIfError(decoded.status().WithContext(Where(m)));
  return std::move(*decoded);
}

double Seconds(const msg::Time& t) { return t.sec + t.nanosec * 1e-9; }

/// An image message's pixels as they are: rgb8 / bgr8 / rgba8 / bgra8 as (h, w, 3) RGB uint8
/// (msg::ColorFromImage), 32FC1 as float32, 16UC1 / mono16 as uint16, mono8 / 8UC1 as uint8.
py::array ImagePixels(const BagMessage& m) {
  const msg::Image image = DecodeAs<msg::Image>(m);
  const std::string& e = image.encoding;
  const std::string where = Where(m);
  if (e == "32FC1") return ImageArray(Unwrap(msg::DepthFromImage(image, where)));
  if (e == "16UC1" || e == "mono16")
    return ImageArray(Unwrap(msg::InstanceIdsFromImage(image, where)));
  if (e == "mono8" || e == "8UC1") return ImageArray(Unwrap(msg::ClassIdsFromImage(image, where)));
  return ImageArray(Unwrap(msg::ColorFromImage(image, where)));
}

/// The decoded message: an image's pixels (ImagePixels), a String's text, an Octomap as an
/// avp.Map, a CameraInfo, JointState or TFMessage as a dict. ValueError for the other types.
py::object Decode(const BagMessage& m) {
  if (m.type == msg::MessageTraits<msg::Image>::kRosName) return ImagePixels(m);
  if (m.type == msg::MessageTraits<msg::String>::kRosName) {
    return py::str(DecodeAs<msg::String>(m).data);
  }
  if (m.type == msg::MessageTraits<msg::Octomap>::kRosName) {
    const msg::Octomap o = DecodeAs<msg::Octomap>(m);
    const std::string where = Where(m);
    const std::string bytes = Unwrap(mapping::OctomapMessageFileBytes(
        o.id, o.binary, o.resolution,
        std::string_view(reinterpret_cast<const char*>(o.data.data()), o.data.size()), where));
    Result<mapping::LoadedMap> loaded = mapping::LoadAnyMapBytes(bytes, where);
    return py::cast(std::make_shared<PyMap>(
        std::make_shared<const mapping::LoadedMap>(Unwrap(std::move(loaded)))));
  }
  if (m.type == msg::MessageTraits<msg::CameraInfo>::kRosName) {
    const msg::CameraInfo c = DecodeAs<msg::CameraInfo>(m);
    py::dict d;
    d["stamp"] = Seconds(c.header.stamp);
    d["frame_id"] = c.header.frame_id;
    d["width"] = c.width;
    d["height"] = c.height;
    d["distortion_model"] = c.distortion_model;
    d["d"] = c.d;
    d["k"] = OwnedMatrix(std::vector<double>(c.k.begin(), c.k.end()), 3);
    d["p"] = OwnedMatrix(std::vector<double>(c.p.begin(), c.p.end()), 4);
    return d;
  }
  if (m.type == msg::MessageTraits<msg::JointState>::kRosName) {
    const msg::JointState j = DecodeAs<msg::JointState>(m);
    py::dict d;
    d["stamp"] = Seconds(j.header.stamp);
    d["name"] = j.name;
    d["position"] = OwnedArray(std::vector<double>(j.position));
    d["velocity"] = OwnedArray(std::vector<double>(j.velocity));
    return d;
  }
  if (m.type == msg::MessageTraits<msg::TFMessage>::kRosName) {
    py::list out;
    for (const msg::TransformStamped& t : DecodeAs<msg::TFMessage>(m).transforms) {
      const Eigen::Quaterniond q(t.transform.rotation.w, t.transform.rotation.x,
                                 t.transform.rotation.y, t.transform.rotation.z);
      const Eigen::Vector3d p(t.transform.translation.x, t.transform.translation.y,
                              t.transform.translation.z);
      py::dict d;
      d["stamp"] = Seconds(t.header.stamp);
      d["parent"] = t.header.frame_id;
      d["child"] = t.child_frame_id;
      d["transform"] = TransformToArray(RigidTransform(q.normalized(), p));
      out.append(d);
    }
    return out;
  }
  throw py::value_error(
      fmt::format("{}: no decoder for {} (decoded: Image, String, Octomap, CameraInfo, JointState, "
                  "TFMessage); Message.data holds its CDR bytes",
                  Where(m), m.type));
}

/// An open bag read once from start to end (iterating it again reopens it).
class Recording {
 public:
  explicit Recording(std::filesystem::path path) : path_(std::move(path)) {
    CheckFileExists(path_, "recording");
    info_ = Open()->info();
  }
  const ros::bag::BagInfo& info() const { return info_; }
  const std::filesystem::path& path() const { return path_; }
  std::unique_ptr<ros::bag::MessageSource> Open() const {
    Result<std::unique_ptr<ros::bag::MessageSource>> source = [&] {
      py::gil_scoped_release release;
      return ros::bag::OpenBag(path_);
    }();
    return Unwrap(std::move(source));
  }

 private:
  std::filesystem::path path_;
  ros::bag::BagInfo info_;
};

/// Recording.messages(topics): the next message of the topics asked for (all when empty).
class MessageIterator {
 public:
  MessageIterator(std::unique_ptr<ros::bag::MessageSource> source, std::set<std::string> topics)
      : source_(std::move(source)), topics_(std::move(topics)) {}
  BagMessage Next() {
    for (;;) {
      Result<std::optional<BagMessage>> next = [&] {
        py::gil_scoped_release release;
        return source_->Next();
      }();
      std::optional<BagMessage> m = Unwrap(std::move(next));
      if (!m) throw py::stop_iteration();
      if (topics_.empty() || topics_.contains(m->topic)) return std::move(*m);
    }
  }

 private:
  std::unique_ptr<ros::bag::MessageSource> source_;
  std::set<std::string> topics_;
};

py::dict InfoDict(const ros::bag::BagInfo& i) {
  py::dict d;
  d["format"] = i.format;
  d["files"] = i.files;
  d["file_bytes"] = i.file_bytes;
  d["topics"] = i.topic_types;
  d["counts"] = i.topic_counts;
  d["metadata"] = i.metadata;
  py::list attachments;
  for (const ros::bag::BagAttachment& a : i.attachments) attachments.append(a.name);
  d["attachments"] = attachments;
  return d;
}

}  // namespace

void BindRecordings(py::module_& m) {
  py::class_<BagMessage>(m, "Message", "One message of a recording.")
      .def_readonly("topic", &BagMessage::topic)
      .def_readonly("type", &BagMessage::type, "e.g. 'sensor_msgs/msg/Image'")
      .def_readonly("log_time", &BagMessage::log_time, "nanoseconds since the epoch")
      .def_property_readonly(
          "data",
          [](const BagMessage& b) {
            return py::bytes(reinterpret_cast<const char*>(b.data.data()), b.data.size());
          },
          "The serialized message (CDR for a ROS 2 bag).")
      .def("decode", &Decode,
           "The message as Python values: an Image's pixels (rgb8 and the other colour "
           "encodings as (h, w, 3) RGB uint8, 32FC1 as float32, 16UC1 / mono16 as uint16 -- "
           "avp's instance masks and the simulator's instance ids, a 16UC1 depth in mm --, mono8 "
           "as uint8), a String's text (avp's /avp/step and /avp/segmentation/instances are "
           "JSON: json.loads), an Octomap as an avp.Map, a CameraInfo, JointState or TFMessage "
           "as a dict.")
      .def(
          "depth",
          [](const BagMessage& b) {
            return ImageArray(Unwrap(msg::DepthFromImage(DecodeAs<msg::Image>(b), Where(b))));
          },
          "A depth image in metres (float32; 16UC1 millimetres and 32FC1 metres alike, 0: no "
          "return), as avp replay reads it.")
      .def("__repr__", [](const BagMessage& b) {
        return fmt::format("<avp.Message {} {} {} bytes>", Where(b), b.type, b.data.size());
      });
  py::class_<MessageIterator>(m, "_MessageIterator")
      .def("__iter__", [](MessageIterator& it) -> MessageIterator& { return it; })
      .def("__next__", &MessageIterator::Next);
  py::class_<Recording>(m, "Recording",
                        "An MCAP recording (avp run --record) or a robot's rosbag2 bag (MCAP, "
                        "Humble's .db3, a bag folder), read as `avp replay` reads it.")
      .def(py::init<std::filesystem::path>(), py::arg("path"))
      .def_property_readonly("path", &Recording::path)
      .def_property_readonly(
          "info", [](const Recording& r) { return InfoDict(r.info()); },
          "format, files, file_bytes, topics (topic: type), counts, metadata "
          "(avp's recordings: the run's), attachments (their names).")
      .def(
          "attachment",
          [](const Recording& r, const std::string& name) {
            for (const ros::bag::BagAttachment& a : r.info().attachments) {
              if (a.name == name) return py::bytes(a.data);
            }
            throw py::value_error(
                fmt::format("'{}' has no attachment '{}'", r.path().string(), name));
          },
          py::arg("name"), "An attachment's bytes (avp's recordings: ground_truth.json).")
      .def(
          "messages",
          [](const Recording& r, const std::vector<std::string>& topics) {
            return MessageIterator(r.Open(), std::set<std::string>(topics.begin(), topics.end()));
          },
          py::arg("topics") = std::vector<std::string>{},
          "The messages in log-time order, of `topics` only when given. A damaged bag yields "
          "every intact message, then raises ValueError naming where it stops.")
      .def("__iter__", [](const Recording& r) { return MessageIterator(r.Open(), {}); })
      .def("__repr__", [](const Recording& r) {
        return fmt::format("<avp.Recording {} ({})>", r.path().string(), r.info().format);
      });
}

}  // namespace avp::python

#pragma once

// ROS 2 topics over plain Cyclone DDS (no ROS install): a Node is one DDS participant that ROS 2
// peers (rmw_cyclonedds or rmw_fastrtps, Humble or Jazzy) see as a node with its publishers and
// subscriptions (`ros2 node list`, `ros2 node info`, `ros2 topic echo`).
//
// Wire conventions (shared/design/ros2-interop.md §1.2): DDS topic "rt" + the fully qualified ROS
// name, type name `pkg::msg::dds_::Type_`, keyless, XCDR1 pinned on every reader and writer, the
// payload is exactly what avp::ros::msg::Encode produces (encapsulation header `00 01 00 00`), QoS
// as rclcpp's profiles, participant USER_DATA `enclave=/;`, endpoint USER_DATA
// `typehash=RIHS01_...;` (the Jazzy type hash; Humble ignores it), and a `ros_discovery_info`
// publisher (rmw_dds_common/ParticipantEntitiesInfo, GIDs of 24 bytes for Humble, 16 for Jazzy).
//
// Environment:
//   ROS_DOMAIN_ID        the DDS domain when NodeOptions::domain_id is -1 (0..232; default 0).
//   CYCLONEDDS_URI       Cyclone's own configuration; when set, avp never adds its own.
//   AVP_ROS2_LOOPBACK=1  as NodeOptions::loopback = true: 127.0.0.1 only, unicast discovery
//                        (loopback has no multicast), for tests and single-machine setups.
//
// Threads: each Node runs one thread that calls every subscription callback of that node, one at
// a time. Publish may be called from any thread, including from a callback.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <avp/core/status.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::dds {

enum class Reliability { kReliable, kBestEffort };
enum class Durability { kVolatile, kTransientLocal };

/// History is always KEEP_LAST `depth`. Liveliness automatic, autodispose off; a transient-local
/// writer keeps its last `depth` samples for late joiners (durability_service likewise).
struct QosProfile {
  Reliability reliability = Reliability::kReliable;
  Durability durability = Durability::kVolatile;
  int depth = 10;

  static QosProfile Default();     ///< keep-last 10, reliable, volatile (rclcpp's default)
  static QosProfile SensorData();  ///< keep-last 5, best effort, volatile (camera drivers)
  static QosProfile TfStatic();    ///< keep-last 1, reliable, transient local (/tf_static)
  static QosProfile Tf();          ///< keep-last 100, reliable, volatile (/tf)
  /// Reliable, transient local, keep-last `depth`: maps and markers that RViz gets when it joins.
  static QosProfile Latched(int depth = 1);

  /// "depth (0) must be >= 1".
  Status Validate() const;
};

struct SampleInfo {
  int64_t source_timestamp_ns = 0;  ///< the writer's clock at publication (Unix epoch)
  int64_t received_ns = 0;          ///< this process's clock when the sample was taken
};

struct NodeOptions {
  std::string name = "avp";      ///< ROS node name: [A-Za-z_][A-Za-z0-9_]*
  std::string namespace_ = "/";  ///< absolute ("/robot1"); a relative one gets a leading '/'
  int domain_id = -1;            ///< 0..232, or -1: ROS_DOMAIN_ID, else 0
  ros::msg::RosDistro distro = ros::msg::RosDistro::kHumble;  ///< GID size in ros_discovery_info
  bool loopback = false;  ///< also AVP_ROS2_LOOPBACK=1; ignored when CYCLONEDDS_URI is set
};

/// The names a raw endpoint is created with: DDS type name ("sensor_msgs::msg::dds_::Image_"),
/// ROS type name ("sensor_msgs/msg/Image", for messages) and Jazzy type hash ("RIHS01_<hex>", may
/// be empty: then no typehash= goes into USER_DATA).
struct TypeInfo {
  std::string dds_name;
  std::string ros_name;
  std::string type_hash;

  template <class M>
  static TypeInfo Of() {
    return {std::string(ros::msg::MessageTraits<M>::kDdsName),
            std::string(ros::msg::MessageTraits<M>::kRosName),
            ros::msg::TypeHashOf(ros::msg::MessageTraits<M>::kRosName).value_or("")};
  }
};

namespace internal {
struct NodeCore;
struct SubscriptionState;
}  // namespace internal

/// Publishes serialised samples (the encapsulation header included) on one topic.
class RawPublisher {
 public:
  ~RawPublisher();
  RawPublisher(const RawPublisher&) = delete;
  RawPublisher& operator=(const RawPublisher&) = delete;

  /// Sends `cdr` as is. Errors name the topic and Cyclone's return code.
  Status Publish(std::span<const uint8_t> cdr);
  /// Readers currently matched (QoS-compatible, same topic and type name), local ones included.
  size_t matched_subscriptions() const;
  /// The fully qualified ROS topic name ("/camera/color/image_raw").
  const std::string& topic() const { return topic_; }
  const TypeInfo& type() const { return type_; }
  /// The writer's 16-byte DDS GUID (its GID in ros_discovery_info).
  std::array<uint8_t, 16> guid() const;

 private:
  friend class Node;
  RawPublisher(std::shared_ptr<internal::NodeCore> core, int32_t writer, int32_t dds_topic,
               std::string topic, TypeInfo type);

  std::shared_ptr<internal::NodeCore> core_;
  int32_t writer_ = 0;
  int32_t dds_topic_ = 0;
  std::string topic_;
  TypeInfo type_;
};

/// Called with the bytes of each received sample on the node's thread; a non-OK status counts the
/// sample as malformed (see RawSubscription::malformed) and the subscription goes on.
using RawCallback = std::function<Status(std::span<const uint8_t> cdr, const SampleInfo& info)>;

/// Receives serialised samples on one topic. Destroying it guarantees that its callback is not
/// running and is never called again (also when destroyed from inside its own callback).
class RawSubscription {
 public:
  ~RawSubscription();
  RawSubscription(const RawSubscription&) = delete;
  RawSubscription& operator=(const RawSubscription&) = delete;

  /// Writers currently matched (QoS-compatible, same topic and type name), local ones included.
  size_t matched_publishers() const;
  /// Samples delivered to the callback, malformed ones included.
  uint64_t received() const;
  /// Samples the callback refused (a decode error); each logs a rate-limited warning.
  uint64_t malformed() const;
  /// The last refusal ("malformed sample on /topic (sensor_msgs/msg/Image): ..."), or OK.
  Status last_error() const;
  const std::string& topic() const { return topic_; }
  const TypeInfo& type() const { return type_; }
  /// The reader's 16-byte DDS GUID (its GID in ros_discovery_info).
  std::array<uint8_t, 16> guid() const;

 private:
  friend class Node;
  RawSubscription(std::shared_ptr<internal::NodeCore> core,
                  std::shared_ptr<internal::SubscriptionState> state, std::string topic,
                  TypeInfo type);

  std::shared_ptr<internal::NodeCore> core_;
  std::shared_ptr<internal::SubscriptionState> state_;
  std::string topic_;
  TypeInfo type_;
};

/// Publishes messages of type M (any type with ros::msg::MessageTraits and Encode).
template <class M>
class Publisher {
 public:
  using Message = M;

  Publisher(std::unique_ptr<RawPublisher> raw, ros::msg::RosDistro distro)
      : raw_(std::move(raw)), distro_(distro) {}

  Status Publish(const M& msg) { return raw_->Publish(ros::msg::Encode(msg, distro_)); }
  size_t matched_subscriptions() const { return raw_->matched_subscriptions(); }
  const std::string& topic() const { return raw_->topic(); }
  const RawPublisher& raw() const { return *raw_; }

 private:
  std::unique_ptr<RawPublisher> raw_;
  ros::msg::RosDistro distro_;
};

/// Receives messages of type M, decoded with ros::msg::Decode; a sample that does not decode is
/// counted in malformed() and never reaches the callback.
template <class M>
class Subscription {
 public:
  using Message = M;

  explicit Subscription(std::unique_ptr<RawSubscription> raw) : raw_(std::move(raw)) {}

  size_t matched_publishers() const { return raw_->matched_publishers(); }
  uint64_t received() const { return raw_->received(); }
  uint64_t malformed() const { return raw_->malformed(); }
  Status last_error() const { return raw_->last_error(); }
  const std::string& topic() const { return raw_->topic(); }
  const RawSubscription& raw() const { return *raw_; }

 private:
  std::unique_ptr<RawSubscription> raw_;
};

/// One ROS 2 node: a DDS participant, its ros_discovery_info publisher and one callback thread.
/// Publishers and subscriptions may outlive it (they then do nothing), but should not.
class Node {
 public:
  /// Validates the options (node name, namespace, domain id: errors name the bad value), creates
  /// the participant and announces the node.
  static Result<std::unique_ptr<Node>> Create(const NodeOptions& options);
  ~Node();
  Node(const Node&) = delete;
  Node& operator=(const Node&) = delete;

  /// `topic`: absolute ("/camera/image"), relative to the node's namespace ("camera/image") or
  /// private ("~/debug"); checked against ROS's rules (error names the bad name).
  template <class M>
  Result<std::unique_ptr<Publisher<M>>> CreatePublisher(std::string_view topic,
                                                        const QosProfile& qos) {
    AVP_ASSIGN_OR_RETURN(auto raw, CreateRawPublisher(topic, TypeInfo::Of<M>(), qos));
    return std::make_unique<Publisher<M>>(std::move(raw), distro());
  }

  template <class M>
  Result<std::unique_ptr<Subscription<M>>> CreateSubscription(
      std::string_view topic, const QosProfile& qos,
      std::function<void(M&&, const SampleInfo&)> callback) {
    if (!callback) return InvalidArgumentError("CreateSubscription: the callback is empty");
    RawCallback raw_callback = [callback = std::move(callback), distro = distro()](
                                   std::span<const uint8_t> cdr, const SampleInfo& info) -> Status {
      Result<M> msg = ros::msg::Decode<M>(cdr, distro);
      if (!msg.ok()) return msg.status();
      callback(std::move(msg).value(), info);
      return Status::Ok();
    };
    AVP_ASSIGN_OR_RETURN(
        auto raw, CreateRawSubscription(topic, TypeInfo::Of<M>(), qos, std::move(raw_callback)));
    return std::make_unique<Subscription<M>>(std::move(raw));
  }

  Result<std::unique_ptr<RawPublisher>> CreateRawPublisher(std::string_view topic,
                                                           const TypeInfo& type,
                                                           const QosProfile& qos);
  Result<std::unique_ptr<RawSubscription>> CreateRawSubscription(std::string_view topic,
                                                                 const TypeInfo& type,
                                                                 const QosProfile& qos,
                                                                 RawCallback callback);

  int domain_id() const;
  const std::string& name() const;
  ros::msg::RosDistro distro() const;
  const std::string& namespace_() const;
  /// "/ns/name".
  const std::string& fully_qualified_name() const;
  /// The 16-byte DDS GUID of the participant (the node's GID without padding).
  std::array<uint8_t, 16> participant_guid() const;

 private:
  explicit Node(std::shared_ptr<internal::NodeCore> core);
  std::shared_ptr<internal::NodeCore> core_;
};

/// "/camera/image" from `topic` as a node in `node_namespace` named `node_name` sees it; an error
/// naming the topic when it breaks ROS's rules (empty, bad characters, a token starting with a
/// digit, "//", a trailing '/', substitutions "{...}").
Result<std::string> ExpandTopicName(std::string_view topic, std::string_view node_name,
                                    std::string_view node_namespace);

/// The domain in effect for `requested` (-1: ROS_DOMAIN_ID, else 0); an error naming the value
/// when it is not an integer in 0..232.
Result<int> ResolveDomainId(int requested);

}  // namespace avp::ros::dds

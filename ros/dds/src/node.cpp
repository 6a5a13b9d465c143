#include <chrono>
#include <cstdlib>
#include <map>
#include <mutex>
#include <thread>

#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/ros/dds/node.h>

#include "discovery_info.h"
#include "names.h"
#include "raw_sertype.h"

namespace avp::ros::dds {

// ---- QoS profiles
// ----------------------------------------------------------------------------------
QosProfile QosProfile::Default() { return {Reliability::kReliable, Durability::kVolatile, 10}; }
QosProfile QosProfile::SensorData() { return {Reliability::kBestEffort, Durability::kVolatile, 5}; }
QosProfile QosProfile::TfStatic() {
  return {Reliability::kReliable, Durability::kTransientLocal, 1};
}
QosProfile QosProfile::Tf() { return {Reliability::kReliable, Durability::kVolatile, 100}; }
QosProfile QosProfile::Latched(int depth) {
  return {Reliability::kReliable, Durability::kTransientLocal, depth};
}
Status QosProfile::Validate() const {
  if (depth < 1) return InvalidArgumentError(fmt::format("QoS depth ({}) must be >= 1", depth));
  return Status::Ok();
}

namespace internal {
namespace {

Status DdsError(std::string_view call, dds_return_t rc, std::string_view context) {
  return InternalError(fmt::format("{} failed for {}: {}", call, context, dds_strretcode(rc)));
}

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

bool LoopbackRequested(const NodeOptions& options) {
  if (options.loopback) return true;
  const char* env = std::getenv("AVP_ROS2_LOOPBACK");
  return env != nullptr && std::string_view(env) == "1";
}

bool CycloneUriSet() {
  const char* env = std::getenv("CYCLONEDDS_URI");
  return env != nullptr && *env != '\0';
}

// 127.0.0.1 only; loopback has no multicast, so discovery goes by unicast to the ports of
// participant indexes 0..MaxAutoParticipantIndex on 127.0.0.1 (shared/design/ros2-interop.md §5).
// The receive buffer asks for 8 MB (no minimum: the kernel caps it at net.core.rmem_max). With
// the default, best-effort images of 0.9-1.2 MB lost fragments and `avp live` got about half the
// colour frames of the simulator (12-15 colour against 22-52 depth in a 4-view episode; one
// capture waited 8.9 s). With it: every frame (33 of 33), captures about 0.1 s.
constexpr const char* kLoopbackConfig =
    "<General><Interfaces><NetworkInterface address=\"127.0.0.1\"/></Interfaces>"
    "<AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
    "<MaxAutoParticipantIndex>100</MaxAutoParticipantIndex>"
    "<Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery>"
    "<Internal><SocketReceiveBufferSize min=\"default\" max=\"8MB\"/></Internal>";

// Explicitly created (loopback) domains are shared by every node of this process in that domain:
// deleting a domain entity deletes all its participants, so the last node deletes it.
class LoopbackDomains {
 public:
  static LoopbackDomains& Get() {
    static LoopbackDomains* instance = new LoopbackDomains();  // never destroyed: no exit races
    return *instance;
  }

  Status Acquire(int domain_id) {
    std::lock_guard lock(mutex_);
    auto it = domains_.find(domain_id);
    if (it != domains_.end()) {
      ++it->second.refs;
      return Status::Ok();
    }
    const dds_entity_t domain =
        dds_create_domain(static_cast<dds_domainid_t>(domain_id), kLoopbackConfig);
    if (domain < 0) {
      if (domain == DDS_RETCODE_PRECONDITION_NOT_MET) {
        return FailedPreconditionError(fmt::format(
            "DDS domain {} already exists in this process without avp's loopback "
            "configuration: create every node of a process in that domain with the same "
            "loopback setting",
            domain_id));
      }
      return DdsError("dds_create_domain", domain, fmt::format("domain {}", domain_id));
    }
    domains_[domain_id] = {domain, 1};
    return Status::Ok();
  }

  void Release(int domain_id) {
    std::lock_guard lock(mutex_);
    auto it = domains_.find(domain_id);
    if (it == domains_.end()) return;
    if (--it->second.refs == 0) {
      dds_delete(it->second.entity);
      domains_.erase(it);
    }
  }

 private:
  struct Entry {
    dds_entity_t entity = 0;
    int refs = 0;
  };
  std::mutex mutex_;
  std::map<int, Entry> domains_;
};

dds_qos_t* MakeQos(const QosProfile& qos, bool writer, const std::string& type_hash) {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q,
                       qos.reliability == Reliability::kReliable ? DDS_RELIABILITY_RELIABLE
                                                                 : DDS_RELIABILITY_BEST_EFFORT,
                       DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, qos.depth);
  if (qos.durability == Durability::kTransientLocal) {
    dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
    dds_qset_durability_service(q, 0, DDS_HISTORY_KEEP_LAST, qos.depth, DDS_LENGTH_UNLIMITED,
                                DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED);
  } else {
    dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
  }
  dds_qset_liveliness(q, DDS_LIVELINESS_AUTOMATIC, DDS_INFINITY);
  if (writer) dds_qset_writer_data_lifecycle(q, false);
  dds_data_representation_id_t xcdr1[1] = {DDS_DATA_REPRESENTATION_XCDR1};
  dds_qset_data_representation(q, 1, xcdr1);
  if (!type_hash.empty()) {
    const std::string user_data = fmt::format("typehash={};", type_hash);
    dds_qset_userdata(q, user_data.data(), user_data.size());
  }
  return q;
}

struct QosDeleter {
  void operator()(dds_qos_t* q) const { dds_delete_qos(q); }
};
using QosPtr = std::unique_ptr<dds_qos_t, QosDeleter>;

}  // namespace

struct SubscriptionState {
  dds_entity_t reader = 0;
  dds_entity_t topic = 0;
  std::string topic_name;
  std::string description;  // "/topic (sensor_msgs/msg/Image)"
  RawCallback callback;
  std::atomic<bool> removed{false};
  std::atomic<uint64_t> received{0};
  std::atomic<uint64_t> malformed{0};
  mutable std::mutex error_mutex;
  Status last_error;
  std::chrono::steady_clock::time_point last_warning{};
  uint64_t suppressed_warnings = 0;

  void RecordMalformed(const Status& status) {
    malformed.fetch_add(1);
    const Status error(status.code(),
                       fmt::format("malformed sample on {}: {}", description, status.message()));
    std::lock_guard lock(error_mutex);
    last_error = error;
    const auto now = std::chrono::steady_clock::now();
    if (last_warning.time_since_epoch().count() == 0 ||
        now - last_warning >= std::chrono::seconds(5)) {
      if (suppressed_warnings > 0) {
        spdlog::warn("{} ({} more since the last warning)", error.message(), suppressed_warnings);
      } else {
        spdlog::warn("{}", error.message());
      }
      last_warning = now;
      suppressed_warnings = 0;
    } else {
      ++suppressed_warnings;
    }
  }
};

struct NodeCore {
  NodeOptions options;
  std::string name;
  std::string namespace_;
  std::string fq_name;
  int domain_id = 0;
  bool owns_loopback_domain = false;
  dds_entity_t participant = 0;
  dds_entity_t waitset = 0;
  dds_entity_t guard = 0;
  dds_entity_t discovery_topic = 0;
  dds_entity_t discovery_writer = 0;
  std::array<uint8_t, 16> participant_guid{};

  std::mutex mutex;  // guards the maps below and `closed`
  std::map<dds_entity_t, std::shared_ptr<SubscriptionState>> subscriptions;  // by reader
  std::map<dds_entity_t, std::array<uint8_t, 16>> reader_guids;
  std::map<dds_entity_t, std::array<uint8_t, 16>> writer_guids;
  bool closed = false;

  // Held while a callback runs; recursive so that a callback may destroy subscriptions.
  std::recursive_mutex dispatch_mutex;
  std::thread thread;
  std::atomic<bool> stop{false};

  ~NodeCore() { Close(); }

  void Close() {
    {
      std::lock_guard lock(mutex);
      if (closed) return;
      closed = true;
    }
    stop = true;
    if (guard > 0) dds_set_guardcondition(guard, true);
    if (thread.joinable()) {
      if (thread.get_id() == std::this_thread::get_id()) {
        thread.detach();  // the node destroyed from its own callback: the loop ends by itself
      } else {
        thread.join();
      }
    }
    std::lock_guard dispatch(dispatch_mutex);
    {
      std::lock_guard lock(mutex);
      for (auto& [reader, state] : subscriptions) state->removed = true;
      subscriptions.clear();
    }
    if (participant > 0) dds_delete(participant);
    participant = 0;
    if (owns_loopback_domain) LoopbackDomains::Get().Release(domain_id);
    owns_loopback_domain = false;
  }

  // Announces the node and its endpoints on ros_discovery_info (transient local, keep-last 1).
  void PublishDiscoveryInfo() {
    std::vector<std::array<uint8_t, 16>> readers, writers;
    {
      std::lock_guard lock(mutex);
      if (closed) return;
      for (const auto& [entity, guid] : reader_guids) readers.push_back(guid);
      for (const auto& [entity, guid] : writer_guids) writers.push_back(guid);
    }
    const std::vector<uint8_t> bytes =
        EncodeDiscoveryInfo(options.distro, participant_guid, namespace_, name, readers, writers);
    ddsi_serdata* sd = nullptr;
    const ddsi_sertype* sertype = nullptr;
    if (WriterSertype(discovery_writer, &sertype) == DDS_RETCODE_OK) {
      sd = NewRawSerdata(sertype, bytes);
    }
    if (sd == nullptr) return;
    sd->timestamp.v = dds_time();
    const dds_return_t rc = dds_writecdr(discovery_writer, sd);
    if (rc != DDS_RETCODE_OK) {
      spdlog::warn("ros2 node {}: publishing ros_discovery_info failed: {}", fq_name,
                   dds_strretcode(rc));
    }
  }

  // The sertype each writer was created with, for building serdata (Cyclone 0.10 has no
  // dds_get_entity_sertype).
  std::map<dds_entity_t, const ddsi_sertype*> writer_sertypes;
  std::mutex sertype_mutex;
  dds_return_t WriterSertype(dds_entity_t writer, const ddsi_sertype** out) {
    std::lock_guard lock(sertype_mutex);
    auto it = writer_sertypes.find(writer);
    if (it == writer_sertypes.end()) return DDS_RETCODE_BAD_PARAMETER;
    *out = it->second;
    return DDS_RETCODE_OK;
  }

  void Run() {
    std::vector<dds_attach_t> triggered(64);
    while (!stop) {
      const dds_return_t n =
          dds_waitset_wait(waitset, triggered.data(), triggered.size(), DDS_MSECS(200));
      if (stop) break;
      if (n < 0) {
        spdlog::error("ros2 node {}: dds_waitset_wait failed: {}", fq_name, dds_strretcode(n));
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        continue;
      }
      for (dds_return_t i = 0; i < n && !stop; ++i) {
        const auto reader = static_cast<dds_entity_t>(triggered[static_cast<size_t>(i)]);
        if (reader == guard) {
          bool value = false;
          dds_take_guardcondition(guard, &value);
          continue;
        }
        std::lock_guard dispatch(dispatch_mutex);
        std::shared_ptr<SubscriptionState> state;
        {
          std::lock_guard lock(mutex);
          auto it = subscriptions.find(reader);
          if (it != subscriptions.end()) state = it->second;
        }
        if (state != nullptr) Drain(*state);
      }
    }
  }

  void Drain(SubscriptionState& state) {
    constexpr int kBatch = 16;
    ddsi_serdata* samples[kBatch];
    dds_sample_info_t infos[kBatch];
    while (!state.removed && !stop) {
      const dds_return_t n = dds_takecdr(state.reader, samples, kBatch, infos, DDS_ANY_STATE);
      if (n <= 0) break;
      for (dds_return_t i = 0; i < n; ++i) {
        const bool deliver = infos[i].valid_data && !state.removed && !stop;
        if (deliver) {
          SampleInfo info;
          info.source_timestamp_ns = infos[i].source_timestamp;
          info.received_ns = NowNs();
          state.received.fetch_add(1);
          Status status;
          try {
            status = state.callback(RawSerdataBytes(samples[i]), info);
          } catch (const std::exception& e) {
            status = InternalError(fmt::format("the callback threw: {}", e.what()));
          }
          if (!status.ok()) state.RecordMalformed(status);
        }
        ddsi_serdata_unref(samples[i]);
      }
    }
  }
};

}  // namespace internal

using internal::NodeCore;
using internal::SubscriptionState;

// ---- Node
// ------------------------------------------------------------------------------------------
Node::Node(std::shared_ptr<NodeCore> core) : core_(std::move(core)) {}
Node::~Node() { core_->Close(); }

int Node::domain_id() const { return core_->domain_id; }
const std::string& Node::name() const { return core_->name; }
const std::string& Node::namespace_() const { return core_->namespace_; }
const std::string& Node::fully_qualified_name() const { return core_->fq_name; }
std::array<uint8_t, 16> Node::participant_guid() const { return core_->participant_guid; }
ros::msg::RosDistro Node::distro() const { return core_->options.distro; }

Result<std::unique_ptr<Node>> Node::Create(const NodeOptions& options) {
  AVP_RETURN_IF_ERROR(ValidateNodeName(options.name));
  AVP_ASSIGN_OR_RETURN(std::string ns, NormalizeNamespace(options.namespace_));
  AVP_ASSIGN_OR_RETURN(const int domain_id, ResolveDomainId(options.domain_id));

  auto core = std::make_shared<NodeCore>();
  core->options = options;
  core->name = options.name;
  core->namespace_ = ns;
  core->fq_name =
      ns == "/" ? fmt::format("/{}", options.name) : fmt::format("{}/{}", ns, options.name);
  core->domain_id = domain_id;
  const std::string context = fmt::format("ROS 2 node {} in domain {}", core->fq_name, domain_id);

  if (internal::LoopbackRequested(options) && !internal::CycloneUriSet()) {
    AVP_RETURN_IF_ERROR(internal::LoopbackDomains::Get().Acquire(domain_id).WithContext(context));
    core->owns_loopback_domain = true;
  }

  internal::QosPtr pqos(dds_create_qos());
  static constexpr char kEnclave[] = "enclave=/;";
  dds_qset_userdata(pqos.get(), kEnclave, sizeof(kEnclave) - 1);
  core->participant =
      dds_create_participant(static_cast<dds_domainid_t>(domain_id), pqos.get(), nullptr);
  if (core->participant < 0) {
    const dds_return_t rc = core->participant;
    core->participant = 0;
    return internal::DdsError("dds_create_participant", rc, context);
  }
  dds_guid_t guid;
  if (const dds_return_t rc = dds_get_guid(core->participant, &guid); rc != DDS_RETCODE_OK) {
    return internal::DdsError("dds_get_guid", rc, context);
  }
  std::copy(std::begin(guid.v), std::end(guid.v), core->participant_guid.begin());

  core->waitset = dds_create_waitset(core->participant);
  if (core->waitset < 0) return internal::DdsError("dds_create_waitset", core->waitset, context);
  core->guard = dds_create_guardcondition(core->participant);
  if (core->guard < 0) return internal::DdsError("dds_create_guardcondition", core->guard, context);
  if (const dds_return_t rc =
          dds_waitset_attach(core->waitset, core->guard, static_cast<dds_attach_t>(core->guard));
      rc != DDS_RETCODE_OK) {
    return internal::DdsError("dds_waitset_attach", rc, context);
  }

  // ros_discovery_info: no "rt/" prefix, reliable, transient local, keep-last 1.
  {
    ddsi_sertype* sertype =
        internal::NewRawSertype("rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_");
    internal::QosPtr qos(internal::MakeQos(QosProfile::Latched(1), /*writer=*/true, ""));
    core->discovery_topic = dds_create_topic_sertype(core->participant, "ros_discovery_info",
                                                     &sertype, qos.get(), nullptr, nullptr);
    if (core->discovery_topic < 0) {
      internal::FreeRawSertype(sertype);
      return internal::DdsError("dds_create_topic_sertype", core->discovery_topic,
                                context + ", topic ros_discovery_info");
    }
    core->discovery_writer =
        dds_create_writer(core->participant, core->discovery_topic, qos.get(), nullptr);
    if (core->discovery_writer < 0) {
      return internal::DdsError("dds_create_writer", core->discovery_writer,
                                context + ", topic ros_discovery_info");
    }
    std::lock_guard lock(core->sertype_mutex);
    core->writer_sertypes[core->discovery_writer] = sertype;
  }
  core->PublishDiscoveryInfo();
  // The thread keeps the core alive: a node destroyed from its own callback detaches it.
  core->thread = std::thread([core] { core->Run(); });
  return std::unique_ptr<Node>(new Node(std::move(core)));
}

namespace {

struct TopicEntities {
  dds_entity_t topic = 0;
  const ddsi_sertype* sertype = nullptr;
};

Result<TopicEntities> CreateTopic(NodeCore& core, const std::string& dds_topic,
                                  const TypeInfo& type, const std::string& context) {
  if (type.dds_name.empty()) return InvalidArgumentError(context + ": empty DDS type name");
  ddsi_sertype* sertype = internal::NewRawSertype(type.dds_name);
  // The topic's QoS only pins XCDR1: every topic of one name in a participant must agree on it.
  internal::QosPtr qos(dds_create_qos());
  dds_data_representation_id_t xcdr1[1] = {DDS_DATA_REPRESENTATION_XCDR1};
  dds_qset_data_representation(qos.get(), 1, xcdr1);
  const dds_entity_t topic = dds_create_topic_sertype(core.participant, dds_topic.c_str(), &sertype,
                                                      qos.get(), nullptr, nullptr);
  if (topic < 0) {
    internal::FreeRawSertype(sertype);
    if (topic == DDS_RETCODE_PRECONDITION_NOT_MET) {
      return FailedPreconditionError(fmt::format(
          "{}: the topic exists in this node with another type (dds_create_topic_sertype: {})",
          context, dds_strretcode(topic)));
    }
    return internal::DdsError("dds_create_topic_sertype", topic, context);
  }
  return TopicEntities{topic, sertype};
}

std::array<uint8_t, 16> GuidOf(dds_entity_t entity) {
  dds_guid_t guid{};
  dds_get_guid(entity, &guid);
  std::array<uint8_t, 16> out{};
  std::copy(std::begin(guid.v), std::end(guid.v), out.begin());
  return out;
}

}  // namespace

Result<std::unique_ptr<RawPublisher>> Node::CreateRawPublisher(std::string_view topic,
                                                               const TypeInfo& type,
                                                               const QosProfile& qos) {
  AVP_ASSIGN_OR_RETURN(std::string fq, ExpandTopicName(topic, core_->name, core_->namespace_));
  const std::string context =
      fmt::format("publisher on {} ({}) of node {}", fq, type.ros_name, core_->fq_name);
  AVP_RETURN_IF_ERROR(qos.Validate().WithContext(context));
  {
    std::lock_guard lock(core_->mutex);
    if (core_->closed) return FailedPreconditionError(context + ": the node is closed");
  }
  AVP_ASSIGN_OR_RETURN(TopicEntities t,
                       CreateTopic(*core_, fmt::format("rt{}", fq), type, context));
  internal::QosPtr wqos(internal::MakeQos(qos, /*writer=*/true, type.type_hash));
  const dds_entity_t writer = dds_create_writer(core_->participant, t.topic, wqos.get(), nullptr);
  if (writer < 0) {
    dds_delete(t.topic);
    return internal::DdsError("dds_create_writer", writer, context);
  }
  {
    std::lock_guard lock(core_->sertype_mutex);
    core_->writer_sertypes[writer] = t.sertype;
  }
  {
    std::lock_guard lock(core_->mutex);
    core_->writer_guids[writer] = GuidOf(writer);
  }
  core_->PublishDiscoveryInfo();
  return std::unique_ptr<RawPublisher>(new RawPublisher(core_, writer, t.topic, fq, type));
}

Result<std::unique_ptr<RawSubscription>> Node::CreateRawSubscription(std::string_view topic,
                                                                     const TypeInfo& type,
                                                                     const QosProfile& qos,
                                                                     RawCallback callback) {
  AVP_ASSIGN_OR_RETURN(std::string fq, ExpandTopicName(topic, core_->name, core_->namespace_));
  const std::string context =
      fmt::format("subscription on {} ({}) of node {}", fq, type.ros_name, core_->fq_name);
  AVP_RETURN_IF_ERROR(qos.Validate().WithContext(context));
  if (!callback) return InvalidArgumentError(context + ": the callback is empty");
  {
    std::lock_guard lock(core_->mutex);
    if (core_->closed) return FailedPreconditionError(context + ": the node is closed");
  }
  AVP_ASSIGN_OR_RETURN(TopicEntities t,
                       CreateTopic(*core_, fmt::format("rt{}", fq), type, context));
  internal::QosPtr rqos(internal::MakeQos(qos, /*writer=*/false, type.type_hash));
  const dds_entity_t reader = dds_create_reader(core_->participant, t.topic, rqos.get(), nullptr);
  if (reader < 0) {
    dds_delete(t.topic);
    return internal::DdsError("dds_create_reader", reader, context);
  }
  auto state = std::make_shared<SubscriptionState>();
  state->reader = reader;
  state->topic = t.topic;
  state->topic_name = fq;
  state->description = fmt::format("{} ({})", fq, type.ros_name);
  state->callback = std::move(callback);

  const dds_entity_t condition = dds_create_readcondition(reader, DDS_ANY_STATE);
  dds_return_t rc = condition < 0 ? condition
                                  : dds_waitset_attach(core_->waitset, condition,
                                                       static_cast<dds_attach_t>(reader));
  if (rc < 0) {
    dds_delete(reader);
    dds_delete(t.topic);
    return internal::DdsError("dds_create_readcondition / dds_waitset_attach", rc, context);
  }
  {
    std::lock_guard lock(core_->mutex);
    core_->subscriptions[reader] = state;
    core_->reader_guids[reader] = GuidOf(reader);
  }
  // Samples that arrived before the reader was in the map: wake the thread to look again.
  dds_set_guardcondition(core_->guard, true);
  core_->PublishDiscoveryInfo();
  return std::unique_ptr<RawSubscription>(new RawSubscription(core_, state, fq, type));
}

// ---- RawPublisher
// ----------------------------------------------------------------------------------
RawPublisher::RawPublisher(std::shared_ptr<NodeCore> core, int32_t writer, int32_t dds_topic,
                           std::string topic, TypeInfo type)
    : core_(std::move(core)),
      writer_(writer),
      dds_topic_(dds_topic),
      topic_(std::move(topic)),
      type_(std::move(type)) {}

RawPublisher::~RawPublisher() {
  {
    std::lock_guard lock(core_->sertype_mutex);
    core_->writer_sertypes.erase(writer_);
  }
  bool closed = false;
  {
    std::lock_guard lock(core_->mutex);
    closed = core_->closed;
    core_->writer_guids.erase(writer_);
  }
  if (closed) return;  // the participant and everything in it are gone
  dds_delete(writer_);
  dds_delete(dds_topic_);
  core_->PublishDiscoveryInfo();
}

Status RawPublisher::Publish(std::span<const uint8_t> cdr) {
  const ddsi_sertype* sertype = nullptr;
  if (core_->WriterSertype(writer_, &sertype) != DDS_RETCODE_OK) {
    return FailedPreconditionError(fmt::format("publishing on {}: the node is closed", topic_));
  }
  ddsi_serdata* sd = internal::NewRawSerdata(sertype, cdr);
  if (sd == nullptr) {
    return InternalError(
        fmt::format("publishing on {}: out of memory for {} bytes", topic_, cdr.size()));
  }
  sd->timestamp.v = dds_time();
  const dds_return_t rc = dds_writecdr(writer_, sd);  // takes the reference
  if (rc != DDS_RETCODE_OK) {
    return internal::DdsError("dds_writecdr", rc, fmt::format("{} ({})", topic_, type_.ros_name));
  }
  return Status::Ok();
}

std::array<uint8_t, 16> RawPublisher::guid() const { return GuidOf(writer_); }

size_t RawPublisher::matched_subscriptions() const {
  dds_publication_matched_status_t status{};
  if (dds_get_publication_matched_status(writer_, &status) != DDS_RETCODE_OK) return 0;
  return status.current_count;
}

// ---- RawSubscription
// -------------------------------------------------------------------------------
RawSubscription::RawSubscription(std::shared_ptr<NodeCore> core,
                                 std::shared_ptr<SubscriptionState> state, std::string topic,
                                 TypeInfo type)
    : core_(std::move(core)),
      state_(std::move(state)),
      topic_(std::move(topic)),
      type_(std::move(type)) {}

RawSubscription::~RawSubscription() {
  // Waits for a running callback (unless this is its thread), then no callback starts again.
  std::lock_guard dispatch(core_->dispatch_mutex);
  state_->removed = true;
  bool closed = false;
  {
    std::lock_guard lock(core_->mutex);
    closed = core_->closed;
    core_->subscriptions.erase(state_->reader);
    core_->reader_guids.erase(state_->reader);
  }
  if (closed) return;
  dds_delete(state_->reader);  // its read condition, attached to the waitset, goes with it
  dds_delete(state_->topic);
  core_->PublishDiscoveryInfo();
}

std::array<uint8_t, 16> RawSubscription::guid() const { return GuidOf(state_->reader); }

size_t RawSubscription::matched_publishers() const {
  dds_subscription_matched_status_t status{};
  if (dds_get_subscription_matched_status(state_->reader, &status) != DDS_RETCODE_OK) return 0;
  return status.current_count;
}
uint64_t RawSubscription::received() const { return state_->received.load(); }
uint64_t RawSubscription::malformed() const { return state_->malformed.load(); }
Status RawSubscription::last_error() const {
  std::lock_guard lock(state_->error_mutex);
  return state_->last_error;
}

}  // namespace avp::ros::dds

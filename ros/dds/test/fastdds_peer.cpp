// avp_ros2_fastdds_peer: the other vendor for ros2_fastdds_interop. A Fast DDS 2.9 participant
// (the default RMW of Humble and Jazzy) on 127.0.0.1 only, with rmw_fastrtps's conventions: XCDR1
// only, keyless, raw bytes (a TopicDataType that copies the serialised payload, encapsulation
// header included, so no fastddsgen). For each endpoint given it reads rt/<in>, prints
//   recv <in> <bytes> <first 4 bytes in hex>
// on stdout, and writes the same bytes to rt/<out>; "matched <topic> <count>" when one of its
// readers or writers matches or unmatches.
//   avp_ros2_fastdds_peer <domain> <seconds> <dds type>,<in>,<out>,<qos> ...
// <qos>: default (reliable, volatile, keep-last 10), sensor (best effort, volatile, keep-last 5),
// latched (reliable, transient local, keep-last 1). Exits after <seconds> (the test kills it
// earlier).

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

namespace {

namespace fdds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;

struct RawSample {
  std::vector<uint8_t> bytes;
};

class RawType : public fdds::TopicDataType {
 public:
  explicit RawType(const std::string& name) {
    setName(name.c_str());
    m_typeSize = 8u << 20;  // the largest payload this peer handles
    m_isGetKeyDefined = false;
  }
  bool serialize(void* data, rtps::SerializedPayload_t* payload) override {
    const auto* s = static_cast<RawSample*>(data);
    if (s->bytes.size() > payload->max_size || s->bytes.size() < 4) return false;
    std::memcpy(payload->data, s->bytes.data(), s->bytes.size());
    payload->length = static_cast<uint32_t>(s->bytes.size());
    payload->encapsulation = s->bytes[1] == 1 ? CDR_LE : CDR_BE;
    return true;
  }
  bool deserialize(rtps::SerializedPayload_t* payload, void* data) override {
    auto* s = static_cast<RawSample*>(data);
    s->bytes.assign(payload->data, payload->data + payload->length);
    return true;
  }
  std::function<uint32_t()> getSerializedSizeProvider(void* data) override {
    const auto size = static_cast<uint32_t>(static_cast<RawSample*>(data)->bytes.size());
    return [size] { return size; };
  }
  void* createData() override { return new RawSample(); }
  void deleteData(void* data) override { delete static_cast<RawSample*>(data); }
  bool getKey(void*, rtps::InstanceHandle_t*, bool) override { return false; }
};

std::mutex print_mutex;

void PrintLine(const std::string& line) {
  std::lock_guard lock(print_mutex);
  std::printf("%s\n", line.c_str());
  std::fflush(stdout);
}

// Reports "matched <topic> <count>" so that the test publishes only once Fast DDS, too, has
// matched (discovery is not symmetric in time: avp may see the match first).
class WriterMatch : public fdds::DataWriterListener {
 public:
  explicit WriterMatch(std::string topic) : topic_(std::move(topic)) {}
  void on_publication_matched(fdds::DataWriter*,
                              const fdds::PublicationMatchedStatus& status) override {
    PrintLine("matched " + topic_ + " " + std::to_string(status.current_count));
  }

 private:
  std::string topic_;
};

class Echo : public fdds::DataReaderListener {
 public:
  explicit Echo(std::string in) : in_(std::move(in)) {}
  void set_writer(fdds::DataWriter* writer) { writer_ = writer; }
  void on_subscription_matched(fdds::DataReader*,
                               const fdds::SubscriptionMatchedStatus& status) override {
    PrintLine("matched " + in_ + " " + std::to_string(status.current_count));
  }
  void on_data_available(fdds::DataReader* reader) override {
    RawSample sample;
    fdds::SampleInfo info;
    while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      char header[16] = "";
      if (sample.bytes.size() >= 4) {
        std::snprintf(header, sizeof(header), "%02x%02x%02x%02x", sample.bytes[0], sample.bytes[1],
                      sample.bytes[2], sample.bytes[3]);
      }
      PrintLine("recv " + in_ + " " + std::to_string(sample.bytes.size()) + " " + header);
      if (!writer_->write(&sample)) {
        std::fprintf(stderr, "fastdds peer: echoing %zu bytes from %s failed\n",
                     sample.bytes.size(), in_.c_str());
      }
    }
  }

 private:
  std::string in_;
  fdds::DataWriter* writer_ = nullptr;
};

template <class Qos>
void ApplyProfile(Qos& qos, const std::string& profile) {
  qos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
  qos.reliability().kind =
      profile == "sensor" ? fdds::BEST_EFFORT_RELIABILITY_QOS : fdds::RELIABLE_RELIABILITY_QOS;
  qos.durability().kind =
      profile == "latched" ? fdds::TRANSIENT_LOCAL_DURABILITY_QOS : fdds::VOLATILE_DURABILITY_QOS;
  qos.history().depth = profile == "latched" ? 1 : profile == "sensor" ? 5 : 10;
  qos.endpoint().history_memory_policy = rtps::DYNAMIC_REUSABLE_MEMORY_MODE;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: %s DOMAIN SECONDS TYPE,IN,OUT,QOS...\n", argv[0]);
    return 2;
  }
  const int domain = std::atoi(argv[1]);
  const int seconds = std::atoi(argv[2]);

  fdds::DomainParticipantQos pqos;
  pqos.name("avp_fastdds_peer");
  // 127.0.0.1 only; unicast discovery towards the avp participants on the same host.
  pqos.transport().use_builtin_transports = false;
  auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
  udp->interfaceWhiteList.push_back("127.0.0.1");
  pqos.transport().user_transports.push_back(udp);
  rtps::Locator_t peer;
  rtps::IPLocator::setIPv4(peer, 127, 0, 0, 1);
  pqos.wire_protocol().builtin.initialPeersList.push_back(peer);
  const std::string enclave = "enclave=/;";
  pqos.user_data().data_vec(std::vector<rtps::octet>(enclave.begin(), enclave.end()));

  auto* factory = fdds::DomainParticipantFactory::get_instance();
  fdds::DomainParticipant* participant = factory->create_participant(domain, pqos);
  if (participant == nullptr) {
    std::fprintf(stderr, "fastdds peer: create_participant failed\n");
    return 1;
  }
  fdds::Publisher* publisher = participant->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  fdds::Subscriber* subscriber = participant->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  std::map<std::string, fdds::TypeSupport> types;
  std::vector<std::unique_ptr<Echo>> listeners;
  std::vector<std::unique_ptr<WriterMatch>> writer_listeners;
  for (int i = 3; i < argc; ++i) {
    std::vector<std::string> parts;
    std::string arg = argv[i];
    size_t start = 0;
    for (size_t pos; (pos = arg.find(',', start)) != std::string::npos; start = pos + 1) {
      parts.push_back(arg.substr(start, pos - start));
    }
    parts.push_back(arg.substr(start));
    if (parts.size() != 4) {
      std::fprintf(stderr, "fastdds peer: bad endpoint '%s'\n", argv[i]);
      return 2;
    }
    const std::string& type_name = parts[0];
    if (types.count(type_name) == 0) {
      fdds::TypeSupport type(new RawType(type_name));
      type.register_type(participant);
      types.emplace(type_name, type);
    }
    fdds::Topic* in =
        participant->create_topic("rt" + parts[1], type_name, fdds::TOPIC_QOS_DEFAULT);
    fdds::Topic* out =
        participant->create_topic("rt" + parts[2], type_name, fdds::TOPIC_QOS_DEFAULT);
    if (in == nullptr || out == nullptr) {
      std::fprintf(stderr, "fastdds peer: create_topic failed for '%s'\n", argv[i]);
      return 1;
    }
    fdds::DataWriterQos wqos = publisher->get_default_datawriter_qos();
    ApplyProfile(wqos, parts[3]);
    wqos.representation().m_value.clear();
    wqos.representation().m_value.push_back(fdds::XCDR_DATA_REPRESENTATION);
    writer_listeners.push_back(std::make_unique<WriterMatch>(parts[2]));
    fdds::DataWriter* writer =
        publisher->create_datawriter(out, wqos, writer_listeners.back().get());
    fdds::DataReaderQos rqos = subscriber->get_default_datareader_qos();
    ApplyProfile(rqos, parts[3]);
    rqos.type_consistency().representation.m_value.clear();
    rqos.type_consistency().representation.m_value.push_back(fdds::XCDR_DATA_REPRESENTATION);
    listeners.push_back(std::make_unique<Echo>(parts[1]));
    listeners.back()->set_writer(writer);
    fdds::DataReader* reader = subscriber->create_datareader(in, rqos, listeners.back().get());
    if (writer == nullptr || reader == nullptr) {
      std::fprintf(stderr, "fastdds peer: endpoint creation failed for '%s'\n", argv[i]);
      return 1;
    }
  }
  std::printf("ready\n");
  std::fflush(stdout);
  std::this_thread::sleep_for(std::chrono::seconds(seconds));
  participant->delete_contained_entities();
  factory->delete_participant(participant);
  return 0;
}

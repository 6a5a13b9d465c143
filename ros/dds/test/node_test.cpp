#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>
#include <thread>
#include <vector>

#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/ros/dds/node.h>
#include <avp/ros/msg/messages.h>

#include "raw_sertype.h"
#include "ros2_test_support.h"

namespace avp::ros::dds {
namespace {

using namespace std::chrono_literals;
using ::testing::HasSubstr;
using testing::LoopbackNode;
using testing::TestDomainId;
using testing::WaitFor;

ros::msg::PoseStamped Pose(double x) {
  ros::msg::PoseStamped p;
  p.header.frame_id = "world";
  p.header.stamp = {12, 34};
  p.pose.position.x = x;
  p.pose.orientation.w = 1;
  return p;
}

TEST(Node, CreateNamesAndDomain) {
  const int domain = TestDomainId();
  NodeOptions options = LoopbackNode("avp_live", domain);
  options.namespace_ = "robot1";
  auto node = Node::Create(options);
  ASSERT_TRUE(node.ok()) << node.status().ToString();
  EXPECT_EQ((*node)->domain_id(), domain);
  EXPECT_EQ((*node)->name(), "avp_live");
  EXPECT_EQ((*node)->namespace_(), "/robot1");
  EXPECT_EQ((*node)->fully_qualified_name(), "/robot1/avp_live");
  auto pub = (*node)->CreatePublisher<ros::msg::PoseStamped>("next_view", QosProfile::Default());
  ASSERT_TRUE(pub.ok());
  EXPECT_EQ((*pub)->topic(), "/robot1/next_view");

  options.name = "bad-name";
  EXPECT_THAT(Node::Create(options).status().message(), HasSubstr("'bad-name'"));
  options.name = "ok";
  options.domain_id = 500;
  EXPECT_THAT(Node::Create(options).status().message(), HasSubstr("(500)"));
}

TEST(Node, BadTopicNamesAreRefused) {
  auto node = Node::Create(LoopbackNode("avp", TestDomainId())).value();
  const auto pub = node->CreatePublisher<ros::msg::Image>("camera//image", QosProfile::Default());
  ASSERT_FALSE(pub.ok());
  EXPECT_THAT(pub.status().message(), HasSubstr("'camera//image'"));
  const auto sub = node->CreateSubscription<ros::msg::Image>(
      "9lives", QosProfile::SensorData(), [](ros::msg::Image&&, const SampleInfo&) {});
  ASSERT_FALSE(sub.ok());
  EXPECT_THAT(sub.status().message(), HasSubstr("'9lives'"));
  QosProfile bad = QosProfile::Default();
  bad.depth = 0;
  EXPECT_THAT(node->CreatePublisher<ros::msg::Image>("x", bad).status().message(),
              HasSubstr("depth (0)"));
}

TEST(Node, QosProfilesMatchRclcpp) {
  EXPECT_EQ(QosProfile::Default().depth, 10);
  EXPECT_EQ(QosProfile::SensorData().reliability, Reliability::kBestEffort);
  EXPECT_EQ(QosProfile::SensorData().depth, 5);
  EXPECT_EQ(QosProfile::TfStatic().durability, Durability::kTransientLocal);
  EXPECT_EQ(QosProfile::TfStatic().depth, 1);
  EXPECT_EQ(QosProfile::Tf().depth, 100);
  EXPECT_EQ(QosProfile::Latched(3).depth, 3);
  EXPECT_EQ(QosProfile::Latched().reliability, Reliability::kReliable);
}

TEST(Node, BestEffortWriterDoesNotMatchReliableReader) {
  const int domain = TestDomainId();
  auto a = Node::Create(LoopbackNode("a", domain)).value();
  auto b = Node::Create(LoopbackNode("b", domain)).value();
  auto pub = a->CreatePublisher<ros::msg::PoseStamped>("/pose", QosProfile::SensorData()).value();
  std::atomic<int> best_effort_got{0}, reliable_got{0};
  auto be_sub = b->CreateSubscription<ros::msg::PoseStamped>(
                     "/pose", QosProfile::SensorData(),
                     [&](ros::msg::PoseStamped&&, const SampleInfo&) { ++best_effort_got; })
                    .value();
  auto rel_sub = b->CreateSubscription<ros::msg::PoseStamped>(
                      "/pose", QosProfile::Default(),
                      [&](ros::msg::PoseStamped&&, const SampleInfo&) { ++reliable_got; })
                     .value();
  // The best-effort reader matching proves discovery has happened.
  ASSERT_TRUE(WaitFor([&] { return be_sub->matched_publishers() == 1; }))
      << "best-effort reader never matched";
  ASSERT_TRUE(pub->Publish(Pose(1)).ok());
  ASSERT_TRUE(WaitFor([&] { return best_effort_got.load() >= 1; })) << "no sample";
  EXPECT_EQ(rel_sub->matched_publishers(), 0u);
  EXPECT_EQ(pub->matched_subscriptions(), 1u);
  EXPECT_EQ(reliable_got.load(), 0);
}

TEST(Node, TransientLocalLateJoinerGetsTheLatchedSample) {
  const int domain = TestDomainId();
  auto a = Node::Create(LoopbackNode("a", domain)).value();
  auto pub = a->CreatePublisher<ros::msg::TFMessage>("/tf_static", QosProfile::TfStatic()).value();
  ros::msg::TFMessage tf;
  tf.transforms.resize(1);
  tf.transforms[0].header.frame_id = "igus_rebel_base_link";
  tf.transforms[0].child_frame_id = "camera_color_optical_frame";
  tf.transforms[0].transform.rotation.w = 1;
  ASSERT_TRUE(pub->Publish(tf).ok());
  std::this_thread::sleep_for(100ms);

  auto b = Node::Create(LoopbackNode("b", domain)).value();
  std::mutex mutex;
  std::vector<ros::msg::TFMessage> got;
  auto sub = b->CreateSubscription<ros::msg::TFMessage>(
                  "/tf_static", QosProfile::TfStatic(),
                  [&](ros::msg::TFMessage&& m, const SampleInfo& info) {
                    EXPECT_GT(info.source_timestamp_ns, 0);
                    EXPECT_GT(info.received_ns, 0);
                    std::lock_guard lock(mutex);
                    got.push_back(std::move(m));
                  })
                 .value();
  ASSERT_TRUE(WaitFor([&] {
    std::lock_guard lock(mutex);
    return !got.empty();
  })) << "the late joiner never got the latched TFMessage";
  std::lock_guard lock(mutex);
  EXPECT_EQ(got[0], tf);
}

TEST(Node, DomainsAreIsolated) {
  const int domain = TestDomainId();
  const int other = TestDomainId(1);  // claimed too: no other test uses it meanwhile
  ASSERT_NE(other, domain);
  auto a = Node::Create(LoopbackNode("a", domain)).value();
  auto b = Node::Create(LoopbackNode("b", domain)).value();
  auto c = Node::Create(LoopbackNode("c", other)).value();
  EXPECT_EQ(c->domain_id(), other);
  auto pub = a->CreatePublisher<ros::msg::PoseStamped>("/pose", QosProfile::Default()).value();
  std::atomic<int> b_got{0}, c_got{0};
  auto sb = b->CreateSubscription<ros::msg::PoseStamped>(
                 "/pose", QosProfile::Default(),
                 [&](ros::msg::PoseStamped&&, const SampleInfo&) { ++b_got; })
                .value();
  auto sc = c->CreateSubscription<ros::msg::PoseStamped>(
                 "/pose", QosProfile::Default(),
                 [&](ros::msg::PoseStamped&&, const SampleInfo&) { ++c_got; })
                .value();
  ASSERT_TRUE(WaitFor([&] { return sb->matched_publishers() == 1; }));
  ASSERT_TRUE(pub->Publish(Pose(2)).ok());
  ASSERT_TRUE(WaitFor([&] { return b_got.load() == 1; }));
  std::this_thread::sleep_for(200ms);
  EXPECT_EQ(sc->matched_publishers(), 0u);
  EXPECT_EQ(c_got.load(), 0);
  EXPECT_EQ(pub->matched_subscriptions(), 1u);
}

TEST(Node, MalformedSampleIsCountedAndTheNextGoodOneDelivered) {
  const int domain = TestDomainId();
  auto a = Node::Create(LoopbackNode("a", domain)).value();
  auto b = Node::Create(LoopbackNode("b", domain)).value();
  auto raw =
      a->CreateRawPublisher("/pose", TypeInfo::Of<ros::msg::PoseStamped>(), QosProfile::Default())
          .value();
  std::atomic<int> good{0};
  auto sub = b->CreateSubscription<ros::msg::PoseStamped>(
                  "/pose", QosProfile::Default(),
                  [&](ros::msg::PoseStamped&& p, const SampleInfo&) {
                    EXPECT_EQ(p, Pose(3));
                    ++good;
                  })
                 .value();
  ASSERT_TRUE(WaitFor([&] { return sub->matched_publishers() == 1; }));
  // A header and a frame_id length far past the end of the sample.
  const std::vector<uint8_t> bad = {0x00, 0x01, 0x00, 0x00, 1,    0,    0, 0,
                                    2,    0,    0,    0,    0xff, 0xff, 0, 0};
  ASSERT_TRUE(raw->Publish(bad).ok());
  ASSERT_TRUE(WaitFor([&] { return sub->malformed() == 1; })) << "malformed sample not counted";
  EXPECT_EQ(good.load(), 0);
  const Status error = sub->last_error();
  EXPECT_THAT(error.message(), HasSubstr("/pose"));
  EXPECT_THAT(error.message(), HasSubstr("geometry_msgs/msg/PoseStamped"));
  EXPECT_THAT(error.message(), HasSubstr("malformed"));
  ASSERT_TRUE(raw->Publish(ros::msg::Encode(Pose(3))).ok());
  ASSERT_TRUE(WaitFor([&] { return good.load() == 1; })) << "good sample after a bad one lost";
  EXPECT_EQ(sub->received(), 2u);
  EXPECT_EQ(sub->malformed(), 1u);
}

TEST(Node, DestroyedSubscriptionIsNeverCalledAgain) {
  const int domain = TestDomainId();
  auto a = Node::Create(LoopbackNode("a", domain)).value();
  auto b = Node::Create(LoopbackNode("b", domain)).value();
  auto pub = a->CreatePublisher<ros::msg::PoseStamped>("/pose", QosProfile::Default()).value();
  std::atomic<int> calls{0};
  std::atomic<bool> in_callback{false};
  auto sub =
      b->CreateSubscription<ros::msg::PoseStamped>("/pose", QosProfile::Default(),
                                                   [&](ros::msg::PoseStamped&&, const SampleInfo&) {
                                                     in_callback = true;
                                                     std::this_thread::sleep_for(200ms);
                                                     ++calls;
                                                     in_callback = false;
                                                   })
          .value();
  ASSERT_TRUE(WaitFor([&] { return sub->matched_publishers() == 1; }));
  ASSERT_TRUE(pub->Publish(Pose(1)).ok());
  ASSERT_TRUE(WaitFor([&] { return in_callback.load(); }));
  sub.reset();  // waits for the running callback
  EXPECT_FALSE(in_callback.load());
  const int after = calls.load();
  EXPECT_EQ(after, 1);
  ASSERT_TRUE(pub->Publish(Pose(2)).ok());
  std::this_thread::sleep_for(200ms);
  EXPECT_EQ(calls.load(), after);
}

TEST(Node, SubscriptionMayDestroyItselfInItsCallback) {
  const int domain = TestDomainId();
  auto node = Node::Create(LoopbackNode("a", domain)).value();
  auto pub = node->CreatePublisher<ros::msg::PoseStamped>("/pose", QosProfile::Default()).value();
  std::unique_ptr<Subscription<ros::msg::PoseStamped>> sub;
  std::atomic<int> calls{0};
  std::mutex mutex;
  {
    std::lock_guard lock(mutex);
    sub = node->CreateSubscription<ros::msg::PoseStamped>(
                  "/pose", QosProfile::Default(),
                  [&](ros::msg::PoseStamped&&, const SampleInfo&) {
                    ++calls;
                    std::lock_guard inner(mutex);
                    sub.reset();
                  })
              .value();
  }
  ASSERT_TRUE(WaitFor([&] { return pub->matched_subscriptions() == 1; }));
  ASSERT_TRUE(pub->Publish(Pose(1)).ok());
  ASSERT_TRUE(pub->Publish(Pose(2)).ok());
  ASSERT_TRUE(WaitFor([&] { return calls.load() >= 1; }));
  std::this_thread::sleep_for(200ms);
  EXPECT_EQ(calls.load(), 1);
  std::lock_guard lock(mutex);
  EXPECT_EQ(sub, nullptr);
}

// Reads ros_discovery_info as a ROS 2 peer does (raw, transient local) and decodes it.
class DiscoveryReader {
 public:
  explicit DiscoveryReader(int domain) {
    participant_ = dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr);
    ddsi_sertype* st =
        internal::NewRawSertype("rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_");
    dds_qos_t* qos = dds_create_qos();
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_durability(qos, DDS_DURABILITY_TRANSIENT_LOCAL);
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
    dds_data_representation_id_t xcdr1[1] = {DDS_DATA_REPRESENTATION_XCDR1};
    dds_qset_data_representation(qos, 1, xcdr1);
    topic_ =
        dds_create_topic_sertype(participant_, "ros_discovery_info", &st, qos, nullptr, nullptr);
    reader_ = dds_create_reader(participant_, topic_, qos, nullptr);
    dds_delete_qos(qos);
  }
  ~DiscoveryReader() { dds_delete(participant_); }
  bool ok() const { return participant_ > 0 && topic_ > 0 && reader_ > 0; }

  /// The latest sample of each participant, decoded for `distro`.
  std::vector<ros::msg::ParticipantEntitiesInfo> Take(ros::msg::RosDistro distro,
                                                      std::vector<size_t>* sizes = nullptr) {
    ddsi_serdata* samples[16];
    dds_sample_info_t infos[16];
    std::vector<ros::msg::ParticipantEntitiesInfo> out;
    const int n = dds_takecdr(reader_, samples, 16, infos, DDS_ANY_STATE);
    for (int i = 0; i < n; ++i) {
      if (infos[i].valid_data) {
        const auto bytes = internal::RawSerdataBytes(samples[i]);
        if (sizes != nullptr) sizes->push_back(bytes.size());
        auto info = ros::msg::Decode<ros::msg::ParticipantEntitiesInfo>(bytes, distro);
        EXPECT_TRUE(info.ok()) << info.status().ToString();
        if (info.ok()) out.push_back(std::move(info).value());
      }
      ddsi_serdata_unref(samples[i]);
    }
    return out;
  }

 private:
  dds_entity_t participant_ = 0, topic_ = 0, reader_ = 0;
};

ros::msg::Gid Gid(const std::array<uint8_t, 16>& guid) {
  ros::msg::Gid gid;
  std::copy(guid.begin(), guid.end(), gid.data.begin());
  return gid;
}

class DiscoveryInfoTest : public ::testing::TestWithParam<ros::msg::RosDistro> {};

TEST_P(DiscoveryInfoTest, AnnouncesTheNodeAndItsEndpoints) {
  const ros::msg::RosDistro distro = GetParam();
  const int domain = TestDomainId();
  NodeOptions options = LoopbackNode("avp_live", domain, distro);
  options.namespace_ = "/robot1";
  auto node = Node::Create(options).value();
  auto pub =
      node->CreatePublisher<ros::msg::PoseStamped>("next_view", QosProfile::Default()).value();
  auto sub = node->CreateSubscription<ros::msg::JointState>(
                     "/joint_states", QosProfile::Default(),
                     [](ros::msg::JointState&&, const SampleInfo&) {})
                 .value();
  DiscoveryReader reader(domain);
  ASSERT_TRUE(reader.ok());
  const ros::msg::Gid participant = Gid(node->participant_guid());
  const ros::msg::Gid writer = Gid(pub->raw().guid());
  const ros::msg::Gid reader_gid = Gid(sub->raw().guid());
  std::vector<size_t> sizes;
  ros::msg::ParticipantEntitiesInfo info;
  ASSERT_TRUE(WaitFor([&] {
    for (auto& i : reader.Take(distro, &sizes)) {
      if (i.gid == participant) info = i;
    }
    return info.gid == participant && info.node_entities_info_seq.size() == 1 &&
           info.node_entities_info_seq[0].writer_gid_seq.size() == 1 &&
           info.node_entities_info_seq[0].reader_gid_seq.size() == 1;
  })) << "no ros_discovery_info sample with the publisher and the subscription";
  const auto& n = info.node_entities_info_seq[0];
  EXPECT_EQ(n.node_name, "avp_live");
  EXPECT_EQ(n.node_namespace, "/robot1");
  EXPECT_EQ(n.writer_gid_seq[0], writer);
  EXPECT_EQ(n.reader_gid_seq[0], reader_gid);
  // The GID size on the wire: 24 bytes (Humble) or 16 (Jazzy); three GIDs in this sample.
  ASSERT_FALSE(sizes.empty());
  EXPECT_EQ(sizes.back(), ros::msg::Encode(info, distro).size());
  EXPECT_EQ(ros::msg::Encode(info, ros::msg::RosDistro::kHumble).size(),
            ros::msg::Encode(info, ros::msg::RosDistro::kJazzy).size() + 3 * 8);
  if (distro == ros::msg::RosDistro::kJazzy) {
    EXPECT_EQ(info.gid, participant);  // the last 8 bytes read back as 0
  }

  // Endpoints that go away are withdrawn.
  pub.reset();
  ASSERT_TRUE(WaitFor([&] {
    for (auto& i : reader.Take(distro)) {
      if (i.gid == participant) info = i;
    }
    return info.node_entities_info_seq.size() == 1 &&
           info.node_entities_info_seq[0].writer_gid_seq.empty();
  })) << "ros_discovery_info not republished after the publisher went away";
}

INSTANTIATE_TEST_SUITE_P(Distros, DiscoveryInfoTest,
                         ::testing::Values(ros::msg::RosDistro::kHumble,
                                           ros::msg::RosDistro::kJazzy),
                         [](const auto& param_info) {
                           return param_info.param == ros::msg::RosDistro::kHumble ? "Humble"
                                                                                   : "Jazzy";
                         });

}  // namespace
}  // namespace avp::ros::dds

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include <dds/dds.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <avp/ros/dds/node.h>
#include <avp/ros/msg/messages.h>

#include "reference_messages.h"
#include "ros2_test_support.h"

extern "C" {
#include "sensor_msgs.h"
#include "tf2_msgs.h"
}

namespace avp::ros::dds {
namespace {

using namespace std::chrono_literals;
using ros::msg::testing::References;
using testing::LoopbackNode;
using testing::TestDomainId;
using testing::WaitFor;

// The types avp reads and writes (issue 14).
using Types =
    ::testing::Types<ros::msg::Time, ros::msg::Header, ros::msg::Image, ros::msg::CameraInfo,
                     ros::msg::JointState, ros::msg::PointCloud2, ros::msg::PoseStamped,
                     ros::msg::TransformStamped, ros::msg::TFMessage, ros::msg::JointTrajectory,
                     ros::msg::MarkerArray, ros::msg::Octomap>;

template <class M>
class PubSubTest : public ::testing::Test {};
TYPED_TEST_SUITE(PubSubTest, Types);

// Messages compare by their encoding: NaN fields make operator== false for equal messages.
template <class M>
std::vector<std::vector<uint8_t>> Encoded(const std::vector<M>& messages) {
  std::vector<std::vector<uint8_t>> out;
  for (const M& m : messages) out.push_back(ros::msg::Encode(m));
  return out;
}

template <class M>
class Collector {
 public:
  std::function<void(M&&, const SampleInfo&)> Callback() {
    return [this](M&& m, const SampleInfo&) {
      std::lock_guard lock(mutex_);
      got_.push_back(ros::msg::Encode(m));
    };
  }
  size_t size() {
    std::lock_guard lock(mutex_);
    return got_.size();
  }
  std::vector<std::vector<uint8_t>> got() {
    std::lock_guard lock(mutex_);
    return got_;
  }

 private:
  std::mutex mutex_;
  std::vector<std::vector<uint8_t>> got_;
};

TYPED_TEST(PubSubTest, BetweenTwoNodesInOneProcess) {
  using M = TypeParam;
  const int domain = TestDomainId();
  auto a = Node::Create(LoopbackNode("talker", domain)).value();
  auto b = Node::Create(LoopbackNode("listener", domain)).value();
  auto pub = a->CreatePublisher<M>("/avp_test/msg", QosProfile::Default()).value();
  Collector<M> collector;
  auto sub =
      b->CreateSubscription<M>("avp_test/msg", QosProfile::Default(), collector.Callback()).value();
  ASSERT_TRUE(WaitFor([&] {
    return pub->matched_subscriptions() == 1 && sub->matched_publishers() == 1;
  })) << "no match";
  const std::vector<M> refs = References<M>();
  for (const M& m : refs) ASSERT_TRUE(pub->Publish(m).ok());
  ASSERT_TRUE(WaitFor([&] { return collector.size() == refs.size(); }))
      << "got " << collector.size() << " of " << refs.size();
  EXPECT_EQ(collector.got(), Encoded(refs));
  EXPECT_EQ(sub->malformed(), 0u);
}

// Spawns avp_ros2_echo; kills it on destruction.
class EchoProcess {
 public:
  EchoProcess(int domain, const std::vector<std::string>& types) {
    std::vector<std::string> args = {AVP_ROS2_ECHO, std::to_string(domain), "20", "/avp_test/in",
                                     "/avp_test/out"};
    args.insert(args.end(), types.begin(), types.end());
    pid_ = fork();
    if (pid_ == 0) {
      std::vector<char*> argv;
      for (auto& s : args) argv.push_back(s.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
  }
  ~EchoProcess() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      int status = 0;
      waitpid(pid_, &status, 0);
    }
  }
  bool started() const { return pid_ > 0; }

 private:
  pid_t pid_ = -1;
};

template <class M>
struct EchoRound {
  std::unique_ptr<Publisher<M>> pub;
  std::unique_ptr<Subscription<M>> sub;
  Collector<M> collector;
};

template <class... Ms>
void RunEchoRounds(Node& node, std::tuple<EchoRound<Ms>...>& rounds) {
  size_t index = 0;
  auto create = [&](auto& round) {
    using M = typename std::decay_t<decltype(*round.pub)>::Message;
    round.pub =
        node.CreatePublisher<M>(fmt::format("/avp_test/in/t{}", index), QosProfile::Latched(10))
            .value();
    round.sub = node.CreateSubscription<M>(fmt::format("/avp_test/out/t{}", index),
                                           QosProfile::Latched(10), round.collector.Callback())
                    .value();
    ++index;
  };
  std::apply([&](auto&... r) { (create(r), ...); }, rounds);
}

TEST(PubSub, BetweenTwoProcessesEveryType) {
  const int domain = TestDomainId();
  using Rounds = std::tuple<EchoRound<ros::msg::Time>, EchoRound<ros::msg::Header>,
                            EchoRound<ros::msg::Image>, EchoRound<ros::msg::CameraInfo>,
                            EchoRound<ros::msg::JointState>, EchoRound<ros::msg::PointCloud2>,
                            EchoRound<ros::msg::PoseStamped>, EchoRound<ros::msg::TransformStamped>,
                            EchoRound<ros::msg::TFMessage>, EchoRound<ros::msg::JointTrajectory>,
                            EchoRound<ros::msg::MarkerArray>, EchoRound<ros::msg::Octomap>>;
  Rounds rounds;
  std::vector<std::string> types;
  std::apply(
      [&](auto&... r) {
        ((types.push_back(std::string(
             ros::msg::MessageTraits<typename std::decay_t<decltype(*r.pub)>::Message>::kDdsName))),
         ...);
      },
      rounds);
  EchoProcess echo(domain, types);
  ASSERT_TRUE(echo.started());
  auto node = Node::Create(LoopbackNode("avp_test", domain)).value();
  RunEchoRounds(*node, rounds);
  auto all_matched = [&] {
    bool ok = true;
    std::apply(
        [&](auto&... r) {
          ((ok = ok && r.pub->matched_subscriptions() == 1 && r.sub->matched_publishers() == 1),
           ...);
        },
        rounds);
    return ok;
  };
  ASSERT_TRUE(WaitFor(all_matched, 10s)) << "the echo process never matched every topic";
  auto publish = [&](auto& r) {
    using M = typename std::decay_t<decltype(*r.pub)>::Message;
    for (const M& m : References<M>()) ASSERT_TRUE(r.pub->Publish(m).ok());
  };
  std::apply([&](auto&... r) { (publish(r), ...); }, rounds);
  auto check = [&](auto& r) {
    using M = typename std::decay_t<decltype(*r.pub)>::Message;
    const auto refs = References<M>();
    EXPECT_TRUE(WaitFor([&] { return r.collector.size() == refs.size(); }, 10s))
        << ros::msg::MessageTraits<M>::kRosName << ": got " << r.collector.size() << " of "
        << refs.size();
    EXPECT_EQ(r.collector.got(), Encoded(refs)) << ros::msg::MessageTraits<M>::kRosName;
  };
  std::apply([&](auto&... r) { (check(r), ...); }, rounds);
}

TEST(PubSub, ReceivedRawBytesAreXcdr1WithTheEncapsulationHeader) {
  const int domain = TestDomainId();
  auto a = Node::Create(LoopbackNode("a", domain)).value();
  auto b = Node::Create(LoopbackNode("b", domain)).value();
  auto pub = a->CreatePublisher<ros::msg::Image>("/camera/image", QosProfile::SensorData()).value();
  std::mutex mutex;
  std::vector<std::vector<uint8_t>> got;
  auto sub = b->CreateRawSubscription("/camera/image", TypeInfo::Of<ros::msg::Image>(),
                                      QosProfile::SensorData(),
                                      [&](std::span<const uint8_t> cdr, const SampleInfo&) {
                                        std::lock_guard lock(mutex);
                                        got.emplace_back(cdr.begin(), cdr.end());
                                        return Status::Ok();
                                      })
                 .value();
  ASSERT_TRUE(
      WaitFor([&] { return pub->matched_subscriptions() == 1 && sub->matched_publishers() == 1; }));
  const ros::msg::Image image = References<ros::msg::Image>()[1];
  ASSERT_TRUE(pub->Publish(image).ok());
  ASSERT_TRUE(WaitFor([&] {
    std::lock_guard lock(mutex);
    return !got.empty();
  }));
  std::lock_guard lock(mutex);
  ASSERT_GE(got[0].size(), 4u);
  EXPECT_EQ(got[0][0], 0x00);
  EXPECT_EQ(got[0][1], 0x01);
  EXPECT_EQ(got[0][2], 0x00);
  EXPECT_EQ(got[0][3], 0x00);
  const auto expected = ros::msg::Encode(image);
  ASSERT_GE(got[0].size(), expected.size());
  EXPECT_LE(got[0].size(), expected.size() + 3);  // RTPS pads to a multiple of 4
  EXPECT_TRUE(std::equal(expected.begin(), expected.end(), got[0].begin()));
}

/// avp's Image and TFMessage bytes as idlc-typed Cyclone readers deserialise them.
void ExpectTypedReadersDecodeAvp(Publisher<ros::msg::Image>& pub,
                                 Publisher<ros::msg::TFMessage>& tf_pub, dds_entity_t img_reader,
                                 dds_entity_t tf_reader) {
  const ros::msg::Image image = References<ros::msg::Image>()[1];
  ASSERT_TRUE(pub.Publish(image).ok());
  void* samples[1] = {nullptr};
  dds_sample_info_t infos[1];
  ASSERT_TRUE(WaitFor([&] { return dds_take(img_reader, samples, infos, 1, 1) == 1; }))
      << "the idlc-typed reader got nothing (or could not deserialise avp's bytes)";
  {
    const auto* im = static_cast<const sensor_msgs_msg_dds__Image_*>(samples[0]);
    EXPECT_EQ(im->header.stamp.sec, image.header.stamp.sec);
    EXPECT_EQ(im->header.stamp.nanosec, image.header.stamp.nanosec);
    EXPECT_EQ(std::string(im->header.frame_id), image.header.frame_id);
    EXPECT_EQ(im->height, image.height);
    EXPECT_EQ(im->width, image.width);
    EXPECT_EQ(std::string(im->encoding), image.encoding);
    EXPECT_EQ(im->is_bigendian, image.is_bigendian);
    EXPECT_EQ(im->step, image.step);
    ASSERT_EQ(im->data._length, image.data.size());
    EXPECT_TRUE(std::equal(image.data.begin(), image.data.end(), im->data._buffer));
    dds_return_loan(img_reader, samples, 1);
  }
  const ros::msg::TFMessage tf = References<ros::msg::TFMessage>().back();
  ASSERT_TRUE(tf_pub.Publish(tf).ok());
  samples[0] = nullptr;
  ASSERT_TRUE(WaitFor([&] { return dds_take(tf_reader, samples, infos, 1, 1) == 1; }));
  {
    const auto* m = static_cast<const tf2_msgs_msg_dds__TFMessage_*>(samples[0]);
    ASSERT_EQ(m->transforms._length, tf.transforms.size());
    for (size_t i = 0; i < tf.transforms.size(); ++i) {
      const auto& c = m->transforms._buffer[i];
      const auto& t = tf.transforms[i];
      EXPECT_EQ(std::string(c.header.frame_id), t.header.frame_id);
      EXPECT_EQ(std::string(c.child_frame_id), t.child_frame_id);
      EXPECT_EQ(c.transform.translation.x, t.transform.translation.x);
      EXPECT_EQ(c.transform.rotation.w, t.transform.rotation.w);
    }
    dds_return_loan(tf_reader, samples, 1);
  }
}

/// An idlc-typed writer's Image as avp decodes it.
void ExpectAvpDecodesTypedWriter(dds_entity_t typed_writer, std::mutex& mutex,
                                 const std::vector<ros::msg::Image>& avp_got) {
  sensor_msgs_msg_dds__Image_ c{};
  c.header.stamp.sec = 7;
  c.header.stamp.nanosec = 8;
  c.header.frame_id = const_cast<char*>("camera_color_optical_frame");
  c.height = 2;
  c.width = 3;
  c.encoding = const_cast<char*>("mono8");
  c.step = 3;
  uint8_t data[6] = {1, 2, 3, 4, 5, 6};
  c.data._buffer = data;
  c.data._length = 6;
  c.data._maximum = 6;
  ASSERT_EQ(dds_write(typed_writer, &c), DDS_RETCODE_OK);
  ASSERT_TRUE(WaitFor([&] {
    std::lock_guard lock(mutex);
    return !avp_got.empty();
  })) << "avp got nothing from the idlc-typed writer";
  {
    std::lock_guard lock(mutex);
    const ros::msg::Image& m = avp_got[0];
    EXPECT_EQ(m.header.stamp.sec, 7);
    EXPECT_EQ(m.header.frame_id, "camera_color_optical_frame");
    EXPECT_EQ(m.encoding, "mono8");
    EXPECT_EQ(m.step, 3u);
    EXPECT_EQ(m.data, (std::vector<uint8_t>{1, 2, 3, 4, 5, 6}));
  }
}

// An independent check of the layout: a Cyclone reader typed by idlc's descriptor (from
// ros2/idl/) deserialises avp's bytes itself, and an idlc-typed writer's bytes decode in avp.
TEST(PubSub, IdlTypedCycloneReaderAndWriterAgreeWithAvp) {
  const int domain = TestDomainId();
  auto node = Node::Create(LoopbackNode("avp", domain)).value();
  auto pub = node->CreatePublisher<ros::msg::Image>("/camera/image", QosProfile::Default()).value();
  auto tf_pub = node->CreatePublisher<ros::msg::TFMessage>("/tf", QosProfile::Tf()).value();
  std::mutex mutex;
  std::vector<ros::msg::Image> avp_got;
  auto sub = node->CreateSubscription<ros::msg::Image>("/camera/typed", QosProfile::Default(),
                                                       [&](ros::msg::Image&& m, const SampleInfo&) {
                                                         std::lock_guard lock(mutex);
                                                         avp_got.push_back(std::move(m));
                                                       })
                 .value();

  const dds_entity_t pp =
      dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr);
  ASSERT_GT(pp, 0);
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 10);
  dds_data_representation_id_t xcdr1[1] = {DDS_DATA_REPRESENTATION_XCDR1};
  dds_qset_data_representation(qos, 1, xcdr1);
  const dds_entity_t img_topic =
      dds_create_topic(pp, &sensor_msgs_msg_dds__Image__desc, "rt/camera/image", qos, nullptr);
  const dds_entity_t img_reader = dds_create_reader(pp, img_topic, qos, nullptr);
  const dds_entity_t typed_topic =
      dds_create_topic(pp, &sensor_msgs_msg_dds__Image__desc, "rt/camera/typed", qos, nullptr);
  const dds_entity_t typed_writer = dds_create_writer(pp, typed_topic, qos, nullptr);
  const dds_entity_t tf_topic =
      dds_create_topic(pp, &tf2_msgs_msg_dds__TFMessage__desc, "rt/tf", qos, nullptr);
  const dds_entity_t tf_reader = dds_create_reader(pp, tf_topic, qos, nullptr);
  dds_delete_qos(qos);
  ASSERT_GT(img_reader, 0);
  ASSERT_GT(typed_writer, 0);
  ASSERT_GT(tf_reader, 0);
  auto reader_matched = [](dds_entity_t reader) {
    dds_subscription_matched_status_t st{};
    return dds_get_subscription_matched_status(reader, &st) == DDS_RETCODE_OK &&
           st.current_count == 1;
  };
  dds_publication_matched_status_t typed_status{};
  ASSERT_TRUE(WaitFor([&] {
    return pub->matched_subscriptions() == 1 && tf_pub->matched_subscriptions() == 1 &&
           sub->matched_publishers() == 1 && reader_matched(img_reader) &&
           reader_matched(tf_reader) &&
           dds_get_publication_matched_status(typed_writer, &typed_status) == DDS_RETCODE_OK &&
           typed_status.current_count == 1;
  }));

  ExpectTypedReadersDecodeAvp(*pub, *tf_pub, img_reader, tf_reader);
  ExpectAvpDecodesTypedWriter(typed_writer, mutex, avp_got);
  EXPECT_EQ(sub->malformed(), 0u);
  dds_delete(pp);
}

}  // namespace
}  // namespace avp::ros::dds

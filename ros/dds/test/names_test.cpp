#include "names.h"

#include <cstdlib>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/ros/dds/node.h>

namespace avp::ros::dds {
namespace {

using ::testing::HasSubstr;

TEST(ExpandTopicName, AbsoluteRelativeAndPrivate) {
  EXPECT_EQ(ExpandTopicName("/camera/image", "avp", "/").value(), "/camera/image");
  EXPECT_EQ(ExpandTopicName("camera/image", "avp", "/").value(), "/camera/image");
  EXPECT_EQ(ExpandTopicName("camera/image", "avp", "/robot1").value(), "/robot1/camera/image");
  EXPECT_EQ(ExpandTopicName("/tf", "avp", "/robot1").value(), "/tf");
  EXPECT_EQ(ExpandTopicName("~/debug", "avp", "/robot1").value(), "/robot1/avp/debug");
  EXPECT_EQ(ExpandTopicName("~", "avp", "/").value(), "/avp");
  EXPECT_EQ(ExpandTopicName("_a/b_1", "avp", "/").value(), "/_a/b_1");
}

TEST(ExpandTopicName, BadNamesAreNamed) {
  for (const char* bad : {"1abc", "/a//b", "a/", "a b", "a-b", "{node}/x", "~x", "/", "a/2b"}) {
    const auto r = ExpandTopicName(bad, "avp", "/");
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(r.status().message(), HasSubstr(std::string("'") + bad + "'")) << bad;
  }
  EXPECT_THAT(ExpandTopicName("", "avp", "/").status().message(), HasSubstr("empty"));
}

TEST(NodeNames, Validation) {
  EXPECT_TRUE(ValidateNodeName("avp_live").ok());
  EXPECT_THAT(ValidateNodeName("1avp").message(), HasSubstr("'1avp'"));
  EXPECT_THAT(ValidateNodeName("a/b").message(), HasSubstr("'a/b'"));
  EXPECT_FALSE(ValidateNodeName("").ok());
  EXPECT_EQ(NormalizeNamespace("").value(), "/");
  EXPECT_EQ(NormalizeNamespace("robot1").value(), "/robot1");
  EXPECT_EQ(NormalizeNamespace("/a/b").value(), "/a/b");
  EXPECT_THAT(NormalizeNamespace("/a/").status().message(), HasSubstr("'/a/'"));
}

class DomainIdTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const char* old = std::getenv("ROS_DOMAIN_ID");
    had_ = old != nullptr;
    if (had_) old_ = old;
  }
  void TearDown() override {
    if (had_) {
      setenv("ROS_DOMAIN_ID", old_.c_str(), 1);
    } else {
      unsetenv("ROS_DOMAIN_ID");
    }
  }
  bool had_ = false;
  std::string old_;
};

TEST_F(DomainIdTest, ExplicitEnvironmentAndDefault) {
  unsetenv("ROS_DOMAIN_ID");
  EXPECT_EQ(ResolveDomainId(-1).value(), 0);
  EXPECT_EQ(ResolveDomainId(42).value(), 42);
  setenv("ROS_DOMAIN_ID", "17", 1);
  EXPECT_EQ(ResolveDomainId(-1).value(), 17);
  EXPECT_EQ(ResolveDomainId(3).value(), 3);  // explicit wins
  setenv("ROS_DOMAIN_ID", "", 1);
  EXPECT_EQ(ResolveDomainId(-1).value(), 0);
}

TEST_F(DomainIdTest, InvalidValuesAreNamed) {
  for (const char* bad : {"233", "-1", "abc", "1.5", "99999"}) {
    setenv("ROS_DOMAIN_ID", bad, 1);
    const auto r = ResolveDomainId(-1);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_THAT(r.status().message(), HasSubstr(std::string("ROS_DOMAIN_ID ('") + bad + "')"));
  }
  EXPECT_THAT(ResolveDomainId(233).status().message(), HasSubstr("(233)"));
  EXPECT_THAT(ResolveDomainId(-5).status().message(), HasSubstr("(-5)"));
  setenv("ROS_DOMAIN_ID", "abc", 1);
  NodeOptions options;
  options.loopback = true;
  const auto node = Node::Create(options);
  ASSERT_FALSE(node.ok());
  EXPECT_THAT(node.status().message(), HasSubstr("'abc'"));
}

}  // namespace
}  // namespace avp::ros::dds

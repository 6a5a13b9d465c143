// An episode whose segmenter is the segmentation service (remote://, over loopback gRPC) gives
// exactly the per-step metrics of the same episode with the oracle in-process: everything the
// oracle reads crosses the wire bit for bit, and the run's segmenter seed travels as `seed`.
#include <memory>
#include <string>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <avp/experiment/episode_runner.h>
#include <avp/segmentation_service/remote_segmenter.h>
#include <avp/segmentation_service/segmentation_server.h>
#include <avp/sim/scenario.h>

namespace avp {
namespace {

/// The built-ins and the remote:// client (never freed: servers outlive it).
const experiment::Registries& Registries() {
  static const auto* registries = [] {
    auto* r = new experiment::Registries(experiment::BuiltinRegistries());
    segmentation_service::RegisterRemoteSegmenter(r->segmenters);
    return r;
  }();
  return *registries;
}

TEST(RemoteSegmenterEndToEndTest, RemoteEpisodeEqualsInProcessEpisode) {
  segmentation_service::ServerOptions so;
  so.segmenters = &Registries().segmenters;
  so.port = 0;
  so.backends = {"oracle"};
  so.threads = 2;
  auto server = segmentation_service::SegmentationServer::Start(so);
  ASSERT_TRUE(server.ok()) << server.status().ToString();

  experiment::RunConfig local;
  local.scenario = std::string(sim::DefaultScenarioName());
  local.seed = 7;
  local.planner.name = "avp-nbv";
  local.segmenter.name = "oracle";
  local.episode.views = 3;
  local.threads = 2;
  experiment::RunConfig remote = local;
  remote.segmenter.name = fmt::format("remote://127.0.0.1:{}", (*server)->port());
  ASSERT_TRUE(remote.Validate(Registries()).ok()) << remote.Validate(Registries()).ToString();

  auto scene = sim::MakeScenario(local.scenario, local.seed);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  auto gt = experiment::GroundTruthFor(local, *scene);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  auto a = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(local, Registries()).value(), *scene, *gt);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  auto b = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(remote, Registries()).value(), *scene, *gt);
  ASSERT_TRUE(b.ok()) << b.status().ToString();

  ASSERT_EQ(a->episode.steps.size(), 3u);
  ASSERT_EQ(b->episode.steps.size(), a->episode.steps.size());
  size_t masks = 0;
  for (size_t i = 0; i < a->episode.steps.size(); ++i) {
    const pipeline::StepRecord& x = a->episode.steps[i];
    const pipeline::StepRecord& y = b->episode.steps[i];
    EXPECT_TRUE(y.segment_status.ok()) << i << ": " << y.segment_status.ToString();
    EXPECT_EQ(y.masks, x.masks) << i;
    EXPECT_EQ(y.metrics, x.metrics) << i;
    EXPECT_EQ(y.X_WC.translation(), x.X_WC.translation()) << i;
    EXPECT_EQ(y.X_WC.rotation(), x.X_WC.rotation()) << i;
    masks += x.masks;
  }
  EXPECT_GT(masks, 0u) << "the episode saw no fruit: the comparison would be vacuous";
  EXPECT_EQ((*server)->stats().infer_ok, 3u);
  EXPECT_EQ(b->final_metrics.exact.f1, a->final_metrics.exact.f1);
}

TEST(RemoteSegmenterEndToEndTest, ServerDownEndsTheEpisodeAsASegmenterFaultNamingTheAddress) {
  int port = 0;
  {
    segmentation_service::ServerOptions so;
    so.segmenters = &Registries().segmenters;
    so.port = 0;
    auto server = segmentation_service::SegmentationServer::Start(so);
    ASSERT_TRUE(server.ok());
    port = (*server)->port();
  }
  experiment::RunConfig c;
  c.scenario = std::string(sim::DefaultScenarioName());
  c.seed = 7;
  c.planner.name = "predefined";
  c.segmenter.name = fmt::format("remote://127.0.0.1:{}/oracle", port);
  c.episode.views = 3;
  c.threads = 2;
  auto scene = sim::MakeScenario(c.scenario, c.seed);
  ASSERT_TRUE(scene.ok());
  auto gt = experiment::GroundTruthFor(c, *scene);
  ASSERT_TRUE(gt.ok());
  auto r = experiment::RunEpisodeOnScene(
      experiment::CheckedRunConfig::Check(c, Registries()).value(), *scene, *gt);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  // Not three views of empty masks: the episode ends at the first view, as a segmenter fault
  // whose reason names the service's address; that view is kept (depth fused).
  EXPECT_EQ(r->episode.end, pipeline::EpisodeEnd::kSegmenterFault);
  ASSERT_EQ(r->episode.steps.size(), 1u);
  const Status& s = r->episode.steps.front().segment_status;
  EXPECT_EQ(s.code(), StatusCode::kUnavailable) << s.ToString();
  const std::string where =
      fmt::format("the segmentation server at 127.0.0.1:{} is unavailable", port);
  EXPECT_NE(s.message().find(where), std::string::npos) << s.message();
  EXPECT_NE(r->episode.end_reason.find(where), std::string::npos) << r->episode.end_reason;
  EXPECT_GT(r->episode.steps.front().integration.endpoints, 0u);
}

}  // namespace
}  // namespace avp

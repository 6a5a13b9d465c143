// The active-vision loop with fake components: what "N views" counts, step records, observers,
// and failures as outcomes (segmenter and capture errors, refused moves, no candidate, stop rule).
#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include <avp/core/camera.h>
#include <avp/pipeline/episode.h>
#include <avp/pipeline/view_fusion.h>
#include <avp/robot/arm.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/sim_arm.h>

namespace avp::pipeline {
namespace {

CameraIntrinsics SmallCamera() {
  return CameraIntrinsics::FromHorizontalFov(64, 48, 60.0, 0.1, 3.0);
}

/// A flat wall 1 m in front of the camera; fails on the frames listed in `fail_frames`.
class WallSource final : public robot::RgbdSource {
 public:
  std::vector<int> fail_frames;
  StatusCode fail_code = StatusCode::kIoError;
  int captured = 0;
  Result<robot::Observation> Capture(const RigidTransform& X_WC, int64_t stamp_ns) override {
    const int index = captured++;
    for (int f : fail_frames) {
      if (f == index) return Status(fail_code, "camera timeout on frame " + std::to_string(index));
    }
    robot::Observation obs;
    obs.frame.K = SmallCamera();
    obs.frame.X_WC = X_WC;
    obs.frame.stamp_ns = stamp_ns;
    obs.frame.rgb = ImageRgb8(64, 48, 100);
    obs.frame.depth_m = DepthImage(64, 48, 1.0f);
    return obs;
  }
  CameraIntrinsics intrinsics() const override { return SmallCamera(); }
};

/// One mask over the left half of the image; fails (or throws) on listed frames.
class HalfSegmenter final : public segmentation::Segmenter {
 public:
  std::vector<uint64_t> fail_frames;
  bool throw_instead = false;
  StatusCode fail_code = StatusCode::kInternal;
  /// Asked to stop on this frame (as Ctrl-C would), then returns what the interrupt says.
  std::stop_source* stop_on = nullptr;
  uint64_t stop_frame = 0;
  std::vector<uint64_t> seen;
  std::string_view name() const override { return "half"; }
  Result<Segmentation> Segment(const segmentation::SegmentationRequest& r) override {
    seen.push_back(r.frame_index);
    if (stop_on != nullptr && r.frame_index == stop_frame) {
      stop_on->request_stop();
      AVP_RETURN_IF_ERROR(segmentation::CheckInterrupt(r));
    }
    for (uint64_t f : fail_frames) {
      if (f == r.frame_index) {
        if (throw_instead) throw std::runtime_error("model crashed");
        return Status(fail_code, "inference server unavailable at 10.0.0.7:8001");
      }
    }
    Segmentation s;
    s.width = r.frame->depth_m.width();
    s.height = r.frame->depth_m.height();
    InstanceMask m;
    m.mask = MaskImage(s.width, s.height, 0);
    for (int v = 0; v < s.height; ++v) {
      for (int u = 0; u < s.width / 2; ++u) m.mask.at(u, v) = 1;
    }
    m.confidence = 0.8f;
    s.instances.push_back(m);
    return s;
  }
};

/// Scripted candidates: for view k, the joint vectors of `script[k]` (possibly out of limits).
class ScriptedPlanner final : public planning::ViewPlanner {
 public:
  std::vector<std::vector<Eigen::VectorXd>> script;
  int stop_at_view = -1;
  int throw_at_view = -1;
  std::vector<int> asked;
  std::vector<size_t> fused_seen;
  std::string_view name() const override { return "scripted"; }
  planning::PlanResult Plan(const planning::PlanningRequest& r, Rng&) override {
    asked.push_back(r.view_index);
    fused_seen.push_back(r.fused_views.size());
    planning::PlanResult out;
    if (r.view_index == throw_at_view) throw std::runtime_error("planner bug");
    if (r.view_index == stop_at_view) {
      out.stop = true;
      out.stop_reason = "gain below threshold";
      return out;
    }
    const size_t k = static_cast<size_t>(r.view_index - 1);
    if (k >= script.size() || script[k].empty()) {
      out.status = NotFoundError("no valid candidate: 0 generated");
      return out;
    }
    for (const Eigen::VectorXd& q : script[k]) {
      planning::ViewCandidate c;
      c.q = q;
      c.reachable = true;
      c.X_WC = r.arm->CameraPose(r.arm->ClampToLimits(q));
      out.ranked.push_back(c);
    }
    out.generated = out.reachable = out.ranked.size();
    return out;
  }
};

/// A SimArm whose moves fail with `fault` from move number `fail_from` on (0-based), counting the
/// requests it got.
class FaultyArm final : public robot::Arm {
 public:
  FaultyArm(const robot::ArmModel& model, Status fault, int fail_from)
      : robot::Arm(model),
        q_(model.home_joints()),
        fault_(std::move(fault)),
        fail_from_(fail_from) {}
  int requests = 0;

 protected:
  Eigen::VectorXd DoCurrentJoints() const override { return q_; }
  robot::MoveResult DoMoveToJoints(const Eigen::VectorXd& q) override {
    robot::MoveResult r;
    r.q = q_;
    if (requests++ >= fail_from_) {
      r.status = fault_;
      return r;
    }
    r.joint_path_length = (q - q_).norm();
    q_ = q;
    r.q = q_;
    return r;
  }

 private:
  Eigen::VectorXd q_;
  Status fault_;
  int fail_from_;
};

class Recorder final : public EpisodeObserver {
 public:
  std::vector<int> views;
  bool ended = false;
  void OnStep(const StepRecord& s, const mapping::SemanticMap&) override {
    EXPECT_FALSE(ended);
    views.push_back(s.view);
  }
  void OnEnd(const EpisodeResult&, const mapping::SemanticMap&) override { ended = true; }
};

class EpisodeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto model = robot::LoadDefaultArm();
    ASSERT_TRUE(model.ok()) << model.status().ToString();
    model_ = std::make_unique<robot::ArmModel>(*model);
    arm_ = std::make_unique<sim::SimArm>(*model_);
    options_.views = 4;
    options_.roi = Box3(Eigen::Vector3d(0.3, -0.5, 0.0), Eigen::Vector3d(1.5, 0.5, 1.5));
  }
  Eigen::VectorXd Home(double dq1) const {
    Eigen::VectorXd q = model_->home_joints();
    q[0] += dq1;
    return q;
  }
  Eigen::VectorXd OutOfLimits() const {
    Eigen::VectorXd q = model_->home_joints();
    q[1] = model_->upper_limits()[1] + 0.5;
    return q;
  }
  Result<EpisodeResult> Run(const std::vector<EpisodeObserver*>& observers = {},
                            robot::Arm* arm = nullptr) {
    EpisodeComponents c{&source_,  &segmenter_, arm != nullptr ? arm : arm_.get(),
                        &planner_, &map_,       stop_.get_token(),
                        nullptr};
    return RunEpisode(
        c, options_,
        [](const mapping::SemanticMap& m) {
          return std::vector<std::pair<std::string, double>>{
              {"known", static_cast<double>(m.grid().CountKnownVoxels())}};
        },
        observers);
  }
  std::unique_ptr<robot::ArmModel> model_;
  std::unique_ptr<sim::SimArm> arm_;
  WallSource source_;
  HalfSegmenter segmenter_;
  ScriptedPlanner planner_;
  mapping::SemanticMap map_;
  EpisodeOptions options_;
  std::stop_source stop_;
};

TEST_F(EpisodeTest, NViewsAreNFusedObservationsAndNMinusOneMoves) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  Recorder rec;
  auto r = Run({&rec});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->end, EpisodeEnd::kBudgetReached);
  ASSERT_EQ(r->views_fused(), 4);
  EXPECT_EQ(source_.captured, 4);
  EXPECT_EQ(planner_.asked, (std::vector<int>{1, 2, 3}));  // no plan after the last view
  EXPECT_EQ(planner_.fused_seen, (std::vector<size_t>{1, 2, 3}));
  EXPECT_EQ(arm_->num_moves(), 3);
  EXPECT_EQ(rec.views, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_TRUE(rec.ended);
  EXPECT_EQ(segmenter_.seen, (std::vector<uint64_t>{0, 1, 2, 3}));
  for (int i = 0; i < 4; ++i) {
    const StepRecord& s = r->steps[static_cast<size_t>(i)];
    EXPECT_EQ(s.view, i);
    EXPECT_EQ(s.masks, 1u);
    EXPECT_GT(s.integration.endpoints, 0u);
    EXPECT_EQ(s.planned, i < 3);
    EXPECT_EQ(s.chosen_rank, i < 3 ? 0 : -1);
    EXPECT_GT(s.known_voxels, 0u);
    EXPECT_EQ(s.Metric("known"), static_cast<double>(s.known_voxels));
    EXPECT_TRUE(std::isnan(s.Metric("missing")));
  }
  // The views are taken where the arm went: view k + 1 at the pose of its chosen candidate.
  EXPECT_NEAR((r->steps[1].q - Home(0.1)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((r->steps[3].q - Home(0.3)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(r->steps[0].joint_path_length, 0.1, 1e-12);
}

/// Keeps what OnView hands over (it is valid only during the call).
class ViewKeeper final : public EpisodeObserver {
 public:
  struct Seen {
    int view = -1;
    bool has_observation = false;
    int64_t stamp_ns = -1;
    int depth_width = 0;
    RigidTransform X_WC;
    int instances = -1;  ///< -1: no segmentation
    int ranked = -1;     ///< -1: no plan
    bool on_step_followed = false;
  };
  std::vector<Seen> seen;
  void OnView(const StepRecord& s, const StepData& d, const mapping::SemanticMap&) override {
    Seen x;
    x.view = s.view;
    if (d.observation != nullptr) {
      x.has_observation = true;
      x.stamp_ns = d.observation->frame.stamp_ns;
      x.depth_width = d.observation->frame.depth_m.width();
      x.X_WC = d.observation->frame.X_WC;
    }
    if (d.segmentation != nullptr) x.instances = static_cast<int>(d.segmentation->instances.size());
    if (d.plan != nullptr) x.ranked = static_cast<int>(d.plan->ranked.size());
    seen.push_back(x);
  }
  void OnStep(const StepRecord& s, const mapping::SemanticMap&) override {
    ASSERT_FALSE(seen.empty());
    EXPECT_EQ(seen.back().view, s.view);  // OnView came first, for the same step
    seen.back().on_step_followed = true;
  }
};

TEST_F(EpisodeTest, ObserversSeeEachViewsFrameSegmentationAndPlan) {
  // View 1's segmentation fails (fused as depth only); view 2's plan has two candidates.
  segmenter_.fail_frames = {1};
  planner_.script = {{Home(0.1)}, {Home(0.2), Home(0.25)}, {Home(0.3)}};
  ViewKeeper keeper;
  auto r = Run({&keeper});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(keeper.seen.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    const ViewKeeper::Seen& x = keeper.seen[i];
    EXPECT_EQ(x.view, static_cast<int>(i));
    EXPECT_TRUE(x.on_step_followed);
    ASSERT_TRUE(x.has_observation);
    EXPECT_EQ(x.stamp_ns, static_cast<int64_t>(i) * 1'000'000'000);
    EXPECT_GT(x.depth_width, 0);
    EXPECT_NEAR((x.X_WC.translation() - r->steps[i].X_WC.translation()).norm(), 0.0, 1e-12);
  }
  EXPECT_EQ(keeper.seen[0].instances, 1);
  EXPECT_EQ(keeper.seen[1].instances, -1);  // the failed segmentation is not handed over
  EXPECT_EQ(keeper.seen[2].instances, 1);
  EXPECT_EQ(keeper.seen[0].ranked, 1);
  EXPECT_EQ(keeper.seen[1].ranked, 2);
  EXPECT_EQ(keeper.seen[2].ranked, 1);
  EXPECT_EQ(keeper.seen[3].ranked, -1);  // no plan after the last view
}

TEST_F(EpisodeTest, UnreachableChosenViewFallsBackToTheNextBestReachableOne) {
  planner_.script = {{OutOfLimits(), OutOfLimits(), Home(0.2)}, {Home(0.3)}, {Home(0.4)}};
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kBudgetReached);
  EXPECT_EQ(r->steps[0].chosen_rank, 2);
  EXPECT_EQ(r->steps[0].refused_moves, 2);
  EXPECT_NEAR((r->steps[1].q - Home(0.2)).norm(), 0.0, 1e-12);
}

TEST_F(EpisodeTest, EveryCandidateRefusedEndsTheEpisodeWithThatReason) {
  planner_.script = {{Home(0.1)}, {OutOfLimits()}};
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kNoReachableMove);
  EXPECT_EQ(r->views_fused(), 2);  // the second view was fused; its move failed
  EXPECT_NE(r->end_reason.find("refused all 1"), std::string::npos) << r->end_reason;
  EXPECT_FALSE(r->steps[1].move_status.ok());
}

TEST_F(EpisodeTest, NoValidCandidateStopsWithThePlannersStatus) {
  planner_.script = {{Home(0.1)}};  // nothing for view 2
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kNoValidCandidate);
  EXPECT_EQ(r->views_fused(), 2);
  EXPECT_NE(r->end_reason.find("no valid candidate"), std::string::npos) << r->end_reason;
  EXPECT_EQ(r->steps[1].plan_status.code(), StatusCode::kNotFound);
}

TEST_F(EpisodeTest, PlannerStoppingRuleEndsTheEpisode) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  planner_.stop_at_view = 2;
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kPlannerStopped);
  EXPECT_EQ(r->end_reason, "gain below threshold");
  EXPECT_EQ(r->views_fused(), 2);
}

TEST_F(EpisodeTest, SegmenterErrorIsRecordedAndTheLoopGoesOn) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  segmenter_.fail_frames = {1};
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kBudgetReached);
  EXPECT_EQ(r->views_fused(), 4);
  EXPECT_EQ(r->steps[1].segment_status.code(), StatusCode::kInternal);
  EXPECT_EQ(r->steps[1].masks, 0u);
  // The depth was still fused, without semantics.
  EXPECT_GT(r->steps[1].integration.endpoints, 0u);
  EXPECT_EQ(r->steps[1].integration.masked_endpoints, 0u);
  EXPECT_GT(r->steps[2].integration.masked_endpoints, 0u);
}

TEST_F(EpisodeTest, UnavailableSegmenterEndsTheEpisodeAsASegmenterFault) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  segmenter_.fail_frames = {1, 2, 3};
  segmenter_.fail_code = StatusCode::kUnavailable;
  Recorder rec;
  auto r = Run({&rec});
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kSegmenterFault);
  EXPECT_EQ(ToString(r->end), "segmenter-fault");
  EXPECT_NE(r->end_reason.find("unavailable at 10.0.0.7:8001"), std::string::npos) << r->end_reason;
  // The view was fused (depth only) and recorded; nothing was planned after it.
  EXPECT_EQ(r->views_fused(), 2);
  EXPECT_EQ(r->steps[1].segment_status.code(), StatusCode::kUnavailable);
  EXPECT_GT(r->steps[1].integration.endpoints, 0u);
  EXPECT_FALSE(r->steps[1].planned);
  EXPECT_EQ(rec.views, (std::vector<int>{0, 1}));
  EXPECT_TRUE(rec.ended);
}

TEST_F(EpisodeTest, SegmenterFailingMaxSegmentFailuresViewsInARowEndsTheEpisode) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}, {Home(0.4)}, {Home(0.5)}};
  options_.views = 5;
  options_.max_segment_failures = 2;
  segmenter_.fail_frames = {0, 2, 3, 4};  // 0 alone, then 2 and 3 in a row
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kSegmenterFault);
  EXPECT_EQ(r->views_fused(), 4);
  EXPECT_NE(r->end_reason.find("the segmenter failed 2 views in a row (max_segment_failures)"),
            std::string::npos)
      << r->end_reason;
}

TEST_F(EpisodeTest, SegmenterFailuresNotInARowDoNotEndTheEpisode) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}, {Home(0.4)}, {Home(0.5)}};
  options_.max_segment_failures = 2;
  segmenter_.fail_frames = {0, 2};  // never 2 in a row
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->views_fused(), 4);
  EXPECT_EQ(r->end, EpisodeEnd::kBudgetReached);
  EXPECT_EQ(r->steps[2].segment_status.code(), StatusCode::kInternal);
}

TEST_F(EpisodeTest, MaxSegmentFailuresAndThePromptAreBounded) {
  EXPECT_TRUE(options_.Validate().ok()) << options_.Validate().ToString();
  options_.max_segment_failures = 0;
  EXPECT_NE(options_.Validate().message().find("max_segment_failures (0) must be in [1, 1000]"),
            std::string::npos)
      << options_.Validate().ToString();
  options_.max_segment_failures = 3;
  options_.record_top_candidates = 100000;
  EXPECT_NE(options_.Validate().message().find("record_top_candidates (100000)"), std::string::npos)
      << options_.Validate().ToString();
  options_.record_top_candidates = 5;
  std::string prompt = "tomato";
  for (int i = 1; i < 100000; ++i) prompt += ", tomato";
  options_.prompt = prompt;
  const Status s = options_.Validate();
  EXPECT_NE(s.message().find("prompt (799998) exceeds the limit max_prompt_bytes = 4096"),
            std::string::npos)
      << s.ToString();
  options_.prompt = " ,\x1b[2J";
  EXPECT_TRUE(options_.Validate().ok());  // the escape sequence is a phrase (of a kind)
  options_.prompt = " ,\t";
  EXPECT_NE(options_.Validate().message().find("prompt (' ,\\t') names no class"),
            std::string::npos)
      << options_.Validate().ToString();
}

TEST_F(EpisodeTest, AStopWhileSegmentingEndsTheEpisodeAsInterrupted) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  segmenter_.stop_on = &stop_;
  segmenter_.stop_frame = 1;
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kInterrupted);
  EXPECT_EQ(r->views_fused(), 2);
  EXPECT_EQ(r->steps[1].segment_status.code(), StatusCode::kCancelled);
  EXPECT_FALSE(r->steps[1].planned);
}

TEST_F(EpisodeTest, ThrowingSegmenterBecomesAStatus) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  segmenter_.fail_frames = {0};
  segmenter_.throw_instead = true;
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->views_fused(), 4);
  EXPECT_NE(r->steps[0].segment_status.message().find("model crashed"), std::string::npos);
}

TEST_F(EpisodeTest, AThrowingPlannerEndsTheEpisodeAsAPlannerFault) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  planner_.throw_at_view = 2;
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kPlannerFault);
  EXPECT_EQ(ToString(r->end), "planner-fault");
  EXPECT_EQ(r->views_fused(), 2);  // the views before the fault are kept
  EXPECT_NE(r->end_reason.find("planner 'scripted' threw: planner bug"), std::string::npos)
      << r->end_reason;
  EXPECT_EQ(r->steps[1].plan_status.code(), StatusCode::kInternal);
}

TEST_F(EpisodeTest, CaptureErrorIsRecordedAndFusesNothing) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  source_.fail_frames = {0};
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->views_fused(), 4);
  EXPECT_EQ(r->steps[0].capture_status.code(), StatusCode::kIoError);
  EXPECT_EQ(r->steps[0].known_voxels, 0u);
  EXPECT_GT(r->steps[1].known_voxels, 0u);
}

TEST_F(EpisodeTest, MissingComponentsAndBadOptionsAreErrors) {
  EpisodeComponents c{&source_, nullptr, arm_.get(), &planner_, &map_, {}, nullptr};
  auto r = RunEpisode(c, options_);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("segmenter"), std::string::npos);
  options_.views = 0;
  auto r2 = Run();
  ASSERT_FALSE(r2.ok());
  EXPECT_NE(r2.status().message().find("views (0)"), std::string::npos) << r2.status().ToString();
  options_.views = 3;
  options_.roi = Box3();
  auto r3 = Run();
  ASSERT_FALSE(r3.ok());
  EXPECT_NE(r3.status().message().find("ROI"), std::string::npos);
}

TEST_F(EpisodeTest, SingleViewEpisodePlansNothing) {
  options_.views = 1;
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->views_fused(), 1);
  EXPECT_TRUE(planner_.asked.empty());
  EXPECT_EQ(arm_->num_moves(), 0);
}

TEST_F(EpisodeTest, ArmThatDoesNotArriveEndsTheEpisodeWithoutTryingOtherCandidates) {
  planner_.script = {{Home(0.1)}, {Home(0.2), Home(0.3), Home(0.4)}, {Home(0.5)}};
  FaultyArm arm(*model_, DeadlineExceededError("joint_states did not reach the goal in 30 s"), 1);
  Recorder rec;
  auto r = Run({&rec}, &arm);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->end, EpisodeEnd::kRobotFault);
  EXPECT_EQ(ToString(r->end), "robot-fault");
  EXPECT_NE(r->end_reason.find("did not reach the goal"), std::string::npos) << r->end_reason;
  EXPECT_EQ(arm.requests, 2);  // one good move, one fault; the two other candidates untried
  EXPECT_EQ(r->views_fused(), 2);
  EXPECT_EQ(r->steps[1].refused_moves, 1);
  EXPECT_TRUE(rec.ended);
}

TEST_F(EpisodeTest, UnavailableArmIsARobotFaultToo) {
  planner_.script = {{Home(0.1), Home(0.2)}};
  FaultyArm arm(*model_, UnavailableError("no /joint_states for 5 s"), 0);
  auto r = Run({}, &arm);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kRobotFault);
  EXPECT_EQ(arm.requests, 1);
  EXPECT_EQ(r->views_fused(), 1);
}

TEST_F(EpisodeTest, RequestedStopEndsTheEpisodeAsInterruptedWithItsSteps) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  // The observer asks to stop after the second view, as Ctrl-C would.
  class StopAfter final : public EpisodeObserver {
   public:
    explicit StopAfter(std::stop_source& s) : s_(s) {}
    void OnStep(const StepRecord& step, const mapping::SemanticMap&) override {
      if (step.view == 1) s_.request_stop();
    }

   private:
    std::stop_source& s_;
  } stopper(stop_);
  Recorder rec;
  auto r = Run({&stopper, &rec});
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kInterrupted);
  EXPECT_EQ(ToString(r->end), "interrupted");
  EXPECT_EQ(r->views_fused(), 2);
  EXPECT_EQ(rec.views, (std::vector<int>{0, 1}));
  EXPECT_TRUE(rec.ended);
  EXPECT_EQ(source_.captured, 2);
}

TEST_F(EpisodeTest, CancelledCaptureEndsTheEpisodeAsInterrupted) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  source_.fail_frames = {2};
  source_.fail_code = StatusCode::kCancelled;
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kInterrupted);
  EXPECT_EQ(r->views_fused(), 3);
  EXPECT_EQ(r->steps[2].capture_status.code(), StatusCode::kCancelled);
  EXPECT_FALSE(r->steps[2].planned);
}

TEST_F(EpisodeTest, CameraDeadlineIsRecordedAndTheLoopGoesOn) {
  planner_.script = {{Home(0.1)}, {Home(0.2)}, {Home(0.3)}};
  source_.fail_frames = {1};
  source_.fail_code = StatusCode::kDeadlineExceeded;
  auto r = Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->end, EpisodeEnd::kBudgetReached);
  EXPECT_EQ(r->views_fused(), 4);
  EXPECT_EQ(r->steps[1].capture_status.code(), StatusCode::kDeadlineExceeded);
}

// ---- ViewFusion: the one place a view is fused (RunEpisode, avp replay, avp map build) ---------

TEST_F(EpisodeTest, ViewFusionGivesTheEpisodesMapAndCounts) {
  // Two views fused through ViewFusion by hand equal the first two steps of an episode whose
  // planner keeps the camera where it is.
  options_.views = 2;
  planner_.script = {{model_->home_joints()}};
  const Result<EpisodeResult> episode = Run();
  ASSERT_TRUE(episode.ok()) << episode.status().ToString();
  ASSERT_EQ(episode->steps.size(), 2u);

  mapping::SemanticMap map;
  ViewFusion fusion(map, options_);
  WallSource source;
  HalfSegmenter segmenter;
  for (int view = 0; view < 2; ++view) {
    const StepRecord& expected = episode->steps[static_cast<size_t>(view)];
    Result<robot::Observation> obs = source.Capture(expected.X_WC, view * 1'000'000'000LL);
    ASSERT_TRUE(obs.ok());
    StepRecord step;
    ViewSeen seen;
    fusion.Segment(std::move(*obs), segmenter, static_cast<uint64_t>(view), {}, step, seen);
    EXPECT_TRUE(step.segment_status.ok());
    EXPECT_EQ(step.masks, 1u);
    ASSERT_TRUE(seen.observation.has_value());
    ASSERT_TRUE(seen.segmentation.has_value());
    EXPECT_EQ(step.integration.endpoints, expected.integration.endpoints);
    EXPECT_EQ(step.known_voxels, expected.known_voxels);
    EXPECT_EQ(step.occupied_voxels, expected.occupied_voxels);
    EXPECT_EQ(step.target_voxels, expected.target_voxels);
    EXPECT_EQ(step.instances, expected.instances);
    EXPECT_EQ(step.known_delta, expected.known_delta);
    EXPECT_EQ(step.target_delta, expected.target_delta);
  }
  EXPECT_GT(map.grid().CountKnownVoxels(), 0u);
  EXPECT_EQ(map.grid().CountKnownVoxels(), map_.grid().CountKnownVoxels());
}

TEST_F(EpisodeTest, ViewFusionFusesDepthOnlyWhenTheSegmenterFails) {
  mapping::SemanticMap map;
  ViewFusion fusion(map, options_);
  segmenter_.fail_frames = {0};
  segmenter_.throw_instead = true;
  Result<robot::Observation> obs = source_.Capture(arm_->CurrentCameraPose(), 0);
  ASSERT_TRUE(obs.ok());
  StepRecord step;
  ViewSeen seen;
  fusion.Segment(std::move(*obs), segmenter_, 0, {}, step, seen);
  EXPECT_EQ(step.segment_status.code(), StatusCode::kInternal);
  EXPECT_NE(step.segment_status.message().find("segmenter 'half' threw: model crashed"),
            std::string::npos)
      << step.segment_status.ToString();
  EXPECT_FALSE(seen.segmentation.has_value());
  EXPECT_EQ(step.masks, 0u);
  EXPECT_GT(step.known_voxels, 0u);   // the depth was fused
  EXPECT_EQ(step.target_voxels, 0u);  // without semantics
  EXPECT_EQ(step.known_delta, static_cast<int64_t>(step.known_voxels));
}

TEST_F(EpisodeTest, ViewFusionRefusesMasksThatDoNotFitTheFrame) {
  // A recorded segmentation of another size: the integrator's error is the step's, nothing fused.
  mapping::SemanticMap map;
  ViewFusion fusion(map, options_);
  Result<robot::Observation> obs = source_.Capture(arm_->CurrentCameraPose(), 0);
  ASSERT_TRUE(obs.ok());
  Segmentation wrong;
  wrong.width = 10;
  wrong.height = 10;
  StepRecord step;
  ViewSeen seen;
  fusion.Fuse(std::move(*obs), wrong, step, seen);
  EXPECT_FALSE(step.integrate_status.ok());
  EXPECT_EQ(step.known_voxels, 0u);
  // The next view's change is counted from the map as it was.
  fusion.RecordMap(step);
  EXPECT_EQ(step.known_delta, 0);
}

/// A wall source whose camera also streams while the arm moves: one frame per requested pose
/// once the move ended (as the simulator's), every `fail_every`-th failing.
class StreamingWallSource final : public robot::RgbdSource {
 public:
  WallSource wall;
  std::vector<robot::MoveStreamRequest> requests;
  std::vector<int64_t> moving_stamps;
  std::vector<RigidTransform> moving_poses;
  int fail_every = 0;

  Result<robot::Observation> Capture(const RigidTransform& X_WC, int64_t stamp_ns) override {
    return wall.Capture(X_WC, stamp_ns);
  }
  CameraIntrinsics intrinsics() const override { return SmallCamera(); }
  std::unique_ptr<robot::MoveStream> StreamMove(const robot::MoveStreamRequest& r) override {
    requests.push_back(r);
    return std::make_unique<Stream>(*this, r);
  }

 private:
  class Stream final : public robot::MoveStream {
   public:
    Stream(StreamingWallSource& s, robot::MoveStreamRequest r) : s_(s), r_(std::move(r)) {}
    Result<std::optional<robot::Observation>> Next() override {
      // Called on the fusion thread; End() comes from the episode's thread.
      while (!ended_.load()) std::this_thread::yield();
      if (!moved_ || next_ >= r_.poses.size()) return std::optional<robot::Observation>();
      const robot::TimedCameraPose& p = r_.poses[next_++];
      if (s_.fail_every > 0 && next_ % static_cast<size_t>(s_.fail_every) == 0) {
        ++c_.failed;
        return IoError("frame lost");
      }
      s_.moving_stamps.push_back(r_.start_stamp_ns + p.t_ns);
      s_.moving_poses.push_back(p.X_WC);
      ++c_.delivered;
      Result<robot::Observation> obs = s_.wall.Capture(p.X_WC, r_.start_stamp_ns + p.t_ns);
      if (!obs.ok()) return obs.status();
      return std::optional<robot::Observation>(std::move(*obs));
    }
    void End(bool moved) override {
      moved_ = moved;
      ended_.store(true);
    }
    robot::MoveStreamCounters counters() const override { return c_; }

   private:
    StreamingWallSource& s_;
    robot::MoveStreamRequest r_;
    std::atomic<bool> ended_{false};
    bool moved_ = false;
    size_t next_ = 0;
    robot::MoveStreamCounters c_;
  };
};

class MotionFusionTest : public EpisodeTest {
 protected:
  Result<EpisodeResult> RunStreaming() {
    EpisodeComponents c{&streaming_, &segmenter_, arm_.get(), &planner_, &map_, stop_.get_token()};
    return RunEpisode(c, options_);
  }
  StreamingWallSource streaming_;
};

TEST_F(MotionFusionTest, FramesAlongEachMoveAreFusedBeforeTheNextPlan) {
  planner_.script = {{Home(0.3)}, {Home(0.6)}, {Home(0.2)}};
  options_.motion_fusion.enabled = true;
  options_.motion_fusion.semantics = MovingSemantics::kEveryFrame;
  auto r = RunStreaming();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->views_fused(), 4);
  ASSERT_EQ(streaming_.requests.size(), 3u);
  int64_t moved_ns = 0;
  size_t frame = 0;
  for (int v = 0; v < 3; ++v) {
    const StepRecord& s = r->steps[static_cast<size_t>(v)];
    const MovingFramesRecord& f = s.motion_frames;
    const robot::MoveStreamRequest& req = streaming_.requests[static_cast<size_t>(v)];
    // The move is the straight line, timed: 0.3 rad at half the URDF's speed takes ~1 s.
    EXPECT_TRUE(f.streamed);
    EXPECT_GT(f.move_s, 0.5);
    EXPECT_DOUBLE_EQ(s.motion.execution_s, f.move_s);
    EXPECT_TRUE(s.motion.straight);
    EXPECT_FALSE(s.motion.planned);
    // A frame every 1/30 s strictly inside the move, each fused with its masks.
    EXPECT_EQ(f.expected, static_cast<int>(req.poses.size()));
    EXPECT_EQ(f.expected, static_cast<int>(std::ceil(f.move_s * 30.0)) - 1);
    EXPECT_EQ(f.fused, f.expected);
    EXPECT_EQ(f.segmented, f.expected);
    EXPECT_EQ(f.dropped + f.failed + f.segment_failed, 0);
    EXPECT_GT(f.integrate_ms, 0.0);
    EXPECT_GT(f.map_rate_hz(), 0.0);
    // Stamped along the episode's clock: view v at v s plus the moves so far.
    EXPECT_EQ(req.start_stamp_ns, v * 1'000'000'000LL + moved_ns);
    for (const robot::TimedCameraPose& p : req.poses) {
      EXPECT_EQ(streaming_.moving_stamps[frame++], req.start_stamp_ns + p.t_ns);
    }
    moved_ns += std::llround(f.move_s * 1e9);
    // The frames were segmented with their own indices.
    EXPECT_NE(std::find(segmenter_.seen.begin(), segmenter_.seen.end(), MovingFrameIndex(v, 1)),
              segmenter_.seen.end());
  }
  EXPECT_FALSE(r->steps[3].motion_frames.streamed);  // no move after the last view
  EXPECT_EQ(streaming_.wall.captured, 4 + static_cast<int>(frame));
  // The moving frames are between the views in pose: the first one of the first move is a
  // little past the start view, towards view 2.
  const double to_next = (r->steps[1].X_WC.translation() - r->steps[0].X_WC.translation()).norm();
  const double first =
      (streaming_.moving_poses.front().translation() - r->steps[0].X_WC.translation()).norm();
  EXPECT_GT(first, 0.0);
  EXPECT_LT(first, 0.1 * to_next);
  // Totals: every moving frame, and the robot's time includes the moves.
  const MotionTotals totals = SumMotion(*r);
  EXPECT_EQ(totals.moving.fused, static_cast<int>(frame));
  EXPECT_GT(totals.robot_s, totals.execution_s);
}

TEST_F(MotionFusionTest, MovingFramesAddToTheMapAndTheNextViewCountsOnlyItsOwnChange) {
  planner_.script = {{Home(0.5)}};
  options_.views = 2;
  options_.motion_fusion.enabled = true;
  options_.motion_fusion.semantics = MovingSemantics::kNone;
  auto with = RunStreaming();
  ASSERT_TRUE(with.ok()) << with.status().ToString();
  const MovingFramesRecord& f = with->steps[0].motion_frames;
  EXPECT_GT(f.fused, 10);
  EXPECT_EQ(f.segmented, 0);  // depth only
  EXPECT_GT(f.known_delta, 0);
  // Known voxels after view 2 = after view 1 + the moving frames' + view 2's own change.
  EXPECT_EQ(with->steps[1].known_voxels, with->steps[0].known_voxels +
                                             static_cast<size_t>(f.known_delta) +
                                             static_cast<size_t>(with->steps[1].known_delta));
  // The same episode without fusion during motion knows less.
  mapping::SemanticMap plain_map;
  EpisodeOptions plain = options_;
  plain.motion_fusion.enabled = false;
  sim::SimArm arm(*model_);
  ScriptedPlanner planner;
  planner.script = planner_.script;
  EpisodeComponents c{&streaming_, &segmenter_, &arm, &planner, &plain_map, {}};
  const size_t requests = streaming_.requests.size();
  auto without = RunEpisode(c, plain);
  ASSERT_TRUE(without.ok());
  EXPECT_EQ(streaming_.requests.size(), requests);  // no stream asked for
  EXPECT_FALSE(without->steps[0].motion_frames.streamed);
  EXPECT_LT(without->steps[1].known_voxels, with->steps[1].known_voxels);
  // Its straight move is recorded with the duration of the same timed line.
  EXPECT_DOUBLE_EQ(without->steps[0].motion.execution_s, with->steps[0].motion.execution_s);
}

TEST_F(MotionFusionTest, LostFramesAreCountedAndASourceThatCannotStreamJustMoves) {
  planner_.script = {{Home(0.5)}};
  options_.views = 2;
  options_.motion_fusion.enabled = true;
  streaming_.fail_every = 4;
  auto r = RunStreaming();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const MovingFramesRecord& f = r->steps[0].motion_frames;
  EXPECT_EQ(f.failed, f.expected / 4);
  EXPECT_EQ(f.fused, f.expected - f.failed);
  EXPECT_NE(f.first_problem.find("frame lost"), std::string::npos) << f.first_problem;
  // WallSource does not stream: the move happens, nothing is fused on the way.
  auto plain = Run();
  ASSERT_TRUE(plain.ok());
  EXPECT_FALSE(plain->steps[0].motion_frames.streamed);
  EXPECT_EQ(plain->steps[0].chosen_rank, 0);
}

TEST_F(MotionFusionTest, ARefusedMoveStreamsNothingAndTheNextCandidateIsStreamed) {
  planner_.script = {{OutOfLimits(), Home(0.4)}};
  options_.views = 2;
  options_.motion_fusion.enabled = true;
  auto r = RunStreaming();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const StepRecord& s = r->steps[0];
  EXPECT_EQ(s.chosen_rank, 1);
  EXPECT_EQ(s.refused_moves, 1);
  // Only the executed move's frames are recorded.
  EXPECT_EQ(s.motion_frames.fused, s.motion_frames.expected);
  EXPECT_EQ(static_cast<int>(streaming_.moving_stamps.size()), s.motion_frames.fused);
}

TEST_F(MotionFusionTest, OptionsAreCheckedAndNamed) {
  options_.motion_fusion.rate_hz = 0.0;
  options_.motion_fusion.max_pending = 0;
  const Status s = options_.Validate();
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("rate_hz"), std::string::npos) << s.ToString();
  EXPECT_NE(s.message().find("max_pending"), std::string::npos) << s.ToString();
}

}  // namespace
}  // namespace avp::pipeline

// A run that finds nothing says why (issue 32): the causes its steps show, in words.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/status.h>
#include <avp/experiment/episode_runner.h>

namespace avp::experiment {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

/// `views` steps with `masks` masks each, planned with a chosen view of gain `gain` (not the last).
RunResult Episode(int views, size_t masks, double gain, size_t found, double coverage) {
  RunResult r;
  for (int v = 0; v < views; ++v) {
    pipeline::StepRecord s;
    s.view = v;
    s.masks = masks;
    s.planned = v + 1 < views;
    s.chosen_rank = s.planned ? 0 : -1;
    s.chosen.gain = gain;
    r.episode.steps.push_back(s);
  }
  r.gt_fruits = 18;
  r.final_metrics.fruits.total = 18;
  r.final_metrics.fruits.found = found;
  r.final_metrics.roi_coverage = coverage;
  return r;
}

TEST(NothingFoundTest, ThePapersPlannerFromAnUnorientedStart) {
  // What `avp run --scenario tomato-unoriented-start --planner reference-nbv` does: no view sees
  // the plant, no mask, no gain.
  RunConfig c;
  c.planner.name = "reference-nbv";
  const std::vector<std::string> why = WhyNothingFound(c, Episode(8, 0, 0.0, 0, 0.0017));
  ASSERT_EQ(why.size(), 3u);
  EXPECT_THAT(why[0], HasSubstr("no view returned a mask: the segmenter 'oracle' found nothing "
                                "for the prompt 'tomato' in 8 views"));
  EXPECT_THAT(why[1], HasSubstr("the views saw 0.2 % of the region of interest"));
  EXPECT_THAT(why[2], HasSubstr("every one of the 7 views planner 'reference-nbv' chose had zero "
                                "gain"));
}

TEST(NothingFoundTest, MasksWithoutFruitAndFailures) {
  RunConfig c;
  RunResult r = Episode(3, 2, 0.5, 0, 0.6);
  r.episode.steps[1].segment_status = UnavailableError("down");
  EXPECT_THAT(WhyNothingFound(c, r),
              ElementsAre(HasSubstr("the segmenter failed at 1 of 3 views (oracle)"),
                          HasSubstr("6 masks were segmented in 3 views, but none made a fruit's "
                                    "voxels")));
}

TEST(NothingFoundTest, SilentWhenAFruitWasFoundOrThereIsNoTruth) {
  RunConfig c;
  EXPECT_THAT(WhyNothingFound(c, Episode(8, 0, 0.0, 1, 0.0)), IsEmpty());
  RunResult no_truth = Episode(8, 0, 0.0, 0, 0.0);
  no_truth.gt_fruits = 0;
  EXPECT_THAT(WhyNothingFound(c, no_truth), IsEmpty());
  EXPECT_THAT(WhyNothingFound(c, RunResult{}), IsEmpty());
}

}  // namespace
}  // namespace avp::experiment

// The Segmenter contract (segmenter.h), checked against every segmenter the registry builds.
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <string>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/limits.h>
#include <avp/core/text.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/segmentation/segmenter_registry.h>

#include "test_frames.h"

namespace avp::segmentation {
namespace {

using test::TestScene;
using ::testing::HasSubstr;

// ---- SplitPrompt and the registry
// ---------------------------------------------------------------

TEST(SplitPromptTest, SplitsOnCommasAndTrims) {
  const auto a = SplitPrompt("tomato, green apple");
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(*a, (std::vector<std::string>{"tomato", "green apple"}));
  const auto b = SplitPrompt("  tomato\t");
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(*b, (std::vector<std::string>{"tomato"}));
  const auto c = SplitPrompt(",red,, Green  ,");
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(*c, (std::vector<std::string>{"red", "Green"}));
}

TEST(SplitPromptTest, NothingLeftIsAnErrorNamingThePrompt) {
  for (const std::string prompt : {"", "   ", " , ,\t,"}) {
    const auto r = SplitPrompt(prompt);
    ASSERT_FALSE(r.ok()) << "\"" << prompt << "\"";
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(r.status().message(), HasSubstr("prompt (" + QuoteText(prompt) + ")"));
  }
  // Control characters reach the message escaped.
  const auto r = SplitPrompt("\x1b[2J, ,");
  ASSERT_TRUE(r.ok());
  const auto e = SplitPrompt(" ,\x1b");
  ASSERT_TRUE(e.ok());  // ESC is a phrase, not space
  const auto blank = SplitPrompt(std::string(" ,\r\n,\f"));
  ASSERT_FALSE(blank.ok());
  EXPECT_THAT(blank.status().message(), HasSubstr("prompt (' ,\\r\\n,\\x0c')"));
}

TEST(SplitPromptTest, DuplicatePhrasesCollapseToTheFirst) {
  const auto r = SplitPrompt("tomato, green apple,tomato , green apple, tomato");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(*r, (std::vector<std::string>{"tomato", "green apple"}));
}

/// "tomato, tomato, ..." with `n` phrases.
std::string RepeatedPrompt(size_t n) {
  std::string prompt;
  for (size_t i = 0; i < n; ++i) prompt += i == 0 ? "tomato" : ", tomato";
  return prompt;
}

TEST(SplitPromptTest, AHundredThousandPhrasesAreRefusedByTheByteLimit) {
  const std::string prompt = RepeatedPrompt(100000);
  const auto r = SplitPrompt(prompt);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(r.status().message(),
              HasSubstr(fmt::format("prompt ({}) exceeds the limit max_prompt_bytes = 4096",
                                    prompt.size())));
}

TEST(SplitPromptTest, PhrasesBeyondTheLimitAreRefusedDuplicatesIncluded) {
  // 65 phrases of "a" are 193 bytes: within max_prompt_bytes, one phrase too many.
  std::string prompt = "a";
  for (int i = 1; i < 65; ++i) prompt += ",a";
  const auto r = SplitPrompt(prompt);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(r.status().message(),
              HasSubstr("phrases in the prompt (65) exceeds the limit max_prompt_phrases = 64"));
  EXPECT_TRUE(SplitPrompt(prompt.substr(2)).ok());  // 64 phrases
  {
    const ScopedLimit more(MaxPromptPhrases(), 100);
    const auto raised = SplitPrompt(prompt);
    ASSERT_TRUE(raised.ok()) << raised.status().ToString();
    EXPECT_EQ(*raised, std::vector<std::string>{"a"});
  }
  const ScopedLimit fewer_bytes(MaxPromptBytes(), 5);
  EXPECT_EQ(SplitPrompt("tomato").status().code(), StatusCode::kResourceExhausted);
  EXPECT_TRUE(SplitPrompt("apple").ok());
}

TEST(SegmenterRegistryTest, BuildsEveryBuiltinAndRejectsUnknownNames) {
  const SegmenterRegistry registry = BuiltinSegmenters();
  EXPECT_EQ(registry.Names(), (std::vector<std::string>{"oracle", "oracle-perfect", "color"}));
  for (const SegmenterEntry& e : registry.entries()) {
    EXPECT_FALSE(e.description.empty()) << e.name;
    EXPECT_TRUE(e.options.has_fields()) << e.name;
    const auto s = registry.Make(e.name, 1);
    ASSERT_TRUE(s.ok()) << e.name << ": " << s.status().ToString();
    EXPECT_EQ((*s)->name(), e.name == "oracle-perfect" ? "oracle" : e.name);
  }
  const auto bad = registry.Make("yolo-world", 1);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(bad.status().message(),
              HasSubstr("unknown segmenter 'yolo-world' (known: oracle, oracle-perfect, color)"));
  SegmenterRegistry again = BuiltinSegmenters();
  EXPECT_THROW(RegisterBuiltinSegmenters(again), Error);
}

TEST(SegmenterRegistryTest, OptionsStartFromTheEntrysDefaults) {
  const SegmenterRegistry registry = BuiltinSegmenters();
  // oracle-perfect is the oracle with OracleOptions::Perfect() as its defaults.
  EXPECT_EQ(registry.Options("oracle-perfect")->As<OracleOptions>().p_false_positive, 0.0);
  EXPECT_EQ(registry.Options("oracle")->As<OracleOptions>().p_false_positive,
            OracleOptions{}.p_false_positive);
  const auto o = registry.Options("oracle", {{"p_merge", "0"}, {"fruit_words", "tomato,apple"}});
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  EXPECT_EQ(o->As<OracleOptions>().p_merge, 0.0);
  EXPECT_EQ(o->As<OracleOptions>().fruit_words, (std::vector<std::string>{"tomato", "apple"}));
  EXPECT_THAT(registry.Options("oracle", {{"v_full", "0.01"}}).status().message(),
              HasSubstr("v_full (0.01) must be >= v_min (0.05)"));
  EXPECT_THAT(registry.Options("color", {{"p_merge", "0"}}).status().message(),
              HasSubstr("unknown color option 'p_merge' (known: min_saturation"));
  const auto seg = registry.Make("oracle", *o, {.seed = 3});
  ASSERT_TRUE(seg.ok());
}

TEST(SegmenterRegistryTest, RegisteredNamesAndSchemesAreBuiltByTheirFactories) {
  std::vector<std::pair<std::string, uint64_t>> calls;
  SegmenterRegistry registry = BuiltinSegmenters();
  auto add = [&](const char* name) {
    SegmenterEntry e;
    e.name = name;
    e.description = "test";
    e.make = [&calls, &registry](std::string_view spec, const AnyOptions&,
                                 const SegmenterContext& c) -> Result<std::unique_ptr<Segmenter>> {
      calls.emplace_back(std::string(spec), c.seed);
      return registry.Make("color", c.seed);
    };
    ASSERT_TRUE(registry.Add(std::move(e)).ok());
  };
  add("test-named");
  add("test-scheme://");
  ASSERT_TRUE(registry.Make("test-named", 7).ok());
  ASSERT_TRUE(registry.Make("test-scheme://host:1234", 9).ok());
  ASSERT_EQ(calls.size(), 2u);
  EXPECT_EQ(calls[0], std::make_pair(std::string("test-named"), uint64_t{7}));
  EXPECT_EQ(calls[1], std::make_pair(std::string("test-scheme://host:1234"), uint64_t{9}));
  // A name is matched exactly, only schemes by prefix; the error lists both kinds.
  const auto bad = registry.Make("test-named-not", 1);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("test-named, test-scheme://..."));
  EXPECT_NE(registry.Find("test-scheme://anything"), nullptr);
  EXPECT_NE(registry.Find("oracle"), nullptr);
  EXPECT_EQ(registry.Find("test-named-not"), nullptr);
  SegmenterEntry duplicate;
  duplicate.name = "oracle";
  EXPECT_THAT(registry.Add(duplicate).message(), HasSubstr("already registered"));
  // A component without options refuses any.
  EXPECT_THAT(registry.Options("test-named", {{"x", "1"}}).status().message(),
              HasSubstr("segmenter 'test-named' has no options (given: x = 1)"));
}

// ---- The contract
// --------------------------------------------------------------------------------

struct ContractCase {
  std::string name;   ///< MakeSegmenter name
  bool reads_labels;  ///< needs SimulatorLabels (and checks their size)
  bool noisy;         ///< results vary with frame_index
};

std::ostream& operator<<(std::ostream& os, const ContractCase& c) { return os << c.name; }

/// A 96 x 72 frame: a green leaf across the middle, four red fruits (two touching, one partly
/// behind the leaf) on grey, labels to match.
TestScene ContractScene() {
  TestScene s(96, 72, 80.0);
  s.PaintFruit(20, 20, 8, 1);
  s.PaintFruit(36, 20, 8, 2);  // touches fruit 1
  s.PaintFruit(75, 18, 9, 3);
  s.PaintFruit(30, 52, 9, 4);
  s.PaintRect(0, 40, 60, 50, 10, SemanticClass::kLeaf, {150, 190, 40});  // covers part of fruit 4
  s.PaintRect(60, 44, 96, 72, 11, SemanticClass::kLeaf, {170, 200, 20});
  return s;
}

class SegmenterContractTest : public ::testing::TestWithParam<ContractCase> {
 protected:
  std::unique_ptr<Segmenter> Make(uint64_t seed = 7) const {
    auto s = BuiltinSegmenters().Make(GetParam().name, seed);
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    return std::move(s).value();
  }
  TestScene scene_ = ContractScene();
};

TEST_P(SegmenterContractTest, OutputValidatesForTheFrameWithConfidencesInUnitRange) {
  auto seg = Make();
  size_t total = 0;
  for (uint64_t i = 0; i < 8; ++i) {
    const auto r = seg->Segment(scene_.Request("tomato", i));
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_TRUE(r->ValidateFor(96, 72).ok()) << r->ValidateFor(96, 72).ToString();
    for (const InstanceMask& m : r->instances) {
      EXPECT_GE(m.confidence, 0.0f);
      EXPECT_LE(m.confidence, 1.0f);
      EXPECT_EQ(m.semantic_class, SemanticClass::kFruit);
      EXPECT_EQ(m.label, "tomato");
      EXPECT_GT(test::Centroid(m.mask).x(), -1.0) << "empty mask";
    }
    total += r->instances.size();
  }
  // Four red fruits: every segmenter finds some of them in 8 frames.
  EXPECT_GE(total, 8u);
}

TEST_P(SegmenterContractTest, AnInterruptStopsTheWorkWithItsStatus) {
  auto seg = Make();
  // Stopped at once: the interrupt's own status comes back.
  SegmentationRequest r = scene_.Request("tomato", 0);
  int asked = 0;
  r.interrupt = [&asked]() -> Status {
    ++asked;
    return CancelledError("the client left");
  };
  const auto stopped = seg->Segment(r);
  ASSERT_FALSE(stopped.ok());
  EXPECT_EQ(stopped.status().code(), StatusCode::kCancelled);
  EXPECT_THAT(stopped.status().message(), HasSubstr("the client left"));
  EXPECT_GE(asked, 1);
  // Stopped later, after the first question: the deadline's status.
  asked = 0;
  r.interrupt = [&asked]() -> Status {
    return ++asked > 1 ? DeadlineExceededError("deadline passed") : Status::Ok();
  };
  const auto late = seg->Segment(r);
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.status().code(), StatusCode::kDeadlineExceeded);
  // An interrupt that never fires changes nothing.
  SegmentationRequest plain = scene_.Request("tomato", 0);
  SegmentationRequest asked_ok = plain;
  asked_ok.interrupt = [] { return Status::Ok(); };
  const auto a = seg->Segment(plain);
  const auto b = seg->Segment(asked_ok);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_TRUE(test::SameSegmentation(*a, *b));
}

TEST_P(SegmenterContractTest, DuplicatePhrasesGiveTheResultsOfOne) {
  auto seg = Make();
  const auto once = seg->Segment(scene_.Request("tomato", 2));
  const auto thrice = seg->Segment(scene_.Request("tomato, tomato,tomato", 2));
  ASSERT_TRUE(once.ok() && thrice.ok());
  EXPECT_TRUE(test::SameSegmentation(*once, *thrice));
  const auto huge = seg->Segment(scene_.Request(std::string(5000, 'a'), 2));
  ASSERT_FALSE(huge.ok());
  EXPECT_EQ(huge.status().code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(huge.status().message(), HasSubstr("max_prompt_bytes"));
}

TEST_P(SegmenterContractTest, SameSeedAndFrameIndexGiveIdenticalResults) {
  auto a = Make(11);
  auto b = Make(11);
  for (uint64_t i : {0u, 3u, 12u}) {
    const auto ra = a->Segment(scene_.Request("tomato", i));
    const auto rb = b->Segment(scene_.Request("tomato", i));
    ASSERT_TRUE(ra.ok() && rb.ok());
    EXPECT_TRUE(test::SameSegmentation(*ra, *rb)) << "frame " << i;
  }
}

TEST_P(SegmenterContractTest, ResultsDoNotDependOnCallOrder) {
  auto fresh = Make();
  auto used = Make();
  for (uint64_t i = 0; i < 5; ++i) ASSERT_TRUE(used->Segment(scene_.Request("tomato", i)).ok());
  const auto a = fresh->Segment(scene_.Request("tomato", 5));
  const auto b = used->Segment(scene_.Request("tomato", 5));
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_TRUE(test::SameSegmentation(*a, *b));
}

TEST_P(SegmenterContractTest, FrameIndexChangesResultsOnlyForNoisySegmenters) {
  auto seg = Make();
  const auto first = seg->Segment(scene_.Request("tomato", 0));
  ASSERT_TRUE(first.ok());
  int differing = 0;
  for (uint64_t i = 1; i < 16; ++i) {
    const auto r = seg->Segment(scene_.Request("tomato", i));
    ASSERT_TRUE(r.ok());
    EXPECT_TRUE(r->ValidateFor(96, 72).ok());
    differing += test::SameSegmentation(*first, *r) ? 0 : 1;
  }
  if (GetParam().noisy) {
    EXPECT_GE(differing, 10);  // confidences alone differ almost surely
  } else {
    EXPECT_EQ(differing, 0);
  }
}

TEST_P(SegmenterContractTest, NullFrameIsAnInvalidArgument) {
  auto seg = Make();
  SegmentationRequest request = scene_.Request();
  request.frame = nullptr;
  const auto r = seg->Segment(request);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("frame is null"));
}

TEST_P(SegmenterContractTest, ImageSizeDifferentFromTheIntrinsicsIsAnErrorNamingTheSizes) {
  auto seg = Make();
  RgbdFrame bad = scene_.frame;
  bad.rgb = ImageRgb8(50, 40, 0);
  SegmentationRequest request = scene_.Request();
  request.frame = &bad;
  const auto r = seg->Segment(request);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("50x40"));
  EXPECT_THAT(r.status().message(), HasSubstr("96x72"));
}

TEST_P(SegmenterContractTest, LabelSizeDifferentFromTheImageIsAnErrorForLabelReaders) {
  auto seg = Make();
  SimulatorLabels small = scene_.labels;
  small.instance_ids = InstanceImage(48, 36, 0);
  SegmentationRequest request = scene_.Request();
  request.labels = &small;
  const auto r = seg->Segment(request);
  if (GetParam().reads_labels) {
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(r.status().message(), HasSubstr("48x36"));
    EXPECT_THAT(r.status().message(), HasSubstr("96x72"));
  } else {
    ASSERT_TRUE(r.ok()) << "segmenters that do not read labels ignore them: "
                        << r.status().ToString();
    EXPECT_TRUE(r->ValidateFor(96, 72).ok());
  }
}

TEST_P(SegmenterContractTest, MissingLabelsFailOnlyForLabelReaders) {
  auto seg = Make();
  SegmentationRequest request = scene_.Request();
  request.labels = nullptr;
  const auto r = seg->Segment(request);
  if (GetParam().reads_labels) {
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_THAT(
        r.status().message(),
        HasSubstr("the oracle segmenter reads the simulator's labels, and this frame has none"));
  } else {
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_FALSE(r->instances.empty());
  }
}

TEST_P(SegmenterContractTest, EmptyPromptIsAnInvalidArgument) {
  auto seg = Make();
  for (const std::string prompt : {"", " ,  , "}) {
    const auto r = seg->Segment(scene_.Request(prompt));
    ASSERT_FALSE(r.ok()) << "\"" << prompt << "\"";
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(r.status().message(), HasSubstr("prompt"));
  }
}

TEST_P(SegmenterContractTest, UnknownPhraseGivesNoInstancesButNoError) {
  auto seg = Make();
  const auto r = seg->Segment(scene_.Request("bicycle"));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->instances.empty());
  EXPECT_TRUE(r->ValidateFor(96, 72).ok());
}

TEST_P(SegmenterContractTest, ScoreThresholdDropsLowerScoresAndIsValidated) {
  auto seg = Make();
  size_t kept = 0;
  size_t all = 0;
  for (uint64_t i = 0; i < 8; ++i) {
    SegmentationRequest request = scene_.Request("tomato", i);
    const auto unfiltered = seg->Segment(request);
    request.score_threshold = 0.96f;
    const auto filtered = seg->Segment(request);
    ASSERT_TRUE(unfiltered.ok() && filtered.ok());
    for (const InstanceMask& m : filtered->instances) EXPECT_GE(m.confidence, 0.96f);
    size_t expected = 0;
    for (const InstanceMask& m : unfiltered->instances) expected += m.confidence >= 0.96f ? 1 : 0;
    EXPECT_EQ(filtered->instances.size(), expected);
    kept += filtered->instances.size();
    all += unfiltered->instances.size();
  }
  EXPECT_LT(kept, all);  // every segmenter reports some scores below 0.96 here
  for (float bad : {-0.1f, 1.5f, std::numeric_limits<float>::quiet_NaN()}) {
    SegmentationRequest request = scene_.Request();
    request.score_threshold = bad;
    const auto r = seg->Segment(request);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(r.status().message(), HasSubstr("score_threshold"));
  }
}

INSTANTIATE_TEST_SUITE_P(AllSegmenters, SegmenterContractTest,
                         ::testing::Values(ContractCase{"oracle", true, true},
                                           ContractCase{"oracle-perfect", true, false},
                                           ContractCase{"color", false, false}),
                         [](const ::testing::TestParamInfo<ContractCase>& param) {
                           std::string name = param.param.name;
                           for (char& c : name) {
                             if (c == '-') c = '_';
                           }
                           return name;
                         });

}  // namespace
}  // namespace avp::segmentation

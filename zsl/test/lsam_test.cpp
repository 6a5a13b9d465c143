// LsamSegmenter end to end on the Grounding DINO stub of make_stubs.py: logits[0, q, t] = +10 when
// query q is planted with the bucket (input_ids[t] mod 97) and the token is attended, else −10;
// boxes[0, q] = the planted normalised (cx, cy, w, h). With the stub vocabulary, "tomato" (id 1100,
// bucket 33) lights query 7 at (0.25, 0.25, 0.2, 0.3), "leaf" (1101) query 123 at (0.5, 0.5, 0.4,
// 0.2), "stem" (1102) query 899 at (0.1, 0.9, 0.2, 0.2), and "cat" / "dog" (1103 / 1104) both
// light query 456 at (0.75, 0.6, 0.1, 0.1). The SAM stubs are those of ywes_test.cpp.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/camera.h>
#include <avp/core/rgbd_frame.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/zsl/lsam_segmenter.h>
#include <avp/zsl/register.h>

#include "ort_runtime.h"
#include "shared_stages.h"

namespace avp::zsl {
namespace {

namespace fs = std::filesystem;
using segmentation::SegmentationRequest;
using ::testing::HasSubstr;
using ::testing::StartsWith;

const fs::path kStubs = AVP_ZSL_STUB_DIR;
const float kHit = 1.f / (1.f + std::exp(-10.f));  // sigmoid(+10) = 0.9999546

LsamOptions CpuOptions() {
  LsamOptions o;
  o.session.device = Device::kCpu;
  o.session.intra_op_threads = 1;
  return o;
}

std::unique_ptr<LsamSegmenter> MakeLsam(const LsamOptions& options = CpuOptions()) {
  Result<std::unique_ptr<LsamSegmenter>> s = LsamSegmenter::Create(kStubs / "lsam", options);
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  return s.ok() ? std::move(s).value() : nullptr;
}

RgbdFrame GreyFrame(int w, int h) {
  RgbdFrame f;
  f.rgb = ImageRgb8(w, h, 128);
  f.depth_m = DepthImage(w, h, 0.f);
  f.K = CameraIntrinsics::FromHorizontalFov(w, h, 60.0);
  return f;
}

SegmentationRequest Request(const RgbdFrame& frame, const std::string& prompt) {
  SegmentationRequest r;
  r.frame = &frame;
  r.prompt = prompt;
  return r;
}

/// The planted normalised box (cx, cy, w, h) in pixels of a w x h image, clipped.
PixelBox Pixels(float cx, float cy, float bw, float bh, int w, int h) {
  const auto clip = [](float v, int hi) { return std::clamp(v, 0.f, static_cast<float>(hi)); };
  return {clip((cx - bw / 2) * w, w), clip((cy - bh / 2) * h, h), clip((cx + bw / 2) * w, w),
          clip((cy + bh / 2) * h, h)};
}

void ExpectBoxNear(const PixelBox& got, const PixelBox& want) {
  EXPECT_NEAR(got.x0, want.x0, 1e-3f);
  EXPECT_NEAR(got.y0, want.y0, 1e-3f);
  EXPECT_NEAR(got.x1, want.x1, 1e-3f);
  EXPECT_NEAR(got.y1, want.y1, 1e-3f);
}

/// As ExpectedStubMask1024x768 in ywes_test.cpp (see the derivation there): the stub decoder's
/// rectangle on the 4-px grid of a 1024x768 image, less its corners off the prompt frame border.
MaskImage ExpectedStubMask1024x768(const PixelBox& box) {
  const auto lit = [](float lo, float hi) {
    int first = -1, last = -1;
    for (int j = 0; j < 256; ++j) {
      const float centre = 4.f * (static_cast<float>(j) + 0.5f);
      if (lo <= centre && centre <= hi) {
        if (first < 0) first = j;
        last = j;
      }
    }
    return std::pair<int, int>(first, last);
  };
  const auto [c0, c1] = lit(box.x0, box.x1);
  const auto [r0, r1] = lit(box.y0, box.y1);
  MaskImage m(1024, 768, 0);
  if (c0 < 0 || r0 < 0) return m;
  const int x0 = 4 * c0, x1 = 4 * (c1 + 1), y0 = 4 * r0, y1 = std::min(768, 4 * (r1 + 1));
  for (int v = y0; v < y1; ++v) {
    for (int u = x0; u < x1; ++u) {
      const bool corner_x = (u == x0 && x0 > 0) || (u == x1 - 1 && x1 < 1024);
      const bool corner_y = (v == y0 && y0 > 0) || (v == y1 - 1 && y1 < 1024);
      if (!(corner_x && corner_y)) m.at(u, v) = 255;
    }
  }
  return m;
}

TEST(LsamTest, CreatesFromTheStubs) {
  auto s = MakeLsam();
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->name(), "lsam");
  EXPECT_EQ(s->sam().encoder_size(), 512);
  EXPECT_EQ(s->grounding().provider(), kCpuProvider);
  EXPECT_EQ(s->options().box_threshold, 0.3f);
  EXPECT_EQ(s->options().text_threshold, 0.25f);
}

TEST(LsamTest, EachPhraseLightsItsPlantedQueryWithItsBoxInPixels) {
  auto s = MakeLsam();
  ASSERT_NE(s, nullptr);
  for (const auto& [w, h] : {std::pair{640, 480}, std::pair{1200, 800}, std::pair{333, 517}}) {
    SCOPED_TRACE(::testing::Message() << w << "x" << h);
    Result<Grounding> g = s->Ground(ImageRgb8(w, h, 128), "Tomato, leaf ,stem");
    ASSERT_TRUE(g.ok()) << g.status().ToString();
    ASSERT_EQ(g->boxes.size(), 3u);
    // Equal scores: query order.
    EXPECT_EQ(g->boxes[0].query, 7);
    EXPECT_EQ(g->boxes[0].phrase, "tomato");
    ExpectBoxNear(g->boxes[0].box, Pixels(0.25f, 0.25f, 0.2f, 0.3f, w, h));
    EXPECT_EQ(g->boxes[1].query, 123);
    EXPECT_EQ(g->boxes[1].phrase, "leaf");
    ExpectBoxNear(g->boxes[1].box, Pixels(0.5f, 0.5f, 0.4f, 0.2f, w, h));
    EXPECT_EQ(g->boxes[2].query, 899);
    EXPECT_EQ(g->boxes[2].phrase, "stem");
    ExpectBoxNear(g->boxes[2].box, Pixels(0.1f, 0.9f, 0.2f, 0.2f, w, h));  // clipped at x = 0
    for (const GroundedBox& b : g->boxes) EXPECT_FLOAT_EQ(b.score, kHit);
  }
  // 640x480 by hand: tomato (0.15·640, 0.1·480)–(0.35·640, 0.4·480) = (96, 48)–(224, 192).
  Result<Grounding> g = s->Ground(ImageRgb8(640, 480, 128), "tomato");
  ASSERT_TRUE(g.ok());
  ASSERT_EQ(g->boxes.size(), 1u);
  ExpectBoxNear(g->boxes[0].box, PixelBox{96, 48, 224, 192});
  EXPECT_EQ(g->timings.size(), 4u);
}

TEST(LsamTest, AQueryLitByTwoPhrasesTakesTheFirstBestOne) {
  auto s = MakeLsam();
  ASSERT_NE(s, nullptr);
  for (const auto& [prompt, phrase] : {std::pair{"cat, dog", "cat"}, std::pair{"dog, cat", "dog"},
                                       std::pair{"leaf, dog", "dog"}}) {
    Result<Grounding> g = s->Ground(ImageRgb8(640, 480, 128), prompt);
    ASSERT_TRUE(g.ok()) << g.status().ToString();
    const auto q456 = std::find_if(g->boxes.begin(), g->boxes.end(),
                                   [](const GroundedBox& b) { return b.query == 456; });
    ASSERT_NE(q456, g->boxes.end()) << prompt;
    EXPECT_EQ(q456->phrase, phrase) << prompt;
  }
}

TEST(LsamTest, BoxAndTextThresholdsApply) {
  // Scores are sigmoid(10) = 0.9999546 (lit) or sigmoid(−10) = 4.5e−5.
  LsamOptions o = CpuOptions();
  o.box_threshold = 0.99996f;
  auto strict_box = MakeLsam(o);
  ASSERT_NE(strict_box, nullptr);
  EXPECT_TRUE(strict_box->Ground(ImageRgb8(64, 48, 0), "tomato, leaf")->boxes.empty());
  o.box_threshold = 0.99995f;
  auto loose_box = MakeLsam(o);
  EXPECT_EQ(loose_box->Ground(ImageRgb8(64, 48, 0), "tomato, leaf")->boxes.size(), 2u);

  o = CpuOptions();
  o.text_threshold = 0.99996f;
  auto strict_text = MakeLsam(o);
  EXPECT_TRUE(strict_text->Ground(ImageRgb8(64, 48, 0), "tomato")->boxes.empty());

  // Thresholds of 0 keep every query (sigmoid(−10) = 4.5e−5 > 0) whose box is not empty: the
  // four planted ones (the other 896 have zero boxes), best first, then by query.
  o = CpuOptions();
  o.box_threshold = 0.f;
  o.text_threshold = 0.f;
  auto all = MakeLsam(o);
  Result<Grounding> g = all->Ground(ImageRgb8(64, 48, 0), "tomato");
  ASSERT_TRUE(g.ok());
  ASSERT_EQ(g->boxes.size(), 4u);
  EXPECT_EQ(g->boxes[0].query, 7);
  EXPECT_EQ(g->boxes[1].query, 123);
  EXPECT_EQ(g->boxes[2].query, 456);
  EXPECT_EQ(g->boxes[3].query, 899);
  EXPECT_FLOAT_EQ(g->boxes[1].score, 1.f / (1.f + std::exp(10.f)));
  o.max_detections = 2;
  auto capped = MakeLsam(o);
  EXPECT_EQ(capped->Ground(ImageRgb8(64, 48, 0), "tomato")->boxes.size(), 2u);

  // A phrase no query knows gives no boxes ("apple" is [UNK] in the stub vocabulary).
  auto s = MakeLsam();
  EXPECT_TRUE(s->Ground(ImageRgb8(64, 48, 0), "apple")->boxes.empty());
}

TEST(LsamTest, SegmentGivesExactMasksOnA1024x768Image) {
  auto s = MakeLsam();
  ASSERT_NE(s, nullptr);
  const RgbdFrame frame = GreyFrame(1024, 768);
  Result<Segmentation> seg = s->Segment(Request(frame, "tomato, leaf"));
  ASSERT_TRUE(seg.ok()) << seg.status().ToString();
  EXPECT_TRUE(seg->ValidateFor(1024, 768).ok());
  ASSERT_EQ(seg->instances.size(), 2u);
  const std::array<PixelBox, 2> boxes = {Pixels(0.25f, 0.25f, 0.2f, 0.3f, 1024, 768),
                                         Pixels(0.5f, 0.5f, 0.4f, 0.2f, 1024, 768)};
  const std::array<const char*, 2> labels = {"tomato", "leaf"};
  for (size_t i = 0; i < 2; ++i) {
    const InstanceMask& m = seg->instances[i];
    EXPECT_EQ(m.label, labels[i]);
    EXPECT_EQ(m.semantic_class, SemanticClass::kFruit);
    EXPECT_FLOAT_EQ(m.confidence, kHit);
    EXPECT_EQ(m.mask_score, 0.875f);
    ASSERT_TRUE(m.box.has_value());
    ExpectBoxNear(*m.box, boxes[i]);
    EXPECT_TRUE(m.mask == ExpectedStubMask1024x768(*m.box)) << labels[i];
  }
  std::vector<std::string> stages;
  for (const StageTiming& t : seg->timings) stages.push_back(t.stage);
  EXPECT_EQ(stages, (std::vector<std::string>{"tokenize", "preprocess", "grounding", "boxes",
                                              "sam_encoder", "sam_decoder", "masks"}));

  // The request threshold applies to the scores.
  SegmentationRequest strict = Request(frame, "tomato");
  strict.score_threshold = 1.f;
  Result<Segmentation> none = s->Segment(strict);
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->instances.empty());
  EXPECT_EQ(none->timings.size(), 4u) << "no SAM stages without boxes";
}

TEST(LsamTest, BadRequestsGiveStatusesNamingTheBadValue) {
  auto s = MakeLsam();
  ASSERT_NE(s, nullptr);
  RgbdFrame empty = GreyFrame(64, 48);
  empty.rgb = ImageRgb8();
  Result<Segmentation> r = s->Segment(Request(empty, "tomato"));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(), "lsam: the image (request.frame->rgb) is empty (0x0)");

  RgbdFrame mismatched = GreyFrame(64, 48);
  mismatched.rgb = ImageRgb8(60, 48, 0);
  r = s->Segment(Request(mismatched, "tomato"));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(),
            "lsam: RGB-D frame: rgb size 60x48 differs from intrinsics 64x48");

  const RgbdFrame frame = GreyFrame(64, 48);
  r = s->Segment(Request(frame, " ,"));
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), StartsWith("lsam: prompt ' ,' has no classes"));
  // A phrase with a "." would be split by Grounding DINO: refused by the tokenizer.
  r = s->Segment(Request(frame, "tomato. leaf"));
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), StartsWith("lsam: "));
}

TEST(LsamTest, CreateNamesWhatIsMissingOrWrong) {
  // A ywes directory has no grounding model.
  Result<std::unique_ptr<LsamSegmenter>> s = LsamSegmenter::Create(kStubs / "ywes", CpuOptions());
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(s.status().message(), StartsWith("lsam: model directory '" +
                                               (kStubs / "ywes").string() + "' is MISSING: "));
  EXPECT_THAT(s.status().message(), HasSubstr("lsam needs model role 'grounding' (gdino.ort/1)"));

  LsamOptions bad = CpuOptions();
  bad.box_threshold = 2.f;
  bad.max_detections = -1;
  s = LsamSegmenter::Create(kStubs / "lsam", bad);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s.status().message(), HasSubstr("box_threshold (2) must be in [0, 1]"));
  EXPECT_THAT(s.status().message(), HasSubstr("max_detections (-1) must be > 0"));
}

TEST(LsamTest, ConcurrentCallsGiveIdenticalResults) {
  auto s = MakeLsam();
  ASSERT_NE(s, nullptr);
  const RgbdFrame frame = GreyFrame(640, 480);
  const Result<Segmentation> reference = s->Segment(Request(frame, "tomato, leaf, stem, cat"));
  ASSERT_TRUE(reference.ok());
  ASSERT_EQ(reference->instances.size(), 4u);
  std::array<int, 4> identical{};
  std::vector<std::thread> threads;
  for (size_t t = 0; t < identical.size(); ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 20; ++i) {
        Result<Segmentation> r = s->Segment(Request(frame, "tomato, leaf, stem, cat"));
        if (!r.ok() || r->instances.size() != reference->instances.size()) continue;
        bool same = true;
        for (size_t k = 0; k < r->instances.size(); ++k) {
          same = same && r->instances[k].mask == reference->instances[k].mask &&
                 r->instances[k].label == reference->instances[k].label &&
                 r->instances[k].box == reference->instances[k].box;
        }
        identical[t] += same ? 1 : 0;
      }
    });
  }
  for (std::thread& th : threads) th.join();
  for (int n : identical) EXPECT_EQ(n, 20);
}

TEST(LsamTest, TheRegisteredSchemeBuildsIt) {
  segmentation::SegmenterRegistry registry;
  BackendSettings cpu;
  cpu.device = Device::kCpu;
  RegisterZslSegmenters(registry, cpu);
  auto made = registry.Make("lsam://" + (kStubs / "lsam").string(), 0);
  ASSERT_TRUE(made.ok()) << made.status().ToString();
  EXPECT_EQ((*made)->name(), "lsam");
  const RgbdFrame frame = GreyFrame(320, 240);
  Result<Segmentation> seg = (*made)->Segment(Request(frame, "leaf"));
  ASSERT_TRUE(seg.ok()) << seg.status().ToString();
  EXPECT_TRUE(seg->ValidateFor(320, 240).ok());
  ASSERT_EQ(seg->instances.size(), 1u);
  EXPECT_EQ(seg->instances[0].label, "leaf");
}

TEST(LsamTest, OptionsSetThroughTheRegistryReachTheBackend) {
  // Scores are sigmoid(10) = 0.9999546 (BoxAndTextThresholdsApply): a box_threshold above it
  // leaves no box; the option model_dir loads the stub models without a spec directory.
  segmentation::SegmenterRegistry registry;
  BackendSettings cpu;
  cpu.device = Device::kCpu;
  RegisterZslSegmenters(registry, cpu);
  const RgbdFrame frame = GreyFrame(320, 240);
  for (const auto& [threshold, expected] :
       std::vector<std::pair<std::string, size_t>>{{"0.99995", 1u}, {"0.99996", 0u}}) {
    Result<AnyOptions> options = registry.Options(
        "lsam", {{"model_dir", (kStubs / "lsam").string()}, {"box_threshold", threshold}});
    ASSERT_TRUE(options.ok()) << options.status().ToString();
    auto made = registry.Make("lsam", *options, {});
    ASSERT_TRUE(made.ok()) << made.status().ToString();
    EXPECT_EQ(dynamic_cast<LsamSegmenter&>(**made).options().box_threshold, std::stof(threshold));
    Result<Segmentation> seg = (*made)->Segment(Request(frame, "leaf"));
    ASSERT_TRUE(seg.ok()) << seg.status().ToString();
    EXPECT_EQ(seg->instances.size(), expected) << "box_threshold " << threshold;
  }
}

}  // namespace
}  // namespace avp::zsl

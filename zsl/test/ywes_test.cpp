// YwesSegmenter end to end on the stub models of make_stubs.py (read its docstring):
//  - detector: score[n, a] = clip(txt_feats[n] · P[:, a], 0, 1) · mean(R channel of `images`),
//    P one-hot at the planted (embedding dim k, anchor a_k) pairs, planted boxes at those anchors;
//  - CLIP text: the embedding of a phrase is the histogram of (BPE id mod 16), so after the L2
//    norm the single-letter words "a", "b", "c", "d" (ids 320..323) are e_0..e_3 and light
//    exactly the planted anchors a_0..a_3;
//  - SAM decoder: low-res pixel (i, j) = +10 inside the box prompt (x0 <= 4(j + 0.5) <= x1, the
//    same in y), else −10; IoU 0.875.
// The assertions are exact: they follow the planted numbers through every transform.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/camera.h>
#include <avp/core/options.h>
#include <avp/core/rgbd_frame.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/zsl/register.h>
#include <avp/zsl/ywes_segmenter.h>

#include "letterbox.h"
#include "manifest.h"
#include "sam_geometry.h"
#include "shared_stages.h"
#include "text_encoder.h"

namespace avp::zsl {
namespace {

namespace fs = std::filesystem;
using segmentation::SegmentationRequest;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::StartsWith;

const fs::path kStubs = AVP_ZSL_STUB_DIR;
using Rgb = std::array<uint8_t, 3>;
constexpr Rgb kRed200 = {200, 50, 10};  // R = 200: mean(R) of a letterboxed 1024x768 image = 0.7
constexpr float kIou = 0.875f;          // the stub decoder's iou_predictions

// ---- helpers
// -------------------------------------------------------------------------------------

YwesOptions CpuOptions() {
  YwesOptions o;
  o.session.device = Device::kCpu;
  o.session.intra_op_threads = 1;
  return o;
}

std::unique_ptr<YwesSegmenter> MakeYwes(const std::string& dir = "ywes",
                                        const YwesOptions& options = CpuOptions()) {
  Result<std::unique_ptr<YwesSegmenter>> s = YwesSegmenter::Create(kStubs / dir, options);
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  return s.ok() ? std::move(s).value() : nullptr;
}

/// A w x h frame of one colour, zero depth, a valid pinhole camera.
RgbdFrame SolidFrame(int w, int h, const Rgb& colour = kRed200) {
  RgbdFrame f;
  f.rgb = ImageRgb8(w, h);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      for (int c = 0; c < 3; ++c) f.rgb.at(u, v, c) = colour[static_cast<size_t>(c)];
    }
  }
  f.depth_m = DepthImage(w, h, 0.f);
  f.K = CameraIntrinsics::FromHorizontalFov(w, h, 60.0);
  return f;
}

/// The stub detector's score for a one-hot embedding e_k (in txt_feats row 0) at its planted
/// anchor a_k: mean(R) of the 640x640 input as ONNX Runtime computes it. The input is built here
/// by hand, independently of the pipeline: R = colour/255 on rows pad_top .. pad_top + rows − 1,
/// 114/255 elsewhere (the pad), as float(v) · float(1/255) like the manifest's scale. A solid
/// colour survives the bilinear resize unchanged, so the image region is constant. ORT's float
/// ReduceMean over 409,600 values differs from the exact mean by up to ~6e-4 (relative), so the
/// pipeline's score is compared with this reference exactly and with the analytic mean to 1e-3.
float StubScore(const Rgb& colour, int pad_top, int rows, int k = 1) {
  BackendLoadOptions load;
  load.session.device = Device::kCpu;
  load.session.intra_op_threads = 1;
  LoadedBackend b = LoadBackend(kBackendYwes, kStubs / "ywes", load);
  EXPECT_TRUE(b.ready()) << b.StateString();
  const size_t plane = 640 * 640;
  const float scale = 1.f / 255.f;
  std::vector<float> images(3 * plane);
  for (size_t c = 0; c < 3; ++c) {
    for (int y = 0; y < 640; ++y) {
      const bool in_image = y >= pad_top && y < pad_top + rows;
      const float v = (in_image ? static_cast<float>(colour[c]) : 114.f) * scale;
      std::fill_n(images.begin() + static_cast<std::ptrdiff_t>(c * plane + y * 640), 640, v);
    }
  }
  std::vector<float> feats(32 * 512, 0.f);
  feats[static_cast<size_t>(k)] = 1.f;
  const std::vector<InputTensor> inputs = {InputTensor::Float32("images", images, {1, 3, 640, 640}),
                                           InputTensor::Float32("txt_feats", feats, {1, 32, 512})};
  Result<std::vector<OutputTensor>> out = b.models.at(kRoleDetector).model.Run(inputs);
  EXPECT_TRUE(out.ok()) << out.status().ToString();
  constexpr std::array<size_t, 4> kAnchors = {10 * 80 + 20, 6400 + 20 * 40 + 10, 8000 + 5 * 20 + 15,
                                              8399};
  return out->front().f32[4 * 8400 + kAnchors[static_cast<size_t>(k)]];  // class row 0
}

/// StubScore of the default 1024x768 frame: 480 image rows of R = 200 from row 80; ≈ 0.7.
float StubScore1024x768() {
  static const float score = StubScore(kRed200, 80, 480);
  return score;
}

float Sigmoid(float x) { return 1.f / (1.f + std::exp(-x)); }

SegmentationRequest Request(const RgbdFrame& frame, const std::string& prompt) {
  SegmentationRequest r;
  r.frame = &frame;
  r.prompt = prompt;
  return r;
}

Segmentation SegmentOk(segmentation::Segmenter& s, const RgbdFrame& frame,
                       const std::string& prompt) {
  Result<Segmentation> r = s.Segment(Request(frame, prompt));
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  if (!r.ok()) return {};
  EXPECT_TRUE(r->ValidateFor(frame.rgb.width(), frame.rgb.height()).ok())
      << r->ValidateFor(frame.rgb.width(), frame.rgb.height()).ToString();
  return std::move(r).value();
}

/// The planted letterboxed boxes (make_stubs.py PLANTED_ANCHORS: cx, cy, w, h → corners).
constexpr std::array<PixelBox, 4> kPlantedLetterboxed = {
    PixelBox{132, 60, 196, 108},   // k = 0, anchor 10·80 + 20
    PixelBox{120, 264, 216, 392},  // k = 1, anchor 6400 + 20·40 + 10
    PixelBox{396, 101, 596, 251},  // k = 2, anchor 8000 + 5·20 + 15
    PixelBox{608, 608, 640, 640},  // k = 3, anchor 8399
};

/// The planted boxes in a 1024x768 source: r = 0.625, pad top 80 (d = 160), left 0; (x − 0,
/// y − 80) / 0.625, clipped. Box 3 lies in the bottom padding (y >= 560 + 80) and clips to nothing.
constexpr std::array<PixelBox, 3> kPlanted1024x768 = {
    PixelBox{211.2f, 0.f, 313.6f, 44.8f},  // y0 = −32 clipped to 0
    PixelBox{192.f, 294.4f, 345.6f, 499.2f},
    PixelBox{633.6f, 33.6f, 953.6f, 273.6f},
};

void ExpectBoxEq(const std::optional<PixelBox>& got, const PixelBox& want) {
  ASSERT_TRUE(got.has_value());
  EXPECT_FLOAT_EQ(got->x0, want.x0);
  EXPECT_FLOAT_EQ(got->y0, want.y0);
  EXPECT_FLOAT_EQ(got->x1, want.x1);
  EXPECT_FLOAT_EQ(got->y1, want.y1);
}

/// [first, last] of the low-res indices the stub decoder lights for prompt coordinates lo..hi:
/// lo <= 4(j + 0.5) <= hi, in float as the graph compares. {-1, -1} when none.
std::pair<int, int> LitRange(float lo, float hi) {
  int first = -1, last = -1;
  for (int j = 0; j < 256; ++j) {
    const float centre = 4.f * (static_cast<float>(j) + 0.5f);
    if (lo <= centre && centre <= hi) {
      if (first < 0) first = j;
      last = j;
    }
  }
  return {first, last};
}

/// The mask the stub chain gives for a source box of a 1024x768 image, derived by hand:
///  - the prompt frame is the image itself (1024/max(1024, 768) = 1; prompt_resized 1024x768), so
///    the box prompt is the box, the crop keeps the top 768 rows and the final resize is the
///    identity;
///  - the stub lights low-res columns first..last (LitRange) and rows likewise;
///  - the ×4 bilinear upsampling (align_corners=False) samples low-res (u + 0.5)/4 − 0.5: pixel
///    4·first takes 0.625 of the lit column (+2.5 > 0, on), pixel 4·first − 1 only 0.375 (−2.5,
///    off); likewise at 4·(last + 1) − 1 / 4·(last + 1). So the mask is columns 4·first ..
///    4·(last + 1) − 1 and rows 4·first_row .. 4·(last_row + 1) − 1 ...
///  - ... less its corners: there both weights are 0.625, −10 + 20·0.625² = −2.1875 < 0. An edge
///    on the border of the 1024² prompt frame (column 0 or 1023, row 0) is not a corner: the
///    sample clamps to the lit index there (weight 1).
/// For a box with corners on multiples of 4 (x0 = 4a), first = a and 4·first = x0: the mask is
/// then exactly the box's pixels x0 .. x1 − 1, y0 .. y1 − 1, less the four corners.
MaskImage ExpectedStubMask1024x768(const PixelBox& box) {
  const auto [c0, c1] = LitRange(box.x0, box.x1);
  const auto [r0, r1] = LitRange(box.y0, box.y1);
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

size_t CountNonzero(const MaskImage& m) {
  const auto d = m.data();
  return static_cast<size_t>(std::count_if(d.begin(), d.end(), [](uint8_t v) { return v != 0; }));
}

std::vector<std::string> StageNames(const Segmentation& s) {
  std::vector<std::string> names;
  for (const StageTiming& t : s.timings) names.push_back(t.stage);
  return names;
}

const InstanceMask* FindLabel(const Segmentation& s, const std::string& label) {
  for (const InstanceMask& m : s.instances) {
    if (m.label == label) return &m;
  }
  return nullptr;
}

// ---- creation
// ------------------------------------------------------------------------------------

TEST(YwesCreateTest, ReadsTheManifestConstants) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->name(), "ywes");
  EXPECT_FALSE(s->baked());
  EXPECT_EQ(s->max_classes(), 32);
  EXPECT_TRUE(s->baked_names().empty());
  ASSERT_NE(s->text_encoder(), nullptr);
  EXPECT_EQ(s->text_encoder()->dim(), 512);
  EXPECT_EQ(s->sam().encoder_size(), 512);
  EXPECT_EQ(s->sam().prompt_frame(), 1024);
  EXPECT_EQ(s->sam().low_res(), 256);
  EXPECT_EQ(s->sam().mask_threshold(), 0.f);
  EXPECT_EQ(s->sam().decoder_batch(), 0);  // [batch, points, 2]: one run for all boxes
  EXPECT_EQ(s->detector().provider(), kCpuProvider);
  EXPECT_EQ(s->model_dir(), kStubs / "ywes");
}

TEST(YwesCreateTest, OptionsAreValidatedNamingEveryBadField) {
  YwesOptions o = CpuOptions();
  o.score_threshold = -1.f;
  o.nms_iou = 2.f;
  o.max_detections = 0;
  o.session.intra_op_threads = -3;
  Result<std::unique_ptr<YwesSegmenter>> s = YwesSegmenter::Create(kStubs / "ywes", o);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.status().message(), HasSubstr("score_threshold (-1) must be in [0, 1]"));
  EXPECT_THAT(s.status().message(), HasSubstr("nms_iou (2) must be in [0, 1]"));
  EXPECT_THAT(s.status().message(), HasSubstr("max_detections (0) must be > 0"));
  EXPECT_THAT(s.status().message(), HasSubstr("intra_op_threads (-3) must be >= 0"));
}

TEST(YwesCreateTest, AMissingDirectoryIsNotFoundNamingIt) {
  Result<std::unique_ptr<YwesSegmenter>> s = YwesSegmenter::Create(kStubs / "nope", CpuOptions());
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(s.status().message(), StartsWith("ywes: model directory '" +
                                               (kStubs / "nope").string() + "' is MISSING: "));
}

struct WrongCase {
  const char* dir;
  StatusCode code;
  const char* expected;  ///< a substring naming the model role, the tensor and the expectation
  bool verify_sha256 = false;
};

void PrintTo(const WrongCase& c, std::ostream* os) { *os << "wrong/" << c.dir; }

class YwesWrongContractTest : public ::testing::TestWithParam<WrongCase> {};

TEST_P(YwesWrongContractTest, CreateFailsNamingTheModelAndTensor) {
  const WrongCase& c = GetParam();
  YwesOptions o = CpuOptions();
  o.verify_sha256 = c.verify_sha256;
  const fs::path dir = kStubs / "wrong" / c.dir;
  Result<std::unique_ptr<YwesSegmenter>> s = YwesSegmenter::Create(dir, o);
  ASSERT_FALSE(s.ok()) << c.dir;
  EXPECT_EQ(s.status().code(), c.code) << s.status().ToString();
  EXPECT_THAT(s.status().message(), StartsWith("ywes: model directory '" + dir.string() + "' is "));
  EXPECT_THAT(s.status().message(), HasSubstr(c.expected));
  EXPECT_EQ(s.status().message().find('\n'), std::string::npos) << "one line";
}

INSTANTIATE_TEST_SUITE_P(
    Stubs, YwesWrongContractTest,
    ::testing::Values(
        WrongCase{"renamed_input", StatusCode::kInvalidArgument,
                  "INVALID: detector: input 'images' is missing (the model has 'image', "
                  "'txt_feats'); yoloworld.txtfeats/1 expects images float32 [1,3,640,640]"},
        WrongCase{"int32_labels", StatusCode::kInvalidArgument,
                  "segmenter.decoder: input 'point_labels' is int32; evitsam.decoder.single/1 "
                  "expects float32"},
        WrongCase{"int32_input_ids", StatusCode::kInvalidArgument,
                  "text: input 'input_ids' is int32; clip.text/1 expects int64"},
        WrongCase{"wrong_rank", StatusCode::kInvalidArgument,
                  "detector: input 'txt_feats' has rank 2 ([32,512]); yoloworld.txtfeats/1 "
                  "expects rank 3 [1,N,512]"},
        WrongCase{"wrong_static_dim", StatusCode::kInvalidArgument,
                  "segmenter.encoder: output 'image_embeddings' has shape [1,256,32,32]; "
                  "evitsam.encoder/1 expects [1,256,64,64]"},
        WrongCase{"transposed_output", StatusCode::kInvalidArgument,
                  "detector: output 'output0' has shape [1,8400,36]; yoloworld.txtfeats/1 expects "
                  "[1,4+N,8400]"},
        WrongCase{"missing_output", StatusCode::kInvalidArgument,
                  "segmenter.decoder: output 'iou_predictions' is missing (the model has "
                  "'masks')"},
        WrongCase{"extra_input", StatusCode::kInvalidArgument,
                  "segmenter.decoder: input 'mask_input' (float32 [1,1,256,256]) is not part of "
                  "evitsam.decoder.single/1"},
        WrongCase{"truncated_file", StatusCode::kInvalidArgument,
                  "segmenter.decoder: ONNX Runtime cannot load '"},
        WrongCase{"size_mismatch", StatusCode::kInvalidArgument, " bytes; models.text.bytes says "},
        WrongCase{"missing_file", StatusCode::kNotFound,
                  "is MISSING: segmenter.encoder: model file '"},
        WrongCase{"sha256_mismatch", StatusCode::kInvalidArgument,
                  "; models.detector.sha256 says 0000000000000000", true},
        WrongCase{"declared_io_mismatch", StatusCode::kInvalidArgument,
                  "detector: input 'txt_feats' has shape [1,32,512]; the manifest declares "
                  "[1,16,512]"},
        WrongCase{"encoder_size_mismatch", StatusCode::kInvalidArgument,
                  "segmenter.encoder: preprocess.size [1024,1024] differs from the model's "
                  "input_image size [512,512] (S = 512)"},
        WrongCase{"n_max_mismatch", StatusCode::kInvalidArgument,
                  "detector: postprocess.n_max (16) differs from the model's N (32"}),
    [](const ::testing::TestParamInfo<WrongCase>& p) { return std::string(p.param.dir); });

TEST(YwesCreateTest, Sha256IsOnlyCheckedOnRequest) {
  EXPECT_NE(MakeYwes("wrong/sha256_mismatch"), nullptr);
}

// ---- the pipeline on planted content
// -------------------------------------------------------------

TEST(YwesPipelineTest, EachClassFiresAtItsPlantedAnchorWithExactBoxesAndMasks) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  const RgbdFrame frame = SolidFrame(1024, 768);
  // The letterbox of this frame, as the test derives it.
  const Letterbox lb = Letterbox::Compute(1024, 768);
  ASSERT_DOUBLE_EQ(lb.scale, 0.625);
  ASSERT_EQ(lb.pad_top, 80);
  ASSERT_EQ(lb.pad_left, 0);
  const std::array<const char*, 3> words = {"a", "b", "c"};
  for (size_t k = 0; k < words.size(); ++k) {
    SCOPED_TRACE(words[k]);
    const Segmentation seg = SegmentOk(*s, frame, words[k]);
    ASSERT_EQ(seg.instances.size(), 1u);
    const InstanceMask& m = seg.instances[0];
    EXPECT_EQ(m.label, words[k]);
    EXPECT_EQ(m.semantic_class, SemanticClass::kFruit);
    // confidence = 1 · mean(R): (480 rows of 200 + 160 rows of 114) / 640 / 255 = 0.7.
    EXPECT_EQ(m.confidence, StubScore(kRed200, 80, 480, static_cast<int>(k)));
    EXPECT_NEAR(m.confidence, 0.7f, 1e-3f);
    EXPECT_EQ(m.mask_score, kIou);
    // Exact un-letterboxing: (x − pad_left, y − pad_top) / r, clipped.
    ExpectBoxEq(m.box, kPlanted1024x768[k]);
    ExpectBoxEq(m.box, lb.ToSource(kPlantedLetterboxed[k]));
    // The mask: the box through the prompt frame, the stub, the upsampling, crop and resize.
    EXPECT_TRUE(m.mask == ExpectedStubMask1024x768(*m.box)) << CountNonzero(m.mask);
    EXPECT_EQ(StageNames(seg),
              (std::vector<std::string>{"tokenize", "text", "letterbox", "detector", "nms",
                                        "sam_encoder", "sam_decoder", "masks"}));
    for (const StageTiming& t : seg.timings) EXPECT_GE(t.ms, 0.0) << t.stage;
  }
  // Spot-check the derivation on box 1 = (192, 294.4)–(345.6, 499.2): lit columns 48..85 and rows
  // 74..124 → pixels 192..343 x 296..499, less 4 corners.
  const MaskImage expected = ExpectedStubMask1024x768(kPlanted1024x768[1]);
  EXPECT_EQ(CountNonzero(expected), 152u * 204u - 4u);
  EXPECT_EQ(expected.at(192, 297), 255);
  EXPECT_EQ(expected.at(192, 296), 0);  // a corner
  EXPECT_EQ(expected.at(191, 300), 0);
  EXPECT_EQ(expected.at(343, 400), 255);
  EXPECT_EQ(expected.at(344, 400), 0);
}

TEST(YwesPipelineTest, ABoxInThePaddingIsDroppedBeforeSam) {
  // "d" lights anchor a_3, whose box (608, 608)–(640, 640) lies in the bottom padding of a
  // 1024x768 frame: it clips to nothing, so there is no instance and SAM does not run.
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  const Segmentation seg = SegmentOk(*s, SolidFrame(1024, 768), "d");
  EXPECT_TRUE(seg.instances.empty());
  EXPECT_EQ(StageNames(seg),
            (std::vector<std::string>{"tokenize", "text", "letterbox", "detector", "nms"}));
  // In a square frame there is no padding: the box maps to (972.8, 972.8)–(1024, 1024).
  const Segmentation square = SegmentOk(*s, SolidFrame(1024, 1024), "d");
  ASSERT_EQ(square.instances.size(), 1u);
  ExpectBoxEq(square.instances[0].box, PixelBox{972.8f, 972.8f, 1024.f, 1024.f});
}

TEST(YwesPipelineTest, ABoxInThePaddingTakesNoDetectionPlace) {
  // With one place (max_detections 1), the padding box of "d" (score 1) must not take it from
  // the class "a b" (0.707 at a_0 and at a_1): it is dropped before NMS and the cut. Dropped
  // after the cut, it left nothing; a random-weight detector's best anchors all lie there.
  YwesOptions o = CpuOptions();
  o.max_detections = 1;
  auto s = MakeYwes("ywes", o);
  ASSERT_NE(s, nullptr);
  const Segmentation seg = SegmentOk(*s, SolidFrame(1024, 768), "d, a b");
  ASSERT_EQ(seg.instances.size(), 1u);
  EXPECT_EQ(seg.instances[0].label, "a b");
  ExpectBoxEq(seg.instances[0].box, kPlanted1024x768[0]);
}

TEST(YwesPipelineTest, ScoresProveRgbOrderScalingAndPadValue) {
  // score = mean of the R input plane over 640x640. A BGR feed, a missing ÷255 or a pad of 0
  // would each give another number.
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  struct Case {
    int w, h;
    Rgb colour;
    int pad_top, rows;  // of the 640x640 letterbox, derived by hand
    float expected;     // the exact mean(R)
  };
  const std::array<Case, 4> cases = {
      Case{1024, 768, {200, 50, 10}, 80, 480, 0.7f},  // (480·200 + 160·114) / 640 / 255
      Case{1024, 768, {10, 50, 200}, 80, 480, (480.f * 10 + 160.f * 114) / 640 / 255},  // R = 10
      Case{640, 640, {200, 50, 10}, 0, 640, 200.f / 255},                               // no pad
      // r = 0.64: 427 rows (round(426.88)), pad 213 split 106 / 107 (round(106.5 ∓ 0.1)).
      Case{1000, 667, {200, 50, 10}, 106, 427, (427.f * 200 + 213.f * 114) / 640 / 255},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(::testing::Message() << c.w << "x" << c.h << " R=" << int(c.colour[0]));
    const Segmentation seg = SegmentOk(*s, SolidFrame(c.w, c.h, c.colour), "b");
    ASSERT_EQ(seg.instances.size(), 1u);
    EXPECT_EQ(seg.instances[0].confidence, StubScore(c.colour, c.pad_top, c.rows));
    EXPECT_NEAR(seg.instances[0].confidence, c.expected, 1e-3f);
  }
  // The alternatives the scores rule out, for the 1024x768 frame: B instead of R gives 0.141,
  // a pad of 0 gives 0.588, no ÷255 saturates the clip at 1 and scores 178.5.
  const float score = SegmentOk(*s, SolidFrame(1024, 768), "b").instances.at(0).confidence;
  EXPECT_GT(std::abs(score - (480.f * 10 + 160.f * 114) / 640 / 255), 0.5f);
  EXPECT_GT(std::abs(score - 480.f * 200 / 640 / 255), 0.1f);
}

TEST(YwesPipelineTest, MultiClassPromptsKeepEachInstancesClass) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  const RgbdFrame frame = SolidFrame(1024, 768);
  for (const std::string prompt : {"c, a, b", "B , A,c", "a, b, c, d, zz"}) {
    SCOPED_TRACE(prompt);
    const Segmentation seg = SegmentOk(*s, frame, prompt);
    ASSERT_EQ(seg.instances.size(), 3u);
    const std::array<const char*, 3> words = {"a", "b", "c"};
    for (size_t k = 0; k < words.size(); ++k) {
      const InstanceMask* m = FindLabel(seg, words[k]);
      ASSERT_NE(m, nullptr) << words[k];
      ExpectBoxEq(m->box, kPlanted1024x768[k]);
      EXPECT_TRUE(m->mask == ExpectedStubMask1024x768(kPlanted1024x768[k]));
    }
  }
  // Equal scores: NMS keeps anchor order (a_0 < a_1 < a_2), whatever the prompt order.
  const Segmentation seg = SegmentOk(*s, frame, "c, b, a");
  ASSERT_EQ(seg.instances.size(), 3u);
  EXPECT_EQ(seg.instances[0].label, "a");
  EXPECT_EQ(seg.instances[1].label, "b");
  EXPECT_EQ(seg.instances[2].label, "c");
}

TEST(YwesPipelineTest, APhraseOfSeveralTokensFiresWhereItsNormalisedEmbeddingPoints) {
  // "a b" embeds as (e_0 + e_1)/√2: it scores 0.7/√2 at anchors a_0 and a_1, both its own.
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  const Segmentation seg = SegmentOk(*s, SolidFrame(1024, 768), "a b");
  ASSERT_EQ(seg.instances.size(), 2u);
  for (size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(seg.instances[k].label, "a b");
    EXPECT_NEAR(seg.instances[k].confidence, StubScore1024x768() / std::sqrt(2.f), 1e-6f);
    ExpectBoxEq(seg.instances[k].box, kPlanted1024x768[k]);
  }
}

TEST(YwesPipelineTest, UnusedTextFeatureSlotsAreZeroAndIgnored) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  Result<std::vector<float>> feats = s->TextFeatures("b, a b, a");
  ASSERT_TRUE(feats.ok()) << feats.status().ToString();
  ASSERT_EQ(feats->size(), 32u * 512u);
  const auto at = [&](size_t row, size_t col) { return (*feats)[row * 512 + col]; };
  EXPECT_EQ(at(0, 1), 1.f);  // "b" = e_1
  EXPECT_NEAR(at(1, 0), 1.f / std::sqrt(2.f), 1e-7f);
  EXPECT_NEAR(at(1, 1), 1.f / std::sqrt(2.f), 1e-7f);
  EXPECT_EQ(at(2, 0), 1.f);  // "a" = e_0
  for (size_t row = 3; row < 32; ++row) {
    for (size_t col = 0; col < 512; ++col) ASSERT_EQ(at(row, col), 0.f) << row << "," << col;
  }
  // With only slot 0 active ("c"), anchors a_0, a_1 and a_3 never fire although the head has
  // 32 score rows: one instance, class 0.
  const Segmentation seg = SegmentOk(*s, SolidFrame(1024, 1024), "c");
  ASSERT_EQ(seg.instances.size(), 1u);
  EXPECT_EQ(seg.instances[0].label, "c");
}

TEST(YwesPipelineTest, Image1000x667UnletterboxesExactlyAndMasksAreWithinOnePixel) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  const Segmentation seg = SegmentOk(*s, SolidFrame(1000, 667), "b");
  ASSERT_EQ(seg.instances.size(), 1u);
  const InstanceMask& m = seg.instances[0];
  // r = 0.64, 640x427, pad top round(106.5 − 0.1) = 106: (120, 264 − 106) / 0.64 etc.
  ExpectBoxEq(m.box, PixelBox{187.5f, 246.875f, 337.5f, 446.875f});
  // Mask: the stub's rectangle in the 1024x683 prompt frame, mapped back (x · 1000/1024,
  // y · 667/683), is within ±1 px of the mask: every mask pixel lies in the rectangle grown by
  // 1 px and every pixel of the rectangle shrunk by 1 px is in the mask.
  const SamTransform t = SamTransform::Compute(1000, 667, 512);
  const std::array<float, 4> p = SamBoxPromptCoords(*m.box, t);
  const auto [c0, c1] = LitRange(p[0], p[2]);
  const auto [r0, r1] = LitRange(p[1], p[3]);
  const double sx = static_cast<double>(t.prompt_resized_w) / 1000;
  const double sy = static_cast<double>(t.prompt_resized_h) / 667;
  const double bx0 = 4.0 * c0 / sx, bx1 = std::min(4.0 * (c1 + 1), 1.0 * t.prompt_resized_w) / sx;
  const double by0 = 4.0 * r0 / sy, by1 = std::min(4.0 * (r1 + 1), 1.0 * t.prompt_resized_h) / sy;
  size_t on = 0;
  for (int v = 0; v < 667; ++v) {
    for (int u = 0; u < 1000; ++u) {
      const bool outer = u + 1 > bx0 - 1 && u < bx1 + 1 && v + 1 > by0 - 1 && v < by1 + 1;
      const bool inner = u >= bx0 + 1 && u + 1 <= bx1 - 1 && v >= by0 + 1 && v + 1 <= by1 - 1;
      if (m.mask.at(u, v) != 0) {
        ++on;
        ASSERT_TRUE(outer) << u << "," << v;
      } else {
        ASSERT_FALSE(inner) << u << "," << v;
      }
    }
  }
  EXPECT_GT(on, 140u * 190u);
}

TEST(YwesPipelineTest, TheLogitVariantAppliesTheManifestsSigmoid) {
  auto s = MakeYwes("ywes_logits");
  ASSERT_NE(s, nullptr);
  const Segmentation seg = SegmentOk(*s, SolidFrame(1024, 768), "a, b");
  ASSERT_EQ(seg.instances.size(), 2u);
  // 20 · 0.7 − 10 = 4 → 1 / (1 + e^−4) = 0.982; the other anchors give sigmoid(−10) < 0.002.
  for (const InstanceMask& m : seg.instances) {
    EXPECT_NEAR(m.confidence, Sigmoid(20.f * StubScore1024x768() - 10.f), 1e-6f);
    EXPECT_NEAR(m.confidence, Sigmoid(4.f), 1e-4f);
  }
  ExpectBoxEq(FindLabel(seg, "b")->box, kPlanted1024x768[1]);
}

/// "a, b, c" on a 1024x768 frame with the plain stubs (`plain`) and with the stub set `variant`
/// (`other`): three instances each.
void SegmentPlainAndVariant(const std::string& variant, Segmentation& plain, Segmentation& other) {
  auto a = MakeYwes();
  auto b = MakeYwes(variant);
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  const RgbdFrame frame = SolidFrame(1024, 768);
  plain = SegmentOk(*a, frame, "a, b, c");
  other = SegmentOk(*b, frame, "a, b, c");
  ASSERT_EQ(plain.instances.size(), 3u);
  ASSERT_EQ(other.instances.size(), 3u);
}

TEST(YwesPipelineTest, TheTransposedLayoutGivesTheSameSegmentation) {
  Segmentation a, b;
  ASSERT_NO_FATAL_FAILURE(SegmentPlainAndVariant("ywes_transposed", a, b));
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(a.instances[i].label, b.instances[i].label);
    EXPECT_EQ(a.instances[i].confidence, b.instances[i].confidence);
    EXPECT_EQ(a.instances[i].box, b.instances[i].box);
    EXPECT_TRUE(a.instances[i].mask == b.instances[i].mask);
  }
}

TEST(YwesPipelineTest, TheOfficialExportShapesGiveTheSameSegmentation) {
  // The stubs with the I/O of the official exports (EfficientViT-SAM: a dynamic encoder batch
  // axis, symbolic 64 x 64 embeddings and 256 x 256 masks; YOLO-World: output0 [?,?,?]), the
  // docs' shapes stated in the manifest: they load and segment as the plain stubs do.
  Segmentation a, b;
  ASSERT_NO_FATAL_FAILURE(SegmentPlainAndVariant("ywes_official_shapes", a, b));
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(a.instances[i].box, b.instances[i].box);
    EXPECT_TRUE(a.instances[i].mask == b.instances[i].mask);
  }
}

TEST(YwesPipelineTest, ClassAwareNmsGivesTheSameResultForDisjointBoxes) {
  YwesOptions o = CpuOptions();
  o.class_agnostic_nms = false;
  auto s = MakeYwes("ywes", o);
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(SegmentOk(*s, SolidFrame(1024, 768), "a, b, c").instances.size(), 3u);
}

TEST(YwesPipelineTest, TheRequestThresholdDropsWeakerInstances) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  const RgbdFrame frame = SolidFrame(1024, 768);
  SegmentationRequest r = Request(frame, "a, a b");  // 0.7 at a_0 ("a"), 0.495 at a_1 ("a b")
  r.score_threshold = 0.6f;
  Result<Segmentation> seg = s->Segment(r);
  ASSERT_TRUE(seg.ok());
  ASSERT_EQ(seg->instances.size(), 1u);
  EXPECT_EQ(seg->instances[0].label, "a");
  r.score_threshold = 0.75f;
  seg = s->Segment(r);
  ASSERT_TRUE(seg.ok());
  EXPECT_TRUE(seg->instances.empty());
}

TEST(YwesPipelineTest, TheDetectorThresholdOptionApplies) {
  YwesOptions o = CpuOptions();
  o.score_threshold = 0.5f;
  auto s = MakeYwes("ywes", o);
  ASSERT_NE(s, nullptr);
  const Segmentation seg = SegmentOk(*s, SolidFrame(1024, 768), "a, a b");
  ASSERT_EQ(seg.instances.size(), 1u);  // 0.495 is not > 0.5
  EXPECT_EQ(seg.instances[0].label, "a");
}

// ---- baked vocabulary
// ------------------------------------------------------------------------------

TEST(YwesBakedTest, ThePromptSelectsAmongTheBakedNames) {
  auto s = MakeYwes("ywes_baked");
  ASSERT_NE(s, nullptr);
  EXPECT_TRUE(s->baked());
  EXPECT_EQ(s->max_classes(), 2);
  EXPECT_EQ(s->baked_names(), (std::vector<std::string>{"tomato", "leaf"}));
  EXPECT_EQ(s->text_encoder(), nullptr);
  const RgbdFrame frame = SolidFrame(1024, 768);

  // The stub fixes txt_feats to e_0 ("tomato": anchor a_0) and e_1 ("leaf": a_1).
  const Segmentation leaf = SegmentOk(*s, frame, "Leaf");
  ASSERT_EQ(leaf.instances.size(), 1u);
  EXPECT_EQ(leaf.instances[0].label, "leaf");
  EXPECT_EQ(leaf.instances[0].confidence, StubScore1024x768());
  ExpectBoxEq(leaf.instances[0].box, kPlanted1024x768[1]);
  EXPECT_TRUE(leaf.instances[0].mask == ExpectedStubMask1024x768(kPlanted1024x768[1]));
  EXPECT_EQ(StageNames(leaf), (std::vector<std::string>{"letterbox", "detector", "nms",
                                                        "sam_encoder", "sam_decoder", "masks"}));

  const Segmentation both = SegmentOk(*s, frame, "leaf, tomato");
  ASSERT_EQ(both.instances.size(), 2u);
  ExpectBoxEq(FindLabel(both, "tomato")->box, kPlanted1024x768[0]);
  ExpectBoxEq(FindLabel(both, "leaf")->box, kPlanted1024x768[1]);

  Result<Segmentation> unknown = s->Segment(Request(frame, "tomato, cat"));
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(unknown.status().message(),
              HasSubstr("ywes: class 'cat' is not in the detector's baked vocabulary (tomato, "
                        "leaf)"));
  Result<std::vector<float>> feats = s->TextFeatures("tomato");
  ASSERT_FALSE(feats.ok());
  EXPECT_EQ(feats.status().code(), StatusCode::kFailedPrecondition);
}

TEST(YwesBakedTest, TheBakedLogitVariantAppliesTheSigmoid) {
  auto s = MakeYwes("ywes_baked_logits");
  ASSERT_NE(s, nullptr);
  const Segmentation seg = SegmentOk(*s, SolidFrame(1024, 768), "tomato");
  ASSERT_EQ(seg.instances.size(), 1u);
  EXPECT_EQ(seg.instances[0].label, "tomato");
  EXPECT_NEAR(seg.instances[0].confidence, Sigmoid(20.f * StubScore1024x768() - 10.f), 1e-6f);
  ExpectBoxEq(seg.instances[0].box, kPlanted1024x768[0]);
}

// ---- prompts, cache, bad requests
// ----------------------------------------------------------------

TEST(YwesPromptTest, MoreClassesThanNMaxAreRefused) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  std::string prompt = "c0";
  for (int i = 1; i < 33; ++i) prompt += ", c" + std::to_string(i);
  const RgbdFrame frame = SolidFrame(64, 48);
  Result<Segmentation> r = s->Segment(Request(frame, prompt));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(r.status().message(),
            "ywes: prompt has 33 classes; the detector takes at most 32 (N_max)");
  // 32 is fine (and duplicates do not count).
  prompt = "c0";
  for (int i = 1; i < 32; ++i) prompt += ", c" + std::to_string(i);
  EXPECT_TRUE(s->Segment(Request(frame, prompt + ", C0, c31")).ok());
  EXPECT_EQ(s->PromptClasses(prompt)->size(), 32u);
}

TEST(YwesPromptTest, TheTextModelRunsOnlyForPhrasesNotYetCached) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  const TextEncoder& text = *s->text_encoder();
  const RgbdFrame frame = SolidFrame(64, 48);
  SegmentOk(*s, frame, "a, b");
  EXPECT_EQ(text.model_runs(), 1u);
  EXPECT_EQ(text.phrases_computed(), 2u);
  const Segmentation again = SegmentOk(*s, frame, "B, a");
  EXPECT_EQ(text.model_runs(), 1u) << "the second call does not run the text model";
  ASSERT_GE(again.timings.size(), 2u);
  EXPECT_EQ(again.timings[0].stage, "tokenize");
  EXPECT_EQ(again.timings[0].ms, 0.0);  // nothing to tokenize
  EXPECT_EQ(again.timings[1].stage, "text");
  SegmentOk(*s, frame, "a, c");
  EXPECT_EQ(text.model_runs(), 2u);
  EXPECT_EQ(text.phrases_computed(), 3u) << "only 'c' was new";
  EXPECT_EQ(text.cache_size(), 3u);
}

TEST(YwesPromptTest, BadRequestsGiveStatusesNamingTheBadValue) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  SegmentationRequest null_frame;
  Result<Segmentation> r = s->Segment(null_frame);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(), "ywes: request.frame is null");

  RgbdFrame empty = SolidFrame(64, 48);
  empty.rgb = ImageRgb8();
  r = s->Segment(Request(empty, "a"));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(r.status().message(), "ywes: the image (request.frame->rgb) is empty (0x0)");

  RgbdFrame mismatched = SolidFrame(64, 48);
  mismatched.depth_m = DepthImage(32, 24, 0.f);
  r = s->Segment(Request(mismatched, "a"));
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(r.status().message(),
            "ywes: RGB-D frame: depth size 32x24 differs from intrinsics 64x48");

  const RgbdFrame frame = SolidFrame(64, 48);
  for (const std::string prompt : {"", " , ,"}) {
    r = s->Segment(Request(frame, prompt));
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(r.status().message(), StartsWith("ywes: prompt '" + prompt + "' has no classes"));
  }

  SegmentationRequest bad_threshold = Request(frame, "a");
  bad_threshold.score_threshold = 1.5f;
  r = s->Segment(bad_threshold);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(), "ywes: request.score_threshold (1.5) must be in [0, 1]");
  bad_threshold.score_threshold = std::nanf("");
  EXPECT_FALSE(s->Segment(bad_threshold).ok());
}

TEST(YwesPromptTest, ConcurrentCallsGiveIdenticalResults) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  const RgbdFrame frame = SolidFrame(1024, 768);
  const std::string prompt = "a, b, c, a b";
  const Segmentation reference = SegmentOk(*s, frame, prompt);
  ASSERT_EQ(reference.instances.size(), 3u);  // "a b" loses to "a" / "b" at their anchors
  constexpr int kThreads = 4;
  constexpr int kCalls = 20;
  std::array<int, kThreads> identical{};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < kCalls; ++i) {
        Result<Segmentation> r = s->Segment(Request(frame, i % 2 == 0 ? prompt : "c, b, a b, a"));
        if (!r.ok() || r->instances.size() != reference.instances.size()) continue;
        bool same = true;
        for (size_t k = 0; k < r->instances.size(); ++k) {
          const InstanceMask& x = r->instances[k];
          const InstanceMask& y = reference.instances[k];
          same = same && x.mask == y.mask && x.label == y.label && x.confidence == y.confidence &&
                 x.box == y.box && x.mask_score == y.mask_score;
        }
        identical[static_cast<size_t>(t)] += same ? 1 : 0;
      }
    });
  }
  for (std::thread& th : threads) th.join();
  for (int t = 0; t < kThreads; ++t) EXPECT_EQ(identical[static_cast<size_t>(t)], kCalls) << t;
}

// ---- the SAM stage alone
// ---------------------------------------------------------------------------

TEST(SamBoxSegmenterTest, ABoxOnMultiplesOf4GivesTheRectangleLessItsFourCorners) {
  auto s = MakeYwes();
  ASSERT_NE(s, nullptr);
  const RgbdFrame frame = SolidFrame(1024, 768);
  const std::array<PixelBox, 2> boxes = {PixelBox{100, 200, 300, 500}, PixelBox{0, 0, 64, 32}};
  Result<SamBoxMasks> r = s->sam().Segment(frame.rgb, boxes);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->masks.size(), 2u);
  EXPECT_EQ(r->iou, (std::vector<float>{kIou, kIou}));
  // Columns 100..299, rows 200..499, less (100, 200), (299, 200), (100, 499), (299, 499).
  const MaskImage& m = r->masks[0];
  for (int v = 0; v < 768; ++v) {
    for (int u = 0; u < 1024; ++u) {
      const bool corner = (u == 100 || u == 299) && (v == 200 || v == 499);
      const bool inside = u >= 100 && u <= 299 && v >= 200 && v <= 499 && !corner;
      ASSERT_EQ(m.at(u, v), inside ? 255 : 0) << u << "," << v;
    }
  }
  // At the image's top-left the edge samples clamp: only the bottom-right corner is lost.
  EXPECT_EQ(CountNonzero(r->masks[1]), 64u * 32u - 1u);
  EXPECT_TRUE(r->masks[1] == ExpectedStubMask1024x768(boxes[1]));

  Result<SamBoxMasks> none = s->sam().Segment(frame.rgb, {});
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->masks.empty());
}

// ---- registration and the Segmenter contract ---------------------------------------------------

/// Sets (value) or unsets (nullptr) an environment variable for its lifetime.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) saved_ = old;
    if (value != nullptr) {
      setenv(name, value, 1);
    } else {
      unsetenv(name);
    }
  }
  ~ScopedEnv() {
    if (saved_) {
      setenv(name_.c_str(), saved_->c_str(), 1);
    } else {
      unsetenv(name_.c_str());
    }
  }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  std::string name_;
  std::optional<std::string> saved_;
};

BackendSettings CpuSettings() {
  BackendSettings s;
  s.device = Device::kCpu;
  s.threads = 1;
  return s;
}

segmentation::SegmenterRegistry CpuRegistry() {
  segmentation::SegmenterRegistry registry;
  RegisterZslSegmenters(registry, CpuSettings());
  return registry;
}

Result<std::unique_ptr<segmentation::Segmenter>> MakeWith(
    const segmentation::SegmenterRegistry& registry, const std::string& spec,
    const OptionValues& overrides) {
  AVP_ASSIGN_OR_RETURN(const AnyOptions options, registry.Options(spec, overrides));
  return registry.Make(spec, options, {});
}

TEST(YwesRegistrationTest, SchemesAndTheModelDirOptionNameTheModelDirectory) {
  const ScopedEnv no_dir("AVP_ZSL_MODEL_DIR", nullptr);
  segmentation::SegmenterRegistry registry = CpuRegistry();
  EXPECT_TRUE(nullptr != registry.Find("ywes"));
  EXPECT_TRUE(nullptr != registry.Find("lsam"));
  EXPECT_TRUE(nullptr != registry.Find("ywes:///opt/models"));
  EXPECT_TRUE(nullptr != registry.Find("lsam://models"));

  Result<fs::path> dir = ModelDirForSpec("ywes", "ywes:///opt/models", "/elsewhere");
  ASSERT_TRUE(dir.ok());
  EXPECT_EQ(*dir, fs::path("/opt/models"));  // the spec's DIR overrides the option
  EXPECT_EQ(ModelDirForSpec("ywes", "ywes", "/opt/m").value(), fs::path("/opt/m"));
  Result<fs::path> empty = ModelDirForSpec("ywes", "ywes://", "/opt/m");
  ASSERT_FALSE(empty.ok());
  EXPECT_THAT(empty.status().message(), HasSubstr("names no model directory"));

  auto missing = registry.Make("ywes", 0);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(missing.status().message(),
              HasSubstr("segmenter 'ywes' needs a model directory: set AVP_ZSL_MODEL_DIR to a "
                        "folder holding manifest.json"));
  EXPECT_THAT(missing.status().message(), HasSubstr("--segmenter-option model_dir=DIR"));
  EXPECT_THAT(missing.status().message(), HasSubstr("docs/zero-shot-models.md"));

  // The option model_dir loads the stub models without the environment variable.
  auto from_option = MakeWith(registry, "ywes", {{"model_dir", (kStubs / "ywes").string()}});
  ASSERT_TRUE(from_option.ok()) << from_option.status().ToString();
  EXPECT_EQ((*from_option)->name(), "ywes");
  auto* ywes = dynamic_cast<YwesSegmenter*>(from_option->get());
  ASSERT_NE(ywes, nullptr);
  EXPECT_EQ(ywes->model_dir(), kStubs / "ywes");
  // A ywes://DIR spec wins over the option.
  auto scheme = MakeWith(registry, "ywes://" + (kStubs / "ywes").string(),
                         {{"model_dir", (kStubs / "nope").string()}});
  EXPECT_TRUE(scheme.ok()) << scheme.status().ToString();

  auto nowhere = registry.Make("ywes://" + (kStubs / "nope").string(), 0);
  ASSERT_FALSE(nowhere.ok());
  EXPECT_EQ(nowhere.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(nowhere.status().message(), HasSubstr((kStubs / "nope").string()));
}

TEST(YwesRegistrationTest, OptionsSetThroughTheRegistryReachTheBackend) {
  const segmentation::SegmenterRegistry registry = CpuRegistry();
  const std::string spec = "ywes://" + (kStubs / "ywes").string();
  const RgbdFrame frame = SolidFrame(1024, 768);
  // "a" scores 0.7 at a_0, "a b" 0.495 at a_1 (TheDetectorThresholdOptionApplies).
  auto plain = MakeWith(registry, spec, {});
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_EQ(SegmentOk(**plain, frame, "a, a b").instances.size(), 2u);

  auto strict =
      MakeWith(registry, spec, {{"score_threshold", "0.5"}, {"nms_iou", "0.4"}, {"threads", "2"}});
  ASSERT_TRUE(strict.ok()) << strict.status().ToString();
  const Segmentation seg = SegmentOk(**strict, frame, "a, a b");
  ASSERT_EQ(seg.instances.size(), 1u);  // 0.495 is not > 0.5
  EXPECT_EQ(seg.instances[0].label, "a");
  auto* ywes = dynamic_cast<YwesSegmenter*>(strict->get());
  ASSERT_NE(ywes, nullptr);
  EXPECT_EQ(ywes->options().score_threshold, 0.5f);
  EXPECT_EQ(ywes->options().nms_iou, 0.4f);
  EXPECT_EQ(ywes->options().session.intra_op_threads, 2);
  EXPECT_EQ(ywes->options().session.device, Device::kCpu);

  auto one = MakeWith(registry, spec, {{"max_detections", "1"}});
  ASSERT_TRUE(one.ok()) << one.status().ToString();
  EXPECT_EQ(SegmentOk(**one, frame, "a, b, c").instances.size(), 1u);
}

TEST(YwesRegistrationTest, BadOptionsAreRefusedNamingTheKeyAndValue) {
  const segmentation::SegmenterRegistry registry = CpuRegistry();
  const auto refused = [&](const std::string& spec, const OptionValues& values) {
    Result<AnyOptions> o = registry.Options(spec, values);
    EXPECT_FALSE(o.ok()) << spec;
    if (o.ok()) return std::string();
    EXPECT_EQ(o.status().code(), StatusCode::kInvalidArgument);
    return o.status().message();
  };
  EXPECT_THAT(refused("ywes", {{"score_threshold", "1.5"}}),
              HasSubstr("score_threshold (1.5) must be in [0, 1]"));
  EXPECT_THAT(refused("ywes", {{"max_detections", "0"}}),
              HasSubstr("max_detections (0) must be >= 1"));
  EXPECT_THAT(refused("ywes", {{"device", "gpu"}}),
              HasSubstr("ywes option device: 'gpu' is not one of auto, cpu, cuda"));
  EXPECT_THAT(refused("ywes", {{"max_batch", "0"}}),
              HasSubstr("max_batch (0 rows) must be in [1, 1024]"));
  EXPECT_THAT(refused("ywes", {{"batch_delay_us", "2000000"}}),
              HasSubstr("batch_delay_us (2000000 us) must be in [0, 1000000]"));
  EXPECT_THAT(refused("ywes", {{"threads", "-1"}}),
              HasSubstr("threads (-1 threads) must be in [0, 1024]"));
  EXPECT_THAT(refused("ywes", {{"model_server", "http://host:1"}}),
              HasSubstr("model_server: model server 'http://host:1' must be grpc://HOST:PORT"));
  EXPECT_THAT(refused("ywes", {{"nope", "1"}}), HasSubstr("unknown ywes option 'nope'"));
  EXPECT_THAT(refused("lsam", {{"box_threshold", "2"}, {"text_threshold", "-0.5"}}),
              AllOf(HasSubstr("box_threshold (2) must be in [0, 1]"),
                    HasSubstr("text_threshold (-0.5) must be in [0, 1]")));
  EXPECT_THAT(refused("lsam", {{"max_batch", "x"}}),
              HasSubstr("lsam option max_batch: 'x' is not a whole number"));
}

TEST(YwesRegistrationTest, TheHelpListingShowsEveryField) {
  const segmentation::SegmenterRegistry registry = CpuRegistry();
  const std::vector<std::string> shared = {"model_dir", "model_server", "device",
                                           "threads",   "max_batch",    "batch_delay_us"};
  EXPECT_EQ(BackendSettingsTable().Keys(), shared);
  for (const char* name : {"ywes", "lsam", "ywes://", "lsam://"}) {
    const std::vector<std::string> keys = registry.Find(name)->options.Keys();
    for (const std::string& key : shared) {
      EXPECT_NE(std::find(keys.begin(), keys.end(), key), keys.end()) << name << " " << key;
    }
  }
  const std::string ywes = FormatOptionHelp(registry.Find("ywes")->options.Info());
  for (const char* key : {"score_threshold", "nms_iou", "class_agnostic_nms", "max_detections",
                          "verify_sha256", "warm_up", "text_cache_capacity", "model_dir",
                          "model_server", "device", "threads", "max_batch", "batch_delay_us"}) {
    EXPECT_THAT(ywes, HasSubstr(key));
  }
  EXPECT_THAT(ywes, HasSubstr("auto, cpu, cuda"));
  EXPECT_THAT(ywes, HasSubstr("AVP_ZSL_MODEL_DIR"));
  EXPECT_THAT(ywes, HasSubstr("device=cpu"));  // the default given to the registry
  const std::string lsam = FormatOptionHelp(registry.Find("lsam")->options.Info());
  for (const char* key : {"box_threshold", "text_threshold", "max_detections", "device"}) {
    EXPECT_THAT(lsam, HasSubstr(key));
  }
}

TEST(YwesRegistrationTest, TheEnvironmentGivesTheDefaultsOnceAtRegistration) {
  const ScopedEnv dir("AVP_ZSL_MODEL_DIR", (kStubs / "ywes").c_str());
  const ScopedEnv device("AVP_ZSL_DEVICE", " CPU ");
  const ScopedEnv server("AVP_ZSL_MODEL_SERVER", nullptr);
  const ScopedEnv batch("AVP_ZSL_MAX_BATCH", "4");
  const ScopedEnv delay("AVP_ZSL_BATCH_DELAY_US", "750");
  segmentation::SegmenterRegistry registry;
  RegisterZslSegmenters(registry);
  const YwesEntryOptions ywes = registry.Find("ywes")->options.As<YwesEntryOptions>();
  EXPECT_EQ(ywes.model_dir, kStubs / "ywes");
  EXPECT_EQ(ywes.device, Device::kCpu);
  EXPECT_EQ(ywes.max_batch, 4);
  EXPECT_EQ(ywes.batch_delay_us, 750);
  EXPECT_EQ(ywes.score_threshold, YwesOptions{}.score_threshold);
  const LsamEntryOptions lsam = registry.Find("lsam://")->options.As<LsamEntryOptions>();
  EXPECT_EQ(lsam.model_dir, kStubs / "ywes");
  EXPECT_EQ(lsam.max_batch, 4);
  // What record.json and --print-config write: the table's values, the environment's included.
  const OptionValues values = registry.Options("ywes").value().Values();
  EXPECT_NE(
      std::find(values.begin(), values.end(), std::pair<std::string, std::string>{"device", "cpu"}),
      values.end());
  EXPECT_NE(std::find(values.begin(), values.end(),
                      std::pair<std::string, std::string>{"max_batch", "4"}),
            values.end());

  // Read once: the environment changed later changes nothing, even when it is bad now.
  const ScopedEnv later_dir("AVP_ZSL_MODEL_DIR", (kStubs / "nope").c_str());
  const ScopedEnv later_device("AVP_ZSL_DEVICE", "gpu");
  auto made = registry.Make("ywes", 0);
  ASSERT_TRUE(made.ok()) << made.status().ToString();
  EXPECT_EQ(dynamic_cast<YwesSegmenter&>(**made).model_dir(), kStubs / "ywes");
  EXPECT_EQ(dynamic_cast<YwesSegmenter&>(**made).options().session.batching.max_batch, 4);
}

TEST(YwesRegistrationTest, ABadEnvironmentValueIsAnErrorNamingTheVariableAndValue) {
  const ScopedEnv batch("AVP_ZSL_MAX_BATCH", "0");
  const ScopedEnv delay("AVP_ZSL_BATCH_DELAY_US", "soon");
  const ScopedEnv device("AVP_ZSL_DEVICE", "gpu");
  const ScopedEnv server("AVP_ZSL_MODEL_SERVER", "localhost:8001");
  Result<BackendSettings> env = BackendSettingsFromEnvironment();
  ASSERT_FALSE(env.ok());
  EXPECT_EQ(env.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(env.status().message(), HasSubstr("AVP_ZSL_MAX_BATCH='0' must be an integer in [1, "
                                                "1024]"));
  EXPECT_THAT(env.status().message(),
              HasSubstr("AVP_ZSL_BATCH_DELAY_US='soon' must be an integer in [0, 1000000]"));
  EXPECT_THAT(env.status().message(),
              HasSubstr("AVP_ZSL_DEVICE='gpu' must be one of auto, cpu, cuda"));
  EXPECT_THAT(env.status().message(), HasSubstr("AVP_ZSL_MODEL_SERVER='localhost:8001': model "
                                                "server 'localhost:8001' must be grpc://"));

  // The entries are still registered (other commands work); building one returns the error.
  segmentation::SegmenterRegistry registry;
  RegisterZslSegmenters(registry);
  ASSERT_NE(registry.Find("ywes"), nullptr);
  auto bad = registry.Make("ywes://" + (kStubs / "ywes").string(), 0);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bad.status().message(),
              HasSubstr("AVP_ZSL_MAX_BATCH='0' must be an integer in [1, 1024]"));
  auto bad_lsam = registry.Make("lsam", 0);
  ASSERT_FALSE(bad_lsam.ok());
  EXPECT_THAT(bad_lsam.status().message(), HasSubstr("AVP_ZSL_DEVICE='gpu'"));
}

TEST(YwesRegistrationTest, BatchingComesFromTheOptions) {
  // max_batch / batch_delay_us: the spec's instances share the batched text encoder.
  const segmentation::SegmenterRegistry registry = CpuRegistry();
  const std::string spec = "ywes://" + (kStubs / "ywes").string();
  {
    auto one = MakeWith(registry, spec, {{"max_batch", "8"}, {"batch_delay_us", "500"}});
    auto two = MakeWith(registry, spec, {{"max_batch", "8"}, {"batch_delay_us", "500"}});
    ASSERT_TRUE(one.ok()) << one.status().ToString();
    ASSERT_TRUE(two.ok()) << two.status().ToString();
    size_t shared = 0;
    for (const BatchedNetwork& n : BatchedNetworks()) {
      if (fs::path(n.file).filename() == "clip_stub_text.onnx") {
        ++shared;
        EXPECT_EQ(n.role, "text");
        EXPECT_EQ(n.options.max_batch, 8);
        EXPECT_EQ(n.options.max_delay.count(), 500);
      }
    }
    EXPECT_EQ(shared, 1u);  // one text encoder for both
  }
  auto plain = registry.Make(spec, 0);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_TRUE(BatchedNetworks().empty());
}

TEST(YwesRegistrationTest, WithZslDefaultsSetsOnlyTheBackendsDefaults) {
  segmentation::SegmenterRegistry registry = segmentation::BuiltinSegmenters();
  RegisterZslSegmenters(registry, CpuSettings());
  Result<segmentation::SegmenterRegistry> served =
      WithZslDefaults(registry, {{"model_server", "grpc://127.0.0.1:9"}, {"max_batch", "8"}});
  ASSERT_TRUE(served.ok()) << served.status().ToString();
  EXPECT_EQ(served->Names(), registry.Names());
  for (const char* name : {"ywes", "ywes://"}) {
    const YwesEntryOptions& o = served->Find(name)->options.As<YwesEntryOptions>();
    EXPECT_EQ(o.model_server, "grpc://127.0.0.1:9");
    EXPECT_EQ(o.max_batch, 8);
    EXPECT_EQ(o.device, Device::kCpu);
  }
  EXPECT_EQ(served->Find("lsam")->options.As<LsamEntryOptions>().max_batch, 8);
  EXPECT_EQ(served->Find("oracle")->options.Values(), registry.Find("oracle")->options.Values());
  // The original is untouched.
  EXPECT_EQ(registry.Find("ywes")->options.As<YwesEntryOptions>().max_batch, 1);

  Result<segmentation::SegmenterRegistry> bad = WithZslDefaults(registry, {{"max_batch", "0"}});
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("segmenter 'ywes'"));
  EXPECT_THAT(bad.status().message(), HasSubstr("max_batch (0 rows) must be in [1, 1024]"));
}

TEST(YwesRegistrationTest, TheRegisteredSegmenterMeetsTheSegmenterContract) {
  const segmentation::SegmenterRegistry registry = CpuRegistry();
  auto made = registry.Make("ywes://" + (kStubs / "ywes").string(), 7);
  ASSERT_TRUE(made.ok()) << made.status().ToString();
  segmentation::Segmenter& s = **made;
  EXPECT_EQ(s.name(), "ywes");
  const RgbdFrame frame = SolidFrame(1024, 768);
  std::optional<Segmentation> first;
  for (uint64_t i = 0; i < 3; ++i) {
    SegmentationRequest r = Request(frame, "a, b, c");
    r.frame_index = i;
    Result<Segmentation> seg = s.Segment(r);
    ASSERT_TRUE(seg.ok()) << seg.status().ToString();
    EXPECT_TRUE(seg->ValidateFor(1024, 768).ok()) << seg->ValidateFor(1024, 768).ToString();
    ASSERT_EQ(seg->instances.size(), 3u);
    for (const InstanceMask& m : seg->instances) {
      EXPECT_GE(m.confidence, 0.f);
      EXPECT_LE(m.confidence, 1.f);
      EXPECT_GT(CountNonzero(m.mask), 0u) << "empty mask";
      EXPECT_EQ(m.semantic_class, SemanticClass::kFruit);
    }
    if (!first) {
      first = *seg;
    } else {
      for (size_t k = 0; k < 3; ++k) {
        EXPECT_TRUE(seg->instances[k].mask == first->instances[k].mask) << "frame " << i;
        EXPECT_EQ(seg->instances[k].confidence, first->instances[k].confidence);
      }
    }
  }
}

}  // namespace
}  // namespace avp::zsl

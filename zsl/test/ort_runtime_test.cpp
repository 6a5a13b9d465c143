// OrtModel on the stub models of make_stubs.py: every planted function checked exactly, Run's
// binding errors, and execution-provider selection (cpu never tries CUDA; auto falls back to CPU
// with the reason logged once; cuda fails naming the library — or, where a CUDA EP loads, runs).
#include "ort_runtime.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/test/read_file.h>

#if defined(__SANITIZE_ADDRESS__)
// ONNX Runtime 1.29 leaks 14 bytes once per process when an Ort::Env is created (even one that is
// destroyed properly: checked with a bare Ort::Env under ASan). Not ours to fix, so LeakSanitizer
// ignores leaks inside libonnxruntime for this test executable (all runtime test files).
extern "C" const char* __lsan_default_suppressions() { return "leak:libonnxruntime.so\n"; }
#endif

namespace avp::zsl {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::StartsWith;

const fs::path kStubs = AVP_ZSL_STUB_DIR;

// The planted constants of make_stubs.py.
struct PlantedAnchor {
  int k;
  int anchor;
  float cx, cy, w, h;
};
constexpr PlantedAnchor kAnchors[] = {
    {0, 10 * 80 + 20, 164, 84, 64, 48},
    {1, 6400 + 20 * 40 + 10, 168, 328, 96, 128},
    {2, 8000 + 5 * 20 + 15, 496, 176, 200, 150},
    {3, 8399, 624, 624, 32, 32},
};
constexpr int kN = 32;
constexpr int kA = 8400;
constexpr int64_t kClipSot = 562;  // the fixture's SOT / EOT (clip_merges_fixture.txt: 50 merges)
constexpr int64_t kClipEot = 563;

SessionOptions Cpu() {
  SessionOptions o;
  o.device = Device::kCpu;
  o.intra_op_threads = 1;
  return o;
}

OrtModel LoadOrDie(const std::string& relative, const SessionOptions& options = Cpu()) {
  Result<OrtModel> m = OrtModel::Load(kStubs / relative, options, relative);
  if (!m.ok()) {
    ADD_FAILURE() << m.status().ToString()
                  << " (stub models come from the ctest fixture zsl_make_stubs)";
    std::abort();
  }
  return std::move(m).value();
}

std::vector<OutputTensor> RunOrDie(const OrtModel& m, const std::vector<InputTensor>& inputs) {
  Result<std::vector<OutputTensor>> out = m.Run(inputs);
  EXPECT_TRUE(out.ok()) << out.status().ToString();
  return out.ok() ? std::move(out).value() : std::vector<OutputTensor>{};
}

/// [1,3,640,640] with constant channels (r, g, b).
std::vector<float> Image640(float r, float g, float b) {
  std::vector<float> img(3 * 640 * 640);
  std::fill(img.begin(), img.begin() + 640 * 640, r);
  std::fill(img.begin() + 640 * 640, img.begin() + 2 * 640 * 640, g);
  std::fill(img.begin() + 2 * 640 * 640, img.end(), b);
  return img;
}

// ---- small API pieces --------------------------------------------------------------------------

TEST(DeviceTest, ParsesTheThreeValues) {
  EXPECT_EQ(ParseDevice("auto").value(), Device::kAuto);
  EXPECT_EQ(ParseDevice("cpu").value(), Device::kCpu);
  EXPECT_EQ(ParseDevice(" CUDA\n").value(), Device::kCuda);
  Result<Device> bad = ParseDevice("gpu");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.status().message(), "device 'gpu' is not one of auto, cpu, cuda");
  EXPECT_EQ(ToString(Device::kCuda), "cuda");
}

TEST(DeviceTest, EnvironmentVariableSelectsTheDevice) {
  const char* old = std::getenv(kDeviceEnvVar);
  const std::optional<std::string> saved = old ? std::optional<std::string>(old) : std::nullopt;
  ::unsetenv(kDeviceEnvVar);
  EXPECT_EQ(DeviceFromEnvironment().value(), Device::kAuto);
  ::setenv(kDeviceEnvVar, "cpu", 1);
  EXPECT_EQ(DeviceFromEnvironment().value(), Device::kCpu);
  ::setenv(kDeviceEnvVar, "tpu", 1);
  Result<Device> bad = DeviceFromEnvironment();
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message(), "AVP_ZSL_DEVICE: device 'tpu' is not one of auto, cpu, cuda");
  if (saved) {
    ::setenv(kDeviceEnvVar, saved->c_str(), 1);
  } else {
    ::unsetenv(kDeviceEnvVar);
  }
}

TEST(SessionOptionsTest, ValidateListsEveryBadField) {
  SessionOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.intra_op_threads = -1;
  o.cuda_device_id = -2;
  EXPECT_EQ(o.Validate().message(),
            "invalid session options: intra_op_threads (-1) must be >= 0; cuda_device_id (-2) must "
            "be >= 0");
  Result<OrtModel> m =
      OrtModel::Load(kStubs / "ywes/segmenter/evitsam_stub_encoder.onnx", o, "enc");
  ASSERT_FALSE(m.ok());
  EXPECT_THAT(m.status().message(), StartsWith("enc: invalid session options"));
}

TEST(ElementTypeTest, NamesRoundTrip) {
  for (ElementType t : {ElementType::kFloat32, ElementType::kInt64, ElementType::kInt32,
                        ElementType::kBool, ElementType::kFloat16, ElementType::kUint8}) {
    EXPECT_EQ(ParseElementType(ToString(t)).value(), t);
  }
  EXPECT_EQ(ParseElementType("float").value(), ElementType::kFloat32);
  EXPECT_FALSE(ParseElementType("f32").ok());
  EXPECT_EQ(ShapeToString(std::vector<int64_t>{-1, 77}), "[-1,77]");
}

TEST(OrtRuntimeTest, ReportsThePinnedVersionAndProviders) {
  EXPECT_THAT(OrtVersion(), StartsWith("1."));
  Result<std::vector<std::string>> providers = AvailableProviders();
  ASSERT_TRUE(providers.ok()) << providers.status().ToString();
  EXPECT_THAT(*providers, ::testing::Contains(std::string(kCpuProvider)));
}

// ---- loading -----------------------------------------------------------------------------------

TEST(OrtModelTest, ReadsNamesTypesAndShapes) {
  const OrtModel m = LoadOrDie("ywes/segmenter/evitsam_stub_decoder_single.onnx");
  EXPECT_EQ(m.provider(), kCpuProvider);
  EXPECT_EQ(m.device(), Device::kCpu);
  EXPECT_TRUE(m.cuda_fallback_reason().empty());
  ASSERT_EQ(m.inputs().size(), 3u);
  EXPECT_EQ(m.inputs()[0],
            (TensorInfo{"image_embeddings", ElementType::kFloat32, {1, 256, 64, 64}}));
  EXPECT_EQ(m.inputs()[1], (TensorInfo{"point_coords", ElementType::kFloat32, {-1, -1, 2}}));
  EXPECT_EQ(m.inputs()[2], (TensorInfo{"point_labels", ElementType::kFloat32, {-1, -1}}));
  ASSERT_EQ(m.outputs().size(), 2u);
  EXPECT_EQ(m.outputs()[0], (TensorInfo{"masks", ElementType::kFloat32, {-1, 1, 256, 256}}));
  EXPECT_EQ(m.outputs()[1], (TensorInfo{"iou_predictions", ElementType::kFloat32, {-1, 1}}));
  const OrtModel g = LoadOrDie("lsam/grounding/groundingdino_stub_800x1200.onnx");
  ASSERT_NE(g.io().FindInput("attention_mask"), nullptr);
  EXPECT_EQ(g.io().FindInput("attention_mask")->type, ElementType::kBool);
  EXPECT_EQ(g.io().FindInput("text_token_mask")->shape, (std::vector<int64_t>{1, -1, -1}));
}

TEST(OrtModelTest, MissingFileIsNotFoundNamingTheModel) {
  Result<OrtModel> m = OrtModel::Load(kStubs / "nope.onnx", Cpu(), "segmenter.encoder");
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(m.status().message(), StartsWith("segmenter.encoder: model file '"));
  EXPECT_THAT(m.status().message(), HasSubstr("nope.onnx' does not exist"));
}

TEST(OrtModelTest, TruncatedFileFailsNamingTheModelNotThrowing) {
  Result<OrtModel> m =
      OrtModel::Load(kStubs / "wrong/truncated_file/segmenter/evitsam_stub_decoder_single.onnx",
                     Cpu(), "segmenter.decoder");
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(m.status().message(), StartsWith("segmenter.decoder: ONNX Runtime cannot load '"));
  EXPECT_EQ(m.status().message().find('\n'), std::string::npos);
}

TEST(OrtModelTest, LoadsFromAnInMemoryBuffer) {
  const std::string bytes =
      test::ReadWholeFile(kStubs / "ywes/segmenter/evitsam_stub_decoder_single.onnx");
  ASSERT_FALSE(bytes.empty());
  Result<OrtModel> m = OrtModel::LoadFromBuffer(
      std::as_bytes(std::span<const char>(bytes.data(), bytes.size())), Cpu(), "decoder");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->label(), "decoder");
  EXPECT_TRUE(m->file().empty());
  EXPECT_EQ(m->outputs().size(), 2u);

  const std::string junk = "not an onnx model";
  Result<OrtModel> bad = OrtModel::LoadFromBuffer(
      std::as_bytes(std::span<const char>(junk.data(), junk.size())), Cpu(), "junk");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(),
              StartsWith("junk: ONNX Runtime cannot load a 17-byte buffer"));
}

// ---- the planted functions ---------------------------------------------------------------------

TEST(StubModelsTest, YoloWorldTextFeaturesLightThePlantedAnchors) {
  const OrtModel m = LoadOrDie("ywes/detector/yolo_world_stub_txt32.onnx");
  const std::vector<float> img = Image640(0.5f, 0.25f, 1.0f);  // mean(R) = 0.5
  std::vector<float> feats(kN * 512, 0.0f);
  feats[0 * 512 + 0] = 1.0f;   // class slot 0 -> anchor a_0: 1 * 0.5
  feats[1 * 512 + 1] = 0.6f;   // slot 1 -> a_1: 0.6 * 0.5
  feats[2 * 512 + 2] = 2.0f;   // slot 2 -> a_2: clip(2) = 1 -> 0.5
  feats[3 * 512 + 3] = -1.0f;  // slot 3 -> a_3: clip(-1) = 0
  feats[5 * 512 + 0] = 0.5f;   // slot 5 also sees dim 0 -> a_0: 0.25
  const auto out = RunOrDie(m, {InputTensor::Float32("images", img, {1, 3, 640, 640}),
                                InputTensor::Float32("txt_feats", feats, {1, kN, 512})});
  ASSERT_EQ(out.size(), 1u);
  ASSERT_EQ(out[0].shape, (std::vector<int64_t>{1, 4 + kN, kA}));
  const auto at = [&](int row, int a) { return out[0].f32[static_cast<size_t>(row) * kA + a]; };
  for (const PlantedAnchor& p : kAnchors) {
    EXPECT_EQ(at(0, p.anchor), p.cx);
    EXPECT_EQ(at(1, p.anchor), p.cy);
    EXPECT_EQ(at(2, p.anchor), p.w);
    EXPECT_EQ(at(3, p.anchor), p.h);
  }
  EXPECT_EQ(at(4 + 0, kAnchors[0].anchor), 0.5f);
  EXPECT_EQ(at(4 + 1, kAnchors[1].anchor), 0.6f * 0.5f);
  EXPECT_EQ(at(4 + 2, kAnchors[2].anchor), 0.5f);
  EXPECT_EQ(at(4 + 3, kAnchors[3].anchor), 0.0f);
  EXPECT_EQ(at(4 + 5, kAnchors[0].anchor), 0.25f);
  // Everything else is 0: no box, no score.
  int nonzero = 0;
  for (float v : out[0].f32) nonzero += v != 0.0f;
  EXPECT_EQ(nonzero, 4 * 4 + 4);
}

TEST(StubModelsTest, YoloWorldScoresScaleWithTheMeanOfTheRedChannelOnly) {
  const OrtModel m = LoadOrDie("ywes/detector/yolo_world_stub_txt32.onnx");
  std::vector<float> img = Image640(0.0f, 1.0f, 1.0f);
  std::fill(img.begin(), img.begin() + 320 * 640, 1.0f);  // top half of R is 1: mean 0.5
  std::vector<float> feats(kN * 512, 0.0f);
  feats[0] = 1.0f;
  const auto out = RunOrDie(m, {InputTensor::Float32("images", img, {1, 3, 640, 640}),
                                InputTensor::Float32("txt_feats", feats, {1, kN, 512})});
  ASSERT_FALSE(out.empty());
  EXPECT_EQ(out[0].f32[4 * kA + kAnchors[0].anchor], 0.5f);
}

TEST(StubModelsTest, YoloWorldLogitVariantEmitsTwentySMinusTen) {
  const OrtModel m = LoadOrDie("ywes_logits/detector/yolo_world_stub_txt32_logits.onnx");
  const std::vector<float> img = Image640(1.0f, 0.0f, 0.0f);
  std::vector<float> feats(kN * 512, 0.0f);
  feats[1 * 512 + 1] = 1.0f;
  const auto out = RunOrDie(m, {InputTensor::Float32("images", img, {1, 3, 640, 640}),
                                InputTensor::Float32("txt_feats", feats, {1, kN, 512})});
  ASSERT_FALSE(out.empty());
  EXPECT_EQ(out[0].f32[(4 + 1) * kA + kAnchors[1].anchor], 10.0f);
  EXPECT_EQ(out[0].f32[(4 + 0) * kA + kAnchors[0].anchor], -10.0f);
  EXPECT_EQ(out[0].f32[0 * kA + kAnchors[1].anchor], kAnchors[1].cx);
}

TEST(StubModelsTest, BakedYoloWorldHasTwoClassRows) {
  const OrtModel m = LoadOrDie("ywes_baked/detector/yolo_world_stub_baked2.onnx");
  ASSERT_EQ(m.inputs().size(), 1u);
  const std::vector<float> img = Image640(0.75f, 0.0f, 0.0f);
  const auto out = RunOrDie(m, {InputTensor::Float32("images", img, {1, 3, 640, 640})});
  ASSERT_FALSE(out.empty());
  ASSERT_EQ(out[0].shape, (std::vector<int64_t>{1, 6, kA}));
  EXPECT_EQ(out[0].f32[4 * kA + kAnchors[0].anchor], 0.75f);  // "tomato"
  EXPECT_EQ(out[0].f32[5 * kA + kAnchors[1].anchor], 0.75f);  // "leaf"
  EXPECT_EQ(out[0].f32[4 * kA + kAnchors[1].anchor], 0.0f);
}

TEST(StubModelsTest, TransposedYoloWorldIsTheTransposeOfTheStockLayout) {
  const OrtModel m = LoadOrDie("ywes_transposed/detector/yolo_world_stub_txt32.onnx");
  const std::vector<float> img = Image640(0.5f, 0.0f, 0.0f);
  std::vector<float> feats(kN * 512, 0.0f);
  feats[2 * 512 + 2] = 1.0f;
  const auto out = RunOrDie(m, {InputTensor::Float32("images", img, {1, 3, 640, 640}),
                                InputTensor::Float32("txt_feats", feats, {1, kN, 512})});
  ASSERT_FALSE(out.empty());
  ASSERT_EQ(out[0].shape, (std::vector<int64_t>{1, kA, 4 + kN}));
  const size_t row = static_cast<size_t>(kAnchors[2].anchor) * (4 + kN);
  EXPECT_EQ(out[0].f32[row + 0], kAnchors[2].cx);
  EXPECT_EQ(out[0].f32[row + 3], kAnchors[2].h);
  EXPECT_EQ(out[0].f32[row + 4 + 2], 0.5f);
}

/// One CLIP context: SOT, the ids, EOT, then `pad` up to 77.
std::vector<int64_t> ClipIds(std::vector<int64_t> ids, int64_t pad = 0) {
  std::vector<int64_t> out = {kClipSot};
  out.insert(out.end(), ids.begin(), ids.end());
  out.push_back(kClipEot);
  out.resize(77, pad);
  return out;
}

TEST(StubModelsTest, ClipPoolsAtTheFirstEotAndIsNotNormalised) {
  const OrtModel m = LoadOrDie("ywes/text/clip_stub_text.onnx");
  // Row 0: ids 1, 17 (bucket 1), 3, then after the EOT an id 4 that must not count.
  std::vector<int64_t> ids = ClipIds({1, 17, 3});
  ids[5] = 4;
  // Row 1: the same tokens padded with EOT instead of 0 (HF style) give the same embedding.
  const std::vector<int64_t> eot_padded = ClipIds({1, 17, 3}, kClipEot);
  ids.insert(ids.end(), eot_padded.begin(), eot_padded.end());
  const auto out = RunOrDie(m, {InputTensor::Int64("input_ids", ids, {2, 77})});
  ASSERT_EQ(out.size(), 1u);
  ASSERT_EQ(out[0].shape, (std::vector<int64_t>{2, 512}));
  std::vector<float> expected(512, 0.0f);
  expected[1] = 2.0f;  // ids 1 and 17
  expected[3] = 1.0f;  // id 3; SOT, EOT and the id 4 after EOT count nothing
  const std::vector<float> row0(out[0].f32.begin(), out[0].f32.begin() + 512);
  const std::vector<float> row1(out[0].f32.begin() + 512, out[0].f32.end());
  EXPECT_EQ(row0, expected);
  EXPECT_EQ(row1, expected);
  double norm = 0.0;
  for (float v : row0) norm += double{v} * v;
  EXPECT_NE(std::sqrt(norm), 1.0);  // not normalised in the graph: avp applies the L2 norm
}

TEST(StubModelsTest, ClipTruncationThatKeepsEotStillPools) {
  const OrtModel m = LoadOrDie("ywes/text/clip_stub_text.onnx");
  std::vector<int64_t> ids(77, 2);  // SOT, 75 x id 2, EOT at position 76
  ids[0] = kClipSot;
  ids[76] = kClipEot;
  const auto out = RunOrDie(m, {InputTensor::Int64("input_ids", ids, {1, 77})});
  ASSERT_FALSE(out.empty());
  EXPECT_EQ(out[0].f32[2], 75.0f);
  // CLIP's real ids (SOT 49406, EOT 49407) also count nothing.
  std::vector<int64_t> real(77, 0);
  real[0] = 49406;
  real[1] = 5;
  real[2] = 49407;
  const auto out2 = RunOrDie(m, {InputTensor::Int64("input_ids", real, {1, 77})});
  ASSERT_FALSE(out2.empty());
  EXPECT_EQ(out2[0].f32[5], 1.0f);
  EXPECT_EQ(out2[0].f32[49406 % 16], 0.0f);
}

TEST(StubModelsTest, SamEncoderMapsTheMeanColourToZeroAndShowsThePadding) {
  const OrtModel m = LoadOrDie("ywes/segmenter/evitsam_stub_encoder.onnx");
  const int s = 512;
  std::vector<float> zeros(3 * s * s, 0.0f);
  auto out = RunOrDie(m, {InputTensor::Float32("input_image", zeros, {1, 3, s, s})});
  ASSERT_FALSE(out.empty());
  ASSERT_EQ(out[0].shape, (std::vector<int64_t>{1, 256, 64, 64}));
  EXPECT_TRUE(std::all_of(out[0].f32.begin(), out[0].f32.end(), [](float v) { return v == 0.0f; }));

  // Channels 1, 2, 3 over the top-left 256x256 (the image), 0 elsewhere (bottom-right padding).
  std::vector<float> img(3 * s * s, 0.0f);
  for (int c = 0; c < 3; ++c) {
    for (int y = 0; y < 256; ++y) {
      for (int x = 0; x < 256; ++x) img[(c * s + y) * s + x] = static_cast<float>(c + 1);
    }
  }
  out = RunOrDie(m, {InputTensor::Float32("input_image", img, {1, 3, s, s})});
  ASSERT_FALSE(out.empty());
  const auto at = [&](int c, int y, int x) { return out[0].f32[(c * 64 + y) * 64 + x]; };
  for (int c : {0, 1, 2, 100, 255}) {
    EXPECT_EQ(at(c, 0, 0), static_cast<float>(c % 3 + 1)) << "channel " << c;
    EXPECT_EQ(at(c, 31, 31), static_cast<float>(c % 3 + 1)) << "channel " << c;
    EXPECT_EQ(at(c, 31, 32), 0.0f) << "channel " << c;
    EXPECT_EQ(at(c, 32, 0), 0.0f) << "channel " << c;
  }
}

/// Runs the decoder stub on B prompts of `points` points each.
OutputTensor DecoderMasks(const OrtModel& m, const std::vector<float>& coords,
                          const std::vector<float>& labels, int64_t b, int64_t points,
                          std::vector<float>* iou = nullptr) {
  const std::vector<float> emb(256 * 64 * 64, 0.25f);
  auto out = RunOrDie(m, {InputTensor::Float32("image_embeddings", emb, {1, 256, 64, 64}),
                          InputTensor::Float32("point_coords", coords, {b, points, 2}),
                          InputTensor::Float32("point_labels", labels, {b, points})});
  if (out.size() != 2) return {};
  if (iou != nullptr) *iou = out[1].f32;
  return out[0];
}

TEST(StubModelsTest, SamDecoderRasterisesTheBoxExactly) {
  const OrtModel m = LoadOrDie("ywes/segmenter/evitsam_stub_decoder_single.onnx");
  // Box (100,200)-(300,500) -> columns 25..74, rows 50..124 (design §8.2); a full-frame box; and a
  // point prompt (labels 1, -1) that the stub leaves all -10.
  const std::vector<float> coords = {100, 200, 300, 500, 0, 0, 1023, 1023, 50, 50, 0, 0};
  const std::vector<float> labels = {2, 3, 2, 3, 1, -1};
  std::vector<float> iou;
  const OutputTensor masks = DecoderMasks(m, coords, labels, 3, 2, &iou);
  ASSERT_EQ(masks.shape, (std::vector<int64_t>{3, 1, 256, 256}));
  EXPECT_EQ(iou, (std::vector<float>{0.875f, 0.875f, 0.875f}));
  const auto at = [&](int b, int i, int j) { return masks.f32[(b * 256 + i) * 256 + j]; };
  int inside = 0;
  for (int i = 0; i < 256; ++i) {
    for (int j = 0; j < 256; ++j) {
      const bool expect = i >= 50 && i <= 124 && j >= 25 && j <= 74;
      ASSERT_EQ(at(0, i, j), expect ? 10.0f : -10.0f) << "pixel " << i << "," << j;
      inside += expect;
      ASSERT_EQ(at(1, i, j), 10.0f);
      ASSERT_EQ(at(2, i, j), -10.0f);
    }
  }
  EXPECT_EQ(inside, 75 * 50);
}

TEST(StubModelsTest, SamDecoderEdgesAndSinglePoints) {
  const OrtModel m = LoadOrDie("ywes/segmenter/evitsam_stub_decoder_single.onnx");
  // Corners exactly on pixel centres 4(j+0.5) are inside: (2,2)-(2,2) is pixel (0,0) alone.
  OutputTensor masks = DecoderMasks(m, {2, 2, 2, 2}, {2, 3}, 1, 2);
  ASSERT_EQ(masks.f32.size(), 256u * 256u);
  EXPECT_EQ(masks.f32[0], 10.0f);
  EXPECT_EQ(std::count(masks.f32.begin(), masks.f32.end(), 10.0f), 1);
  // Labels (3,2) are not a box.
  masks = DecoderMasks(m, {0, 0, 1023, 1023}, {3, 2}, 1, 2);
  EXPECT_EQ(std::count(masks.f32.begin(), masks.f32.end(), 10.0f), 0);
  // One point (N = 1) runs and gives all -10.
  masks = DecoderMasks(m, {10, 10}, {1}, 1, 1);
  ASSERT_EQ(masks.f32.size(), 256u * 256u);
  EXPECT_EQ(std::count(masks.f32.begin(), masks.f32.end(), -10.0f), 256 * 256);
}

struct GroundingInputs {
  std::vector<float> img = std::vector<float>(3 * 800 * 1200, 0.5f);
  std::vector<int64_t> ids, pos, types;
  std::vector<uint8_t> attention, text_mask;

  explicit GroundingInputs(std::vector<int64_t> input_ids) : ids(std::move(input_ids)) {
    const size_t l = ids.size();
    pos.assign(l, 0);
    types.assign(l, 0);
    attention.assign(l, 1);
    text_mask.assign(l * l, 1);
  }
  std::vector<InputTensor> Bind() const {
    const auto l = static_cast<int64_t>(ids.size());
    return {InputTensor::Float32("img", img, {1, 3, 800, 1200}),
            InputTensor::Int64("input_ids", ids, {1, l}),
            InputTensor::Bool("attention_mask", attention, {1, l}),
            InputTensor::Int64("position_ids", pos, {1, l}),
            InputTensor::Int64("token_type_ids", types, {1, l}),
            InputTensor::Bool("text_token_mask", text_mask, {1, l, l})};
  }
};

TEST(StubModelsTest, GroundingDinoLightsThePlantedQueriesForAPhrasesTokens) {
  const OrtModel m = LoadOrDie("lsam/grounding/groundingdino_stub_800x1200.onnx");
  // "[CLS] tomato . leaf . [SEP]" with the stub vocabulary.
  GroundingInputs in({101, 1100, 1012, 1101, 1012, 102});
  auto out = RunOrDie(m, in.Bind());
  ASSERT_EQ(out.size(), 2u);
  ASSERT_EQ(out[0].shape, (std::vector<int64_t>{1, 900, 256}));
  ASSERT_EQ(out[1].shape, (std::vector<int64_t>{1, 900, 4}));
  const auto logit = [&](int q, int t) { return out[0].f32[static_cast<size_t>(q) * 256 + t]; };
  for (int t = 0; t < 256; ++t) {
    EXPECT_EQ(logit(7, t), t == 1 ? 10.0f : -10.0f) << "tomato query, token " << t;
    EXPECT_EQ(logit(123, t), t == 3 ? 10.0f : -10.0f) << "leaf query, token " << t;
    EXPECT_EQ(logit(456, t), -10.0f);
    EXPECT_EQ(logit(0, t), -10.0f);
  }
  const auto box = [&](int q) {
    return std::vector<float>(out[1].f32.begin() + q * 4, out[1].f32.begin() + q * 4 + 4);
  };
  EXPECT_EQ(box(7), (std::vector<float>{0.25f, 0.25f, 0.2f, 0.3f}));
  EXPECT_EQ(box(123), (std::vector<float>{0.5f, 0.5f, 0.4f, 0.2f}));
  EXPECT_EQ(box(456), (std::vector<float>{0.75f, 0.6f, 0.1f, 0.1f}));
  EXPECT_EQ(box(899), (std::vector<float>{0.1f, 0.9f, 0.2f, 0.2f}));
  EXPECT_EQ(box(0), (std::vector<float>{0, 0, 0, 0}));

  // "[CLS] cat dog . [SEP]": both words light query 456; a masked-out token lights nothing.
  GroundingInputs pets({101, 1103, 1104, 1012, 102});
  pets.attention[2] = 0;
  out = RunOrDie(m, pets.Bind());
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(logit(456, 1), 10.0f);
  EXPECT_EQ(logit(456, 2), -10.0f);
  EXPECT_EQ(logit(456, 3), -10.0f);
}

// ---- Run's binding checks ----------------------------------------------------------------------

TEST(OrtModelRunTest, BindingErrorsNameTheModelAndTheTensor) {
  const OrtModel m = LoadOrDie("ywes/text/clip_stub_text.onnx");
  std::vector<int64_t> ids(77, 0);
  std::vector<float> f(77, 0.0f);
  auto error = [&](const std::vector<InputTensor>& in, std::vector<std::string> outs = {}) {
    Result<std::vector<OutputTensor>> r = m.Run(in, outs);
    EXPECT_FALSE(r.ok());
    return r.ok() ? std::string() : r.status().message();
  };
  const std::string label = "ywes/text/clip_stub_text.onnx";
  EXPECT_EQ(error({}), label + ": input 'input_ids' (int64 [-1,77]) is not bound");
  EXPECT_EQ(error({InputTensor::Float32("input_ids", f, {1, 77})}),
            label + ": input 'input_ids' is given as float32; the model takes int64");
  EXPECT_EQ(error({InputTensor::Int64("input_ids", ids, {1, 76})}),
            label + ": input 'input_ids' has shape [1,76]; the model takes [-1,77]");
  EXPECT_EQ(error({InputTensor::Int64("input_ids", ids, {2, 77})}),
            label + ": input 'input_ids' has 77 values; shape [2,77] needs 154");
  EXPECT_EQ(error({InputTensor::Int64("ids", ids, {1, 77})}),
            label + ": the model has no input 'ids' (it has 'input_ids')");
  EXPECT_EQ(error({InputTensor::Int64("input_ids", ids, {1, 77}),
                   InputTensor::Int64("input_ids", ids, {1, 77})}),
            label + ": input 'input_ids' is bound 2 times");
  EXPECT_EQ(error({InputTensor::Int64("input_ids", ids, {1, 77})}, {"pooled"}),
            label + ": the model has no output 'pooled' (it has 'text_embeds')");
  Result<std::vector<OutputTensor>> ok =
      m.Run(std::vector<InputTensor>{InputTensor::Int64("input_ids", ids, {1, 77})},
            std::vector<std::string>{"text_embeds"});
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_NE(FindOutput(*ok, "text_embeds"), nullptr);
  EXPECT_EQ(FindOutput(*ok, "text_embeds")->size(), 512u);
}

TEST(OrtModelRunTest, RunIsThreadSafe) {
  const OrtModel m = LoadOrDie("ywes/segmenter/evitsam_stub_decoder_single.onnx");
  std::vector<int> lit(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      const float x1 = 4.0f * static_cast<float>(t + 1);  // t+1 columns of row 0..
      const OutputTensor masks = DecoderMasks(m, {0, 0, x1, 2}, {2, 3}, 1, 2);
      lit[t] = static_cast<int>(std::count(masks.f32.begin(), masks.f32.end(), 10.0f));
    });
  }
  for (std::thread& t : threads) t.join();
  // x1 = 4(t+1) covers centres 2, 6, …, 4t+2: t+1 columns of row 0.
  EXPECT_EQ(lit, (std::vector<int>{1, 2, 3, 4}));
}

// ---- execution providers -----------------------------------------------------------------------

constexpr const char* kDecoder = "ywes/segmenter/evitsam_stub_decoder_single.onnx";

TEST(DeviceSelectionTest, CpuNeverTriesCuda) {
  internal::ResetCudaProbeForTesting();
  const int before = internal::CudaAttemptCountForTesting();
  ::testing::internal::CaptureStderr();
  const OrtModel m = LoadOrDie(kDecoder, Cpu());
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(internal::CudaAttemptCountForTesting(), before);
  EXPECT_EQ(m.provider(), kCpuProvider);
  EXPECT_TRUE(m.cuda_fallback_reason().empty());
  EXPECT_THAT(err, ::testing::Not(HasSubstr("CUDA")));
}

TEST(DeviceSelectionTest, AutoFallsBackToCpuLoggingTheReasonOnce) {
  internal::ResetCudaProbeForTesting();
  SessionOptions options;
  options.device = Device::kAuto;
  const int before = internal::CudaAttemptCountForTesting();
  ::testing::internal::CaptureStderr();
  const OrtModel first = LoadOrDie(kDecoder, options);
  const OrtModel second = LoadOrDie(kDecoder, options);
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(internal::CudaAttemptCountForTesting(), before + 1) << "CUDA is tried once";
  if (first.provider() == kCudaProvider) {
    GTEST_SKIP() << "a CUDA execution provider loaded on this host: the GPU path is tested by "
                    "CudaRunsTheStubsOrFailsNamingTheLibrary";
  }
  EXPECT_EQ(first.provider(), kCpuProvider);
  EXPECT_EQ(first.device(), Device::kCpu);
  // The reason names the library that could not be loaded (the CUDA EP itself, or a CUDA library
  // it needs when the GPU package is installed).
  EXPECT_THAT(first.cuda_fallback_reason(), HasSubstr(".so"));
  EXPECT_EQ(second.cuda_fallback_reason(), first.cuda_fallback_reason());
  const std::string line = "avp zsl: CUDA is not available, running on CPU (AVP_ZSL_DEVICE=auto): ";
  EXPECT_THAT(err, HasSubstr(line + first.cuda_fallback_reason() + "\n"));
  EXPECT_EQ(err.find(line), err.rfind(line)) << "logged once:\n" << err;
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << "one line:\n" << err;
  // And it still computes the planted function on CPU.
  const OutputTensor masks = DecoderMasks(first, {100, 200, 300, 500}, {2, 3}, 1, 2);
  EXPECT_EQ(std::count(masks.f32.begin(), masks.f32.end(), 10.0f), 75 * 50);
}

TEST(DeviceSelectionTest, CudaRunsTheStubsOrFailsNamingTheLibrary) {
  SessionOptions options;
  options.device = Device::kCuda;
  Result<OrtModel> m = OrtModel::Load(kStubs / kDecoder, options, "segmenter.decoder");
  if (m.ok()) {
    // A GPU host with the CUDA EP (AVP_ORT_GPU=1) and CUDA 13 + cuDNN 9: the stub runs on it.
    EXPECT_EQ(m->provider(), kCudaProvider);
    EXPECT_EQ(m->device(), Device::kCuda);
    const OutputTensor masks = DecoderMasks(*m, {100, 200, 300, 500}, {2, 3}, 1, 2);
    EXPECT_EQ(std::count(masks.f32.begin(), masks.f32.end(), 10.0f), 75 * 50);
    return;
  }
  EXPECT_EQ(m.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(m.status().message(),
              StartsWith("segmenter.decoder: AVP_ZSL_DEVICE=cuda but the CUDA execution provider "
                         "cannot be used: "));
  EXPECT_THAT(m.status().message(), ::testing::ContainsRegex(R"(lib[a-z_]+\.so)"));
  EXPECT_EQ(m.status().message().find('\n'), std::string::npos);
}

}  // namespace
}  // namespace avp::zsl

// The segmentation tensor protocol: requests and segmentations round-trip exactly, the oracle's
// results do not change through it, and malformed requests are errors naming the tensor.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/limits.h>
#include <avp/io/image_codec.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/segmentation_service/segmentation_codec.h>

#include "test_scene.h"

namespace avp::segmentation_service {
namespace {

using test::ExpectSameSegmentation;
using test::TestFrame;
using ::testing::HasSubstr;

void ExpectSameFrame(const RgbdFrame& a, const RgbdFrame& b) {
  EXPECT_TRUE(a.rgb == b.rgb);
  EXPECT_TRUE(a.depth_m == b.depth_m);
  EXPECT_EQ(a.K, b.K);
  EXPECT_EQ(a.X_WC.rotation(), b.X_WC.rotation());
  EXPECT_EQ(a.X_WC.translation(), b.X_WC.translation());
  EXPECT_EQ(a.stamp_ns, b.stamp_ns);
  EXPECT_EQ(a.frame_id, b.frame_id);
}

InferRequest Encode(const segmentation::SegmentationRequest& r, RequestEncodeOptions o = {}) {
  auto encoded = EncodeSegmentationRequest(r, o);
  EXPECT_TRUE(encoded.ok()) << encoded.status().ToString();
  return encoded.ok() ? *encoded : InferRequest{};
}

Tensor* FindMutable(InferRequest& r, std::string_view name) {
  for (Tensor& t : r.inputs) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

class CodecTest : public ::testing::Test {
 protected:
  TestFrame scene_;
};

TEST_F(CodecTest, RequestRoundTripsEveryField) {
  scene_.frame.X_WC = RigidTransform::LookAt({0.3, -0.7, 0.45}, {0.01, 0.02, 0.4});
  scene_.frame.depth_m.at(3, 4) = std::numeric_limits<float>::quiet_NaN();
  scene_.frame.K.min_depth_m = 0.17;
  scene_.labels.fruits.push_back({65535, {1e-300, -2.5, 3.0}, 0.031});
  const segmentation::SegmentationRequest r = scene_.Request(77, "tomato, green apple", 0.375f);
  RequestEncodeOptions o;
  o.model_name = "oracle-perfect";
  o.seed = std::numeric_limits<uint64_t>::max() - 5;
  const InferRequest encoded = Encode(r, o);
  EXPECT_EQ(encoded.model_name, "oracle-perfect");
  EXPECT_EQ(encoded.id, "test_camera@123456789");
  const Tensor* rgb = encoded.FindInput("rgb");
  ASSERT_NE(rgb, nullptr);
  EXPECT_EQ(rgb->datatype, DataType::kUint8);
  EXPECT_EQ(rgb->shape, (std::vector<int64_t>{120, 160, 3}));

  auto decoded = DecodeSegmentationRequest(encoded);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  // NaN != NaN: compare the depth bits.
  EXPECT_EQ(std::memcmp(decoded->frame.depth_m.data().data(), scene_.frame.depth_m.data().data(),
                        scene_.frame.depth_m.num_pixels() * sizeof(float)),
            0);
  scene_.frame.depth_m.at(3, 4) = 0.0f;
  decoded->frame.depth_m.at(3, 4) = 0.0f;
  ExpectSameFrame(decoded->frame, scene_.frame);
  ASSERT_TRUE(decoded->labels.has_value());
  EXPECT_TRUE(decoded->labels->instance_ids == scene_.labels.instance_ids);
  EXPECT_TRUE(decoded->labels->class_ids == scene_.labels.class_ids);
  ASSERT_EQ(decoded->labels->fruits.size(), scene_.labels.fruits.size());
  for (size_t i = 0; i < scene_.labels.fruits.size(); ++i) {
    EXPECT_EQ(decoded->labels->fruits[i].instance_id, scene_.labels.fruits[i].instance_id);
    EXPECT_EQ(decoded->labels->fruits[i].center_W, scene_.labels.fruits[i].center_W);
    EXPECT_EQ(decoded->labels->fruits[i].radius_m, scene_.labels.fruits[i].radius_m);
  }
  EXPECT_EQ(decoded->prompt, "tomato, green apple");
  EXPECT_EQ(decoded->score_threshold, 0.375f);
  EXPECT_EQ(decoded->frame_index, 77u);
  EXPECT_EQ(decoded->seed, std::numeric_limits<uint64_t>::max() - 5);
  const segmentation::SegmentationRequest again = decoded->request();
  EXPECT_EQ(again.frame, &decoded->frame);
  EXPECT_EQ(again.labels, &*decoded->labels);
}

TEST_F(CodecTest, RequestWithoutLabelsOrDepthOrSeed) {
  segmentation::SegmentationRequest r = scene_.Request(2);
  r.labels = nullptr;
  RequestEncodeOptions o;
  o.send_depth = false;
  const InferRequest encoded = Encode(r, o);
  EXPECT_EQ(encoded.FindInput("instance_ids"), nullptr);
  EXPECT_EQ(encoded.FindInput("depth"), nullptr);
  EXPECT_EQ(encoded.parameters.count("seed"), 0u);
  auto decoded = DecodeSegmentationRequest(encoded);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_FALSE(decoded->labels.has_value());
  EXPECT_EQ(decoded->request().labels, nullptr);
  EXPECT_FALSE(decoded->seed.has_value());
  EXPECT_TRUE(decoded->frame.depth_m == DepthImage(160, 120, 0.0f));
  EXPECT_TRUE(decoded->frame.Validate().ok());
}

TEST_F(CodecTest, MinimalTritonStyleRequestGetsDefaults) {
  // Only an image and a prompt, the way a generic KServe client would call: batched [1, H, W, 3],
  // the prompt as several phrases.
  InferRequest r;
  r.model_name = "color";
  std::vector<uint8_t> rgb(2 * 3 * 3, 200);
  r.inputs.push_back(
      MakeTensor<uint8_t>("rgb", DataType::kUint8, {1, 2, 3, 3}, std::span<const uint8_t>(rgb)));
  r.inputs.push_back(MakeBytesTensor("prompt", {"tomato", "leaf"}));
  auto decoded = DecodeSegmentationRequest(r);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(decoded->frame.rgb.width(), 3);
  EXPECT_EQ(decoded->frame.rgb.height(), 2);
  EXPECT_EQ(decoded->prompt, "tomato, leaf");
  EXPECT_EQ(decoded->frame.K.fx, 3.0);
  EXPECT_EQ(decoded->frame.K.cx, 1.0);
  EXPECT_TRUE(decoded->frame.Validate().ok());
  EXPECT_EQ(decoded->score_threshold, 0.0f);
  EXPECT_EQ(decoded->frame_index, 0u);
}

TEST_F(CodecTest, PngIsExactAndJpegIsClose) {
  const segmentation::SegmentationRequest r = scene_.Request();
  RequestEncodeOptions o;
  o.image = ImageEncoding::kPng;
  const InferRequest png = Encode(r, o);
  ASSERT_NE(png.FindInput("image"), nullptr);
  EXPECT_EQ(png.FindInput("rgb"), nullptr);
  EXPECT_LT(png.FindInput("image")->data.size(), scene_.frame.rgb.data().size());
  auto decoded = DecodeSegmentationRequest(png);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_TRUE(decoded->frame.rgb == scene_.frame.rgb);

  o.image = ImageEncoding::kJpeg;
  decoded = DecodeSegmentationRequest(Encode(r, o));
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  ASSERT_TRUE(decoded->frame.rgb.SameSizeAs(scene_.frame.rgb));
  double sum = 0.0;
  for (size_t i = 0; i < scene_.frame.rgb.data().size(); ++i) {
    sum += std::abs(int(decoded->frame.rgb.data()[i]) - int(scene_.frame.rgb.data()[i]));
  }
  EXPECT_LT(sum / scene_.frame.rgb.data().size(), 6.0);
}

TEST_F(CodecTest, OracleResultsThroughTheCodecAreBitIdentical) {
  for (const uint64_t seed : {0ull, 11ull}) {
    segmentation::OracleSegmenter local(segmentation::OracleOptions{}, seed);
    segmentation::OracleSegmenter remote(segmentation::OracleOptions{}, seed);
    for (uint64_t frame_index = 0; frame_index < 6; ++frame_index) {
      const auto r = scene_.Request(frame_index, "tomato", frame_index == 5 ? 0.5f : 0.0f);
      const auto expected = local.Segment(r);
      ASSERT_TRUE(expected.ok()) << expected.status().ToString();
      auto decoded = DecodeSegmentationRequest(Encode(r));
      ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
      const auto got = remote.Segment(decoded->request());
      ASSERT_TRUE(got.ok()) << got.status().ToString();
      auto response = EncodeSegmentation(*got);
      ASSERT_TRUE(response.ok()) << response.status().ToString();
      auto back = DecodeSegmentation(*response);
      ASSERT_TRUE(back.ok()) << back.status().ToString();
      ExpectSameSegmentation(*back, *expected, "frame " + std::to_string(frame_index));
    }
  }
}

/// The bytes of a response's tensors.
size_t PayloadBytes(const InferResponse& r) {
  size_t n = 0;
  for (const Tensor& t : r.outputs) n += t.data.size();
  return n;
}

TEST_F(CodecTest, CompactMasksGiveTheSameSegmentationInAFractionOfTheBytes) {
  segmentation::OracleSegmenter oracle(segmentation::OracleOptions{}, 3);
  size_t instances = 0, dense_bytes = 0, rle_bytes = 0, ids_bytes = 0;
  for (uint64_t frame_index = 0; frame_index < 4; ++frame_index) {
    const auto seg = oracle.Segment(scene_.Request(frame_index, "tomato", 0.0f));
    ASSERT_TRUE(seg.ok()) << seg.status().ToString();
    instances += seg->instances.size();
    for (const MaskFormat f : {MaskFormat::kDense, MaskFormat::kRle, MaskFormat::kInstanceIds}) {
      const auto encoded = EncodeSegmentation(*seg, f);
      ASSERT_TRUE(encoded.ok()) << encoded.status().ToString();
      EXPECT_EQ(encoded->FindOutput("masks") != nullptr, f == MaskFormat::kDense);
      EXPECT_EQ(encoded->FindOutput("mask_rle") != nullptr, f == MaskFormat::kRle);
      EXPECT_EQ(encoded->FindOutput("mask_ids") != nullptr, f == MaskFormat::kInstanceIds);
      (f == MaskFormat::kDense ? dense_bytes
       : f == MaskFormat::kRle ? rle_bytes
                               : ids_bytes) += PayloadBytes(*encoded);
      const auto back = DecodeSegmentation(*encoded);
      ASSERT_TRUE(back.ok()) << back.status().ToString();
      // dense and rle give the very bytes back; instance_ids too, but where the (noisy)
      // oracle's masks overlap, the earlier instance keeps the pixel.
      Segmentation expected = *seg;
      if (f == MaskFormat::kInstanceIds) {
        std::vector<uint8_t> taken(static_cast<size_t>(seg->width * seg->height), 0);
        for (InstanceMask& m : expected.instances) {
          for (size_t p = 0; p < taken.size(); ++p) {
            if (m.mask.data()[p] == 0) continue;
            if (taken[p] != 0) m.mask.data()[p] = 0;
            taken[p] = 1;
          }
        }
      }
      ExpectSameSegmentation(*back, expected, std::string(ToString(f)));
    }
  }
  ASSERT_GT(instances, 4u);
  std::printf("%zu instances in 4 frames: dense %zu bytes, rle %zu, instance_ids %zu\n", instances,
              dense_bytes, rle_bytes, ids_bytes);
  EXPECT_LT(rle_bytes * 50, dense_bytes);
  EXPECT_LT(ids_bytes, dense_bytes);
}

TEST(SegmentationCodecTest, InstanceIdsKeepTheEarlierInstanceWhereMasksOverlap) {
  Segmentation s;
  s.width = 4;
  s.height = 2;
  for (int i = 0; i < 2; ++i) {
    InstanceMask m;
    m.mask = MaskImage(4, 2, 0);
    for (int u = i; u < i + 3; ++u) m.mask.at(u, 1) = i == 0 ? 255 : 1;
    m.confidence = 0.9f - 0.1f * static_cast<float>(i);
    s.instances.push_back(std::move(m));
  }
  const auto rle = DecodeSegmentation(*EncodeSegmentation(s, MaskFormat::kRle));
  ASSERT_TRUE(rle.ok()) << rle.status().ToString();
  ExpectSameSegmentation(*rle, s);  // RLE is exact, overlaps and foreground values included
  const auto ids = DecodeSegmentation(*EncodeSegmentation(s, MaskFormat::kInstanceIds));
  ASSERT_TRUE(ids.ok()) << ids.status().ToString();
  EXPECT_TRUE(ids->instances[0].mask == s.instances[0].mask);
  // Pixels (1, 1) and (2, 1) went to instance 0; instance 1 keeps (3, 1), with its value 1.
  EXPECT_EQ(ids->instances[1].mask.at(1, 1), 0);
  EXPECT_EQ(ids->instances[1].mask.at(2, 1), 0);
  EXPECT_EQ(ids->instances[1].mask.at(3, 1), 1);
}

TEST(SegmentationCodecTest, BadCompactMasksAreErrorsNamingTheOutput) {
  Segmentation s;
  s.width = 3;
  s.height = 2;
  InstanceMask m;
  m.mask = MaskImage(3, 2, 0);
  m.mask.at(1, 1) = 255;
  s.instances.push_back(m);
  const auto error = [](InferResponse r) {
    const auto d = DecodeSegmentation(r);
    EXPECT_FALSE(d.ok());
    return d.ok() ? std::string() : d.status().ToString();
  };
  InferResponse rle = *EncodeSegmentation(s, MaskFormat::kRle);
  InferResponse no_size = rle;
  std::erase_if(no_size.outputs, [](const Tensor& t) { return t.name == "image_size"; });
  EXPECT_THAT(error(no_size), HasSubstr("no 'image_size'"));
  InferResponse odd = rle;
  const std::vector<std::string> three = {"abc"};
  *std::find_if(odd.outputs.begin(), odd.outputs.end(), [](const Tensor& t) {
    return t.name == "mask_rle";
  }) = MakeBytesTensor("mask_rle", three);
  EXPECT_THAT(error(odd), HasSubstr("'mask_rle'[0] has 3 bytes"));
  InferResponse short_runs = rle;
  const std::vector<uint32_t> runs = {1, 2};  // sums to 3, not 6
  std::string bytes(reinterpret_cast<const char*>(runs.data()), 8);
  *std::find_if(short_runs.outputs.begin(), short_runs.outputs.end(), [](const Tensor& t) {
    return t.name == "mask_rle";
  }) = MakeBytesTensor("mask_rle", std::vector<std::string>{bytes});
  EXPECT_THAT(error(short_runs), HasSubstr("mask_rle'[0]"));
  InferResponse ids = *EncodeSegmentation(s, MaskFormat::kInstanceIds);
  const std::vector<uint16_t> big = {0, 0, 0, 0, 7, 0};
  *std::find_if(ids.outputs.begin(), ids.outputs.end(), [](const Tensor& t) {
    return t.name == "mask_ids";
  }) = MakeTensor<uint16_t>("mask_ids", DataType::kUint16, {2, 3}, std::span<const uint16_t>(big));
  EXPECT_THAT(error(ids), HasSubstr("id 7 at pixel (1, 1), but there are 1 instances"));
  // A few bytes declaring two 16384 x 16384 masks are refused before anything is allocated.
  InferResponse huge = rle;
  const std::vector<int32_t> big_size = {16384, 16384};
  *std::find_if(huge.outputs.begin(), huge.outputs.end(), [](const Tensor& t) {
    return t.name == "image_size";
  }) = MakeTensor<int32_t>("image_size", DataType::kInt32, {2}, std::span<const int32_t>(big_size));
  const std::vector<std::string> two = {"", ""};
  *std::find_if(huge.outputs.begin(), huge.outputs.end(), [](const Tensor& t) {
    return t.name == "mask_rle";
  }) = MakeBytesTensor("mask_rle", two);
  const std::vector<float> two_scores = {0.5f, 0.5f};
  *std::find_if(huge.outputs.begin(), huge.outputs.end(), [](const Tensor& t) {
    return t.name == "scores";
  }) = MakeTensor<float>("scores", DataType::kFp32, {2}, std::span<const float>(two_scores));
  const auto d = DecodeSegmentation(huge);
  EXPECT_EQ(d.status().code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(d.status().message(), HasSubstr("over the limit"));
  EXPECT_FALSE(MaskFormatFromString("zip").has_value());
  EXPECT_EQ(*MaskFormatFromString("instance_ids"), MaskFormat::kInstanceIds);
}

TEST(SegmentationCodecTest, SegmentationRoundTripsEveryField) {
  Segmentation s;
  s.width = 5;
  s.height = 3;
  for (int i = 0; i < 3; ++i) {
    InstanceMask m;
    m.mask = MaskImage(5, 3, 0);
    m.mask.at(i, 1) = 1;
    m.mask.at(4, 2) = static_cast<uint8_t>(200 + i);  // nonzero values other than 1 stay as sent
    m.semantic_class = static_cast<SemanticClass>(i + 1);
    m.confidence = 0.1f * static_cast<float>(i + 1);
    m.label = i == 1 ? "green apple, ripe ☺" : (i == 2 ? "" : "tomato");
    if (i != 1) m.box = PixelBox{0.5f, 1.25f, 4.0f + i, 3.0f};
    m.mask_score = i == 0 ? -1.0f : 0.8125f;
    s.instances.push_back(std::move(m));
  }
  s.timings = {{"detector", 12.5}, {"sam \"encoder\"", 0.1}, {"detector", 1e-300}};
  auto encoded = EncodeSegmentation(s);
  ASSERT_TRUE(encoded.ok()) << encoded.status().ToString();
  std::vector<std::string> names;
  for (const Tensor& t : encoded->outputs) names.push_back(t.name);
  EXPECT_EQ(names, (std::vector<std::string>{"masks", "classes", "scores", "labels", "boxes",
                                             "has_box", "mask_scores"}));
  for (size_t i = 0; i < encoded->outputs.size(); ++i) {
    EXPECT_EQ(encoded->outputs[i].datatype, SegmentationOutputs()[i].datatype) << names[i];
  }
  EXPECT_EQ(encoded->FindOutput("masks")->shape, (std::vector<int64_t>{3, 3, 5}));
  auto back = DecodeSegmentation(*encoded);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ExpectSameSegmentation(*back, s);

  Segmentation empty;
  empty.width = 640;
  empty.height = 480;
  auto e = DecodeSegmentation(*EncodeSegmentation(empty));
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->width, 640);
  EXPECT_EQ(e->height, 480);
  EXPECT_TRUE(e->instances.empty());
  EXPECT_TRUE(e->timings.empty());
}

TEST(SegmentationCodecTest, OptionalOutputsHaveDefaults) {
  InferResponse r;
  const std::vector<uint8_t> masks = {1, 0, 0, 1};
  const std::vector<float> scores = {0.9f, 0.4f};
  r.outputs.push_back(
      MakeTensor<uint8_t>("masks", DataType::kBool, {2, 1, 2}, std::span<const uint8_t>(masks)));
  r.outputs.push_back(
      MakeTensor<float>("scores", DataType::kFp32, {2}, std::span<const float>(scores)));
  auto s = DecodeSegmentation(r);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  ASSERT_EQ(s->instances.size(), 2u);
  EXPECT_EQ(s->instances[1].semantic_class, SemanticClass::kFruit);
  EXPECT_EQ(s->instances[1].label, "");
  EXPECT_FALSE(s->instances[1].box.has_value());
  EXPECT_EQ(s->instances[1].mask_score, -1.0f);
  EXPECT_EQ(s->instances[1].mask.at(1, 0), 1);
}

TEST(SegmentationCodecTest, MalformedResponsesAreErrorsNamingTheOutput) {
  Segmentation s;
  s.width = 2;
  s.height = 2;
  InstanceMask m;
  m.mask = MaskImage(2, 2, 1);
  s.instances.push_back(m);
  const InferResponse good = *EncodeSegmentation(s);

  InferResponse r = good;
  r.outputs.erase(r.outputs.begin());
  EXPECT_THAT(DecodeSegmentation(r).status().message(), HasSubstr("lacks output 'masks'"));

  r = good;
  r.outputs[2].shape = {2};
  EXPECT_THAT(DecodeSegmentation(r).status().message(), HasSubstr("output 'scores'"));

  r = good;
  const std::vector<int32_t> bad_class = {9};
  r.outputs[1] =
      MakeTensor<int32_t>("classes", DataType::kInt32, {1}, std::span<const int32_t>(bad_class));
  EXPECT_EQ(DecodeSegmentation(r).status().message(),
            "output 'classes'[0] (9) is not a semantic class id (0 - 6)");

  for (const float bad : {1.5f, -0.1f, std::numeric_limits<float>::quiet_NaN()}) {
    r = good;
    const std::vector<float> score = {bad};
    r.outputs[2] = MakeTensor<float>("scores", DataType::kFp32, {1}, std::span<const float>(score));
    const auto d = DecodeSegmentation(r);
    ASSERT_FALSE(d.ok()) << bad;
    EXPECT_THAT(d.status().message(), HasSubstr("output 'scores'[0] ("));
    EXPECT_THAT(d.status().message(), HasSubstr("must be a confidence: finite and in [0, 1]"));
  }

  r = good;
  r.parameters["timings"] = std::string("[{\"stage\": 3}]");
  EXPECT_THAT(DecodeSegmentation(r).status().message(), HasSubstr("parameter 'timings'"));

  s.instances[0].mask = MaskImage(3, 2, 1);
  EXPECT_THAT(EncodeSegmentation(s).status().message(), HasSubstr("instance 0: mask is 3x2"));
}

// ---- malformed requests
// --------------------------------------------------------------------------

class MalformedRequestTest : public CodecTest {
 protected:
  void SetUp() override { good_ = Encode(scene_.Request(1)); }
  /// The decoder's error for `r`, which must be InvalidArgument.
  std::string Error(const InferRequest& r) {
    auto d = DecodeSegmentationRequest(r);
    EXPECT_FALSE(d.ok());
    if (d.ok()) return "";
    EXPECT_EQ(d.status().code(), StatusCode::kInvalidArgument) << d.status().ToString();
    return d.status().message();
  }
  InferRequest good_;
};

TEST_F(MalformedRequestTest, WrongDatatype) {
  InferRequest r = good_;
  FindMutable(r, "depth")->datatype = DataType::kFp64;
  FindMutable(r, "depth")->shape = {60, 160};  // same bytes, so only the datatype is wrong
  EXPECT_EQ(Error(r),
            "input 'depth' must be FP32 [H, W] = [120, 160] (the colour image's size), got FP64 "
            "[60, 160]");
  r = good_;
  FindMutable(r, "rgb")->datatype = DataType::kInt8;
  EXPECT_EQ(Error(r), "input 'rgb' must be UINT8 [H, W, 3] RGB8, got INT8 [120, 160, 3]");
}

TEST_F(MalformedRequestTest, WrongShape) {
  InferRequest r = good_;
  FindMutable(r, "rgb")->shape = {120, 120, 4};
  EXPECT_EQ(Error(r), "input 'rgb' must be UINT8 [H, W, 3] RGB8, got UINT8 [120, 120, 4]");
  r = good_;
  FindMutable(r, "instance_ids")->shape = {160, 120};
  EXPECT_THAT(Error(r), HasSubstr("input 'instance_ids' must be UINT16 [H, W] = [120, 160]"));
  r = good_;
  FindMutable(r, "intrinsics")->shape = {2, 3};
  EXPECT_THAT(Error(r), HasSubstr("input 'intrinsics' must be FP64 [6]"));
}

TEST_F(MalformedRequestTest, ShapeAndBytesDisagree) {
  InferRequest r = good_;
  FindMutable(r, "rgb")->data.resize(100);
  EXPECT_EQ(Error(r), "input 'rgb': shape [120, 160, 3] of UINT8 needs 57600 bytes, got 100");
}

TEST_F(MalformedRequestTest, MissingOrEmptyTensors) {
  InferRequest r = good_;
  std::erase_if(r.inputs, [](const Tensor& t) { return t.name == "rgb"; });
  EXPECT_EQ(Error(r),
            "missing input 'rgb' (UINT8 [H, W, 3]) or 'image' (BYTES [1], a PNG or JPEG)");
  r = good_;
  std::erase_if(r.inputs, [](const Tensor& t) { return t.name == "prompt"; });
  EXPECT_THAT(Error(r), HasSubstr("missing input 'prompt'"));
  r = good_;
  *FindMutable(r, "prompt") = MakeBytesTensor("prompt", {" , "});
  EXPECT_THAT(Error(r), HasSubstr("input 'prompt' (\" , \") is empty"));
  r = good_;
  *FindMutable(r, "prompt") = MakeBytesTensor("prompt", {});
  EXPECT_THAT(Error(r), HasSubstr("input 'prompt' (\"\") is empty"));
  r = good_;
  std::erase_if(r.inputs, [](const Tensor& t) { return t.name == "class_ids"; });
  EXPECT_THAT(Error(r), HasSubstr("input 'instance_ids' is given without 'class_ids'"));
}

TEST_F(MalformedRequestTest, UndecodableImage) {
  InferRequest r = good_;
  std::erase_if(r.inputs, [](const Tensor& t) { return t.name == "rgb"; });
  r.inputs.push_back(MakeBytesTensor("image", {"definitely not a PNG"}));
  EXPECT_EQ(Error(r), "input 'image': the 20 bytes are not a PNG or JPEG image OpenCV can decode");
  r.inputs.back() = MakeBytesTensor("image", {""});
  EXPECT_THAT(Error(r), HasSubstr("the 0 bytes are not a PNG or JPEG"));
  r.inputs.push_back(good_.inputs.front());
  EXPECT_THAT(Error(r), HasSubstr("inputs 'rgb' and 'image' are both given"));
}

TEST_F(MalformedRequestTest, BadValuesAndParameters) {
  InferRequest r = good_;
  r.inputs.push_back(MakeBytesTensor("nms_threshold", {"0.5"}));
  EXPECT_THAT(Error(r), HasSubstr("unknown input 'nms_threshold' BYTES [1]; known inputs: rgb, "
                                  "image, depth"));
  r = good_;
  r.inputs.push_back(good_.inputs.front());
  EXPECT_EQ(Error(r), "input 'rgb' is given twice");
  r = good_;
  const std::vector<double> not_rigid = {2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  *FindMutable(r, "camera_pose") = MakeTensor<double>("camera_pose", DataType::kFp64, {4, 4},
                                                      std::span<const double>(not_rigid));
  EXPECT_THAT(Error(r), HasSubstr("input 'camera_pose' (2, 0, 0, 0, 0, 1"));
  r = good_;
  const std::vector<double> bad_k = {-1, 100, 80, 60, 0.1, 3};
  *FindMutable(r, "intrinsics") =
      MakeTensor<double>("intrinsics", DataType::kFp64, {6}, std::span<const double>(bad_k));
  EXPECT_THAT(Error(r), HasSubstr("input 'intrinsics': invalid camera intrinsics: fx (-1)"));
  r = good_;
  const std::vector<double> bad_fruit = {1.5, 0, 0, 0, 0.03};
  *FindMutable(r, "fruits") =
      MakeTensor<double>("fruits", DataType::kFp64, {1, 5}, std::span<const double>(bad_fruit));
  EXPECT_THAT(Error(r), HasSubstr("input 'fruits' row 0: instance_id (1.5)"));
  r = good_;
  r.parameters["score_threshold"] = 2.0;
  EXPECT_EQ(Error(r), "parameter 'score_threshold' (2) must be in [0, 1]");
  r = good_;
  r.parameters["seed"] = true;
  EXPECT_THAT(Error(r), HasSubstr("parameter 'seed' (bool true)"));
  r = good_;
  r.parameters["frame_index"] = std::string("seven");
  EXPECT_THAT(Error(r), HasSubstr("parameter 'frame_index' (string \"seven\")"));
  r = good_;
  r.parameters["mask_format"] = std::string("zip");
  EXPECT_EQ(Error(r), "parameter 'mask_format' ('zip') must be dense, rle or instance_ids");
  r = good_;
  r.parameters["mask_format"] = std::string("rle");
  const auto rle = DecodeSegmentationRequest(r);
  ASSERT_TRUE(rle.ok()) << rle.status().ToString();
  EXPECT_EQ(rle->mask_format, MaskFormat::kRle);
}

// ---- budgets: checked before anything is decoded
// -----------------------------------------------------------------

/// A PNG of 8-byte signature and IHDR chunk declaring w x h, and no pixels at all.
std::string PngHeader(uint32_t w, uint32_t h) {
  std::string png = "\x89PNG\r\n\x1a\n";
  const auto be32 = [&](uint32_t v) {
    for (int i = 3; i >= 0; --i) png.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  };
  be32(13);
  png += "IHDR";
  be32(w);
  be32(h);
  png += std::string("\x08\x02\x00\x00\x00", 5);  // 8-bit RGB
  be32(0);                                        // CRC (never read)
  png += "garbage instead of IDAT";
  return png;
}

/// A JPEG: SOI, an APP0 segment, then an SOF0 frame header declaring w x h.
std::string JpegHeader(uint16_t w, uint16_t h) {
  std::string jpeg = "\xff\xd8";
  jpeg += std::string("\xff\xe0\x00\x06JFIF", 8);
  jpeg += std::string("\xff\xc0\x00\x11\x08", 5);
  jpeg.push_back(static_cast<char>(h >> 8));
  jpeg.push_back(static_cast<char>(h & 0xff));
  jpeg.push_back(static_cast<char>(w >> 8));
  jpeg.push_back(static_cast<char>(w & 0xff));
  jpeg += "rest of a frame that is never decoded";
  return jpeg;
}

class BudgetTest : public MalformedRequestTest {
 protected:
  /// The decoder's error for `r`, which must be ResourceExhausted.
  std::string Exhausted(const InferRequest& r, const RequestBudget& budget = {}) {
    auto d = DecodeSegmentationRequest(r, budget);
    EXPECT_FALSE(d.ok());
    if (d.ok()) return "";
    EXPECT_EQ(d.status().code(), StatusCode::kResourceExhausted) << d.status().ToString();
    EXPECT_EQ(CheckRequestBudget(r, budget).message(), d.status().message());
    return d.status().message();
  }
  InferRequest WithImage(std::string bytes) {
    InferRequest r = good_;
    std::erase_if(r.inputs, [](const Tensor& t) { return t.name != "prompt"; });
    r.inputs.push_back(MakeBytesTensor("image", {std::move(bytes)}));
    return r;
  }
};

TEST(EncodedImageSizeTest, ReadsPngAndJpegHeadersOnly) {
  EXPECT_EQ(EncodedImageSize(PngHeader(20000, 20000)), std::make_pair(20000u, 20000u));
  EXPECT_EQ(EncodedImageSize(JpegHeader(640, 480)), std::make_pair(640u, 480u));
  // A real PNG from the codec.
  ImageRgb8 rgb(7, 5, 10);
  auto png = io::EncodePng(rgb);
  ASSERT_TRUE(png.ok());
  EXPECT_EQ(EncodedImageSize(std::string(png->begin(), png->end())), std::make_pair(7u, 5u));
  auto jpeg = io::EncodeJpeg(rgb, 90);
  ASSERT_TRUE(jpeg.ok());
  EXPECT_EQ(EncodedImageSize(std::string(jpeg->begin(), jpeg->end())), std::make_pair(7u, 5u));
  // Cut short, other formats, nothing.
  EXPECT_EQ(EncodedImageSize(PngHeader(1, 1).substr(0, 20)), std::nullopt);
  EXPECT_EQ(EncodedImageSize(JpegHeader(1, 1).substr(0, 14)), std::nullopt);
  EXPECT_EQ(EncodedImageSize("BM\x36\x00\x00\x00"), std::nullopt);
  EXPECT_EQ(EncodedImageSize(""), std::nullopt);
  EXPECT_EQ(EncodedImageSize(std::string("\xff\xd8\xff\xd9", 4)), std::nullopt);
}

TEST_F(BudgetTest, AnImageDeclaring20000x20000PixelsIsRefusedBeforeDecoding) {
  // A few dozen bytes that declare 400 million pixels: refused from the header, never decoded
  // (decoding them would fail as undecodable instead).
  EXPECT_EQ(Exhausted(WithImage(PngHeader(20000, 20000))),
            "input 'image' declaring 20000 x 20000 pixels (400000000) exceeds the limit "
            "max_image_pixels = 16777216; raise it with `avp serve segmentation "
            "--max-image-pixels N` (docs/segmentation-service.md)");
  EXPECT_THAT(Exhausted(WithImage(JpegHeader(20000, 20000))),
              HasSubstr("input 'image' declaring 20000 x 20000 pixels (400000000)"));
  // A raw 'rgb' declaring the same, with no bytes at all: its shape is enough.
  InferRequest r = good_;
  Tensor* rgb = FindMutable(r, "rgb");
  rgb->shape = {20000, 20000, 3};
  rgb->data.clear();
  EXPECT_THAT(Exhausted(r), HasSubstr("input 'rgb' of 20000 x 20000 pixels (400000000) exceeds "
                                      "the limit max_image_pixels"));
  rgb->shape = {1, 20000, 20000, 3};
  EXPECT_THAT(Exhausted(r), HasSubstr("max_image_pixels"));
  r = good_;
  FindMutable(r, "depth")->shape = {1 << 30, 1 << 30};
  EXPECT_THAT(Exhausted(r), HasSubstr("input 'depth' of 1073741824 x 1073741824 pixels"));
  // The budget is the server's: a smaller one refuses the 160 x 120 frame too.
  RequestBudget small;
  small.max_image_pixels = 160 * 120 - 1;
  EXPECT_THAT(Exhausted(good_, small), HasSubstr("input 'rgb' of 160 x 120 pixels (19200)"));
  small.max_image_pixels = 160 * 120;
  EXPECT_TRUE(DecodeSegmentationRequest(good_, small).ok());
}

TEST_F(BudgetTest, OnlyPngAndJpegAreAccepted) {
  // OpenCV would decode a BMP (and read its declared size first): the format is not accepted.
  const std::string bmp = std::string("BM") + std::string(52, '\0');
  EXPECT_EQ(Error(WithImage(bmp)),
            "input 'image': the 54 bytes are not a PNG or JPEG image OpenCV can decode");
  InferRequest r = WithImage("x");
  r.inputs.back().shape = {100000};
  EXPECT_THAT(Error(r), HasSubstr("input 'image' must be BYTES [1]"));
  EXPECT_THAT(Error(r), HasSubstr("got BYTES [100000]"));
}

TEST_F(BudgetTest, AHundredThousandPhrasePromptIsRefusedNamingTheLimit) {
  std::string prompt = "tomato";
  for (int i = 1; i < 100000; ++i) prompt += ", tomato";
  InferRequest r = good_;
  *FindMutable(r, "prompt") = MakeBytesTensor("prompt", {prompt});
  EXPECT_EQ(Exhausted(r),
            "input 'prompt' (799998) exceeds the limit max_prompt_bytes = 4096; raise it with "
            "`avp serve segmentation --max-prompt-bytes N` (docs/segmentation-service.md)");
  // As 100 000 elements.
  *FindMutable(r, "prompt") = MakeBytesTensor("prompt", std::vector<std::string>(100000, "tomato"));
  EXPECT_THAT(Exhausted(r), HasSubstr("phrases (elements) of input 'prompt' (100000) exceeds the "
                                      "limit max_prompt_phrases = 64"));
  // Within the bytes, beyond the phrases.
  std::string many = "a";
  for (int i = 1; i < 65; ++i) many += ",a";
  *FindMutable(r, "prompt") = MakeBytesTensor("prompt", {many});
  EXPECT_THAT(Exhausted(r), HasSubstr("phrases in input 'prompt' (65) exceeds the limit "
                                      "max_prompt_phrases = 64"));
  RequestBudget more;
  more.max_prompt_phrases = 65;
  const ScopedLimit more_in_process(segmentation::MaxPromptPhrases(), 65);
  auto d = DecodeSegmentationRequest(r, more);
  ASSERT_TRUE(d.ok()) << d.status().ToString();
}

TEST_F(BudgetTest, CountsOfInputsParametersAndFruitsAreBounded) {
  InferRequest r = good_;
  for (int i = 0; i < 10; ++i) r.inputs.push_back(MakeBytesTensor("x", {"y"}));
  EXPECT_THAT(Error(r), HasSubstr("the request has 18 inputs: a segmentation request has at most "
                                  "9"));
  r = good_;
  for (int i = 0; i < 65; ++i) r.parameters[fmt::format("p{}", i)] = int64_t{i};
  EXPECT_THAT(Error(r), HasSubstr("parameters: at most 64 are accepted"));
  r = good_;
  r.parameters["frame_id"] = std::string(5000, '\x1b');
  EXPECT_THAT(Error(r), HasSubstr("parameter 'frame_id' is 5008 bytes long"));
  r = good_;
  r.requested_outputs.assign(12, "masks");
  EXPECT_THAT(Error(r), HasSubstr("asks for 12 outputs"));
  r = good_;
  FindMutable(r, "fruits")->shape = {70000, 5};
  EXPECT_THAT(Error(r), HasSubstr("input 'fruits' has 70000 rows: at most 65535"));
  r = good_;
  r.inputs.push_back(MakeBytesTensor(std::string(300, '\x1b'), {"y"}));
  const std::string unknown = Error(r);
  EXPECT_THAT(unknown, HasSubstr("unknown input '\\x1b\\x1b"));
  EXPECT_EQ(unknown.find('\x1b'), std::string::npos);
  EXPECT_LT(unknown.size(), 500u);
}

TEST_F(CodecTest, EncodeRejectsBadRequests) {
  segmentation::SegmentationRequest r = scene_.Request();
  r.frame = nullptr;
  EXPECT_EQ(EncodeSegmentationRequest(r, {}).status().message(),
            "segmentation request: frame is null");
  r = scene_.Request(0, "  ");
  EXPECT_THAT(EncodeSegmentationRequest(r, {}).status().message(), HasSubstr("has no phrase"));
  SimulatorLabels small;
  small.instance_ids = InstanceImage(2, 2);
  small.class_ids = ClassImage(2, 2);
  r = scene_.Request();
  r.labels = &small;
  EXPECT_THAT(EncodeSegmentationRequest(r, {}).status().message(),
              HasSubstr("simulator labels are 2x2"));
}

}  // namespace
}  // namespace avp::segmentation_service

// The built-in I/O contracts and CheckContract: synthetic model I/O for each kind of mismatch, then
// every good stub model (make_stubs.py) against its contract.
#include "contracts.h"

#include <cctype>
#include <filesystem>
#include <ostream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "ort_runtime.h"

namespace avp::zsl {
namespace {

using ::testing::HasSubstr;

constexpr ElementType f32 = ElementType::kFloat32;
constexpr ElementType i64 = ElementType::kInt64;
constexpr ElementType i32 = ElementType::kInt32;

const std::filesystem::path kStubs = AVP_ZSL_STUB_DIR;

const Contract& Get(const char* id) {
  Result<const Contract*> c = FindContract(id);
  EXPECT_TRUE(c.ok()) << c.status().ToString();
  return **c;
}

ModelIo TxtFeatsIo() {
  return {{{"images", f32, {1, 3, 640, 640}}, {"txt_feats", f32, {1, 32, 512}}},
          {{"output0", f32, {1, 36, 8400}}}};
}

ModelIo DecoderIo() {
  return {{{"image_embeddings", f32, {1, 256, 64, 64}},
           {"point_coords", f32, {-1, -1, 2}},
           {"point_labels", f32, {-1, -1}}},
          {{"masks", f32, {-1, 1, 256, 256}}, {"iou_predictions", f32, {-1, 1}}}};
}

std::string ErrorOf(const Result<ContractBinding>& r) {
  EXPECT_FALSE(r.ok());
  return r.ok() ? "" : r.status().message();
}

TEST(ContractsTest, SixBuiltinContractsInDesignOrder) {
  std::vector<std::string> ids;
  for (const Contract& c : BuiltinContracts()) ids.push_back(c.id);
  EXPECT_EQ(ids, (std::vector<std::string>{"yoloworld.txtfeats/1", "yoloworld.baked/1",
                                           "clip.text/1", "evitsam.encoder/1",
                                           "evitsam.decoder.single/1", "gdino.ort/1"}));
  const Contract& gdino = Get(kGroundingDinoOrt);
  ASSERT_NE(gdino.FindInput("text_token_mask"), nullptr);
  EXPECT_EQ(gdino.FindInput("text_token_mask")->type, ElementType::kBool);
  EXPECT_EQ(ShapeToString(gdino.FindInput("text_token_mask")->shape), "[1,L,L]");
  EXPECT_EQ(ShapeToString(gdino.FindOutput("logits")->shape), "[1,900,256]");
  EXPECT_EQ(ShapeToString(Get(kYoloWorldTxtFeats).FindOutput("output0")->shape), "[1,4+N,8400]");
  EXPECT_EQ(ShapeToString(Get(kYoloWorldTxtFeats).FindOutput("output0")->transposed_shape),
            "[1,8400,4+N]");
  EXPECT_EQ(ShapeToString(Get(kClipText).FindInput("input_ids")->shape), "[B,77]");
  EXPECT_EQ(ShapeToString(Get(kEvitSamEncoder).FindInput("input_image")->shape), "[1,3,S,S]");
}

TEST(ContractsTest, UnknownContractListsTheBuiltinOnes) {
  Result<const Contract*> c = FindContract("yolo/9");
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(c.status().message(), HasSubstr("unknown contract 'yolo/9' (built in: "
                                              "yoloworld.txtfeats/1, yoloworld.baked/1"));
}

TEST(ContractsTest, GoodTextFeatureDetectorBindsN) {
  Result<ContractBinding> b = CheckContract("detector", TxtFeatsIo(), Get(kYoloWorldTxtFeats));
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->Dim("N"), 32);
  EXPECT_EQ(b->Name("output0"), "output0");
  EXPECT_FALSE(b->transposed);
}

TEST(ContractsTest, AlternativeOutputNameIsBound) {
  ModelIo io = TxtFeatsIo();
  io.outputs[0].name = "output";
  Result<ContractBinding> b = CheckContract("detector", io, Get(kYoloWorldTxtFeats));
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->Name("output0"), "output");
}

TEST(ContractsTest, DynamicAxesAreAcceptedAndReportedDynamic) {
  const ModelIo clip = {{{"input_ids", i64, {-1, 77}}}, {{"text_embeds", f32, {-1, 512}}}};
  Result<ContractBinding> b = CheckContract("text", clip, Get(kClipText));
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->Dim("B"), kDynamicDim);
  Result<ContractBinding> d =
      CheckContract("segmenter.decoder", DecoderIo(), Get(kEvitSamDecoderSingle));
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  EXPECT_EQ(d->Dim("B"), kDynamicDim);
  EXPECT_EQ(d->Dim("P"), kDynamicDim);
}

TEST(ContractsTest, RenamedInputNamesTheMissingTensorAndTheStranger) {
  ModelIo io = TxtFeatsIo();
  io.inputs[0].name = "image";
  const std::string e = ErrorOf(CheckContract("detector", io, Get(kYoloWorldTxtFeats)));
  EXPECT_THAT(e, HasSubstr("detector: input 'images' is missing (the model has 'image', "
                           "'txt_feats'); yoloworld.txtfeats/1 expects images float32 "
                           "[1,3,640,640]"));
  EXPECT_THAT(e, HasSubstr("detector: input 'image' (float32 [1,3,640,640]) is not part of "
                           "yoloworld.txtfeats/1 (its inputs are images, txt_feats)"));
}

TEST(ContractsTest, WrongElementTypeIsOneActionableLine) {
  ModelIo io = DecoderIo();
  io.inputs[2].type = i32;
  EXPECT_EQ(ErrorOf(CheckContract("segmenter.decoder", io, Get(kEvitSamDecoderSingle))),
            "segmenter.decoder: input 'point_labels' is int32; evitsam.decoder.single/1 expects "
            "float32");
}

TEST(ContractsTest, WrongRank) {
  ModelIo io = TxtFeatsIo();
  io.inputs[1].shape = {32, 512};
  EXPECT_THAT(ErrorOf(CheckContract("detector", io, Get(kYoloWorldTxtFeats))),
              HasSubstr("detector: input 'txt_feats' has rank 2 ([32,512]); yoloworld.txtfeats/1 "
                        "expects rank 3 [1,N,512]"));
}

TEST(ContractsTest, WrongStaticDimension) {
  const ModelIo io = {{{"input_image", f32, {1, 3, 512, 512}}},
                      {{"image_embeddings", f32, {1, 256, 32, 32}}}};
  EXPECT_EQ(ErrorOf(CheckContract("segmenter.encoder", io, Get(kEvitSamEncoder))),
            "segmenter.encoder: output 'image_embeddings' has shape [1,256,32,32]; "
            "evitsam.encoder/1 expects [1,256,64,64] (dim 2 is 32, not 64, dim 3 is 32, not 64)");
}

TEST(ContractsTest, SymbolsMustAgreeAcrossTensors) {
  ModelIo io = TxtFeatsIo();
  io.outputs[0].shape = {1, 20, 8400};
  EXPECT_THAT(ErrorOf(CheckContract("detector", io, Get(kYoloWorldTxtFeats))),
              HasSubstr("output 'output0' has shape [1,20,8400]; yoloworld.txtfeats/1 expects "
                        "[1,4+N,8400] (dim 1 is 20, not 4+N = 36 (N = 32 from input "
                        "'txt_feats'))"));
  const ModelIo square = {{{"input_image", f32, {1, 3, 512, 1024}}},
                          {{"image_embeddings", f32, {1, 256, 64, 64}}}};
  EXPECT_THAT(ErrorOf(CheckContract("segmenter.encoder", square, Get(kEvitSamEncoder))),
              HasSubstr("dim 3 is 1024, not S = 512 (S = 512 from input 'input_image')"));
}

TEST(ContractsTest, BakedClassCountComesFromTheOutput) {
  const ModelIo io = {{{"images", f32, {1, 3, 640, 640}}}, {{"output0", f32, {1, 6, 8400}}}};
  Result<ContractBinding> b = CheckContract("detector", io, Get(kYoloWorldBaked));
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->Dim("NC"), 2);
  const ModelIo none = {{{"images", f32, {1, 3, 640, 640}}}, {{"output0", f32, {1, 4, 8400}}}};
  EXPECT_THAT(ErrorOf(CheckContract("detector", none, Get(kYoloWorldBaked))),
              HasSubstr("dim 1 is 4, not 4+NC with NC >= 1"));
}

TEST(ContractsTest, UndeclaredTransposedOutputSaysHowToDeclareIt) {
  ModelIo io = TxtFeatsIo();
  io.outputs[0].shape = {1, 8400, 36};
  EXPECT_THAT(ErrorOf(CheckContract("detector", io, Get(kYoloWorldTxtFeats))),
              HasSubstr("detector: output 'output0' has shape [1,8400,36]; yoloworld.txtfeats/1 "
                        "expects [1,4+N,8400] (dim 1 is 8400, not 4+N = 36 (N = 32 from input "
                        "'txt_feats'), dim 2 is 36, not 8400); this is the transposed [A,4+N] "
                        "layout: declare it with postprocess.layout \"[A,4+N]\""));
  ContractCheckOptions declared;
  declared.transposed_layout = true;
  Result<ContractBinding> b =
      CheckContract("detector", io, Get(kYoloWorldTxtFeats), nullptr, declared);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_TRUE(b->transposed);
  EXPECT_EQ(b->Dim("N"), 32);
  // Declared transposed, but the model is not.
  EXPECT_THAT(
      ErrorOf(CheckContract("detector", TxtFeatsIo(), Get(kYoloWorldTxtFeats), nullptr, declared)),
      HasSubstr("the manifest declares postprocess.layout \"[A,4+N]\" but this is the "
                "[4+N,A] layout"));
}

TEST(ContractsTest, MissingOutput) {
  ModelIo io = DecoderIo();
  io.outputs.pop_back();
  EXPECT_EQ(ErrorOf(CheckContract("segmenter.decoder", io, Get(kEvitSamDecoderSingle))),
            "segmenter.decoder: output 'iou_predictions' is missing (the model has 'masks'); "
            "evitsam.decoder.single/1 expects iou_predictions float32 [B,1]");
}

TEST(ContractsTest, ExtraOutputsAreFineExtraInputsAreNot) {
  ModelIo io = DecoderIo();
  io.outputs.push_back({"low_res_masks", f32, {-1, 4, 256, 256}});
  EXPECT_TRUE(CheckContract("segmenter.decoder", io, Get(kEvitSamDecoderSingle)).ok());
  io.inputs.push_back({"mask_input", f32, {1, 1, 256, 256}});
  EXPECT_EQ(ErrorOf(CheckContract("segmenter.decoder", io, Get(kEvitSamDecoderSingle))),
            "segmenter.decoder: input 'mask_input' (float32 [1,1,256,256]) is not part of "
            "evitsam.decoder.single/1 (its inputs are image_embeddings, point_coords, "
            "point_labels)");
}

TEST(ContractsTest, EveryProblemIsReportedOnOneLine) {
  ModelIo io = DecoderIo();
  io.inputs[1].type = i32;
  io.inputs[2].type = i32;
  const std::string e = ErrorOf(CheckContract("segmenter.decoder", io, Get(kEvitSamDecoderSingle)));
  EXPECT_EQ(e,
            "segmenter.decoder: input 'point_coords' is int32; evitsam.decoder.single/1 expects "
            "float32; segmenter.decoder: input 'point_labels' is int32; evitsam.decoder.single/1 "
            "expects float32");
  EXPECT_EQ(e.find('\n'), std::string::npos);
}

TEST(ContractsTest, TheManifestMayStateWhatTheGraphLeavesDynamic) {
  // The official EfficientViT-SAM L0 encoder export (export_encoder.py, torch 1.13) has a dynamic
  // batch axis and symbolic output dimensions; the docs' shapes stated in the manifest are
  // accepted, and it is the stated value that the contract then checks.
  const ModelIo official = {{{"input_image", f32, {-1, 3, 512, 512}}},
                            {{"image_embeddings", f32, {-1, 256, -1, -1}}}};
  ModelIo declared = {{{"input_image", f32, {1, 3, 512, 512}}},
                      {{"image_embeddings", f32, {1, 256, 64, 64}}}};
  const Result<ContractBinding> b =
      CheckContract("segmenter.encoder", official, Get(kEvitSamEncoder), &declared);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->Dim("S"), 512);
  declared.outputs[0].shape = {1, 256, 32, 32};
  EXPECT_THAT(
      ErrorOf(CheckContract("segmenter.encoder", official, Get(kEvitSamEncoder), &declared)),
      HasSubstr("segmenter.encoder: output 'image_embeddings' has shape [1,256,32,32]; "
                "evitsam.encoder/1 expects"));
}

TEST(ContractsTest, DeclaredIoMustDescribeTheModel) {
  ModelIo declared = TxtFeatsIo();
  declared.inputs[1].shape = {1, 16, 512};
  EXPECT_EQ(ErrorOf(CheckContract("detector", TxtFeatsIo(), Get(kYoloWorldTxtFeats), &declared)),
            "detector: input 'txt_feats' has shape [1,32,512]; the manifest declares [1,16,512]");

  declared = TxtFeatsIo();
  declared.inputs[1].shape = {1, -1, 512};  // -1 in the manifest matches anything
  EXPECT_TRUE(CheckContract("detector", TxtFeatsIo(), Get(kYoloWorldTxtFeats), &declared).ok());

  declared = TxtFeatsIo();
  declared.inputs[0].type = ElementType::kFloat16;
  EXPECT_EQ(ErrorOf(CheckContract("detector", TxtFeatsIo(), Get(kYoloWorldTxtFeats), &declared)),
            "detector: input 'images' is float32; the manifest declares float16");

  declared = TxtFeatsIo();
  declared.outputs[0].name = "scores";
  EXPECT_EQ(ErrorOf(CheckContract("detector", TxtFeatsIo(), Get(kYoloWorldTxtFeats), &declared)),
            "detector: the manifest declares output 'scores', which the model does not have (it "
            "has 'output0')");

  declared = TxtFeatsIo();
  declared.inputs.pop_back();
  EXPECT_EQ(ErrorOf(CheckContract("detector", TxtFeatsIo(), Get(kYoloWorldTxtFeats), &declared)),
            "detector: the model's input 'txt_feats' (float32 [1,32,512]) is not declared in the "
            "manifest");
}

// ---- the good stubs satisfy their contracts ----------------------------------------------------

struct StubCase {
  const char* file;
  const char* contract;
  const char* symbol;
  int64_t value;
};

void PrintTo(const StubCase& c, std::ostream* os) { *os << c.file; }

class StubContractTest : public ::testing::TestWithParam<StubCase> {};

TEST_P(StubContractTest, LoadsAndMatches) {
  const StubCase& c = GetParam();
  SessionOptions options;
  options.device = Device::kCpu;
  Result<OrtModel> model = OrtModel::Load(kStubs / c.file, options, "stub");
  ASSERT_TRUE(model.ok()) << model.status().ToString()
                          << " (stubs come from the ctest fixture zsl_make_stubs)";
  Result<ContractBinding> b = CheckContract("stub", model->io(), Get(c.contract));
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->Dim(c.symbol), c.value);
}

INSTANTIATE_TEST_SUITE_P(
    Stubs, StubContractTest,
    ::testing::Values(
        StubCase{"ywes/detector/yolo_world_stub_txt32.onnx", kYoloWorldTxtFeats, "N", 32},
        StubCase{"ywes_logits/detector/yolo_world_stub_txt32_logits.onnx", kYoloWorldTxtFeats, "N",
                 32},
        StubCase{"ywes_baked/detector/yolo_world_stub_baked2.onnx", kYoloWorldBaked, "NC", 2},
        StubCase{"ywes/text/clip_stub_text.onnx", kClipText, "B", kDynamicDim},
        StubCase{"ywes/segmenter/evitsam_stub_encoder.onnx", kEvitSamEncoder, "S", 512},
        StubCase{"ywes/segmenter/evitsam_stub_decoder_single.onnx", kEvitSamDecoderSingle, "B",
                 kDynamicDim},
        StubCase{"lsam/grounding/groundingdino_stub_800x1200.onnx", kGroundingDinoOrt, "L",
                 kDynamicDim}),
    [](const ::testing::TestParamInfo<StubCase>& p) {
      // "ywes/detector/yolo_world_stub_txt32.onnx" -> "ywes_detector_yolo_world_stub_txt32"
      std::string name = std::filesystem::path(p.param.file).replace_extension().string();
      for (char& ch : name) {
        if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
      }
      return name;
    });

}  // namespace
}  // namespace avp::zsl

// manifest.json parsing and file checks, and LoadBackend on the stub model directories: the good
// sets are READY, every wrong-contract set fails at load with a line naming the model, the tensor
// and the expectation. Real-weight checks read AVP_ZSL_MODEL_DIR and skip when it is unset.
#include "manifest.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <ostream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::zsl {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::StartsWith;

const fs::path kStubs = AVP_ZSL_STUB_DIR;

BackendLoadOptions CpuOptions() {
  BackendLoadOptions o;
  o.session.device = Device::kCpu;
  o.session.intra_op_threads = 1;
  return o;
}

/// A minimal valid manifest with a detector and a text model; `extra` is spliced into the
/// detector's object.
std::string MiniManifest(const std::string& detector_extra = "", const std::string& top = "") {
  return R"({
  "format": "avp.zsl.models/1",)" +
         top + R"(
  "models": {
    "detector": {"contract": "yoloworld.txtfeats/1", "file": "detector/d.onnx", "bytes": 10,
                 "licence": "AGPL-3.0", "origin": "test")" +
         detector_extra + R"(},
    "text": {"contract": "clip.text/1", "file": "text/t.onnx", "bytes": 5, "licence": "MIT",
             "origin": "test", "text": {"vocabulary": "text/bpe.txt.gz"}}
  }
})";
}

/// `text` with the first `from` replaced by `to`.
std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

Status ParseStatus(const std::string& text) {
  Result<Manifest> m = ParseManifest(text, "/models", "manifest.json");
  return m.status();
}

// ---- parsing -----------------------------------------------------------------------------------

TEST(ManifestParseTest, FillsTheContractDefaults) {
  Result<Manifest> m = ParseManifest(MiniManifest(), "/models");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->format, kManifestFormat);
  const ModelEntry* det = m->Find("detector");
  ASSERT_NE(det, nullptr);
  EXPECT_EQ(det->role, "detector");
  EXPECT_EQ(det->contract, kYoloWorldTxtFeats);
  EXPECT_EQ(det->file.relative, "detector/d.onnx");
  EXPECT_EQ(det->file.path, fs::path("/models/detector/d.onnx"));
  EXPECT_EQ(det->file.bytes, 10u);
  EXPECT_FALSE(det->file.sha256.has_value());
  EXPECT_EQ(det->licence, "AGPL-3.0");
  EXPECT_EQ(det->preprocess.height, 640);
  EXPECT_EQ(det->preprocess.width, 640);
  EXPECT_EQ(det->preprocess.padding, PaddingMode::kCentre);
  EXPECT_EQ(det->preprocess.pad_value, 114.0f);
  EXPECT_EQ(det->preprocess.pad_space, PadSpace::kPixels);
  EXPECT_EQ(det->preprocess.scale, 1.0f / 255.0f);
  EXPECT_EQ(det->postprocess.layout, DetectionLayout::kAttributesByAnchors);
  EXPECT_EQ(det->postprocess.score_activation, ScoreActivation::kNone);
  EXPECT_EQ(det->postprocess.n_max, 0);
  EXPECT_TRUE(det->declared.inputs.empty());
  const ModelEntry* text = m->Find("text");
  ASSERT_NE(text, nullptr);
  ASSERT_TRUE(text->text.has_value());
  EXPECT_EQ(text->text->tokenizer, TokenizerKind::kClipBpe);
  EXPECT_EQ(text->text->context, 77);
  EXPECT_EQ(text->text->sot, 49406);
  EXPECT_EQ(text->text->eot, 49407);
  EXPECT_EQ(text->text->pad, 0);
  EXPECT_EQ(text->text->dim, 512);
  EXPECT_FALSE(text->text->normalized_in_graph);
  EXPECT_EQ(text->text->vocabulary.path, fs::path("/models/text/bpe.txt.gz"));
  EXPECT_EQ(m->Find("grounding"), nullptr);
}

TEST(ManifestParseTest, ReadsEveryFieldOfTheStubManifests) {
  Result<Manifest> m = ReadManifest(kStubs / "ywes");
  ASSERT_TRUE(m.ok()) << m.status().ToString() << " (from the ctest fixture zsl_make_stubs)";
  EXPECT_EQ(m->models.size(), 4u);
  const ModelEntry& enc = *m->Find(kRoleSegmenterEncoder);
  EXPECT_EQ(enc.preprocess.height, 512);
  EXPECT_EQ(enc.preprocess.padding, PaddingMode::kBottomRight);
  EXPECT_EQ(enc.preprocess.pad_space, PadSpace::kNormalized);
  EXPECT_EQ(enc.preprocess.mean, (std::array<float, 3>{123.675f, 116.28f, 103.53f}));
  EXPECT_EQ(enc.preprocess.stddev, (std::array<float, 3>{58.395f, 57.12f, 57.375f}));
  EXPECT_TRUE(enc.file.sha256.has_value());
  EXPECT_EQ(enc.declared.outputs.at(0),
            (TensorInfo{"image_embeddings", ElementType::kFloat32, {1, 256, 64, 64}}));
  const ModelEntry& dec = *m->Find(kRoleSegmenterDecoder);
  EXPECT_EQ(dec.postprocess.prompt_frame, 1024);
  EXPECT_EQ(dec.postprocess.low_res, 256);
  EXPECT_EQ(dec.postprocess.mask_threshold, 0.0f);
  EXPECT_EQ(dec.declared.inputs.at(1).shape, (std::vector<int64_t>{-1, -1, 2}));
  const ModelEntry& text = *m->Find(kRoleText);
  EXPECT_EQ(text.text->sot, 562);  // the 50-merge fixture
  EXPECT_EQ(text.text->eot, 563);
  EXPECT_TRUE(fs::exists(text.text->vocabulary.path));
  EXPECT_EQ(m->Find(kRoleDetector)->postprocess.n_max, 32);

  Result<Manifest> lsam = ReadManifest(kStubs / "lsam");
  ASSERT_TRUE(lsam.ok()) << lsam.status().ToString();
  const ModelEntry& g = *lsam->Find(kRoleGrounding);
  EXPECT_EQ(g.preprocess.height, 800);
  EXPECT_EQ(g.preprocess.width, 1200);
  EXPECT_EQ(g.preprocess.resize, ResizeMode::kStretch);
  EXPECT_EQ(g.postprocess.box_format, BoxFormat::kCxCyWhNormalized);
  EXPECT_EQ(g.postprocess.score_activation, ScoreActivation::kSigmoid);
  ASSERT_TRUE(g.text.has_value());
  EXPECT_EQ(g.text->tokenizer, TokenizerKind::kBertWordPiece);
  EXPECT_EQ(g.text->context, 256);
  EXPECT_EQ(g.text->cls, 101);
  EXPECT_EQ(g.text->sep, 102);
  EXPECT_EQ(g.text->period, 1012);
  EXPECT_TRUE(g.text->lower_case);

  Result<Manifest> baked = ReadManifest(kStubs / "ywes_baked");
  ASSERT_TRUE(baked.ok()) << baked.status().ToString();
  EXPECT_EQ(baked->Find(kRoleDetector)->postprocess.baked_names,
            (std::vector<std::string>{"tomato", "leaf"}));
}

TEST(ManifestParseTest, BadJsonSaysWhere) {
  const Status s = ParseStatus("{\n  \"format\": \"avp.zsl.models/1\",\n  \"models\": {,}\n}");
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), StartsWith("manifest.json: not valid JSON: "));
  EXPECT_THAT(s.message(), HasSubstr("line 3"));
}

TEST(ManifestParseTest, WhatSizesAnAllocationIsBounded) {
  // An image side, the detector's classes, a text model's context and width, and a stated
  // dimension each size what avp allocates: refused past their bounds, naming the field.
  EXPECT_THAT(ParseStatus(MiniManifest(R"(, "preprocess": {"size": 100000})")).message(),
              HasSubstr("models.detector.preprocess.size: expected S or [height, width] "
                        "(integers in [1, 8192]), got 100000"));
  EXPECT_THAT(ParseStatus(MiniManifest(R"(, "postprocess": {"n_max": 1000000000})")).message(),
              HasSubstr("models.detector.postprocess.n_max: 1000000000 is too large (at most "
                        "4096)"));
  EXPECT_THAT(ParseStatus(Replace(MiniManifest(), R"("vocabulary": "text/bpe.txt.gz")",
                                  R"("vocabulary": "text/bpe.txt.gz", "context": 100000)"))
                  .message(),
              HasSubstr("models.text.text.context: 100000 is too large (at most 4096)"));
  EXPECT_THAT(
      ParseStatus(
          MiniManifest(
              R"(, "inputs": [{"name": "images", "type": "float32", "shape": [1, 3, 9999999, 640]}])"))
          .message(),
      HasSubstr("models.detector.inputs[0].shape: a dimension exceeds 1048576, got "
                "[1,3,9999999,640]"));
  EXPECT_TRUE(ParseStatus(MiniManifest(R"(, "preprocess": {"size": [800, 1200]})")).ok());
}

TEST(ManifestParseTest, ErrorsNameTheField) {
  EXPECT_EQ(ParseStatus(R"({"models": {}})").message(),
            "manifest.json: manifest: missing field 'format' (a string)");
  EXPECT_EQ(ParseStatus(R"({"format": "x/2", "models": {}})").message(),
            "manifest.json: manifest.format: expected \"avp.zsl.models/1\", got \"x/2\"");
  EXPECT_EQ(ParseStatus(MiniManifest("", R"(
  "modles": {},)"))
                .message(),
            "manifest.json: manifest: unknown field 'modles'");
  // A wrong type, naming the field path and the value.
  EXPECT_EQ(ParseStatus(Replace(MiniManifest(), "\"bytes\": 10", "\"bytes\": \"12\"")).message(),
            "manifest.json: models.detector.bytes: expected an integer >= 0, got \"12\"");
  // A missing field.
  EXPECT_EQ(ParseStatus(Replace(MiniManifest(), "\"file\": \"text/t.onnx\", ", "")).message(),
            "manifest.json: models.text: missing field 'file' (the .onnx file, relative to the "
            "model directory)");
  // Typos are errors, not silently ignored.
  EXPECT_EQ(
      ParseStatus(MiniManifest(R"(, "postprocess": {"score_activaton": "sigmoid"})")).message(),
      "manifest.json: models.detector.postprocess: unknown field 'score_activaton'");
  EXPECT_EQ(
      ParseStatus(MiniManifest(R"(, "postprocess": {"score_activation": "softmax"})")).message(),
      "manifest.json: models.detector.postprocess.score_activation: expected one of \"none\", "
      "\"sigmoid\", got \"softmax\"");
  EXPECT_EQ(ParseStatus(MiniManifest(R"(, "postprocess": {"layout": "[A,N]"})")).message(),
            "manifest.json: models.detector.postprocess.layout: expected one of \"[4+N,A]\", "
            "\"[A,4+N]\", got \"[A,N]\"");
  EXPECT_EQ(ParseStatus(MiniManifest(R"(, "preprocess": {"std": [1, 0, 1]})")).message(),
            "manifest.json: models.detector.preprocess.std: expected 3 positive numbers, got "
            "[1,0,1]");
  EXPECT_EQ(ParseStatus(MiniManifest(R"(, "sha256": "abc")")).message(),
            "manifest.json: models.detector.sha256: expected 64 hex digits, got \"abc\"");
  EXPECT_EQ(
      ParseStatus(MiniManifest(R"(, "inputs": [{"name": "images", "type": "f32", "shape": [1]}])"))
          .message(),
      "manifest.json: models.detector.inputs[0].type: element type 'f32' is not one of "
      "float32, float16, float64, int8, uint8, int16, int32, int64, bool, string");
  EXPECT_EQ(
      ParseStatus(
          MiniManifest(R"(, "inputs": [{"name": "images", "type": "float32", "shape": [1, -2]}])"))
          .message(),
      "manifest.json: models.detector.inputs[0].shape: expected integers >= -1, got [1,-2]");
}

TEST(ManifestParseTest, ContractSpecificRules) {
  const Status unknown =
      ParseStatus(Replace(MiniManifest(), "yoloworld.txtfeats/1", "yoloworld.txtfeats/9"));
  EXPECT_EQ(unknown.code(), StatusCode::kNotFound);
  EXPECT_THAT(unknown.message(), StartsWith("manifest.json: models.detector.contract: unknown "
                                            "contract 'yoloworld.txtfeats/9' (built in: "));
  EXPECT_EQ(
      ParseStatus(Replace(MiniManifest(), "yoloworld.txtfeats/1", "yoloworld.baked/1")).message(),
      "manifest.json: models.detector.postprocess: missing field 'baked_names' "
      "(yoloworld.baked/1 needs the class names, one per score row)");
  EXPECT_EQ(
      ParseStatus(Replace(MiniManifest(), ", \"text\": {\"vocabulary\": \"text/bpe.txt.gz\"}", ""))
          .message(),
      "manifest.json: models.text: missing field 'text' (clip.text/1 needs text.vocabulary)");
  EXPECT_EQ(
      ParseStatus(Replace(MiniManifest(), "\"detector/d.onnx\"", "\"/abs/d.onnx\"")).message(),
      "manifest.json: models.detector.file: '/abs/d.onnx' must be relative to the model "
      "directory");
}

TEST(ManifestParseTest, OptionalSectionsOverrideTheDefaults) {
  // "licence" (as in the design) and "license" are both accepted, but not both at once.
  EXPECT_EQ(
      ParseStatus(Replace(MiniManifest(), "\"licence\": \"AGPL-3.0\"", "\"license\": \"AGPL-3.0\""))
          .ok(),
      true);
  EXPECT_EQ(ParseStatus(MiniManifest(R"(, "license": "GPL-3.0")")).message(),
            "manifest.json: models.detector: unknown field 'license'");
  Result<Manifest> ok = ParseManifest(MiniManifest(R"(, "sha256": ")" + std::string(64, 'A') + R"(",
      "preprocess": {"size": [320, 480], "channel_order": "bgr", "pad_value": 0},
      "postprocess": {"layout": "[A,4+N]", "score_activation": "sigmoid", "n_max": 16},
      "_note": "comments start with an underscore")"),
                                      "/m");
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  const ModelEntry& d = *ok->Find("detector");
  EXPECT_EQ(d.file.sha256, std::string(64, 'a'));
  EXPECT_EQ(d.preprocess.height, 320);
  EXPECT_EQ(d.preprocess.width, 480);
  EXPECT_EQ(d.preprocess.channel_order, ChannelOrder::kBgr);
  EXPECT_EQ(d.preprocess.pad_value, 0.0f);
  EXPECT_EQ(d.postprocess.layout, DetectionLayout::kAnchorsByAttributes);
  EXPECT_EQ(d.postprocess.score_activation, ScoreActivation::kSigmoid);
  EXPECT_EQ(d.postprocess.n_max, 16);
}

TEST(ManifestParseTest, TheDocumentedExampleParses) {
  const fs::path doc = fs::path(AVP_CONFIG_DIR).parent_path() / "docs" / "zero-shot-models.md";
  const std::string text = test::ReadWholeFile(doc);
  ASSERT_FALSE(text.empty()) << doc;
  const size_t section = text.find("## Model directory and manifest");
  ASSERT_NE(section, std::string::npos);
  const size_t begin = text.find("```json\n", section);
  ASSERT_NE(begin, std::string::npos);
  const size_t end = text.find("\n```", begin + 8);
  ASSERT_NE(end, std::string::npos);
  Result<Manifest> m =
      ParseManifest(text.substr(begin + 8, end - begin - 8), "/models", doc.string());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  for (const char* backend : {kBackendYwes, kBackendLsam}) {
    const std::vector<std::string> roles = BackendRoles(backend, *m).value();
    for (const std::string& role : roles) {
      EXPECT_NE(m->Find(role), nullptr) << backend << " needs " << role;
    }
  }
  EXPECT_EQ(m->Find(kRoleSegmenterEncoder)->preprocess.height, 512);
  EXPECT_EQ(m->Find(kRoleText)->text->vocabulary.bytes, 1356917u);
}

// ---- reading and file checks -------------------------------------------------------------------

class ManifestFilesTest : public avp::test::TempDirTest {};

TEST_F(ManifestFilesTest, MissingDirectoryOrManifestIsNotFound) {
  Result<Manifest> none = ReadManifest(dir_ / "absent");
  EXPECT_EQ(none.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(none.status().message(), HasSubstr("absent' does not exist"));
  Result<Manifest> empty = ReadManifest(dir_);
  EXPECT_EQ(empty.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(empty.status().message(), HasSubstr("manifest.json' does not exist"));
  Write("manifest.json", "{ not json");
  Result<Manifest> bad = ReadManifest(dir_);
  EXPECT_EQ(bad.status().code(), StatusCode::kParseError);
  EXPECT_THAT(bad.status().message(),
              StartsWith((dir_ / "manifest.json").string() + ": not valid JSON"));
}

TEST_F(ManifestFilesTest, CheckFilesNamesTheFileAndTheField) {
  fs::create_directories(dir_ / "detector");
  fs::create_directories(dir_ / "text");
  Write("manifest.json", MiniManifest(R"(, "sha256": ")" + std::string(64, '0') + "\""));
  Result<Manifest> m = ReadManifest(dir_);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  const ModelEntry& det = *m->Find("detector");
  const ModelEntry& text = *m->Find("text");

  Status s = CheckFiles(det);
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
  EXPECT_EQ(s.message(), "detector: model file '" + (dir_ / "detector/d.onnx").string() +
                             "' does not exist (field models.detector.file)");
  Write("detector/d.onnx", "0123456789X");
  s = CheckFiles(det);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "detector: '" + (dir_ / "detector/d.onnx").string() +
                             "' has 11 bytes; models.detector.bytes says 10");
  Write("detector/d.onnx", "0123456789");
  EXPECT_TRUE(CheckFiles(det).ok()) << "sha256 is checked only on request";
  s = CheckFiles(det, /*verify_sha256=*/true);
  EXPECT_EQ(s.message(), "detector: '" + (dir_ / "detector/d.onnx").string() +
                             "' has sha256 "
                             "84d89877f0d4041efb6bf91a16f0248f2fd573e6af05c19f96bedb9f882f7882; "
                             "models.detector.sha256 says " +
                             std::string(64, '0'));

  Write("text/t.onnx", "12345");
  s = CheckFiles(text);
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
  EXPECT_EQ(s.message(), "text: vocabulary file '" + (dir_ / "text/bpe.txt.gz").string() +
                             "' does not exist (field models.text.text.vocabulary)");
  Write("text/bpe.txt.gz", "x");
  EXPECT_TRUE(CheckFiles(text).ok());
}

TEST_F(ManifestFilesTest, FileSha256MatchesKnownDigests) {
  EXPECT_EQ(FileSha256(Write("empty", "")).value(),
            "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(FileSha256(Write("abc", "abc")).value(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  // 56 bytes: the padding spills into a second block.
  EXPECT_EQ(
      FileSha256(Write("two", "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq")).value(),
      "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(FileSha256(dir_ / "none").status().code(), StatusCode::kNotFound);
}

// ---- backends ----------------------------------------------------------------------------------

TEST(BackendRolesTest, DependOnTheDetectorContract) {
  Result<Manifest> ywes = ReadManifest(kStubs / "ywes");
  ASSERT_TRUE(ywes.ok()) << ywes.status().ToString();
  EXPECT_EQ(
      BackendRoles(kBackendYwes, *ywes).value(),
      (std::vector<std::string>{"detector", "text", "segmenter.encoder", "segmenter.decoder"}));
  Result<Manifest> baked = ReadManifest(kStubs / "ywes_baked");
  ASSERT_TRUE(baked.ok()) << baked.status().ToString();
  EXPECT_EQ(BackendRoles(kBackendYwes, *baked).value(),
            (std::vector<std::string>{"detector", "segmenter.encoder", "segmenter.decoder"}));
  EXPECT_EQ(BackendRoles(kBackendLsam, *ywes).value(),
            (std::vector<std::string>{"grounding", "segmenter.encoder", "segmenter.decoder"}));
  EXPECT_EQ(BackendRoles("sam3", *ywes).status().message(),
            "unknown backend 'sam3' (expected ywes or lsam)");
}

TEST(LoadBackendTest, YwesStubsAreReadyWithEveryConstantResolved) {
  LoadedBackend b = LoadBackend(kBackendYwes, kStubs / "ywes", CpuOptions());
  ASSERT_TRUE(b.ready()) << b.StateString();
  EXPECT_EQ(b.StateString(), "READY");
  EXPECT_TRUE(b.status.ok());
  EXPECT_EQ(b.models.size(), 4u);
  const LoadedModel* det = b.Find(kRoleDetector);
  ASSERT_NE(det, nullptr);
  EXPECT_EQ(det->binding.Dim("N"), 32);
  EXPECT_EQ(det->entry.postprocess.n_max, 32);
  EXPECT_EQ(det->model.provider(), kCpuProvider);
  EXPECT_EQ(det->model.label(), "detector");
  const LoadedModel* enc = b.Find(kRoleSegmenterEncoder);
  ASSERT_NE(enc, nullptr);
  EXPECT_EQ(enc->binding.Dim("S"), 512);
  EXPECT_EQ(enc->entry.preprocess.height, 512);
  ASSERT_NE(b.Find(kRoleText), nullptr);
  EXPECT_EQ(b.Find(kRoleText)->entry.text->dim, 512);
  EXPECT_EQ(b.Find("grounding"), nullptr);
}

TEST(LoadBackendTest, EncoderSizeComesFromTheModelWhenTheManifestOmitsIt) {
  Result<Manifest> m = ReadManifest(kStubs / "ywes");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  m->models.at(kRoleSegmenterEncoder).preprocess.height = 0;
  m->models.at(kRoleSegmenterEncoder).preprocess.width = 0;
  LoadedBackend b = LoadBackend(kBackendYwes, *m, CpuOptions());
  ASSERT_TRUE(b.ready()) << b.StateString();
  EXPECT_EQ(b.Find(kRoleSegmenterEncoder)->entry.preprocess.width, 512);
}

TEST(LoadBackendTest, VariantsAreReady) {
  LoadedBackend logits = LoadBackend(kBackendYwes, kStubs / "ywes_logits", CpuOptions());
  ASSERT_TRUE(logits.ready()) << logits.StateString();
  EXPECT_EQ(logits.Find(kRoleDetector)->entry.postprocess.score_activation,
            ScoreActivation::kSigmoid);
  LoadedBackend baked = LoadBackend(kBackendYwes, kStubs / "ywes_baked", CpuOptions());
  ASSERT_TRUE(baked.ready()) << baked.StateString();
  EXPECT_EQ(baked.models.size(), 3u);
  EXPECT_EQ(baked.Find(kRoleDetector)->binding.Dim("NC"), 2);
  EXPECT_EQ(baked.Find(kRoleDetector)->entry.postprocess.n_max, 2);
  LoadedBackend baked_logits =
      LoadBackend(kBackendYwes, kStubs / "ywes_baked_logits", CpuOptions());
  ASSERT_TRUE(baked_logits.ready()) << baked_logits.StateString();
  LoadedBackend transposed = LoadBackend(kBackendYwes, kStubs / "ywes_transposed", CpuOptions());
  ASSERT_TRUE(transposed.ready()) << transposed.StateString();
  EXPECT_TRUE(transposed.Find(kRoleDetector)->binding.transposed);
  EXPECT_EQ(transposed.Find(kRoleDetector)->entry.postprocess.layout,
            DetectionLayout::kAnchorsByAttributes);
}

TEST(LoadBackendTest, LsamStubsAreReady) {
  LoadedBackend b = LoadBackend(kBackendLsam, kStubs / "lsam", CpuOptions());
  ASSERT_TRUE(b.ready()) << b.StateString();
  EXPECT_EQ(b.models.size(), 3u);
  EXPECT_EQ(b.Find(kRoleGrounding)->binding.Dim("L"), kDynamicDim);
  EXPECT_EQ(b.Find(kRoleGrounding)->entry.preprocess.width, 1200);
}

TEST(LoadBackendTest, WarmUpRunsEveryModelAndLogsTheTimes) {
  BackendLoadOptions options = CpuOptions();
  options.warm_up = true;
  ::testing::internal::CaptureStderr();
  LoadedBackend b = LoadBackend(kBackendLsam, kStubs / "lsam", options);
  const std::string err = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(b.ready()) << b.StateString();
  EXPECT_THAT(err, HasSubstr("avp zsl: lsam warm-up (CPUExecutionProvider): grounding "));
  EXPECT_THAT(err, HasSubstr("segmenter.decoder "));
}

TEST(LoadBackendTest, MissingDirectoryRoleOrFileIsMissing) {
  LoadedBackend none = LoadBackend(kBackendYwes, kStubs / "no_such_dir", CpuOptions());
  EXPECT_EQ(none.state, BackendState::kMissing);
  EXPECT_THAT(none.StateString(), StartsWith("MISSING(model directory '"));
  EXPECT_TRUE(none.models.empty());

  LoadedBackend lsam = LoadBackend(kBackendLsam, kStubs / "ywes", CpuOptions());
  EXPECT_EQ(lsam.state, BackendState::kMissing);
  EXPECT_THAT(lsam.reason, StartsWith("lsam needs model role 'grounding' (gdino.ort/1); "));
  EXPECT_THAT(lsam.reason, HasSubstr("manifest.json lists detector, segmenter.decoder, "
                                     "segmenter.encoder, text"));

  LoadedBackend file = LoadBackend(kBackendYwes, kStubs / "wrong/missing_file", CpuOptions());
  EXPECT_EQ(file.state, BackendState::kMissing);
  EXPECT_EQ(file.status.code(), StatusCode::kNotFound);
  EXPECT_THAT(file.reason, StartsWith("segmenter.encoder: model file '"));
  EXPECT_THAT(file.reason, HasSubstr("evitsam_stub_encoder.onnx' does not exist (field "
                                     "models.segmenter.encoder.file)"));
}

TEST(LoadBackendTest, ARoleWithTheWrongContractIsInvalid) {
  Result<Manifest> m = ReadManifest(kStubs / "ywes");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  m->models.at(kRoleText).contract = kEvitSamEncoder;
  LoadedBackend b = LoadBackend(kBackendYwes, *m, CpuOptions());
  EXPECT_EQ(b.StateString(),
            "INVALID(text: contract evitsam.encoder/1 cannot serve this role (expected "
            "clip.text/1))");
}

TEST(LoadBackendTest, Sha256IsCheckedOnRequest) {
  EXPECT_TRUE(LoadBackend(kBackendYwes, kStubs / "wrong/sha256_mismatch", CpuOptions()).ready());
  BackendLoadOptions options = CpuOptions();
  options.verify_sha256 = true;
  EXPECT_TRUE(LoadBackend(kBackendYwes, kStubs / "ywes", options).ready());
  LoadedBackend b = LoadBackend(kBackendYwes, kStubs / "wrong/sha256_mismatch", options);
  EXPECT_EQ(b.state, BackendState::kInvalid);
  EXPECT_THAT(b.reason, StartsWith("detector: '"));
  EXPECT_THAT(b.reason, HasSubstr("; models.detector.sha256 says " + std::string(64, '0')));
}

struct WrongCase {
  const char* dir;
  const char* expected;  ///< a substring of the reason
};

void PrintTo(const WrongCase& c, std::ostream* os) { *os << "wrong/" << c.dir; }

class WrongContractTest : public ::testing::TestWithParam<WrongCase> {};

TEST_P(WrongContractTest, FailsAtLoadNamingModelTensorAndExpectation) {
  const WrongCase& c = GetParam();
  LoadedBackend b = LoadBackend(kBackendYwes, kStubs / "wrong" / c.dir, CpuOptions());
  EXPECT_EQ(b.state, BackendState::kInvalid) << b.StateString();
  EXPECT_THAT(b.reason, HasSubstr(c.expected));
  EXPECT_EQ(b.reason.find('\n'), std::string::npos) << "one line";
  EXPECT_TRUE(b.models.empty());
  EXPECT_EQ(b.StateString(), "INVALID(" + b.reason + ")");
}

INSTANTIATE_TEST_SUITE_P(
    Stubs, WrongContractTest,
    ::testing::Values(
        WrongCase{"renamed_input",
                  "detector: input 'images' is missing (the model has 'image', 'txt_feats'); "
                  "yoloworld.txtfeats/1 expects images float32 [1,3,640,640]"},
        WrongCase{"int32_labels",
                  "segmenter.decoder: input 'point_labels' is int32; evitsam.decoder.single/1 "
                  "expects float32"},
        WrongCase{"int32_input_ids", "text: input 'input_ids' is int32; clip.text/1 expects int64"},
        WrongCase{"wrong_rank",
                  "detector: input 'txt_feats' has rank 2 ([32,512]); yoloworld.txtfeats/1 "
                  "expects rank 3 [1,N,512]"},
        WrongCase{"wrong_static_dim",
                  "segmenter.encoder: output 'image_embeddings' has shape [1,256,32,32]; "
                  "evitsam.encoder/1 expects [1,256,64,64] (dim 2 is 32, not 64, dim 3 is 32, not "
                  "64)"},
        WrongCase{"transposed_output",
                  "detector: output 'output0' has shape [1,8400,36]; yoloworld.txtfeats/1 expects "
                  "[1,4+N,8400]"},
        WrongCase{"transposed_output",
                  "this is the transposed [A,4+N] layout: declare it with postprocess.layout "
                  "\"[A,4+N]\""},
        WrongCase{"missing_output",
                  "segmenter.decoder: output 'iou_predictions' is missing (the model has "
                  "'masks'); evitsam.decoder.single/1 expects iou_predictions float32 [B,1]"},
        WrongCase{"extra_input",
                  "segmenter.decoder: input 'mask_input' (float32 [1,1,256,256]) is not part of "
                  "evitsam.decoder.single/1"},
        WrongCase{"truncated_file", "segmenter.decoder: ONNX Runtime cannot load '"},
        WrongCase{"size_mismatch", " bytes; models.text.bytes says "},
        WrongCase{"declared_io_mismatch",
                  "detector: input 'txt_feats' has shape [1,32,512]; the manifest declares "
                  "[1,16,512]"},
        WrongCase{"encoder_size_mismatch",
                  "segmenter.encoder: preprocess.size [1024,1024] differs from the model's "
                  "input_image size [512,512] (S = 512)"},
        WrongCase{"n_max_mismatch",
                  "detector: postprocess.n_max (16) differs from the model's N (32; output0 "
                  "[1,36,8400])"}),
    [](const ::testing::TestParamInfo<WrongCase>& p) {
      return std::string(p.param.dir) + "_" + std::to_string(p.index);
    });

TEST_F(ManifestFilesTest, BadManifestMakesTheBackendInvalid) {
  Write("manifest.json", "{\"format\": \"avp.zsl.models/1\", \"models\": 3}");
  LoadedBackend b = LoadBackend(kBackendYwes, dir_, CpuOptions());
  EXPECT_EQ(b.state, BackendState::kInvalid);
  EXPECT_EQ(b.status.code(), StatusCode::kParseError);
  EXPECT_EQ(b.reason, (dir_ / "manifest.json").string() +
                          ": manifest.models: expected an object of models by role, got 3");
}

// ---- real weights (opt-in) ---------------------------------------------------------------------

TEST(RealModelsTest, BackendsInTheModelDirectoryLoad) {
  const std::optional<fs::path> dir = ModelDirFromEnvironment();
  if (!dir) {
    GTEST_SKIP()
        << "AVP_ZSL_MODEL_DIR is not set: set it to a model directory with a manifest.json "
           "(docs/zero-shot-models.md, \"Model directory and manifest\") to check real "
           "exports";
  }
  Result<Manifest> m = ReadManifest(*dir);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  BackendLoadOptions options;  // AVP_ZSL_DEVICE decides the device
  Result<Device> device = DeviceFromEnvironment();
  ASSERT_TRUE(device.ok()) << device.status().ToString();
  options.session.device = *device;
  options.verify_sha256 = true;
  options.warm_up = true;
  int checked = 0;
  for (const char* backend : {kBackendYwes, kBackendLsam}) {
    LoadedBackend b = LoadBackend(backend, *m, options);
    if (b.state == BackendState::kMissing) {
      std::fprintf(stderr, "%s: %s\n", backend, b.StateString().c_str());
      continue;
    }
    EXPECT_TRUE(b.ready()) << backend << ": " << b.StateString();
    ++checked;
  }
  if (checked == 0) {
    GTEST_SKIP() << *dir << " has neither a complete ywes nor a complete lsam set";
  }
}

}  // namespace
}  // namespace avp::zsl

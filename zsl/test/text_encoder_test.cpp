// TextEncoder on the CLIP text stub of make_stubs.py: text_embeds[b, c] (c < 16) counts the tokens
// up to the first EOT whose id is below 562 (the fixture's SOT) and whose id mod 16 is c; columns
// 16..511 are 0; not normalised. So the L2-normalised embedding of a phrase is its normalised
// histogram of (BPE id mod 16), which these tests compute with ClipTokenizer on the same merges.
#include "text_encoder.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <avp/test/temp_dir_test.h>

#include "clip_tokenizer.h"
#include "manifest.h"

namespace avp::zsl {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

const fs::path kStubs = AVP_ZSL_STUB_DIR;
constexpr int kDim = 512;

BackendLoadOptions CpuOptions() {
  BackendLoadOptions o;
  o.session.device = Device::kCpu;
  o.session.intra_op_threads = 1;
  return o;
}

/// The text role of the ywes stubs in `dir`, loaded and validated.
LoadedModel TextModel(const fs::path& dir = kStubs / "ywes") {
  LoadedBackend b = LoadBackend(kBackendYwes, dir, CpuOptions());
  EXPECT_TRUE(b.ready()) << b.StateString();
  auto node = b.models.extract(kRoleText);
  return std::move(node.mapped());
}

TextEncoder MakeEncoder(const TextEncoderOptions& options = {},
                        const fs::path& dir = kStubs / "ywes") {
  Result<TextEncoder> e = TextEncoder::Create(TextModel(dir), options);
  EXPECT_TRUE(e.ok()) << e.status().ToString();
  return std::move(e).value();
}

/// What the stub + L2 give for `phrase`: the normalised histogram of (id mod 16) of its BPE ids
/// (all fixture ids are < 562), in 512 columns.
std::vector<float> ExpectedEmbedding(const std::string& phrase, size_t max_tokens = 75) {
  static const ClipTokenizer tokenizer =
      ClipTokenizer::FromMergesFile(fs::path(AVP_ZSL_TEST_DATA) / "clip_merges_fixture.txt")
          .value();
  std::vector<int32_t> ids = tokenizer.Encode(phrase);
  if (ids.size() > max_tokens) ids.resize(max_tokens);  // 77 = SOT + 75 + EOT
  std::vector<double> hist(kDim, 0.0);
  for (int32_t id : ids) hist[static_cast<size_t>(id % 16)] += 1.0;
  double norm = 0.0;
  for (double v : hist) norm += v * v;
  norm = std::sqrt(norm);
  std::vector<float> out(kDim);
  for (size_t i = 0; i < out.size(); ++i) out[i] = static_cast<float>(hist[i] / norm);
  return out;
}

void ExpectRowEq(std::span<const float> row, const std::vector<float>& expected,
                 const std::string& what) {
  ASSERT_EQ(row.size(), expected.size()) << what;
  for (size_t i = 0; i < row.size(); ++i) {
    ASSERT_NEAR(row[i], expected[i], 1e-6f) << what << " column " << i;
  }
}

TEST(TextEncoderTest, CreatesFromTheStubTextModel) {
  const TextEncoder e = MakeEncoder();
  EXPECT_EQ(e.dim(), kDim);
  EXPECT_EQ(e.static_batch(), 0);  // [batch, 77]: dynamic
  EXPECT_EQ(e.model_runs(), 0u);
  EXPECT_EQ(e.cache_size(), 0u);
  EXPECT_EQ(e.cache_capacity(), 1024u);
  EXPECT_EQ(e.precomputed_size(), 0u);
  EXPECT_EQ(e.model().provider(), kCpuProvider);
}

TEST(TextEncoderTest, SingleLetterWordsAreOneHotAndWordsAdd) {
  // "a" is one BPE symbol "a</w>": id 256 + ('a' − 33) = 320, bucket 0; "b" 321, bucket 1.
  const TextEncoder e = MakeEncoder();
  const std::vector<std::string> phrases = {"a", "b", "a b", "tomato"};
  Result<TextEmbeddings> r = e.Encode(phrases);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->dim, kDim);
  ASSERT_EQ(r->values.size(), 4u * kDim);
  std::vector<float> one_hot_a(kDim, 0.f), one_hot_b(kDim, 0.f), ab(kDim, 0.f);
  one_hot_a[0] = 1.f;
  one_hot_b[1] = 1.f;
  ab[0] = ab[1] = static_cast<float>(1.0 / std::sqrt(2.0));
  ExpectRowEq(r->Row(0), one_hot_a, "a");
  ExpectRowEq(r->Row(1), one_hot_b, "b");
  ExpectRowEq(r->Row(2), ab, "a b");
  ExpectRowEq(r->Row(3), ExpectedEmbedding("tomato"), "tomato");
  // Unit norm.
  for (size_t i = 0; i < 4; ++i) {
    double n = 0.0;
    for (float v : r->Row(i)) n += static_cast<double>(v) * v;
    EXPECT_NEAR(n, 1.0, 1e-6) << i;
  }
  // All four in ONE model run.
  EXPECT_EQ(r->computed, 4u);
  EXPECT_EQ(r->from_cache, 0u);
  EXPECT_EQ(e.model_runs(), 1u);
  EXPECT_EQ(e.phrases_computed(), 4u);
}

TEST(TextEncoderTest, TheCacheIsKeyedByTheNormalisedPhraseAndSkipsTheModel) {
  const TextEncoder e = MakeEncoder();
  const std::vector<std::string> first = {"a", "b", "c"};
  ASSERT_TRUE(e.Encode(first).ok());
  EXPECT_EQ(e.model_runs(), 1u);
  EXPECT_EQ(e.cache_size(), 3u);

  const std::vector<std::string> second = {" B ", "d", "A", "d"};
  Result<TextEmbeddings> r = e.Encode(second);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->from_cache, 2u);  // "b" and "a"
  EXPECT_EQ(r->computed, 1u);    // "d", once although asked twice
  EXPECT_EQ(e.model_runs(), 2u);
  EXPECT_EQ(e.phrases_computed(), 4u);
  std::vector<float> d(kDim, 0.f);
  d[3] = 1.f;
  ExpectRowEq(r->Row(1), d, "d");
  ExpectRowEq(r->Row(3), d, "d again");
  std::vector<float> b(kDim, 0.f);
  b[1] = 1.f;
  ExpectRowEq(r->Row(0), b, "cached b");

  const std::vector<std::string> cached = {"a", "b", "c", "d"};
  Result<TextEmbeddings> all = e.Encode(cached);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->from_cache, 4u);
  EXPECT_EQ(all->computed, 0u);
  EXPECT_EQ(e.model_runs(), 2u) << "a fully cached call does not run the model";
  EXPECT_EQ(all->tokenize_ms, 0.0);
  EXPECT_EQ(all->model_ms, 0.0);
}

TEST(TextEncoderTest, ACapacityOfZeroRunsTheModelEveryTime) {
  TextEncoderOptions options;
  options.cache_capacity = 0;
  const TextEncoder e = MakeEncoder(options);
  const std::vector<std::string> phrases = {"a"};
  ASSERT_TRUE(e.Encode(phrases).ok());
  ASSERT_TRUE(e.Encode(phrases).ok());
  EXPECT_EQ(e.model_runs(), 2u);
  EXPECT_EQ(e.cache_size(), 0u);
}

TEST(TextEncoderTest, TruncationKeepsTheEndOfTextToken) {
  // 100 words: 77 = SOT + 75 words + EOT after truncation; the stub pools at the (forced) EOT, so
  // the embedding counts 75 tokens of bucket 0 (normalised: e_0). Without the forced EOT ArgMax
  // would pick position 0 (SOT, counted nothing) and the norm would be 0, an error.
  const TextEncoder e = MakeEncoder();
  std::string phrase = "a";
  for (int i = 1; i < 100; ++i) phrase += " a";
  const std::vector<std::string> phrases = {phrase};
  Result<TextEmbeddings> r = e.Encode(phrases);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  std::vector<float> e0(kDim, 0.f);
  e0[0] = 1.f;
  ExpectRowEq(r->Row(0), e0, "100 x a");
}

TEST(TextEncoderTest, AZeroEmbeddingIsAnErrorNamingThePhrase) {
  // The special-token string is stripped from user text: [SOT][EOT] counts nothing.
  const TextEncoder e = MakeEncoder();
  const std::vector<std::string> phrases = {"a", "<|endoftext|>"};
  Result<TextEmbeddings> r = e.Encode(phrases);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(),
              HasSubstr("text: the embedding of '<|endoftext|>' has L2 norm 0"));
}

TEST(TextEncoderTest, AnEmptyListGivesNoRowsAndRunsNothing) {
  const TextEncoder e = MakeEncoder();
  Result<TextEmbeddings> r = e.Encode({});
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->values.empty());
  EXPECT_EQ(e.model_runs(), 0u);
}

TEST(TextEncoderTest, ConcurrentCallsAgree) {
  const TextEncoder e = MakeEncoder();
  const std::vector<std::string> phrases = {"tomato", "a b", "leaf", "c"};
  const std::vector<float> reference = e.Encode(phrases).value().values;
  std::vector<std::thread> threads;
  std::array<bool, 4> same{};
  for (size_t t = 0; t < same.size(); ++t) {
    threads.emplace_back([&, t] {
      bool ok = true;
      for (int i = 0; i < 20; ++i) {
        Result<TextEmbeddings> r = e.Encode(phrases);
        ok = ok && r.ok() && r->values == reference;
      }
      same[t] = ok;
    });
  }
  for (std::thread& t : threads) t.join();
  for (bool s : same) EXPECT_TRUE(s);
}

// ---- manifests edited in a copy of the stubs
// ------------------------------------------------------

class TextEncoderManifestTest : public test::TempDirTest {
 protected:
  /// Copies the ywes stubs to dir_/ywes and applies `edit` to models.text.text.
  fs::path CopyWithTextEdit(const std::function<void(nlohmann::json&)>& edit) {
    const fs::path dir = dir_ / "ywes";
    fs::copy(kStubs / "ywes", dir, fs::copy_options::recursive);
    nlohmann::json manifest;
    std::ifstream(dir / kManifestFileName) >> manifest;
    edit(manifest["models"]["text"]["text"]);
    std::ofstream(dir / kManifestFileName) << manifest.dump(2);
    return dir;
  }

  void WriteFloats(const fs::path& path, const std::vector<float>& values) {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(values.data()),
              static_cast<std::streamsize>(values.size() * sizeof(float)));
  }
};

TEST_F(TextEncoderManifestTest, PrecomputedVocabulariesAreUsedBeforeTheModel) {
  std::vector<float> rows(2 * kDim, 0.f);
  rows[0] = 3.f;  // "Red Tomato": (3, 4) → (0.6, 0.8) once normalised
  rows[1] = 4.f;
  rows[kDim + 5] = 0.5f;  // "leaf": e_5
  const fs::path dir = CopyWithTextEdit([&](nlohmann::json& text) {
    text["precomputed"] = {{{"name", "test"},
                            {"embeddings", "text/vocab_test.f32"},
                            {"names", "text/vocab_test.txt"}}};
  });
  WriteFloats(dir / "text/vocab_test.f32", rows);
  std::ofstream(dir / "text/vocab_test.txt") << "Red  Tomato\nleaf\n";

  const TextEncoder e = MakeEncoder({}, dir);
  EXPECT_EQ(e.precomputed_size(), 2u);
  const std::vector<std::string> phrases = {"red tomato", "LEAF", "a"};
  Result<TextEmbeddings> r = e.Encode(phrases);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->from_precomputed, 2u);
  EXPECT_EQ(r->computed, 1u);
  std::vector<float> tomato(kDim, 0.f), leaf(kDim, 0.f);
  tomato[0] = 0.6f;
  tomato[1] = 0.8f;
  leaf[5] = 1.f;
  ExpectRowEq(r->Row(0), tomato, "precomputed red tomato");
  ExpectRowEq(r->Row(1), leaf, "precomputed leaf");
  EXPECT_EQ(e.cache_size(), 1u) << "precomputed phrases are not cached again";
}

TEST_F(TextEncoderManifestTest, APrecomputedBlobOfTheWrongSizeFailsNamingTheFile) {
  const fs::path dir = CopyWithTextEdit([&](nlohmann::json& text) {
    text["precomputed"] = {{{"name", "test"},
                            {"embeddings", "text/vocab_test.f32"},
                            {"names", "text/vocab_test.txt"}}};
  });
  WriteFloats(dir / "text/vocab_test.f32", std::vector<float>(kDim + 1, 1.f));
  std::ofstream(dir / "text/vocab_test.txt") << "tomato\n";
  Result<TextEncoder> e = TextEncoder::Create(TextModel(dir));
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(e.status().message(), HasSubstr("text: precomputed vocabulary 'test': '" +
                                              (dir / "text/vocab_test.f32").string() +
                                              "' has 2052 bytes; 1 names x 512 float32 need 2048"));
}

TEST_F(TextEncoderManifestTest, EndOfTextPaddingGivesTheSameEmbeddingsAsZeroPadding) {
  // HF pads with EOT (here the fixture's 563); the graph pools at the FIRST EOT either way.
  const fs::path dir = CopyWithTextEdit([](nlohmann::json& text) { text["pad"] = 563; });
  const TextEncoder eot_padded = MakeEncoder({}, dir);
  const TextEncoder zero_padded = MakeEncoder();
  const std::vector<std::string> phrases = {"tomato", "a b c", "green apple"};
  Result<TextEmbeddings> a = eot_padded.Encode(phrases);
  Result<TextEmbeddings> b = zero_padded.Encode(phrases);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->values, b->values);
}

TEST_F(TextEncoderManifestTest, NormalizedInGraphSkipsTheL2Norm) {
  const fs::path dir =
      CopyWithTextEdit([](nlohmann::json& text) { text["normalized_in_graph"] = true; });
  const TextEncoder e = MakeEncoder({}, dir);
  const std::vector<std::string> phrases = {"a a a"};
  Result<TextEmbeddings> r = e.Encode(phrases);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->Row(0)[0], 3.f) << "the stub's raw count, not divided by its norm";
}

TEST_F(TextEncoderManifestTest, SpecialIdsThatDisagreeWithTheMergesFileAreRefused) {
  const fs::path dir = CopyWithTextEdit([](nlohmann::json& text) {
    text["sot"] = 49406;
    text["eot"] = 49407;
  });
  Result<TextEncoder> e = TextEncoder::Create(TextModel(dir));
  ASSERT_FALSE(e.ok());
  EXPECT_THAT(e.status().message(),
              HasSubstr("gives SOT 562 and EOT 563; text.sot and text.eot say 49406 and 49407"));
}

TEST(TextEncoderTest, RefusesAModelThatIsNotCLIPText) {
  LoadedBackend b = LoadBackend(kBackendYwes, kStubs / "ywes", CpuOptions());
  ASSERT_TRUE(b.ready());
  auto node = b.models.extract(kRoleDetector);
  Result<TextEncoder> e = TextEncoder::Create(std::move(node.mapped()));
  ASSERT_FALSE(e.ok());
  EXPECT_THAT(e.status().message(),
              HasSubstr("text: role 'detector' has contract yoloworld.txtfeats/1; TextEncoder "
                        "needs clip.text/1"));
}

}  // namespace
}  // namespace avp::zsl

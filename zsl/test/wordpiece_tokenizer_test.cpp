// BERT WordPiece and Grounding DINO's text inputs on a 35-token fixture vocabulary
// (test/data/bert_vocab_fixture.txt; id = 0-based line):
//   0 [PAD]  1 [UNK]  2 [CLS]  3 [SEP]  4 [MASK]  5 .  6 ,  7 !  8 (  9 )  10 -  11 ?
//   12 tomato  13 leaf  14 red  15 green  16 pepper  17 ##s  18 stem  19 un  20 ##want  21 ##ed
//   22 want  23 cafe  24 apfel  25 a  26 ##p  27 ##fel  28 straw  29 ##berry  30 bell  31 ##a
//   32 日  33 本  34 ß
#include "wordpiece_tokenizer.h"

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <avp/test/temp_dir_test.h>

#include "sha256.h"

namespace avp::zsl {
namespace {

using Ids = std::vector<int32_t>;
using Ids64 = std::vector<int64_t>;

const std::filesystem::path kFixture =
    std::filesystem::path(AVP_ZSL_TEST_DATA) / "bert_vocab_fixture.txt";

class WordPieceTokenizerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto tokenizer = WordPieceTokenizer::FromVocabFile(kFixture);
    ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
    tokenizer_ = std::make_unique<WordPieceTokenizer>(std::move(tokenizer).value());
  }
  static void TearDownTestSuite() { tokenizer_.reset(); }
  static Ids Encode(std::string_view text) { return tokenizer_->Encode(text); }

  static std::unique_ptr<WordPieceTokenizer> tokenizer_;
};

std::unique_ptr<WordPieceTokenizer> WordPieceTokenizerTest::tokenizer_;

TEST_F(WordPieceTokenizerTest, SpecialTokenIds) {
  EXPECT_EQ(tokenizer_->vocab_size(), 35u);
  EXPECT_EQ(tokenizer_->pad_id(), 0);
  EXPECT_EQ(tokenizer_->unk_id(), 1);
  EXPECT_EQ(tokenizer_->cls_id(), 2);
  EXPECT_EQ(tokenizer_->sep_id(), 3);
  EXPECT_EQ(tokenizer_->dot_id(), 5);
}

TEST_F(WordPieceTokenizerTest, WholeWordsAndLowerCase) {
  EXPECT_EQ(Encode("Tomato leaf"), (Ids{12, 13}));
  EXPECT_EQ(Encode("RED  Pepper"), (Ids{14, 16}));
  EXPECT_EQ(Encode(""), (Ids{}));
}

TEST_F(WordPieceTokenizerTest, ContinuationPieces) {
  EXPECT_EQ(Encode("unwanted"), (Ids{19, 20, 21}));  // un ##want ##ed
  EXPECT_EQ(Encode("peppers"), (Ids{16, 17}));       // pepper ##s
  EXPECT_EQ(Encode("strawberry"), (Ids{28, 29}));
  EXPECT_EQ(Encode("ap"), (Ids{25, 26}));  // a ##p
  // Longest match first: "apfel" is one token, not a ##p ##fel.
  EXPECT_EQ(Encode("apfel apfels"), (Ids{24, 24, 17}));
}

TEST_F(WordPieceTokenizerTest, UnknownWordsBecomeOneUnk) {
  EXPECT_EQ(Encode("leaves"), (Ids{1}));
  // "apx" starts as a ##p, but "##x" is missing: the whole word is [UNK], not a ##p [UNK].
  EXPECT_EQ(Encode("apx tomato"), (Ids{1, 12}));
  EXPECT_EQ(Encode("\xE2\x98\x83"), (Ids{1}));  // U+2603 snowman: a symbol, not punctuation
  // Bracketed special-token strings are ordinary text.
  EXPECT_EQ(Encode("[SEP]"), (Ids{1, 1, 1}));
}

TEST_F(WordPieceTokenizerTest, WordsLongerThan100CharactersAreUnknown) {
  const Ids hundred = Encode(std::string(100, 'a'));  // a ##a x 99
  ASSERT_EQ(hundred.size(), 100u);
  EXPECT_EQ(hundred.front(), 25);
  EXPECT_EQ(std::count(hundred.begin(), hundred.end(), 31), 99);
  EXPECT_EQ(Encode(std::string(101, 'a')), (Ids{1}));
}

TEST_F(WordPieceTokenizerTest, PunctuationIsSplitOneCharacterEach) {
  EXPECT_EQ(Encode("red-pepper"), (Ids{14, 10, 16}));
  EXPECT_EQ(Encode("(green)"), (Ids{8, 15, 9}));
  EXPECT_EQ(Encode("tomato!!"), (Ids{12, 7, 7}));
  EXPECT_EQ(Encode("tomato,leaf."), (Ids{12, 6, 13, 5}));
  EXPECT_EQ(Encode("leaves?"), (Ids{1, 11}));
}

TEST_F(WordPieceTokenizerTest, AccentsAreStripped) {
  EXPECT_EQ(Encode("Café"), (Ids{23}));
  EXPECT_EQ(Encode("ÄPFEL"), (Ids{24}));
  EXPECT_EQ(Encode("cafe\xCC\x81"), (Ids{23}));  // decomposed: e + U+0301
  EXPECT_EQ(Encode("ß"), (Ids{34}));             // no canonical decomposition: kept
}

TEST_F(WordPieceTokenizerTest, CleansControlCharactersAndSplitsCjk) {
  EXPECT_EQ(Encode("tom\x01"
                   "ato"),
            (Ids{12}));
  EXPECT_EQ(Encode("tom\xE2\x80\x8B"
                   "ato"),
            (Ids{12}));  // U+200B zero-width space (Cf)
  EXPECT_EQ(Encode("\ttomato\nleaf\r"), (Ids{12, 13}));
  EXPECT_EQ(Encode("tomato\xC2\xA0leaf"), (Ids{12, 13}));  // U+00A0 (Zs)
  EXPECT_EQ(Encode("日本tomato"), (Ids{32, 33, 12}));
}

TEST_F(WordPieceTokenizerTest, GroundingPromptWithTwoPhrases) {
  const auto text = tokenizer_->EncodeGroundingPrompt({"Red pepper", "leaf"});
  ASSERT_TRUE(text.ok()) << text.status().ToString();
  EXPECT_EQ(text->caption, "red pepper . leaf .");
  EXPECT_EQ(text->length, 7);
  //                       [CLS] red pepper .  leaf .  [SEP]
  EXPECT_EQ(text->input_ids, (Ids64{2, 14, 16, 5, 13, 5, 3}));
  EXPECT_EQ(text->position_ids, (Ids64{0, 0, 1, 2, 0, 1, 0}));
  EXPECT_EQ(text->token_type_ids, (Ids64{0, 0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(text->attention_mask, (std::vector<uint8_t>{1, 1, 1, 1, 1, 1, 1}));
  const std::vector<uint8_t> expected_mask = {
      1, 0, 0, 0, 0, 0, 0,  // [CLS]: itself only
      0, 1, 1, 1, 0, 0, 0,  // red: red pepper .
      0, 1, 1, 1, 0, 0, 0,  // pepper
      0, 1, 1, 1, 0, 0, 0,  // . closing "red pepper"
      0, 0, 0, 0, 1, 1, 0,  // leaf: leaf .
      0, 0, 0, 0, 1, 1, 0,  // . closing "leaf"
      0, 0, 0, 0, 0, 0, 1,  // [SEP]: itself only
  };
  ASSERT_EQ(text->text_token_mask.size(), 49u);
  for (int i = 0; i < 7; ++i) {
    for (int j = 0; j < 7; ++j) {
      EXPECT_EQ(text->text_token_mask[i * 7 + j], expected_mask[i * 7 + j]) << i << "," << j;
    }
  }
  EXPECT_EQ(text->phrase_token_spans, (std::vector<std::pair<int, int>>{{1, 3}, {4, 5}}));
}

TEST_F(WordPieceTokenizerTest, GroundingPromptWithMultiPiecePhrases) {
  const auto text = tokenizer_->EncodeGroundingPrompt({"peppers", "unwanted stem"});
  ASSERT_TRUE(text.ok()) << text.status().ToString();
  EXPECT_EQ(text->caption, "peppers . unwanted stem .");
  EXPECT_EQ(text->input_ids, (Ids64{2, 16, 17, 5, 19, 20, 21, 18, 5, 3}));
  EXPECT_EQ(text->position_ids, (Ids64{0, 0, 1, 2, 0, 1, 2, 3, 4, 0}));
  EXPECT_EQ(text->phrase_token_spans, (std::vector<std::pair<int, int>>{{1, 3}, {4, 8}}));
  const int n = text->length;
  ASSERT_EQ(n, 10);
  // Row "un" (4) sees exactly its block 4..8.
  for (int j = 0; j < n; ++j) {
    EXPECT_EQ(text->text_token_mask[4 * n + j], (j >= 4 && j <= 8) ? 1 : 0) << j;
  }
  // Row "##s" (2) sees exactly 1..3.
  for (int j = 0; j < n; ++j) {
    EXPECT_EQ(text->text_token_mask[2 * n + j], (j >= 1 && j <= 3) ? 1 : 0) << j;
  }
}

TEST_F(WordPieceTokenizerTest, GroundingCaptionLongerThanTheLimitIsAnError) {
  ASSERT_TRUE(tokenizer_->EncodeGroundingPrompt({"red pepper", "leaf"}, 7).ok());
  const auto text = tokenizer_->EncodeGroundingPrompt({"red pepper", "leaf"}, 6);
  ASSERT_FALSE(text.ok());
  EXPECT_EQ(text.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(text.status().message(),
            "grounding caption 'red pepper . leaf .' has 7 tokens; the text encoder takes at most "
            "6");
}

TEST_F(WordPieceTokenizerTest, GroundingPromptErrors) {
  const auto none = tokenizer_->EncodeGroundingPrompt({});
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.status().code(), StatusCode::kInvalidArgument);

  const auto empty = tokenizer_->EncodeGroundingPrompt({"leaf", " \x01 "});
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.status().message(), "grounding phrase ' \x01 ' has no tokens");

  for (const std::string phrase : {"st. leaf", "leaf?"}) {
    const auto separator = tokenizer_->EncodeGroundingPrompt({"tomato", phrase});
    ASSERT_FALSE(separator.ok()) << phrase;
    EXPECT_EQ(separator.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(separator.status().message().find("'" + phrase + "' contains '.' or '?'"),
              std::string::npos)
        << separator.status().message();
  }
}

TEST(WordPieceFromVocabTest, MissingSpecialTokensAreNamed) {
  auto tokenizer = WordPieceTokenizer::FromVocab({"[PAD]", "[SEP]", "tomato"});
  ASSERT_FALSE(tokenizer.ok());
  EXPECT_EQ(tokenizer.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(tokenizer.status().message(),
            "WordPiece vocabulary (3 tokens) lacks the special token(s) [CLS], [UNK]");
}

TEST(WordPieceFromVocabTest, GroundingNeedsADotToken) {
  auto tokenizer = WordPieceTokenizer::FromVocab({"[PAD]", "[UNK]", "[CLS]", "[SEP]", "leaf"});
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->dot_id(), -1);
  EXPECT_EQ(tokenizer->Encode("leaf"), (Ids{4}));
  const auto text = tokenizer->EncodeGroundingPrompt({"leaf"});
  ASSERT_FALSE(text.ok());
  EXPECT_EQ(text.status().code(), StatusCode::kFailedPrecondition);
}

TEST(WordPieceFromVocabTest, LaterDuplicateWins) {
  auto tokenizer =
      WordPieceTokenizer::FromVocab({"[PAD]", "[UNK]", "[CLS]", "[SEP]", "leaf", "leaf"});
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->Encode("leaf"), (Ids{5}));
  EXPECT_EQ(tokenizer->vocab_size(), 6u);
}

class WordPieceVocabFileTest : public test::TempDirTest {};

TEST_F(WordPieceVocabFileTest, MissingFileIsNotFound) {
  const std::filesystem::path path = dir_ / "no_vocab.txt";
  auto tokenizer = WordPieceTokenizer::FromVocabFile(path);
  ASSERT_FALSE(tokenizer.ok());
  EXPECT_EQ(tokenizer.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(tokenizer.status().message(),
            "WordPiece vocabulary file '" + path.string() + "' not found");
}

TEST_F(WordPieceVocabFileTest, ErrorsNameTheFile) {
  const std::filesystem::path path = Write("vocab.txt", "[PAD]\n[UNK]\n[SEP]\n");
  auto tokenizer = WordPieceTokenizer::FromVocabFile(path);
  ASSERT_FALSE(tokenizer.ok());
  EXPECT_EQ(tokenizer.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(tokenizer.status().message(),
            "WordPiece vocabulary file '" + path.string() +
                "': WordPiece vocabulary (3 tokens) lacks the special token(s) [CLS]");
}

TEST_F(WordPieceVocabFileTest, CrlfLinesAndNoFinalNewline) {
  const std::filesystem::path path =
      Write("vocab.txt", "[PAD]\r\n[UNK]\r\n[CLS]\r\n[SEP]\r\n.\r\ntomato");
  auto tokenizer = WordPieceTokenizer::FromVocabFile(path);
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->vocab_size(), 6u);
  EXPECT_EQ(tokenizer->dot_id(), 4);
  EXPECT_EQ(tokenizer->Encode("tomato."), (Ids{5, 4}));
}

// Golden ids of bert-base-uncased (Hugging Face's BertTokenizer) with the real vocabulary,
// committed in zsl/data/vocab (AVP_ZSL_VOCAB_DIR; its README names the source and licence) and
// pinned by its sha256, so this runs in every build.
TEST(WordPieceRealVocabularyTest, GoldenIds) {
  const std::filesystem::path path =
      std::filesystem::path(AVP_ZSL_VOCAB_DIR) / "bert-base-uncased-vocab.txt";
  const Result<std::string> sha = FileSha256(path);
  ASSERT_TRUE(sha.ok()) << sha.status().ToString();
  ASSERT_EQ(*sha, "07eced375cec144d27c900241f3e339478dec958f92fddbc551f295c992038a3")
      << path.string() << " is not BERT's bert-base-uncased vocab.txt";
  auto tokenizer = WordPieceTokenizer::FromVocabFile(path);
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->vocab_size(), 30522u);
  EXPECT_EQ(tokenizer->pad_id(), 0);
  EXPECT_EQ(tokenizer->unk_id(), 100);
  EXPECT_EQ(tokenizer->cls_id(), 101);
  EXPECT_EQ(tokenizer->sep_id(), 102);
  EXPECT_EQ(tokenizer->dot_id(), 1012);
  EXPECT_EQ(tokenizer->Encode("a photo of a cat"), (Ids{1037, 6302, 1997, 1037, 4937}));
  EXPECT_EQ(tokenizer->Encode("Hello, world!"), (Ids{7592, 1010, 2088, 999}));
  // "transformer" is not a token: greedy longest match gives "transform" "##er".
  EXPECT_EQ(tokenizer->Encode("Using a Transformer network is simple"),
            (Ids{2478, 1037, 10938, 2121, 2897, 2003, 3722}));
  Result<GroundingText> text = tokenizer->EncodeGroundingPrompt({"tomato", "green apple"});
  ASSERT_TRUE(text.ok()) << text.status().ToString();
  EXPECT_EQ(text->input_ids, (Ids64{101, 20856, 1012, 2665, 6207, 1012, 102}));
}

}  // namespace
}  // namespace avp::zsl

// The CLIP BPE tokenizer on a hand-built 50-merge fixture (test/data/clip_merges_fixture.txt).
//
// How the expected ids follow from CLIP's construction rule:
//  - ids 0..255 are the byte symbols in GPT-2 bytes_to_unicode order: the printable bytes
//    '!'..'~' (0x21..0x7E) are ids 0..93 (id = byte - 33), 0xA1..0xAC are 94..105
//    (id = byte - 161 + 94), 0xAE..0xFF are 106..187 (id = byte - 174 + 106); the other 68 bytes
//    follow in ascending order: 0x00..0x20 are 188..220, 0x7F..0xA0 are 221..254, 0xAD is 255.
//  - ids 256..511 are the same symbols with "</w>" (id + 256): "a</w>" = 97 - 33 + 256 = 320.
//  - merge rank r (line r + 2 of the fixture) has id 512 + r; SOT = 562, EOT = 563, 564 in all.
// Fixture merges used below (rank: pair -> id):
//   0 t o -> 512 "to"         1 m a -> 513        2 t o</w> -> 514     3 to ma -> 515 "toma"
//   4 toma to</w> -> 516 "tomato</w>"            5 e s</w> -> 517 "es</w>"
//   6 l e -> 518   7 a f</w> -> 519   8 le af</w> -> 520 "leaf</w>"
//   9 r e -> 521   10 re d</w> -> 522 "red</w>"   11 o f</w> -> 523 "of</w>"
//   12 p h -> 524  13 ph o -> 525  14 pho to</w> -> 526 "photo</w>"
//   15 c a -> 527  16 ca f -> 528  17 Ã ©</w> -> 529  18 caf Ã©</w> -> 530 "café</w>"
//   19 Ã ¤ -> 531  20 e l</w> -> 532  21 p f -> 533  22 Ã¤ pf -> 534
//   23 Ã¤pf el</w> -> 535 "äpfel</w>"
//   24 i m -> 536  25 e n -> 537  26 p im -> 538  27 i en -> 539  28 pim ien -> 540
//   29 pimien to</w> -> 541 "pimiento</w>"
//   30 r o -> 542  31 j o</w> -> 543  32 ro jo</w> -> 544 "rojo</w>"
//   33 i t</w> -> 545  34 ' s</w> -> 546  35 ' t</w> -> 547  36 d o -> 548
//   37 do n</w> -> 549  38 r e</w> -> 550  39 ' re</w> -> 551  40 l l</w> -> 552
//   41 ' ll</w> -> 553  42 ! ! -> 554  43 2 0 -> 555 (never applies: digits are split one by one)
//   44 e r -> 556  45 v e</w> -> 557  46 ' ve</w> -> 558  47 s t -> 559  48 e m</w> -> 560
//   49 st em</w> -> 561 "stem</w>"
#include "clip_tokenizer.h"

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <zlib.h>

#include <avp/core/error.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

#include "sha256.h"

namespace avp::zsl {
namespace {

using Ids = std::vector<int32_t>;

const std::filesystem::path kFixture =
    std::filesystem::path(AVP_ZSL_TEST_DATA) / "clip_merges_fixture.txt";

constexpr int32_t kSot = 562;
constexpr int32_t kEot = 563;

void WriteGzip(const std::filesystem::path& path, const std::string& bytes) {
  gzFile file = gzopen(path.c_str(), "wb");
  ASSERT_NE(file, nullptr) << path;
  ASSERT_EQ(gzwrite(file, bytes.data(), static_cast<unsigned>(bytes.size())),
            static_cast<int>(bytes.size()));
  ASSERT_EQ(gzclose(file), Z_OK);
}

class ClipTokenizerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto tokenizer = ClipTokenizer::FromMergesFile(kFixture);
    ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
    tokenizer_ = std::make_unique<ClipTokenizer>(std::move(tokenizer).value());
  }
  static void TearDownTestSuite() { tokenizer_.reset(); }
  static Ids Encode(std::string_view text) { return tokenizer_->Encode(text); }

  static std::unique_ptr<ClipTokenizer> tokenizer_;
};

std::unique_ptr<ClipTokenizer> ClipTokenizerTest::tokenizer_;

TEST_F(ClipTokenizerTest, VocabularyFollowsClipsConstruction) {
  EXPECT_EQ(tokenizer_->vocab_size(), 564u);  // 256 + 256 + 50 + 2
  EXPECT_EQ(tokenizer_->sot(), kSot);
  EXPECT_EQ(tokenizer_->eot(), kEot);
}

TEST_F(ClipTokenizerTest, ByteSymbolsUseGpt2Order) {
  EXPECT_EQ(Encode("!"), (Ids{256}));  // '!' is byte symbol 0
  EXPECT_EQ(Encode("ab"), (Ids{64, 321}));
  EXPECT_EQ(Encode("~"), (Ids{93 + 256}));
  // U+00AD (soft hyphen, bytes C2 AD): 0xC2 is printable (id 126); 0xAD is the last of the
  // non-printable bytes, symbol 255.
  EXPECT_EQ(Encode("\xC2\xAD"), (Ids{126, 511}));
  // 日本 = E6 97 A5 E6 9C AC: 0xE6 -> 162, 0x97 -> 245 (non-printable), 0xA5 -> 98,
  // 0x9C -> 250 (non-printable), 0xAC -> 105 + 256.
  EXPECT_EQ(Encode("日本"), (Ids{162, 245, 98, 162, 250, 361}));
}

TEST_F(ClipTokenizerTest, WholeWordsMergeToTheirEndOfWordIds) {
  EXPECT_EQ(Encode("a photo of a tomato"), (Ids{320, 526, 523, 320, 516}));
  EXPECT_EQ(Encode("leaf"), (Ids{520}));
  EXPECT_EQ(Encode("red"), (Ids{522}));
  EXPECT_EQ(Encode("stem"), (Ids{561}));
}

TEST_F(ClipTokenizerTest, EndOfWordMarksOnlyTheLastSymbol) {
  // "tomatoes": both "t o" pairs merge (rank 0), but "t o</w>" does not occur, so the word stays
  // in three pieces: "toma" "to" "es</w>". A whole-word lookup would get this wrong.
  EXPECT_EQ(Encode("tomatoes"), (Ids{515, 512, 517}));
  // "stems": s t -> st; "e m</w>" does not occur (the word ends in s</w>).
  EXPECT_EQ(Encode("stems"), (Ids{559, 68, 76, 338}));
  // Unmerged last symbol: "they" = t h e y</w>.
  EXPECT_EQ(Encode("they"), (Ids{83, 71, 68, 344}));
}

TEST_F(ClipTokenizerTest, MergesTheLowestRankedPairFirst) {
  // "ere" = e r e</w>: "e r" (rank 44) is leftmost, but "r e</w>" (rank 38) ranks lower.
  EXPECT_EQ(Encode("ere"), (Ids{68, 550}));
  // "pimiento" needs six merges in rank order: t o</w>, i m, e n, p im, i en, pim ien, then
  // pimien to</w>.
  EXPECT_EQ(Encode("pimiento rojo"), (Ids{541, 544}));
}

TEST_F(ClipTokenizerTest, MergesNonOverlappingOccurrencesLeftToRight) {
  EXPECT_EQ(Encode("!!!"), (Ids{554, 256}));      // !! !</w>
  EXPECT_EQ(Encode("!!!!"), (Ids{554, 0, 256}));  // !! ! !</w>: "! !</w>" is no merge
}

TEST_F(ClipTokenizerTest, Contractions) {
  EXPECT_EQ(Encode("it's"), (Ids{545, 546}));
  EXPECT_EQ(Encode("don't"), (Ids{549, 547}));
  EXPECT_EQ(Encode("they're"), (Ids{83, 71, 68, 344, 551}));
  EXPECT_EQ(Encode("i've"), (Ids{328, 558}));
  EXPECT_EQ(Encode("we'll"), (Ids{86, 324, 553}));
  EXPECT_EQ(Encode("i'm"), (Ids{328, 6, 332}));            // "'m" is a piece without a merge
  EXPECT_EQ(Encode("she'd"), (Ids{82, 71, 324, 6, 323}));  // "'d" likewise
  EXPECT_EQ(Encode("IT'S"), (Ids{545, 546}));              // lower-cased first
  // An apostrophe that starts no contraction is punctuation of its own: rock ' n.
  EXPECT_EQ(Encode("rock'n"), (Ids{542, 66, 330, 262, 333}));
}

TEST_F(ClipTokenizerTest, DigitsAreSplitOneByOne) {
  // "2 0" is a merge of the fixture, but each digit is its own piece: 2</w> 0</w> 2</w> 4</w>.
  EXPECT_EQ(Encode("2024"), (Ids{273, 271, 273, 275}));
  EXPECT_EQ(Encode("tomato2"), (Ids{516, 273}));
}

TEST_F(ClipTokenizerTest, NonAsciiLetters) {
  EXPECT_EQ(Encode("café"), (Ids{530}));   // c a f Ã ©</w> -> café</w>
  EXPECT_EQ(Encode("äpfel"), (Ids{535}));  // Ã ¤ p f e l</w> -> äpfel</w>
  EXPECT_EQ(Encode("CAFÉ"), (Ids{530}));   // Unicode lower-casing
  EXPECT_EQ(Encode("ÄPFEL"), (Ids{535}));
  EXPECT_EQ(Encode("Pimiento Rojo"), (Ids{541, 544}));
}

TEST_F(ClipTokenizerTest, PunctuationRuns) {
  EXPECT_EQ(Encode("?!..."), (Ids{30, 0, 13, 13, 269}));  // one piece, no merges
  EXPECT_EQ(Encode("tomato, leaf"), (Ids{516, 267, 520}));
  EXPECT_EQ(Encode("(red)"), (Ids{263, 522, 264}));
}

TEST_F(ClipTokenizerTest, CleansWhitespaceAndHtmlEntities) {
  EXPECT_EQ(Encode("  a \t\n photo  "), (Ids{320, 526}));
  EXPECT_EQ(Encode("tomato &amp; leaf"), (Ids{516, 261, 520}));
  EXPECT_EQ(Encode("&amp;lt;"), (Ids{283}));  // unescaped twice, as CLIP does: "<"
  EXPECT_EQ(Encode("&#116;&#x6F;mato"), (Ids{516}));
  EXPECT_EQ(Encode("a&nbsp;leaf"), (Ids{320, 520}));  // U+00A0 is whitespace
  EXPECT_EQ(Encode(""), (Ids{}));
  EXPECT_EQ(Encode(" \t "), (Ids{}));
  // U+001C is stripped at the ends (Python's str.strip) but is no whitespace inside (it is a
  // piece of its own there: byte 0x1C is symbol 188 + 28 = 216, 472 with </w>).
  EXPECT_EQ(Encode("\x1Ctomato\x1C"), (Ids{516}));
  EXPECT_EQ(Encode("a\x1C"
                   "b"),
            (Ids{320, 472, 321}));
}

TEST_F(ClipTokenizerTest, LowerCasesGreekWithFinalSigma) {
  EXPECT_EQ(Encode("ΟΔΟΣ"), Encode("οδος"));  // a word-final capital sigma becomes ς
  EXPECT_NE(Encode("ΟΔΟΣ"), Encode("οδοσ"));
  EXPECT_EQ(Encode("ΣΟ"), Encode("σο"));
}

TEST_F(ClipTokenizerTest, InvalidUtf8BecomesReplacementCharacter) {
  // U+FFFD = EF BF BD: 0xEF -> 171, 0xBF -> 123, 0xBD -> 121 + 256.
  EXPECT_EQ(Encode("\xFF"), (Ids{171, 123, 377}));
}

TEST_F(ClipTokenizerTest, InjectedSpecialTokensAreStripped) {
  EXPECT_EQ(Encode("a <|endoftext|> tomato"), (Ids{320, 516}));
  EXPECT_EQ(Encode("<|startoftext|>leaf"), (Ids{520}));
  EXPECT_EQ(Encode("A<|EndOfText|>b"), (Ids{320, 321}));
  EXPECT_EQ(Encode("&lt;|endoftext|&gt;leaf"), (Ids{520}));
  const std::vector<int64_t> tokens = tokenizer_->Tokenize("<|endoftext|>red");
  EXPECT_EQ(tokens[0], kSot);
  EXPECT_EQ(tokens[1], 522);
  EXPECT_EQ(tokens[2], kEot);
  EXPECT_EQ(tokens[3], 0);
}

TEST_F(ClipTokenizerTest, TokenizeFramesAndPadsWithZeros) {
  const std::vector<int64_t> tokens = tokenizer_->Tokenize("A photo of a tomato");
  std::vector<int64_t> expected(77, 0);
  const std::vector<int64_t> head = {kSot, 320, 526, 523, 320, 516, kEot};
  std::copy(head.begin(), head.end(), expected.begin());
  EXPECT_EQ(tokens, expected);

  EXPECT_EQ(tokenizer_->Tokenize(""), [] {
    std::vector<int64_t> v(77, 0);
    v[0] = kSot;
    v[1] = kEot;
    return v;
  }());
}

std::string Repeat(const std::string& word, int count) {
  std::string text;
  for (int i = 0; i < count; ++i) text += word + " ";
  return text;
}

TEST_F(ClipTokenizerTest, TruncationKeepsEotAtTheLastPosition) {
  // 75 words fill the context exactly: SOT, 75 x "a</w>", EOT.
  const std::vector<int64_t> exact = tokenizer_->Tokenize(Repeat("a", 75));
  ASSERT_EQ(exact.size(), 77u);
  EXPECT_EQ(exact[0], kSot);
  for (int i = 1; i <= 75; ++i) EXPECT_EQ(exact[i], 320) << i;
  EXPECT_EQ(exact[76], kEot);

  // 100 words: cut to 77 with position 76 forced to EOT.
  const std::vector<int64_t> cut = tokenizer_->Tokenize(Repeat("a", 100));
  ASSERT_EQ(cut.size(), 77u);
  EXPECT_EQ(cut[0], kSot);
  for (int i = 1; i <= 75; ++i) EXPECT_EQ(cut[i], 320) << i;
  EXPECT_EQ(cut[76], kEot);
  EXPECT_EQ(std::count(cut.begin(), cut.end(), kEot), 1);
}

TEST_F(ClipTokenizerTest, OtherContextLengths) {
  EXPECT_EQ(tokenizer_->Tokenize("tomato", 4), (std::vector<int64_t>{kSot, 516, kEot, 0}));
  EXPECT_EQ(tokenizer_->Tokenize("a a a a", 4), (std::vector<int64_t>{kSot, 320, 320, kEot}));
  EXPECT_EQ(tokenizer_->Tokenize("a", 1), (std::vector<int64_t>{kEot}));  // as clip.tokenize
  EXPECT_THROW(tokenizer_->Tokenize("a", 0), Error);
}

TEST_F(ClipTokenizerTest, ConcurrentEncodingAgrees) {
  const std::vector<std::string> texts = {"a photo of a tomato", "tomatoes", "café äpfel",
                                          "pimiento rojo", "it's 2024!!!"};
  std::vector<Ids> expected;
  for (const std::string& text : texts) expected.push_back(Encode(text));
  std::vector<std::thread> threads;
  std::vector<int> mismatches(4, 0);
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 200; ++i) {
        const size_t k = static_cast<size_t>(i + t) % texts.size();
        if (tokenizer_->Encode(texts[k]) != expected[k]) ++mismatches[t];
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(mismatches, (std::vector<int>{0, 0, 0, 0}));
}

TEST(ClipTokenizerFromMergesTest, EmptyMergeListHasOnlyBytesAndSpecials) {
  auto tokenizer = ClipTokenizer::FromMerges({});
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->vocab_size(), 514u);
  EXPECT_EQ(tokenizer->sot(), 512);
  EXPECT_EQ(tokenizer->eot(), 513);
  EXPECT_EQ(tokenizer->Encode("tomato"), (Ids{83, 78, 76, 64, 83, 334}));
}

TEST(ClipTokenizerFromMergesTest, MergeIdsFollowTheirRank) {
  auto tokenizer = ClipTokenizer::FromMerges({{"a", "b</w>"}, {"c", "ab</w>"}});
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->Encode("ab"), (Ids{512}));
  EXPECT_EQ(tokenizer->Encode("cab"), (Ids{513}));
  EXPECT_EQ(tokenizer->sot(), 514);
}

TEST(ClipTokenizerFromMergesTest, EmptySymbolIsAnError) {
  auto tokenizer = ClipTokenizer::FromMerges({{"a", "b"}, {"", "c"}});
  ASSERT_FALSE(tokenizer.ok());
  EXPECT_EQ(tokenizer.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(tokenizer.status().message(), "CLIP merge 1 ('' 'c') has an empty symbol");
}

class ClipMergesFileTest : public test::TempDirTest {};

TEST_F(ClipMergesFileTest, GzipFileGivesTheSameTokenizer) {
  const std::filesystem::path gz = dir_ / "merges.txt.gz";
  WriteGzip(gz, test::ReadWholeFile(kFixture));
  auto tokenizer = ClipTokenizer::FromMergesFile(gz);
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->vocab_size(), 564u);
  EXPECT_EQ(tokenizer->Encode("a photo of a tomato"), (Ids{320, 526, 523, 320, 516}));
  EXPECT_EQ(tokenizer->Encode("café äpfel"), (Ids{530, 535}));
}

TEST_F(ClipMergesFileTest, CrlfLineEndingsAndNoFinalNewline) {
  const std::filesystem::path path = Write("crlf.txt", "#version: 0.2\r\nt o\r\nto m</w>");
  auto tokenizer = ClipTokenizer::FromMergesFile(path);
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->vocab_size(), 516u);
  EXPECT_EQ(tokenizer->Encode("tom"), (Ids{513}));
}

TEST_F(ClipMergesFileTest, ReadsOnlyTheMergesClipUses) {
  // 48,894 merges, then lines CLIP never reads (one of them malformed).
  std::string text = "#version: 0.2\n";
  for (size_t i = 0; i < ClipTokenizer::kClipMergeCount; ++i) text += "x y\n";
  text += "not a merge\nz w\n";
  auto tokenizer = ClipTokenizer::FromMergesFile(Write("full.txt", text));
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->vocab_size(), 49408u);
  EXPECT_EQ(tokenizer->sot(), 49406);
  EXPECT_EQ(tokenizer->eot(), 49407);
}

TEST_F(ClipMergesFileTest, MissingFileIsNotFound) {
  const std::filesystem::path path = dir_ / "no_such_merges.txt.gz";
  auto tokenizer = ClipTokenizer::FromMergesFile(path);
  ASSERT_FALSE(tokenizer.ok());
  EXPECT_EQ(tokenizer.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(tokenizer.status().message(), "CLIP merges file '" + path.string() + "' not found");
}

TEST_F(ClipMergesFileTest, MalformedLineNamesFileAndLine) {
  const std::filesystem::path path = Write("bad.txt", "#version: 0.2\nt o\nm a x\nr e\n");
  auto tokenizer = ClipTokenizer::FromMergesFile(path);
  ASSERT_FALSE(tokenizer.ok());
  EXPECT_EQ(tokenizer.status().code(), StatusCode::kParseError);
  EXPECT_EQ(tokenizer.status().message(),
            "CLIP merges file '" + path.string() +
                "' line 3: expected two symbols separated by a space, got 'm a x'");
}

TEST_F(ClipMergesFileTest, EmptyLineInsideTheFileIsMalformed) {
  const std::filesystem::path path = Write("blank.txt", "#version: 0.2\nt o\n\nr e\n");
  auto tokenizer = ClipTokenizer::FromMergesFile(path);
  ASSERT_FALSE(tokenizer.ok());
  EXPECT_EQ(tokenizer.status().code(), StatusCode::kParseError);
  EXPECT_NE(tokenizer.status().message().find("'" + path.string() + "' line 3"), std::string::npos)
      << tokenizer.status().message();
}

TEST_F(ClipMergesFileTest, EmptyFileIsAParseError) {
  const std::filesystem::path path = Write("empty.txt", "");
  auto tokenizer = ClipTokenizer::FromMergesFile(path);
  ASSERT_FALSE(tokenizer.ok());
  EXPECT_EQ(tokenizer.status().code(), StatusCode::kParseError);
  EXPECT_NE(tokenizer.status().message().find(path.string()), std::string::npos);
}

TEST_F(ClipMergesFileTest, TruncatedGzipIsAnIoError) {
  const std::filesystem::path whole = dir_ / "whole.txt.gz";
  WriteGzip(whole, test::ReadWholeFile(kFixture));
  const std::string bytes = test::ReadWholeFile(whole);
  const std::filesystem::path path = Write("truncated.txt.gz", bytes.substr(0, bytes.size() / 2));
  auto tokenizer = ClipTokenizer::FromMergesFile(path);
  ASSERT_FALSE(tokenizer.ok());
  EXPECT_EQ(tokenizer.status().code(), StatusCode::kIoError);
  EXPECT_NE(tokenizer.status().message().find("'" + path.string() + "'"), std::string::npos)
      << tokenizer.status().message();
}

// Golden ids from OpenAI's clip.tokenize with the real vocabulary, committed in zsl/data/vocab
// (AVP_ZSL_VOCAB_DIR; its README names the source and licence) and pinned by its sha256, so this
// runs in every build.
TEST(ClipTokenizerRealVocabularyTest, GoldenIds) {
  const std::filesystem::path path =
      std::filesystem::path(AVP_ZSL_VOCAB_DIR) / "bpe_simple_vocab_16e6.txt.gz";
  const Result<std::string> sha = FileSha256(path);
  ASSERT_TRUE(sha.ok()) << sha.status().ToString();
  ASSERT_EQ(*sha, "924691ac288e54409236115652ad4aa250f48203de50a9e4722a6ecd48d6804a")
      << path.string() << " is not OpenAI CLIP's bpe_simple_vocab_16e6.txt.gz";
  auto tokenizer = ClipTokenizer::FromMergesFile(path);
  ASSERT_TRUE(tokenizer.ok()) << tokenizer.status().ToString();
  EXPECT_EQ(tokenizer->vocab_size(), 49408u);
  EXPECT_EQ(tokenizer->sot(), 49406);
  EXPECT_EQ(tokenizer->eot(), 49407);
  EXPECT_EQ(tokenizer->Encode("a photo of a cat"), (Ids{320, 1125, 539, 320, 2368}));
  EXPECT_EQ(tokenizer->Encode("a painting of a cat"), (Ids{320, 3086, 539, 320, 2368}));
  EXPECT_EQ(tokenizer->Encode("bozuman"), (Ids{647, 4091, 786}));
  const std::vector<int64_t> tokens = tokenizer->Tokenize("a photo of a cat");
  ASSERT_EQ(tokens.size(), 77u);
  EXPECT_EQ((std::vector<int64_t>(tokens.begin(), tokens.begin() + 8)),
            (std::vector<int64_t>{49406, 320, 1125, 539, 320, 2368, 49407, 0}));
}

}  // namespace
}  // namespace avp::zsl

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/limits.h>
#include <avp/core/text.h>

namespace avp {
namespace {

TEST(TextTest, PrintableTextIsKept) {
  EXPECT_EQ(EscapeText("tomato, apple 0.5"), "tomato, apple 0.5");
  EXPECT_EQ(QuoteText("abc"), "'abc'");
}

TEST(TextTest, ControlCharactersAndHighBytesAreEscaped) {
  // An ANSI "clear screen" from a crafted file must not reach the terminal.
  EXPECT_EQ(EscapeText("a\x1b[2Jb"), "a\\x1b[2Jb");
  EXPECT_EQ(EscapeText("l1\nl2\r\t"), "l1\\nl2\\r\\t");
  EXPECT_EQ(EscapeText(std::string("a\0b", 3)), "a\\x00b");
  EXPECT_EQ(EscapeText("\x7f\xff"), "\\x7f\\xff");
  EXPECT_EQ(QuoteText("it's \\"), "'it\\'s \\\\'");
}

TEST(TextTest, LongTextIsShortenedWithItsLength) {
  const std::string digits(300, '9');
  const std::string shown = QuoteText(digits);
  EXPECT_EQ(shown, "'" + std::string(kQuotedTextMaxChars, '9') + "...(300 bytes)'");
  EXPECT_EQ(EscapeText("abcdef", 3), "abc...(6 bytes)");
  EXPECT_EQ(EscapeText("abc", 3), "abc");
}

TEST(LimitsTest, ExceedsLimitNamesAmountLimitAndHowToRaise) {
  EXPECT_TRUE(CheckLimit("phrases", 64, "max_phrases", 64).ok());
  const Status s = CheckLimit("prompt phrases", 100000, "max_phrases", 64, "raise it with --x");
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(s.message(),
            "prompt phrases (100000) exceeds the limit max_phrases = 64; raise it with --x");
  EXPECT_EQ(ExceedsLimit("seeds", 5, "max_seeds", 4).message(),
            "seeds (5) exceeds the limit max_seeds = 4");
}

}  // namespace
}  // namespace avp

namespace avp {
namespace {

const Limit& TestLimit() {
  static const Limit limit("test_widgets", 10, "widgets", "widgets of a test");
  return limit;
}

TEST(LimitsTest, RegisteredLimitChecksAndNamesHowToRaise) {
  EXPECT_TRUE(TestLimit().Check("widgets", 10).ok());
  const Status s = TestLimit().Check("widgets in the request", 11);
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(s.message(),
            "widgets in the request (11) exceeds the limit test_widgets = 10; raise it with "
            "--limit test_widgets=N (docs/limits.md)");
  bool listed = false;
  for (const LimitInfo& info : RegisteredLimits()) {
    if (info.name == "test_widgets") {
      listed = true;
      EXPECT_EQ(info.default_value, 10u);
      EXPECT_EQ(info.unit, "widgets");
    }
  }
  EXPECT_TRUE(listed);
}

TEST(LimitsTest, SetLimitsParsesStrictlyAndScopedLimitRestores) {
  {
    const ScopedLimit scoped(TestLimit(), 3);
    EXPECT_EQ(TestLimit().value(), 3u);
    ASSERT_TRUE(SetLimits("test_widgets=20").ok());
    EXPECT_EQ(TestLimit().value(), 20u);
  }
  EXPECT_EQ(TestLimit().value(), 10u);
  EXPECT_EQ(SetLimits("nope=3").code(), StatusCode::kNotFound);
  EXPECT_NE(SetLimits("nope=3").message().find("unknown limit 'nope'"), std::string::npos);
  for (const char* bad : {"test_widgets=-1", "test_widgets=0", "test_widgets=1e9",
                          "test_widgets=99999999999999999999", "test_widgets", "test_widgets="}) {
    EXPECT_EQ(SetLimits(bad).code(), StatusCode::kInvalidArgument) << bad;
  }
  EXPECT_EQ(TestLimit().value(), 10u);
  EXPECT_THROW(Limit("test_widgets", 5, "", ""), Error);
}

TEST(TextTest, NearestNameFindsSlipsOfTheKeyboardOnly) {
  const std::vector<std::string> commands = {"scenes", "render", "map", "run", "replay", "bench"};
  EXPECT_EQ(NearestName("rendr", commands), "render");
  EXPECT_EQ(NearestName("Render", commands), "render");  // case counts as no edit
  EXPECT_EQ(NearestName("rnu", commands), "run");        // a swap counts once
  EXPECT_EQ(NearestName("bnech", commands), "bench");
  EXPECT_EQ(NearestName("run", commands), "");  // known
  EXPECT_EQ(NearestName("zzzzzz", commands), "");
  EXPECT_EQ(NearestName("", commands), "");
  EXPECT_EQ(NearestName(std::string(1000, 'r'), commands), "");
  const std::vector<std::string> keys = {"episode.views", "episode.prompt", "p_unknown"};
  EXPECT_EQ(NearestName("episode.view", keys), "episode.views");
  EXPECT_EQ(NearestName("p_unkown", keys), "p_unknown");
  EXPECT_EQ(DidYouMean("p_unkown", keys), "; did you mean 'p_unknown'?");
  EXPECT_EQ(DidYouMean("q", keys), "");
}

}  // namespace
}  // namespace avp

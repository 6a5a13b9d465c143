#include <string>

#include <gtest/gtest.h>

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

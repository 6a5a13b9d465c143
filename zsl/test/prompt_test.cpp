#include "prompt.h"

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <avp/core/limits.h>
#include <avp/segmentation/segmenter.h>

namespace avp::zsl {
namespace {

using Classes = std::vector<std::string>;

TEST(NormalizeClassNameTest, TrimsCollapsesAndLowerCasesAscii) {
  EXPECT_EQ(NormalizeClassName("  Red \n\t Tomato  "), "red tomato");
  EXPECT_EQ(NormalizeClassName("LEAF"), "leaf");
  EXPECT_EQ(NormalizeClassName(""), "");
  EXPECT_EQ(NormalizeClassName(" \t\r\n "), "");
  // Non-ASCII bytes are left as they are: no Unicode case mapping.
  EXPECT_EQ(NormalizeClassName("  CAFÉ ÄPFEL "), "cafÉ Äpfel");
}

TEST(ParsePromptClassesTest, SplitsAtCommasTrimsAndLowerCases) {
  const auto classes = ParsePromptClasses("Tomato, leaf , STEM,red   pepper");
  ASSERT_TRUE(classes.ok()) << classes.status().ToString();
  EXPECT_EQ(*classes, (Classes{"tomato", "leaf", "stem", "red pepper"}));
}

TEST(ParsePromptClassesTest, KeepsTheFirstOccurrenceOfDuplicates) {
  const auto classes = ParsePromptClasses("leaf, Tomato, LEAF ,tomato,  leaf,stem");
  ASSERT_TRUE(classes.ok()) << classes.status().ToString();
  EXPECT_EQ(*classes, (Classes{"leaf", "tomato", "stem"}));
}

TEST(ParsePromptClassesTest, DropsEmptyPieces) {
  const auto classes = ParsePromptClasses(",a,, b , ,");
  ASSERT_TRUE(classes.ok()) << classes.status().ToString();
  EXPECT_EQ(*classes, (Classes{"a", "b"}));
}

TEST(ParsePromptClassesTest, SingleClassWithoutComma) {
  const auto classes = ParsePromptClasses("  Tomato\t");
  ASSERT_TRUE(classes.ok()) << classes.status().ToString();
  EXPECT_EQ(*classes, (Classes{"tomato"}));
}

TEST(ParsePromptClassesTest, KeepsNonAsciiBytes) {
  const auto classes = ParsePromptClasses("Pimiento Rojo, Café, ÄPFEL");
  ASSERT_TRUE(classes.ok()) << classes.status().ToString();
  EXPECT_EQ(*classes, (Classes{"pimiento rojo", "café", "Äpfel"}));
}

TEST(ParsePromptClassesTest, EmptyPromptIsAnErrorQuotingThePrompt) {
  const auto empty = ParsePromptClasses("");
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(empty.status().message(),
            "prompt '' has no classes: expected comma-separated names such as 'tomato, leaf'");

  const auto commas = ParsePromptClasses(" , ,\t");
  ASSERT_FALSE(commas.ok());
  EXPECT_EQ(commas.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(commas.status().message().find("prompt ' , ,\\t' has no classes"), std::string::npos)
      << commas.status().message();
}

TEST(ParsePromptClassesTest, TheProcessWidePromptLimitsApply) {
  std::string prompt = "tomato";
  for (int i = 1; i < 100000; ++i) prompt += ", tomato";
  const auto huge = ParsePromptClasses(prompt);
  ASSERT_FALSE(huge.ok());
  EXPECT_EQ(huge.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(huge.status().message().find("prompt (799998) exceeds the limit max_prompt_bytes"),
            std::string::npos)
      << huge.status().message();
  std::string many = "a";
  for (int i = 1; i < 65; ++i) many += ",a";  // 65 phrases, one class
  const auto phrases = ParsePromptClasses(many);
  ASSERT_FALSE(phrases.ok());
  EXPECT_NE(phrases.status().message().find("phrases in the prompt (65) exceeds the limit "
                                            "max_prompt_phrases = 64"),
            std::string::npos)
      << phrases.status().message();
}

std::string NumberedClasses(int count) {
  std::string prompt;
  for (int i = 0; i < count; ++i) prompt += (i > 0 ? ", class" : "class") + std::to_string(i);
  return prompt;
}

TEST(ParsePromptClassesTest, MoreClassesThanTheLimitIsAnError) {
  const auto classes = ParsePromptClasses(NumberedClasses(40), 32);
  ASSERT_FALSE(classes.ok());
  EXPECT_EQ(classes.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(classes.status().message(),
            "prompt has 40 classes; the detector takes at most 32 (N_max)");
}

TEST(ParsePromptClassesTest, ExactlyTheLimitIsAccepted) {
  const auto classes = ParsePromptClasses(NumberedClasses(32), 32);
  ASSERT_TRUE(classes.ok()) << classes.status().ToString();
  ASSERT_EQ(classes->size(), 32u);
  EXPECT_EQ(classes->front(), "class0");
  EXPECT_EQ(classes->back(), "class31");
}

TEST(ParsePromptClassesTest, DuplicatesDoNotCountTowardsTheLimit) {
  const auto classes = ParsePromptClasses("a, b, A, b, c", 3);
  ASSERT_TRUE(classes.ok()) << classes.status().ToString();
  EXPECT_EQ(*classes, (Classes{"a", "b", "c"}));
  EXPECT_FALSE(ParsePromptClasses("a, b, c, d", 3).ok());
}

TEST(ParsePromptClassesTest, ZeroLimitMeansNoDetectorLimit) {
  // Only the process-wide max_prompt_phrases (64 by default) applies then.
  const ScopedLimit more(segmentation::MaxPromptPhrases(), 100);
  const auto classes = ParsePromptClasses(NumberedClasses(100));
  ASSERT_TRUE(classes.ok()) << classes.status().ToString();
  EXPECT_EQ(classes->size(), 100u);
}

}  // namespace
}  // namespace avp::zsl

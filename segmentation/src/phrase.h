#pragma once

// Private helpers for reading prompt phrases (shared by the oracle and colour segmenters).

#include <cctype>
#include <string>
#include <string_view>
#include <vector>

namespace avp::segmentation::internal {

/// The phrase's words, lower-cased, split on white space ("Ripe  Tomatoes" -> {"ripe",
/// "tomatoes"}).
inline std::vector<std::string> PhraseWords(std::string_view phrase) {
  std::vector<std::string> words;
  std::string word;
  for (char c : phrase) {
    if (std::isspace(static_cast<unsigned char>(c)) != 0) {
      if (!word.empty()) words.push_back(std::move(word));
      word.clear();
    } else {
      word.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
    }
  }
  if (!word.empty()) words.push_back(std::move(word));
  return words;
}

/// The spellings a vocabulary entry may match for `word`: the word itself, then its English
/// singulars ("tomatoes" -> "tomato", "strawberries" -> "strawberry", "apples" -> "apple").
inline std::vector<std::string> SingularCandidates(const std::string& word) {
  std::vector<std::string> out = {word};
  const auto ends_with = [&](std::string_view suffix) {
    return word.size() > suffix.size() && word.compare(word.size() - suffix.size(), suffix.size(),
                                                       suffix.data(), suffix.size()) == 0;
  };
  if (ends_with("ies")) out.push_back(word.substr(0, word.size() - 3) + "y");
  if (ends_with("oes")) out.push_back(word.substr(0, word.size() - 2));
  if (ends_with("s")) out.push_back(word.substr(0, word.size() - 1));
  return out;
}

/// True for a non-empty word of lower-case ASCII letters and hyphens.
inline bool IsVocabularyWord(std::string_view word) {
  if (word.empty()) return false;
  for (char c : word) {
    if (!((c >= 'a' && c <= 'z') || c == '-')) return false;
  }
  return true;
}

}  // namespace avp::segmentation::internal

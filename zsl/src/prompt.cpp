// Detector prompt parsing: comma-separated class names, normalised and de-duplicated.
#include "prompt.h"

#include <cstdint>
#include <unordered_set>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/segmentation/segmenter.h>

namespace avp::zsl {
namespace {

bool IsAsciiSpace(char c) {
  return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
}

char AsciiLower(char c) { return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c; }

}  // namespace

std::string NormalizeClassName(std::string_view name) {
  std::string out;
  out.reserve(name.size());
  bool pending_space = false;
  for (const char c : name) {
    if (IsAsciiSpace(c)) {
      pending_space = !out.empty();  // never a leading space
      continue;
    }
    if (pending_space) out.push_back(' ');
    pending_space = false;
    out.push_back(AsciiLower(c));
  }
  return out;  // a trailing space is never written: it stays pending
}

Result<std::vector<std::string>> ParsePromptClasses(std::string_view prompt, size_t max_classes) {
  // The prompt limits of every segmenter (segmentation::SplitPrompt), before anything is copied.
  AVP_RETURN_IF_ERROR(segmentation::MaxPromptBytes().Check("prompt", prompt.size()));
  uint64_t pieces = 0;
  for (size_t begin = 0; begin <= prompt.size();) {
    size_t end = prompt.find(',', begin);
    if (end == std::string_view::npos) end = prompt.size();
    const std::string_view piece = prompt.substr(begin, end - begin);
    if (piece.find_first_not_of(" \t\n\r\f\v") != std::string_view::npos) ++pieces;
    begin = end + 1;
  }
  AVP_RETURN_IF_ERROR(segmentation::MaxPromptPhrases().Check("phrases in the prompt", pieces));
  std::vector<std::string> classes;
  std::unordered_set<std::string> seen;
  size_t begin = 0;
  while (begin <= prompt.size()) {
    size_t end = prompt.find(',', begin);
    if (end == std::string_view::npos) end = prompt.size();
    std::string name = NormalizeClassName(prompt.substr(begin, end - begin));
    if (!name.empty() && seen.insert(name).second) classes.push_back(std::move(name));
    begin = end + 1;
  }
  if (classes.empty()) {
    return InvalidArgumentError(fmt::format(
        "prompt {} has no classes: expected comma-separated names such as 'tomato, leaf'",
        QuoteText(prompt)));
  }
  if (max_classes > 0 && classes.size() > max_classes) {
    return InvalidArgumentError(
        fmt::format("prompt has {} classes; the detector takes at most {} (N_max)", classes.size(),
                    max_classes));
  }
  return classes;
}

}  // namespace avp::zsl

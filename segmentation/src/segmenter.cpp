#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/segmentation/segmenter.h>

namespace avp::segmentation {

namespace {

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
}

/// Calls f(phrase) for each trimmed, non-empty comma-separated piece of `prompt`, in order.
template <typename F>
void ForEachPhrase(std::string_view prompt, F&& f) {
  size_t start = 0;
  while (start <= prompt.size()) {
    size_t end = prompt.find(',', start);
    if (end == std::string_view::npos) end = prompt.size();
    size_t b = start;
    size_t e = end;
    while (b < e && IsSpace(prompt[b])) ++b;
    while (e > b && IsSpace(prompt[e - 1])) --e;
    if (e > b) f(prompt.substr(b, e - b));
    start = end + 1;
  }
}

}  // namespace

const Limit& MaxPromptBytes() {
  static const Limit limit("max_prompt_bytes", 4096, "bytes",
                           "bytes of one segmentation prompt (its comma-separated phrases)");
  return limit;
}

const Limit& MaxPromptPhrases() {
  static const Limit limit("max_prompt_phrases", 64, "phrases",
                           "phrases in one segmentation prompt, duplicates included");
  return limit;
}

Result<std::vector<std::string>> SplitPrompt(std::string_view prompt) {
  AVP_RETURN_IF_ERROR(MaxPromptBytes().Check("prompt", prompt.size()));
  uint64_t count = 0;
  ForEachPhrase(prompt, [&](std::string_view) { ++count; });
  AVP_RETURN_IF_ERROR(MaxPromptPhrases().Check("phrases in the prompt", count));
  std::vector<std::string> phrases;
  phrases.reserve(static_cast<size_t>(count));
  ForEachPhrase(prompt, [&](std::string_view phrase) {
    if (std::find(phrases.begin(), phrases.end(), phrase) == phrases.end()) {
      phrases.emplace_back(phrase);
    }
  });
  if (phrases.empty()) {
    return InvalidArgumentError(
        fmt::format("prompt ({}) has no phrase: expected e.g. \"tomato\" or \"tomato, apple\"",
                    QuoteText(prompt)));
  }
  return phrases;
}

}  // namespace avp::segmentation

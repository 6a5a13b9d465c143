#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/segmentation/segmenter.h>

namespace avp::segmentation {

namespace {

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
}

}  // namespace

Result<std::vector<std::string>> SplitPrompt(std::string_view prompt) {
  std::vector<std::string> phrases;
  size_t start = 0;
  while (start <= prompt.size()) {
    size_t end = prompt.find(',', start);
    if (end == std::string_view::npos) end = prompt.size();
    size_t b = start;
    size_t e = end;
    while (b < e && IsSpace(prompt[b])) ++b;
    while (e > b && IsSpace(prompt[e - 1])) --e;
    if (e > b) phrases.emplace_back(prompt.substr(b, e - b));
    start = end + 1;
  }
  if (phrases.empty()) {
    return InvalidArgumentError(fmt::format(
        "prompt (\"{}\") has no phrase: expected e.g. \"tomato\" or \"tomato, apple\"", prompt));
  }
  return phrases;
}

}  // namespace avp::segmentation

#include <algorithm>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/segmentation/color_segmenter.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/segmentation/segmenter.h>

namespace avp::segmentation {

namespace {

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
}

struct Registry {
  std::mutex mutex;
  std::map<std::string, SegmenterFactory, std::less<>> factories;
};

Registry& GetRegistry() {
  static Registry registry;
  return registry;
}

bool IsScheme(std::string_view name) {
  return name.size() >= 3 && name.substr(name.size() - 3) == "://";
}

SegmenterFactory FindFactory(std::string_view spec) {
  Registry& registry = GetRegistry();
  std::lock_guard lock(registry.mutex);
  for (const auto& [key, f] : registry.factories) {
    if (key == spec || (IsScheme(key) && spec.substr(0, key.size()) == key)) return f;
  }
  return {};
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

const std::vector<std::string>& SegmenterNames() {
  static const std::vector<std::string> kNames = {"oracle", "oracle-perfect", "color"};
  return kNames;
}

Result<std::unique_ptr<Segmenter>> MakeSegmenter(std::string_view name, uint64_t seed) {
  if (name == "oracle") {
    return std::unique_ptr<Segmenter>(std::make_unique<OracleSegmenter>(OracleOptions{}, seed));
  }
  if (name == "oracle-perfect") {
    return std::unique_ptr<Segmenter>(
        std::make_unique<OracleSegmenter>(OracleOptions::Perfect(), seed));
  }
  if (name == "color") return std::unique_ptr<Segmenter>(std::make_unique<ColorSegmenter>());
  if (SegmenterFactory factory = FindFactory(name)) return factory(name, seed);
  return NotFoundError(fmt::format("unknown segmenter \"{}\"; known: {}", name,
                                   fmt::join(KnownSegmenterSpecs(), ", ")));
}

bool IsKnownSegmenter(std::string_view spec) {
  const auto& builtin = SegmenterNames();
  if (std::find(builtin.begin(), builtin.end(), spec) != builtin.end()) return true;
  return static_cast<bool>(FindFactory(spec));
}

std::vector<std::string> KnownSegmenterSpecs() {
  std::vector<std::string> known = SegmenterNames();
  for (std::string& n : RegisteredSegmenterNames()) known.push_back(IsScheme(n) ? n + "..." : n);
  return known;
}

void RegisterSegmenterFactory(std::string name, SegmenterFactory factory) {
  Registry& registry = GetRegistry();
  std::lock_guard lock(registry.mutex);
  registry.factories[std::move(name)] = std::move(factory);
}

std::vector<std::string> RegisteredSegmenterNames() {
  Registry& registry = GetRegistry();
  std::lock_guard lock(registry.mutex);
  std::vector<std::string> names;
  for (const auto& entry : registry.factories) names.push_back(entry.first);
  return names;
}

}  // namespace avp::segmentation

#include <avp/core/semantic_class.h>

namespace avp {

namespace {
constexpr std::array<std::string_view, kNumSemanticClasses> kNames = {
    "background", "fruit", "leaf", "stem", "support", "ground", "other"};
}  // namespace

std::string_view ToString(SemanticClass c) {
  const auto i = static_cast<size_t>(c);
  return i < kNames.size() ? kNames[i] : std::string_view("invalid");
}

std::optional<SemanticClass> SemanticClassFromString(std::string_view name) {
  for (size_t i = 0; i < kNames.size(); ++i) {
    if (kNames[i] == name) return static_cast<SemanticClass>(i);
  }
  return std::nullopt;
}

const std::array<SemanticClass, kNumSemanticClasses>& AllSemanticClasses() {
  static const std::array<SemanticClass, kNumSemanticClasses> all = {
      SemanticClass::kBackground, SemanticClass::kFruit,   SemanticClass::kLeaf,
      SemanticClass::kStem,       SemanticClass::kSupport, SemanticClass::kGround,
      SemanticClass::kOther};
  return all;
}

}  // namespace avp

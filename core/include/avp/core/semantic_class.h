#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>

namespace avp {

/// Semantic classes shared by the simulator, segmentation, the map and evaluation. The numeric
/// values are written into class label images and map files: append, never renumber.
enum class SemanticClass : uint8_t {
  kBackground = 0,  ///< nothing / sky / out of range
  kFruit = 1,       ///< the target organ (tomato, apple, ...)
  kLeaf = 2,
  kStem = 3,     ///< main stem, branches, cordons, petioles, peduncles
  kSupport = 4,  ///< stakes, wires, posts, pots
  kGround = 5,   ///< floor, soil, table
  kOther = 6,    ///< anything else in the scene (walls, robot base, ...)
};

inline constexpr int kNumSemanticClasses = 7;

/// "background", "fruit", "leaf", "stem", "support", "ground", "other".
std::string_view ToString(SemanticClass c);
/// Inverse of ToString (case-sensitive); nullopt for unknown names.
std::optional<SemanticClass> SemanticClassFromString(std::string_view name);
/// All classes in numeric order.
const std::array<SemanticClass, kNumSemanticClasses>& AllSemanticClasses();

}  // namespace avp

#pragma once

#include <array>
#include <cstdint>
#include <type_traits>

#include <avp/core/semantic_class.h>

namespace avp::mapping {

/// Fixed-point scale of SemanticCell::class_log_odds: stored = round(log_odds *
/// kClassLogOddsScale).
inline constexpr float kClassLogOddsScale = 1024.0f;

/// The semantic evidence of one voxel. Every fusion policy keeps `semantic_class`, `confidence`,
/// `instance_id` and `observations` meaningful, so readers (planner, evaluation, exports) never
/// need to know which policy wrote them; `class_log_odds` is the Bayesian policy's state.
struct SemanticCell {
  /// Fused class (SemanticClass value); kBackground (0) means "no semantic label".
  uint8_t semantic_class = 0;
  /// Bits 0-1: consecutive frames another instance has claimed this voxel (instance association,
  /// see docs/mapping-semantics.md); bits 2-7 reserved (0).
  uint8_t flags = 0;
  /// Fruit instance the voxel belongs to; 0 = none.
  uint16_t instance_id = 0;
  /// Frames in which a mask covered the voxel (saturates at 65535).
  uint16_t observations = 0;
  /// Frames in which the voxel was an endpoint outside every mask (negative evidence).
  uint16_t misses = 0;
  /// Confidence of `semantic_class` in [0, 1]: the reference's fused score, or the Bayesian
  /// posterior probability of the class.
  float confidence = 0.0f;
  /// Bayesian policy: log-odds of each class against background, in units of
  /// 1 / kClassLogOddsScale (index 0, background, stays 0).
  std::array<int16_t, kNumSemanticClasses> class_log_odds{};

  SemanticClass cls() const { return static_cast<SemanticClass>(semantic_class); }
  bool has_label() const { return semantic_class != 0; }
  bool operator==(const SemanticCell&) const = default;
};

static_assert(std::is_trivially_copyable_v<SemanticCell>);
static_assert(sizeof(SemanticCell) <= 32);

}  // namespace avp::mapping

#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>

namespace avp::zsl {

/// The canonical form of one class name, used as the text-embedding cache key: leading and trailing
/// ASCII whitespace removed, inner runs of ASCII whitespace collapsed to one space, ASCII letters
/// lower-cased. Non-ASCII bytes are kept as they are (no Unicode case mapping or normalisation).
///   NormalizeClassName("  Red   Tomato\t") == "red tomato"
std::string NormalizeClassName(std::string_view name);

/// Splits a detector prompt such as "Tomato, leaf , stem,tomato" into class names: split at commas,
/// NormalizeClassName each piece, drop empty pieces and keep only the first occurrence of each name
/// (in prompt order): {"tomato", "leaf", "stem"}.
///
/// `max_classes` is the detector's fixed class count N_max (0 = no detector limit).
/// Errors: ResourceExhausted, before anything is copied, when the prompt is longer than the
/// process-wide max_prompt_bytes or has more phrases (duplicates included) than
/// max_prompt_phrases (segmentation::MaxPromptBytes / MaxPromptPhrases, as SplitPrompt);
/// InvalidArgument when the prompt yields no class (the message quotes the prompt, escaped and
/// shortened), or more than `max_classes` classes remain after de-duplication ("prompt has 40
/// classes; the detector takes at most 32 (N_max)").
Result<std::vector<std::string>> ParsePromptClasses(std::string_view prompt,
                                                    size_t max_classes = 0);

}  // namespace avp::zsl

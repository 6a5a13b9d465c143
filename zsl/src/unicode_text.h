#pragma once
// Internal to avp_zsl (not installed): UTF-8 and PCRE2 helpers shared by the CLIP and WordPiece
// tokenizers.

#ifndef PCRE2_CODE_UNIT_WIDTH
#define PCRE2_CODE_UNIT_WIDTH 8
#endif

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <pcre2.h>

namespace avp::zsl::internal {

/// Appends the UTF-8 encoding of `cp` (a Unicode scalar value) to `out`.
void AppendUtf8(std::string& out, char32_t cp);

/// Length of the valid UTF-8 sequence that starts at `s[i]`, or 0 when it is not one (stray
/// continuation bytes, overlong forms, surrogates and code points above U+10FFFF are invalid).
size_t ValidUtf8Length(std::string_view s, size_t i);

/// `s` with every byte that does not start a valid UTF-8 sequence replaced by U+FFFD.
std::string SanitizeUtf8(std::string_view s);

/// The code point of the valid UTF-8 sequence at `s[i]`; advances `i` past it.
/// @pre `s` is valid UTF-8 (see SanitizeUtf8) and i < s.size().
char32_t DecodeUtf8(std::string_view s, size_t& i);

struct Pcre2CodeDeleter {
  void operator()(pcre2_code* code) const { pcre2_code_free(code); }
};
using Pcre2Code = std::unique_ptr<pcre2_code, Pcre2CodeDeleter>;

/// Compiles `pattern` with PCRE2_UTF | PCRE2_UCP | `options`. The patterns are constants of this
/// module, so a failure is a bug: throws avp::Error naming the pattern and PCRE2's message.
Pcre2Code CompileRegex(std::string_view pattern, uint32_t options = 0);

/// Every match of `code` in `subject` (valid UTF-8), left to right, as findall does; characters
/// between matches are skipped. @pre no alternative of the pattern matches the empty string.
std::vector<std::string_view> FindAll(const pcre2_code* code, std::string_view subject);

/// Replaces every match of `code` in `subject` (valid UTF-8) with `replacement` (pcre2_substitute
/// with PCRE2_SUBSTITUTE_GLOBAL | `options`).
std::string Substitute(const pcre2_code* code, std::string_view subject,
                       std::string_view replacement, uint32_t options = 0);

/// Unicode lower-casing of valid UTF-8, close to Python's `str.lower()`: upper- and title-case
/// letters (`\p{Lu}`, `\p{Lt}`) take their lower-case form from PCRE2's tables, U+0130 becomes
/// "i" + U+0307, and a capital sigma becomes the final sigma U+03C2 under Unicode's Final_Sigma
/// condition (at most three case-ignorable characters are looked through before it; "cased" means
/// Lu, Ll or Lt). Other characters with a lower-case mapping (Roman numerals, circled letters)
/// stay as they are.
std::string LowerCase(std::string_view s);

}  // namespace avp::zsl::internal

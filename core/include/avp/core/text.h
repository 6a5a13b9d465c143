#pragma once

// Text from outside (a file's contents, a request, a command line) shown in messages: escaped so
// that it cannot reach the terminal as control characters, and shortened so that a crafted
// 300-digit number or a megabyte-long line does not flood the log (docs/limits.md).

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace avp {

/// At most this many characters of outside text in a message by default.
inline constexpr size_t kQuotedTextMaxChars = 64;

/// `text` escaped for a message: printable ASCII kept, `\n \r \t \\ \'` as C escapes, every other
/// byte below 0x20, 0x7f and above as \xNN (so invalid UTF-8 and escape sequences are harmless),
/// cut after `max_chars` input bytes with "...(N bytes)" giving the full length. No quotes added.
std::string EscapeText(std::string_view text, size_t max_chars = kQuotedTextMaxChars);

/// EscapeText in single quotes: "'abc\x1b[2J...(300 bytes)'".
std::string QuoteText(std::string_view text, size_t max_chars = kQuotedTextMaxChars);

/// The name of `known` nearest to `name` (case-insensitive edit distance, a swap of two
/// neighbouring letters counting once) when it is close enough to be a slip of the keyboard: at
/// most 1 edit for names of up to 4 letters, 2 up to 8, else a quarter of the length; ties go to
/// the earlier name. Empty when none is, or `name` is itself known.
std::string NearestName(std::string_view name, const std::vector<std::string>& known);

/// "; did you mean 'x'?" for NearestName, or "" (appended to "unknown ..." messages).
std::string DidYouMean(std::string_view name, const std::vector<std::string>& known);

}  // namespace avp

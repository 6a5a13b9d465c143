#pragma once

// Text from outside (a file's contents, a request, a command line) shown in messages: escaped so
// that it cannot reach the terminal as control characters, and shortened so that a crafted
// 300-digit number or a megabyte-long line does not flood the log (docs/limits.md).

#include <cstddef>
#include <string>
#include <string_view>

namespace avp {

/// At most this many characters of outside text in a message by default.
inline constexpr size_t kQuotedTextMaxChars = 64;

/// `text` escaped for a message: printable ASCII kept, `\n \r \t \\ \'` as C escapes, every other
/// byte below 0x20, 0x7f and above as \xNN (so invalid UTF-8 and escape sequences are harmless),
/// cut after `max_chars` input bytes with "...(N bytes)" giving the full length. No quotes added.
std::string EscapeText(std::string_view text, size_t max_chars = kQuotedTextMaxChars);

/// EscapeText in single quotes: "'abc\x1b[2J...(300 bytes)'".
std::string QuoteText(std::string_view text, size_t max_chars = kQuotedTextMaxChars);

}  // namespace avp

#include <fmt/format.h>

#include <avp/core/text.h>

namespace avp {

std::string EscapeText(std::string_view text, size_t max_chars) {
  const size_t shown = text.size() < max_chars ? text.size() : max_chars;
  std::string out;
  out.reserve(shown + 16);
  for (size_t i = 0; i < shown; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    switch (c) {
      case '\n':
        out += "\\n";
        break;
      case '\r':
        out += "\\r";
        break;
      case '\t':
        out += "\\t";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\'':
        out += "\\'";
        break;
      default:
        if (c < 0x20 || c >= 0x7f) {
          out += fmt::format("\\x{:02x}", c);
        } else {
          out += static_cast<char>(c);
        }
    }
  }
  if (shown < text.size()) out += fmt::format("...({} bytes)", text.size());
  return out;
}

std::string QuoteText(std::string_view text, size_t max_chars) {
  std::string out(1, '\'');
  out += EscapeText(text, max_chars);
  out += '\'';
  return out;
}

}  // namespace avp

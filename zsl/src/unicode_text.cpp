// UTF-8 and PCRE2 helpers shared by the tokenizers.
#include "unicode_text.h"

#include <array>

#include <fmt/format.h>

#include <avp/core/error.h>

namespace avp::zsl::internal {
namespace {

struct Pcre2MatchDataDeleter {
  void operator()(pcre2_match_data* data) const { pcre2_match_data_free(data); }
};
using Pcre2MatchData = std::unique_ptr<pcre2_match_data, Pcre2MatchDataDeleter>;

}  // namespace

void AppendUtf8(std::string& out, char32_t cp) {
  if (cp < 0x80) {
    out.push_back(static_cast<char>(cp));
  } else if (cp < 0x800) {
    out.push_back(static_cast<char>(0xC0 | (cp >> 6)));
    out.push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else if (cp < 0x10000) {
    out.push_back(static_cast<char>(0xE0 | (cp >> 12)));
    out.push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out.push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else {
    out.push_back(static_cast<char>(0xF0 | (cp >> 18)));
    out.push_back(static_cast<char>(0x80 | ((cp >> 12) & 0x3F)));
    out.push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out.push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  }
}

size_t ValidUtf8Length(std::string_view s, size_t i) {
  const auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char b0 = byte(i);
  if (b0 < 0x80) return 1;
  size_t length = 0;
  unsigned char lo = 0x80, hi = 0xBF;  // the allowed range of the second byte
  if (b0 >= 0xC2 && b0 <= 0xDF) {
    length = 2;
  } else if (b0 >= 0xE0 && b0 <= 0xEF) {
    length = 3;
    if (b0 == 0xE0) lo = 0xA0;  // overlong
    if (b0 == 0xED) hi = 0x9F;  // surrogates
  } else if (b0 >= 0xF0 && b0 <= 0xF4) {
    length = 4;
    if (b0 == 0xF0) lo = 0x90;  // overlong
    if (b0 == 0xF4) hi = 0x8F;  // above U+10FFFF
  } else {
    return 0;
  }
  if (i + length > s.size()) return 0;
  if (byte(i + 1) < lo || byte(i + 1) > hi) return 0;
  for (size_t k = 2; k < length; ++k) {
    if (byte(i + k) < 0x80 || byte(i + k) > 0xBF) return 0;
  }
  return length;
}

std::string SanitizeUtf8(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (size_t i = 0; i < s.size();) {
    const size_t length = ValidUtf8Length(s, i);
    if (length == 0) {
      AppendUtf8(out, 0xFFFD);
      ++i;
    } else {
      out.append(s.substr(i, length));
      i += length;
    }
  }
  return out;
}

char32_t DecodeUtf8(std::string_view s, size_t& i) {
  const auto byte = [&](size_t k) {
    return static_cast<char32_t>(static_cast<unsigned char>(s[k]));
  };
  const char32_t b0 = byte(i);
  if (b0 < 0x80) {
    i += 1;
    return b0;
  }
  if (b0 < 0xE0) {
    const char32_t cp = ((b0 & 0x1F) << 6) | (byte(i + 1) & 0x3F);
    i += 2;
    return cp;
  }
  if (b0 < 0xF0) {
    const char32_t cp = ((b0 & 0x0F) << 12) | ((byte(i + 1) & 0x3F) << 6) | (byte(i + 2) & 0x3F);
    i += 3;
    return cp;
  }
  const char32_t cp = ((b0 & 0x07) << 18) | ((byte(i + 1) & 0x3F) << 12) |
                      ((byte(i + 2) & 0x3F) << 6) | (byte(i + 3) & 0x3F);
  i += 4;
  return cp;
}

Pcre2Code CompileRegex(std::string_view pattern, uint32_t options) {
  int error = 0;
  PCRE2_SIZE offset = 0;
  pcre2_code* code = pcre2_compile(reinterpret_cast<PCRE2_SPTR>(pattern.data()), pattern.size(),
                                   options | PCRE2_UTF | PCRE2_UCP, &error, &offset, nullptr);
  if (code == nullptr) {
    std::array<PCRE2_UCHAR, 256> buffer{};
    pcre2_get_error_message(error, buffer.data(), buffer.size());
    const std::string message(reinterpret_cast<const char*>(buffer.data()));
    AVP_THROW_UNLESS(code != nullptr, pattern, offset, message);
  }
  return Pcre2Code(code);
}

std::vector<std::string_view> FindAll(const pcre2_code* code, std::string_view subject) {
  std::vector<std::string_view> matches;
  const Pcre2MatchData match(pcre2_match_data_create_from_pattern(code, nullptr));
  AVP_THROW_UNLESS(match != nullptr, "pcre2_match_data_create_from_pattern failed");
  const auto* data = reinterpret_cast<PCRE2_SPTR>(subject.data());
  size_t offset = 0;
  while (offset < subject.size()) {
    const int rc =
        pcre2_match(code, data, subject.size(), offset, PCRE2_NO_UTF_CHECK, match.get(), nullptr);
    if (rc == PCRE2_ERROR_NOMATCH) break;
    AVP_THROW_UNLESS(rc > 0, rc);
    const PCRE2_SIZE* ovector = pcre2_get_ovector_pointer(match.get());
    const size_t begin = ovector[0];
    const size_t end = ovector[1];
    AVP_THROW_UNLESS(end > begin, begin, end);
    matches.push_back(subject.substr(begin, end - begin));
    offset = end;
  }
  return matches;
}

std::string Substitute(const pcre2_code* code, std::string_view subject,
                       std::string_view replacement, uint32_t options) {
  const uint32_t flags =
      options | PCRE2_SUBSTITUTE_GLOBAL | PCRE2_SUBSTITUTE_OVERFLOW_LENGTH | PCRE2_NO_UTF_CHECK;
  std::string out(subject.size() + 16, '\0');
  for (int attempt = 0; attempt < 2; ++attempt) {
    PCRE2_SIZE length = out.size();
    const int rc =
        pcre2_substitute(code, reinterpret_cast<PCRE2_SPTR>(subject.data()), subject.size(), 0,
                         flags, nullptr, nullptr, reinterpret_cast<PCRE2_SPTR>(replacement.data()),
                         replacement.size(), reinterpret_cast<PCRE2_UCHAR*>(out.data()), &length);
    if (rc >= 0) {
      out.resize(length);
      return out;
    }
    AVP_THROW_UNLESS(rc == PCRE2_ERROR_NOMEMORY && attempt == 0, rc, attempt);
    out.assign(length, '\0');  // `length` is now the size needed
  }
  return out;  // not reached
}

std::string LowerCase(std::string_view s) {
  static const Pcre2Code kDottedCapitalI = CompileRegex(R"(\x{130})");
  // Unicode's Final_Sigma condition: a cased letter before (up to three case-ignorable characters
  // between, as a lookbehind needs a bounded length) and none after.
  static const Pcre2Code kFinalSigma = [] {
    const std::string cased = R"([\p{Lu}\p{Ll}\p{Lt}])";
    const std::string ignorable =
        R"([\p{Mn}\p{Me}\p{Cf}\p{Lm}\p{Sk}'.:\x{B7}\x{387}\x{55F}\x{5F4}\x{2018}\x{2019}\x{2024})"
        R"(\x{2027}\x{FE13}\x{FE52}\x{FE55}\x{FF07}\x{FF0E}\x{FF1A}])";
    return CompileRegex("(?<=" + cased + "|" + cased + ignorable + "|" + cased + ignorable +
                        ignorable + "|" + cased + ignorable + ignorable + ignorable +
                        R"()\x{3A3}(?!)" + ignorable + "*" + cased + ")");
  }();
  static const Pcre2Code kUpper = CompileRegex(R"(\p{Lu}+|\p{Lt}+)");
  std::string out = Substitute(kDottedCapitalI.get(), s, "i\xCC\x87");
  out = Substitute(kFinalSigma.get(), out, "\xCF\x82");  // U+03C2 final sigma
  return Substitute(kUpper.get(), out, "\\L$0", PCRE2_SUBSTITUTE_EXTENDED);
}

}  // namespace avp::zsl::internal

#include <algorithm>
#include <vector>

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

namespace {

char Lower(char c) { return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c; }

/// Optimal string alignment distance (Levenshtein plus adjacent transpositions), case-insensitive.
size_t EditDistance(std::string_view a, std::string_view b) {
  const size_t n = a.size(), m = b.size();
  std::vector<std::vector<size_t>> d(n + 1, std::vector<size_t>(m + 1, 0));
  for (size_t i = 0; i <= n; ++i) d[i][0] = i;
  for (size_t j = 0; j <= m; ++j) d[0][j] = j;
  for (size_t i = 1; i <= n; ++i) {
    for (size_t j = 1; j <= m; ++j) {
      const size_t cost = Lower(a[i - 1]) == Lower(b[j - 1]) ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && Lower(a[i - 1]) == Lower(b[j - 2]) &&
          Lower(a[i - 2]) == Lower(b[j - 1])) {
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
      }
    }
  }
  return d[n][m];
}

}  // namespace

std::string NearestName(std::string_view name, const std::vector<std::string>& known) {
  // Outside text may be long: a name far longer than any known one is no slip.
  if (name.empty() || name.size() > 256) return "";
  const size_t allowed = name.size() <= 4 ? 1 : name.size() <= 8 ? 2 : name.size() / 4;
  std::string best;
  size_t best_distance = allowed + 1;
  for (const std::string& k : known) {
    if (k == name) return "";
    if (k.size() > name.size() + allowed || name.size() > k.size() + allowed) continue;
    const size_t d = EditDistance(name, k);
    if (d < best_distance) {
      best_distance = d;
      best = k;
    }
  }
  return best;
}

std::string DidYouMean(std::string_view name, const std::vector<std::string>& known) {
  const std::string nearest = NearestName(name, known);
  return nearest.empty() ? "" : "; did you mean '" + nearest + "'?";
}

}  // namespace avp

// OpenAI CLIP's byte-level BPE tokenizer, written from the rules in zero-shot-models.md §4.2.
#include "clip_tokenizer.h"

#include <algorithm>
#include <array>
#include <limits>
#include <mutex>
#include <unordered_map>

#include <fmt/format.h>
#include <zlib.h>

#include <avp/core/error.h>

#include "unicode_text.h"

namespace avp::zsl {
namespace {

using internal::AppendUtf8;
using internal::CompileRegex;
using internal::Pcre2Code;
using internal::Substitute;

constexpr std::string_view kEndOfWord = "</w>";
constexpr std::string_view kStartOfText = "<|startoftext|>";
constexpr std::string_view kEndOfText = "<|endoftext|>";
/// The per-piece BPE cache is cleared when it grows past this many pieces (bounds memory on
/// adversarial input; prompts repeat a few hundred words at most).
constexpr size_t kMaxCachedPieces = 100000;
/// The characters `\s` of Python's `regex` module matches (CLIP's whitespace_clean), as the body
/// of a PCRE2 character class. PCRE2's own `\s` differs: it adds U+180E.
constexpr const char* kWhitespace =
    R"(\t\n\x{0B}\f\r \x{85}\x{A0}\x{1680}\x{2000}-\x{200A}\x{2028}\x{2029}\x{202F}\x{205F}\x{3000})";

/// One pass of HTML unescaping for the common named entities and numeric character references;
/// anything else (including entities without ';') is copied unchanged.
std::string HtmlUnescapeOnce(std::string_view s) {
  static constexpr std::array<std::pair<std::string_view, std::string_view>, 6> kNamed = {{
      {"amp", "&"},
      {"lt", "<"},
      {"gt", ">"},
      {"quot", "\""},
      {"apos", "'"},
      {"nbsp", "\xC2\xA0"},
  }};
  std::string out;
  out.reserve(s.size());
  size_t i = 0;
  while (i < s.size()) {
    if (s[i] != '&') {
      out.push_back(s[i++]);
      continue;
    }
    const size_t semi = s.find(';', i + 1);
    if (semi == std::string_view::npos || semi - i > 12) {
      out.push_back(s[i++]);
      continue;
    }
    const std::string_view name = s.substr(i + 1, semi - i - 1);
    bool replaced = false;
    if (name.size() >= 2 && name[0] == '#') {
      const bool hex = name[1] == 'x' || name[1] == 'X';
      const std::string_view digits = name.substr(hex ? 2 : 1);
      uint64_t cp = 0;
      bool ok = !digits.empty();
      for (const char c : digits) {
        int d = -1;
        if (c >= '0' && c <= '9') d = c - '0';
        if (hex && c >= 'a' && c <= 'f') d = c - 'a' + 10;
        if (hex && c >= 'A' && c <= 'F') d = c - 'A' + 10;
        if (d < 0) {
          ok = false;
          break;
        }
        cp = std::min<uint64_t>(cp * (hex ? 16 : 10) + static_cast<uint64_t>(d), 0x110000);
      }
      if (ok) {
        const bool valid = cp != 0 && cp < 0x110000 && !(cp >= 0xD800 && cp <= 0xDFFF);
        AppendUtf8(out, valid ? static_cast<char32_t>(cp) : char32_t{0xFFFD});
        replaced = true;
      }
    } else {
      for (const auto& [entity, text] : kNamed) {
        if (name == entity) {
          out.append(text);
          replaced = true;
          break;
        }
      }
    }
    if (replaced) {
      i = semi + 1;
    } else {
      out.push_back(s[i++]);
    }
  }
  return out;
}

/// GPT-2's `bytes_to_unicode`: the printable bytes '!'..'~', U+00A1..U+00AC and U+00AE..U+00FF
/// stand for themselves; the other 68 bytes map, in ascending order, to U+0100, U+0101, ...
/// `order` lists the bytes in vocabulary order (the printable ones first).
struct ByteTable {
  std::array<std::string, 256> symbol;  // UTF-8 of the character standing for each byte
  std::array<uint8_t, 256> order{};
};

ByteTable MakeByteTable() {
  ByteTable table;
  std::array<bool, 256> printable{};
  size_t n = 0;
  for (int b = 0; b < 256; ++b) {
    printable[b] = (b >= '!' && b <= '~') || (b >= 0xA1 && b <= 0xAC) || (b >= 0xAE && b <= 0xFF);
    if (printable[b]) {
      AppendUtf8(table.symbol[b], static_cast<char32_t>(b));
      table.order[n++] = static_cast<uint8_t>(b);
    }
  }
  char32_t next = 0x100;
  for (int b = 0; b < 256; ++b) {
    if (printable[b]) continue;
    AppendUtf8(table.symbol[b], next++);
    table.order[n++] = static_cast<uint8_t>(b);
  }
  return table;
}

struct PairHash {
  size_t operator()(const std::pair<std::string, std::string>& p) const {
    const size_t h1 = std::hash<std::string>()(p.first);
    const size_t h2 = std::hash<std::string>()(p.second);
    return h1 ^ (h2 + 0x9E3779B97F4A7C15ull + (h1 << 6) + (h1 >> 2));
  }
};

}  // namespace

struct ClipTokenizer::Impl {
  ByteTable bytes;
  std::unordered_map<std::string, int32_t> encoder;
  std::unordered_map<std::pair<std::string, std::string>, int32_t, PairHash> ranks;
  int32_t sot = 0;
  int32_t eot = 0;
  size_t vocab_size = 0;

  // Python's whitespace: `\s` of the `regex` module, plus U+001C..U+001F for str.strip().
  Pcre2Code strip_re = CompileRegex(std::string("^[") + kWhitespace + R"(\x{1C}-\x{1F}]+|[)" +
                                    kWhitespace + R"(\x{1C}-\x{1F}]+\z)");
  Pcre2Code whitespace_re = CompileRegex(std::string("[") + kWhitespace + "]+");
  // CLIP's pre-tokenizer pattern (case-insensitive, as in simple_tokenizer.py).
  Pcre2Code split_re = CompileRegex(
      std::string(R"(<\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|\p{L}+|\p{N}|[^)") +
          kWhitespace + R"(\p{L}\p{N}]+)",
      PCRE2_CASELESS);

  mutable std::mutex cache_mutex;
  mutable std::unordered_map<std::string, std::vector<int32_t>> cache;

  std::string Clean(std::string_view text) const;
  std::vector<int32_t> EncodePiece(std::string_view piece) const;
  std::vector<int32_t> Bpe(std::string_view piece) const;
};

std::string ClipTokenizer::Impl::Clean(std::string_view text) const {
  std::string s = internal::SanitizeUtf8(text);
  s = HtmlUnescapeOnce(HtmlUnescapeOnce(s));  // CLIP unescapes twice ("&amp;lt;" -> "<")
  s = Substitute(strip_re.get(), s, "");      // str.strip()
  s = Substitute(whitespace_re.get(), s, " ");
  return internal::LowerCase(s);
}

std::vector<int32_t> ClipTokenizer::Impl::Bpe(std::string_view piece) const {
  // One symbol per byte; the last one carries the end-of-word marker.
  std::vector<std::string> word;
  word.reserve(piece.size());
  for (const char c : piece) word.push_back(bytes.symbol[static_cast<unsigned char>(c)]);
  if (word.empty()) return {};
  word.back() += kEndOfWord;

  std::pair<std::string, std::string> key;
  while (word.size() > 1) {
    // The adjacent pair with the lowest rank; stop when no pair is ranked.
    int32_t best_rank = std::numeric_limits<int32_t>::max();
    size_t best = word.size();
    for (size_t i = 0; i + 1 < word.size(); ++i) {
      key.first = word[i];
      key.second = word[i + 1];
      const auto it = ranks.find(key);
      if (it != ranks.end() && it->second < best_rank) {
        best_rank = it->second;
        best = i;
      }
    }
    if (best == word.size()) break;
    const std::string first = word[best];
    const std::string second = word[best + 1];
    // Merge every non-overlapping occurrence of the pair, scanning left to right.
    std::vector<std::string> merged;
    merged.reserve(word.size());
    for (size_t i = 0; i < word.size();) {
      if (i + 1 < word.size() && word[i] == first && word[i + 1] == second) {
        merged.push_back(first + second);
        i += 2;
      } else {
        merged.push_back(std::move(word[i]));
        ++i;
      }
    }
    word = std::move(merged);
  }

  std::vector<int32_t> ids;
  ids.reserve(word.size());
  for (const std::string& symbol : word) {
    const auto it = encoder.find(symbol);
    // Every symbol is a byte symbol, a byte symbol + </w> or a merge result: all are in the vocab.
    AVP_THROW_UNLESS(it != encoder.end(), symbol);
    ids.push_back(it->second);
  }
  return ids;
}

std::vector<int32_t> ClipTokenizer::Impl::EncodePiece(std::string_view piece) const {
  const std::string key(piece);
  {
    std::lock_guard<std::mutex> lock(cache_mutex);
    const auto it = cache.find(key);
    if (it != cache.end()) return it->second;
  }
  std::vector<int32_t> ids = Bpe(piece);
  std::lock_guard<std::mutex> lock(cache_mutex);
  if (cache.size() >= kMaxCachedPieces) cache.clear();
  cache.emplace(key, ids);
  return ids;
}

ClipTokenizer::ClipTokenizer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ClipTokenizer::ClipTokenizer(ClipTokenizer&&) noexcept = default;
ClipTokenizer& ClipTokenizer::operator=(ClipTokenizer&&) noexcept = default;
ClipTokenizer::~ClipTokenizer() = default;

Result<ClipTokenizer> ClipTokenizer::FromMerges(
    std::vector<std::pair<std::string, std::string>> merges) {
  auto impl = std::make_unique<Impl>();
  impl->bytes = MakeByteTable();

  // CLIP's vocabulary list, in order; a string listed twice keeps its later id (a Python dict).
  std::vector<std::string> vocab;
  vocab.reserve(512 + merges.size() + 2);
  for (const uint8_t b : impl->bytes.order) vocab.push_back(impl->bytes.symbol[b]);
  for (const uint8_t b : impl->bytes.order) {
    vocab.push_back(impl->bytes.symbol[b] + std::string(kEndOfWord));
  }
  for (size_t rank = 0; rank < merges.size(); ++rank) {
    auto& [first, second] = merges[rank];
    if (first.empty() || second.empty()) {
      return InvalidArgumentError(
          fmt::format("CLIP merge {} ('{}' '{}') has an empty symbol", rank, first, second));
    }
    vocab.push_back(first + second);
    impl->ranks[std::move(merges[rank])] = static_cast<int32_t>(rank);
  }
  vocab.emplace_back(kStartOfText);
  vocab.emplace_back(kEndOfText);
  impl->encoder.reserve(vocab.size());
  for (size_t id = 0; id < vocab.size(); ++id) {
    impl->encoder[vocab[id]] = static_cast<int32_t>(id);
  }
  impl->vocab_size = vocab.size();
  impl->sot = impl->encoder.at(std::string(kStartOfText));
  impl->eot = impl->encoder.at(std::string(kEndOfText));

  return ClipTokenizer(std::move(impl));
}

Result<ClipTokenizer> ClipTokenizer::FromMergesFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    return NotFoundError(fmt::format("CLIP merges file '{}' not found", path.string()));
  }
  // gzopen reads gzip data and, transparently, plain files.
  gzFile file = gzopen(path.c_str(), "rb");
  if (file == nullptr) {
    return IoError(fmt::format("cannot open CLIP merges file '{}'", path.string()));
  }
  std::string text;
  std::array<char, 1 << 16> buffer{};
  int n = 0;
  while ((n = gzread(file, buffer.data(), static_cast<unsigned>(buffer.size()))) > 0) {
    text.append(buffer.data(), static_cast<size_t>(n));
  }
  int gz_error = Z_OK;
  const std::string gz_message = gzerror(file, &gz_error);
  const int close_rc = gzclose_r(file);
  if (n < 0 || gz_error != Z_OK || close_rc != Z_OK) {
    return IoError(fmt::format("cannot read CLIP merges file '{}': {}", path.string(),
                               gz_error != Z_OK ? gz_message : "corrupt or truncated gzip data"));
  }
  if (text.empty()) {
    return ParseError(
        fmt::format("CLIP merges file '{}' is empty: expected a header line and one merge per line",
                    path.string()));
  }

  std::vector<std::pair<std::string, std::string>> merges;
  size_t pos = text.find('\n');  // line 1 is the header
  size_t line_number = 1;
  while (pos != std::string::npos && merges.size() < kClipMergeCount) {
    const size_t begin = pos + 1;
    const size_t end = std::min(text.find('\n', begin), text.size());
    pos = end < text.size() ? end : std::string::npos;
    ++line_number;
    std::string_view line(text.data() + begin, end - begin);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line.empty() && end == text.size()) break;  // the final newline
    // Two fields separated by spaces or tabs.
    std::vector<std::string_view> fields;
    size_t i = 0;
    while (i < line.size() && fields.size() <= 2) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
      if (i == line.size()) break;
      size_t j = i;
      while (j < line.size() && line[j] != ' ' && line[j] != '\t') ++j;
      fields.push_back(line.substr(i, j - i));
      i = j;
    }
    if (fields.size() != 2) {
      return ParseError(fmt::format(
          "CLIP merges file '{}' line {}: expected two symbols separated by a space, got '{}'",
          path.string(), line_number, line));
    }
    merges.emplace_back(std::string(fields[0]), std::string(fields[1]));
  }
  return FromMerges(std::move(merges));
}

std::vector<int32_t> ClipTokenizer::Encode(std::string_view text) const {
  const std::string cleaned = impl_->Clean(text);
  std::vector<int32_t> ids;
  for (const std::string_view piece : internal::FindAll(impl_->split_re.get(), cleaned)) {
    if (piece == kStartOfText || piece == kEndOfText) continue;  // injected special tokens
    const std::vector<int32_t> piece_ids = impl_->EncodePiece(piece);
    ids.insert(ids.end(), piece_ids.begin(), piece_ids.end());
  }
  return ids;
}

std::vector<int64_t> ClipTokenizer::Tokenize(std::string_view text, int context_length) const {
  AVP_THROW_UNLESS(context_length > 0, context_length);
  const std::vector<int32_t> ids = Encode(text);
  const size_t length = static_cast<size_t>(context_length);
  std::vector<int64_t> tokens(length, 0);
  tokens[0] = impl_->sot;
  const size_t copied = std::min(ids.size(), length - 1);
  std::copy(ids.begin(), ids.begin() + static_cast<std::ptrdiff_t>(copied), tokens.begin() + 1);
  // EOT right after the text, or on the last position when the text fills or overflows it.
  tokens[std::min(1 + ids.size(), length - 1)] = impl_->eot;
  return tokens;
}

int32_t ClipTokenizer::sot() const { return impl_->sot; }
int32_t ClipTokenizer::eot() const { return impl_->eot; }
size_t ClipTokenizer::vocab_size() const { return impl_->vocab_size; }

}  // namespace avp::zsl

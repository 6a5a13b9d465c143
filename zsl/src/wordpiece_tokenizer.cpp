// BERT's uncased BasicTokenizer + WordPiece, and Grounding DINO's text inputs (§4.4).
#include "wordpiece_tokenizer.h"

#include <fstream>
#include <iterator>
#include <unordered_map>

#include <fmt/format.h>

#include "unicode_text.h"

namespace avp::zsl {
namespace {

using internal::CompileRegex;
using internal::Pcre2Code;
using internal::Substitute;

constexpr std::string_view kContinuation = "##";

/// The base letter of each precomposed letter U+00C0..U+017F (its NFD without the combining
/// marks); '.' where the letter has no canonical decomposition and stays as it is.
constexpr std::string_view kAccentBase =
    // U+00C0..U+00FF
    "AAAAAA.CEEEEIIII.NOOOOO..UUUUY.."
    "aaaaaa.ceeeeiiii.nooooo..uuuuy.y"
    // U+0100..U+017F
    "AaAaAaCcCcCcCcDd..EeEeEeEeEeGgGgGgGgHh..IiIiIiIiI...JjKk.LlLlLl....NnNnNn...OoOoOo..RrRrRr"
    "SsSsSsSsTtTt..UuUuUuUuUuUuWwYyYZzZzZz.";
constexpr char32_t kAccentTableFirst = 0xC0;
static_assert(kAccentBase.size() == 0x180 - 0xC0);

/// Lower-cased `s` with the accents stripped (see the class comment): table letters become their
/// base letter and combining marks are removed.
std::string StripAccents(std::string_view s) {
  static const Pcre2Code kCombiningMark = CompileRegex(R"(\p{Mn}+)");
  std::string out;
  out.reserve(s.size());
  for (size_t i = 0; i < s.size();) {
    const size_t begin = i;
    const char32_t cp = internal::DecodeUtf8(s, i);
    if (cp >= kAccentTableFirst && cp < kAccentTableFirst + kAccentBase.size() &&
        kAccentBase[cp - kAccentTableFirst] != '.') {
      out.push_back(kAccentBase[cp - kAccentTableFirst]);
    } else {
      out.append(s.substr(begin, i - begin));
    }
  }
  return Substitute(kCombiningMark.get(), out, "");
}

}  // namespace

struct WordPieceTokenizer::Impl {
  std::unordered_map<std::string, int32_t> vocab;
  size_t vocab_size = 0;
  int32_t cls = -1;
  int32_t sep = -1;
  int32_t unk = -1;
  int32_t pad = -1;
  int32_t dot = -1;
  int32_t question = -1;  // "?", which GroundingDINO also treats as a special token

  bool IsSeparator(int32_t id) const { return id == dot || (question >= 0 && id == question); }

  // BERT's _clean_text: drop U+0000, U+FFFD and control characters (\p{C} but tab, LF, CR) ...
  Pcre2Code control_re = CompileRegex(R"((?![\t\n\r])[\p{C}\x{FFFD}])");
  // ... and turn tab, LF, CR and \p{Zs} into spaces.
  Pcre2Code space_re = CompileRegex(R"([\t\n\r\p{Zs}])");
  // BERT's _is_chinese_char ranges (CJK Unified Ideographs and their extensions, compatibility).
  Pcre2Code cjk_re = CompileRegex(
      R"([\x{4E00}-\x{9FFF}\x{3400}-\x{4DBF}\x{20000}-\x{2A6DF}\x{2A700}-\x{2B73F})"
      R"(\x{2B740}-\x{2B81F}\x{2B820}-\x{2CEAF}\x{F900}-\x{FAFF}\x{2F800}-\x{2FA1F}])");
  // One punctuation character (\p{P} or an ASCII symbol), or a run of other non-space characters.
  Pcre2Code word_re = CompileRegex(R"([!-/:-@\[-`{-~\p{P}]|[^\s!-/:-@\[-`{-~\p{P}]+)");

  void AppendWordPieces(std::string_view word, std::vector<int32_t>& ids) const;
};

void WordPieceTokenizer::Impl::AppendWordPieces(std::string_view word,
                                                std::vector<int32_t>& ids) const {
  // Byte offsets of the code point boundaries.
  std::vector<size_t> bounds;
  for (size_t i = 0; i < word.size();) {
    bounds.push_back(i);
    internal::DecodeUtf8(word, i);
  }
  bounds.push_back(word.size());
  const size_t chars = bounds.size() - 1;
  if (chars > kMaxCharsPerWord) {
    ids.push_back(unk);
    return;
  }
  std::vector<int32_t> pieces;
  std::string candidate;
  size_t start = 0;
  while (start < chars) {
    // The longest vocabulary entry that starts at `start` ("##" after the first piece).
    size_t end = chars;
    int32_t id = -1;
    for (; end > start; --end) {
      candidate = start > 0 ? std::string(kContinuation) : std::string();
      candidate.append(word.substr(bounds[start], bounds[end] - bounds[start]));
      const auto it = vocab.find(candidate);
      if (it != vocab.end()) {
        id = it->second;
        break;
      }
    }
    if (id < 0) {
      ids.push_back(unk);  // the whole word is unknown, as in BERT
      return;
    }
    pieces.push_back(id);
    start = end;
  }
  ids.insert(ids.end(), pieces.begin(), pieces.end());
}

WordPieceTokenizer::WordPieceTokenizer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
WordPieceTokenizer::WordPieceTokenizer(WordPieceTokenizer&&) noexcept = default;
WordPieceTokenizer& WordPieceTokenizer::operator=(WordPieceTokenizer&&) noexcept = default;
WordPieceTokenizer::~WordPieceTokenizer() = default;

Result<WordPieceTokenizer> WordPieceTokenizer::FromVocab(std::vector<std::string> vocab) {
  auto impl = std::make_unique<Impl>();
  impl->vocab_size = vocab.size();
  impl->vocab.reserve(vocab.size());
  for (size_t id = 0; id < vocab.size(); ++id) {
    impl->vocab[std::move(vocab[id])] = static_cast<int32_t>(id);
  }
  const auto find = [&](std::string_view token) {
    const auto it = impl->vocab.find(std::string(token));
    return it == impl->vocab.end() ? -1 : it->second;
  };
  std::string missing;
  for (const auto& [token, id] : {std::pair<std::string_view, int32_t*>{"[CLS]", &impl->cls},
                                  {"[SEP]", &impl->sep},
                                  {"[UNK]", &impl->unk},
                                  {"[PAD]", &impl->pad}}) {
    *id = find(token);
    if (*id < 0) missing += fmt::format("{}{}", missing.empty() ? "" : ", ", token);
  }
  if (!missing.empty()) {
    return InvalidArgumentError(
        fmt::format("WordPiece vocabulary ({} tokens) lacks the special token(s) {}",
                    impl->vocab_size, missing));
  }
  impl->dot = find(".");
  impl->question = find("?");
  return WordPieceTokenizer(std::move(impl));
}

Result<WordPieceTokenizer> WordPieceTokenizer::FromVocabFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    return NotFoundError(fmt::format("WordPiece vocabulary file '{}' not found", path.string()));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return IoError(fmt::format("cannot open WordPiece vocabulary file '{}'", path.string()));
  }
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) {
    return IoError(fmt::format("reading WordPiece vocabulary file '{}' failed", path.string()));
  }
  std::vector<std::string> vocab;
  size_t begin = 0;
  while (begin < text.size()) {
    size_t end = text.find('\n', begin);
    if (end == std::string::npos) end = text.size();
    std::string_view line(text.data() + begin, end - begin);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    vocab.emplace_back(line);
    begin = end + 1;
  }
  Result<WordPieceTokenizer> tokenizer = FromVocab(std::move(vocab));
  if (!tokenizer.ok()) {
    return tokenizer.status().WithContext(
        fmt::format("WordPiece vocabulary file '{}'", path.string()));
  }
  return tokenizer;
}

std::vector<int32_t> WordPieceTokenizer::Encode(std::string_view text) const {
  std::string s = internal::SanitizeUtf8(text);
  s = Substitute(impl_->control_re.get(), s, "");
  s = Substitute(impl_->space_re.get(), s, " ");
  s = Substitute(impl_->cjk_re.get(), s, " $0 ");
  s = StripAccents(internal::LowerCase(s));
  std::vector<int32_t> ids;
  for (const std::string_view word : internal::FindAll(impl_->word_re.get(), s)) {
    impl_->AppendWordPieces(word, ids);
  }
  return ids;
}

Result<GroundingText> WordPieceTokenizer::EncodeGroundingPrompt(
    const std::vector<std::string>& phrases, size_t max_length) const {
  if (phrases.empty()) {
    return InvalidArgumentError("grounding prompt has no phrases");
  }
  if (impl_->dot < 0) {
    return FailedPreconditionError(
        "the WordPiece vocabulary has no '.' token, which Grounding DINO needs between phrases");
  }
  GroundingText out;
  std::vector<int32_t> ids = {impl_->cls};
  for (const std::string& phrase : phrases) {
    const std::string lowered = internal::LowerCase(internal::SanitizeUtf8(phrase));
    if (!out.caption.empty()) out.caption += " . ";
    out.caption += lowered;
    // The caption's tokens are the phrases' tokens with a "." after each: BERT splits the caption
    // at the spaces around each "." before anything else.
    const std::vector<int32_t> phrase_ids = Encode(lowered);
    if (phrase_ids.empty()) {
      return InvalidArgumentError(fmt::format("grounding phrase '{}' has no tokens", phrase));
    }
    for (const int32_t id : phrase_ids) {
      if (impl_->IsSeparator(id)) {
        return InvalidArgumentError(
            fmt::format("grounding phrase '{}' contains '.' or '?', which Grounding DINO reads as "
                        "a phrase separator",
                        phrase));
      }
    }
    const int begin = static_cast<int>(ids.size());
    ids.insert(ids.end(), phrase_ids.begin(), phrase_ids.end());
    out.phrase_token_spans.emplace_back(begin, static_cast<int>(ids.size()));
    ids.push_back(impl_->dot);
  }
  out.caption += " .";
  ids.push_back(impl_->sep);
  if (ids.size() > max_length) {
    return InvalidArgumentError(
        fmt::format("grounding caption '{}' has {} tokens; the text encoder takes at most {}",
                    out.caption, ids.size(), max_length));
  }

  const size_t length = ids.size();
  out.length = static_cast<int>(length);
  out.input_ids.assign(ids.begin(), ids.end());
  out.token_type_ids.assign(length, 0);
  out.attention_mask.assign(length, 1);
  out.position_ids.assign(length, 0);
  // generate_masks_with_special_tokens_and_transfer_map, with its special tokens [CLS], [SEP], "."
  // and "?": start from the identity; a special token in the first or last position keeps only
  // itself; every other one closes the block (previous special, col], whose tokens attend to each
  // other and take the positions 0, 1, ...
  out.text_token_mask.assign(length * length, 0);
  for (size_t i = 0; i < length; ++i) out.text_token_mask[i * length + i] = 1;
  size_t previous = 0;
  for (size_t col = 0; col < length; ++col) {
    const int32_t id = ids[col];
    if (id != impl_->cls && id != impl_->sep && !impl_->IsSeparator(id)) continue;
    if (col != 0 && col != length - 1) {
      for (size_t i = previous + 1; i <= col; ++i) {
        for (size_t j = previous + 1; j <= col; ++j) out.text_token_mask[i * length + j] = 1;
        out.position_ids[i] = static_cast<int64_t>(i - previous - 1);
      }
    }
    previous = col;
  }
  return out;
}

int32_t WordPieceTokenizer::cls_id() const { return impl_->cls; }
int32_t WordPieceTokenizer::sep_id() const { return impl_->sep; }
int32_t WordPieceTokenizer::unk_id() const { return impl_->unk; }
int32_t WordPieceTokenizer::pad_id() const { return impl_->pad; }
int32_t WordPieceTokenizer::dot_id() const { return impl_->dot; }
size_t WordPieceTokenizer::vocab_size() const { return impl_->vocab_size; }

}  // namespace avp::zsl

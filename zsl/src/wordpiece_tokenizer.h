#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <avp/core/status.h>

namespace avp::zsl {

/// Grounding DINO's text inputs for one caption of L tokens (design: zero-shot-models.md §4.4),
/// laid out as GroundingDINO's `generate_masks_with_special_tokens_and_transfer_map` builds them
/// with its special tokens [CLS], [SEP], "." and "?".
struct GroundingText {
  /// The lower-cased caption that was tokenized: "tomato . leaf ."
  std::string caption;
  /// `[CLS] phrase_1 . phrase_2 . … phrase_n . [SEP]`, L entries.
  std::vector<int64_t> input_ids;
  /// 0 on [CLS] and [SEP]; 0, 1, 2, … within each phrase block (the phrase's tokens and the "."
  /// that closes it), restarting at 0 after each special token.
  std::vector<int64_t> position_ids;
  /// All 0 (one segment).
  std::vector<int64_t> token_type_ids;
  /// All 1 (no padding).
  std::vector<uint8_t> attention_mask;
  /// L*L row-major, 1 where token i may attend token j: [CLS] and [SEP] attend only to themselves;
  /// the tokens of a phrase block (the phrase and its closing ".") attend to each other only.
  std::vector<uint8_t> text_token_mask;
  /// [begin, end) token indices of each phrase (without its "."), in input order.
  std::vector<std::pair<int, int>> phrase_token_spans;
  /// L.
  int length = 0;
};

/// BERT's uncased WordPiece tokenizer (bert-base-uncased `vocab.txt`), for Grounding DINO's text
/// encoder.
///
/// `Encode` follows BERT's BasicTokenizer then WordpieceTokenizer:
///  1. clean: invalid UTF-8 bytes become U+FFFD; U+0000, U+FFFD and control/format characters
///     (`\p{C}` except tab, newline, carriage return) are removed; tab, newline, CR and `\p{Zs}`
///     become spaces; CJK ideographs get a space on each side.
///  2. lower-case (Unicode upper- and title-case letters, PCRE2 case tables) and strip accents:
///     the precomposed letters of Latin-1 Supplement and Latin Extended-A (U+00C0–U+017F) become
///     their base letter ("é" → "e", "ä" → "a"; letters without a canonical decomposition such as
///     "ß", "ø", "æ", "ł" stay), and combining marks (`\p{Mn}`) are removed. BERT uses NFD; other
///     precomposed letters (Vietnamese, Greek with tonos, …) keep their accent here.
///  3. split on whitespace and punctuation (`\p{P}` and the ASCII symbols !"#$%&'()*+,-./:;<=>?@
///     [\]^_`{|}~), each punctuation character its own word.
///  4. WordPiece: greedy longest match first, continuation pieces prefixed with "##"; a word that
///     cannot be split, or that is longer than 100 characters, becomes [UNK].
/// Bracketed special-token strings in the text ("[SEP]") are ordinary text ("[", "sep", "]").
/// Thread-safe (all methods are const). Move-only.
class WordPieceTokenizer {
 public:
  static constexpr size_t kMaxCharsPerWord = 100;
  static constexpr size_t kGroundingMaxLength = 256;

  /// Reads `vocab.txt`: one token per line, id = 0-based line index (a trailing '\r' is dropped).
  /// Errors: NotFound (no such file), IoError, and those of FromVocab; all name the file.
  static Result<WordPieceTokenizer> FromVocabFile(const std::filesystem::path& path);

  /// id = index in `vocab`; a token listed twice keeps its later id (as BERT's loader does).
  /// InvalidArgument when [CLS], [SEP], [UNK] or [PAD] is missing (the message names it).
  static Result<WordPieceTokenizer> FromVocab(std::vector<std::string> vocab);

  WordPieceTokenizer(WordPieceTokenizer&&) noexcept;
  WordPieceTokenizer& operator=(WordPieceTokenizer&&) noexcept;
  ~WordPieceTokenizer();

  /// The WordPiece ids of `text`, without [CLS]/[SEP].
  std::vector<int32_t> Encode(std::string_view text) const;

  /// Grounding DINO's text inputs for `phrases` (normally ParsePromptClasses output): caption =
  /// the lower-cased phrases joined with " . " plus a final " ." ("tomato . leaf ."), tokens
  /// `[CLS] … [SEP]`, masks and position ids as GroundingText describes.
  /// Errors (InvalidArgument): no phrases; a phrase that yields no token or contains a "." or "?"
  /// token (Grounding DINO would split the phrase there); the caption is longer than `max_length`
  /// tokens (the message names both); FailedPrecondition when the vocabulary has no "." token.
  Result<GroundingText> EncodeGroundingPrompt(const std::vector<std::string>& phrases,
                                              size_t max_length = kGroundingMaxLength) const;

  int32_t cls_id() const;
  int32_t sep_id() const;
  int32_t unk_id() const;
  int32_t pad_id() const;
  /// The id of ".", or -1 when the vocabulary has none.
  int32_t dot_id() const;
  size_t vocab_size() const;

 private:
  struct Impl;
  explicit WordPieceTokenizer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace avp::zsl

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

/// OpenAI CLIP's byte-level BPE tokenizer (`simple_tokenizer.py`), as used by the CLIP ViT-B/32
/// text encoder behind YOLO-World (design: zero-shot-models.md §4.2).
///
/// Vocabulary, in CLIP's order: the 256 byte symbols in GPT-2 `bytes_to_unicode` order (the 188
/// printable bytes first, then the other 68), the same 256 with `</w>`, one entry per merge (the
/// concatenation of its pair), `<|startoftext|>` and `<|endoftext|>`. With the full merges file
/// this is 49,408 entries, SOT = 49406 and EOT = 49407.
///
/// `Encode` runs, in order:
///  1. clean: invalid UTF-8 bytes become U+FFFD; HTML entities are unescaped twice (as CLIP does):
///     `&amp; &lt; &gt; &quot; &apos; &nbsp;` and numeric `&#NN;` / `&#xHH;` (with the `;` only);
///     the ends are trimmed as Python's `str.strip()` does and inner runs of whitespace (the
///     characters of Python's `\s`) become one space; then Unicode lower-casing of upper- and
///     title-case letters (PCRE2's case tables, U+0130 -> "i" + U+0307, final sigma).
///     Differences from CLIP, which runs ftfy first: no ftfy repairs and **no NFC normalisation**,
///     so decomposed input ("e" + U+0301) is tokenized as written, not as the precomposed letter;
///     the other HTML5 named entities are left as they are; characters with a lower-case mapping
///     that are not letters (Roman numerals, circled letters) are not lower-cased.
///  2. split (PCRE2, UTF + UCP, case-insensitive), in this order: the special-token strings,
///     `'s 't 're 've 'm 'll 'd`, `\p{L}+`, a single `\p{N}` ("2024" is four pieces),
///     `[^\s\p{L}\p{N}]+`. Special-token strings found in the text are **dropped** (CLIP would emit
///     their ids), so user text can never end the sequence early.
///  3. each piece's UTF-8 bytes through the byte-to-unicode table; BPE with `</w>` on the last
///     symbol, merging the lowest-ranked adjacent pair (all its non-overlapping occurrences, left
///     to right) until no ranked pair is left. Results are cached per piece.
///
/// Thread-safe: `Encode` and `Tokenize` may be called concurrently (the piece cache has a mutex).
/// Move-only.
class ClipTokenizer {
 public:
  /// CLIP uses the first 48,894 merges (49152 - 256 - 2) of `bpe_simple_vocab_16e6.txt`.
  static constexpr size_t kClipMergeCount = 49152 - 256 - 2;
  static constexpr int kClipContextLength = 77;

  /// Reads a merges file in the `bpe_simple_vocab_16e6.txt` format, plain or gzip-compressed (zlib
  /// reads both; the name does not matter): line 1 is a header and is skipped, then one merge per
  /// line as two symbols separated by one space; at most kClipMergeCount merges are read and later
  /// lines are ignored. A trailing empty line is allowed; `\r` before a newline is ignored.
  /// Errors: NotFound (no such file), IoError (unreadable or corrupt/truncated gzip), ParseError
  /// (empty file, or a line that is not two symbols: "'<file>' line 7: ..."). All name the file.
  static Result<ClipTokenizer> FromMergesFile(const std::filesystem::path& path);

  /// Builds the tokenizer from merges in rank order (rank = index). Each symbol must be non-empty
  /// (InvalidArgument naming the merge's index otherwise). A pair listed twice takes its later
  /// rank, and a vocabulary string listed twice its later id, as with CLIP's Python dicts.
  static Result<ClipTokenizer> FromMerges(std::vector<std::pair<std::string, std::string>> merges);

  ClipTokenizer(ClipTokenizer&&) noexcept;
  ClipTokenizer& operator=(ClipTokenizer&&) noexcept;
  ~ClipTokenizer();

  /// The BPE ids of `text`, without SOT/EOT (see the class comment for the steps).
  std::vector<int32_t> Encode(std::string_view text) const;

  /// CLIP's `clip.tokenize(text, truncate=True)`: `[SOT] Encode(text) [EOT]`, padded with 0 to
  /// `context_length`; a longer sequence is cut to `context_length` with its last position set to
  /// EOT (so the text encoder, which pools at the first EOT, still sees one).
  /// @pre context_length > 0 (throws avp::Error otherwise).
  std::vector<int64_t> Tokenize(std::string_view text,
                                int context_length = kClipContextLength) const;

  int32_t sot() const;
  int32_t eot() const;
  /// 256 + 256 + number of merges + 2 (49,408 for CLIP).
  size_t vocab_size() const;

 private:
  struct Impl;
  explicit ClipTokenizer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace avp::zsl

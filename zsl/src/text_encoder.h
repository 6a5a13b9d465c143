#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <avp/core/status.h>

namespace avp::zsl {

struct LoadedModel;  // manifest.h
class TensorModel;   // tensor_model.h

/// Settings of a TextEncoder.
struct TextEncoderOptions {
  /// Entries of the per-phrase embedding cache (LRU). 0 = no cache (every call runs the model
  /// for every phrase that is not in a precomputed vocabulary).
  size_t cache_capacity = 1024;
};

/// The embeddings of a list of phrases, as TextEncoder::Encode returns them.
struct TextEmbeddings {
  int dim = 0;  ///< the embedding width (512 for CLIP ViT-B/32)
  /// phrases.size() rows of `dim` floats, row-major, in the order of the phrases; each row has
  /// unit L2 norm.
  std::vector<float> values;
  size_t from_precomputed = 0;  ///< phrases found in a precomputed vocabulary
  size_t from_cache = 0;        ///< phrases found in the LRU cache
  size_t computed = 0;          ///< phrases the text model ran for (in one batch)
  double tokenize_ms = 0.0;     ///< BPE tokenization of the computed phrases
  double model_ms = 0.0;        ///< the text model run(s), normalisation and caching included

  /// Row `i` (i < phrases.size()).
  std::span<const float> Row(size_t i) const {
    return std::span<const float>(values).subspan(i * static_cast<size_t>(dim),
                                                  static_cast<size_t>(dim));
  }
};

/// CLIP text embeddings for detector prompts (design: zero-shot-models.md §4.2): ClipTokenizer →
/// the `clip.text/1` model (`input_ids` int64 [B,77] → `text_embeds` f32 [B,512]), batched over
/// the phrases that are not cached → L2 normalisation (skipped when the manifest's
/// `text.normalized_in_graph` says the export already divides by the norm) → an LRU cache keyed by
/// NormalizeClassName(phrase), so "Tomato " and "tomato" share one entry.
///
/// A manifest's `text.precomputed` vocabularies (rows of `text.dim` float32 per line of a names
/// file, as the text model's `text_embeds` gives them) are loaded at creation; their rows are
/// normalised like the model's (idempotent for rows stored already normalised) and are looked up
/// before the cache, never evicted.
///
/// Batching: one run for all uncached phrases when the model's batch axis B is dynamic; in chunks
/// of B rows (the last chunk padded with copies of its first row) when the export fixes B.
///
/// Thread-safe: `Encode` may run on several threads at once (the session is shared, the cache
/// locked); two threads missing the same phrase may both compute it (same result). Move-only.
class TextEncoder {
 public:
  /// Takes the `text` role of a loaded ywes backend (contract clip.text/1, with its `text`
  /// section): reads the CLIP merges file (`text.vocabulary`) and the precomputed vocabularies.
  /// Errors: InvalidArgument when the entry is not clip.text/1 or has no `text` section, or when
  /// a precomputed blob's size is not names × dim × 4 bytes (naming the file and both numbers);
  /// the tokenizer's errors (NotFound, IoError, ParseError naming the merges file). All start
  /// with "text: ".
  static Result<TextEncoder> Create(LoadedModel text_model, const TextEncoderOptions& options = {});

  TextEncoder(TextEncoder&&) noexcept;
  TextEncoder& operator=(TextEncoder&&) noexcept;
  ~TextEncoder();

  /// The unit-norm embeddings of `phrases`, in order (duplicates allowed; each distinct
  /// uncached phrase is computed once). An empty list gives no rows.
  /// Errors: InvalidArgument when a phrase's embedding has norm 0 or is not finite ("text: the
  /// embedding of '<|endoftext|>' has L2 norm 0"); the model's run errors ("text: ...").
  Result<TextEmbeddings> Encode(std::span<const std::string> phrases) const;

  /// The embedding width (`text_embeds` columns).
  int dim() const;
  /// The model's static batch size, or 0 when its batch axis is dynamic.
  int static_batch() const;
  /// How many times the text model has run, and for how many phrases in all (rows of those
  /// runs, padding excluded); for tests and statistics.
  uint64_t model_runs() const;
  uint64_t phrases_computed() const;
  /// Entries now in the LRU cache, and its capacity.
  size_t cache_size() const;
  size_t cache_capacity() const;
  /// Phrases of the precomputed vocabularies (normalised names).
  size_t precomputed_size() const;
  /// The session (for its provider and device).
  const TensorModel& model() const;

 private:
  struct Impl;
  explicit TextEncoder(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace avp::zsl

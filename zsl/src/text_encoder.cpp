#include "text_encoder.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/core/stopwatch.h>

#include "clip_tokenizer.h"
#include "lru_cache.h"
#include "manifest.h"
#include "prompt.h"

namespace avp::zsl {

namespace {

/// Divides `row` by its L2 norm (unless `normalized_in_graph`); InvalidArgument for a zero or
/// non-finite norm.
Status NormalizeRow(std::span<float> row, bool normalized_in_graph, const std::string& phrase) {
  double sum = 0.0;
  for (float v : row) sum += static_cast<double>(v) * v;
  const double norm = std::sqrt(sum);
  if (!std::isfinite(norm) || norm == 0.0) {
    return InvalidArgumentError(
        fmt::format("text: the embedding of '{}' has L2 norm {}", phrase, norm));
  }
  if (normalized_in_graph) return Status::Ok();
  for (float& v : row) v = static_cast<float>(v / norm);
  return Status::Ok();
}

Result<std::string> ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return IoError(fmt::format("text: cannot open '{}'", path.string()));
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return IoError(fmt::format("text: cannot read '{}'", path.string()));
  return bytes;
}

/// One precomputed vocabulary: names (one per line) and rows of `dim` little-endian float32.
Status LoadPrecomputed(const PrecomputedVocabulary& vocab, int dim, bool normalized_in_graph,
                       std::unordered_map<std::string, std::vector<float>>& out) {
  AVP_ASSIGN_OR_RETURN(const std::string names_text, ReadFile(vocab.names.path));
  AVP_ASSIGN_OR_RETURN(const std::string blob, ReadFile(vocab.embeddings.path));
  std::vector<std::string> names;
  size_t start = 0;
  while (start < names_text.size()) {
    size_t end = names_text.find('\n', start);
    if (end == std::string::npos) end = names_text.size();
    std::string line = names_text.substr(start, end - start);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    names.push_back(NormalizeClassName(line));
    if (names.back().empty()) {
      return InvalidArgumentError(
          fmt::format("text: precomputed vocabulary '{}': line {} of '{}' is empty", vocab.name,
                      names.size(), vocab.names.path.string()));
    }
    start = end + 1;
  }
  const size_t row_bytes = static_cast<size_t>(dim) * sizeof(float);
  if (blob.size() != names.size() * row_bytes) {
    return InvalidArgumentError(fmt::format(
        "text: precomputed vocabulary '{}': '{}' has {} bytes; {} names x {} float32 need {}",
        vocab.name, vocab.embeddings.path.string(), blob.size(), names.size(), dim,
        names.size() * row_bytes));
  }
  for (size_t i = 0; i < names.size(); ++i) {
    std::vector<float> row(static_cast<size_t>(dim));
    std::memcpy(row.data(), blob.data() + i * row_bytes, row_bytes);
    if constexpr (std::endian::native == std::endian::big) {
      for (float& v : row) {
        uint32_t u;
        std::memcpy(&u, &v, sizeof u);
        u = ((u & 0xffu) << 24) | ((u & 0xff00u) << 8) | ((u >> 8) & 0xff00u) | (u >> 24);
        std::memcpy(&v, &u, sizeof u);
      }
    }
    AVP_RETURN_IF_ERROR(NormalizeRow(row, normalized_in_graph, names[i])
                            .WithContext(fmt::format("precomputed vocabulary '{}'", vocab.name)));
    out.insert_or_assign(names[i], std::move(row));  // a later vocabulary overrides
  }
  return Status::Ok();
}

}  // namespace

struct TextEncoder::Impl {
  Impl(LoadedModel m, ClipTokenizer t, size_t capacity)
      : model(std::move(m)), tokenizer(std::move(t)), cache(capacity) {}

  LoadedModel model;
  ClipTokenizer tokenizer;
  TextConfig text;
  int dim = 512;
  int batch = 0;  // 0 = dynamic
  std::string input_name;
  std::string output_name;
  std::unordered_map<std::string, std::vector<float>> precomputed;
  mutable LruCache<std::string, std::vector<float>> cache;  // locks itself
  mutable std::atomic<uint64_t> runs{0};
  mutable std::atomic<uint64_t> computed{0};

  /// Runs the model on `ids` (rows of text.context ids) and returns rows of `dim` floats.
  Result<std::vector<float>> Run(const std::vector<int64_t>& ids, size_t rows) const;
};

Result<std::vector<float>> TextEncoder::Impl::Run(const std::vector<int64_t>& ids,
                                                  size_t rows) const {
  const InputTensor input = InputTensor::Int64(
      input_name, ids, {static_cast<int64_t>(rows), static_cast<int64_t>(text.context)});
  const std::vector<std::string> outputs = {output_name};
  AVP_ASSIGN_OR_RETURN(std::vector<OutputTensor> out,
                       model.model.Run(std::span<const InputTensor>(&input, 1), outputs));
  runs.fetch_add(1, std::memory_order_relaxed);
  if (out.size() != 1 || out[0].f32.size() != rows * static_cast<size_t>(dim)) {
    return InternalError(fmt::format("text: output '{}' has {} values ({}); expected {} x {}",
                                     output_name, out.empty() ? 0 : out[0].f32.size(),
                                     out.empty() ? "?" : ShapeToString(out[0].shape), rows, dim));
  }
  return std::move(out[0].f32);
}

TextEncoder::TextEncoder(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TextEncoder::TextEncoder(TextEncoder&&) noexcept = default;
TextEncoder& TextEncoder::operator=(TextEncoder&&) noexcept = default;
TextEncoder::~TextEncoder() = default;

Result<TextEncoder> TextEncoder::Create(LoadedModel text_model, const TextEncoderOptions& options) {
  const ModelEntry& entry = text_model.entry;
  if (entry.contract != kClipText) {
    return InvalidArgumentError(fmt::format("text: role '{}' has contract {}; TextEncoder needs {}",
                                            entry.role, entry.contract, kClipText));
  }
  if (!entry.text) {
    return InvalidArgumentError(
        fmt::format("text: models.{}.text is missing (the CLIP vocabulary file)", entry.role));
  }
  const TextConfig text = *entry.text;
  Result<ClipTokenizer> tokenizer = ClipTokenizer::FromMergesFile(text.vocabulary.path);
  if (!tokenizer.ok()) return tokenizer.status().WithContext("text");
  if (tokenizer->sot() != text.sot || tokenizer->eot() != text.eot) {
    return InvalidArgumentError(fmt::format(
        "text: the merges file '{}' gives SOT {} and EOT {}; text.sot and text.eot say {} and {}",
        text.vocabulary.path.string(), tokenizer->sot(), tokenizer->eot(), text.sot, text.eot));
  }
  const ContractBinding binding = text_model.binding;
  auto impl = std::make_unique<Impl>(std::move(text_model), std::move(tokenizer).value(),
                                     options.cache_capacity);
  impl->text = text;
  impl->input_name = binding.Name("input_ids");
  impl->output_name = binding.Name("text_embeds");
  const TensorInfo* out = impl->model.model.io().FindOutput(impl->output_name);
  impl->dim = out != nullptr && out->shape.size() == 2 && out->shape[1] > 0
                  ? static_cast<int>(out->shape[1])
                  : text.dim;
  const int64_t b = binding.Dim("B");
  impl->batch = b == kDynamicDim ? 0 : static_cast<int>(b);
  for (const PrecomputedVocabulary& vocab : text.precomputed) {
    AVP_RETURN_IF_ERROR(
        LoadPrecomputed(vocab, impl->dim, text.normalized_in_graph, impl->precomputed));
  }
  return TextEncoder(std::move(impl));
}

Result<TextEmbeddings> TextEncoder::Encode(std::span<const std::string> phrases) const {
  const Impl& m = *impl_;
  const size_t dim = static_cast<size_t>(m.dim);
  TextEmbeddings out;
  out.dim = m.dim;
  out.values.assign(phrases.size() * dim, 0.0f);
  const auto copy_row = [&](size_t i, std::span<const float> row) {
    std::copy(row.begin(), row.end(), out.values.begin() + static_cast<std::ptrdiff_t>(i * dim));
  };

  // Look every phrase up; the rest (each distinct key once) go to the model.
  std::vector<std::string> todo;                  // normalised phrases to compute
  std::vector<std::vector<size_t>> todo_targets;  // the output rows of each
  std::map<std::string, size_t> todo_slot;
  for (size_t i = 0; i < phrases.size(); ++i) {
    std::string key = NormalizeClassName(phrases[i]);
    if (const auto it = m.precomputed.find(key); it != m.precomputed.end()) {
      copy_row(i, it->second);
      ++out.from_precomputed;
      continue;
    }
    if (const auto it = todo_slot.find(key); it != todo_slot.end()) {
      todo_targets[it->second].push_back(i);
      continue;
    }
    if (std::optional<std::vector<float>> cached = m.cache.Get(key)) {
      copy_row(i, *cached);
      ++out.from_cache;
      continue;
    }
    todo_slot.emplace(key, todo.size());
    todo.push_back(std::move(key));
    todo_targets.push_back({i});
  }
  if (todo.empty()) return out;

  // Tokenize ([SOT] ... [EOT], 0-padded to the context; the manifest's pad id after EOT).
  const auto tokenize_start = std::chrono::steady_clock::now();
  const size_t context = static_cast<size_t>(m.text.context);
  std::vector<int64_t> ids;
  ids.reserve(todo.size() * context);
  for (const std::string& phrase : todo) {
    std::vector<int64_t> row = m.tokenizer.Tokenize(phrase, m.text.context);
    if (m.text.pad != 0) {
      const auto eot = std::find(row.begin(), row.end(), m.text.eot);
      if (eot != row.end()) std::fill(eot + 1, row.end(), m.text.pad);
    }
    ids.insert(ids.end(), row.begin(), row.end());
  }
  out.tokenize_ms = MsSince(tokenize_start);

  // Run: one batch when B is dynamic, else chunks of B rows (the last padded with its first row).
  const auto model_start = std::chrono::steady_clock::now();
  const size_t chunk = m.batch > 0 ? static_cast<size_t>(m.batch) : todo.size();
  std::vector<float> embeds;
  embeds.reserve(todo.size() * dim);
  for (size_t first = 0; first < todo.size(); first += chunk) {
    const size_t rows = std::min(chunk, todo.size() - first);
    std::vector<int64_t> batch_ids(
        ids.begin() + static_cast<std::ptrdiff_t>(first * context),
        ids.begin() + static_cast<std::ptrdiff_t>((first + rows) * context));
    for (size_t pad = rows; pad < chunk; ++pad) {
      batch_ids.insert(batch_ids.end(), batch_ids.begin(),
                       batch_ids.begin() + static_cast<std::ptrdiff_t>(context));
    }
    AVP_ASSIGN_OR_RETURN(const std::vector<float> result, m.Run(batch_ids, chunk));
    embeds.insert(embeds.end(), result.begin(),
                  result.begin() + static_cast<std::ptrdiff_t>(rows * dim));
  }
  for (size_t k = 0; k < todo.size(); ++k) {
    std::span<float> row(embeds.data() + k * dim, dim);
    AVP_RETURN_IF_ERROR(NormalizeRow(row, m.text.normalized_in_graph, todo[k]));
    for (size_t i : todo_targets[k]) copy_row(i, row);
    m.cache.Put(todo[k], std::vector<float>(row.begin(), row.end()));
  }
  out.computed = todo.size();
  m.computed.fetch_add(todo.size(), std::memory_order_relaxed);
  out.model_ms = MsSince(model_start);
  return out;
}

int TextEncoder::dim() const { return impl_->dim; }
int TextEncoder::static_batch() const { return impl_->batch; }
uint64_t TextEncoder::model_runs() const { return impl_->runs.load(); }
uint64_t TextEncoder::phrases_computed() const { return impl_->computed.load(); }
size_t TextEncoder::cache_size() const { return impl_->cache.size(); }
size_t TextEncoder::cache_capacity() const { return impl_->cache.capacity(); }
size_t TextEncoder::precomputed_size() const { return impl_->precomputed.size(); }
const TensorModel& TextEncoder::model() const { return impl_->model.model.get(); }

}  // namespace avp::zsl

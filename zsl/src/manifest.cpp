// manifest.json parsing, file checks and backend start-up (design: zero-shot-models.md §7).
#include "manifest.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <initializer_list>
#include <set>
#include <sstream>
#include <system_error>
#include <utility>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "ort_handler.h"
#include "remote_model.h"

namespace avp::zsl {

namespace fs = std::filesystem;
using nlohmann::json;

const ModelEntry* Manifest::Find(std::string_view role) const {
  auto it = models.find(std::string(role));
  return it == models.end() ? nullptr : &it->second;
}

// ---- parsing -----------------------------------------------------------------------------------

namespace {

// Bounds on what a manifest may declare, each sizing an allocation (docs/limits.md): an image side
// of a network's input (preprocess.size, prompt_frame, low_res), the classes of a detector
// (n_max: txt_feats rows), a text model's context and embedding width, and a stated dimension.
constexpr int64_t kMaxImageSide = 8192;
constexpr int64_t kMaxClasses = 4096;
constexpr int64_t kMaxContext = 4096;
constexpr int64_t kMaxEmbeddingDim = 65536;
constexpr int64_t kMaxDeclaredDim = int64_t{1} << 20;
constexpr size_t kMaxDeclaredRank = 8;

std::string Describe(const json& value) {
  std::string text = value.dump();
  if (text.size() > 40) text = text.substr(0, 37) + "...";
  return text;
}

/// One JSON object being read: records the fields used, so that unknown ones are errors.
class Fields {
 public:
  Fields(const json& object, std::string path, const std::string& source)
      : object_(object), path_(std::move(path)), source_(source) {}

  Status Error(std::string_view key, std::string_view message) const {
    const std::string where = key.empty() ? path_ : fmt::format("{}.{}", path_, key);
    return ParseError(fmt::format("{}: {}: {}", source_, where, message));
  }
  const std::string& path() const { return path_; }
  const std::string& source() const { return source_; }

  /// The field, or nullptr when absent (the field then counts as known).
  const json* Get(const std::string& key) {
    used_.insert(key);
    auto it = object_.find(key);
    return it == object_.end() ? nullptr : &*it;
  }

  Status Missing(const std::string& key, std::string_view what) const {
    return Error("", fmt::format("missing field '{}' ({})", key, what));
  }

  Status String(const std::string& key, std::string& out, bool required) {
    const json* v = Get(key);
    if (v == nullptr) return required ? Missing(key, "a string") : Status::Ok();
    if (!v->is_string()) return Error(key, fmt::format("expected a string, got {}", Describe(*v)));
    out = v->get<std::string>();
    return Status::Ok();
  }

  Status Int(const std::string& key, int64_t& out, bool required, int64_t min) {
    const json* v = Get(key);
    if (v == nullptr) return required ? Missing(key, "an integer") : Status::Ok();
    if (!v->is_number_integer() || v->get<int64_t>() < min) {
      return Error(key, fmt::format("expected an integer >= {}, got {}", min, Describe(*v)));
    }
    out = v->get<int64_t>();
    return Status::Ok();
  }

  /// `max`: what the value may size (a side in pixels, rows of a tensor) is bounded before
  /// anything is allocated from it.
  Status Int(const std::string& key, int& out, bool required, int64_t min,
             int64_t max = 1'000'000'000) {
    int64_t value = out;
    AVP_RETURN_IF_ERROR(Int(key, value, required, min));
    if (value > max) return Error(key, fmt::format("{} is too large (at most {})", value, max));
    out = static_cast<int>(value);
    return Status::Ok();
  }

  Status Number(const std::string& key, float& out, bool positive = false) {
    const json* v = Get(key);
    if (v == nullptr) return Status::Ok();
    if (!v->is_number() || (positive && v->get<double>() <= 0.0)) {
      return Error(key, fmt::format("expected a {}number, got {}", positive ? "positive " : "",
                                    Describe(*v)));
    }
    out = static_cast<float>(v->get<double>());
    return Status::Ok();
  }

  Status Bool(const std::string& key, bool& out) {
    const json* v = Get(key);
    if (v == nullptr) return Status::Ok();
    if (!v->is_boolean())
      return Error(key, fmt::format("expected true or false, got {}", Describe(*v)));
    out = v->get<bool>();
    return Status::Ok();
  }

  Status Triple(const std::string& key, std::array<float, 3>& out, bool positive) {
    const json* v = Get(key);
    if (v == nullptr) return Status::Ok();
    bool ok = v->is_array() && v->size() == 3;
    for (size_t i = 0; ok && i < 3; ++i) {
      ok = (*v)[i].is_number() && (!positive || (*v)[i].get<double>() > 0.0);
    }
    if (!ok) {
      return Error(key, fmt::format("expected 3 {}numbers, got {}", positive ? "positive " : "",
                                    Describe(*v)));
    }
    for (size_t i = 0; i < 3; ++i) out[i] = static_cast<float>((*v)[i].get<double>());
    return Status::Ok();
  }

  template <typename E>
  Status Enum(const std::string& key, E& out,
              std::initializer_list<std::pair<const char*, E>> choices) {
    const json* v = Get(key);
    if (v == nullptr) return Status::Ok();
    std::vector<std::string> names;
    for (const auto& [name, value] : choices) {
      if (v->is_string() && v->get<std::string>() == name) {
        out = value;
        return Status::Ok();
      }
      names.push_back(fmt::format("\"{}\"", name));
    }
    return Error(key,
                 fmt::format("expected one of {}, got {}", fmt::join(names, ", "), Describe(*v)));
  }

  /// Fields nobody asked for are errors (typos must not pass silently); "_…" keys are comments.
  Status CheckUnknown() const {
    for (auto it = object_.begin(); it != object_.end(); ++it) {
      if (!it.key().empty() && it.key()[0] == '_') continue;
      if (used_.count(it.key()) == 0) return Error("", fmt::format("unknown field '{}'", it.key()));
    }
    return Status::Ok();
  }

 private:
  const json& object_;
  std::string path_;
  const std::string& source_;
  std::set<std::string> used_;
};

bool IsHex64(const std::string& s) {
  return s.size() == 64 && std::all_of(s.begin(), s.end(), [](char c) {
           return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F');
         });
}

std::string Lower(std::string s) {
  for (char& c : s) {
    if (c >= 'A' && c <= 'F') c = static_cast<char>(c - 'A' + 'a');
  }
  return s;
}

Status ExpectObject(const json& value, const Fields& parent, const std::string& key) {
  if (!value.is_object()) {
    return parent.Error(key, fmt::format("expected an object, got {}", Describe(value)));
  }
  return Status::Ok();
}

/// A file reference: "dir/x.txt" or {"file": …, "bytes": …, "sha256": …}.
Status ParseFileRef(const json& value, Fields& parent, const std::string& key, const fs::path& dir,
                    bool bytes_required, FileRef& out) {
  if (value.is_string()) {
    if (bytes_required) return parent.Error(key, "expected {\"file\", \"bytes\", …}, got a string");
    out.relative = value.get<std::string>();
  } else if (value.is_object()) {
    Fields f(value, parent.path() + "." + key, parent.source());
    AVP_RETURN_IF_ERROR(f.String("file", out.relative, true));
    int64_t bytes = -1;
    AVP_RETURN_IF_ERROR(f.Int("bytes", bytes, bytes_required, 0));
    if (bytes >= 0) out.bytes = static_cast<uint64_t>(bytes);
    std::string sha;
    AVP_RETURN_IF_ERROR(f.String("sha256", sha, false));
    if (!sha.empty()) {
      if (!IsHex64(sha))
        return f.Error("sha256", fmt::format("expected 64 hex digits, got \"{}\"", sha));
      out.sha256 = Lower(sha);
    }
    AVP_RETURN_IF_ERROR(f.CheckUnknown());
  } else {
    return parent.Error(key,
                        fmt::format("expected a file name or an object, got {}", Describe(value)));
  }
  if (out.relative.empty()) return parent.Error(key, "the file name is empty");
  const fs::path rel(out.relative);
  if (rel.is_absolute()) {
    return parent.Error(key,
                        fmt::format("'{}' must be relative to the model directory", out.relative));
  }
  out.path = dir / rel;
  return Status::Ok();
}

Status ParseTensorList(const json& value, Fields& parent, const std::string& key,
                       std::vector<TensorInfo>& out) {
  if (!value.is_array()) {
    return parent.Error(key, fmt::format("expected an array of tensors, got {}", Describe(value)));
  }
  for (size_t i = 0; i < value.size(); ++i) {
    const std::string item = fmt::format("{}[{}]", key, i);
    AVP_RETURN_IF_ERROR(ExpectObject(value[i], parent, item));
    Fields f(value[i], parent.path() + "." + item, parent.source());
    TensorInfo t;
    AVP_RETURN_IF_ERROR(f.String("name", t.name, true));
    std::string type;
    AVP_RETURN_IF_ERROR(f.String("type", type, true));
    Result<ElementType> parsed = ParseElementType(type);
    if (!parsed.ok()) return f.Error("type", parsed.status().message());
    t.type = *parsed;
    const json* shape = f.Get("shape");
    if (shape == nullptr) return f.Missing("shape", "an array of integers, -1 = dynamic");
    if (!shape->is_array())
      return f.Error("shape", fmt::format("expected an array, got {}", Describe(*shape)));
    // A stated dimension may size what avp allocates (it stands for one the graph leaves
    // dynamic: CheckContract), so it is bounded as a request's dynamic dimension is.
    if (shape->size() > kMaxDeclaredRank) {
      return f.Error("shape", fmt::format("rank {} exceeds {}", shape->size(), kMaxDeclaredRank));
    }
    for (const json& d : *shape) {
      if (!d.is_number_integer() || d.get<int64_t>() < -1) {
        return f.Error("shape", fmt::format("expected integers >= -1, got {}", Describe(*shape)));
      }
      if (d.get<int64_t>() > kMaxDeclaredDim) {
        return f.Error("shape", fmt::format("a dimension exceeds {}, got {}", kMaxDeclaredDim,
                                            Describe(*shape)));
      }
      t.shape.push_back(d.get<int64_t>());
    }
    AVP_RETURN_IF_ERROR(f.CheckUnknown());
    out.push_back(std::move(t));
  }
  return Status::Ok();
}

Status ParsePreprocess(const json& value, Fields& parent, Preprocess& p) {
  AVP_RETURN_IF_ERROR(ExpectObject(value, parent, "preprocess"));
  Fields f(value, parent.path() + ".preprocess", parent.source());
  if (const json* size = f.Get("size")) {
    // The network's input is allocated from it: each side in [1, kMaxImageSide].
    const auto side = [](const json& v) {
      return v.is_number_integer() && v.get<int64_t>() > 0 && v.get<int64_t>() <= kMaxImageSide;
    };
    if (side(*size)) {
      p.height = p.width = static_cast<int>(size->get<int64_t>());
    } else if (size->is_array() && size->size() == 2 && side((*size)[0]) && side((*size)[1])) {
      p.height = static_cast<int>((*size)[0].get<int64_t>());
      p.width = static_cast<int>((*size)[1].get<int64_t>());
    } else {
      return f.Error("size", fmt::format("expected S or [height, width] (integers in [1, {}]), "
                                         "got {}",
                                         kMaxImageSide, Describe(*size)));
    }
  }
  AVP_RETURN_IF_ERROR(f.Enum<ResizeMode>(
      "resize", p.resize, {{"fit", ResizeMode::kFit}, {"stretch", ResizeMode::kStretch}}));
  AVP_RETURN_IF_ERROR(f.Enum<Interpolation>("interpolation", p.interpolation,
                                            {{"linear", Interpolation::kLinear},
                                             {"nearest", Interpolation::kNearest},
                                             {"area", Interpolation::kArea},
                                             {"cubic", Interpolation::kCubic}}));
  AVP_RETURN_IF_ERROR(f.Enum<PaddingMode>("padding", p.padding,
                                          {{"centre", PaddingMode::kCentre},
                                           {"center", PaddingMode::kCentre},
                                           {"bottom_right", PaddingMode::kBottomRight},
                                           {"none", PaddingMode::kNone}}));
  AVP_RETURN_IF_ERROR(f.Number("pad_value", p.pad_value));
  AVP_RETURN_IF_ERROR(
      f.Enum<PadSpace>("pad_space", p.pad_space,
                       {{"pixels", PadSpace::kPixels}, {"normalized", PadSpace::kNormalized}}));
  AVP_RETURN_IF_ERROR(
      f.Enum<ChannelOrder>("channel_order", p.channel_order,
                           {{"rgb", ChannelOrder::kRgb}, {"bgr", ChannelOrder::kBgr}}));
  AVP_RETURN_IF_ERROR(f.Number("scale", p.scale, /*positive=*/true));
  AVP_RETURN_IF_ERROR(f.Triple("mean", p.mean, false));
  AVP_RETURN_IF_ERROR(f.Triple("std", p.stddev, true));
  return f.CheckUnknown();
}

Status ParsePostprocess(const json& value, Fields& parent, Postprocess& p) {
  AVP_RETURN_IF_ERROR(ExpectObject(value, parent, "postprocess"));
  Fields f(value, parent.path() + ".postprocess", parent.source());
  AVP_RETURN_IF_ERROR(
      f.Enum<DetectionLayout>("layout", p.layout,
                              {{"[4+N,A]", DetectionLayout::kAttributesByAnchors},
                               {"[A,4+N]", DetectionLayout::kAnchorsByAttributes}}));
  AVP_RETURN_IF_ERROR(f.Enum<BoxFormat>("box_format", p.box_format,
                                        {{"cxcywh", BoxFormat::kCxCyWh},
                                         {"xyxy", BoxFormat::kXyXy},
                                         {"cxcywh_normalized", BoxFormat::kCxCyWhNormalized}}));
  AVP_RETURN_IF_ERROR(f.Enum<ScoreActivation>(
      "score_activation", p.score_activation,
      {{"none", ScoreActivation::kNone}, {"sigmoid", ScoreActivation::kSigmoid}}));
  AVP_RETURN_IF_ERROR(f.Int("n_max", p.n_max, false, 1, kMaxClasses));
  if (const json* names = f.Get("baked_names")) {
    bool ok = names->is_array() && !names->empty();
    for (size_t i = 0; ok && i < names->size(); ++i) {
      ok = (*names)[i].is_string() && !(*names)[i].get<std::string>().empty();
    }
    if (!ok) {
      return f.Error("baked_names",
                     fmt::format("expected a non-empty array of names, got {}", Describe(*names)));
    }
    p.baked_names.clear();
    for (const json& n : *names) p.baked_names.push_back(n.get<std::string>());
  }
  AVP_RETURN_IF_ERROR(f.Int("prompt_frame", p.prompt_frame, false, 1, kMaxImageSide));
  AVP_RETURN_IF_ERROR(f.Int("low_res", p.low_res, false, 1, kMaxImageSide));
  AVP_RETURN_IF_ERROR(f.Number("mask_threshold", p.mask_threshold));
  return f.CheckUnknown();
}

Status ParseText(const json& value, Fields& parent, const fs::path& dir, TextConfig& t) {
  AVP_RETURN_IF_ERROR(ExpectObject(value, parent, "text"));
  Fields f(value, parent.path() + ".text", parent.source());
  AVP_RETURN_IF_ERROR(f.Enum<TokenizerKind>(
      "tokenizer", t.tokenizer,
      {{"clip_bpe", TokenizerKind::kClipBpe}, {"bert_wordpiece", TokenizerKind::kBertWordPiece}}));
  AVP_RETURN_IF_ERROR(f.Int("context", t.context, false, 1, kMaxContext));
  AVP_RETURN_IF_ERROR(f.Int("sot", t.sot, false, 0));
  AVP_RETURN_IF_ERROR(f.Int("eot", t.eot, false, 0));
  AVP_RETURN_IF_ERROR(f.Int("pad", t.pad, false, 0));
  AVP_RETURN_IF_ERROR(f.Int("cls", t.cls, false, 0));
  AVP_RETURN_IF_ERROR(f.Int("sep", t.sep, false, 0));
  AVP_RETURN_IF_ERROR(f.Int("period", t.period, false, 0));
  const json* vocab = f.Get("vocabulary");
  if (vocab == nullptr) return f.Missing("vocabulary", "the tokenizer's vocabulary file");
  AVP_RETURN_IF_ERROR(ParseFileRef(*vocab, f, "vocabulary", dir, false, t.vocabulary));
  AVP_RETURN_IF_ERROR(f.Int("dim", t.dim, false, 1, kMaxEmbeddingDim));
  AVP_RETURN_IF_ERROR(f.Bool("normalized_in_graph", t.normalized_in_graph));
  AVP_RETURN_IF_ERROR(f.Bool("lower_case", t.lower_case));
  if (const json* pre = f.Get("precomputed")) {
    if (!pre->is_array()) {
      return f.Error("precomputed", fmt::format("expected an array, got {}", Describe(*pre)));
    }
    for (size_t i = 0; i < pre->size(); ++i) {
      const std::string item = fmt::format("precomputed[{}]", i);
      AVP_RETURN_IF_ERROR(ExpectObject((*pre)[i], f, item));
      Fields g((*pre)[i], f.path() + "." + item, f.source());
      PrecomputedVocabulary p;
      AVP_RETURN_IF_ERROR(g.String("name", p.name, true));
      const json* emb = g.Get("embeddings");
      if (emb == nullptr) return g.Missing("embeddings", "the .f32 file");
      AVP_RETURN_IF_ERROR(ParseFileRef(*emb, g, "embeddings", dir, false, p.embeddings));
      const json* names = g.Get("names");
      if (names == nullptr) return g.Missing("names", "the .txt file, one name per line");
      AVP_RETURN_IF_ERROR(ParseFileRef(*names, g, "names", dir, false, p.names));
      AVP_RETURN_IF_ERROR(g.CheckUnknown());
      t.precomputed.push_back(std::move(p));
    }
  }
  return f.CheckUnknown();
}

/// The §4 defaults of each contract, before the manifest's own values.
void ApplyContractDefaults(ModelEntry& e) {
  const std::string& c = e.contract;
  if (c == kYoloWorldTxtFeats || c == kYoloWorldBaked) {
    e.preprocess.height = e.preprocess.width = 640;
    e.preprocess.resize = ResizeMode::kFit;
    e.preprocess.padding = PaddingMode::kCentre;
    e.preprocess.pad_value = 114.0f;
    e.preprocess.pad_space = PadSpace::kPixels;
    e.preprocess.scale = 1.0f / 255.0f;
    e.postprocess.layout = DetectionLayout::kAttributesByAnchors;
    e.postprocess.box_format = BoxFormat::kCxCyWh;
    e.postprocess.score_activation = ScoreActivation::kNone;
  } else if (c == kEvitSamEncoder) {
    e.preprocess.height = e.preprocess.width = 0;  // S, from the model
    e.preprocess.resize = ResizeMode::kFit;
    e.preprocess.padding = PaddingMode::kBottomRight;
    e.preprocess.pad_value = 0.0f;
    e.preprocess.pad_space = PadSpace::kNormalized;
    e.preprocess.mean = {123.675f, 116.28f, 103.53f};
    e.preprocess.stddev = {58.395f, 57.12f, 57.375f};
  } else if (c == kGroundingDinoOrt) {
    e.preprocess.height = 800;
    e.preprocess.width = 1200;
    e.preprocess.resize = ResizeMode::kStretch;
    e.preprocess.padding = PaddingMode::kNone;
    e.preprocess.scale = 1.0f / 255.0f;
    e.preprocess.mean = {0.485f, 0.456f, 0.406f};
    e.preprocess.stddev = {0.229f, 0.224f, 0.225f};
    e.postprocess.box_format = BoxFormat::kCxCyWhNormalized;
    e.postprocess.score_activation = ScoreActivation::kSigmoid;
  }
}

TextConfig DefaultText(const std::string& contract) {
  TextConfig t;
  if (contract == kClipText) {
    t.tokenizer = TokenizerKind::kClipBpe;
    t.context = 77;
  } else if (contract == kGroundingDinoOrt) {
    t.tokenizer = TokenizerKind::kBertWordPiece;
    t.context = 256;
  }
  return t;
}

Status ParseModel(const json& value, Fields& models, const std::string& role, const fs::path& dir,
                  ModelEntry& e) {
  AVP_RETURN_IF_ERROR(ExpectObject(value, models, role));
  Fields f(value, models.path() + "." + role, models.source());
  e.role = role;
  AVP_RETURN_IF_ERROR(f.String("contract", e.contract, true));
  Result<const Contract*> contract = FindContract(e.contract);
  if (!contract.ok()) {
    return NotFoundError(
        fmt::format("{}: {}.contract: {}", f.source(), f.path(), contract.status().message()));
  }
  ApplyContractDefaults(e);

  const json* file = f.Get("file");
  if (file == nullptr) return f.Missing("file", "the .onnx file, relative to the model directory");
  if (!file->is_string())
    return f.Error("file", fmt::format("expected a string, got {}", Describe(*file)));
  AVP_RETURN_IF_ERROR(ParseFileRef(*file, f, "file", dir, false, e.file));
  int64_t bytes = 0;
  AVP_RETURN_IF_ERROR(f.Int("bytes", bytes, true, 0));
  e.file.bytes = static_cast<uint64_t>(bytes);
  std::string sha;
  AVP_RETURN_IF_ERROR(f.String("sha256", sha, false));
  if (!sha.empty()) {
    if (!IsHex64(sha))
      return f.Error("sha256", fmt::format("expected 64 hex digits, got \"{}\"", sha));
    e.file.sha256 = Lower(sha);
  }
  // "licence" (British, as in the design) or "license".
  const bool has_licence = f.Get("licence") != nullptr;
  AVP_RETURN_IF_ERROR(f.String(has_licence ? "licence" : "license", e.licence, false));
  if (e.licence.empty()) return f.Missing("licence", "the artifact's licence, e.g. \"Apache-2.0\"");
  AVP_RETURN_IF_ERROR(f.String("origin", e.origin, true));
  AVP_RETURN_IF_ERROR(f.String("served_as", e.served_as, false));

  if (const json* in = f.Get("inputs"))
    AVP_RETURN_IF_ERROR(ParseTensorList(*in, f, "inputs", e.declared.inputs));
  if (const json* out = f.Get("outputs")) {
    AVP_RETURN_IF_ERROR(ParseTensorList(*out, f, "outputs", e.declared.outputs));
  }
  if (const json* pre = f.Get("preprocess"))
    AVP_RETURN_IF_ERROR(ParsePreprocess(*pre, f, e.preprocess));
  if (const json* post = f.Get("postprocess")) {
    AVP_RETURN_IF_ERROR(ParsePostprocess(*post, f, e.postprocess));
  }
  const bool needs_text = e.contract == kClipText || e.contract == kGroundingDinoOrt;
  if (const json* text = f.Get("text")) {
    TextConfig t = DefaultText(e.contract);
    AVP_RETURN_IF_ERROR(ParseText(*text, f, dir, t));
    e.text = std::move(t);
  } else if (needs_text) {
    return f.Missing("text", fmt::format("{} needs text.vocabulary", e.contract));
  }
  if (e.contract == kYoloWorldBaked && e.postprocess.baked_names.empty()) {
    return f.Error("postprocess",
                   "missing field 'baked_names' (yoloworld.baked/1 needs the class "
                   "names, one per score row)");
  }
  return f.CheckUnknown();
}

}  // namespace

Result<Manifest> ParseManifest(std::string_view json_text, const fs::path& dir,
                               std::string_view source) {
  const std::string src(source);
  json root;
  try {
    root = json::parse(json_text.begin(), json_text.end());
  } catch (const json::parse_error& e) {
    return ParseError(fmt::format("{}: not valid JSON: {}", src, e.what()));
  }
  if (!root.is_object()) {
    return ParseError(fmt::format("{}: expected a JSON object, got {}", src, Describe(root)));
  }
  Manifest m;
  m.dir = dir;
  m.file = dir / kManifestFileName;
  Fields top(root, "manifest", src);
  AVP_RETURN_IF_ERROR(top.String("format", m.format, true));
  if (m.format != kManifestFormat) {
    return top.Error("format",
                     fmt::format("expected \"{}\", got \"{}\"", kManifestFormat, m.format));
  }
  AVP_RETURN_IF_ERROR(top.String("description", m.description, false));
  const json* models = top.Get("models");
  if (models == nullptr) return top.Missing("models", "an object of models by role");
  if (!models->is_object()) {
    return top.Error(
        "models", fmt::format("expected an object of models by role, got {}", Describe(*models)));
  }
  Fields roles(*models, "models", src);
  for (auto it = models->begin(); it != models->end(); ++it) {
    if (!it.key().empty() && it.key()[0] == '_') continue;
    ModelEntry entry;
    roles.Get(it.key());
    AVP_RETURN_IF_ERROR(ParseModel(it.value(), roles, it.key(), dir, entry));
    m.models.emplace(it.key(), std::move(entry));
  }
  AVP_RETURN_IF_ERROR(top.CheckUnknown());
  return m;
}

Result<Manifest> ReadManifest(const fs::path& model_dir) {
  std::error_code ec;
  if (!fs::is_directory(model_dir, ec)) {
    return NotFoundError(fmt::format("model directory '{}' does not exist", model_dir.string()));
  }
  const fs::path file = model_dir / kManifestFileName;
  if (!fs::is_regular_file(file, ec)) {
    return NotFoundError(fmt::format("'{}' does not exist", file.string()));
  }
  std::ifstream in(file, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  if (!in && !in.eof()) return IoError(fmt::format("cannot read '{}'", file.string()));
  AVP_ASSIGN_OR_RETURN(Manifest m, ParseManifest(text.str(), model_dir, file.string()));
  m.file = file;
  return m;
}

// ---- file checks -------------------------------------------------------------------------------

namespace {

Status CheckFile(const std::string& role, const FileRef& ref, const std::string& field,
                 std::string_view what, bool verify_sha256) {
  std::error_code ec;
  if (!fs::is_regular_file(ref.path, ec)) {
    return NotFoundError(fmt::format("{}: {} '{}' does not exist (field models.{}.{})", role, what,
                                     ref.path.string(), role, field));
  }
  if (ref.bytes) {
    const uintmax_t size = fs::file_size(ref.path, ec);
    if (ec)
      return IoError(
          fmt::format("{}: cannot stat '{}': {}", role, ref.path.string(), ec.message()));
    if (size != *ref.bytes) {
      return InvalidArgumentError(
          fmt::format("{}: '{}' has {} bytes; models.{}.{} says {}", role, ref.path.string(), size,
                      role, field == "file" ? "bytes" : field + ".bytes", *ref.bytes));
    }
  }
  if (verify_sha256 && ref.sha256) {
    AVP_ASSIGN_OR_RETURN(const std::string sha, FileSha256(ref.path));
    if (sha != *ref.sha256) {
      return InvalidArgumentError(
          fmt::format("{}: '{}' has sha256 {}; models.{}.{} says {}", role, ref.path.string(), sha,
                      role, field == "file" ? "sha256" : field + ".sha256", *ref.sha256));
    }
  }
  return Status::Ok();
}

}  // namespace

Status CheckFiles(const ModelEntry& entry, bool verify_sha256, bool model_file) {
  if (model_file) {
    AVP_RETURN_IF_ERROR(CheckFile(entry.role, entry.file, "file", "model file", verify_sha256));
  }
  if (entry.text) {
    AVP_RETURN_IF_ERROR(CheckFile(entry.role, entry.text->vocabulary, "text.vocabulary",
                                  "vocabulary file", verify_sha256));
    for (size_t i = 0; i < entry.text->precomputed.size(); ++i) {
      const PrecomputedVocabulary& p = entry.text->precomputed[i];
      AVP_RETURN_IF_ERROR(CheckFile(entry.role, p.embeddings,
                                    fmt::format("text.precomputed[{}].embeddings", i),
                                    "precomputed embeddings", verify_sha256));
      AVP_RETURN_IF_ERROR(CheckFile(entry.role, p.names,
                                    fmt::format("text.precomputed[{}].names", i),
                                    "precomputed names", verify_sha256));
    }
  }
  return Status::Ok();
}

// ---- backends ----------------------------------------------------------------------------------

Result<std::vector<std::string>> BackendRoles(std::string_view backend, const Manifest& manifest) {
  if (backend == kBackendYwes) {
    std::vector<std::string> roles = {kRoleDetector};
    const ModelEntry* detector = manifest.Find(kRoleDetector);
    if (detector == nullptr || detector->contract != kYoloWorldBaked) roles.push_back(kRoleText);
    roles.push_back(kRoleSegmenterEncoder);
    roles.push_back(kRoleSegmenterDecoder);
    return roles;
  }
  if (backend == kBackendLsam) {
    return std::vector<std::string>{kRoleGrounding, kRoleSegmenterEncoder, kRoleSegmenterDecoder};
  }
  return InvalidArgumentError(
      fmt::format("unknown backend '{}' (expected {} or {})", backend, kBackendYwes, kBackendLsam));
}

std::string_view ToString(BackendState state) {
  switch (state) {
    case BackendState::kReady:
      return "READY";
    case BackendState::kMissing:
      return "MISSING";
    case BackendState::kInvalid:
      return "INVALID";
  }
  return "INVALID";
}

std::string LoadedBackend::StateString() const {
  if (state == BackendState::kReady) return "READY";
  return fmt::format("{}({})", ToString(state), reason);
}

const LoadedModel* LoadedBackend::Find(std::string_view role) const {
  auto it = models.find(std::string(role));
  return it == models.end() ? nullptr : &it->second;
}

std::optional<fs::path> ModelDirFromEnvironment() {
  const char* dir = std::getenv(kModelDirEnvVar);
  if (dir == nullptr || *dir == '\0') return std::nullopt;
  return fs::path(dir);
}

namespace {

/// The contracts a role accepts.
std::vector<std::string> ContractsFor(const std::string& role) {
  if (role == kRoleDetector) return {kYoloWorldTxtFeats, kYoloWorldBaked};
  if (role == kRoleText) return {kClipText};
  if (role == kRoleSegmenterEncoder) return {kEvitSamEncoder};
  if (role == kRoleSegmenterDecoder) return {kEvitSamDecoderSingle};
  if (role == kRoleGrounding) return {kGroundingDinoOrt};
  return {};
}

/// The image input of a contract (checked against preprocess.size), or nullptr.
const char* ImageInput(const std::string& contract) {
  if (contract == kYoloWorldTxtFeats || contract == kYoloWorldBaked) return "images";
  if (contract == kEvitSamEncoder) return "input_image";
  if (contract == kGroundingDinoOrt) return "img";
  return nullptr;
}

/// preprocess.size against the model's static image size; fills a size the manifest leaves out.
Status ResolveImageSize(LoadedModel& m) {
  const char* input = ImageInput(m.entry.contract);
  if (input == nullptr) return Status::Ok();
  const TensorInfo* t = m.model.io().FindInput(m.binding.Name(input));
  if (t == nullptr || t->shape.size() != 4) return Status::Ok();  // the contract check reported it
  const int64_t h = t->shape[2];
  const int64_t w = t->shape[3];
  Preprocess& p = m.entry.preprocess;
  const std::string& role = m.entry.role;
  const bool given = p.height > 0 && p.width > 0;
  const bool mismatch =
      (h != kDynamicDim && given && h != p.height) || (w != kDynamicDim && given && w != p.width);
  if (mismatch) {
    const std::string what =
        m.entry.contract == kEvitSamEncoder ? fmt::format(" (S = {})", m.binding.Dim("S")) : "";
    return InvalidArgumentError(
        fmt::format("{}: preprocess.size [{},{}] differs from the model's {} size [{},{}]{}", role,
                    p.height, p.width, t->name, h, w, what));
  }
  if (!given) {
    if (h == kDynamicDim || w == kDynamicDim) {
      return InvalidArgumentError(
          fmt::format("{}: input '{}' has a dynamic size {}; set preprocess.size in the manifest",
                      role, t->name, ShapeToString(t->shape)));
    }
    p.height = static_cast<int>(h);
    p.width = static_cast<int>(w);
  }
  return Status::Ok();
}

Status CrossCheck(std::map<std::string, LoadedModel>& models) {
  auto find = [&](const char* role) -> LoadedModel* {
    auto it = models.find(role);
    return it == models.end() ? nullptr : &it->second;
  };
  for (auto& [role, m] : models) AVP_RETURN_IF_ERROR(ResolveImageSize(m));

  if (LoadedModel* det = find(kRoleDetector)) {
    Postprocess& post = det->entry.postprocess;
    const std::string& out_name = det->binding.Name("output0");
    const TensorInfo* out = det->model.io().FindOutput(out_name);
    const std::string out_shape = out != nullptr ? ShapeToString(out->shape) : "?";
    if (det->entry.contract == kYoloWorldTxtFeats) {
      const int64_t n = det->binding.Dim("N");
      if (n == kDynamicDim && post.n_max == 0) {
        return InvalidArgumentError(
            "detector: txt_feats has a dynamic class dimension N; set postprocess.n_max");
      }
      if (n != kDynamicDim && post.n_max != 0 && post.n_max != n) {
        return InvalidArgumentError(
            fmt::format("detector: postprocess.n_max ({}) differs from the model's N ({}; {} {})",
                        post.n_max, n, out_name, out_shape));
      }
      if (n != kDynamicDim) post.n_max = static_cast<int>(n);
      if (LoadedModel* text = find(kRoleText)) {
        const TensorInfo* emb = text->model.io().FindOutput(text->binding.Name("text_embeds"));
        const int64_t text_width = emb != nullptr && emb->shape.size() == 2 ? emb->shape[1] : 512;
        const TensorInfo* feats = det->model.io().FindInput(det->binding.Name("txt_feats"));
        const int64_t feats_width =
            feats != nullptr && feats->shape.size() == 3 ? feats->shape[2] : 512;
        if (text_width != feats_width) {
          return InvalidArgumentError(fmt::format(
              "detector: txt_feats width {} differs from the text model's text_embeds width {}",
              feats_width, text_width));
        }
        if (text->entry.text && text->entry.text->dim != text_width) {
          return InvalidArgumentError(
              fmt::format("text: text.dim ({}) differs from the model's text_embeds width {}",
                          text->entry.text->dim, text_width));
        }
        if (text->entry.text && text->entry.text->context != 77) {
          return InvalidArgumentError(fmt::format(
              "text: text.context ({}) differs from clip.text/1's 77 input_ids positions",
              text->entry.text->context));
        }
      }
    } else {
      const int64_t nc = det->binding.Dim("NC");
      const auto names = static_cast<int64_t>(post.baked_names.size());
      if (nc != kDynamicDim && nc != names) {
        return InvalidArgumentError(fmt::format(
            "detector: postprocess.baked_names has {} names; the model has NC = {} class rows "
            "({} {})",
            names, nc, out_name, out_shape));
      }
      post.n_max = static_cast<int>(names);
    }
  }

  LoadedModel* enc = find(kRoleSegmenterEncoder);
  LoadedModel* dec = find(kRoleSegmenterDecoder);
  if (enc != nullptr && dec != nullptr) {
    const TensorInfo* produced = enc->model.io().FindOutput("image_embeddings");
    const TensorInfo* consumed = dec->model.io().FindInput("image_embeddings");
    if (produced != nullptr && consumed != nullptr) {
      bool same = produced->shape.size() == consumed->shape.size();
      for (size_t i = 0; same && i < produced->shape.size(); ++i) {
        const int64_t a = produced->shape[i];
        const int64_t b = consumed->shape[i];
        if (a != kDynamicDim && b != kDynamicDim && a != b) same = false;
      }
      if (!same) {
        return InvalidArgumentError(fmt::format(
            "segmenter.decoder: input 'image_embeddings' {} differs from the encoder's output {}",
            ShapeToString(consumed->shape), ShapeToString(produced->shape)));
      }
    }
  }
  if (dec != nullptr) {
    const Postprocess& post = dec->entry.postprocess;
    if (post.low_res != 256) {
      return InvalidArgumentError(fmt::format(
          "segmenter.decoder: postprocess.low_res ({}) differs from the model's 256x256 masks",
          post.low_res));
    }
  }
  if (LoadedModel* gd = find(kRoleGrounding)) {
    const int64_t l = gd->binding.Dim("L");
    const int context = gd->entry.text ? gd->entry.text->context : 256;
    if (context > 256) {
      return InvalidArgumentError(fmt::format(
          "grounding: text.context ({}) exceeds the 256 token slots of 'logits'", context));
    }
    if (l != kDynamicDim && l > context) {
      return InvalidArgumentError(fmt::format(
          "grounding: the model's text length L = {} exceeds text.context ({})", l, context));
    }
  }
  return Status::Ok();
}

/// Zero inputs for a warm-up run: dynamic axes become 1.
Status WarmUp(const LoadedModel& m, double& ms) {
  std::vector<std::vector<float>> f32;
  std::vector<std::vector<int64_t>> i64;
  std::vector<std::vector<uint8_t>> b;
  f32.reserve(m.model.inputs().size());
  i64.reserve(m.model.inputs().size());
  b.reserve(m.model.inputs().size());
  std::vector<InputTensor> inputs;
  for (const TensorInfo& t : m.model.inputs()) {
    std::vector<int64_t> shape = t.shape;
    size_t n = 1;
    for (int64_t& d : shape) {
      if (d == kDynamicDim) d = 1;
      n *= static_cast<size_t>(d);
    }
    switch (t.type) {
      case ElementType::kFloat32:
        f32.emplace_back(n, 0.0f);
        inputs.push_back(InputTensor::Float32(t.name, f32.back(), shape));
        break;
      case ElementType::kInt64:
        i64.emplace_back(n, 0);
        inputs.push_back(InputTensor::Int64(t.name, i64.back(), shape));
        break;
      case ElementType::kBool:
        b.emplace_back(n, uint8_t{1});
        inputs.push_back(InputTensor::Bool(t.name, b.back(), shape));
        break;
      default:
        return Status::Ok();  // not a type Run binds: no warm-up for this model
    }
  }
  const auto start = std::chrono::steady_clock::now();
  Result<std::vector<OutputTensor>> out = m.model.Run(inputs);
  ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (!out.ok()) return out.status().WithContext("warm-up");
  return Status::Ok();
}

LoadedBackend Fail(LoadedBackend out, Status status) {
  out.state =
      status.code() == StatusCode::kNotFound ? BackendState::kMissing : BackendState::kInvalid;
  out.reason = status.message();
  out.status = std::move(status);
  out.models.clear();
  return out;
}

}  // namespace

LoadedBackend LoadBackend(std::string_view backend, const fs::path& model_dir,
                          const BackendLoadOptions& options) {
  Result<Manifest> manifest = ReadManifest(model_dir);
  if (!manifest.ok()) {
    LoadedBackend out;
    out.backend = std::string(backend);
    out.model_dir = model_dir;
    return Fail(std::move(out), manifest.status());
  }
  return LoadBackend(backend, *manifest, options);
}

LoadedBackend LoadBackend(std::string_view backend, const Manifest& manifest,
                          const BackendLoadOptions& options) {
  LoadedBackend out;
  out.backend = std::string(backend);
  out.model_dir = manifest.dir;
  Result<std::vector<std::string>> roles = BackendRoles(backend, manifest);
  if (!roles.ok()) return Fail(std::move(out), roles.status());

  // 1. Every role is listed, with a contract that can serve it, and its files are there.
  for (const std::string& role : *roles) {
    const ModelEntry* entry = manifest.Find(role);
    const std::vector<std::string> accepted = ContractsFor(role);
    if (entry == nullptr) {
      std::vector<std::string> listed;
      for (const auto& [r, e] : manifest.models) listed.push_back(r);
      return Fail(std::move(out),
                  NotFoundError(fmt::format(
                      "{} needs model role '{}' ({}); {} lists {}", backend, role,
                      fmt::join(accepted, " or "), manifest.file.string(),
                      listed.empty() ? "none" : fmt::format("{}", fmt::join(listed, ", ")))));
    }
    if (std::find(accepted.begin(), accepted.end(), entry->contract) == accepted.end()) {
      return Fail(std::move(out), InvalidArgumentError(fmt::format(
                                      "{}: contract {} cannot serve this role (expected {})", role,
                                      entry->contract, fmt::join(accepted, " or "))));
    }
  }
  // With a model server the networks are there, not here: only the text files are needed.
  const bool remote = !options.session.model_server.empty();
  for (const std::string& role : *roles) {
    Status files = CheckFiles(*manifest.Find(role), options.verify_sha256, !remote);
    if (!files.ok()) return Fail(std::move(out), files);
  }

  // 2-3. One session (or one model of the server) per role, checked against its contract and
  // the declared I/O.
  for (const std::string& role : *roles) {
    const ModelEntry& entry = *manifest.Find(role);
    Result<ModelRef> model =
        remote ? ConnectRemoteModel(options.session.model_server, entry.ServedName(), role)
               : LoadBatchedOrtModel(entry.file.path, options.session, role);
    if (!model.ok() && remote) return Fail(std::move(out), model.status());
    if (!model.ok()) {
      Status s = model.status();
      // A file that exists but does not load is INVALID, not MISSING.
      if (s.code() == StatusCode::kNotFound) s = InvalidArgumentError(s.message());
      return Fail(std::move(out), s);
    }
    Result<const Contract*> contract = FindContract(entry.contract);
    if (!contract.ok())
      return Fail(std::move(out), InvalidArgumentError(contract.status().message()));
    ContractCheckOptions check;
    check.transposed_layout = entry.postprocess.layout == DetectionLayout::kAnchorsByAttributes;
    const bool declared = !entry.declared.inputs.empty() || !entry.declared.outputs.empty();
    Result<ContractBinding> binding =
        CheckContract(role, model->io(), **contract, declared ? &entry.declared : nullptr, check);
    if (!binding.ok()) return Fail(std::move(out), binding.status());
    out.models.emplace(role,
                       LoadedModel{entry, std::move(model).value(), std::move(binding).value()});
  }

  // 4. Cross-checks between the models.
  Status cross = CrossCheck(out.models);
  if (!cross.ok()) return Fail(std::move(out), cross);

  // 5. Optional warm-up.
  if (options.warm_up) {
    std::vector<std::string> times;
    for (const std::string& role : *roles) {
      double ms = 0.0;
      Status warm = WarmUp(out.models.at(role), ms);
      if (!warm.ok()) return Fail(std::move(out), warm);
      times.push_back(fmt::format("{} {:.1f} ms", role, ms));
    }
    std::fprintf(stderr, "avp zsl: %s warm-up (%s): %s\n", out.backend.c_str(),
                 out.models.begin()->second.model.provider().c_str(),
                 fmt::format("{}", fmt::join(times, ", ")).c_str());
  }
  out.state = BackendState::kReady;
  out.status = Status::Ok();
  return out;
}

}  // namespace avp::zsl

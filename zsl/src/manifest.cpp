// manifest.json parsing and validation (design: zero-shot-models.md §7); the files it names
// and a backend's start-up are in backend_loader.cpp.
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

}  // namespace avp::zsl

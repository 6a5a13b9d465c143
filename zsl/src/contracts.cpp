// Built-in model I/O contracts and the check against them (design: zero-shot-models.md §4, §7).
#include "contracts.h"

#include <algorithm>
#include <optional>
#include <utility>

#include <fmt/format.h>

namespace avp::zsl {

std::string DimSpec::ToString() const {
  if (fixed()) return std::to_string(value);
  if (offset == 0) return symbol;
  if (offset > 0) return fmt::format("{}+{}", offset, symbol);
  return fmt::format("{}{}", symbol, offset);
}

std::string ShapeToString(std::span<const DimSpec> shape) {
  std::vector<std::string> dims;
  for (const DimSpec& d : shape) dims.push_back(d.ToString());
  return fmt::format("[{}]", fmt::join(dims, ","));
}

const TensorSpec* Contract::FindInput(std::string_view name) const {
  for (const TensorSpec& t : inputs) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

const TensorSpec* Contract::FindOutput(std::string_view name) const {
  for (const TensorSpec& t : outputs) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

namespace {

DimSpec F(int64_t v) { return DimSpec::Fixed(v); }
DimSpec S(std::string s, int64_t offset = 0) { return DimSpec::Symbol(std::move(s), offset); }

TensorSpec T(std::string name, ElementType type, std::vector<DimSpec> shape) {
  TensorSpec t;
  t.name = std::move(name);
  t.type = type;
  t.shape = std::move(shape);
  return t;
}

TensorSpec YoloOutput(const std::string& classes) {
  TensorSpec t = T("output0", ElementType::kFloat32, {F(1), S(classes, 4), F(8400)});
  t.alt_names = {"output"};
  t.transposed_shape = {F(1), F(8400), S(classes, 4)};
  return t;
}

std::vector<Contract> MakeContracts() {
  constexpr ElementType f32 = ElementType::kFloat32;
  constexpr ElementType i64 = ElementType::kInt64;
  constexpr ElementType b = ElementType::kBool;
  std::vector<Contract> all;
  all.push_back({kYoloWorldTxtFeats,
                 "YOLO-World with text-feature input (Ultralytics v2 export, fixed N_max)",
                 {T("images", f32, {F(1), F(3), F(640), F(640)}),
                  T("txt_feats", f32, {F(1), S("N"), F(512)})},
                 {YoloOutput("N")}});
  all.push_back({kYoloWorldBaked,
                 "YOLO-World with its vocabulary baked in (set_classes, then export)",
                 {T("images", f32, {F(1), F(3), F(640), F(640)})},
                 {YoloOutput("NC")}});
  all.push_back(
      {kClipText,
       "CLIP ViT-B/32 text encoder, pooled at argmax(input_ids), projected, not normalised",
       {T("input_ids", i64, {S("B"), F(77)})},
       {T("text_embeds", f32, {S("B"), F(512)})}});
  all.push_back({kEvitSamEncoder,
                 "EfficientViT-SAM image encoder (S = 512 for L0-L2, 1024 for XL0/XL1)",
                 {T("input_image", f32, {F(1), F(3), S("S"), S("S")})},
                 {T("image_embeddings", f32, {F(1), F(256), F(64), F(64)})}});
  all.push_back(
      {kEvitSamDecoderSingle,
       "EfficientViT-SAM prompt decoder, --return-single-mask, low-res logits",
       {T("image_embeddings", f32, {F(1), F(256), F(64), F(64)}),
        T("point_coords", f32, {S("B"), S("P"), F(2)}), T("point_labels", f32, {S("B"), S("P")})},
       {T("masks", f32, {S("B"), F(1), F(256), F(256)}),
        T("iou_predictions", f32, {S("B"), F(1)})}});
  all.push_back(
      {kGroundingDinoOrt,
       "Grounding DINO, the ORT export of hpc203/GroundingDINO-onnxrun (800x1200)",
       {T("img", f32, {F(1), F(3), F(800), F(1200)}), T("input_ids", i64, {F(1), S("L")}),
        T("attention_mask", b, {F(1), S("L")}), T("position_ids", i64, {F(1), S("L")}),
        T("token_type_ids", i64, {F(1), S("L")}), T("text_token_mask", b, {F(1), S("L"), S("L")})},
       {T("logits", f32, {F(1), F(900), F(256)}), T("boxes", f32, {F(1), F(900), F(4)})}});
  return all;
}

std::string Quoted(const std::vector<TensorInfo>& tensors) {
  if (tensors.empty()) return "none";
  std::vector<std::string> names;
  for (const TensorInfo& t : tensors) names.push_back("'" + t.name + "'");
  return fmt::format("{}", fmt::join(names, ", "));
}

std::string SpecNames(const TensorSpec& spec) {
  if (spec.alt_names.empty()) return spec.name;
  return fmt::format("{} (or {})", spec.name, fmt::join(spec.alt_names, ", "));
}

const TensorInfo* FindByNames(const std::vector<TensorInfo>& tensors, const TensorSpec& spec) {
  for (const TensorInfo& t : tensors) {
    if (t.name == spec.name) return &t;
  }
  for (const std::string& alt : spec.alt_names) {
    for (const TensorInfo& t : tensors) {
      if (t.name == alt) return &t;
    }
  }
  return nullptr;
}

/// A symbol's value and where it was first seen.
struct Bound {
  int64_t value = 0;
  std::string from;
};
using Symbols = std::map<std::string, Bound>;

/// Compares `model` with `expected` (same rank), binding symbols in `symbols`. Returns the
/// problems, e.g. "dim 2 is 32, not 64" or "dim 1 is 84, not 4+N = 36 (N = 32 from input
/// 'txt_feats')".
std::vector<std::string> MatchDims(const std::vector<int64_t>& model,
                                   const std::vector<DimSpec>& expected, const std::string& where,
                                   Symbols& symbols) {
  std::vector<std::string> problems;
  for (size_t d = 0; d < expected.size(); ++d) {
    const int64_t m = model[d];
    const DimSpec& e = expected[d];
    if (m == kDynamicDim) continue;  // a dynamic axis can take the expected size
    if (e.fixed()) {
      if (m != e.value) problems.push_back(fmt::format("dim {} is {}, not {}", d, m, e.value));
      continue;
    }
    const int64_t v = m - e.offset;
    if (v < 1) {
      problems.push_back(
          fmt::format("dim {} is {}, not {} with {} >= 1", d, m, e.ToString(), e.symbol));
      continue;
    }
    auto it = symbols.find(e.symbol);
    if (it == symbols.end()) {
      symbols[e.symbol] = {v, where};
    } else if (it->second.value != v) {
      problems.push_back(fmt::format("dim {} is {}, not {} = {} ({} = {} from {})", d, m,
                                     e.ToString(), it->second.value + e.offset, e.symbol,
                                     it->second.value, it->second.from));
    }
  }
  return problems;
}

bool Matches(const std::vector<int64_t>& model, const std::vector<DimSpec>& expected,
             Symbols symbols /* a copy */) {
  return model.size() == expected.size() && MatchDims(model, expected, "", symbols).empty();
}

/// The manifest's declared I/O against the model's.
void CheckDeclared(std::string_view role, const char* kind, const std::vector<TensorInfo>& model,
                   const std::vector<TensorInfo>& declared, bool require_all,
                   std::vector<std::string>& errors) {
  for (const TensorInfo& d : declared) {
    const TensorInfo* t = nullptr;
    for (const TensorInfo& m : model) {
      if (m.name == d.name) t = &m;
    }
    if (t == nullptr) {
      errors.push_back(
          fmt::format("{}: the manifest declares {} '{}', which the model does not "
                      "have (it has {})",
                      role, kind, d.name, Quoted(model)));
      continue;
    }
    if (t->type != d.type) {
      errors.push_back(fmt::format("{}: {} '{}' is {}; the manifest declares {}", role, kind,
                                   d.name, ToString(t->type), ToString(d.type)));
    }
    // -1 on either side matches: the manifest may leave a dimension open, and it may state
    // one the graph leaves dynamic (the official EfficientViT-SAM encoder export has a dynamic
    // batch axis and symbolic 64 x 64 output dimensions); the stated value is then checked
    // against the contract instead (CheckContract).
    bool same = t->shape.size() == d.shape.size();
    for (size_t i = 0; same && i < d.shape.size(); ++i) {
      if (d.shape[i] != kDynamicDim && t->shape[i] != kDynamicDim && d.shape[i] != t->shape[i]) {
        same = false;
      }
    }
    if (!same) {
      errors.push_back(fmt::format("{}: {} '{}' has shape {}; the manifest declares {}", role, kind,
                                   d.name, ShapeToString(t->shape), ShapeToString(d.shape)));
    }
  }
  if (!require_all || declared.empty()) return;
  for (const TensorInfo& m : model) {
    const bool listed = std::any_of(declared.begin(), declared.end(),
                                    [&](const TensorInfo& d) { return d.name == m.name; });
    if (!listed) {
      errors.push_back(
          fmt::format("{}: the model's {} '{}' ({} {}) is not declared in the manifest", role, kind,
                      m.name, ToString(m.type), ShapeToString(m.shape)));
    }
  }
}

}  // namespace

const std::vector<Contract>& BuiltinContracts() {
  static const std::vector<Contract> contracts = MakeContracts();
  return contracts;
}

Result<const Contract*> FindContract(std::string_view id) {
  std::vector<std::string> ids;
  for (const Contract& c : BuiltinContracts()) {
    if (c.id == id) return &c;
    ids.push_back(c.id);
  }
  return NotFoundError(
      fmt::format("unknown contract '{}' (built in: {})", id, fmt::join(ids, ", ")));
}

const std::string& ContractBinding::Name(const std::string& name) const {
  auto it = names.find(name);
  return it == names.end() ? name : it->second;
}

int64_t ContractBinding::Dim(const std::string& symbol) const {
  auto it = dims.find(symbol);
  return it == dims.end() ? kDynamicDim : it->second;
}

namespace {

/// The shapes checked against the contract: the graph's, with each dimension it leaves dynamic
/// and the manifest states filled in from the manifest (whose statements are checked first).
ModelIo EffectiveShapes(std::string_view role, const ModelIo& io, const ModelIo* declared,
                        std::vector<std::string>& errors) {
  ModelIo effective = io;
  if (declared == nullptr) return effective;
  CheckDeclared(role, "input", io.inputs, declared->inputs, /*require_all=*/true, errors);
  CheckDeclared(role, "output", io.outputs, declared->outputs, /*require_all=*/false, errors);
  const auto narrow = [](std::vector<TensorInfo>& tensors, const std::vector<TensorInfo>& stated) {
    for (TensorInfo& t : tensors) {
      for (const TensorInfo& d : stated) {
        if (d.name != t.name || d.shape.size() != t.shape.size()) continue;
        for (size_t i = 0; i < t.shape.size(); ++i) {
          if (t.shape[i] == kDynamicDim) t.shape[i] = d.shape[i];
        }
      }
    }
  };
  narrow(effective.inputs, declared->inputs);
  narrow(effective.outputs, declared->outputs);
  return effective;
}

/// One tensor of the contract against the model's: present (binding its name), of the type, rank
/// and shape the contract expects (binding its symbols), or an error line naming what differs.
void CheckTensor(std::string_view role, const char* kind, const TensorSpec& spec,
                 const std::vector<TensorInfo>& tensors, const Contract& contract,
                 const ContractCheckOptions& options, Symbols& symbols, ContractBinding& binding,
                 std::vector<std::string>& errors) {
  const TensorInfo* t = FindByNames(tensors, spec);
  if (t == nullptr) {
    errors.push_back(fmt::format("{}: {} '{}' is missing (the model has {}); {} expects {} {} {}",
                                 role, kind, spec.name, Quoted(tensors), contract.id,
                                 SpecNames(spec), ToString(spec.type), ShapeToString(spec.shape)));
    return;
  }
  binding.names[spec.name] = t->name;
  if (t->type != spec.type) {
    errors.push_back(fmt::format("{}: {} '{}' is {}; {} expects {}", role, kind, t->name,
                                 ToString(t->type), contract.id, ToString(spec.type)));
  }
  const bool transposed = options.transposed_layout && !spec.transposed_shape.empty();
  const std::vector<DimSpec>& expected = transposed ? spec.transposed_shape : spec.shape;
  if (t->shape.size() != expected.size()) {
    errors.push_back(fmt::format("{}: {} '{}' has rank {} ({}); {} expects rank {} {}", role, kind,
                                 t->name, t->shape.size(), ShapeToString(t->shape), contract.id,
                                 expected.size(), ShapeToString(expected)));
    return;
  }
  const Symbols before = symbols;
  const std::string where = fmt::format("{} '{}'", kind, t->name);
  const std::vector<std::string> problems = MatchDims(t->shape, expected, where, symbols);
  if (problems.empty()) {
    if (transposed) binding.transposed = true;
    return;
  }
  std::string line = fmt::format("{}: {} '{}' has shape {}; {} expects {} ({})", role, kind,
                                 t->name, ShapeToString(t->shape), contract.id,
                                 ShapeToString(expected), fmt::join(problems, ", "));
  if (!spec.transposed_shape.empty()) {
    const std::vector<DimSpec>& other = transposed ? spec.shape : spec.transposed_shape;
    if (Matches(t->shape, other, before)) {
      line += transposed ? "; the manifest declares postprocess.layout \"[A,4+N]\" but this is "
                           "the [4+N,A] layout"
                         : "; this is the transposed [A,4+N] layout: declare it with "
                           "postprocess.layout \"[A,4+N]\"";
    }
  }
  errors.push_back(std::move(line));
}

/// A required input the contract does not know cannot be fed: an error line for each.
void CheckUnknownInputs(std::string_view role, const ModelIo& io, const Contract& contract,
                        std::vector<std::string>& errors) {
  for (const TensorInfo& t : io.inputs) {
    bool known = false;
    for (const TensorSpec& spec : contract.inputs) {
      if (t.name == spec.name ||
          std::find(spec.alt_names.begin(), spec.alt_names.end(), t.name) != spec.alt_names.end()) {
        known = true;
      }
    }
    if (!known) {
      std::vector<std::string> names;
      for (const TensorSpec& spec : contract.inputs) names.push_back(spec.name);
      errors.push_back(fmt::format("{}: input '{}' ({} {}) is not part of {} (its inputs are {})",
                                   role, t.name, ToString(t.type), ShapeToString(t.shape),
                                   contract.id, fmt::join(names, ", ")));
    }
  }
}

}  // namespace

Result<ContractBinding> CheckContract(std::string_view role, const ModelIo& io,
                                      const Contract& contract, const ModelIo* declared,
                                      const ContractCheckOptions& options) {
  std::vector<std::string> errors;
  const ModelIo effective = EffectiveShapes(role, io, declared, errors);
  ContractBinding binding;
  binding.contract = contract.id;
  Symbols symbols;
  for (const TensorSpec& spec : contract.inputs) {
    CheckTensor(role, "input", spec, effective.inputs, contract, options, symbols, binding, errors);
  }
  for (const TensorSpec& spec : contract.outputs) {
    CheckTensor(role, "output", spec, effective.outputs, contract, options, symbols, binding,
                errors);
  }
  CheckUnknownInputs(role, io, contract, errors);
  if (!errors.empty()) return InvalidArgumentError(fmt::format("{}", fmt::join(errors, "; ")));
  // Every symbol of the contract gets a value: kDynamicDim when no occurrence is static.
  for (const std::vector<TensorSpec>* side : {&contract.inputs, &contract.outputs}) {
    for (const TensorSpec& spec : *side) {
      for (const auto* shape : {&spec.shape, &spec.transposed_shape}) {
        for (const DimSpec& d : *shape) {
          if (!d.fixed()) binding.dims.emplace(d.symbol, kDynamicDim);
        }
      }
    }
  }
  for (const auto& [symbol, bound] : symbols) binding.dims[symbol] = bound.value;
  return binding;
}

}  // namespace avp::zsl

#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>

#include "ort_runtime.h"

namespace avp::zsl {

/// Built-in model I/O contracts (design: zero-shot-models.md §4, §7 step 3), as data, and the check
/// of a loaded model against one of them and against the manifest's declared I/O.
///
///  - `yoloworld.txtfeats/1`: images f32 [1,3,640,640], txt_feats f32 [1,N,512]
///    -> output0 (or output) f32 [1,4+N,8400]
///  - `yoloworld.baked/1`: images f32 [1,3,640,640] -> output0 (or output) f32 [1,4+NC,8400]
///  - `clip.text/1`: input_ids int64 [B,77] -> text_embeds f32 [B,512]
///  - `evitsam.encoder/1`: input_image f32 [1,3,S,S] -> image_embeddings f32 [1,256,64,64]
///  - `evitsam.decoder.single/1`: image_embeddings f32 [1,256,64,64], point_coords f32 [B,P,2],
///    point_labels f32 [B,P] -> masks f32 [B,1,256,256], iou_predictions f32 [B,1]
///  - `gdino.ort/1`: img f32 [1,3,800,1200], input_ids / position_ids / token_type_ids int64
///    [1,L], attention_mask bool [1,L], text_token_mask bool [1,L,L]
///    -> logits f32 [1,900,256], boxes f32 [1,900,4]
///
/// Symbols (N, NC, B, P, S, L) stand for dimensions that the export fixes or leaves dynamic: every
/// static occurrence of a symbol must agree, and the check reports their values
/// (`ContractBinding`). The YOLO-World outputs may instead be transposed, [1,8400,4+N], when the
/// manifest declares `postprocess.layout` "[A,4+N]".

// Contract ids.
inline constexpr const char* kYoloWorldTxtFeats = "yoloworld.txtfeats/1";
inline constexpr const char* kYoloWorldBaked = "yoloworld.baked/1";
inline constexpr const char* kClipText = "clip.text/1";
inline constexpr const char* kEvitSamEncoder = "evitsam.encoder/1";
inline constexpr const char* kEvitSamDecoderSingle = "evitsam.decoder.single/1";
inline constexpr const char* kGroundingDinoOrt = "gdino.ort/1";

/// One dimension of a contract shape: a fixed size, or `symbol + offset` (e.g. "4+N").
struct DimSpec {
  int64_t value = 0;   ///< the size when `symbol` is empty
  std::string symbol;  ///< non-empty: the dimension is symbol + offset
  int64_t offset = 0;

  static DimSpec Fixed(int64_t v) { return {v, "", 0}; }
  static DimSpec Symbol(std::string s, int64_t offset = 0) { return {0, std::move(s), offset}; }
  bool fixed() const { return symbol.empty(); }
  /// "640", "N", "4+N".
  std::string ToString() const;
};

/// "[1,4+N,8400]".
std::string ShapeToString(std::span<const DimSpec> shape);

/// One input or output a contract requires.
struct TensorSpec {
  std::string name;                    ///< the canonical name
  std::vector<std::string> alt_names;  ///< other accepted names ("output" for "output0")
  ElementType type = ElementType::kFloat32;
  std::vector<DimSpec> shape;
  /// Non-empty for the YOLO-World output: the shape accepted when the manifest declares the
  /// transposed layout "[A,4+N]".
  std::vector<DimSpec> transposed_shape;
};

/// A built-in contract: id, a one-line description, required inputs (a model may have no others)
/// and required outputs (a model may have more).
struct Contract {
  std::string id;
  std::string description;
  std::vector<TensorSpec> inputs;
  std::vector<TensorSpec> outputs;

  const TensorSpec* FindInput(std::string_view name) const;
  const TensorSpec* FindOutput(std::string_view name) const;
};

/// The six contracts above, in that order.
const std::vector<Contract>& BuiltinContracts();

/// The contract with this id. Errors: NotFound "unknown contract 'x/1' (built in: …)".
Result<const Contract*> FindContract(std::string_view id);

/// What the check found: the model's actual tensor names and the values of the contract's symbols.
struct ContractBinding {
  std::string contract;
  /// Contract tensor name → the model's name (they differ only for alternative names, e.g.
  /// "output0" → "output").
  std::map<std::string, std::string> names;
  /// Symbol → value; kDynamicDim (-1) when every occurrence is dynamic in the model.
  std::map<std::string, int64_t> dims;
  /// True when the model's YOLO-World output is [1,A,4+N] (declared "[A,4+N]").
  bool transposed = false;

  /// The model's name for contract tensor `name` (`name` itself when not bound).
  const std::string& Name(const std::string& name) const;
  /// The symbol's value, or kDynamicDim when dynamic or unknown.
  int64_t Dim(const std::string& symbol) const;
};

/// How the manifest qualifies the check.
struct ContractCheckOptions {
  /// The manifest declares the YOLO-World layout "[A,4+N]": expect `transposed_shape`.
  bool transposed_layout = false;
};

/// Compares a model's I/O with `contract` and, when `declared` is given, with the manifest's
/// declared inputs/outputs. Every problem is reported, as one line each joined by "; ", each
/// starting with `role` and naming the tensor and the expectation, e.g.
///   "segmenter.decoder: input 'point_labels' is int32; evitsam.decoder.single/1 expects float32"
///   "detector: input 'images' is missing (the model has 'image', 'txt_feats');
///    yoloworld.txtfeats/1 expects images float32 [1,3,640,640]"
///   "detector: input 'txt_feats' has rank 2 ([32,512]); yoloworld.txtfeats/1 expects rank 3
///    [1,N,512]"
///   "segmenter.encoder: output 'image_embeddings' has shape [1,256,32,32]; evitsam.encoder/1
///    expects [1,256,64,64] (dim 2 is 32, not 64)"
///   "segmenter.decoder: output 'iou_predictions' is missing (the model has 'masks'); …"
///   "detector: input 'txt_feats' has shape [1,32,512]; the manifest declares [1,16,512]"
/// Checked: names (a required input or output missing; an input the contract does not know),
/// element types, ranks, static dimensions, symbol consistency (4+N = 36 with N = 32), symbols
/// >= 1. A manifest dimension of -1 matches anything; otherwise declared and model dimensions must
/// be equal. Errors: InvalidArgument with the lines above.
Result<ContractBinding> CheckContract(std::string_view role, const ModelIo& io,
                                      const Contract& contract, const ModelIo* declared = nullptr,
                                      const ContractCheckOptions& options = {});

}  // namespace avp::zsl

#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>

#include "contracts.h"
#include "detections.h"  // ScoreActivation
#include "ort_runtime.h"
#include "sha256.h"  // FileSha256

namespace avp::zsl {

/// The model directory's `manifest.json` and start-up validation (design: zero-shot-models.md §7;
/// the format is documented in docs/zero-shot-models.md, "Model directory and manifest").
///
/// A manifest lists models by **role**; a backend needs these roles:
///   ywes: `detector` (yoloworld.txtfeats/1 or yoloworld.baked/1), `text` (clip.text/1; only with
///         a text-feature detector), `segmenter.encoder` (evitsam.encoder/1), `segmenter.decoder`
///         (evitsam.decoder.single/1)
///   lsam: `grounding` (gdino.ort/1), `segmenter.encoder`, `segmenter.decoder`
/// Every field a backend needs is in these structs, with the contract's defaults (§4) filled in
/// where the manifest leaves a field out.

inline constexpr const char* kManifestFileName = "manifest.json";
inline constexpr const char* kManifestFormat = "avp.zsl.models/1";
// kModelDirEnvVar (AVP_ZSL_MODEL_DIR): avp/zsl/zsl.h.

// Roles.
inline constexpr const char* kRoleDetector = "detector";
inline constexpr const char* kRoleText = "text";
inline constexpr const char* kRoleSegmenterEncoder = "segmenter.encoder";
inline constexpr const char* kRoleSegmenterDecoder = "segmenter.decoder";
inline constexpr const char* kRoleGrounding = "grounding";

// Backends.
inline constexpr const char* kBackendYwes = "ywes";
inline constexpr const char* kBackendLsam = "lsam";

/// A file of the model directory with its recorded size and, optionally, sha256.
struct FileRef {
  std::string relative;        ///< as written in the manifest (relative to its directory)
  std::filesystem::path path;  ///< model_dir / relative
  std::optional<uint64_t> bytes;
  std::optional<std::string> sha256;  ///< 64 lower-case hex digits
};

/// How the image is resized to the model input.
enum class ResizeMode {
  kFit,      ///< scale by min(H_in/H, W_in/W), keep the aspect ratio, then pad
  kStretch,  ///< resize to exactly the input size (Grounding DINO)
};
enum class PaddingMode {
  kCentre,       ///< YOLO letterbox: left/top = round(d/2 - 0.1), right/bottom = round(d/2 + 0.1)
  kBottomRight,  ///< SAM: the image at the top-left
  kNone,
};
/// Where `pad_value` applies.
enum class PadSpace {
  kPixels,      ///< in 0-255 pixel values, before scale/mean/std (YOLO's 114)
  kNormalized,  ///< in model-input values, after normalisation (SAM's 0)
};
enum class ChannelOrder { kRgb, kBgr };
enum class Interpolation { kLinear, kNearest, kArea, kCubic };

/// Image pre-processing: input = ((pixel * scale) - mean[c]) / stddev[c], NCHW.
struct Preprocess {
  int height = 0;  ///< model input height; 0 = take it from the model (the encoder's S)
  int width = 0;   ///< model input width; 0 = take it from the model
  ResizeMode resize = ResizeMode::kFit;
  Interpolation interpolation = Interpolation::kLinear;
  PaddingMode padding = PaddingMode::kCentre;
  float pad_value = 0.0f;
  PadSpace pad_space = PadSpace::kPixels;
  ChannelOrder channel_order = ChannelOrder::kRgb;
  float scale = 1.0f;
  std::array<float, 3> mean{0.0f, 0.0f, 0.0f};
  std::array<float, 3> stddev{1.0f, 1.0f, 1.0f};  ///< the manifest's "std"
};

/// YOLO-World output layout.
enum class DetectionLayout {
  kAttributesByAnchors,  ///< "[4+N,A]": output0 [1,4+N,8400] (the stock export)
  kAnchorsByAttributes,  ///< "[A,4+N]": output0 [1,8400,4+N]
};
enum class BoxFormat {
  kCxCyWh,            ///< centre x, centre y, width, height in model-input pixels (YOLO)
  kXyXy,              ///< corners in model-input pixels
  kCxCyWhNormalized,  ///< centre and size divided by the input size (Grounding DINO)
};

/// Output post-processing constants.
struct Postprocess {
  // Detectors (YOLO-World, Grounding DINO).
  DetectionLayout layout = DetectionLayout::kAttributesByAnchors;
  BoxFormat box_format = BoxFormat::kCxCyWh;
  ScoreActivation score_activation = ScoreActivation::kNone;
  /// yoloworld.txtfeats/1: the export's class slots N; 0 in the manifest = take N from the model.
  /// After `LoadBackend` this is always the model's N.
  int n_max = 0;
  /// yoloworld.baked/1: the class names, one per score row (required; must match NC).
  std::vector<std::string> baked_names;
  // SAM decoders.
  int prompt_frame = 1024;      ///< the long side prompts are scaled to
  int low_res = 256;            ///< the decoder's mask size
  float mask_threshold = 0.0f;  ///< masks are logit > threshold
};

enum class TokenizerKind {
  kNone,
  kClipBpe,        ///< CLIP byte-level BPE (clip.text/1)
  kBertWordPiece,  ///< BERT uncased WordPiece (gdino.ort/1)
};

/// A precomputed embedding blob for a fixed vocabulary: `embeddings` holds rows of `dim` float32
/// (little-endian), one per line of `names`.
struct PrecomputedVocabulary {
  std::string name;
  FileRef embeddings;
  FileRef names;
};

/// Text-side constants (clip.text/1 and gdino.ort/1).
struct TextConfig {
  TokenizerKind tokenizer = TokenizerKind::kNone;
  int context = 0;  ///< CLIP 77; Grounding DINO's maximum L, 256
  // CLIP ids.
  int64_t sot = 49406;
  int64_t eot = 49407;
  int64_t pad = 0;
  // BERT ids.
  int64_t cls = 101;
  int64_t sep = 102;
  int64_t period = 1012;
  /// bpe_simple_vocab_16e6.txt(.gz) or BERT vocab.txt (required).
  FileRef vocabulary;
  int dim = 512;                     ///< embedding width (CLIP)
  bool normalized_in_graph = false;  ///< the export already divides by the L2 norm
  bool lower_case = true;            ///< BERT uncased
  std::vector<PrecomputedVocabulary> precomputed;
};

/// One model of the manifest.
struct ModelEntry {
  std::string role;      ///< "detector", "segmenter.decoder", …
  std::string contract;  ///< a built-in contract id
  FileRef file;          ///< `bytes` is required for models
  std::string licence;
  std::string origin;
  /// `served_as`: the model's name on a model server (RuntimeOptions::model_server, `avp serve
  /// models`, a Triton repository); empty: the role.
  std::string served_as;
  /// served_as, or the role.
  const std::string& ServedName() const { return served_as.empty() ? role : served_as; }
  /// The manifest's `inputs` / `outputs` (empty when not declared).
  ModelIo declared;
  Preprocess preprocess;
  Postprocess postprocess;
  /// Present for clip.text/1 and gdino.ort/1 (required there).
  std::optional<TextConfig> text;
};

/// A parsed manifest.
struct Manifest {
  std::filesystem::path dir;   ///< the model directory
  std::filesystem::path file;  ///< dir / manifest.json (or what was parsed)
  std::string format;
  std::string description;
  std::map<std::string, ModelEntry> models;  ///< by role

  const ModelEntry* Find(std::string_view role) const;
};

/// Parses manifest text; relative files resolve against `dir`. `source` names the text in errors.
/// Contract defaults (§4) fill what the manifest leaves out. Errors: ParseError naming the source
/// and the field path, e.g. "…/manifest.json: models.detector.bytes: expected a non-negative
/// integer, got \"12\"", "…: models.text: missing field 'file'", "…: models.detector.postprocess:
/// unknown field 'score_activaton'", "…: not valid JSON: … line 3, column 5 …"; NotFound for an
/// unknown contract id (naming the field).
Result<Manifest> ParseManifest(std::string_view json_text, const std::filesystem::path& dir,
                               std::string_view source = kManifestFileName);

/// Reads and parses `model_dir`/manifest.json. Errors: NotFound (no directory or no manifest),
/// IoError, and those of ParseManifest.
Result<Manifest> ReadManifest(const std::filesystem::path& model_dir);

/// Checks that a model's file and its text files (vocabulary, precomputed blobs) exist with the
/// recorded sizes, and with the recorded sha256 when `verify_sha256`. Errors name the role, the
/// file and the field: NotFound "segmenter.encoder: model file '…/x.onnx' does not exist (field
/// models.segmenter.encoder.file)"; InvalidArgument "text: '…/clip.onnx' has 2810 bytes;
/// models.text.bytes says 2811" or "…: sha256 is …; models.detector.sha256 says …".
/// Without `model_file` only the text files are checked (the network is on a model server).
Status CheckFiles(const ModelEntry& entry, bool verify_sha256 = false, bool model_file = true);

/// The roles `backend` ("ywes" or "lsam") needs from this manifest, in load order. ywes needs
/// `text` only with a text-feature detector. Errors: InvalidArgument for an unknown backend.
Result<std::vector<std::string>> BackendRoles(std::string_view backend, const Manifest& manifest);

// ---- start-up validation -----------------------------------------------------------------------

enum class BackendState {
  kReady,
  kMissing,  ///< the model directory, manifest, a role or a file is not there
  kInvalid,  ///< present but wrong: bad manifest, size or sha256, contract, cross-check, load
};

/// "READY", "MISSING", "INVALID".
std::string_view ToString(BackendState state);

/// A loaded, validated model: its manifest entry (n_max and the encoder size resolved from the
/// model), its session and what the contract check found.
struct LoadedModel {
  ModelEntry entry;
  ModelRef model;  ///< in process (OrtModel) or on a model server (RemoteModel)
  ContractBinding binding;
};

/// One backend's models after start-up validation. Move-only (holds sessions).
struct LoadedBackend {
  std::string backend;  ///< "ywes" or "lsam"
  BackendState state = BackendState::kMissing;
  /// Why the backend is not ready (one line, naming the role, file or tensor); empty when ready.
  std::string reason;
  /// The error behind `reason` (NotFound for MISSING; InvalidArgument, ParseError, … for INVALID).
  Status status;
  std::filesystem::path model_dir;
  std::map<std::string, LoadedModel> models;  ///< by role; all of them when ready

  bool ready() const { return state == BackendState::kReady; }
  /// "READY", "MISSING(reason)" or "INVALID(reason)".
  std::string StateString() const;
  /// The model for `role`, or nullptr.
  const LoadedModel* Find(std::string_view role) const;
};

struct BackendLoadOptions {
  SessionOptions session;
  bool verify_sha256 = false;
  /// Run each model once on zeros after loading and log the time to stderr (§7 step 5).
  bool warm_up = false;
};

/// Start-up for one backend (§7): reads the manifest, checks the files (sizes; sha256 on request),
/// creates one session per model, checks each against its contract and the manifest's declared I/O,
/// then cross-checks the models:
///   - txt_feats width (512) = the text model's text_embeds width = text.dim;
///   - postprocess.n_max (when given) = the detector's N; baked_names count = NC;
///   - the encoder's image_embeddings shape = the decoder's image_embeddings shape;
///   - the encoder's input size S = preprocess.size (when given);
///   - the decoder's mask size = postprocess.low_res;
///   - Grounding DINO's L (when static) <= text.context.
/// Never throws; the result says READY, MISSING(reason) or INVALID(reason), e.g.
/// "INVALID(segmenter.decoder: input 'point_labels' is int32; evitsam.decoder.single/1 expects
/// float32)". The role names of a model in errors are the manifest's.
LoadedBackend LoadBackend(std::string_view backend, const std::filesystem::path& model_dir,
                          const BackendLoadOptions& options = {});
/// The same from an already parsed manifest.
LoadedBackend LoadBackend(std::string_view backend, const Manifest& manifest,
                          const BackendLoadOptions& options = {});

/// LoadBackend's first step, without loading a network: every role of `backend` is listed in the
/// manifest with a contract that can serve it, and its files are there (sizes; sha256 on
/// request; `remote`: the networks are a model server's, only the text files are checked).
Status CheckBackendFiles(std::string_view backend, const Manifest& manifest, bool verify_sha256,
                         bool remote);
/// The same for a model directory: its manifest read, then CheckBackendFiles.
Status CheckBackendDir(std::string_view backend, const std::filesystem::path& model_dir,
                       bool remote);

/// The model directory from `AVP_ZSL_MODEL_DIR`, or nullopt when unset or empty.
std::optional<std::filesystem::path> ModelDirFromEnvironment();

}  // namespace avp::zsl

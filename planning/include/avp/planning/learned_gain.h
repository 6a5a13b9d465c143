#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>

namespace avp::planning {

/// A learned gain (docs/planning.md, "A learned gain"): an ONNX model that maps a candidate
/// view's feature row (view_features.h) to the share of the planning step's best true gain the
/// view is expected to reach, run by ONNX Runtime on the CPU.
///
/// The model file carries its manifest as ONNX metadata, key kLearnedGainManifestKey: a JSON
/// object with
///   "format": "avp-learned-gain/1",
///   "feature_version", "feature_hash", "feature_names": the planner's feature list it was
///     trained on (kViewFeatureVersion, ViewFeatureHash(), ViewFeatureNames()),
///   "data": how its training data was made (command, scenarios, seeds, rows, sha256),
///   "training": the script, its settings and the hash of the model's trees,
/// and one input [N, ViewFeatureCount()] float and one output [N] or [N, 1] float.
///
/// Load refuses, naming the file and what differs: a missing or unreadable file, one over
/// kMaxLearnedGainModelBytes, one that is not ONNX, no or malformed manifest, another format,
/// feature version, hash, count or order, or inputs and outputs of other types or shapes. Predict
/// refuses a row count that does not match, and any non-finite prediction (naming the row): the
/// planner then falls back to its hand-written gain for that step, with a warning (never a silent
/// wrong ranking).
inline constexpr std::string_view kLearnedGainManifestKey = "avp_manifest";
inline constexpr std::string_view kLearnedGainFormat = "avp-learned-gain/1";
/// The largest model file Load reads (64 MiB; the committed model is 0.6 MB).
inline constexpr uintmax_t kMaxLearnedGainModelBytes = uintmax_t{64} << 20;

class LearnedGainModel {
 public:
  /// Errors: see the class comment; Unimplemented when avp was built without ONNX Runtime.
  static Result<std::shared_ptr<const LearnedGainModel>> Load(const std::filesystem::path& file);

  ~LearnedGainModel();
  LearnedGainModel(const LearnedGainModel&) = delete;
  LearnedGainModel& operator=(const LearnedGainModel&) = delete;

  /// One value per row of `rows` (row-major, n x ViewFeatureCount()). Thread-safe.
  Result<std::vector<float>> Predict(std::span<const float> rows, size_t n) const;

  const std::filesystem::path& file() const { return file_; }
  /// The manifest, as stored (JSON text).
  const std::string& manifest() const { return manifest_; }
  /// One line: the file, its format and the data it was trained on.
  std::string Summary() const;

 private:
  LearnedGainModel() = default;
  struct Session;
  std::unique_ptr<Session> session_;
  std::filesystem::path file_;
  std::string manifest_;
  std::string summary_;
};

/// Where the option value `spec` points: a bare name without a directory or extension ("learned")
/// is `<config dir>/models/<name>.onnx` (robot::DefaultConfigDir()); anything else is a path.
std::filesystem::path ResolveGainModelPath(std::string_view spec);

/// Checks a manifest (JSON text) against the planner's feature list; OK or InvalidArgument
/// naming every mismatch. Used by Load; public for tests.
Status CheckLearnedGainManifest(std::string_view manifest);

}  // namespace avp::planning

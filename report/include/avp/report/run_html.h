#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>

#include <avp/core/status.h>
#include <avp/core/voxel_key.h>
#include <avp/pipeline/episode.h>

// The run report (report.html of every `avp run` / `avp live` folder, docs/report.md): one
// self-contained page that shows the episode in 3D (three.js, bundled at build time) with its data
// embedded. RunReportCollector keeps, view by view, what the planner saw; WriteRunReportHtml writes
// the page.
namespace avp::report {

struct RunReportOptions {
  /// Width (pixels) the masks picture of each view is reduced to (at most; never enlarged).
  int mask_image_width = 320;
  /// JPEG quality of the masks picture, in [1, 100].
  int mask_jpeg_quality = 80;
  /// Ranked candidates kept per step (the best ones); the rest are counted, not kept.
  size_t max_candidates = 2000;
};

/// Everything the page shows besides the steps (filled after the episode).
struct RunReportInfo {
  /// The page's title (scene, planner, segmenter, seed).
  std::string title;
  /// Key/value facts shown in the page's header (command, scene, planner, end, ...), in order.
  std::vector<std::pair<std::string, std::string>> facts;
  /// record.json's "fruits" (FruitsJson: centre, radius, found, found_view, ...), or null when
  /// the run has no ground truth.
  nlohmann::json fruits;
};

/// An EpisodeObserver that keeps, for every fused view (OnView), the map's occupied voxels as the
/// planner saw them (as changes from the previous view: voxels added or changed, with class,
/// instance and confidence, and voxels removed), the camera (X_WC, intrinsics, depth range, the
/// median depth), the masks (a reduced JPEG of the masks drawn over the colour image, and each
/// instance's class, label and score), every ranked candidate with its gain, cost and utility and
/// the one the arm moved to, the map counts and the step's metrics.
class RunReportCollector final : public pipeline::EpisodeObserver {
 public:
  explicit RunReportCollector(RunReportOptions options = {});

  void OnView(const pipeline::StepRecord& step, const pipeline::StepData& data,
              const mapping::SemanticMap& map) override;
  void OnStep(const pipeline::StepRecord& /*step*/, const mapping::SemanticMap& /*map*/) override {}

  /// Views collected so far.
  size_t steps() const { return steps_.size(); }
  /// Occupied voxels after each collected view (what the page draws at that step).
  std::vector<size_t> OccupiedVoxelsPerStep() const;

  /// The page's data (docs/report.md, "The data"): format "avp-run-report" version 1.
  /// InvalidArgument when the occupied voxels span more than 65535 voxels along an axis (keys
  /// are stored as 16-bit offsets), naming the extent.
  Result<nlohmann::json> Data(const RunReportInfo& info) const;

 private:
  struct VoxelSet {
    VoxelKey key;
    uint32_t value = 0;  ///< class | confidence (0-255) << 8 | instance << 16
  };
  struct Step {
    std::vector<VoxelSet> set;
    std::vector<VoxelKey> removed;
    size_t occupied = 0;
    nlohmann::json json;  ///< everything else (camera, masks, plan, metrics)
  };

  RunReportOptions options_;
  double voxel_size_m_ = 0.0;
  std::unordered_map<VoxelKey, uint32_t, VoxelKeyHash> occupied_;
  std::vector<Step> steps_;
};

/// The page: `viewer_js` (the bundled viewer, an IIFE) inline in a script and `data` inline as
/// JSON (`<script type="application/json" id="avp-report-data">`), "</" escaped in both.
std::string RunReportHtml(const nlohmann::json& data, std::string_view viewer_js,
                          std::string_view title);

/// Writes report.html (atomically) with the viewer bundled at build time (RunViewerJs()).
/// Data()'s errors, or IoError naming the file.
Status WriteRunReportHtml(const std::filesystem::path& path, const RunReportCollector& collector,
                          const RunReportInfo& info);

/// The data embedded in a report page (RunReportHtml's JSON), for tests and tools. NotFound when
/// the page has none, ParseError when it is not JSON; both name the file.
Result<nlohmann::json> ReadRunReportData(const std::filesystem::path& html);

/// Standard base64 (RFC 4648, with padding), as the page's binary blobs are stored.
std::string Base64Encode(std::string_view bytes);
/// Its inverse; InvalidArgument naming the offset of the first character that is not base64.
Result<std::string> Base64Decode(std::string_view text);

}  // namespace avp::report

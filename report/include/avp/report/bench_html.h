#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include <avp/core/status.h>
#include <avp/report/bench_summary.h>

namespace avp::report {

/// A bench episode's run folder relative to the bench folder:
/// runs/<SafeFileName(scenario)>/<SafeFileName(planner)>/seed-<seed>.
std::filesystem::path BenchRunFolder(const std::string& scenario, const std::string& planner,
                                     uint64_t seed);

/// The data of a bench's report.html (docs/report.md, "Bench report"): the bench's description,
/// and per scenario and planner the per-view statistics of every metric (mean, 95 % CI, n over
/// the successful seeds: the numbers of summary.csv, unrounded), the final view's table (the
/// numbers of summary.md), the fraction found per visibility bin (fruits_by_visibility.csv) and
/// each episode's run folder (relative to `bench_dir`) with the files it holds there. Non-finite
/// values are null; a CI without an interval (one seed) is 0, as in summary.csv.
nlohmann::json BenchReportJson(const BenchDescription& bench,
                               const std::vector<BenchEpisode>& episodes, double seconds,
                               const std::filesystem::path& bench_dir);

/// `data` as the text of a `<script type="application/json">` element: every '<' written as
/// \u003c (still the same JSON), invalid UTF-8 replaced.
std::string JsonForHtmlScript(const nlohmann::json& data);

/// `js` safe inside a `<script>` element: "</script" written as "<\/script" (case-insensitive).
std::string JsForHtmlScript(std::string_view js);

/// The self-contained report.html of a bench: the bench page's script (BenchViewerJs(), bundled
/// at build time) and `data` (BenchReportJson) inline; opens offline from disk.
std::string BenchReportHtml(const nlohmann::json& data);

/// Writes BenchReportHtml(data) to `path` atomically. Errors: IoError naming the path.
Status WriteBenchReportHtml(const std::filesystem::path& path, const nlohmann::json& data);

/// The data embedded in a bench report page (BenchReportHtml's JSON), for tests and tools.
/// NotFound when the page has none, ParseError when it is not JSON; both name the file.
Result<nlohmann::json> ReadBenchReportData(const std::filesystem::path& html);

}  // namespace avp::report

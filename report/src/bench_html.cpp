#include <algorithm>
#include <cctype>
#include <cmath>
#include <system_error>

#include <fmt/format.h>

#include <avp/eval/ground_truth.h>
#include <avp/io/file.h>
#include <avp/report/bench_html.h>
#include <avp/report/svg_plot.h>
#include <avp/report/web_assets.h>

#include "bench_aggregates.h"

namespace avp::report {

namespace fs = std::filesystem;

namespace {

using internal::BenchKey;

constexpr std::string_view kDataId = "avp-bench-data";

/// A number for the page: non-finite ones are null.
nlohmann::json Num(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

/// {mean, ci_lo, ci_hi, n} of one view, as summary.csv has it (null ends: no interval).
nlohmann::json StatJson(const eval::Summary& s) {
  return {{"mean", Num(s.mean)}, {"ci_lo", Num(s.ci_lo)}, {"ci_hi", Num(s.ci_hi)}, {"n", s.n}};
}

/// The files a run folder holds (at most 32, sorted); empty when it does not exist.
nlohmann::json FolderFiles(const fs::path& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_regular_file(ec)) names.push_back(it->path().filename().string());
  }
  std::sort(names.begin(), names.end());
  if (names.size() > 32) names.resize(32);
  return names;
}

nlohmann::json PlannerJson(const internal::BenchAggregates& a, const BenchDescription& bench,
                           const std::vector<BenchEpisode>& episodes, const std::string& scenario,
                           const std::string& planner, const fs::path& bench_dir) {
  const BenchKey key{scenario, planner};
  nlohmann::json per_view = nlohmann::json::object();
  for (const std::string& metric : a.metric_order) {
    nlohmann::json mean = nlohmann::json::array(), lo = nlohmann::json::array(),
                   hi = nlohmann::json::array(), n = nlohmann::json::array();
    for (int v = 0; v < bench.views; ++v) {
      const eval::Summary s = a.Stat(key, metric, v);
      mean.push_back(Num(s.mean));
      lo.push_back(Num(s.ci_lo));
      hi.push_back(Num(s.ci_hi));
      n.push_back(s.n);
    }
    per_view[metric] = {{"mean", mean}, {"ci_lo", lo}, {"ci_hi", hi}, {"n", n}};
  }
  const int last = bench.views - 1;
  const auto plan = a.plan_ms.find(key);
  const auto episode = a.episode_s.find(key);
  const auto failed = a.failed.find(key);
  nlohmann::json final_view = {
      {"view", bench.views},
      {"plan_ms_mean", plan == a.plan_ms.end() ? 0.0 : internal::MeanOf(plan->second)},
      {"episode_s_mean", episode == a.episode_s.end() ? 0.0 : internal::MeanOf(episode->second)},
  };
  for (const char* metric :
       {"f1", "f1_tol", "fruits_found", "fruits_total", "fruits_found_fraction"}) {
    final_view[metric] = StatJson(a.Stat(key, metric, last));
  }
  nlohmann::json bins = nlohmann::json::array();
  for (const VisibilityBin& b : FoundByVisibility(episodes, scenario, planner)) {
    bins.push_back({{"lo", b.lo},
                    {"hi", b.hi},
                    {"fruits", b.fruits},
                    {"found", b.found},
                    {"fraction", Num(b.fraction)},
                    {"ci_lo", Num(b.ci_lo)},
                    {"ci_hi", Num(b.ci_hi)}});
  }
  nlohmann::json runs = nlohmann::json::array();
  for (const BenchEpisode& e : episodes) {
    if (e.scenario != scenario || e.planner != planner) continue;
    const fs::path folder = BenchRunFolder(e.scenario, e.planner, e.seed);
    const bool ok = e.status.ok() && !e.metrics.empty();
    runs.push_back({{"seed", e.seed},
                    {"ok", ok},
                    {"status", e.status.ok() ? (ok ? "" : "no views") : e.status.ToString()},
                    {"folder", folder.generic_string()},
                    {"files", FolderFiles(bench_dir / folder)},
                    {"views", e.metrics.size()},
                    {"episode_s", Num(e.episode_s)}});
  }
  return {{"name", planner},
          {"n", a.Stat(key, "f1", last).n},
          {"failed", failed == a.failed.end() ? 0 : failed->second},
          {"per_view", per_view},
          {"final", final_view},
          {"visibility_bins", bins},
          {"runs", runs}};
}

}  // namespace

fs::path BenchRunFolder(const std::string& scenario, const std::string& planner, uint64_t seed) {
  return fs::path("runs") / SafeFileName(scenario) / SafeFileName(planner) /
         fmt::format("seed-{}", seed);
}

nlohmann::json BenchReportJson(const BenchDescription& bench,
                               const std::vector<BenchEpisode>& episodes, double seconds,
                               const fs::path& bench_dir) {
  const internal::BenchAggregates a = internal::Aggregate(episodes, bench.views);
  nlohmann::json run_options = nlohmann::json::object();
  for (const auto& [k, v] : bench.run_options) run_options[k] = v;
  nlohmann::json planner_options = nlohmann::json::object();
  for (const auto& [p, options] : bench.planner_options) {
    if (options.empty()) continue;
    for (const auto& [k, v] : options) planner_options[p][k] = v;
  }
  nlohmann::json scenarios = nlohmann::json::array();
  for (const std::string& s : bench.scenarios) {
    nlohmann::json visibility;  // null: no fruit has a best visible fraction
    const auto vis = bench.visibility.find(s);
    if (vis != bench.visibility.end() && vis->second.fruits > 0.0) {
      nlohmann::json levels = nlohmann::json::array(), visible = nlohmann::json::array();
      for (size_t l = 0; l < vis->second.visible.size(); ++l) {
        levels.push_back(eval::kVisibleFractionLevels[l]);
        visible.push_back(vis->second.visible[l]);
      }
      visibility = {{"fruits", vis->second.fruits}, {"levels", levels}, {"visible", visible}};
    }
    nlohmann::json planners = nlohmann::json::array();
    for (const std::string& p : bench.planners) {
      planners.push_back(PlannerJson(a, bench, episodes, s, p, bench_dir));
    }
    nlohmann::json leads = nlohmann::json::array();
    for (const PairedLead& l : PairedLeads(episodes, s, bench.planners)) {
      leads.push_back({{"planner", l.planner},
                       {"versus", l.versus},
                       {"f1", StatJson(l.f1)},
                       {"found", StatJson(l.found)},
                       {"verdict", l.verdict}});
    }
    scenarios.push_back({{"name", s},
                         {"file_name", SafeFileName(s)},
                         {"visibility", visibility},
                         {"planners", planners},
                         {"leads", leads}});
  }
  return {{"format", "avp-bench-report"},
          {"version", 1},
          {"bench",
           {{"scenarios", bench.scenarios},
            {"planners", bench.planners},
            {"seeds", bench.seeds},
            {"views", bench.views},
            {"segmenter", bench.segmenter},
            {"voxel_size_m", bench.voxel_size_m},
            {"revision", bench.revision},
            {"description", bench.description},
            {"run_options", run_options},
            {"planner_options", planner_options},
            {"episodes", episodes.size()},
            {"failed", a.failed_total},
            {"seconds", Num(seconds)}}},
          {"metrics", a.metric_order},
          {"scenarios", scenarios}};
}

std::string JsonForHtmlScript(const nlohmann::json& data) {
  const std::string text = data.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  std::string out;
  out.reserve(text.size() + text.size() / 16);
  for (char c : text) {
    if (c == '<') {
      out += "\\u003c";
    } else {
      out += c;
    }
  }
  return out;
}

std::string JsForHtmlScript(std::string_view js) {
  std::string out;
  out.reserve(js.size());
  constexpr std::string_view kEnd = "</script";
  for (size_t i = 0; i < js.size(); ++i) {
    if (js[i] == '<' && i + kEnd.size() <= js.size() &&
        std::equal(
            kEnd.begin(), kEnd.end(), js.begin() + static_cast<std::ptrdiff_t>(i),
            [](char end, char c) { return std::tolower(static_cast<unsigned char>(c)) == end; })) {
      out += "<\\/";
      ++i;  // the '/' is written
      continue;
    }
    out += js[i];
  }
  return out;
}

std::string BenchReportHtml(const nlohmann::json& data) {
  std::string title = "avp bench";
  if (data.contains("bench") && data["bench"].contains("description") &&
      data["bench"]["description"].is_string() &&
      !data["bench"]["description"].get<std::string>().empty()) {
    title += ": " + data["bench"]["description"].get<std::string>();
  }
  std::string html =
      "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
      "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>";
  html += EscapeXml(title);
  html +=
      "</title>\n</head>\n<body>\n<div id=\"avp-bench\"><noscript>This report needs "
      "JavaScript; summary.md beside it has the tables.</noscript></div>\n"
      "<pre id=\"avp-selftest\" hidden></pre>\n"
      "<script type=\"application/json\" id=\"";
  html += kDataId;
  html += "\">";
  html += JsonForHtmlScript(data);
  html += "</script>\n<script>\n";
  html += JsForHtmlScript(BenchViewerJs());
  html += "\n</script>\n</body>\n</html>\n";
  return html;
}

Result<nlohmann::json> ReadBenchReportData(const fs::path& html) {
  AVP_ASSIGN_OR_RETURN(const std::string text, io::ReadFileBounded(html, "bench report"));
  const std::string open = fmt::format("<script type=\"application/json\" id=\"{}\">", kDataId);
  const size_t begin = text.find(open);
  if (begin == std::string::npos) {
    return NotFoundError(fmt::format("{}: no bench report data ({})", html.string(), open));
  }
  const size_t start = begin + open.size();
  const size_t end = text.find("</script>", start);
  if (end == std::string::npos) {
    return ParseError(
        fmt::format("{}: the bench report data at offset {} has no end", html.string(), start));
  }
  nlohmann::json data =
      nlohmann::json::parse(text.begin() + static_cast<std::ptrdiff_t>(start),
                            text.begin() + static_cast<std::ptrdiff_t>(end), nullptr, false);
  if (data.is_discarded()) {
    return ParseError(
        fmt::format("{}: the bench report data at offset {} is not JSON", html.string(), start));
  }
  return data;
}

Status WriteBenchReportHtml(const fs::path& path, const nlohmann::json& data) {
  return io::WriteFileAtomic(path, BenchReportHtml(data));
}

}  // namespace avp::report

#pragma once

// Internal to avp::report: the per-view statistics of a bench's episodes, shared by the summary
// (bench_summary.cpp) and the HTML report (bench_html.cpp) so both show the same numbers.

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include <avp/eval/statistics.h>
#include <avp/report/bench_summary.h>

namespace avp::report::internal {

struct BenchKey {
  std::string scenario, planner;
  bool operator<(const BenchKey& o) const {
    return std::tie(scenario, planner) < std::tie(o.scenario, o.planner);
  }
};

/// Every successful episode's metrics per (scenario, planner), metric and view.
struct BenchAggregates {
  /// values[key][metric][view] -> samples over seeds
  std::map<BenchKey, std::map<std::string, std::vector<std::vector<double>>>> values;
  std::map<BenchKey, std::vector<double>> plan_ms, episode_s;
  /// Per episode: contacts (where known), straight-line contacts, motion time; per move: its
  /// planning time.
  std::map<BenchKey, std::vector<double>> contacts, straight_line_contacts, motion_s,
      move_planning_ms;
  /// Per episode whose start the simulator checked: 1 when it broke the start clearance.
  std::map<BenchKey, std::vector<double>> start_clearance_broken;
  std::map<BenchKey, size_t> failed;
  size_t failed_total = 0;
  std::vector<std::string> metric_order;

  eval::Summary Stat(const BenchKey& key, const std::string& metric, int view) const {
    auto it = values.find(key);
    if (it == values.end()) return eval::Summary{};
    auto m = it->second.find(metric);
    if (m == it->second.end()) return eval::Summary{};
    return eval::Summarize(m->second[static_cast<size_t>(view)]);
  }
};

inline double MeanOf(const std::vector<double>& xs) {
  double s = 0.0;
  for (double x : xs) s += x;
  return xs.empty() ? 0.0 : s / static_cast<double>(xs.size());
}

/// An episode that ended early keeps its last map, so its last metrics carry on to the remaining
/// views.
inline BenchAggregates Aggregate(const std::vector<BenchEpisode>& episodes, int views) {
  BenchAggregates a;
  for (const BenchEpisode& j : episodes) {
    const BenchKey key{j.scenario, j.planner};
    if (!j.status.ok() || j.metrics.empty()) {
      ++a.failed[key];
      ++a.failed_total;
      continue;
    }
    if (a.metric_order.empty()) {
      for (const auto& [name, v] : j.metrics.front()) a.metric_order.push_back(name);
    }
    for (int v = 0; v < views; ++v) {
      const auto& row = j.metrics[std::min<size_t>(static_cast<size_t>(v), j.metrics.size() - 1)];
      for (const auto& [name, value] : row) {
        auto& per_view = a.values[key][name];
        per_view.resize(static_cast<size_t>(views));
        if (std::isfinite(value)) per_view[static_cast<size_t>(v)].push_back(value);
      }
    }
    a.plan_ms[key].insert(a.plan_ms[key].end(), j.plan_ms.begin(), j.plan_ms.end());
    a.episode_s[key].push_back(j.episode_s);
    if (std::isfinite(j.contacts)) a.contacts[key].push_back(j.contacts);
    if (std::isfinite(j.straight_line_contacts)) {
      a.straight_line_contacts[key].push_back(j.straight_line_contacts);
    }
    if (std::isfinite(j.motion_s)) a.motion_s[key].push_back(j.motion_s);
    if (std::isfinite(j.start_clearance_broken)) {
      a.start_clearance_broken[key].push_back(j.start_clearance_broken);
    }
    a.move_planning_ms[key].insert(a.move_planning_ms[key].end(), j.move_planning_ms.begin(),
                                   j.move_planning_ms.end());
  }
  return a;
}

}  // namespace avp::report::internal

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <tuple>

#include <fmt/format.h>

#include <avp/eval/statistics.h>
#include <avp/io/file.h>
#include <avp/report/bench_summary.h>
#include <avp/report/svg_plot.h>

#include "bench_aggregates.h"

namespace avp::report {

namespace fs = std::filesystem;

namespace {

using internal::Aggregate;
using internal::MeanOf;
using Aggregates = internal::BenchAggregates;
using Key = internal::BenchKey;

/// printf's "%.9g" (summary.csv's number format).
std::string FormatG9(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

/// summary.csv's columns after the metric's name: "mean,ci_lo,ci_hi,n,versus".
std::string CsvStat(const eval::Summary& s, const std::string& versus = {}) {
  return fmt::format("{},{},{},{},{}", FormatG9(s.mean), FormatG9(s.ci_lo), FormatG9(s.ci_hi), s.n,
                     versus);
}

/// "n" of a table, marked when the interval rests on few seeds.
std::string SampleSize(size_t n) {
  return n < eval::kSmallSample && n > 0 ? fmt::format("{} (small)", n) : std::to_string(n);
}

/// The lead's paired differences of one scenario: a markdown table and summary.csv's rows.
std::string LeadTable(const std::vector<PairedLead>& leads, const BenchDescription& bench) {
  if (leads.empty()) return "";
  std::string md = fmt::format(
      "\nLead of `{}` over each planner at view {}, paired by seed (its value minus the other's "
      "on the same seeds, mean and 95 % interval): **ahead** when the whole F1 interval is above "
      "0, behind when below, tied when it holds 0:\n\n| versus | seeds | F1 lead | found "
      "fraction lead | verdict |\n|---|---|---|---|---|\n",
      leads.front().planner, bench.views);
  for (const PairedLead& l : leads) {
    md += fmt::format("| {} | {} | {} | {} | {} |\n", l.versus, SampleSize(l.f1.n),
                      eval::FormatMeanInterval(l.f1, 3, true),
                      eval::FormatMeanInterval(l.found, 3, true),
                      l.verdict == "ahead" ? "**ahead**" : l.verdict);
  }
  return md;
}

std::string LeadCsv(const std::vector<PairedLead>& leads, const BenchDescription& bench) {
  std::string csv;
  for (const PairedLead& l : leads) {
    csv += fmt::format("{},{},{},{},f1_lead,{}\n", l.scenario, l.planner, bench.segmenter,
                       bench.views, CsvStat(l.f1, l.versus));
    csv += fmt::format("{},{},{},{},found_lead,{}\n", l.scenario, l.planner, bench.segmenter,
                       bench.views, CsvStat(l.found, l.versus));
  }
  return csv;
}

std::string SummaryCsv(const Aggregates& a, const BenchDescription& bench) {
  std::string csv = "scenario,planner,segmenter,view,metric,mean,ci_lo,ci_hi,n,versus\n";
  for (const auto& [key, metrics] : a.values) {
    for (const std::string& name : a.metric_order) {
      auto it = metrics.find(name);
      if (it == metrics.end()) continue;
      for (int v = 0; v < bench.views; ++v) {
        const eval::Summary s = eval::Summarize(it->second[static_cast<size_t>(v)]);
        csv += fmt::format("{},{},{},{},{},{}\n", key.scenario, key.planner, bench.segmenter, v + 1,
                           name, CsvStat(s));
      }
    }
    // The episode's motion (docs/motion.md), on the last view's line: contacts and motion time
    // per episode (wall times stay out: summary.csv is the same for the same seeds).
    for (const auto& [name, values] :
         {std::pair{"contacts", &a.contacts},
          std::pair{"straight_line_contacts", &a.straight_line_contacts},
          std::pair{"motion_s", &a.motion_s},
          std::pair{"start_clearance_broken", &a.start_clearance_broken}}) {
      const auto it = values->find(key);
      if (it == values->end() || it->second.empty()) continue;
      csv += fmt::format("{},{},{},{},{},{}\n", key.scenario, key.planner, bench.segmenter,
                         bench.views, name, CsvStat(eval::Summarize(it->second)));
    }
  }
  return csv;
}

/// The metrics of the regret probe in summary.csv, in this order.
constexpr std::array<const char*, 3> kRegretMetrics = {"oracle_regret", "oracle_rank_correlation",
                                                       "oracle_chosen_rank"};

double RegretValue(const BenchRegret& r, size_t metric) {
  switch (metric) {
    case 0:
      return r.regret;
    case 1:
      return r.rank_correlation;
    default:
      return static_cast<double>(r.chosen_true_rank);
  }
}

/// summary.csv's rows of the regret probe: per view a plan chose (2 .. views), then pooled over
/// every plan step at view 0. None when no episode measured its regret.
std::string RegretCsv(const std::vector<BenchEpisode>& episodes, const BenchDescription& bench) {
  std::string csv;
  for (const std::string& s : bench.scenarios) {
    for (const std::string& p : bench.planners) {
      // samples[metric][view], view 0 pooled
      std::vector<std::vector<std::vector<double>>> samples(
          kRegretMetrics.size(),
          std::vector<std::vector<double>>(static_cast<size_t>(std::max(bench.views, 1)) + 1));
      bool any = false;
      for (const BenchEpisode& e : episodes) {
        if (e.scenario != s || e.planner != p || !e.status.ok() || e.metrics.empty()) continue;
        for (const BenchRegret& r : e.regret) {
          const int view = r.step + 2;
          if (view < 2 || view > bench.views) continue;
          any = true;
          for (size_t m = 0; m < kRegretMetrics.size(); ++m) {
            samples[m][static_cast<size_t>(view)].push_back(RegretValue(r, m));
            samples[m][0].push_back(RegretValue(r, m));
          }
        }
      }
      if (!any) continue;
      for (size_t m = 0; m < kRegretMetrics.size(); ++m) {
        for (int v = 0; v <= bench.views; ++v) {
          if (v == 1) continue;
          const eval::Summary st = eval::Summarize(samples[m][static_cast<size_t>(v)]);
          csv += fmt::format("{},{},{},{},{},{}\n", s, p, bench.segmenter, v, kRegretMetrics[m],
                             CsvStat(st));
        }
      }
    }
  }
  return csv;
}

/// The regret table of one scenario (empty when no planner's regret was measured).
std::string RegretTable(const std::vector<BenchEpisode>& episodes, const BenchDescription& bench,
                        const std::string& scenario) {
  std::string rows;
  for (const std::string& p : bench.planners) {
    const RegretSummary r = SummarizeRegret(episodes, scenario, p);
    if (r.plans == 0) continue;
    const std::string correlation =
        r.correlated == 0
            ? "– | –"
            : fmt::format("{:.3f} | {}", r.rank_correlation_median,
                          eval::FormatMeanInterval(r.rank_correlation_mean, r.rank_correlation_lo,
                                                   r.rank_correlation_hi, r.correlated));
    rows += fmt::format("| {} | {} | {:.0f} | {} | {} / {} | {:.0f} | {} |\n", p, r.plans,
                        r.candidates_median,
                        eval::FormatMeanInterval(r.regret_mean, r.regret_lo, r.regret_hi, r.plans),
                        r.best_chosen, r.plans, r.chosen_rank_median, correlation);
  }
  if (rows.empty()) return "";
  return "\nOracle regret of each plan step (`--oracle-regret`; every seed's plans pooled): regret "
         "= 1 − the choice's true gain / the best candidate's, the choice's rank by the truth, "
         "and Spearman's correlation of the planner's gain with the true gain over the "
         "candidates (a planner with one candidate has no regret by definition):\n\n| planner | "
         "plans | candidates (median) | regret | truly best chosen | median true rank | median "
         "rank corr. | rank corr. |\n|---|---|---|---|---|---|---|---|\n" +
         rows;
}

std::string MarkdownHeader(const BenchDescription& bench, double seconds) {
  std::string md = fmt::format(
      "# avp bench\n\n{} scenario(s) x {} planner(s) x {} seed(s), {} fused views, segmenter "
      "`{}`, {} mm voxels; revision `{}`; {:.0f} s.\n\nMean over seeds [95 % interval: a "
      "percentile bootstrap of the mean, within the metric's range; none below 2 seeds, "
      "\"(small)\" below {}]. `found` = fruits found / all fruits of the scene "
      "(docs/evaluation.md).\n",
      bench.scenarios.size(), bench.planners.size(), bench.seeds, bench.views, bench.segmenter,
      bench.voxel_size_m * 1e3, bench.revision, seconds, eval::kSmallSample);
  if (!bench.description.empty()) md += fmt::format("\n{}.\n", bench.description);
  if (!bench.run_options.empty()) {
    std::string text;
    for (const auto& [k, v] : bench.run_options) {
      text += fmt::format("{}`{} = {}`", text.empty() ? "" : ", ", k, v);
    }
    md += fmt::format("\nRun configuration over its defaults: {}.\n", text);
  }
  for (const auto& [planner, options] : bench.planner_options) {
    if (options.empty()) continue;
    std::string text;
    for (const auto& [k, v] : options) {
      text += fmt::format("{}`{} = {}`", text.empty() ? "" : ", ", k, v);
    }
    md += fmt::format("\n{} options over its defaults: {}.\n", planner, text);
  }
  return md;
}

/// "mean" of one per-episode series of `key` with `digits` decimals, "–" when there is none.
std::string MeanCell(const std::map<Key, std::vector<double>>& series, const Key& key, int digits) {
  const auto it = series.find(key);
  if (it == series.end() || it->second.empty()) return "–";
  return fmt::format("{:.{}f}", MeanOf(it->second), digits);
}

/// Contacts per episode: "mean (straight line: mean)", with the most in one episode when any,
/// and the episodes that started with an object inside the assumed start clearance.
std::string ContactsCell(const Aggregates& a, const Key& key) {
  const auto it = a.contacts.find(key);
  if (it == a.contacts.end() || it->second.empty()) return "–";
  const double most = *std::max_element(it->second.begin(), it->second.end());
  double broken = 0.0;
  if (const auto b = a.start_clearance_broken.find(key); b != a.start_clearance_broken.end()) {
    for (const double v : b->second) broken += v;
  }
  return fmt::format(
      "{}{} ({}){}", MeanCell(a.contacts, key, 2),
      most > 0 ? fmt::format(", at most {:.0f}", most) : std::string(),
      MeanCell(a.straight_line_contacts, key, 2),
      broken > 0 ? fmt::format("; start clearance broken in {:.0f}", broken) : std::string());
}

/// The final view's table of one scenario; appends its cells.
std::string FinalViewTable(const Aggregates& a, const BenchDescription& bench,
                           const std::string& scenario, std::vector<BenchCell>& cells) {
  const int last = bench.views - 1;
  std::string md = fmt::format(
      "\n## {}\n\n| planner | n | F1 (exact) view {} | F1 (±1 voxel) | fruits found | found "
      "fraction | plan ms/step | episode s | contacts/episode (straight line) | motion s | "
      "failed |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
      scenario, bench.views);
  for (const std::string& p : bench.planners) {
    const Key key{scenario, p};
    const eval::Summary f1 = a.Stat(key, "f1", last);
    const eval::Summary f1t = a.Stat(key, "f1_tol", last);
    const eval::Summary found = a.Stat(key, "fruits_found", last);
    const eval::Summary total = a.Stat(key, "fruits_total", last);
    const eval::Summary frac = a.Stat(key, "fruits_found_fraction", last);
    const auto plan = a.plan_ms.find(key);
    const auto episode = a.episode_s.find(key);
    const auto failed = a.failed.find(key);
    BenchCell cell;
    cell.scenario = scenario;
    cell.planner = p;
    cell.runs = f1.n;
    cell.final_f1_mean = f1.mean;
    cell.final_f1_lo = f1.ci_lo;
    cell.final_f1_hi = f1.ci_hi;
    cell.final_found_mean = frac.mean;
    cell.final_found_lo = frac.ci_lo;
    cell.final_found_hi = frac.ci_hi;
    cell.fruits_total_mean = total.mean;
    cell.plan_ms_mean = plan == a.plan_ms.end() ? 0.0 : MeanOf(plan->second);
    cell.episode_s_mean = episode == a.episode_s.end() ? 0.0 : MeanOf(episode->second);
    cell.failed = failed == a.failed.end() ? 0 : failed->second;
    md += fmt::format(
        "| {} | {} | {} | {} | {:.1f} / {:.1f} | {} | {:.0f} | {:.2f} | {} | {} | {} |\n", p,
        SampleSize(f1.n), eval::FormatMeanInterval(f1), eval::FormatMeanInterval(f1t), found.mean,
        total.mean, eval::FormatMeanInterval(frac), cell.plan_ms_mean, cell.episode_s_mean,
        ContactsCell(a, key), MeanCell(a.motion_s, key, 1), cell.failed);
    cells.push_back(cell);
  }
  return md;
}

std::string BinLabel(const VisibilityBin& b) {
  return fmt::format("[{:.2f}, {:.2f}{}", b.lo, b.hi, b.hi >= 1.0 ? "]" : ")");
}

/// fruits_by_visibility.csv: FoundByVisibility per scenario, planner and bin.
std::string VisibilityCsv(const std::vector<BenchEpisode>& episodes,
                          const BenchDescription& bench) {
  std::string csv =
      "scenario,planner,segmenter,visible_from,visible_to,fruits,found,fraction,wilson_lo,"
      "wilson_hi\n";
  for (const std::string& s : bench.scenarios) {
    for (const std::string& p : bench.planners) {
      for (const VisibilityBin& b : FoundByVisibility(episodes, s, p)) {
        csv += fmt::format("{},{},{},{},{},{},{},{},{},{}\n", s, p, bench.segmenter, FormatG9(b.lo),
                           FormatG9(b.hi), b.fruits, b.found, FormatG9(b.fraction),
                           FormatG9(b.ci_lo), FormatG9(b.ci_hi));
      }
    }
  }
  return csv;
}

/// The fraction found per visibility bin of one scenario (empty when no fruit has a best
/// visible fraction).
std::string VisibilityTable(const std::vector<BenchEpisode>& episodes,
                            const BenchDescription& bench, const std::string& scenario) {
  std::string rows;
  std::vector<VisibilityBin> header;
  size_t binned = 0;
  for (const std::string& p : bench.planners) {
    const std::vector<VisibilityBin> bins = FoundByVisibility(episodes, scenario, p);
    header = bins;
    rows += "| " + p + " |";
    for (const VisibilityBin& b : bins) {
      binned += b.fruits;
      if (b.fruits == 0) {
        rows += " – |";
      } else {
        rows += fmt::format(" {} / {} = {:.2f} [{:.2f}, {:.2f}] |", b.found, b.fruits, b.fraction,
                            b.ci_lo, b.ci_hi);
      }
    }
    rows += "\n";
  }
  if (binned == 0) return "";
  std::string md =
      "\nFruits found at the final view by best visible fraction (found / fruits over all seeds, "
      "Wilson 95 % interval):\n\n| planner |";
  for (const VisibilityBin& b : header) md += " " + BinLabel(b) + " |";
  md += "\n|---|";
  for (size_t i = 0; i < header.size(); ++i) md += "---|";
  return md + "\n" + rows;
}

/// How hidden the fruits are (docs/evaluation.md): a fruit that no reachable view shows much of is
/// hard to find for any planner. Only for observable ground truths (a file has no views).
std::string VisibilityLine(const BenchDescription& bench, const std::string& scenario) {
  const auto it = bench.visibility.find(scenario);
  if (it == bench.visibility.end() || !(it->second.fruits > 0.0)) return "";
  const FruitVisibility& v = it->second;
  std::string md =
      "\nFruits by their best visible fraction from a reachable observation view (all seeds):";
  for (size_t l = 0; l < v.visible.size(); ++l) {
    md += fmt::format("{}≥ {:.0f} %: {:.1f} %", l == 0 ? " " : ", ",
                      100.0 * eval::kVisibleFractionLevels[l], 100.0 * v.visible[l] / v.fruits);
  }
  return md + ".\n";
}

std::string F1PerViewTable(const Aggregates& a, const BenchDescription& bench,
                           const std::string& scenario) {
  std::string md = "\nF1 (exact) per fused view:\n\n| planner |";
  for (int v = 1; v <= bench.views; ++v) md += fmt::format(" {} |", v);
  md += "\n|---|";
  for (int v = 1; v <= bench.views; ++v) md += "---|";
  md += "\n";
  for (const std::string& p : bench.planners) {
    md += "| " + p + " |";
    for (int v = 0; v < bench.views; ++v) {
      md += fmt::format(" {:.3f} |", a.Stat({scenario, p}, "f1", v).mean);
    }
    md += "\n";
  }
  return md;
}

/// Plots in the style of the paper's Fig. 3: one series per planner, its 95 % interval as a band.
Status WriteScenarioPlots(const fs::path& out_dir, const Aggregates& a,
                          const BenchDescription& bench, const std::string& scenario,
                          std::vector<fs::path>& files) {
  for (const auto& [metric, label, file] :
       {std::tuple{"f1", "voxel F1 (exact)", "f1"},
        std::tuple{"fruits_found_fraction", "fraction of fruits found", "fruits"}}) {
    LinePlot plot;
    plot.title =
        fmt::format("{}: {} ({} seeds, mean and 95 % interval)", scenario, label, bench.seeds);
    plot.x_label = "fused views";
    plot.y_label = label;
    plot.y_min = 0.0;
    plot.y_max = 1.0;
    for (const std::string& p : bench.planners) {
      LineSeries series;
      // The legend says when the band rests on few seeds (or there is none).
      const size_t n = a.Stat({scenario, p}, metric, std::max(bench.views - 1, 0)).n;
      series.name = n < eval::kSmallSample
                        ? fmt::format("{} (n = {}{})", p, n, n < 2 ? ", no interval" : ", small")
                        : p;
      for (int v = 0; v < bench.views; ++v) {
        const eval::Summary st = a.Stat({scenario, p}, metric, v);
        series.x.push_back(v + 1);
        series.y.push_back(st.mean);
        series.band_lo.push_back(st.ci_lo);
        series.band_hi.push_back(st.ci_hi);
      }
      plot.series.push_back(series);
    }
    const fs::path svg = out_dir / fmt::format("{}_{}.svg", file, SafeFileName(scenario));
    AVP_RETURN_IF_ERROR(WriteLinePlotSvg(svg, plot));
    files.push_back(svg);
  }
  return Status::Ok();
}

}  // namespace

void FruitVisibility::Add(const eval::GroundTruth& gt) {
  if (gt.best_visible_fraction.empty()) return;
  fruits += static_cast<double>(gt.fruits.size());
  for (size_t l = 0; l < visible.size(); ++l) {
    visible[l] += static_cast<double>(gt.FruitsVisibleAtLeast(eval::kVisibleFractionLevels[l]));
  }
}

std::pair<double, double> WilsonInterval95(size_t k, size_t n) {
  if (n == 0) {
    return {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
  }
  constexpr double z = 1.96;
  const double nn = static_cast<double>(n);
  const double p = static_cast<double>(k) / nn;
  const double denom = 1.0 + z * z / nn;
  const double centre = (p + z * z / (2.0 * nn)) / denom;
  const double half = z * std::sqrt(p * (1.0 - p) / nn + z * z / (4.0 * nn * nn)) / denom;
  // The ends are exact: 0 found has lower bound 0, all found upper bound 1.
  return {k == 0 ? 0.0 : std::max(0.0, centre - half), k == n ? 1.0 : std::min(1.0, centre + half)};
}

std::vector<VisibilityBin> FoundByVisibility(const std::vector<BenchEpisode>& episodes,
                                             const std::string& scenario,
                                             const std::string& planner) {
  constexpr size_t kLevels = eval::kVisibleFractionLevels.size();
  std::vector<VisibilityBin> bins(kLevels + 1);
  for (size_t i = 0; i < bins.size(); ++i) {
    bins[i].lo = i == 0 ? 0.0 : eval::kVisibleFractionLevels[i - 1];
    bins[i].hi = i == kLevels ? 1.0 : eval::kVisibleFractionLevels[i];
  }
  for (const BenchEpisode& e : episodes) {
    if (e.scenario != scenario || e.planner != planner || !e.status.ok() || e.metrics.empty()) {
      continue;
    }
    for (const BenchFruit& f : e.fruits) {
      if (!std::isfinite(f.best_visible_fraction)) continue;
      size_t i = 0;
      while (i < kLevels && f.best_visible_fraction >= eval::kVisibleFractionLevels[i]) ++i;
      ++bins[i].fruits;
      bins[i].found += f.found ? 1 : 0;
    }
  }
  for (VisibilityBin& b : bins) {
    if (b.fruits == 0) continue;
    b.fraction = static_cast<double>(b.found) / static_cast<double>(b.fruits);
    std::tie(b.ci_lo, b.ci_hi) = WilsonInterval95(b.found, b.fruits);
  }
  return bins;
}

RegretSummary SummarizeRegret(const std::vector<BenchEpisode>& episodes,
                              const std::string& scenario, const std::string& planner) {
  std::vector<double> regret, rank, correlation, candidates;
  RegretSummary out;
  for (const BenchEpisode& e : episodes) {
    if (e.scenario != scenario || e.planner != planner || !e.status.ok() || e.metrics.empty()) {
      continue;
    }
    for (const BenchRegret& r : e.regret) {
      ++out.plans;
      if (std::isfinite(r.regret)) regret.push_back(r.regret);
      rank.push_back(static_cast<double>(r.chosen_true_rank));
      candidates.push_back(static_cast<double>(r.candidates));
      out.best_chosen += r.chosen_true_rank == 1 ? 1 : 0;
      if (std::isfinite(r.rank_correlation)) correlation.push_back(r.rank_correlation);
    }
  }
  if (out.plans == 0) return out;
  const eval::Summary rs = eval::Summarize(regret);
  out.regret_mean = rs.mean;
  out.regret_lo = rs.ci_lo;
  out.regret_hi = rs.ci_hi;
  out.chosen_rank_median = eval::Median(rank);
  out.candidates_median = eval::Median(candidates);
  out.correlated = correlation.size();
  const eval::Summary cs = eval::Summarize(correlation);
  out.rank_correlation_mean = cs.mean;
  out.rank_correlation_lo = cs.ci_lo;
  out.rank_correlation_hi = cs.ci_hi;
  out.rank_correlation_median = eval::Median(correlation);
  return out;
}

std::vector<PairedLead> PairedLeads(const std::vector<BenchEpisode>& episodes,
                                    const std::string& scenario,
                                    const std::vector<std::string>& planners) {
  std::vector<PairedLead> leads;
  if (planners.size() < 2) return leads;
  // seed -> (F1, found fraction) at the final view, per planner, successful episodes only.
  const auto finals = [&](const std::string& planner) {
    std::map<uint64_t, std::pair<double, double>> out;
    for (const BenchEpisode& e : episodes) {
      if (e.scenario != scenario || e.planner != planner || !e.status.ok() || e.metrics.empty()) {
        continue;
      }
      double f1 = std::numeric_limits<double>::quiet_NaN(), found = f1;
      for (const auto& [name, value] : e.metrics.back()) {
        if (name == "f1") f1 = value;
        if (name == "fruits_found_fraction") found = value;
      }
      out[e.seed] = {f1, found};
    }
    return out;
  };
  const auto lead = finals(planners.front());
  for (size_t i = 1; i < planners.size(); ++i) {
    const auto other = finals(planners[i]);
    std::vector<double> d_f1, d_found;
    for (const auto& [seed, a] : lead) {
      const auto b = other.find(seed);
      if (b == other.end()) continue;
      d_f1.push_back(a.first - b->second.first);
      d_found.push_back(a.second - b->second.second);
    }
    PairedLead l;
    l.scenario = scenario;
    l.planner = planners.front();
    l.versus = planners[i];
    l.f1 = eval::Summarize(d_f1);
    l.found = eval::Summarize(d_found);
    l.verdict = eval::PairedVerdict(l.f1);
    leads.push_back(std::move(l));
  }
  return leads;
}

std::string SafeFileName(std::string s) {
  for (char& c : s) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.')) c = '_';
  }
  return s;
}

Result<BenchTables> WriteBenchSummary(const fs::path& out_dir, const BenchDescription& bench,
                                      const std::vector<BenchEpisode>& episodes, double seconds) {
  const Aggregates a = Aggregate(episodes, bench.views);
  BenchTables tables;
  tables.failed = a.failed_total;
  std::string lead_csv;
  for (const std::string& s : bench.scenarios) {
    const std::vector<PairedLead> leads = PairedLeads(episodes, s, bench.planners);
    lead_csv += LeadCsv(leads, bench);
    tables.leads.insert(tables.leads.end(), leads.begin(), leads.end());
  }
  const fs::path csv_path = out_dir / "summary.csv";
  AVP_RETURN_IF_ERROR(
      io::WriteFileAtomic(csv_path, SummaryCsv(a, bench) + RegretCsv(episodes, bench) + lead_csv));
  const fs::path visibility_csv = out_dir / "fruits_by_visibility.csv";
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(visibility_csv, VisibilityCsv(episodes, bench)));
  std::vector<fs::path> plots;
  std::string md = MarkdownHeader(bench, seconds);
  for (const std::string& s : bench.scenarios) {
    md += FinalViewTable(a, bench, s, tables.cells);
    std::vector<PairedLead> leads;
    for (const PairedLead& l : tables.leads) {
      if (l.scenario == s) leads.push_back(l);
    }
    md += LeadTable(leads, bench);
    md += VisibilityLine(bench, s);
    md += VisibilityTable(episodes, bench, s);
    md += F1PerViewTable(a, bench, s);
    md += RegretTable(episodes, bench, s);
    AVP_RETURN_IF_ERROR(WriteScenarioPlots(out_dir, a, bench, s, plots));
  }
  const fs::path md_path = out_dir / "summary.md";
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(md_path, md));
  tables.files = {md_path, csv_path, visibility_csv};
  tables.files.insert(tables.files.end(), plots.begin(), plots.end());
  return tables;
}

}  // namespace avp::report

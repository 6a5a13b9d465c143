#include "avp/report/conditions.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <system_error>
#include <tuple>
#include <utility>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <avp/io/file.h>
#include <avp/io/json.h>

namespace avp::report {

namespace fs = std::filesystem;

namespace {

std::vector<std::string> SplitCsvLine(const std::string& line) {
  std::vector<std::string> fields;
  std::string field;
  std::istringstream in(line);
  while (std::getline(in, field, ',')) fields.push_back(field);
  if (!line.empty() && line.back() == ',') fields.emplace_back();
  return fields;
}

/// A number of metrics.csv ("nan" is one).
Result<double> CsvNumber(const std::string& text, const fs::path& file, size_t row,
                         const std::string& column) {
  const char* begin = text.c_str();
  char* end = nullptr;
  const double v = std::strtod(begin, &end);
  if (text.empty() || end != begin + text.size()) {
    return ParseError(fmt::format("{}: row {}: column {} ('{}') is not a number", file.string(),
                                  row, column, text));
  }
  return v;
}

/// The views, final F1 and final found fraction of a run's metrics.csv.
Status ReadMetrics(const fs::path& file, BenchRunResult& r) {
  AVP_ASSIGN_OR_RETURN(const std::string text, io::ReadFileBounded(file, "metrics file"));
  std::istringstream in(text);
  std::string line;
  if (!std::getline(in, line)) return ParseError(fmt::format("{}: no header", file.string()));
  const std::vector<std::string> header = SplitCsvLine(line);
  const auto column = [&](const std::string& name) -> Result<size_t> {
    const auto it = std::find(header.begin(), header.end(), name);
    if (it == header.end()) {
      return ParseError(fmt::format("{}: no column '{}' in the header", file.string(), name));
    }
    return static_cast<size_t>(it - header.begin());
  };
  AVP_ASSIGN_OR_RETURN(const size_t f1_col, column("f1"));
  AVP_ASSIGN_OR_RETURN(const size_t found_col, column("fruits_found_fraction"));
  size_t row = 1;
  while (std::getline(in, line)) {
    ++row;
    if (line.empty()) continue;
    const std::vector<std::string> fields = SplitCsvLine(line);
    if (fields.size() <= std::max(f1_col, found_col)) {
      return ParseError(fmt::format("{}: row {} has {} fields", file.string(), row, fields.size()));
    }
    AVP_ASSIGN_OR_RETURN(r.f1, CsvNumber(fields[f1_col], file, row, "f1"));
    AVP_ASSIGN_OR_RETURN(r.found_fraction,
                         CsvNumber(fields[found_col], file, row, "fruits_found_fraction"));
    ++r.views;
  }
  return Status::Ok();
}

Result<BenchRunResult> ReadRun(const fs::path& dir) {
  BenchRunResult r;
  // Names from the path until record.json says them (a run that never finished has none).
  r.scenario = dir.parent_path().parent_path().filename().string();
  r.planner = dir.parent_path().filename().string();
  // ReadBenchRuns passes only folders named seed-<n>.
  const std::string seed_text = dir.filename().string().substr(5);
  std::from_chars(seed_text.data(), seed_text.data() + seed_text.size(), r.seed);
  std::error_code ec;
  if (!fs::exists(dir / "record.json", ec)) {
    r.error = "no record.json (the episode failed or never finished)";
    if (Result<nlohmann::json> state = io::ReadJsonFile(dir / "avp-state.json"); state.ok()) {
      const nlohmann::json& s = *state;
      r.error = fmt::format("state {}{}", s.value("state", std::string("unknown")),
                            s.contains("error") ? ": " + s.value("error", std::string()) : "");
    }
    return r;
  }
  AVP_ASSIGN_OR_RETURN(const nlohmann::json rec, io::ReadJsonFile(dir / "record.json"));
  try {
    r.scenario = rec.at("scenario").get<std::string>();
    r.planner = rec.at("planner").get<std::string>();
    r.seed = rec.at("seed").get<uint64_t>();
    const std::string end = rec.at("end").get<std::string>();
    if (end == "segmenter-fault") {
      r.error = "segmenter fault: " + rec.value("end_reason", std::string());
      return r;
    }
  } catch (const nlohmann::json::exception& e) {
    return ParseError(
        fmt::format("{}: not a bench record: {}", (dir / "record.json").string(), e.what()));
  }
  AVP_RETURN_IF_ERROR(ReadMetrics(dir / "metrics.csv", r));
  r.ok = r.views > 0;
  if (!r.ok) r.error = "no views";
  return r;
}

/// A number of a record, null for NaN (record.json writes non-finite numbers as null).
double JsonNumber(const nlohmann::json& j) {
  return j.is_null() ? std::numeric_limits<double>::quiet_NaN() : j.get<double>();
}

/// Every metric of every view of a run's metrics.csv: the columns after `view` and before
/// `known_voxels` (MetricsCsvWriter writes the step's metrics there, in their order).
Status ReadAllMetrics(const fs::path& file, BenchEpisode& e) {
  AVP_ASSIGN_OR_RETURN(const std::string text, io::ReadFileBounded(file, "metrics file"));
  std::istringstream in(text);
  std::string line;
  if (!std::getline(in, line)) return ParseError(fmt::format("{}: no header", file.string()));
  const std::vector<std::string> header = SplitCsvLine(line);
  const auto end = std::find(header.begin(), header.end(), "known_voxels");
  if (header.empty() || header.front() != "view" || end == header.end()) {
    return ParseError(fmt::format(
        "{}: not an avp metrics file (the header must start with view and hold known_voxels)",
        file.string()));
  }
  const size_t n = static_cast<size_t>(end - header.begin());
  size_t row = 1;
  while (std::getline(in, line)) {
    ++row;
    if (line.empty()) continue;
    const std::vector<std::string> fields = SplitCsvLine(line);
    if (fields.size() != header.size()) {
      return ParseError(fmt::format("{}: row {} has {} fields, the header {}", file.string(), row,
                                    fields.size(), header.size()));
    }
    std::vector<std::pair<std::string, double>> metrics;
    metrics.reserve(n - 1);
    for (size_t c = 1; c < n; ++c) {
      AVP_ASSIGN_OR_RETURN(const double v, CsvNumber(fields[c], file, row, header[c]));
      metrics.emplace_back(header[c], v);
    }
    e.metrics.push_back(std::move(metrics));
  }
  return Status::Ok();
}

/// conditions.csv writes names unquoted: none may hold a comma, a quote or a line break.
Status CheckCsvName(std::string_view what, const std::string& name) {
  if (name.find_first_of(",\"\r\n") == std::string::npos) return Status::Ok();
  return InvalidArgumentError(fmt::format(
      "the {} name '{}' holds a comma, a quote or a line break, which would break the columns of "
      "conditions.csv: rename it",
      what, name));
}

std::string Num(double v) { return std::isfinite(v) ? fmt::format("{:.3f}", v) : "nan"; }
std::string MeanCi(const eval::Summary& s) { return eval::FormatMeanInterval(s); }
std::string Csv(const eval::Summary& s) {
  return fmt::format("{:.9g},{:.9g},{:.9g},{}", s.mean, s.ci_lo, s.ci_hi, s.n);
}

}  // namespace

Result<std::vector<BenchRunResult>> ReadBenchRuns(const fs::path& bench_dir) {
  const fs::path runs = bench_dir / "runs";
  std::error_code ec;
  if (!fs::is_directory(runs, ec)) {
    return NotFoundError(
        fmt::format("'{}' is not an avp bench folder: it has no runs/ folder", bench_dir.string()));
  }
  std::vector<fs::path> dirs;
  for (const auto& scenario : fs::directory_iterator(runs, ec)) {
    if (!scenario.is_directory()) continue;
    for (const auto& planner : fs::directory_iterator(scenario.path(), ec)) {
      if (!planner.is_directory()) continue;
      for (const auto& seed : fs::directory_iterator(planner.path(), ec)) {
        if (!seed.is_directory()) continue;
        const std::string name = seed.path().filename().string();
        uint64_t n = 0;
        const char* first = name.data() + std::min<size_t>(5, name.size());
        const char* last = name.data() + name.size();
        const auto [ptr, err] = std::from_chars(first, last, n);
        if (name.rfind("seed-", 0) != 0 || first == last || err != std::errc() || ptr != last) {
          return InvalidArgumentError(fmt::format(
              "'{}' is not a run folder of an avp bench (runs/<scenario>/<planner>/seed-<n>, n a "
              "whole number)",
              seed.path().string()));
        }
        dirs.push_back(seed.path());
      }
    }
  }
  if (ec) return IoError(fmt::format("cannot list '{}': {}", runs.string(), ec.message()));
  std::sort(dirs.begin(), dirs.end());
  std::vector<BenchRunResult> out;
  out.reserve(dirs.size());
  for (const fs::path& d : dirs) {
    AVP_ASSIGN_OR_RETURN(BenchRunResult r, ReadRun(d));
    out.push_back(std::move(r));
  }
  return out;
}

Result<BenchEpisode> ReadBenchEpisode(const fs::path& dir, const std::string& scenario,
                                      const std::string& planner, uint64_t seed) {
  BenchEpisode e;
  e.scenario = scenario;
  e.planner = planner;
  e.seed = seed;
  const Result<nlohmann::json> state = io::ReadJsonFile(dir / "avp-state.json");
  if (!state.ok()) {
    e.status = UnavailableError(
        fmt::format("'{}' holds no finished episode: {}", dir.string(), state.status().message()));
    return e;
  }
  const std::string s = state->is_object() ? state->value("state", std::string("unknown")) : "";
  if (s != "complete") {
    const std::string error = state->is_object() ? state->value("error", std::string()) : "";
    e.status = UnavailableError(fmt::format("'{}': state {}{}", dir.string(), s.empty() ? "?" : s,
                                            error.empty() ? "" : ": " + error));
    return e;
  }
  const fs::path file = dir / "record.json";
  AVP_ASSIGN_OR_RETURN(const nlohmann::json rec, io::ReadJsonFile(file));
  try {
    const std::string r_scenario = rec.at("scenario").get<std::string>();
    const std::string r_planner = rec.at("planner").get<std::string>();
    const uint64_t r_seed = rec.at("seed").get<uint64_t>();
    if (r_scenario != scenario || r_planner != planner || r_seed != seed) {
      return ParseError(
          fmt::format("{}: the record of {} / {} / seed {} where {} / {} / seed {} belongs",
                      file.string(), r_scenario, r_planner, r_seed, scenario, planner, seed));
    }
    e.episode_s = rec.at("episode_seconds").get<double>();
    for (const nlohmann::json& t : rec.value("plan_ms", nlohmann::json::array())) {
      e.plan_ms.push_back(JsonNumber(t));
    }
    // The episode's moves (docs/motion.md); absent in records older than motion planning.
    if (const auto m = rec.find("motion"); m != rec.end() && m->is_object()) {
      const auto total = [&](const char* key) {
        const auto c = m->find(key);
        return c != m->end() && c->is_object() ? JsonNumber(c->at("total"))
                                               : std::numeric_limits<double>::quiet_NaN();
      };
      e.contacts = total("contacts");
      e.straight_line_contacts = total("straight_line_contacts");
      e.motion_s = JsonNumber(m->value("execution_s", nlohmann::json(0.0)));
      for (const nlohmann::json& t : m->value("planning_ms", nlohmann::json::array())) {
        e.move_planning_ms.push_back(JsonNumber(t));
      }
      if (const auto start = m->find("start_clearance");
          start != m->end() && start->is_object() && start->value("checked", false)) {
        e.start_clearance_broken = start->value("broken", false) ? 1.0 : 0.0;
      }
    }
    for (const nlohmann::json& f : rec.at("fruits")) {
      e.fruits.push_back({.best_visible_fraction = JsonNumber(f.at("best_visible_fraction")),
                          .episode_visible_fraction = JsonNumber(f.at("episode_visible_fraction")),
                          .found = f.at("found").get<bool>()});
    }
    for (const nlohmann::json& g : rec.value("oracle_regret", nlohmann::json::array())) {
      e.regret.push_back({.step = g.at("step").get<int>(),
                          .candidates = g.at("candidates").get<size_t>(),
                          .regret = JsonNumber(g.at("regret")),
                          .chosen_true_rank = g.at("chosen_true_rank").get<size_t>(),
                          .rank_correlation = JsonNumber(g.at("rank_correlation"))});
    }
    if (rec.at("end").get<std::string>() == "segmenter-fault") {
      e.status = UnavailableError(
          fmt::format("segmenter fault: {}", rec.value("end_reason", std::string())));
    }
  } catch (const nlohmann::json::exception& ex) {
    return ParseError(fmt::format("{}: not a bench record: {}", file.string(), ex.what()));
  }
  AVP_RETURN_IF_ERROR(ReadAllMetrics(dir / "metrics.csv", e));
  return e;
}

namespace {

/// (condition, scenario, planner) -> seed -> run.
using RunKey = std::tuple<std::string, std::string, std::string>;
using RunMap = std::map<RunKey, std::map<uint64_t, BenchRunResult>>;

/// Every condition's runs, with the scenarios and planners in order of first appearance (the
/// lead planner first).
struct ConditionRuns {
  std::vector<std::string> scenarios;
  std::vector<std::string> planners;
  RunMap runs;
};

/// Each condition named once, with a name fit for a CSV field.
Status CheckConditionNames(const std::vector<ConditionBench>& conditions) {
  std::set<std::string> names;
  for (const ConditionBench& c : conditions) {
    if (!names.insert(c.name).second) {
      return InvalidArgumentError(fmt::format("the condition '{}' is given twice", c.name));
    }
    AVP_RETURN_IF_ERROR(CheckCsvName("condition", c.name));
  }
  return Status::Ok();
}

/// The tables may not go into a bench they read (its own files, its --force). `out`: out_dir
/// made canonical (`out_ok`: without error).
Status CheckOutsideBench(const fs::path& out_dir, const fs::path& out, bool out_ok,
                         const ConditionBench& c) {
  std::error_code in_ec;
  const fs::path in = fs::weakly_canonical(fs::absolute(c.dir, in_ec), in_ec);
  const auto in_end = std::mismatch(in.begin(), in.end(), out.begin(), out.end()).first;
  if (out_ok && !in_ec && !in.empty() && in_end == in.end()) {
    return InvalidArgumentError(
        fmt::format("the output folder '{}' is inside the bench folder '{}' of condition '{}': "
                    "write the tables elsewhere",
                    out_dir.string(), c.dir.string(), c.name));
  }
  return Status::Ok();
}

Result<ConditionRuns> ReadConditionRuns(const fs::path& out_dir,
                                        const std::vector<ConditionBench>& conditions,
                                        const std::string& lead) {
  std::error_code ec;
  const fs::path out = fs::weakly_canonical(fs::absolute(out_dir, ec), ec);
  ConditionRuns all;
  all.planners = {lead};
  for (const ConditionBench& c : conditions) {
    AVP_ASSIGN_OR_RETURN(const std::vector<BenchRunResult> list, ReadBenchRuns(c.dir));
    AVP_RETURN_IF_ERROR(CheckOutsideBench(out_dir, out, !ec, c));
    bool has_lead = false;
    for (const BenchRunResult& r : list) {
      AVP_RETURN_IF_ERROR(CheckCsvName("scenario", r.scenario));
      AVP_RETURN_IF_ERROR(CheckCsvName("planner", r.planner));
      if (std::find(all.scenarios.begin(), all.scenarios.end(), r.scenario) ==
          all.scenarios.end()) {
        all.scenarios.push_back(r.scenario);
      }
      if (std::find(all.planners.begin(), all.planners.end(), r.planner) == all.planners.end()) {
        all.planners.push_back(r.planner);
      }
      has_lead = has_lead || r.planner == lead;
      all.runs[{c.name, r.scenario, r.planner}][r.seed] = r;
    }
    if (!has_lead) {
      return InvalidArgumentError(
          fmt::format("the lead planner '{}' has no run in condition '{}' "
                      "('{}')",
                      lead, c.name, c.dir.string()));
    }
  }
  return all;
}

/// One planner's final-view F1, found fraction and views over the seeds (failed runs counted).
ConditionCell Cell(const std::string& condition, const std::string& scenario,
                   const std::string& planner, const std::map<uint64_t, BenchRunResult>& seeds) {
  ConditionCell cell;
  cell.condition = condition;
  cell.scenario = scenario;
  cell.planner = planner;
  std::vector<double> f1, found, views;
  for (const auto& [seed, r] : seeds) {
    if (!r.ok) {
      ++cell.failed;
      continue;
    }
    f1.push_back(r.f1);
    found.push_back(r.found_fraction);
    views.push_back(r.views);
  }
  cell.f1 = eval::Summarize(f1);
  cell.found = eval::Summarize(found);
  cell.views = eval::Summarize(views);
  return cell;
}

/// The lead planner's F1 and found fraction minus another's, seed by seed (both runs ok).
ConditionLead Lead(const std::string& condition, const std::string& scenario,
                   const std::string& lead, const std::string& versus,
                   const std::map<uint64_t, BenchRunResult>& lead_seeds,
                   const std::map<uint64_t, BenchRunResult>& other_seeds) {
  std::vector<double> d_f1, d_found;
  for (const auto& [seed, a] : lead_seeds) {
    const auto b = other_seeds.find(seed);
    if (!a.ok || b == other_seeds.end() || !b->second.ok) continue;
    d_f1.push_back(a.f1 - b->second.f1);
    d_found.push_back(a.found_fraction - b->second.found_fraction);
  }
  ConditionLead l;
  l.condition = condition;
  l.scenario = scenario;
  l.planner = lead;
  l.versus = versus;
  l.f1 = eval::Summarize(d_f1);
  l.found = eval::Summarize(d_found);
  l.verdict = eval::PairedVerdict(l.f1);
  return l;
}

/// The cells and leads of every (scenario, condition), into `t`; returns conditions.csv.
std::string ScoreConditions(const ConditionRuns& all, const std::vector<ConditionBench>& conditions,
                            const std::string& lead, ConditionTables& t) {
  std::string csv = "condition,scenario,planner,versus,metric,mean,ci_lo,ci_hi,n\n";
  for (const std::string& s : all.scenarios) {
    for (const ConditionBench& c : conditions) {
      for (const std::string& p : all.planners) {
        const auto it = all.runs.find({c.name, s, p});
        if (it == all.runs.end()) continue;
        ConditionCell cell = Cell(c.name, s, p, it->second);
        csv += fmt::format("{},{},{},,f1,{}\n", c.name, s, p, Csv(cell.f1));
        csv += fmt::format("{},{},{},,fruits_found_fraction,{}\n", c.name, s, p, Csv(cell.found));
        csv += fmt::format("{},{},{},,views,{}\n", c.name, s, p, Csv(cell.views));
        t.cells.push_back(std::move(cell));
      }
      const auto lead_runs = all.runs.find({c.name, s, lead});
      if (lead_runs == all.runs.end()) continue;
      for (const std::string& p : all.planners) {
        if (p == lead) continue;
        const auto other = all.runs.find({c.name, s, p});
        if (other == all.runs.end()) continue;
        ConditionLead l = Lead(c.name, s, lead, p, lead_runs->second, other->second);
        csv += fmt::format("{},{},{},{},f1_lead,{}\n", c.name, s, lead, p, Csv(l.f1));
        csv += fmt::format("{},{},{},{},found_lead,{}\n", c.name, s, lead, p, Csv(l.found));
        t.leads.push_back(std::move(l));
      }
    }
  }
  return csv;
}

const ConditionCell* FindCell(const ConditionTables& t, const std::string& c, const std::string& s,
                              const std::string& p) {
  for (const ConditionCell& x : t.cells) {
    if (x.condition == c && x.scenario == s && x.planner == p) return &x;
  }
  return nullptr;
}

const ConditionLead* FindLead(const ConditionTables& t, const std::string& c, const std::string& s,
                              const std::string& p) {
  for (const ConditionLead& x : t.leads) {
    if (x.condition == c && x.scenario == s && x.versus == p) return &x;
  }
  return nullptr;
}

/// The markdown table of one scenario: a row per condition, F1 / found per planner, the lead's
/// F1 lead over each other planner, and the lead's views.
std::string ScenarioTable(const ConditionTables& t, const std::string& s,
                          const std::vector<ConditionBench>& conditions,
                          const std::vector<std::string>& planners, const std::string& lead) {
  std::string md = fmt::format("\n## {}\n\n| condition |", s);
  std::string rule = "|---|";
  for (const std::string& p : planners) {
    md += fmt::format(" {} F1 / found |", p);
    rule += "---|";
  }
  for (size_t i = 1; i < planners.size(); ++i) {
    md += fmt::format(" F1 lead vs {} |", planners[i]);
    rule += "---|";
  }
  md += fmt::format(" views ({}) |\n{}---|\n", lead, rule);
  for (const ConditionBench& c : conditions) {
    md += fmt::format("| {} |", c.name);
    for (const std::string& p : planners) {
      const ConditionCell* x = FindCell(t, c.name, s, p);
      md += x == nullptr ? " – |"
                         : fmt::format(" {} / {}{} |", MeanCi(x->f1), Num(x->found.mean),
                                       x->failed > 0 ? fmt::format(" ({} failed)", x->failed)
                                                     : std::string());
    }
    for (size_t i = 1; i < planners.size(); ++i) {
      const ConditionLead* l = FindLead(t, c.name, s, planners[i]);
      md += l == nullptr ? " – |"
                         : fmt::format(" {} {} |", eval::FormatMeanInterval(l->f1, 3, true),
                                       l->verdict == "ahead" ? "**ahead**" : l->verdict);
    }
    const ConditionCell* x = FindCell(t, c.name, s, lead);
    md += fmt::format(" {} |\n", x == nullptr ? "–" : fmt::format("{:.1f}", x->views.mean));
  }
  return md;
}

/// How often the lead planner is ahead, and every comparison where it is not.
std::string LeadSummary(const ConditionTables& t, const std::string& lead) {
  std::vector<const ConditionLead*> not_ahead;
  for (const ConditionLead& l : t.leads) {
    if (l.verdict != "ahead") not_ahead.push_back(&l);
  }
  std::string md =
      fmt::format("\n`{}` is ahead in {} of {} comparisons (condition × scenario × planner).", lead,
                  t.leads.size() - not_ahead.size(), t.leads.size());
  if (not_ahead.empty()) return md + "\n";
  md += " Not ahead:\n\n";
  for (const ConditionLead* l : not_ahead) {
    md += fmt::format("- {}, {}, vs {}: F1 {} ({}), found {}\n", l->condition, l->scenario,
                      l->versus, eval::FormatMeanInterval(l->f1, 3, true), l->verdict,
                      eval::FormatMeanInterval(l->found, 3, true));
  }
  return md;
}

/// conditions.md: the conditions, a table per scenario, and the lead's summary.
std::string ConditionMarkdown(const ConditionTables& t, const ConditionRuns& all,
                              const std::vector<ConditionBench>& conditions,
                              const std::string& lead) {
  std::string md = "# avp bench: conditions\n\n";
  md += fmt::format(
      "{} condition(s), {} scenario(s), planners {}. Final view, mean over seeds [95 % interval, "
      "a percentile bootstrap of the mean]; the lead of `{}` is its F1 minus the other planner's, "
      "seed by seed (paired): **ahead** when its 95 % interval is above 0, behind when below, "
      "tied when it holds 0, n/a below two seeds. `found` = fraction of the fruits found.\n\n",
      conditions.size(), all.scenarios.size(), fmt::join(all.planners, ", "), lead);
  md += "| condition | bench folder | what |\n|---|---|---|\n";
  for (const ConditionBench& c : conditions) {
    md += fmt::format("| {} | `{}` | {} |\n", c.name, c.dir.string(),
                      c.description.empty() ? "–" : c.description);
  }
  for (const std::string& s : all.scenarios) {
    md += ScenarioTable(t, s, conditions, all.planners, lead);
  }
  return md + LeadSummary(t, lead);
}

}  // namespace

Result<ConditionTables> WriteConditionTables(const fs::path& out_dir,
                                             const std::vector<ConditionBench>& conditions,
                                             const std::string& lead) {
  if (conditions.empty()) return InvalidArgumentError("no condition to compare");
  AVP_RETURN_IF_ERROR(CheckConditionNames(conditions));
  AVP_ASSIGN_OR_RETURN(const ConditionRuns all, ReadConditionRuns(out_dir, conditions, lead));
  ConditionTables t;
  const std::string csv = ScoreConditions(all, conditions, lead, t);
  const std::string md = ConditionMarkdown(t, all, conditions, lead);
  const fs::path csv_path = out_dir / "conditions.csv";
  const fs::path md_path = out_dir / "conditions.md";
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(csv_path, csv, "conditions table"));
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(md_path, md, "conditions table"));
  t.files = {md_path, csv_path};
  return t;
}

}  // namespace avp::report

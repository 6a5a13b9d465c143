#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include <avp/apps/run_command.h>
#include <avp/apps/scene_source.h>
#include <avp/core/parallel.h>
#include <avp/eval/statistics.h>
#include <avp/eval/svg_plot.h>
#include <avp/io/json.h>
#include <avp/io/yaml.h>
#include <avp/sim/scenario.h>

namespace avp::apps {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::string Join(const std::vector<std::string>& v) {
  std::string out;
  for (const std::string& s : v) out += (out.empty() ? "" : ", ") + s;
  return out;
}

/// One episode of the bench and what it produced.
struct Job {
  std::string scenario, planner;
  uint64_t seed = 0;
  size_t group = 0;  ///< index of its (scenario, seed) scene and ground truth
  Status status;
  std::vector<std::vector<std::pair<std::string, double>>> metrics;  ///< per fused view
  std::vector<double> plan_ms;
  double episode_s = 0.0;
  std::string end;
};

struct Group {
  std::string scenario;
  uint64_t seed = 0;
  Result<sim::Scene> scene = InternalError("not built");
  Result<eval::GroundTruth> gt = InternalError("not computed");
};

class ProgressBar {
 public:
  ProgressBar(bool enabled, size_t total, std::string what)
      : enabled_(enabled), total_(total), what_(std::move(what)), t0_(Clock::now()) {}
  void Tick() {
    const size_t done = ++done_;
    if (!enabled_) return;
    std::lock_guard<std::mutex> lock(mu_);
    const double s = SecondsSince(t0_);
    const double eta =
        done > 0 ? s / static_cast<double>(done) * static_cast<double>(total_ - done) : 0.0;
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(kWidth * static_cast<double>(done) /
                                        static_cast<double>(std::max<size_t>(total_, 1)));
    std::fprintf(stderr, "\r%s [%s%s] %zu/%zu  %.0f s elapsed, ~%.0f s left   ", what_.c_str(),
                 std::string(static_cast<size_t>(filled), '#').c_str(),
                 std::string(static_cast<size_t>(kWidth - filled), '.').c_str(), done, total_, s,
                 eta);
    if (done == total_) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  }

 private:
  bool enabled_;
  size_t total_;
  std::string what_;
  Clock::time_point t0_;
  std::atomic<size_t> done_{0};
  std::mutex mu_;
};

std::string SafeName(std::string s) {
  for (char& c : s) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.')) c = '_';
  }
  return s;
}

}  // namespace

Status BenchOptions::Validate() const {
  std::vector<std::string> errors;
  if (scenarios.empty()) errors.push_back("no scenario");
  if (planners.empty()) errors.push_back("no planner");
  if (seeds.empty()) errors.push_back("no seed");
  const auto& known = sim::ListScenarios();
  for (const std::string& s : scenarios) {
    if (std::none_of(known.begin(), known.end(), [&](const auto& k) { return k.name == s; })) {
      std::vector<std::string> names;
      for (const auto& k : known) names.push_back(k.name);
      errors.push_back(fmt::format("unknown scenario '{}' (known: {})", s, Join(names)));
    }
  }
  for (const std::string& p : planners) {
    if (!eval::IsKnownPlanner(p)) {
      errors.push_back(
          fmt::format("unknown planner '{}' (known: {})", p, Join(eval::KnownPlannerNames())));
    }
  }
  std::set<uint64_t> unique(seeds.begin(), seeds.end());
  if (unique.size() != seeds.size()) errors.push_back("seeds repeat");
  if (jobs < 0) errors.push_back(fmt::format("jobs ({}) must be >= 0", jobs));
  if (out_dir.empty()) errors.push_back("the output folder (--out) is empty");
  const bool has_avp_nbv = std::find(planners.begin(), planners.end(), "avp-nbv") != planners.end();
  if (!base.planner_options.empty() && !has_avp_nbv) {
    errors.push_back("avp-nbv options are given but avp-nbv is not among the planners");
  }
  if (errors.empty()) {
    eval::RunConfig probe = base;
    probe.planner = base.planner_options.empty() ? planners.front() : "avp-nbv";
    probe.scenario = scenarios.front();
    probe.scene_file.clear();
    return probe.Validate();
  }
  return InvalidArgumentError("invalid bench options: " + Join(errors));
}

Result<BenchOptions> LoadBenchConfig(const fs::path& yaml) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node root, io::LoadYamlFile(yaml));
  const std::string ctx = yaml.string();
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(
      root,
      {"description", "scenarios", "planners", "seeds", "views", "segmenter", "prompt",
       "voxel_size_m", "policy", "carving", "depth_noise", "max_range_m", "avp_nbv_options"},
      ctx));
  BenchOptions o;
  auto strings = [&](const char* key, std::vector<std::string>& out) -> Status {
    const YAML::Node n = root[key];
    if (!n || !n.IsSequence() || n.size() == 0) {
      return InvalidArgumentError(fmt::format("{}: '{}' must be a non-empty list", ctx, key));
    }
    for (const YAML::Node& item : n) out.push_back(item.as<std::string>());
    return Status::Ok();
  };
  try {
    AVP_RETURN_IF_ERROR(strings("scenarios", o.scenarios));
    AVP_RETURN_IF_ERROR(strings("planners", o.planners));
    const YAML::Node seeds = root["seeds"];
    if (seeds && seeds.IsSequence()) {
      for (const YAML::Node& s : seeds) o.seeds.push_back(s.as<uint64_t>());
    } else if (seeds && seeds.IsMap()) {
      AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(seeds, {"first", "count"}, ctx + ": seeds"));
      const uint64_t first = seeds["first"] ? seeds["first"].as<uint64_t>() : 0;
      const uint64_t count = seeds["count"].as<uint64_t>();
      for (uint64_t i = 0; i < count; ++i) o.seeds.push_back(first + i);
    } else {
      return InvalidArgumentError(
          fmt::format("{}: 'seeds' must be a list or {{first, count}}", ctx));
    }
    if (const YAML::Node opts = root["avp_nbv_options"]) {
      if (!opts.IsMap()) {
        return InvalidArgumentError(
            fmt::format("{}: 'avp_nbv_options' must be a map of option: value", ctx));
      }
      for (const auto& kv : opts) {
        o.base.planner_options[kv.first.as<std::string>()] = kv.second.as<std::string>();
      }
    }
    if (root["views"]) o.base.views = root["views"].as<int>();
    if (root["segmenter"]) o.base.segmenter = root["segmenter"].as<std::string>();
    if (root["prompt"]) o.base.prompt = root["prompt"].as<std::string>();
    if (root["voxel_size_m"]) o.base.voxel_size_m = root["voxel_size_m"].as<double>();
    if (root["max_range_m"]) o.base.max_range_m = root["max_range_m"].as<double>();
    if (root["depth_noise"]) o.base.depth_noise = root["depth_noise"].as<bool>();
    if (root["policy"]) {
      const std::string p = root["policy"].as<std::string>();
      const auto policy = mapping::FusionPolicyFromString(p);
      if (!policy) return InvalidArgumentError(fmt::format("{}: unknown policy '{}'", ctx, p));
      o.base.policy = *policy;
    }
    if (root["carving"]) {
      const std::string c = root["carving"].as<std::string>();
      const auto carving = mapping::FreeSpaceCarvingFromString(c);
      if (!carving) return InvalidArgumentError(fmt::format("{}: unknown carving '{}'", ctx, c));
      o.base.carving = *carving;
    }
  } catch (const YAML::Exception& e) {
    return InvalidArgumentError(fmt::format("{}: {}", ctx, e.what()));
  }
  return o;
}

Result<BenchSummary> RunBench(const BenchOptions& options) {
  const auto t0 = Clock::now();
  AVP_RETURN_IF_ERROR(options.Validate());
  std::error_code ec;
  fs::create_directories(options.out_dir / "runs", ec);
  if (ec) {
    return IoError(fmt::format("cannot create '{}': {}", options.out_dir.string(), ec.message()));
  }
  // Episodes run in parallel; inside each, one thread.
  eval::RunConfig base = options.base;
  base.threads = 1;
  base.scene_file.clear();

  // 1. Scenes and ground truths, one per (scenario, seed), shared by the planners.
  std::vector<Group> groups;
  for (const std::string& s : options.scenarios) {
    for (uint64_t seed : options.seeds) groups.push_back(Group{s, seed});
  }
  {
    ProgressBar bar(options.progress, groups.size(), "ground truth");
    ParallelFor(groups.size(), options.jobs, [&](size_t i) {
      Group& g = groups[i];
      g.scene = sim::MakeScenario(g.scenario, g.seed);
      if (g.scene.ok()) {
        eval::RunConfig c = base;
        c.scenario = g.scenario;
        c.seed = g.seed;
        g.gt = eval::GroundTruthFor(c, *g.scene);
      }
      bar.Tick();
    });
  }
  for (const Group& g : groups) {
    if (!g.scene.ok()) return g.scene.status();
    if (!g.gt.ok()) {
      return Status(g.gt.status().code(), fmt::format("ground truth of {} seed {}: {}", g.scenario,
                                                      g.seed, g.gt.status().message()));
    }
  }

  // 2. Episodes.
  std::vector<Job> jobs;
  for (size_t gi = 0; gi < groups.size(); ++gi) {
    for (const std::string& p : options.planners) {
      Job j;
      j.scenario = groups[gi].scenario;
      j.seed = groups[gi].seed;
      j.planner = p;
      j.group = gi;
      jobs.push_back(std::move(j));
    }
  }
  {
    ProgressBar bar(options.progress, jobs.size(), "episodes");
    ParallelFor(jobs.size(), options.jobs, [&](size_t i) {
      Job& j = jobs[i];
      const Group& g = groups[j.group];
      eval::RunConfig c = base;
      c.scenario = j.scenario;
      c.seed = j.seed;
      c.planner = j.planner;
      if (c.planner != "avp-nbv") c.planner_options.clear();  // they are avp-nbv's
      const fs::path dir = options.out_dir / "runs" / SafeName(j.scenario) / SafeName(j.planner) /
                           fmt::format("seed-{}", j.seed);
      std::error_code e;
      fs::create_directories(dir, e);
      Result<std::unique_ptr<eval::MetricsCsvWriter>> csv =
          eval::MetricsCsvWriter::Open(dir / "metrics.csv");
      std::vector<pipeline::EpisodeObserver*> observers;
      if (csv.ok()) observers.push_back(csv->get());
      const auto te = Clock::now();
      Result<eval::RunResult> r = eval::RunEpisodeOnScene(c, *g.scene, *g.gt, observers);
      j.episode_s = SecondsSince(te);
      if (!r.ok()) {
        j.status = r.status();
      } else {
        j.end = std::string(pipeline::ToString(r->episode.end));
        for (const pipeline::StepRecord& s : r->episode.steps) {
          j.metrics.push_back(s.metrics);
          if (s.planned) j.plan_ms.push_back(s.times.plan_ms);
        }
        nlohmann::json rec{{"scenario", j.scenario},
                           {"planner", j.planner},
                           {"seed", j.seed},
                           {"segmenter", c.segmenter},
                           {"views", c.views},
                           {"planner_options", c.planner_options},
                           {"end", j.end},
                           {"end_reason", r->episode.end_reason},
                           {"episode_seconds", j.episode_s},
                           {"git_revision", SourceRevision()}};
        (void)io::WriteJsonFile(dir / "record.json", rec);
      }
      bar.Tick();
    });
  }

  // 3. Aggregate: per (scenario, planner, view, metric) over seeds. An episode that ended early
  // keeps its last map, so its last metrics carry on to the remaining views.
  BenchSummary summary;
  summary.episodes = jobs.size();
  const int views = base.views;
  struct Key {
    std::string scenario, planner;
    bool operator<(const Key& o) const {
      return std::tie(scenario, planner) < std::tie(o.scenario, o.planner);
    }
  };
  // values[key][metric][view] -> samples
  std::map<Key, std::map<std::string, std::vector<std::vector<double>>>> values;
  std::map<Key, std::vector<double>> plan_ms, episode_s;
  std::map<Key, size_t> failed;
  std::vector<std::string> metric_order;
  for (const Job& j : jobs) {
    const Key key{j.scenario, j.planner};
    if (!j.status.ok() || j.metrics.empty()) {
      ++failed[key];
      ++summary.failed;
      continue;
    }
    if (metric_order.empty()) {
      for (const auto& [name, v] : j.metrics.front()) metric_order.push_back(name);
    }
    for (int v = 0; v < views; ++v) {
      const auto& row = j.metrics[std::min<size_t>(static_cast<size_t>(v), j.metrics.size() - 1)];
      for (const auto& [name, value] : row) {
        auto& per_view = values[key][name];
        per_view.resize(static_cast<size_t>(views));
        if (std::isfinite(value)) per_view[static_cast<size_t>(v)].push_back(value);
      }
    }
    plan_ms[key].insert(plan_ms[key].end(), j.plan_ms.begin(), j.plan_ms.end());
    episode_s[key].push_back(j.episode_s);
  }

  const fs::path csv_path = options.out_dir / "summary.csv";
  std::FILE* csv = std::fopen(csv_path.c_str(), "w");
  if (csv == nullptr) return IoError(fmt::format("cannot write '{}'", csv_path.string()));
  std::fprintf(csv, "scenario,planner,segmenter,view,metric,mean,ci95,n\n");
  for (const auto& [key, metrics] : values) {
    for (const std::string& name : metric_order) {
      auto it = metrics.find(name);
      if (it == metrics.end()) continue;
      for (int v = 0; v < views; ++v) {
        const std::vector<double>& xs = it->second[static_cast<size_t>(v)];
        const eval::Summary s = eval::Summarize(xs);
        std::fprintf(csv, "%s,%s,%s,%d,%s,%.9g,%.9g,%zu\n", key.scenario.c_str(),
                     key.planner.c_str(), base.segmenter.c_str(), v + 1, name.c_str(), s.mean,
                     std::isfinite(s.ci95) ? s.ci95 : 0.0, s.n);
      }
    }
  }
  std::fclose(csv);
  summary.files.push_back(csv_path);

  auto stat = [&](const Key& key, const std::string& metric, int view) {
    auto it = values.find(key);
    if (it == values.end()) return eval::Summary{};
    auto m = it->second.find(metric);
    if (m == it->second.end()) return eval::Summary{};
    return eval::Summarize(m->second[static_cast<size_t>(view)]);
  };
  auto mean_of = [](const std::vector<double>& xs) {
    double s = 0.0;
    for (double x : xs) s += x;
    return xs.empty() ? 0.0 : s / static_cast<double>(xs.size());
  };

  // Markdown: the final view per planner, then F1 per view.
  std::string md = fmt::format(
      "# avp bench\n\n{} scenario(s) x {} planner(s) x {} seed(s), {} fused views, segmenter "
      "`{}`, {} mm voxels; revision `{}`; {:.0f} s.\n\nMean ± 95 % CI over seeds (Student's "
      "t). `found` = fruits found / all fruits of the scene (docs/evaluation.md).\n",
      options.scenarios.size(), options.planners.size(), options.seeds.size(), views,
      base.segmenter, base.voxel_size_m * 1e3, SourceRevision(), SecondsSince(t0));
  if (!base.planner_options.empty()) {
    std::string opts;
    for (const auto& [k, v] : base.planner_options) {
      opts += fmt::format("{}`{} = {}`", opts.empty() ? "" : ", ", k, v);
    }
    md += fmt::format("\navp-nbv options over its defaults: {}.\n", opts);
  }
  for (const std::string& s : options.scenarios) {
    md += fmt::format(
        "\n## {}\n\n| planner | n | F1 (exact) view {} | F1 (±1 voxel) | fruits found | found "
        "fraction | plan ms/step | episode s | failed |\n|---|---|---|---|---|---|---|---|---|\n",
        s, views);
    for (const std::string& p : options.planners) {
      const Key key{s, p};
      const eval::Summary f1 = stat(key, "f1", views - 1);
      const eval::Summary f1t = stat(key, "f1_tol", views - 1);
      const eval::Summary found = stat(key, "fruits_found", views - 1);
      const eval::Summary total = stat(key, "fruits_total", views - 1);
      const eval::Summary frac = stat(key, "fruits_found_fraction", views - 1);
      // As in summary.csv: no interval (one seed) reads 0.
      auto ci = [](double c) { return std::isfinite(c) ? c : 0.0; };
      md += fmt::format(
          "| {} | {} | {:.3f} ± {:.3f} | {:.3f} ± {:.3f} | {:.1f} / {:.1f} | {:.3f} ± {:.3f} | "
          "{:.0f} | {:.2f} | {} |\n",
          p, f1.n, f1.mean, ci(f1.ci95), f1t.mean, ci(f1t.ci95), found.mean, total.mean, frac.mean,
          ci(frac.ci95), mean_of(plan_ms[key]), mean_of(episode_s[key]), failed[key]);
      BenchCell cell;
      cell.scenario = s;
      cell.planner = p;
      cell.runs = f1.n;
      cell.final_f1_mean = f1.mean;
      cell.final_f1_ci95 = ci(f1.ci95);
      cell.final_found_mean = frac.mean;
      cell.final_found_ci95 = ci(frac.ci95);
      cell.fruits_total_mean = total.mean;
      cell.plan_ms_mean = mean_of(plan_ms[key]);
      cell.episode_s_mean = mean_of(episode_s[key]);
      cell.failed = failed[key];
      summary.cells.push_back(cell);
    }
    // How hidden the fruits are (docs/evaluation.md): a fruit that no reachable view shows much of
    // is hard to find for any planner. Only for observable ground truths (a file has no views).
    {
      double fruits = 0.0;
      std::array<double, eval::kVisibleFractionLevels.size()> visible{};
      for (const Group& g : groups) {
        if (g.scenario != s || g.gt->best_visible_fraction.empty()) continue;
        fruits += static_cast<double>(g.gt->fruits.size());
        for (size_t l = 0; l < visible.size(); ++l) {
          visible[l] +=
              static_cast<double>(g.gt->FruitsVisibleAtLeast(eval::kVisibleFractionLevels[l]));
        }
      }
      if (fruits > 0.0) {
        md +=
            "\nFruits by their best visible fraction from a reachable observation view (all "
            "seeds):";
        for (size_t l = 0; l < visible.size(); ++l) {
          md += fmt::format("{}≥ {:.0f} %: {:.1f} %", l == 0 ? " " : ", ",
                            100.0 * eval::kVisibleFractionLevels[l], 100.0 * visible[l] / fruits);
        }
        md += ".\n";
      }
    }
    md += "\nF1 (exact) per fused view:\n\n| planner |";
    for (int v = 1; v <= views; ++v) md += fmt::format(" {} |", v);
    md += "\n|---|";
    for (int v = 1; v <= views; ++v) md += "---|";
    md += "\n";
    for (const std::string& p : options.planners) {
      md += "| " + p + " |";
      for (int v = 0; v < views; ++v) md += fmt::format(" {:.3f} |", stat({s, p}, "f1", v).mean);
      md += "\n";
    }

    // Plots in the style of the paper's Fig. 3: one series per planner, ±95 % CI band.
    for (const auto& [metric, label, file] :
         {std::tuple{"f1", "voxel F1 (exact)", "f1"},
          std::tuple{"fruits_found_fraction", "fraction of fruits found", "fruits"}}) {
      eval::LinePlot plot;
      plot.title = fmt::format("{}: {} ({} seeds, mean ± 95 % CI)", s, label, options.seeds.size());
      plot.x_label = "fused views";
      plot.y_label = label;
      plot.y_min = 0.0;
      plot.y_max = 1.0;
      for (const std::string& p : options.planners) {
        eval::LineSeries series;
        series.name = p;
        for (int v = 0; v < views; ++v) {
          const eval::Summary st = stat({s, p}, metric, v);
          series.x.push_back(v + 1);
          series.y.push_back(st.mean);
          series.band.push_back(std::isfinite(st.ci95) ? st.ci95 : 0.0);
        }
        plot.series.push_back(series);
      }
      const fs::path svg = options.out_dir / fmt::format("{}_{}.svg", file, SafeName(s));
      AVP_RETURN_IF_ERROR(eval::WriteLinePlotSvg(svg, plot));
      summary.files.push_back(svg);
    }
  }
  const fs::path md_path = options.out_dir / "summary.md";
  std::FILE* f = std::fopen(md_path.c_str(), "w");
  if (f == nullptr) return IoError(fmt::format("cannot write '{}'", md_path.string()));
  std::fputs(md.c_str(), f);
  std::fclose(f);
  summary.files.insert(summary.files.begin(), md_path);
  summary.seconds = SecondsSince(t0);
  return summary;
}

}  // namespace avp::apps

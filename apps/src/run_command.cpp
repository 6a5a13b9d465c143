#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <sys/utsname.h>
#include <unistd.h>

#include <avp/apps/run_command.h>
#include <avp/apps/scene_source.h>
#include <avp/eval/svg_plot.h>
#include <avp/io/json.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/ply_export.h>

#ifndef AVP_SOURCE_DIR
#define AVP_SOURCE_DIR ""
#endif

namespace avp::apps {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

namespace {

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::string RunShell(const std::string& command) {
  std::string out;
  std::FILE* p = ::popen(command.c_str(), "r");
  if (p == nullptr) return out;
  char buf[256];
  while (std::fgets(buf, sizeof buf, p) != nullptr) out += buf;
  ::pclose(p);
  while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
  return out;
}

json ToJson(const eval::RunConfig& c) {
  return json{{"scenario", c.scenario},
              {"scene_file", c.scene_file.string()},
              {"seed", c.seed},
              {"planner", c.planner},
              {"segmenter", c.segmenter},
              {"views", c.views},
              {"prompt", c.prompt},
              {"voxel_size_m", c.voxel_size_m},
              {"policy", std::string(mapping::ToString(c.policy))},
              {"carving", std::string(mapping::ToString(c.carving))},
              {"max_range_m", c.max_range_m},
              {"depth_noise", c.depth_noise},
              {"camera", io::ToJson(c.K)},
              {"roi_margin_m", c.roi_margin_m},
              {"threads", c.threads},
              {"gt_file", c.gt_file.string()},
              {"planner_options", c.planner_options},
              {"oracle_regret", c.oracle_regret}};
}

json StepJson(const pipeline::StepRecord& s) {
  json metrics = json::object();
  for (const auto& [k, v] : s.metrics) metrics[k] = std::isfinite(v) ? json(v) : json(nullptr);
  json j{{"view", s.view + 1},
         {"X_WC", io::ToJson(s.X_WC)},
         {"masks", s.masks},
         {"known_voxels", s.known_voxels},
         {"target_voxels", s.target_voxels},
         {"instances", s.instances},
         {"metrics", metrics},
         {"times_ms",
          {{"capture", s.times.capture_ms},
           {"segment", s.times.segment_ms},
           {"integrate", s.times.integrate_ms},
           {"metrics", s.times.metrics_ms},
           {"plan", s.times.plan_ms},
           {"move", s.times.move_ms},
           {"total", s.times.total_ms}}}};
  if (!s.capture_status.ok()) j["capture_error"] = s.capture_status.ToString();
  if (!s.segment_status.ok()) j["segment_error"] = s.segment_status.ToString();
  if (!s.integrate_status.ok()) j["integrate_error"] = s.integrate_status.ToString();
  if (s.planned) {
    json cands = json::array();
    for (const planning::ViewCandidate& c : s.top_candidates) {
      cands.push_back(
          {{"utility", c.utility},
           {"gain", c.gain},
           {"cost", c.cost},
           {"source", c.source},
           {"eye",
            {c.X_WC.translation().x(), c.X_WC.translation().y(), c.X_WC.translation().z()}}});
    }
    j["plan"] = {{"status", s.plan_status.ToString()},
                 {"generated", s.candidates_generated},
                 {"reachable", s.candidates_reachable},
                 {"chosen_rank", s.chosen_rank},
                 {"refused_moves", s.refused_moves},
                 {"joint_path_length_rad", s.joint_path_length},
                 {"top_candidates", cands}};
  }
  return j;
}

}  // namespace

std::string SourceRevision() {
  const std::string dir = AVP_SOURCE_DIR;
  if (dir.empty() || !fs::exists(fs::path(dir) / ".git")) return "unknown";
  const std::string rev = RunShell(fmt::format("git -C '{}' rev-parse HEAD 2>/dev/null", dir));
  if (rev.empty()) return "unknown";
  const std::string dirty =
      RunShell(fmt::format("git -C '{}' status --porcelain --untracked-files=no 2>/dev/null", dir));
  return dirty.empty() ? rev : rev + "-dirty";
}

std::string HostDescription() {
  char host[256] = {0};
  ::gethostname(host, sizeof host - 1);
  utsname u{};
  ::uname(&u);
  return fmt::format("{} ({} {} {}, {} hardware threads)", host, u.sysname, u.release, u.machine,
                     std::thread::hardware_concurrency());
}

Status ParsePlannerOptions(const std::vector<std::string>& items,
                           std::map<std::string, std::string>& out) {
  for (const std::string& item : items) {
    const size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0) {
      return InvalidArgumentError(
          fmt::format("planner option '{}' must be KEY=VALUE (e.g. p_unknown=0.1)", item));
    }
    out[item.substr(0, eq)] = item.substr(eq + 1);
  }
  return Status::Ok();
}

Result<RunSummary> RunRun(const RunOptions& options) {
  const auto t0 = Clock::now();
  const eval::RunConfig& config = options.config;
  AVP_RETURN_IF_ERROR(config.Validate());
  if (options.out_dir.empty()) return InvalidArgumentError("the output folder (--out) is empty");
  std::error_code ec;
  fs::create_directories(options.out_dir, ec);
  if (ec) {
    return IoError(fmt::format("cannot create '{}': {}", options.out_dir.string(), ec.message()));
  }
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene,
                       LoadScene(SceneSource{config.scenario, config.scene_file, config.seed}));
  RunSummary summary;
  summary.scene_name = scene.name;

  const auto t_gt = Clock::now();
  AVP_ASSIGN_OR_RETURN(const eval::GroundTruth gt, eval::GroundTruthFor(config, scene));
  const double gt_s = SecondsSince(t_gt);

  const fs::path csv_path = options.out_dir / "metrics.csv";
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<eval::MetricsCsvWriter> csv,
                       eval::MetricsCsvWriter::Open(csv_path));
  struct Progress final : pipeline::EpisodeObserver {
    const RunOptions* o = nullptr;
    void OnStep(const pipeline::StepRecord& s, const mapping::SemanticMap&) override {
      if (o->on_step) o->on_step(s);
    }
  } progress;
  progress.o = &options;
  std::unique_ptr<mapping::SemanticMap> map;
  AVP_ASSIGN_OR_RETURN(eval::RunResult result,
                       eval::RunEpisodeOnScene(config, scene, gt, {csv.get(), &progress}, &map));
  csv.reset();
  result.gt_ms = gt_s * 1e3;
  summary.files.push_back(csv_path);

  const fs::path ot = options.out_dir / "map.ot";
  AVP_RETURN_IF_ERROR(mapping::ExportOctomapColor(*map, ot).status());
  summary.files.push_back(ot);
  const fs::path ply = options.out_dir / "fruit_voxels.ply";
  AVP_RETURN_IF_ERROR(mapping::ExportSemanticPly(map->grid(), ply).status());
  summary.files.push_back(ply);

  // F1 and fruits found per view.
  eval::LinePlot plot;
  plot.title = fmt::format("{} — {} / {} (seed {})", scene.name, config.planner, config.segmenter,
                           config.seed);
  plot.x_label = "fused views";
  plot.y_label = "F1 / fraction of fruits found";
  plot.y_min = 0.0;
  plot.y_max = 1.0;
  eval::LineSeries f1;
  f1.name = "voxel F1 (exact)";
  eval::LineSeries f1_tol;
  f1_tol.name = "voxel F1 (±1 voxel)";
  eval::LineSeries found;
  found.name = "fruits found (fraction)";
  for (const pipeline::StepRecord& s : result.episode.steps) {
    f1.x.push_back(s.view + 1);
    f1.y.push_back(s.Metric("f1"));
    f1_tol.x.push_back(s.view + 1);
    f1_tol.y.push_back(s.Metric("f1_tol"));
    found.x.push_back(s.view + 1);
    found.y.push_back(s.Metric("fruits_found_fraction"));
  }
  plot.series = {f1, f1_tol, found};
  const fs::path svg = options.out_dir / "metrics.svg";
  AVP_RETURN_IF_ERROR(eval::WriteLinePlotSvg(svg, plot));
  summary.files.push_back(svg);

  json steps = json::array();
  for (const pipeline::StepRecord& s : result.episode.steps) steps.push_back(StepJson(s));
  json final_metrics = json::object();
  for (const auto& [k, v] : eval::MetricsRow(result.final_metrics)) {
    final_metrics[k] = std::isfinite(v) ? json(v) : json(nullptr);
  }
  // How hidden each fruit is from the best view the arm can take
  // (GroundTruth::best_visible_fraction).
  json best_visible = json::array();
  for (const sim::FruitTruth& f : gt.fruits) {
    const auto it = gt.best_visible_fraction.find(f.instance_id);
    if (it == gt.best_visible_fraction.end()) continue;
    best_visible.push_back({{"fruit", f.instance_id}, {"best_visible_fraction", it->second}});
  }
  json regret = json::array();  // empty without --oracle-regret
  for (const eval::StepRegret& g : result.regret) {
    auto finite = [](double v) { return std::isfinite(v) ? json(v) : json(nullptr); };
    regret.push_back({{"step", g.step},
                      {"candidates", g.candidates},
                      {"chosen_true_gain", g.chosen_true_gain},
                      {"best_true_gain", g.best_true_gain},
                      {"regret", g.regret},
                      {"chosen_true_rank", g.chosen_true_rank},
                      {"rank_correlation", finite(g.rank_correlation)}});
  }
  json visible_at_least = json::object();
  for (const double v : eval::kVisibleFractionLevels) {
    visible_at_least[fmt::format("{:.2f}", v)] = gt.FruitsVisibleAtLeast(v);
  }
  const json record{
      {"avp", "avp run"},
      {"config", ToJson(config)},
      {"scene",
       {{"name", scene.name}, {"description", scene.description}, {"fruits", gt.fruits.size()}}},
      {"ground_truth",
       {{"source", gt.source},
        {"voxels", gt.voxels.size()},
        {"observable_fruits", gt.ObservableFruits()},
        {"views_tried", gt.views_tried},
        {"views_reachable", gt.views_reachable},
        {"fruits_visible_at_least", visible_at_least},
        {"fruits", best_visible},
        {"seconds", gt_s}}},
      {"git_revision", SourceRevision()},
      {"host", HostDescription()},
      {"end", std::string(pipeline::ToString(result.episode.end))},
      {"end_reason", result.episode.end_reason},
      {"views_fused", result.episode.views_fused()},
      {"episode_seconds", result.episode.total_ms / 1e3},
      {"final_metrics", final_metrics},
      {"oracle_regret", regret},
      {"steps", steps}};
  const fs::path record_path = options.out_dir / "record.json";
  AVP_RETURN_IF_ERROR(io::WriteJsonFile(record_path, record));
  summary.files.insert(summary.files.begin(), record_path);
  summary.result = std::move(result);
  summary.seconds = SecondsSince(t0);
  return summary;
}

}  // namespace avp::apps

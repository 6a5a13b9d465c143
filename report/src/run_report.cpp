#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include <avp/io/json.h>
#include <avp/report/metrics_csv.h>
#include <avp/report/run_report.h>

namespace avp::report {

std::string FormatStepLine(const pipeline::StepRecord& s, std::string_view progress) {
  const Eigen::Vector3d eye = s.X_WC.translation();
  const std::string metrics =
      std::isnan(s.Metric("f1"))
          ? std::string()
          : fmt::format("  F1 {:.3f} (tol {:.3f})  fruits {:.0f}/{:.0f}", s.Metric("f1"),
                        s.Metric("f1_tol"), s.Metric("fruits_found"), s.Metric("fruits_total"));
  std::string problems = !s.capture_status.ok()   ? "  capture: " + s.capture_status.ToString()
                         : !s.segment_status.ok() ? "  segment: " + s.segment_status.ToString()
                                                  : std::string();
  for (const std::string& w : s.plan_warnings) problems += "  planner warning: " + w;
  const pipeline::MovingFramesRecord& f = s.motion_frames;
  const std::string moving =
      f.streamed ? fmt::format("  then {} frames fused while moving ({:.0f} frames/s{}{})", f.fused,
                               f.map_rate_hz(),
                               f.dropped > 0 ? fmt::format(", {} dropped", f.dropped) : "",
                               f.failed > 0 ? fmt::format(", {} failed", f.failed) : "")
                 : std::string();
  const std::string candidates = s.planned
                                     ? fmt::format(", {} of {} candidates reachable",
                                                   s.candidates_reachable, s.candidates_generated)
                                     : std::string();
  return fmt::format(
      "view {}/{}  eye ({:.3f}, {:.3f}, {:.3f})  {} masks{}  [segment {:.0f} ms, integrate {:.0f} "
      "ms, plan {:.0f} ms{}]{}{}{}",
      s.view + 1, s.views_total, eye.x(), eye.y(), eye.z(), s.masks, metrics, s.times.segment_ms,
      s.times.integrate_ms, s.times.plan_ms, candidates, moving,
      progress.empty() ? std::string() : fmt::format("  {}", progress), problems);
}

using nlohmann::json;

namespace {

json Finite(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

}  // namespace

json ContactsJson(const std::optional<robot::MotionContacts>& c) {
  if (!c) return nullptr;
  return {{"total", c->total()}, {"plant", c->plant}, {"fruit", c->fruit}, {"support", c->support},
          {"ground", c->ground}, {"self", c->self},   {"first", c->first}};
}

json MovingFramesJson(const pipeline::MovingFramesRecord& f) {
  return {{"streamed", f.streamed},
          {"expected", f.expected},
          {"fused", f.fused},
          {"segmented", f.segmented},
          {"dropped", f.dropped},
          {"skipped", f.skipped},
          {"failed", f.failed},
          {"segment_failed", f.segment_failed},
          {"move_s", f.move_s},
          {"capture_ms", f.capture_ms},
          {"segment_ms", f.segment_ms},
          {"integrate_ms", f.integrate_ms},
          {"busy_ms", f.busy_ms},
          {"wall_ms", f.wall_ms},
          {"map_rate_hz", f.map_rate_hz()},
          {"known_delta", f.known_delta},
          {"target_delta", f.target_delta},
          {"first_problem", f.first_problem}};
}

json MotionJson(const pipeline::MotionRecord& m) {
  json path = json::array();
  for (const Eigen::Vector3d& p : m.camera_path_W) path.push_back({p.x(), p.y(), p.z()});
  return {{"planned", m.planned},
          {"attempts", m.attempts},
          {"rejected", m.rejected},
          {"map_update_ms", m.map_update_ms},
          {"planning_ms", m.planning_ms},
          {"straight", m.straight},
          {"samples", m.samples},
          {"path_length_rad", m.path_length_rad},
          {"execution_s", m.execution_s},
          {"contacts", ContactsJson(m.contacts)},
          {"straight_line_contacts", ContactsJson(m.straight_line_contacts)},
          {"camera_path", std::move(path)}};
}

json MotionTotalsJson(const pipeline::EpisodeResult& e) {
  const pipeline::MotionTotals t = pipeline::SumMotion(e);
  std::vector<double> sorted = t.planning_ms;
  std::sort(sorted.begin(), sorted.end());
  const auto quantile = [&](double q) {
    if (sorted.empty()) return json(nullptr);
    return json(sorted[static_cast<size_t>(q * static_cast<double>(sorted.size() - 1) + 0.5)]);
  };
  json home = nullptr;
  if (e.return_home) {
    home = MotionJson(*e.return_home);
    home["status"] = e.return_home_status.ToString();
  }
  json start = nullptr;
  if (e.start_clearance) {
    const auto& truth = e.start_clearance->truth;
    const bool near = truth && std::isfinite(truth->distance_m);
    start = {{"assumed_m", e.start_clearance->assumed_m},
             {"checked", truth.has_value()},
             {"nearest_m", near ? json(truth->distance_m) : json(nullptr)},
             {"nearest", near ? json(truth->nearest) : json(nullptr)},
             {"broken", e.start_clearance->broken()}};
  }
  return {{"moves", t.moves},
          {"attempts", t.attempts},
          {"rejected", t.rejected},
          {"execution_s", t.execution_s},
          {"path_length_rad", t.path_length_rad},
          {"planning_ms", t.planning_ms},
          {"planning_ms_median", quantile(0.5)},
          {"planning_ms_max", sorted.empty() ? json(nullptr) : json(sorted.back())},
          {"contacts", ContactsJson(t.contacts)},
          {"straight_line_contacts", ContactsJson(t.straight_line_contacts)},
          {"robot_s", t.robot_s},
          {"moving_frames", t.moving.streamed ? MovingFramesJson(t.moving) : json(nullptr)},
          {"return_home", std::move(home)},
          {"start_clearance", std::move(start)}};
}

json StepJson(const pipeline::StepRecord& s) {
  json metrics = json::object();
  for (const auto& [k, v] : s.metrics) metrics[k] = std::isfinite(v) ? json(v) : json(nullptr);
  json j{{"view", s.view + 1},
         {"X_WC", io::ToJson(s.X_WC)},
         {"masks", s.masks},
         {"masks_without_depth", s.masks_without_depth},
         {"known_voxels", s.known_voxels},
         {"occupied_voxels", s.occupied_voxels},
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
                 {"in_collision", s.candidates_in_collision},
                 {"top_candidates", cands},
                 {"motion", MotionJson(s.motion)}};
    if (s.motion_frames.streamed) j["plan"]["motion_frames"] = MovingFramesJson(s.motion_frames);
    if (!s.plan_warnings.empty()) j["plan"]["warnings"] = s.plan_warnings;
  }
  return j;
}

json MetricsJson(const eval::MapMetrics& metrics) {
  json out = json::object();
  for (const auto& [k, v] : MetricsRow(metrics)) out[k] = Finite(v);
  return out;
}

json GroundTruthJson(const eval::GroundTruth& gt, double seconds) {
  // How hidden each fruit is from the best view the arm can take
  // (GroundTruth::best_visible_fraction).
  json best_visible = json::array();
  for (const sim::FruitTruth& f : gt.fruits) {
    const auto it = gt.best_visible_fraction.find(f.instance_id);
    if (it == gt.best_visible_fraction.end()) continue;
    best_visible.push_back({{"fruit", f.instance_id}, {"best_visible_fraction", it->second}});
  }
  json visible_at_least = json::object();
  for (const double v : eval::kVisibleFractionLevels) {
    visible_at_least[fmt::format("{:.2f}", v)] = gt.FruitsVisibleAtLeast(v);
  }
  return {{"source", gt.source},
          {"voxels", gt.voxels.size()},
          {"observable_fruits", gt.ObservableFruits()},
          {"views_tried", gt.views_tried},
          {"views_reachable", gt.views_reachable},
          {"fruits_visible_at_least", visible_at_least},
          {"fruits", best_visible},
          {"seconds", seconds}};
}

json FruitsJson(const std::vector<eval::FruitResult>& fruits) {
  const auto view = [](int v) { return v >= 0 ? json(v + 1) : json(nullptr); };
  const auto vec = [](const Eigen::Vector3d& p) {
    return p.allFinite() ? json::array({p.x(), p.y(), p.z()}) : json(nullptr);
  };
  json out = json::array();
  for (const eval::FruitResult& f : fruits) {
    out.push_back({{"fruit", f.instance_id},
                   {"name", f.name},
                   {"center_m", vec(f.center_W)},
                   {"radius_m", f.radius_m},
                   {"semi_axes_m", vec(f.radii)},
                   {"best_visible_fraction", Finite(f.best_visible_fraction)},
                   {"episode_visible_fraction", Finite(f.episode_visible_fraction)},
                   {"episode_best_view", view(f.episode_best_view)},
                   {"observable_voxels", f.observable_voxels},
                   {"recalled_voxels", f.recalled_voxels},
                   {"matched_voxels", f.matched_voxels},
                   {"found", f.found},
                   {"found_view", view(f.found_view)},
                   {"found_since_view", view(f.found_since_view)},
                   {"estimate", f.estimated ? json{{"center_m", vec(f.estimated_center_W)},
                                                   {"radius_m", f.estimated_radius_m},
                                                   {"sphere_fitted", f.sphere_fitted}}
                                            : json(nullptr)},
                   {"center_error_m", Finite(f.center_error_m)},
                   {"radius_error_m", Finite(f.radius_error_m)}});
  }
  return out;
}

json RegretJson(const std::vector<eval::StepRegret>& regret) {
  json out = json::array();
  const auto vec = [](const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); };
  for (const eval::StepRegret& g : regret) {
    json scored = json::array();
    for (const eval::ScoredCandidate& c : g.scored) {
      json terms = json::object();
      for (const auto& [name, value] : c.gain_terms) terms[name] = value;
      scored.push_back({{"eye", vec(c.eye)},
                        {"forward", vec(c.forward)},
                        {"gain", c.gain},
                        {"utility", c.utility},
                        {"cost", c.cost},
                        {"true_gain", c.true_gain},
                        {"source", c.source},
                        {"gain_terms", std::move(terms)}});
      if (!c.features.empty()) scored.back()["features"] = c.features;
    }
    json step = {{"step", g.step},
                 {"candidates", g.candidates},
                 {"chosen_true_gain", g.chosen_true_gain},
                 {"best_true_gain", g.best_true_gain},
                 {"regret", g.regret},
                 {"chosen_true_rank", g.chosen_true_rank},
                 {"rank_correlation", Finite(g.rank_correlation)},
                 {"scored", std::move(scored)}};
    if (!g.feature_names.empty()) {
      // The columns of the rows, so that a data set names what it holds (docs/planning.md).
      step["feature_version"] = g.feature_version;
      step["feature_hash"] = g.feature_hash;
      step["feature_names"] = g.feature_names;
    }
    if (!g.features_error.empty()) step["features_error"] = g.features_error;
    out.push_back(std::move(step));
  }
  return out;
}

LinePlot EpisodeMetricsPlot(std::string title, const std::vector<pipeline::StepRecord>& steps) {
  LinePlot plot;
  plot.title = std::move(title);
  plot.x_label = "fused views";
  plot.y_label = "F1 / fraction of fruits found";
  plot.y_min = 0.0;
  plot.y_max = 1.0;
  LineSeries f1;
  f1.name = "voxel F1 (exact)";
  LineSeries f1_tol;
  f1_tol.name = "voxel F1 (±1 voxel)";
  LineSeries found;
  found.name = "fruits found (fraction)";
  for (const pipeline::StepRecord& s : steps) {
    f1.x.push_back(s.view + 1);
    f1.y.push_back(s.Metric("f1"));
    f1_tol.x.push_back(s.view + 1);
    f1_tol.y.push_back(s.Metric("f1_tol"));
    found.x.push_back(s.view + 1);
    found.y.push_back(s.Metric("fruits_found_fraction"));
  }
  plot.series = {f1, f1_tol, found};
  return plot;
}

}  // namespace avp::report

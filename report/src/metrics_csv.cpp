#include <fmt/format.h>

#include <avp/report/metrics_csv.h>

namespace avp::report {

std::vector<std::pair<std::string, double>> MetricsRow(const eval::MapMetrics& m) {
  auto d = [](size_t v) { return static_cast<double>(v); };
  return {
      {"f1", m.exact.f1},
      {"precision", m.exact.precision},
      {"recall", m.exact.recall},
      {"tp", d(m.exact.tp)},
      {"fp", d(m.exact.fp)},
      {"fn", d(m.exact.fn)},
      {"f1_tol", m.tolerant.f1},
      {"precision_tol", m.tolerant.precision},
      {"recall_tol", m.tolerant.recall},
      {"tp_tol", d(m.tolerant.tp)},
      {"fp_tol", d(m.tolerant.fp)},
      {"fn_tol", d(m.tolerant.fn)},
      {"fruits_found", d(m.fruits.found)},
      {"fruits_total", d(m.fruits.total)},
      {"fruits_observable", d(m.fruits.observable)},
      {"fruits_found_fraction", m.fruits.found_fraction},
      {"center_error_m", m.fruits.mean_center_error_m},
      {"radius_error_m", m.fruits.mean_radius_error_m},
      {"map_instances", d(m.fruits.map_instances)},
      {"entropy_sum_bits", m.entropy_sum_bits},
      {"entropy_mean_bits", m.entropy_mean_bits},
      {"predicted_voxels", d(m.predicted_voxels)},
      {"roi_coverage", m.roi_coverage},
  };
}

// ---- metrics.csv

Result<std::unique_ptr<MetricsCsvWriter>> MetricsCsvWriter::Open(
    const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(io::StepFileWriter file, io::StepFileWriter::Create(path, "metrics file"));
  return std::unique_ptr<MetricsCsvWriter>(new MetricsCsvWriter(std::move(file)));
}

void MetricsCsvWriter::Write(const std::string& text) {
  if (!status_.ok() || closed_) return;
  status_ = file_.Write(text);
  if (!status_.ok() && stop_.stop_possible()) stop_.request_stop();
}

Status MetricsCsvWriter::Close() {
  if (closed_) return status_;
  closed_ = true;
  const Status s = file_.Close();
  if (status_.ok()) status_ = s;
  return status_;
}

void MetricsCsvWriter::OnStep(const pipeline::StepRecord& s, const mapping::SemanticMap&) {
  if (!header_written_) {
    std::string header = "view";
    for (const auto& [name, value] : s.metrics) header += "," + name;
    header +=
        ",known_voxels,occupied_voxels,target_voxels,instances,masks,capture_ms,"
        "segment_ms,integrate_ms,metrics_ms,plan_ms,move_ms,step_ms,candidates,"
        "reachable,chosen_rank,chosen_utility,chosen_gain,joint_path_length,eye_x,"
        "eye_y,eye_z,status\n";
    Write(header);
    header_written_ = true;
  }
  std::string row = fmt::format("{}", s.view + 1);
  for (const auto& [name, value] : s.metrics) row += fmt::format(",{:.9g}", value);
  const Eigen::Vector3d eye = s.X_WC.translation();
  std::string status = "ok";
  if (!s.capture_status.ok())
    status = "capture-error";
  else if (!s.segment_status.ok())
    status = "segment-error";
  else if (!s.integrate_status.ok())
    status = "integrate-error";
  else if (s.planned && s.chosen_rank < 0)
    status = "no-move";
  row += fmt::format(
      ",{},{},{},{},{},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{},{},{},{:.6g},{:.6g},"
      "{:.6g},{:.4f},{:.4f},{:.4f},{}\n",
      s.known_voxels, s.occupied_voxels, s.target_voxels, s.instances, s.masks, s.times.capture_ms,
      s.times.segment_ms, s.times.integrate_ms, s.times.metrics_ms, s.times.plan_ms,
      s.times.move_ms, s.times.total_ms, s.candidates_generated, s.candidates_reachable,
      s.chosen_rank, s.chosen_rank >= 0 ? s.chosen.utility : 0.0,
      s.chosen_rank >= 0 ? s.chosen.gain : 0.0, s.joint_path_length, eye.x(), eye.y(), eye.z(),
      status);
  Write(row);
}

}  // namespace avp::report

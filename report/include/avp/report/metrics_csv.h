#pragma once

#include <filesystem>
#include <memory>
#include <stop_token>
#include <string>
#include <utility>
#include <vector>

#include <avp/core/status.h>
#include <avp/eval/metrics.h>
#include <avp/io/file.h>
#include <avp/pipeline/episode.h>

namespace avp::report {

/// The (name, value) metrics of a map, in a fixed order: the columns of metrics.csv and the
/// metrics of summary.csv (docs/evaluation.md).
std::vector<std::pair<std::string, double>> MetricsRow(const eval::MapMetrics& m);

/// Writes metrics.csv: one row per fused view, written to the file as each step completes (a
/// long run leaves its results as it goes). Every write is checked: the first failure (a full
/// disk) is kept, later rows are not written, the stop source (when given) is asked to stop the
/// episode, and status() / Close() return it naming the file.
class MetricsCsvWriter final : public pipeline::EpisodeObserver {
 public:
  static Result<std::unique_ptr<MetricsCsvWriter>> Open(const std::filesystem::path& path);
  /// A write error requests a stop on `stop` (the episode's stop source).
  void StopOnError(std::stop_source stop) { stop_ = std::move(stop); }
  void OnStep(const pipeline::StepRecord& step, const mapping::SemanticMap& map) override;
  /// OK, or the first write error.
  const Status& status() const { return status_; }
  /// Flushes the file to the disk and closes it: the first error of the writer, if any.
  Status Close();

 private:
  explicit MetricsCsvWriter(io::StepFileWriter file) : file_(std::move(file)) {}
  void Write(const std::string& text);
  io::StepFileWriter file_;
  std::stop_source stop_{std::nostopstate};
  Status status_;
  bool header_written_ = false;
  bool closed_ = false;
};

}  // namespace avp::report

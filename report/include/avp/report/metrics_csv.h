#pragma once

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <avp/core/status.h>
#include <avp/eval/metrics.h>
#include <avp/pipeline/episode.h>

namespace avp::report {

/// The (name, value) metrics of a map, in a fixed order: the columns of metrics.csv and the
/// metrics of summary.csv (docs/evaluation.md).
std::vector<std::pair<std::string, double>> MetricsRow(const eval::MapMetrics& m);

/// Writes metrics.csv: one row per fused view, written and flushed as each step completes.
class MetricsCsvWriter final : public pipeline::EpisodeObserver {
 public:
  static Result<std::unique_ptr<MetricsCsvWriter>> Open(const std::filesystem::path& path);
  void OnStep(const pipeline::StepRecord& step, const mapping::SemanticMap& map) override;
  ~MetricsCsvWriter() override;

 private:
  explicit MetricsCsvWriter(std::FILE* f, std::filesystem::path path)
      : file_(f), path_(std::move(path)) {}
  std::FILE* file_ = nullptr;
  std::filesystem::path path_;
  bool header_written_ = false;
};

}  // namespace avp::report

#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include <avp/eval/ground_truth.h>
#include <avp/eval/metrics.h>
#include <avp/eval/oracle_planner.h>
#include <avp/pipeline/episode.h>
#include <avp/report/svg_plot.h>

namespace avp::report {

/// The line `avp run` prints for a step (and the Python module's run): the view, the eye, the
/// masks, F1 and fruits found (with a ground truth), the stage times, the candidates,
/// `progress` (e.g. report::FormatProgressTimes) and the capture's or segmenter's problem. No
/// newline.
std::string FormatStepLine(const pipeline::StepRecord& step, std::string_view progress = {});

/// One step of record.json: the view, its pose, masks, map counts, metrics, stage times, and the
/// plan (status, candidates, the best ones) when the step planned.
nlohmann::json StepJson(const pipeline::StepRecord& step);
/// Contacts by what was touched ({"total", "plant", "fruit", "support", "ground", "self",
/// "first"}), null when unknown (a real robot).
nlohmann::json ContactsJson(const std::optional<robot::MotionContacts>& contacts);
/// One move: planned or not, attempts, rejected candidates and why, times, path length,
/// contacts, the camera's path.
nlohmann::json MotionJson(const pipeline::MotionRecord& motion);
/// What fusion during motion did along one move (pipeline::MovingFramesRecord), or summed.
nlohmann::json MovingFramesJson(const pipeline::MovingFramesRecord& frames);
/// The episode's moves summed (pipeline::SumMotion), with the return home.
nlohmann::json MotionTotalsJson(const pipeline::EpisodeResult& episode);

/// The metrics of MetricsRow as a JSON object (non-finite values as null).
nlohmann::json MetricsJson(const eval::MapMetrics& metrics);

/// record.json's ground-truth block: source, voxels, observable fruits, the views tried and
/// reachable, fruits by best visible fraction (counts at each kVisibleFractionLevels and per
/// fruit), and how long it took.
nlohmann::json GroundTruthJson(const eval::GroundTruth& gt, double seconds);

/// record.json's per-fruit list (docs/evaluation.md, "Per-fruit results"): one object per
/// ground-truth fruit of experiment::RunResult::fruits. Views are 1-based like record.json's
/// steps; values that do not exist (NaN, view -1) are null.
nlohmann::json FruitsJson(const std::vector<eval::FruitResult>& fruits);

/// record.json's oracle_regret: one entry per plan step (empty without --oracle-regret).
nlohmann::json RegretJson(const std::vector<eval::StepRegret>& regret);

/// metrics.svg of a run: F1 (exact and one-voxel tolerance) and the fraction of fruits found per
/// fused view.
LinePlot EpisodeMetricsPlot(std::string title, const std::vector<pipeline::StepRecord>& steps);

}  // namespace avp::report

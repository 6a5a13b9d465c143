#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <utility>

#include <fmt/format.h>

#include <avp/core/rng.h>
#include <avp/core/text.h>
#include <avp/eval/ground_truth_io.h>
#include <avp/eval/metrics.h>
#include <avp/experiment/episode_runner.h>
#include <avp/experiment/replay.h>
#include <avp/io/yaml.h>
#include <avp/mapping/integrator.h>
#include <avp/recording/encode.h>
#include <avp/recording/layout.h>
#include <avp/report/metrics_csv.h>

namespace avp::experiment {

namespace {

using Clock = std::chrono::steady_clock;
using json = nlohmann::json;

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// The map's counts as pipeline::RunEpisode records them.
using pipeline::CountTargetInstances;
using pipeline::CountTargetVoxels;

bool SameValue(double a, double b) {
  return (std::isnan(a) && std::isnan(b)) ||
         std::bit_cast<uint64_t>(a) == std::bit_cast<uint64_t>(b);
}

/// The recorded step's metrics ([[name, value|null]]) against the recomputed ones: empty when
/// equal (bit for bit; null = NaN), else the first difference.
std::string CompareMetrics(const json& step, const pipeline::StepRecord& s) {
  const auto it = step.find("metrics");
  if (it == step.end() || !it->is_array()) return "the recorded step has no metrics";
  if (it->size() != s.metrics.size()) {
    return fmt::format("{} metrics recorded, {} recomputed", it->size(), s.metrics.size());
  }
  for (size_t i = 0; i < s.metrics.size(); ++i) {
    const json& m = (*it)[i];
    if (!m.is_array() || m.size() != 2 || !m[0].is_string() ||
        !(m[1].is_number() || m[1].is_null())) {
      return fmt::format("recorded metric {} is {}", i, EscapeText(m.dump()));
    }
    const double recorded = m[1].is_null() ? std::nan("") : m[1].get<double>();
    if (m[0].get<std::string>() != s.metrics[i].first ||
        !SameValue(recorded, s.metrics[i].second)) {
      return fmt::format("{} = {} recorded, {} = {} replayed", EscapeText(m[0].get<std::string>()),
                         recorded, s.metrics[i].first, s.metrics[i].second);
    }
  }
  return {};
}

/// A status as StatusText wrote it ("" = OK, else "<Code>: message"), back.
Status StatusFromText(const json& j) {
  if (!j.is_string() || j.get<std::string>().empty()) return Status::Ok();
  const std::string text = j.get<std::string>();
  for (int c = 1; c <= static_cast<int>(StatusCode::kResourceExhausted); ++c) {
    const auto code = static_cast<StatusCode>(c);
    const std::string prefix = fmt::format("{}: ", ToString(code));
    if (text.starts_with(prefix)) return Status(code, text.substr(prefix.size()));
  }
  return Status(StatusCode::kInternal, text);
}

template <class T>
T Get(const json& j, const char* key, T fallback) {
  const auto it = j.find(key);
  if (it == j.end() || it->is_null()) return fallback;
  try {
    return it->get<T>();
  } catch (const json::exception&) {
    return fallback;
  }
}

/// The plan an avp recording's step made (planning is not rerun): the step's plan fields and
/// every ranked candidate. False (nothing set) when the step holds no readable plan.
bool RecordedPlan(const json& step, int keep_top, pipeline::StepRecord& s,
                  planning::PlanResult& plan) {
  if (!step.is_object() || !Get<bool>(step, "planned", false)) return false;
  const auto candidates = step.find("candidates");
  if (candidates == step.end() || !candidates->is_array()) return false;
  for (const json& c : *candidates) {
    if (!c.is_object() || !c.contains("X_WC")) return false;
    Result<RigidTransform> X = recording::PoseFromJson(c.at("X_WC"));
    if (!X.ok()) return false;
    planning::ViewCandidate v;
    v.X_WC = *X;
    const std::vector<double> q = Get<std::vector<double>>(c, "q", {});
    v.q = Eigen::Map<const Eigen::VectorXd>(q.data(), static_cast<Eigen::Index>(q.size()));
    v.reachable = Get<bool>(c, "reachable", false);
    v.gain = Get<double>(c, "gain", std::nan(""));
    v.cost = Get<double>(c, "cost", std::nan(""));
    v.utility = Get<double>(c, "utility", std::nan(""));
    v.source = Get<std::string>(c, "source", "");
    plan.ranked.push_back(std::move(v));
  }
  s.planned = true;
  s.plan_status = StatusFromText(step.value("plan_status", json()));
  s.move_status = StatusFromText(step.value("move_status", json()));
  s.candidates_generated = Get<size_t>(step, "candidates_generated", 0);
  s.candidates_reachable = Get<size_t>(step, "candidates_reachable", 0);
  s.chosen_rank = Get<int>(step, "chosen_rank", -1);
  s.refused_moves = Get<int>(step, "refused_moves", 0);
  s.joint_path_length = Get<double>(step, "joint_path_length", 0.0);
  const size_t top = std::min(plan.ranked.size(), static_cast<size_t>(std::max(keep_top, 0)));
  s.top_candidates.assign(plan.ranked.begin(), plan.ranked.begin() + static_cast<long>(top));
  if (s.chosen_rank >= 0 && static_cast<size_t>(s.chosen_rank) < plan.ranked.size()) {
    s.chosen = plan.ranked[static_cast<size_t>(s.chosen_rank)];
  }
  plan.status = s.plan_status;
  plan.generated = s.candidates_generated;
  plan.reachable = s.candidates_reachable;
  plan.stop = Get<bool>(step, "plan_stop", false);
  plan.stop_reason = Get<std::string>(step, "plan_stop_reason", "");
  return true;
}

/// Whether every view has the recording's masks.
bool AllRecorded(const recording::Bag& bag) {
  return std::all_of(bag.views.begin(), bag.views.end(),
                     [](const recording::BagView& v) { return v.segmentation.has_value(); });
}

}  // namespace

Result<RunConfig> BagRunConfig(const recording::Bag& bag) {
  RunConfig config;
  const auto it = bag.avp_metadata.find("run_config");
  if (it == bag.avp_metadata.end()) return config;
  const std::string context = fmt::format("{}: metadata run_config", bag.path.string());
  AVP_ASSIGN_OR_RETURN(const YAML::Node node, io::ParseYaml(it->second, context));
  AVP_RETURN_IF_ERROR(ReadRunConfigYaml(node, context, config));
  return config;
}

Result<ReplaySummary> ReplayToFolder(const recording::Bag& bag, RunConfig config,
                                     const Registries& registries, const ReplayOptions& options) {
  ReplaySummary summary;
  summary.views = bag.views.size();
  if (bag.views.empty()) return InvalidArgumentError(bag.path.string() + ": no view to replay");

  // The segmenter.
  const bool recorded = options.segmenter == kRecordedSegmenter ||
                        (options.segmenter.empty() && bag.avp_recording && AllRecorded(bag));
  if (recorded) {
    for (const recording::BagView& v : bag.views) {
      if (!v.segmentation) {
        return InvalidArgumentError(
            fmt::format("{}: view {} has no recorded masks ({}): give --segmenter NAME",
                        bag.path.string(), v.index, recording::kInstancesTopic));
      }
    }
    summary.segmenter = std::string(kRecordedSegmenter);
  } else {
    if (!options.segmenter.empty() && options.segmenter != config.segmenter.name) {
      config.segmenter = {options.segmenter, {}};
    }
    summary.segmenter = config.segmenter.name;
    if (summary.segmenter.starts_with("oracle")) {
      for (const recording::BagView& v : bag.views) {
        if (!v.observation.labels) {
          return InvalidArgumentError(fmt::format(
              "{}: the '{}' segmenter needs the simulator's label images ({}, {}), and view {} "
              "has none (a real robot's bag never has them): use --segmenter recorded (an avp "
              "recording's masks) or a real segmenter (color, ywes, lsam, remote://...)",
              bag.path.string(), summary.segmenter, recording::kSimInstanceTopic,
              recording::kSimClassTopic, v.index));
        }
      }
    }
  }
  AVP_RETURN_IF_ERROR(config.Validate(registries));

  // The ground truth and the ROI of the coverage metric.
  std::optional<eval::GroundTruth> gt;
  if (bag.ground_truth) {
    Result<eval::GroundTruth> read = eval::GroundTruthFromJson(*bag.ground_truth);
    if (!read.ok()) {
      return read.status().WithContext(
          fmt::format("{}: attachment {}", bag.path.string(), recording::kGroundTruthAttachment));
    }
    if (std::abs(read->voxel_size_m - config.map.grid.voxel_size_m) > 1e-12) {
      summary.notes.push_back(
          fmt::format("the ground truth has {} m voxels but the map {} m: no metrics",
                      read->voxel_size_m, config.map.grid.voxel_size_m));
    } else {
      gt = std::move(*read);
    }
  }
  Box3 roi;
  std::string scene_name = bag.path.stem().string();
  std::string scene_description = "replay of " + bag.path.string();
  if (auto s = bag.avp_metadata.find("scene"); s != bag.avp_metadata.end()) scene_name = s->second;
  if (bag.avp_recording && (!config.scenario.empty() || !config.scene_file.empty())) {
    Result<sim::Scene> scene = LoadScene(config, registries);
    if (scene.ok()) {
      roi = scene->plant_bounds.Inflated(config.roi_margin_m);
      scene_name = scene->name;
      scene_description = scene->description;
    } else if (gt) {
      summary.notes.push_back(
          fmt::format("the recording's scene could not be loaded ({}): roi_coverage is 0",
                      scene.status().message()));
    }
  }

  pipeline::EpisodeOptions eo = config.episode;
  eo.integrator.num_threads = config.threads;
  std::unique_ptr<segmentation::Segmenter> segmenter;
  if (!recorded) {
    AVP_ASSIGN_OR_RETURN(const AnyOptions segmenter_options, SegmenterOptions(config, registries));
    AVP_ASSIGN_OR_RETURN(segmenter, registries.segmenters.Make(
                                        config.segmenter.name, segmenter_options,
                                        {.seed = Rng(config.seed).Fork("segmenter").NextU64()}));
  }

  FolderRun run;
  run.command = "avp replay";
  run.scene_name = scene_name;
  run.scene_description = scene_description;
  run.gt = gt ? &*gt : nullptr;
  run.extra = [&]() {
    json notes = summary.notes;
    return json{{"replay",
                 {{"bag", bag.path.string()},
                  {"avp_recording", bag.avp_recording},
                  {"recorded_with", bag.avp_metadata},
                  {"segmenter", summary.segmenter},
                  {"views", bag.views.size()},
                  {"damage", bag.damage.ok() ? json(nullptr) : json(bag.damage.ToString())},
                  {"intact_bytes", bag.intact_bytes},
                  {"file_bytes", bag.file_bytes},
                  {"pairs", bag.pairs},
                  {"pairs_thinned", bag.pairs_thinned},
                  {"skipped", bag.skipped},
                  {"skipped_count", bag.skipped_count},
                  {"metrics_compared", summary.metrics_compared},
                  {"metrics_differ", summary.metrics_differ},
                  {"first_difference", summary.first_difference},
                  {"notes", notes}}}};
  };
  run.run = [&](const std::vector<pipeline::EpisodeObserver*>& observers,
                std::unique_ptr<mapping::SemanticMap>* map_out,
                std::stop_token stop) -> Result<RunResult> {
    auto map = std::make_unique<mapping::SemanticMap>(config.map);
    const mapping::Integrator integrator(eo.integrator);
    eval::EvalOptions eval_options;
    eval_options.roi = roi;
    eval::FruitTracker fruits;
    RunResult result;
    pipeline::EpisodeResult& episode = result.episode;
    const auto t_episode = Clock::now();
    size_t known = map->grid().CountKnownVoxels();
    size_t target = CountTargetVoxels(map->grid(), eo.target_class);
    const int total = static_cast<int>(bag.views.size());
    for (int i = 0; i < total; ++i) {
      if (stop.stop_requested()) {
        episode.end = pipeline::EpisodeEnd::kInterrupted;
        episode.end_reason = fmt::format("stop requested before view {}", i);
        break;
      }
      const recording::BagView& view = bag.views[static_cast<size_t>(i)];
      const auto t_step = Clock::now();
      pipeline::StepRecord step;
      step.view = i;
      step.views_total = total;
      step.X_WC = view.observation.frame.X_WC;
      step.q = view.q;
      // Labels with the ground truth's fruits (what the simulator's source hands the oracle).
      robot::Observation obs = view.observation;
      // CameraInfo carries no depth range: the configuration's camera's.
      obs.frame.K.min_depth_m = config.camera.min_depth_m;
      obs.frame.K.max_depth_m = config.camera.max_depth_m;
      if (obs.labels && gt) {
        obs.labels->fruits.clear();
        for (const sim::FruitTruth& f : gt->fruits) {
          obs.labels->fruits.push_back({f.instance_id, f.center_W, f.mean_radius_m()});
        }
      }
      std::optional<Segmentation> seg;
      auto t0 = Clock::now();
      if (recorded) {
        seg = *view.segmentation;
      } else {
        segmentation::SegmentationRequest request;
        request.frame = &obs.frame;
        request.prompt = eo.prompt;
        request.score_threshold = eo.score_threshold;
        request.labels = obs.labels ? &*obs.labels : nullptr;
        request.frame_index = static_cast<uint64_t>(view.index);
        Result<Segmentation> r = InternalError("segmenter not called");
        try {
          r = segmenter->Segment(request);
        } catch (const std::exception& e) {
          r = InternalError(fmt::format("segmenter '{}' threw: {}", segmenter->name(), e.what()));
        }
        if (r.ok()) {
          if (Status v = r->ValidateFor(obs.frame.depth_m.width(), obs.frame.depth_m.height());
              !v.ok()) {
            r = InternalError(fmt::format("segmenter '{}' returned an invalid segmentation: {}",
                                          segmenter->name(), v.ToString()));
          }
        }
        if (r.ok()) {
          seg = std::move(*r);
        } else {
          step.segment_status = r.status();
        }
      }
      step.times.segment_ms = MsSince(t0);
      if (seg) step.masks = seg->instances.size();
      t0 = Clock::now();
      Result<mapping::IntegrationStats> stats =
          integrator.Integrate(obs.frame, seg ? &*seg : nullptr, *map);
      step.times.integrate_ms = MsSince(t0);
      if (stats.ok()) {
        step.integration = *stats;
      } else {
        step.integrate_status = stats.status();
      }
      step.known_voxels = map->grid().CountKnownVoxels();
      step.occupied_voxels = map->grid().CountOccupiedVoxels();
      step.target_voxels = CountTargetVoxels(map->grid(), eo.target_class);
      step.instances = CountTargetInstances(*map, eo.target_class);
      step.known_delta = static_cast<int64_t>(step.known_voxels) - static_cast<int64_t>(known);
      step.target_delta = static_cast<int64_t>(step.target_voxels) - static_cast<int64_t>(target);
      known = step.known_voxels;
      target = step.target_voxels;
      if (gt) {
        t0 = Clock::now();
        std::vector<eval::FruitResult> now;
        result.final_metrics = eval::EvaluateMap(*map, *gt, eval_options, &now);
        std::optional<std::unordered_map<uint16_t, double>> visible;
        if (obs.labels) visible = VisibleFractions(obs, gt->fruits, eo.integrator.max_range_m);
        fruits.AfterView(i, std::move(now), visible);
        step.metrics = report::MetricsRow(result.final_metrics);
        step.times.metrics_ms = MsSince(t0);
        if (bag.avp_recording && !view.step.is_null()) {
          ++summary.metrics_compared;
          const std::string difference = CompareMetrics(view.step, step);
          if (!difference.empty()) {
            if (summary.metrics_differ++ == 0) {
              summary.first_difference = fmt::format("view {}: {}", view.index, difference);
            }
          }
        }
      }
      // The plan the recorded episode made after this view (not rerun): record.json, the
      // report and metrics.csv show it as the episode had it.
      planning::PlanResult plan;
      const bool planned =
          bag.avp_recording && RecordedPlan(view.step, eo.record_top_candidates, step, plan);
      step.times.total_ms = MsSince(t_step);
      episode.steps.push_back(step);
      const pipeline::StepData data{&obs, seg ? &*seg : nullptr, planned ? &plan : nullptr};
      for (pipeline::EpisodeObserver* o : observers) {
        if (o == nullptr) continue;
        o->OnView(episode.steps.back(), data, *map);
        o->OnStep(episode.steps.back(), *map);
      }
    }
    if (episode.end != pipeline::EpisodeEnd::kInterrupted && !bag.damage.ok()) {
      episode.end = pipeline::EpisodeEnd::kInterrupted;
      episode.end_reason =
          fmt::format("the recording is damaged ({}): replayed the {} intact views",
                      bag.damage.message(), bag.views.size());
    } else if (episode.end == pipeline::EpisodeEnd::kBudgetReached) {
      episode.end_reason = fmt::format("replayed {} views of {}", episode.steps.size(),
                                       bag.path.filename().string());
    }
    episode.total_ms = MsSince(t_episode);
    for (pipeline::EpisodeObserver* o : observers) {
      if (o != nullptr) o->OnEnd(episode, *map);
    }
    if (gt) {
      result.gt_voxels = gt->voxels.size();
      result.gt_fruits = gt->fruits.size();
      result.fruits = fruits.Result();
    }
    *map_out = std::move(map);
    return result;
  };
  RunFolderOptions folder = options.folder;
  folder.inputs.emplace_back(bag.path, "bag");
  AVP_ASSIGN_OR_RETURN(summary.run, RunEpisodeToFolder(config, registries, folder, run));
  return summary;
}

}  // namespace avp::experiment

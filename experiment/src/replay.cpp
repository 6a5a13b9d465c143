#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <utility>

#include <fmt/format.h>

#include <avp/core/parallel.h>
#include <avp/core/rng.h>
#include <avp/core/stopwatch.h>
#include <avp/core/text.h>
#include <avp/eval/ground_truth_io.h>
#include <avp/eval/metrics.h>
#include <avp/experiment/episode_runner.h>
#include <avp/experiment/replay.h>
#include <avp/io/yaml.h>
#include <avp/pipeline/view_fusion.h>
#include <avp/report/metrics_csv.h>
#include <avp/report/run_report.h>
#include <avp/ros/bag/encode.h>
#include <avp/ros/bag/layout.h>

namespace avp::experiment {

namespace {

using Clock = SteadyClock;
using json = nlohmann::json;

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
      // Six significant digits: enough to see the difference, not 16 digits of noise.
      return fmt::format("{} = {:.6g} recorded, {:.6g} replayed",
                         EscapeText(m[0].get<std::string>()), recorded, s.metrics[i].second);
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
    Result<RigidTransform> X = ros::bag::PoseFromJson(c.at("X_WC"));
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

}  // namespace

size_t ReplaySummary::masks() const {
  size_t n = 0;
  for (const ViewMasks& v : view_masks) n += v.masks;
  return n;
}

size_t ReplaySummary::masks_without_depth() const {
  size_t n = 0;
  for (const ViewMasks& v : view_masks) n += v.masks_without_depth;
  return n;
}

Result<RunConfig> BagRunConfig(const ros::bag::BagReader& bag) {
  RunConfig config;
  const auto it = bag.avp_metadata().find("run_config");
  if (it == bag.avp_metadata().end()) return config;
  const std::string context = fmt::format("{}: metadata run_config", bag.path().string());
  AVP_ASSIGN_OR_RETURN(const YAML::Node node, io::ParseYaml(it->second, context));
  AVP_RETURN_IF_ERROR(ReadRunConfigYaml(node, context, config));
  return config;
}

namespace {

/// The segmenters that read a bag's own masks or the simulator's labels, for the messages.
constexpr std::string_view kRealSegmenters =
    "color, ywes://MODEL_DIR, lsam://MODEL_DIR or remote://HOST:PORT (`avp run --segmenter help` "
    "lists them)";

/// The oracle segmenters need the simulator's label images: `which` has none ("the bag", "view 3").
Status OracleNeedsLabels(const ros::bag::BagReader& bag, const std::string& segmenter,
                         const std::string& which) {
  return InvalidArgumentError(fmt::format(
      "{}: the '{}' segmenter needs the simulator's label images ({}, {}), and {} has none (a real "
      "robot's bag never has them): use --segmenter recorded (an avp recording's masks) or a real "
      "segmenter: {}",
      bag.path().string(), segmenter, ros::bag::kSimInstanceTopic, ros::bag::kSimClassTopic, which,
      kRealSegmenters));
}

/// Whether the replay uses the recording's masks (else config.segmenter, set from
/// options.segmenter); summary.segmenter names the choice. Errors: "recorded" for a bag without
/// masks, an oracle segmenter for a bag without simulator labels, no segmenter for a robot's bag.
Result<bool> ChooseSegmenter(const ros::bag::BagReader& bag, const ReplayOptions& options,
                             RunConfig& config, ReplaySummary& summary) {
  // A bag read as a robot's (as_robot_bag) keeps no masks.
  const bool has_masks = bag.avp_recording() && bag.HasTopic(ros::bag::kInstancesTopic);
  const bool recorded = options.segmenter == kRecordedSegmenter ||
                        (options.segmenter.empty() && bag.avp_recording() && has_masks);
  if (recorded) {
    if (!has_masks) {
      return InvalidArgumentError(
          fmt::format("{}: the bag has no recorded masks ({}): give --segmenter NAME: {}",
                      bag.path().string(), ros::bag::kInstancesTopic, kRealSegmenters));
    }
    summary.segmenter = std::string(kRecordedSegmenter);
    return true;
  }
  if (!options.segmenter.empty() && options.segmenter != config.segmenter.name) {
    config.segmenter = {options.segmenter, {}};
  }
  summary.segmenter = config.segmenter.name;
  const bool has_labels = bag.HasSimulatorLabels();
  if (summary.segmenter.starts_with("oracle") && !has_labels) {
    if (options.segmenter.empty() && !bag.avp_recording()) {
      return InvalidArgumentError(fmt::format(
          "{}: a robot's bag has neither avp's masks nor the simulator's labels, so it needs a "
          "segmenter: give --segmenter NAME: {}",
          bag.path().string(), kRealSegmenters));
    }
    return OracleNeedsLabels(bag, summary.segmenter, "the bag");
  }
  return false;
}

/// The bag's ground truth when it has one of the map's voxel size (else a note says why not).
Result<std::optional<eval::GroundTruth>> BagGroundTruth(const ros::bag::BagReader& bag,
                                                        const RunConfig& config,
                                                        ReplaySummary& summary) {
  if (!bag.ground_truth()) return std::optional<eval::GroundTruth>();
  Result<eval::GroundTruth> read = eval::GroundTruthFromJson(*bag.ground_truth());
  if (!read.ok()) {
    return read.status().WithContext(
        fmt::format("{}: attachment {}", bag.path().string(), ros::bag::kGroundTruthAttachment));
  }
  if (std::abs(read->voxel_size_m - config.map.grid.voxel_size_m) > 1e-12) {
    summary.notes.push_back(
        fmt::format("the ground truth has {} m voxels but the map {} m: no metrics",
                    read->voxel_size_m, config.map.grid.voxel_size_m));
    return std::optional<eval::GroundTruth>();
  }
  return std::optional<eval::GroundTruth>(std::move(*read));
}

/// The plant a replay is of: an avp recording's scene when it loads (its name, description and
/// the ROI of the coverage metric), else the bag's name and an empty ROI.
struct ReplayScene {
  Box3 roi;
  std::string name;
  std::string description;
};

ReplayScene SceneOfBag(const ros::bag::BagReader& bag, const RunConfig& config,
                       const Registries& registries, bool have_truth, ReplaySummary& summary) {
  ReplayScene out{config.replay.Roi().value_or(Box3()), bag.path().stem().string(),
                  "replay of " + bag.path().string()};
  if (auto s = bag.avp_metadata().find("scene"); s != bag.avp_metadata().end()) {
    out.name = s->second;
  }
  if (bag.avp_recording() && !config.replay.Roi() &&
      (!config.scenario.empty() || !config.scene_file.empty())) {
    Result<sim::Scene> scene = LoadScene(config, registries);
    if (scene.ok()) {
      out.roi = scene->plant_bounds.Inflated(config.roi_margin_m);
      out.name = scene->name;
      out.description = scene->description;
    } else if (have_truth) {
      summary.notes.push_back(
          fmt::format("the recording's scene could not be loaded ({}): roi_coverage is 0",
                      scene.status().message()));
    }
  }
  return out;
}

/// record.json's "replay" section: the bag, what became of each of its frames, the comparison
/// with the recorded metrics.
json ReplayRecord(const ros::bag::BagReader& bag, const ReplaySummary& summary) {
  const ros::bag::FrameAccount& a = bag.account();
  std::map<int, const ReplaySummary::ViewMasks*> masks;
  for (const ReplaySummary::ViewMasks& m : summary.view_masks) masks[m.index] = &m;
  json frames = json::array();
  for (const ros::bag::FrameAccount::Frame& f : a.frames) {
    json j{{"index", f.index}, {"stamp_ns", f.stamp_ns}, {"what", f.what}};
    if (auto m = masks.find(f.index); m != masks.end() && f.what == "fused") {
      j["masks"] = m->second->masks;
      j["masks_without_depth"] = m->second->masks_without_depth;
    }
    frames.push_back(std::move(j));
  }
  std::vector<std::string> files;
  for (const auto& f : bag.info().files) files.push_back(f.string());
  const json notes = summary.notes;
  return json{{"replay",
               {{"bag", bag.path().string()},
                {"format", bag.info().format},
                {"files", files},
                {"avp_recording", bag.avp_recording()},
                {"recorded_with", bag.avp_metadata()},
                {"segmenter", summary.segmenter},
                {"views", summary.views},
                {"damage", bag.damage().ok() ? json(nullptr) : json(bag.damage().ToString())},
                {"bytes_read", bag.bytes_read()},
                {"file_bytes", bag.info().file_bytes},
                {"pairs", a.pairs},
                {"moving_frames", summary.moving.streamed ? report::MovingFramesJson(summary.moving)
                                                          : json(nullptr)},
                {"left_out", a.left_out},
                {"skipped_by_reason", a.skipped_by_reason},
                {"skipped", a.skipped},
                {"skipped_count", a.skipped_count()},
                {"frames", frames},
                {"masks_without_depth", summary.masks_without_depth()},
                {"masks", summary.masks()},
                {"topic_messages", bag.topic_messages()},
                {"metrics_compared", summary.metrics_compared},
                {"metrics_differ", summary.metrics_differ},
                {"first_difference", summary.first_difference},
                {"notes", notes}}}};
}

/// The episode of a replay: each view of the bag, as it is read, fused through the pipeline
/// (pipeline::ViewFusion, as the episode fused it), evaluated against the ground truth when there
/// is one, with the plan the recorded episode made after it.
class ReplayEpisode {
 public:
  /// `first`: the bag's first view, read before the run folder was made (so that a bag with
  /// nothing to fuse is refused before anything is written).
  ReplayEpisode(ros::bag::BagReader& bag, std::optional<ros::bag::BagView> first,
                const RunConfig& config, const pipeline::EpisodeOptions& eo,
                const eval::GroundTruth* gt, const Box3& roi, segmentation::Segmenter* segmenter,
                ReplaySummary& summary)
      : bag_(bag),
        first_(std::move(first)),
        config_(config),
        eo_(eo),
        gt_(gt),
        segmenter_(segmenter),
        summary_(summary) {
    eval_options_.roi = roi;
  }

  Result<RunResult> Run(const std::vector<pipeline::EpisodeObserver*>& observers,
                        std::unique_ptr<mapping::SemanticMap>* map_out, std::stop_token stop) {
    auto map = std::make_unique<mapping::SemanticMap>(config_.map);
    pipeline::ViewFusion fusion(*map, eo_);
    pipeline::EpisodeResult& episode = result_.episode;
    const auto t_episode = Clock::now();
    for (int i = 0;;) {
      if (stop.stop_requested()) {
        episode.end = pipeline::EpisodeEnd::kInterrupted;
        episode.end_reason = fmt::format("stop requested before view {}", i);
        break;
      }
      Result<std::optional<ros::bag::BagView>> view =
          first_ ? Result<std::optional<ros::bag::BagView>>(std::move(first_)) : bag_.Next();
      first_.reset();
      if (!view.ok()) return view.status();
      if (!*view) break;
      if ((*view)->moving) {
        ReplayMovingFrame(**view, fusion, stop);
        continue;
      }
      if (moving_.streamed) {
        // The frames of the move before this view: what they added, so that the view's change
        // is its own (as the episode recorded it).
        fusion.RecordMoving(moving_);
        pipeline::AddMovingFrames(moving_, summary_.moving);
        moving_ = {};
      }
      AVP_RETURN_IF_ERROR(ReplayView(i++, **view, fusion, stop, observers));
    }
    summary_.views = episode.steps.size();
    EndOfReplay(episode);
    episode.total_ms = MsSince(t_episode);
    pipeline::NotifyEnd(observers, episode, *map);
    if (gt_ != nullptr) {
      result_.gt_voxels = gt_->voxels.size();
      result_.gt_fruits = gt_->fruits.size();
      result_.fruits = fruits_.Result();
    }
    *map_out = std::move(map);
    return std::move(result_);
  }

 private:
  /// The view's observation as the episode's source handed it to the segmenter: the
  /// configuration's depth range (CameraInfo carries none) and the ground truth's fruits in the
  /// labels.
  robot::Observation ObservationOf(const ros::bag::BagView& view) const {
    robot::Observation obs = view.observation;
    obs.frame.K.min_depth_m = config_.camera.min_depth_m;
    obs.frame.K.max_depth_m = config_.camera.max_depth_m;
    if (obs.labels && gt_ != nullptr) {
      obs.labels->fruits.clear();
      for (const sim::FruitTruth& f : gt_->fruits) {
        obs.labels->fruits.push_back({f.instance_id, f.center_W, f.mean_radius_m()});
      }
    }
    return obs;
  }

  /// A frame the recorded episode fused while the arm moved, fused the same way
  /// (episode.motion_fusion: its carving and decimation, the ROI only): with its recorded masks,
  /// else the segmenter's (when one was given), else depth only.
  void ReplayMovingFrame(const ros::bag::BagView& view, pipeline::ViewFusion& fusion,
                         const std::stop_token& stop) {
    moving_.streamed = true;
    const robot::Observation obs = ObservationOf(view);
    std::optional<Segmentation> masks;
    if (view.segmentation) {
      masks = *view.segmentation;
    } else if (segmenter_ != nullptr) {
      Result<Segmentation> seg = pipeline::SegmentObservation(
          *segmenter_, obs, eo_, pipeline::MovingFrameIndex(view.index, view.moving_k), stop);
      if (seg.ok()) {
        masks = std::move(*seg);
      } else {
        ++moving_.segment_failed;
        if (moving_.first_problem.empty()) moving_.first_problem = seg.status().ToString();
      }
    }
    fusion.FuseMoving(obs, masks ? &*masks : nullptr, moving_);
  }

  /// Why the view cannot be segmented as chosen (no recorded masks, no labels for the oracle).
  Status CheckView(const ros::bag::BagView& view) const {
    if (segmenter_ == nullptr && !view.segmentation) {
      return InvalidArgumentError(
          fmt::format("{}: view {} has no recorded masks ({}): give --segmenter NAME",
                      bag_.path().string(), view.index, ros::bag::kInstancesTopic));
    }
    if (segmenter_ != nullptr && summary_.segmenter.starts_with("oracle") &&
        !view.observation.labels) {
      return OracleNeedsLabels(bag_, summary_.segmenter, fmt::format("view {}", view.index));
    }
    return Status::Ok();
  }

  Status ReplayView(int i, const ros::bag::BagView& view, pipeline::ViewFusion& fusion,
                    const std::stop_token& stop,
                    const std::vector<pipeline::EpisodeObserver*>& observers) {
    AVP_RETURN_IF_ERROR(CheckView(view));
    const auto t_step = Clock::now();
    pipeline::StepRecord step;
    step.view = i;
    step.views_total = static_cast<int>(bag_.account().fused);  // read so far
    step.X_WC = view.observation.frame.X_WC;
    step.q = view.q;
    pipeline::ViewSeen seen;
    if (segmenter_ == nullptr) {
      const auto t0 = Clock::now();
      std::optional<Segmentation> masks = *view.segmentation;
      step.times.segment_ms = MsSince(t0);
      fusion.Fuse(ObservationOf(view), std::move(masks), step, seen);
    } else {
      fusion.Segment(ObservationOf(view), *segmenter_, static_cast<uint64_t>(view.index), stop,
                     step, seen);
    }
    summary_.view_masks.push_back({view.index, step.masks, step.masks_without_depth});
    if (gt_ != nullptr) Evaluate(i, view, *seen.observation, fusion.map(), step);
    // The plan the recorded episode made after this view (not rerun): record.json, the report
    // and metrics.csv show it as the episode had it.
    planning::PlanResult plan;
    if (bag_.avp_recording() && RecordedPlan(view.step, eo_.record_top_candidates, step, plan)) {
      seen.plan = std::move(plan);
    }
    step.times.total_ms = MsSince(t_step);
    result_.episode.steps.push_back(step);
    pipeline::NotifyStep(observers, result_.episode.steps.back(), seen.Data(), fusion.map());
    return Status::Ok();
  }

  /// The step's metrics against the ground truth (as `avp run` computes them), the fruits' state,
  /// and for an avp recording the comparison with the recorded metrics.
  void Evaluate(int i, const ros::bag::BagView& view, const robot::Observation& obs,
                const mapping::SemanticMap& map, pipeline::StepRecord& step) {
    const auto t0 = Clock::now();
    std::vector<eval::FruitResult> now;
    result_.final_metrics = eval::EvaluateMap(map, *gt_, eval_options_, &now);
    std::optional<std::unordered_map<uint16_t, double>> visible;
    if (obs.labels) visible = VisibleFractions(obs, gt_->fruits, eo_.integrator.max_range_m);
    fruits_.AfterView(i, std::move(now), visible);
    step.metrics = report::MetricsRow(result_.final_metrics);
    step.times.metrics_ms = MsSince(t0);
    if (!bag_.avp_recording() || view.step.is_null()) return;
    ++summary_.metrics_compared;
    const std::string difference = CompareMetrics(view.step, step);
    if (!difference.empty() && summary_.metrics_differ++ == 0) {
      // 1-based, as the progress lines and the report number views.
      summary_.first_difference = fmt::format("view {}: {}", view.index + 1, difference);
    }
  }

  /// How the replay ended: interrupted by a stop or the bag's damage, else all its views.
  void EndOfReplay(pipeline::EpisodeResult& episode) const {
    if (episode.end != pipeline::EpisodeEnd::kInterrupted && !bag_.damage().ok()) {
      episode.end = pipeline::EpisodeEnd::kInterrupted;
      episode.end_reason =
          fmt::format("the recording is damaged ({}): replayed the {} intact views",
                      bag_.damage().message(), episode.steps.size());
    } else if (episode.end == pipeline::EpisodeEnd::kBudgetReached) {
      episode.end_reason = fmt::format("replayed {} views of {}", episode.steps.size(),
                                       bag_.path().filename().string());
    }
  }

  ros::bag::BagReader& bag_;
  std::optional<ros::bag::BagView> first_;
  const RunConfig& config_;
  const pipeline::EpisodeOptions& eo_;
  const eval::GroundTruth* gt_;
  segmentation::Segmenter* segmenter_;  ///< null: the recorded masks
  ReplaySummary& summary_;
  /// The moving frames since the last view.
  pipeline::MovingFramesRecord moving_;
  eval::EvalOptions eval_options_;
  eval::FruitTracker fruits_;
  RunResult result_;
};

}  // namespace

Result<ReplaySummary> ReplayToFolder(ros::bag::BagReader& bag, RunConfig config,
                                     const Registries& registries, const ReplayOptions& options) {
  ReplaySummary summary;
  // The first view is read before anything else: a bag with nothing to fuse is refused before
  // anything is written, and a streamed bag has shown its topics (masks? labels?) by then.
  AVP_RETURN_IF_ERROR(
      ReplayConfigTable().Validate(config.replay).WithContext("invalid run configuration: replay"));
  AVP_RETURN_IF_ERROR(bag.SetSelection(config.replay));
  AVP_ASSIGN_OR_RETURN(std::optional<ros::bag::BagView> first, bag.Next());
  AVP_ASSIGN_OR_RETURN(const bool recorded, ChooseSegmenter(bag, options, config, summary));
  // The region of interest: the map keeps what is inside it.
  if (const std::optional<Box3> roi = config.replay.Roi()) config.map.grid.roi = *roi;
  // Checked once, here: the bag has chosen the segmenter.
  AVP_ASSIGN_OR_RETURN(const CheckedRunConfig checked,
                       CheckedRunConfig::Check(std::move(config), registries));
  const RunConfig& c = *checked;
  const ThreadScope threads(c.threads);
  AVP_ASSIGN_OR_RETURN(const std::optional<eval::GroundTruth> gt, BagGroundTruth(bag, c, summary));
  const ReplayScene scene = SceneOfBag(bag, c, registries, gt.has_value(), summary);

  // The episode's planning ROI: the moving frames updated only it (MotionFusionOptions).
  pipeline::EpisodeOptions eo = c.episode;
  eo.roi = scene.roi;
  std::unique_ptr<segmentation::Segmenter> segmenter;
  if (!recorded) {
    AVP_ASSIGN_OR_RETURN(
        segmenter, registries.segmenters.Make(c.segmenter.name, checked.segmenter_options(),
                                              {.seed = Rng(c.seed).Fork("segmenter").NextU64()}));
  }
  ReplayEpisode episode(bag, std::move(first), c, eo, gt ? &*gt : nullptr, scene.roi,
                        segmenter.get(), summary);

  FolderRun run;
  run.command = "avp replay";
  run.scene_name = scene.name;
  run.scene_description = scene.description;
  run.gt = gt ? &*gt : nullptr;
  run.extra = [&]() { return ReplayRecord(bag, summary); };
  run.run = [&](const std::vector<pipeline::EpisodeObserver*>& observers,
                std::unique_ptr<mapping::SemanticMap>* map_out,
                std::stop_token stop) -> Result<RunResult> {
    return episode.Run(observers, map_out, std::move(stop));
  };
  RunFolderOptions folder = options.folder;
  for (const auto& f : bag.info().files) folder.inputs.emplace_back(f, "bag");
  AVP_ASSIGN_OR_RETURN(summary.run, RunEpisodeToFolder(checked, folder, run));
  return summary;
}

}  // namespace avp::experiment

#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/text.h>
#include <avp/experiment/run_config.h>
#include <avp/io/options_yaml.h>
#include <avp/io/yaml.h>
#include <avp/sim/scenario.h>

namespace avp::experiment {

namespace {

constexpr std::string_view kOptions = ".options.";

/// "planner" / "segmenter" keys: true and done (or an error) when `key` is one of them.
bool SetComponentKey(ComponentChoice& choice, std::string_view component, std::string_view key,
                     std::string_view value, Status& status) {
  if (key.substr(0, component.size()) != component) return false;
  const std::string_view rest = key.substr(component.size());
  if (rest.empty() || rest == ".name") {
    choice.name = std::string(value);
    return true;
  }
  if (rest.substr(0, kOptions.size()) == kOptions && rest.size() > kOptions.size()) {
    choice.options.emplace_back(std::string(rest.substr(kOptions.size())), std::string(value));
    return true;
  }
  status = InvalidArgumentError(
      fmt::format("unknown run configuration key '{}' ({}.name and {}.options.KEY are known)", key,
                  component, component));
  return true;
}

/// The top-level keys and sections, for messages.
std::vector<std::string> TopLevelKeys() {
  std::vector<std::string> keys;
  for (const std::string& k : RunConfigTable().Keys()) {
    const std::string head = k.substr(0, k.find('.'));
    if (keys.empty() || keys.back() != head) keys.push_back(head);
  }
  keys.push_back("planner");
  keys.push_back("segmenter");
  return keys;
}

YAML::Node ComponentToYaml(const std::string& name, const AnyOptions& options) {
  YAML::Node node(YAML::NodeType::Map);
  node["name"] = name;
  if (options.has_fields()) node["options"] = io::OptionsToYaml(options.Values(), options.Info());
  return node;
}

}  // namespace

std::optional<Box3> ReplayConfig::Roi() const {
  if (roi_min_m.size() != 3 || roi_max_m.size() != 3) return std::nullopt;
  return Box3(Eigen::Vector3d(roi_min_m[0], roi_min_m[1], roi_min_m[2]),
              Eigen::Vector3d(roi_max_m[0], roi_max_m[1], roi_max_m[2]));
}

const OptionTable<ReplayConfig>& ReplayConfigTable() {
  static const auto* table = [] {
    using R = ReplayConfig;
    auto* t = new OptionTable<R>("replay key");
    ros::bag::AddFrameSelectionOptions(*t);
    t->RealList("roi_min_m", &R::roi_min_m, "m", ValueRange::Closed(-1000, 1000), 0, 3,
                "the map keeps voxels inside [roi_min_m, roi_max_m] only (x,y,z in the base "
                "frame; empty: no box)");
    t->RealList("roi_max_m", &R::roi_max_m, "m", ValueRange::Closed(-1000, 1000), 0, 3,
                "the box's other corner (x,y,z)");
    t->AddRule([](const R& r, std::vector<std::string>& errors) {
      const size_t a = r.roi_min_m.size(), b = r.roi_max_m.size();
      if ((a != 0 && a != 3) || (b != 0 && b != 3) || a != b) {
        errors.push_back(fmt::format(
            "roi_min_m ({} values) and roi_max_m ({} values): give both as x,y,z or neither", a,
            b));
        return;
      }
      for (size_t i = 0; i < a; ++i) {
        if (!(r.roi_max_m[i] > r.roi_min_m[i])) {
          errors.push_back(fmt::format("roi_max_m[{}] = {} must be above roi_min_m[{}] = {}", i,
                                       r.roi_max_m[i], i, r.roi_min_m[i]));
        }
      }
    });
    return t;
  }();
  return *table;
}

const OptionTable<RunConfig>& RunConfigTable() {
  static const auto* table = [] {
    using R = RunConfig;
    auto* t = new OptionTable<R>("run configuration key");
    t->Text("scenario", &R::scenario, "a registered scenario (empty: the default one)");
    t->Path("scene_file", &R::scene_file, "a YAML scene file instead of a scenario");
    t->Text("arrangement", &R::arrangement,
            "how the scene file's plant is arranged: reference, full-occlusion, single-cluster, "
            "unoriented-start or KEY=VALUE items joined by '+' (docs/scene-format.md)");
    t->Integer("seed", &R::seed, "", ValueRange::Any(),
               "seed of the plant, the noise and every choice");
    t->Integer("threads", &R::threads, "", ValueRange::Closed(0, kMaxThreads),
               "threads (0 = all); results do not depend on it");
    t->Real("roi_margin_m", &R::roi_margin_m, "m", ValueRange::Closed(0, 1),
            "the planning ROI is the plant's bounds inflated by this");
    t->Path("ground_truth_file", &R::ground_truth_file,
            "ground truth from an OctoMap .bt instead of the observable fruit surface");
    t->Flag("oracle_regret", &R::oracle_regret,
            "measure each plan step's regret with the truth (record.json oracle_regret)");
    t->Flag("oracle_regret_features", &R::oracle_regret_features,
            "with oracle_regret: each scored candidate's feature row too (learned gain data)");
    t->Flag("oracle_motion", &R::oracle_motion,
            "simulation, with motion.enabled: plan motion against the true scene instead of the "
            "map (collision-free motion's ceiling)");
    t->Nested("camera", &R::camera, CameraIntrinsicsTable());
    t->Nested("depth_noise", &R::depth_noise, sim::DepthNoiseTable());
    t->Nested("map", &R::map, mapping::MapOptionTable());
    t->Nested("episode", &R::episode, pipeline::EpisodeOptionTable());
    t->Nested("ground_truth", &R::ground_truth, eval::GroundTruthOptionTable());
    t->Nested("replay", &R::replay, ReplayConfigTable());
    t->Nested("motion", &R::motion, motion::MotionOptionTable());
    t->AddRule([](const R& c, std::vector<std::string>& errors) {
      if (c.oracle_regret_features && !c.oracle_regret) {
        errors.push_back("oracle_regret_features needs oracle_regret");
      }
      if (!c.scenario.empty() && !c.scene_file.empty()) {
        errors.push_back(fmt::format("give a scenario ('{}') or a scene file ('{}'), not both",
                                     c.scenario, c.scene_file.string()));
      }
    });
    return t;
  }();
  return *table;
}

Status SetRunConfigKey(RunConfig& config, std::string_view key, std::string_view value) {
  Status status;
  if (SetComponentKey(config.planner, "planner", key, value, status) ||
      SetComponentKey(config.segmenter, "segmenter", key, value, status)) {
    return status;
  }
  if (!RunConfigTable().Has(key)) {
    std::vector<std::string> keys = RunConfigTable().Keys();
    const std::vector<std::string> top = TopLevelKeys();
    keys.insert(keys.end(), top.begin(), top.end());
    return InvalidArgumentError(fmt::format(
        "unknown run configuration key '{}' (known: {}; avp run --print-config shows them all){}",
        key, fmt::join(TopLevelKeys(), ", "), DidYouMean(key, keys)));
  }
  return RunConfigTable().Set(config, key, value);
}

Result<AnyOptions> PlannerOptions(const RunConfig& config, const Registries& registries) {
  return registries.planners.Options(config.planner.name, config.planner.options);
}

Result<AnyOptions> SegmenterOptions(const RunConfig& config, const Registries& registries) {
  return registries.segmenters.Options(config.segmenter.name, config.segmenter.options);
}

Status RunConfig::Validate(const Registries& registries) const {
  std::vector<std::string> errors = RunConfigTable().Problems(*this);
  if (!scenario.empty() && registries.scenarios.Find(scenario) == nullptr) {
    errors.push_back(fmt::format("unknown scenario '{}' (known: {}){}", scenario,
                                 fmt::join(registries.scenarios.Names(), ", "),
                                 DidYouMean(scenario, registries.scenarios.Names())));
  }
  if (const Result<sim::Arrangement> a = sim::ParseArrangement(arrangement); !a.ok()) {
    errors.push_back(a.status().message());
  } else if (scene_file.empty() && !a->IsIdentity()) {
    errors.push_back(fmt::format(
        "arrangement '{}' needs a scene file (scene_file): a scenario ('{}') is arranged by its "
        "generator (only 'reference' is accepted)",
        arrangement, scenario.empty() ? sim::DefaultScenarioName() : scenario));
  }
  if (Result<AnyOptions> p = PlannerOptions(*this, registries); !p.ok()) {
    errors.push_back(p.status().message());
  }
  if (Result<AnyOptions> s = SegmenterOptions(*this, registries); !s.ok()) {
    errors.push_back(s.status().message());
  } else if (Status ready = registries.segmenters.Check(segmenter.name, *s); !ready.ok()) {
    // A missing model directory, found before a run folder exists.
    errors.push_back(ready.message());
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError(
      fmt::format("invalid run configuration: {}", fmt::join(errors, "; ")));
}

CheckedRunConfig::CheckedRunConfig(RunConfig config, const Registries& registries,
                                   AnyOptions planner, AnyOptions segmenter)
    : config_(std::move(config)),
      registries_(&registries),
      planner_options_(std::move(planner)),
      segmenter_options_(std::move(segmenter)) {}

Result<CheckedRunConfig> CheckedRunConfig::Check(RunConfig config, const Registries& registries) {
  AVP_RETURN_IF_ERROR(config.Validate(registries));
  AVP_ASSIGN_OR_RETURN(AnyOptions planner, PlannerOptions(config, registries));
  AVP_ASSIGN_OR_RETURN(AnyOptions segmenter, SegmenterOptions(config, registries));
  return CheckedRunConfig(std::move(config), registries, std::move(planner), std::move(segmenter));
}

Result<YAML::Node> RunConfigToYaml(const RunConfig& config, const Registries& registries) {
  AVP_ASSIGN_OR_RETURN(const AnyOptions planner, PlannerOptions(config, registries));
  AVP_ASSIGN_OR_RETURN(const AnyOptions segmenter, SegmenterOptions(config, registries));
  YAML::Node root =
      io::OptionsToYaml(RunConfigTable().Values(config), RunConfigTable().Info(config));
  root["planner"] = ComponentToYaml(config.planner.name, planner);
  root["segmenter"] = ComponentToYaml(config.segmenter.name, segmenter);
  return root;
}

Status ReadRunConfigYaml(const YAML::Node& node, std::string_view context, RunConfig& config) {
  AVP_ASSIGN_OR_RETURN(const OptionValues values, io::FlattenYaml(node, context));
  for (const auto& [key, value] : values) {
    if (Status s = SetRunConfigKey(config, key, value); !s.ok()) return s.WithContext(context);
  }
  return Status::Ok();
}

Result<RunConfig> LoadRunConfig(const std::filesystem::path& yaml, const Registries& registries) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node root, io::LoadYamlFile(yaml));
  RunConfig config;
  AVP_RETURN_IF_ERROR(ReadRunConfigYaml(root, yaml.string(), config));
  if (Status s = config.Validate(registries); !s.ok()) return s.WithContext(yaml.string());
  return config;
}

}  // namespace avp::experiment

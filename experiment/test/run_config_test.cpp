// The run configuration tree: YAML out and back in unchanged, every key settable, unknown keys and
// bad values named, defaults written once (each module's own).
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/experiment/run_config.h>
#include <avp/io/options_yaml.h>
#include <avp/planning/avp_nbv_planner.h>
#include <avp/segmentation/oracle_segmenter.h>

namespace avp::experiment {
namespace {

using ::testing::HasSubstr;

const Registries& TheRegistries() {
  static const auto* registries = new Registries(BuiltinRegistries());
  return *registries;
}

std::string YamlOf(const RunConfig& c) {
  const Result<YAML::Node> yaml = RunConfigToYaml(c, TheRegistries());
  EXPECT_TRUE(yaml.ok()) << yaml.status().ToString();
  return yaml.ok() ? io::YamlText(*yaml) : std::string();
}

/// A configuration far from the defaults, through the same keys a user types.
RunConfig Changed() {
  RunConfig c;
  for (const auto& [key, value] : std::vector<std::pair<std::string, std::string>>{
           {"scenario", "tomato-full-occlusion"},
           {"seed", "18446744073709551615"},
           {"threads", "3"},
           {"roi_margin_m", "0.0625"},
           {"oracle_regret", "true"},
           {"camera.fx", "600.5"},
           {"depth_noise.enabled", "false"},
           {"map.grid.voxel_size_m", "0.01"},
           {"map.semantics.policy", "reference-max"},
           {"map.semantics.miss_log_odds", "0.3"},
           {"episode.views", "5"},
           {"episode.prompt", "tomato, green apple"},
           {"episode.integrator.carving", "raycast"},
           {"ground_truth.radii_m", "0.3,0.45"},
           {"planner", "isler-oa"},
           {"planner.options.cost_weight", "0.25"},
           {"planner.options.candidates.radii_m", "0.3,0.6"},
           {"segmenter.name", "oracle-perfect"},
           {"segmenter.options.fruit_words", "tomato,apple"}}) {
    EXPECT_TRUE(SetRunConfigKey(c, key, value).ok()) << key;
  }
  return c;
}

TEST(RunConfigTest, PrintedYamlReadsBackUnchanged) {
  for (const RunConfig& c : {RunConfig{}, Changed()}) {
    ASSERT_TRUE(c.Validate(TheRegistries()).ok()) << c.Validate(TheRegistries()).ToString();
    const std::string text = YamlOf(c);
    RunConfig back;
    ASSERT_TRUE(ReadRunConfigYaml(YAML::Load(text), "printed.yaml", back).ok());
    ASSERT_TRUE(back.Validate(TheRegistries()).ok()) << back.Validate(TheRegistries()).ToString();
    EXPECT_EQ(YamlOf(back), text);
    EXPECT_TRUE(RunConfigTable().Differences(back, c).empty());
    EXPECT_EQ(back.planner.name, c.planner.name);
    EXPECT_EQ(back.segmenter.name, c.segmenter.name);
  }
  const RunConfig c = Changed();
  const std::string text = YamlOf(c);
  EXPECT_THAT(text, HasSubstr("seed: 18446744073709551615\n"));
  EXPECT_THAT(text, HasSubstr("  grid:\n    voxel_size_m: 0.01\n"));
  EXPECT_THAT(text, HasSubstr("planner:\n  name: isler-oa\n  options:\n    candidates:\n"
                              "      radii_m: [0.3, 0.6]\n"));
  EXPECT_THAT(text, HasSubstr("    cost_weight: 0.25\n"));
  EXPECT_THAT(text, HasSubstr("    fruit_words: [tomato, apple]\n"));
  // The component options print in full: every field of the planner's table, defaults included.
  const AnyOptions planner = PlannerOptions(c, TheRegistries()).value();
  for (const std::string& key : planner.Keys()) {
    EXPECT_THAT(text, HasSubstr(key.substr(key.rfind('.') + 1) + ":")) << key;
  }
  EXPECT_EQ(SegmenterOptions(c, TheRegistries())->As<segmentation::OracleOptions>().p_merge, 0.0)
      << "oracle-perfect's defaults";
}

TEST(RunConfigTest, CheckedOnceAtTheDoor) {
  // A CheckedRunConfig is only made by Check: valid, its components' options resolved.
  RunConfig c;
  ASSERT_TRUE(SetRunConfigKey(c, "planner.options.p_unknown", "0.25").ok());
  ASSERT_TRUE(SetRunConfigKey(c, "threads", "3").ok());
  const Result<CheckedRunConfig> checked = CheckedRunConfig::Check(c, TheRegistries());
  ASSERT_TRUE(checked.ok()) << checked.status().ToString();
  EXPECT_EQ((*checked)->threads, 3);
  EXPECT_EQ(&checked->registries(), &TheRegistries());
  EXPECT_EQ(checked->planner_options().As<planning::AvpNbvOptions>().p_unknown, 0.25);
  EXPECT_EQ(checked->segmenter_options().As<segmentation::OracleOptions>().p_merge,
            SegmenterOptions(c, TheRegistries())->As<segmentation::OracleOptions>().p_merge);
  // Every problem at once, as Validate names them; no CheckedRunConfig is made.
  ASSERT_TRUE(SetRunConfigKey(c, "planner.options.p_unknown", "1.5").ok());
  c.scenario = "no-such-plant";
  const Result<CheckedRunConfig> bad = CheckedRunConfig::Check(c, TheRegistries());
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("invalid run configuration"));
  EXPECT_THAT(bad.status().message(), HasSubstr("unknown scenario 'no-such-plant'"));
  EXPECT_THAT(bad.status().message(), HasSubstr("p_unknown (1.5)"));
}

TEST(RunConfigTest, UnknownKeysAndBadValuesAreNamed) {
  RunConfig c;
  Status s = SetRunConfigKey(c, "map.grid.voxel_sise_m", "0.01");
  EXPECT_THAT(s.message(), HasSubstr("unknown run configuration key 'map.grid.voxel_sise_m' "
                                     "(known: scenario, scene_file, arrangement, seed,"));
  EXPECT_THAT(s.message(),
              HasSubstr("map, episode, ground_truth, replay, motion, planner, segmenter"));
  s = SetRunConfigKey(c, "planner.option.p_unknown", "0.1");
  EXPECT_THAT(s.message(), HasSubstr("planner.name and planner.options.KEY are known"));
  EXPECT_THAT(SetRunConfigKey(c, "seed", "-1").message(), HasSubstr("is not a whole number >= 0"));
  EXPECT_THAT(SetRunConfigKey(c, "episode.views", "many").message(),
              HasSubstr("'many' is not a whole number"));
  EXPECT_THAT(ReadRunConfigYaml(YAML::Load("episode: {viewz: 3}"), "run.yaml", c).message(),
              HasSubstr("run.yaml: unknown run configuration key 'episode.viewz'"));

  // Validate names every problem at once: the tables' ranges and the components' options.
  c = RunConfig{};
  c.episode.views = 0;
  c.map.grid.voxel_size_m = 1.0;
  c.planner.options = {{"p_unknown", "2"}};
  c.segmenter.name = "magic";
  c.scenario = "tomato-nowhere";
  const std::string m = c.Validate(TheRegistries()).message();
  EXPECT_THAT(m, HasSubstr("invalid run configuration: "));
  EXPECT_THAT(m, HasSubstr("map.grid.voxel_size_m (1 m) must be in [0.002, 0.02]"));
  EXPECT_THAT(m, HasSubstr("episode.views (0) must be in [1, 1000]"));
  EXPECT_THAT(m, HasSubstr("unknown scenario 'tomato-nowhere' (known: tomato-multiple-clusters"));
  EXPECT_THAT(m, HasSubstr("p_unknown (2) must be in [0, 1)"));
  EXPECT_THAT(m, HasSubstr("unknown segmenter 'magic' (known: oracle, oracle-perfect, color)"));
}

TEST(RunConfigTest, ArrangementNeedsASceneFileAndAKnownName) {
  RunConfig c;
  ASSERT_TRUE(SetRunConfigKey(c, "arrangement", "full-occlusion").ok());
  EXPECT_THAT(c.Validate(TheRegistries()).message(),
              HasSubstr("arrangement 'full-occlusion' needs a scene file (scene_file): a scenario "
                        "('tomato-multiple-clusters') is arranged by its generator"));
  c.arrangement = "reference";
  EXPECT_TRUE(c.Validate(TheRegistries()).ok()) << c.Validate(TheRegistries()).ToString();
  c.scene_file = "plant.yaml";  // not read by Validate
  c.arrangement = "single-cluster+start-yaw=20";
  EXPECT_TRUE(c.Validate(TheRegistries()).ok()) << c.Validate(TheRegistries()).ToString();
  c.arrangement = "sideways";
  EXPECT_THAT(c.Validate(TheRegistries()).message(), HasSubstr("unknown arrangement 'sideways'"));
}

TEST(RunConfigTest, DefaultsAreTheModulesOwn) {
  // Each default is written once, in its module: the run nests the module structs.
  const RunConfig c;
  EXPECT_EQ(c.map.grid.voxel_size_m, mapping::GridOptions{}.voxel_size_m);
  EXPECT_EQ(c.episode.integrator.carving, mapping::IntegratorOptions{}.carving);
  EXPECT_EQ(c.episode.integrator.max_range_m, mapping::IntegratorOptions{}.max_range_m);
  EXPECT_EQ(c.map.semantics.policy, mapping::SemanticOptions{}.policy);
  EXPECT_EQ(c.ground_truth.voxel_size_m, c.map.grid.voxel_size_m);
  EXPECT_EQ(c.ground_truth.max_range_m, c.episode.integrator.max_range_m);
  EXPECT_EQ(PlannerOptions(c, TheRegistries())->As<planning::AvpNbvOptions>().p_unknown,
            planning::AvpNbvOptions{}.p_unknown);
}

}  // namespace
}  // namespace avp::experiment

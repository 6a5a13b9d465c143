#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/io/options_yaml.h>

namespace avp::io {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::Pair;

struct Shell {
  std::vector<double> radii_m = {0.35, 0.55};
  int max_targets = 12;
};
struct Planner {
  double p_unknown = 0.05;
  bool predict = true;
  std::string note = "a: b";
  Shell candidates;
};

const OptionTable<Shell>& ShellTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<Shell>("shell option");
    t->RealList("radii_m", &Shell::radii_m, "m", ValueRange::Above(0), 2, 2, "radii");
    t->Integer("max_targets", &Shell::max_targets, "", ValueRange::AtLeast(1), "targets");
    return t;
  }();
  return *table;
}

const OptionTable<Planner>& PlannerTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<Planner>("planner option");
    t->Real("p_unknown", &Planner::p_unknown, "", ValueRange::HalfOpen(0, 1), "occlusion");
    t->Flag("predict", &Planner::predict, "predict");
    t->Text("note", &Planner::note, "a note");
    t->Nested("candidates", &Planner::candidates, ShellTable());
    return t;
  }();
  return *table;
}

TEST(OptionsYamlTest, WritesNestedMapsAndReadsThemBack) {
  Planner p;
  p.p_unknown = 0.1;
  p.candidates.radii_m = {0.3, 0.7};
  const YAML::Node node = OptionsToYaml(PlannerTable().Values(p), PlannerTable().Info());
  const std::string text = YamlText(node);
  EXPECT_THAT(text, HasSubstr("p_unknown: 0.1\n"));
  EXPECT_THAT(text, HasSubstr("candidates:\n  radii_m: [0.3, 0.7]\n  max_targets: 12\n"));
  Planner back;
  back.predict = false;
  ASSERT_TRUE(ReadOptionsYaml(PlannerTable(), back, YAML::Load(text), "test.yaml").ok());
  EXPECT_TRUE(PlannerTable().Differences(back, p).empty());
  EXPECT_EQ(back.note, "a: b");
}

TEST(OptionsYamlTest, FlattensInDocumentOrder) {
  const Result<OptionValues> v =
      FlattenYaml(YAML::Load("b: 1\na: {y: [1, 2], x: true}\nc:\n"), "ctx");
  ASSERT_TRUE(v.ok());
  EXPECT_THAT(*v,
              ElementsAre(Pair("b", "1"), Pair("a.y", "1,2"), Pair("a.x", "true"), Pair("c", "")));
  EXPECT_THAT(FlattenYaml(YAML::Load("[1, 2]"), "ctx").status().message(),
              HasSubstr("ctx: expected a map"));
  EXPECT_THAT(FlattenYaml(YAML::Load("a: [{b: 1}]"), "ctx").status().message(),
              HasSubstr("'a' must be a list"));
}

TEST(OptionsYamlTest, UnknownKeysNameTheKnownOnes) {
  Planner p;
  const Status s =
      ReadOptionsYaml(PlannerTable(), p, YAML::Load("candidates: {radius: 1}"), "run.yaml");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("run.yaml: unknown planner option 'candidates.radius' "
                                     "(known: p_unknown, predict, note, candidates.radii_m"));
  AnyOptions none;
  EXPECT_THAT(ReadOptionsYaml(none, YAML::Load("x: 1"), "run.yaml", "planner 'random'").message(),
              HasSubstr("planner 'random' has no options"));
}

}  // namespace
}  // namespace avp::io

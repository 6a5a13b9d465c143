#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <avp/planning/learned_gain.h>
#include <avp/planning/view_features.h>

namespace avp::planning {
namespace {

using ::testing::HasSubstr;
namespace fs = std::filesystem;

/// The models make_gain_models.py wrote (the gain_models fixture).
fs::path ModelDir() { return fs::path(AVP_GAIN_MODEL_DIR); }

std::string Manifest(const nlohmann::json& patch = nlohmann::json::object()) {
  nlohmann::json m = {{"format", kLearnedGainFormat},
                      {"feature_version", kViewFeatureVersion},
                      {"feature_hash", ViewFeatureHash()}};
  nlohmann::json names = nlohmann::json::array();
  for (const std::string_view n : ViewFeatureNames()) names.push_back(n);
  m["feature_names"] = names;
  m.merge_patch(patch);
  return m.dump();
}

TEST(LearnedGainManifestTest, AcceptsThePlannersFeatureListAndNamesEveryMismatch) {
  EXPECT_TRUE(CheckLearnedGainManifest(Manifest()).ok());
  EXPECT_THAT(CheckLearnedGainManifest("[1, 2]").message(), HasSubstr("not a JSON object"));
  EXPECT_THAT(CheckLearnedGainManifest("{").message(), HasSubstr("not a JSON object"));
  const std::string old = CheckLearnedGainManifest(Manifest({{"feature_version", 0}})).message();
  EXPECT_THAT(old, HasSubstr("feature_version 0"));
  const Status hash =
      CheckLearnedGainManifest(Manifest({{"feature_hash", "feedfacefeedface"}, {"format", "x/2"}}));
  EXPECT_THAT(hash.message(), HasSubstr("feature_hash 'feedfacefeedface'"));
  EXPECT_THAT(hash.message(), HasSubstr("format 'x/2'"));
  EXPECT_THAT(CheckLearnedGainManifest(Manifest({{"feature_names", {"a", "b"}}})).message(),
              HasSubstr("2 feature names"));
  nlohmann::json swapped = nlohmann::json::parse(Manifest())["feature_names"];
  std::swap(swapped[3], swapped[4]);
  EXPECT_THAT(CheckLearnedGainManifest(Manifest({{"feature_names", swapped}})).message(),
              HasSubstr("feature 3 is \"" + swapped[3].get<std::string>() + "\""));
}

TEST(LearnedGainManifestTest, TheFeatureListIsNamedUniquelyAndHashed) {
  const auto names = ViewFeatureNames();
  EXPECT_EQ(names.size(), ViewFeatureCount());
  EXPECT_EQ(std::set<std::string_view>(names.begin(), names.end()).size(), names.size());
  EXPECT_EQ(ViewFeatureHash().size(), 16u);
  EXPECT_EQ(ViewFeatureHash(), ViewFeatureHash());
}

TEST(LearnedGainModelTest, ResolvesBareNamesUnderTheConfigDirectory) {
  EXPECT_EQ(ResolveGainModelPath("learned").filename(), "learned.onnx");
  EXPECT_EQ(ResolveGainModelPath("learned").parent_path().filename(), "models");
  EXPECT_EQ(ResolveGainModelPath("/tmp/m.onnx"), fs::path("/tmp/m.onnx"));
  EXPECT_EQ(ResolveGainModelPath("m.onnx"), fs::path("m.onnx"));
}

#if defined(AVP_WITH_ONNX)

TEST(LearnedGainModelTest, PredictsWhatTheTrainingFrameworkPredicted) {
  const Result<std::shared_ptr<const LearnedGainModel>> model =
      LearnedGainModel::Load(ModelDir() / "good.onnx");
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_THAT((*model)->Summary(), HasSubstr("400 rows"));
  std::ifstream in(ModelDir() / "good.onnx.check.json");
  const nlohmann::json check = nlohmann::json::parse(in);
  std::vector<float> rows;
  for (const auto& row : check["rows"]) {
    for (const auto& v : row) rows.push_back(v.get<float>());
  }
  const size_t n = check["rows"].size();
  const Result<std::vector<float>> p = (*model)->Predict(rows, n);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_EQ(p->size(), n);
  double spread = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const double expected = check["predictions"][i].get<double>();
    EXPECT_NEAR((*p)[i], expected, 1e-5) << "row " << i;
    spread = std::max(spread, std::abs(expected - check["predictions"][0].get<double>()));
  }
  EXPECT_GT(spread, 0.1);  // the rows differ, and so do the predictions
  EXPECT_THAT(
      (*model)->Predict(std::vector<float>(rows.begin(), rows.end() - 1), n).status().message(),
      HasSubstr("values for"));
  EXPECT_TRUE((*model)->Predict({}, 0).ok());
}

TEST(LearnedGainModelTest, RefusesBadFilesByName) {
  const auto error = [](const char* name) {
    return LearnedGainModel::Load(ModelDir() / name).status();
  };
  EXPECT_EQ(error("missing.onnx").code(), StatusCode::kNotFound);
  EXPECT_THAT(error("missing.onnx").message(), HasSubstr("missing.onnx"));
  EXPECT_THAT(error("not_onnx.onnx").message(), HasSubstr("ONNX Runtime cannot load it"));
  EXPECT_THAT(error("truncated.onnx").message(), HasSubstr("truncated.onnx"));
  EXPECT_THAT(error("no_manifest.onnx").message(), HasSubstr("no manifest"));
  EXPECT_THAT(error("old_version.onnx").message(), HasSubstr("feature_version"));
  EXPECT_THAT(error("other_names.onnx").message(), HasSubstr("feature_hash"));
  EXPECT_THAT(error("other_format.onnx").message(), HasSubstr("someone-elses/3"));
  EXPECT_THAT(error("wide_input.onnx").message(), HasSubstr("its input has shape"));
  // Over the size limit: refused before ONNX Runtime reads it (a sparse file: no disk used).
  const fs::path huge = ModelDir() / "huge.onnx";
  { std::ofstream(huge).put('x'); }
  fs::resize_file(huge, kMaxLearnedGainModelBytes + 1);
  EXPECT_THAT(error("huge.onnx").message(), HasSubstr("over the limit"));
  fs::remove(huge);
}

TEST(LearnedGainModelTest, ANonFinitePredictionIsAnErrorNamingTheRow) {
  const auto model = LearnedGainModel::Load(ModelDir() / "nan.onnx");
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  const std::vector<float> rows(2 * ViewFeatureCount(), 0.5f);
  const Status s = (*model)->Predict(rows, 2).status();
  EXPECT_THAT(s.message(), HasSubstr("for row 0 is not finite"));
}

/// The committed model (configs/models/learned.onnx) loads and computes what scikit-learn did.
TEST(LearnedGainModelTest, TheCommittedModelEqualsItsStoredPredictions) {
  const fs::path file = ResolveGainModelPath("learned");
  const auto model = LearnedGainModel::Load(file);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  std::ifstream in(file.string() + ".check.json");
  ASSERT_TRUE(in.good()) << file << ".check.json";
  const nlohmann::json check = nlohmann::json::parse(in);
  std::vector<float> rows;
  for (const auto& row : check["rows"]) {
    for (const auto& v : row) rows.push_back(v.get<float>());
  }
  const Result<std::vector<float>> p = (*model)->Predict(rows, check["rows"].size());
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  for (size_t i = 0; i < p->size(); ++i) {
    EXPECT_NEAR((*p)[i], check["predictions"][i].get<double>(), check["tolerance"].get<double>())
        << "row " << i;
  }
}

#else

TEST(LearnedGainModelTest, WithoutOnnxRuntimeLoadingIsRefused) {
  EXPECT_THAT(LearnedGainModel::Load(ModelDir() / "good.onnx").status().message(),
              HasSubstr("without ONNX Runtime"));
}

#endif

}  // namespace
}  // namespace avp::planning

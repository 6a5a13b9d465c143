// metrics.csv is written step by step, each write checked: the rows are on the file as the
// episode goes, and a write that fails (a full disk) stops the episode and names the file.
#include <filesystem>
#include <fstream>
#include <stop_token>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/mapping/semantic_map.h>
#include <avp/report/metrics_csv.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::report {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::StartsWith;

std::string ReadAll(const fs::path& p) { return test::ReadWholeFile(p); }

pipeline::StepRecord Step(int view) {
  pipeline::StepRecord s;
  s.view = view;
  s.views_total = 3;
  s.metrics = {{"f1", 0.25 * view}, {"fruits_found", 1.0}};
  s.masks = 2;
  return s;
}

class MetricsCsvTest : public test::TempDirTest {
 protected:
  const mapping::SemanticMap map_;
};

TEST_F(MetricsCsvTest, RowsAreOnTheFileAsTheEpisodeGoes) {
  const fs::path p = dir_ / "metrics.csv";
  Result<std::unique_ptr<MetricsCsvWriter>> w = MetricsCsvWriter::Open(p);
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  (*w)->OnStep(Step(0), map_);
  std::string text = ReadAll(p);
  EXPECT_THAT(text, StartsWith("view,f1,fruits_found,known_voxels,"));
  EXPECT_THAT(text, HasSubstr("\n1,0,1,0,0,0,0,2,"));
  (*w)->OnStep(Step(1), map_);
  EXPECT_THAT(ReadAll(p), HasSubstr("\n2,0.25,1,"));
  EXPECT_TRUE((*w)->status().ok());
  EXPECT_TRUE((*w)->Close().ok());
}

TEST_F(MetricsCsvTest, AFullDiskStopsTheEpisodeNamingTheFile) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  Result<std::unique_ptr<MetricsCsvWriter>> w = MetricsCsvWriter::Open("/dev/full");
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  std::stop_source stop;
  (*w)->StopOnError(stop);
  EXPECT_FALSE(stop.stop_requested());
  (*w)->OnStep(Step(0), map_);
  EXPECT_TRUE(stop.stop_requested()) << "the episode was not asked to stop";
  EXPECT_EQ((*w)->status().code(), StatusCode::kIoError);
  EXPECT_THAT((*w)->status().message(), HasSubstr("metrics file '/dev/full'"));
  EXPECT_THAT((*w)->status().message(), HasSubstr("No space left on device"));
  EXPECT_EQ((*w)->Close().code(), StatusCode::kIoError);
}

TEST_F(MetricsCsvTest, UnwritablePathIsNamed) {
  std::ofstream(dir_ / "file") << "x";
  const Status s = MetricsCsvWriter::Open(dir_ / "file" / "metrics.csv").status();
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr((dir_ / "file" / "metrics.csv").string()));
}

}  // namespace
}  // namespace avp::report

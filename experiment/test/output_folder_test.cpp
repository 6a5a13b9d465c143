// The lifecycle of an output folder (avp-state.json) and what a rerun into it may do: a folder
// holding results is refused unless --force, which empties only what avp writes.
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/experiment/output_folder.h>
#include <avp/test/temp_dir_test.h>

namespace avp::experiment {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

class OutputFolderTest : public test::TempDirTest {};

TEST_F(OutputFolderTest, MissingAndEmptyFoldersAreUsedAsTheyAre) {
  EXPECT_TRUE(PrepareOutputFolder(dir_ / "a" / "b", RunFolderKind(), false).ok());
  EXPECT_TRUE(fs::is_directory(dir_ / "a" / "b"));
  EXPECT_TRUE(PrepareOutputFolder(dir_ / "a" / "b", RunFolderKind(), false).ok());
  EXPECT_EQ(ReadFolderState(dir_ / "a" / "b").status().code(), StatusCode::kNotFound);
}

TEST_F(OutputFolderTest, StatesFollowTheRun) {
  const fs::path d = dir_ / "run";
  ASSERT_TRUE(PrepareOutputFolder(d, RunFolderKind(), false).ok());
  ASSERT_TRUE(MarkInProgress(d, RunFolderKind(), "avp run").ok());
  Result<FolderState> s = ReadFolderState(d);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ(s->state, "in-progress");
  EXPECT_EQ(s->kind, "run");
  EXPECT_FALSE(s->started.empty());
  const std::string started = s->started;
  ASSERT_TRUE(MarkComplete(d, RunFolderKind(), "avp run").ok());
  s = ReadFolderState(d);
  EXPECT_EQ(s->state, "complete");
  EXPECT_EQ(s->started, started);
  EXPECT_FALSE(s->finished.empty());
  MarkFailed(d, RunFolderKind(), "avp run", IoError("writing 'map.ot' failed"));
  s = ReadFolderState(d);
  EXPECT_EQ(s->state, "failed");
  EXPECT_THAT(s->error, HasSubstr("writing 'map.ot' failed"));
}

TEST_F(OutputFolderTest, AnOversizedStateFileIsRefusedBeforeItIsRead) {
  const fs::path d = dir_ / "run";
  fs::create_directories(d);
  std::ofstream(d / "avp-state.json") << std::string((64 << 10) + 1, ' ');
  const Status s = ReadFolderState(d).status();
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted) << s.ToString();
  EXPECT_THAT(s.message(), HasSubstr("avp state file"));
}

TEST_F(OutputFolderTest, AFolderWithResultsIsRefusedSayingWhatItHolds) {
  const fs::path d = dir_ / "run";
  ASSERT_TRUE(PrepareOutputFolder(d, RunFolderKind(), false).ok());
  ASSERT_TRUE(MarkInProgress(d, RunFolderKind(), "avp run").ok());
  std::ofstream(d / "metrics.csv") << "view\n1\n";
  Status s = PrepareOutputFolder(d, RunFolderKind(), false);
  EXPECT_EQ(s.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(s.message(), HasSubstr("output folder '" + d.string() + "' already holds"));
  EXPECT_THAT(s.message(), HasSubstr("an avp run that did not finish"));
  EXPECT_THAT(s.message(), HasSubstr("--force"));
  EXPECT_EQ(CheckOutputFolder(d, RunFolderKind(), false).message(), s.message());
  ASSERT_TRUE(MarkComplete(d, RunFolderKind(), "avp run").ok());
  EXPECT_THAT(PrepareOutputFolder(d, RunFolderKind(), false).message(),
              HasSubstr("the results of a complete avp run"));
  // --force empties it (the temporary file a kill left included).
  std::ofstream(d / "record.json.tmp.123.0") << "{";
  EXPECT_TRUE(CheckOutputFolder(d, RunFolderKind(), true).ok());
  EXPECT_TRUE(fs::exists(d / "metrics.csv")) << "CheckOutputFolder changed the folder";
  ASSERT_TRUE(PrepareOutputFolder(d, RunFolderKind(), true).ok());
  EXPECT_TRUE(fs::is_empty(d));
}

TEST_F(OutputFolderTest, ForceNeverRemovesWhatAvpDidNotWrite) {
  const fs::path d = dir_ / "data";
  fs::create_directories(d / "raw");
  std::ofstream(d / "scan.bag") << "bytes";
  Status s = PrepareOutputFolder(d, RunFolderKind(), true);
  EXPECT_EQ(s.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(s.message(), HasSubstr("'raw', 'scan.bag'"));
  EXPECT_THAT(s.message(), HasSubstr("not an avp run folder, so --force does not empty it"));
  EXPECT_TRUE(fs::exists(d / "scan.bag"));
  // A file of a run folder's name alone is not enough: no marker and no record.json.
  const fs::path lone = dir_ / "lone";
  fs::create_directories(lone);
  std::ofstream(lone / "metrics.csv") << "mine";
  EXPECT_THAT(PrepareOutputFolder(lone, RunFolderKind(), true).message(),
              HasSubstr("so --force does not empty it"));
  EXPECT_TRUE(fs::exists(lone / "metrics.csv"));
  // A run folder is not a bench folder.
  const fs::path run = dir_ / "run";
  ASSERT_TRUE(PrepareOutputFolder(run, RunFolderKind(), false).ok());
  ASSERT_TRUE(MarkComplete(run, RunFolderKind(), "avp run").ok());
  std::ofstream(run / "record.json") << "{}";
  EXPECT_THAT(PrepareOutputFolder(run, BenchFolderKind(), true).message(),
              HasSubstr("not an avp bench folder"));
  EXPECT_TRUE(fs::exists(run / "record.json"));
  // An earlier avp's run folder (record.json, no marker) may be replaced with --force.
  const fs::path old = dir_ / "old";
  fs::create_directories(old);
  std::ofstream(old / "record.json") << "{}";
  std::ofstream(old / "map.ot") << "x";
  EXPECT_THAT(PrepareOutputFolder(old, RunFolderKind(), false).message(),
              HasSubstr("the results of an earlier avp run"));
  EXPECT_TRUE(PrepareOutputFolder(old, RunFolderKind(), true).ok());
  EXPECT_TRUE(fs::is_empty(old));
}

TEST_F(OutputFolderTest, ForceIsOfferedOnlyWhereItWorks) {
  // A folder of someone else's files: --force would not empty it, so the refusal does not offer
  // it.
  const fs::path d = dir_ / "data";
  fs::create_directories(d);
  std::ofstream(d / "notes.txt") << "mine";
  const Status s = CheckOutputFolder(d, RunFolderKind(), false);
  EXPECT_EQ(s.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(s.message(), HasSubstr("--force would not empty it): give another --out"));
  EXPECT_THAT(s.message(), Not(HasSubstr("or --force to replace it")));
  // A finished run: --force works there, and is offered.
  const fs::path run = dir_ / "run";
  ASSERT_TRUE(PrepareOutputFolder(run, RunFolderKind(), false).ok());
  ASSERT_TRUE(MarkComplete(run, RunFolderKind(), "avp run").ok());
  EXPECT_THAT(CheckOutputFolder(run, RunFolderKind(), false).message(),
              HasSubstr("or --force to replace it"));
  // A render into that run folder is refused, without offering --force, and with it.
  EXPECT_THAT(CheckOutputFolder(run, RenderFolderKind(), false).message(),
              HasSubstr("not an avp render folder (--force would not empty it)"));
  EXPECT_THAT(CheckOutputFolder(run, RenderFolderKind(), true).message(),
              HasSubstr("not an avp render folder, so --force does not empty it"));
}

TEST_F(OutputFolderTest, OneOutputFileRule) {
  const fs::path map = dir_ / "occl.avpmap";
  EXPECT_TRUE(CheckOutputFile(map, false).ok());  // missing: written
  std::ofstream(map) << "x";
  Status s = CheckOutputFile(map, false);
  EXPECT_EQ(s.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(s.message(), HasSubstr("'" + map.string() + "' already exists"));
  EXPECT_THAT(s.message(), HasSubstr("or --force to replace it"));
  EXPECT_TRUE(CheckOutputFile(map, true).ok());
  // A folder is named as one (not "unknown export format ''").
  s = CheckOutputFile(dir_, true);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("is a folder: give a file name"));
  // Never into another command's results, even with --force.
  const fs::path run = dir_ / "run";
  ASSERT_TRUE(PrepareOutputFolder(run, RunFolderKind(), false).ok());
  ASSERT_TRUE(MarkInProgress(run, RunFolderKind(), "avp run").ok());
  s = CheckOutputFile(run / "map.ot", true);
  EXPECT_EQ(s.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(s.message(), HasSubstr("the folder of an avp run (run)"));
  EXPECT_THAT(CheckOutputFile(run / "extra.ply", false).message(),
              HasSubstr("give an --out outside it"));
  EXPECT_EQ(CheckOutputFile("", false).code(), StatusCode::kInvalidArgument);
}

TEST_F(OutputFolderTest, AFileOrAPathThroughAFileIsNamed) {
  std::ofstream(dir_ / "file") << "x";
  Status s = PrepareOutputFolder(dir_ / "file", RunFolderKind(), true);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("is a file, not a folder"));
  s = PrepareOutputFolder(dir_ / "file" / "run", RunFolderKind(), false);
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr((dir_ / "file" / "run").string()));
  EXPECT_THAT(s.message(), Not(HasSubstr("Success")));
  EXPECT_FALSE(ReadFolderState(dir_ / "file").ok());
}

TEST_F(OutputFolderTest, AStateFileAvpDidNotWriteIsNotTrusted) {
  const fs::path d = dir_ / "run";
  fs::create_directories(d);
  std::ofstream(d / "avp-state.json") << "{\"colour\": \"red\"}";
  EXPECT_EQ(ReadFolderState(d).status().code(), StatusCode::kParseError);
  EXPECT_THAT(PrepareOutputFolder(d, RunFolderKind(), true).message(),
              HasSubstr("so --force does not empty it"));
}

}  // namespace
}  // namespace avp::experiment

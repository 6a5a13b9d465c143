// WriteFileAtomic: writes and replaces whole files, creates folders, leaves no temporary file,
// and names the path when it cannot write.
#include <algorithm>
#include <fstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/io/file.h>
#include <avp/io/file_kind.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::io {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

std::string Read(const std::filesystem::path& p) { return test::ReadWholeFile(p); }

class WriteFileAtomicTest : public test::TempDirTest {};

TEST_F(WriteFileAtomicTest, WritesReplacesAndCreatesFolders) {
  const std::filesystem::path p = dir_ / "a" / "b" / "out.bin";
  const std::string first("one\0two", 7);
  ASSERT_TRUE(WriteFileAtomic(p, first, "test file").ok());
  EXPECT_EQ(Read(p), first);
  ASSERT_TRUE(WriteFileAtomic(p, "short").ok());
  EXPECT_EQ(Read(p), "short");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "a" / "b" / "out.bin.tmp"));
}

TEST_F(WriteFileAtomicTest, FailureNamesThePathAndLeavesNothing) {
  const std::filesystem::path blocker = dir_ / "file";
  ASSERT_TRUE(WriteFileAtomic(blocker, "x").ok());
  const Status s = WriteFileAtomic(blocker / "inside.txt", "y", "plot");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr("plot"));
  EXPECT_THAT(s.message(), HasSubstr(blocker.string()));
  EXPECT_EQ(Read(blocker), "x");
}

class ReadFileBoundedTest : public test::TempDirTest {};

TEST_F(ReadFileBoundedTest, ReadsWholeFiles) {
  const std::string bytes(
      "a\0b\xff"
      "c",
      5);
  ASSERT_TRUE(WriteFileAtomic(dir_ / "f.bin", bytes).ok());
  const Result<std::string> r = ReadFileBounded(dir_ / "f.bin", "test file");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(*r, bytes);
  ASSERT_TRUE(WriteFileAtomic(dir_ / "empty", "").ok());
  EXPECT_EQ(ReadFileBounded(dir_ / "empty", "test file").value(), "");
}

TEST_F(ReadFileBoundedTest, MissingFolderAndTooLargeAreTold) {
  const Status missing = ReadFileBounded(dir_ / "nope.ot", "OctoMap file").status();
  EXPECT_EQ(missing.code(), StatusCode::kNotFound);
  EXPECT_THAT(missing.message(), HasSubstr("OctoMap file '"));
  EXPECT_THAT(missing.message(), HasSubstr("nope.ot' does not exist"));
  // A folder is not "missing": it exists and is the wrong kind of thing.
  const Status folder = ReadFileBounded(dir_, "map file").status();
  EXPECT_EQ(folder.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(folder.message(), HasSubstr("is a folder, not a map file"));
  ASSERT_TRUE(WriteFileAtomic(dir_ / "big", std::string(100, 'x')).ok());
  const Status big = ReadFileBounded(dir_ / "big", "scene file", 99).status();
  EXPECT_EQ(big.code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(big.message(), HasSubstr("of 100 bytes (100) exceeds the limit"));
  EXPECT_TRUE(ReadFileBounded(dir_ / "big", "scene file", 100).ok());
  {
    const ScopedLimit limit(MaxFileBytes(), 50);
    const Status s = ReadFileBounded(dir_ / "big", "scene file").status();
    EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
    EXPECT_THAT(s.message(), HasSubstr("max_file_bytes = 50; raise it with --limit"));
  }
  EXPECT_TRUE(ReadFileBounded(dir_ / "big", "scene file").ok());
}

// ---- Durable writes: no "Success" in errors, no temporary files left, step-by-step writers ------

std::vector<std::string> Names(const std::filesystem::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    names.push_back(e.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

TEST_F(WriteFileAtomicTest, ATargetThatIsAFolderIsToldAsSuch) {
  // Before, rename() failed and the clean-up reused its error code: "cannot move ...: Success".
  const std::filesystem::path folder = dir_ / "map.ot";
  std::filesystem::create_directories(folder / "inside");
  const Status s = WriteFileAtomic(folder, "bytes", "map file");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s.message(), HasSubstr("map file '" + folder.string() + "'"));
  EXPECT_THAT(s.message(), HasSubstr("is a folder"));
  EXPECT_THAT(s.message(), Not(HasSubstr("Success")));
  EXPECT_EQ(Names(dir_), std::vector<std::string>{"map.ot"});  // no temporary file left
}

TEST_F(WriteFileAtomicTest, LeavesOnlyTheFileAndKeepsTheOldOneOnFailure) {
  const std::filesystem::path p = dir_ / "record.json";
  ASSERT_TRUE(WriteFileAtomic(p, "old").ok());
  ASSERT_TRUE(WriteFileAtomic(p, "new").ok());
  EXPECT_EQ(Names(dir_), std::vector<std::string>{"record.json"});
  EXPECT_EQ(Read(p), "new");
  // An unwritable target (its parent is a file) fails naming the target and the reason.
  const Status s = WriteFileAtomic(p / "x.json", "y", "JSON file");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s.message(), HasSubstr((p / "x.json").string()));
  EXPECT_THAT(s.message(), Not(HasSubstr("Success")));
  EXPECT_EQ(Read(p), "new");
}

TEST(SyncFolderTest, FlushesAFolderAndNamesAMissingOne) {
  EXPECT_TRUE(SyncFolder(std::filesystem::temp_directory_path()).ok());
  const Status s = SyncFolder("/nonexistent-avp-folder");
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr("'/nonexistent-avp-folder'"));
  EXPECT_THAT(s.message(), HasSubstr("No such file or directory"));
}

class StepFileWriterTest : public test::TempDirTest {};

TEST_F(StepFileWriterTest, WritesEachStepAtOnce) {
  const std::filesystem::path p = dir_ / "metrics.csv";
  Result<StepFileWriter> w = StepFileWriter::Create(p, "metrics file");
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  ASSERT_TRUE(w->Write("view,f1\n").ok());
  EXPECT_EQ(Read(p), "view,f1\n");  // on the file before the writer is closed
  ASSERT_TRUE(w->Write("1,0.5\n").ok());
  EXPECT_EQ(Read(p), "view,f1\n1,0.5\n");
  EXPECT_TRUE(w->Close().ok());
  EXPECT_TRUE(w->Close().ok());
}

TEST_F(StepFileWriterTest, AFullDeviceStopsTheWriterNamingTheFile) {
  if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  Result<StepFileWriter> w = StepFileWriter::Create("/dev/full", "metrics file");
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  const Status s = w->Write("view,f1\n");
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr("metrics file '/dev/full'"));
  EXPECT_THAT(s.message(), HasSubstr("No space left on device"));
  // Every later write and the close give the first error.
  EXPECT_EQ(w->Write("1,0.5\n").message(), s.message());
  EXPECT_EQ(w->Close().message(), s.message());
}

TEST_F(StepFileWriterTest, UnwritablePathsAreNamed) {
  std::ofstream(dir_ / "file") << "x";
  Status s = StepFileWriter::Create(dir_ / "file" / "metrics.csv", "metrics file").status();
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr((dir_ / "file" / "metrics.csv").string()));
  EXPECT_THAT(s.message(), HasSubstr("Not a directory"));
  s = StepFileWriter::Create(dir_, "metrics file").status();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("it is a folder"));
}

class SameFileTest : public test::TempDirTest {};

TEST_F(SameFileTest, TellsEverySpellingOfTheSameFile) {
  const std::filesystem::path map = dir_ / "plant.avpmap";
  std::ofstream(map) << "map";
  EXPECT_TRUE(SameFile(map, map));
  EXPECT_TRUE(SameFile(map, dir_ / "." / "plant.avpmap"));
  EXPECT_TRUE(SameFile(map, dir_ / "sub" / ".." / "plant.avpmap"));
  std::filesystem::create_symlink(map, dir_ / "link.avpmap");
  EXPECT_TRUE(SameFile(map, dir_ / "link.avpmap"));
  std::filesystem::create_hard_link(map, dir_ / "hard.avpmap");
  EXPECT_TRUE(SameFile(map, dir_ / "hard.avpmap"));
  EXPECT_FALSE(SameFile(map, dir_ / "other.avpmap"));
  EXPECT_TRUE(SameFile(dir_ / "new.ply", dir_ / "." / "new.ply"));  // neither exists yet
  EXPECT_FALSE(SameFile(map, ""));

  const Status s = CheckOutputIsNotInput(dir_ / "link.avpmap", "export file", map, "map file");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("export file '" + (dir_ / "link.avpmap").string() +
                                     "' is the map file '" + map.string() + "'"));
  EXPECT_THAT(s.message(), HasSubstr("outputs never overwrite inputs"));
  EXPECT_TRUE(CheckOutputIsNotInput(dir_ / "out.ply", "export file", map, "map file").ok());
  EXPECT_TRUE(CheckOutputIsNotInput(dir_ / "out.ply", "export file", "", "map file").ok());
}

TEST(FileKindTest, FilesAreNamedByTheirFirstBytes) {
  using namespace std::string_literals;
  EXPECT_EQ(DescribeFileKind("\x89PNG\r\n\x1a\n\0\0\0\rIHDR"s), "a PNG image");
  EXPECT_EQ(DescribeFileKind("\xff\xd8\xff\xe0"), "a JPEG image");
  EXPECT_EQ(DescribeFileKind("\x89MCAP0\r\n"), "an MCAP recording");
  EXPECT_EQ(DescribeFileKind("SQLite format 3\0"s), "an SQLite database (a rosbag2 .db3?)");
  EXPECT_EQ(DescribeFileKind("# Octomap OcTree binary file\n"), "an OctoMap map (.bt / .ot)");
  EXPECT_EQ(DescribeFileKind("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), "a Wavefront OBJ mesh");
  EXPECT_EQ(DescribeFileKind("{\n  \"end\": \"done\",\n  \"end_reason\": \"\",\n  "
                             "\"planner\": \"avp-nbv\"\n}"),
            "an avp run record (record.json)");
  EXPECT_EQ(DescribeFileKind("{\"bench\": {}, \"format\": \"avp-bench 1\"}"),
            "an avp bench record (bench.json)");
  // Text it does not know is left to the reader (YAML, another program's JSON).
  EXPECT_EQ(DescribeFileKind("scenario: tomato-single-cluster\nseed: 3\n"), "");
  EXPECT_EQ(DescribeFileKind("{\"scenario\": \"tomato-single-cluster\"}"), "");
  EXPECT_EQ(DescribeFileKind(""), "");
}

}  // namespace
}  // namespace avp::io

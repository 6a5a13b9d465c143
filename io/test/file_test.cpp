// WriteFileAtomic: writes and replaces whole files, creates folders, leaves no temporary file,
// and names the path when it cannot write.
#include <fstream>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/io/file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::io {
namespace {

using ::testing::HasSubstr;

std::string Read(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

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

}  // namespace
}  // namespace avp::io

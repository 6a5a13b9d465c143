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

}  // namespace
}  // namespace avp::io

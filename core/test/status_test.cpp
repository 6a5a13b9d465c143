#include <algorithm>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/status.h>

namespace avp {
namespace {

using ::testing::ContainsRegex;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::StartsWith;

// ---- StatusCode and Status ----------------------------------------------------------------------

TEST(StatusTest, CodeNames) {
  EXPECT_EQ(ToString(StatusCode::kOk), "OK");
  EXPECT_EQ(ToString(StatusCode::kInvalidArgument), "InvalidArgument");
  EXPECT_EQ(ToString(StatusCode::kNotFound), "NotFound");
  EXPECT_EQ(ToString(StatusCode::kParseError), "ParseError");
  EXPECT_EQ(ToString(StatusCode::kIoError), "IoError");
  EXPECT_EQ(ToString(StatusCode::kUnreachable), "Unreachable");
  EXPECT_EQ(ToString(StatusCode::kFailedPrecondition), "FailedPrecondition");
  EXPECT_EQ(ToString(StatusCode::kOutOfRange), "OutOfRange");
  EXPECT_EQ(ToString(StatusCode::kInternal), "Internal");
  EXPECT_EQ(ToString(StatusCode::kDeadlineExceeded), "DeadlineExceeded");
  EXPECT_EQ(ToString(StatusCode::kUnavailable), "Unavailable");
  EXPECT_EQ(ToString(StatusCode::kCancelled), "Cancelled");
  EXPECT_EQ(ToString(StatusCode::kResourceExhausted), "ResourceExhausted");
  EXPECT_EQ(ToString(static_cast<StatusCode>(99)), "Unknown");
}

TEST(StatusTest, DefaultIsOk) {
  const Status ok;
  EXPECT_TRUE(ok.ok());
  EXPECT_EQ(ok.code(), StatusCode::kOk);
  EXPECT_EQ(ok.message(), "");
  EXPECT_EQ(ok.ToString(), "OK");
  EXPECT_EQ(ok, Status::Ok());
}

TEST(StatusTest, FactoriesSetCodeAndMessage) {
  const std::vector<std::pair<Status, StatusCode>> cases = {
      {InvalidArgumentError("m"), StatusCode::kInvalidArgument},
      {NotFoundError("m"), StatusCode::kNotFound},
      {ParseError("m"), StatusCode::kParseError},
      {IoError("m"), StatusCode::kIoError},
      {UnreachableError("m"), StatusCode::kUnreachable},
      {FailedPreconditionError("m"), StatusCode::kFailedPrecondition},
      {OutOfRangeError("m"), StatusCode::kOutOfRange},
      {InternalError("m"), StatusCode::kInternal},
      {DeadlineExceededError("m"), StatusCode::kDeadlineExceeded},
      {UnavailableError("m"), StatusCode::kUnavailable},
      {CancelledError("m"), StatusCode::kCancelled},
      {ResourceExhaustedError("m"), StatusCode::kResourceExhausted},
  };
  for (const auto& [status, code] : cases) {
    EXPECT_FALSE(status.ok());
    EXPECT_EQ(status.code(), code);
    EXPECT_EQ(status.message(), "m");
    EXPECT_EQ(status.ToString(), std::string(ToString(code)) + ": m");
  }
}

TEST(StatusTest, ToStringPrefixesTheCode) {
  EXPECT_EQ(InvalidArgumentError("width (-13) must be > 0").ToString(),
            "InvalidArgument: width (-13) must be > 0");
}

TEST(StatusTest, WithContextPrependsAndLeavesOkAlone) {
  const Status inner = NotFoundError("file 'a.yaml' does not exist");
  const Status outer = inner.WithContext("scene").WithContext("run");
  EXPECT_EQ(outer.code(), StatusCode::kNotFound);
  EXPECT_EQ(outer.message(), "run: scene: file 'a.yaml' does not exist");
  EXPECT_EQ(inner.message(), "file 'a.yaml' does not exist");  // a copy; the original is unchanged
  EXPECT_TRUE(Status::Ok().WithContext("scene").ok());
  EXPECT_EQ(Status::Ok().WithContext("scene").message(), "");
}

TEST(StatusTest, Equality) {
  EXPECT_EQ(IoError("x"), IoError("x"));
  EXPECT_NE(IoError("x"), IoError("y"));
  EXPECT_NE(IoError("x"), ParseError("x"));
  EXPECT_NE(IoError(""), Status::Ok());
}

// ---- Result ------------------------------------------------------------------------------------

TEST(ResultTest, HoldsAValue) {
  Result<int> r = 42;
  EXPECT_TRUE(r.ok());
  EXPECT_TRUE(static_cast<bool>(r));
  EXPECT_TRUE(r.status().ok());
  EXPECT_EQ(r.value(), 42);
  EXPECT_EQ(*r, 42);
  EXPECT_EQ(r.value_or(7), 42);
  r.value() = 43;
  EXPECT_EQ(*r, 43);
}

TEST(ResultTest, HoldsAnError) {
  const Result<int> r = NotFoundError("no scenario 'orchard'");
  EXPECT_FALSE(r.ok());
  EXPECT_FALSE(static_cast<bool>(r));
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(r.status().message(), "no scenario 'orchard'");
  EXPECT_EQ(r.value_or(7), 7);
}

TEST(ResultTest, ValueOnErrorThrowsWithTheMessage) {
  const Result<std::string> r = ParseError("bad number 'abc' at line 3");
  try {
    (void)r.value();
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_STREQ(e.what(), "ParseError: bad number 'abc' at line 3");
  }
  EXPECT_THROW((void)*r, Error);
  EXPECT_THROW((void)r->size(), Error);
  Result<std::string> mutable_r = IoError("disk full");
  EXPECT_THROW((void)mutable_r.value(), Error);
  EXPECT_THROW((void)std::move(mutable_r).value(), Error);
  // avp::Error is a std::runtime_error, so generic handlers catch it too.
  EXPECT_THROW((void)r.value(), std::runtime_error);
}

TEST(ResultTest, ArrowAndMoveOnlyValues) {
  Result<std::string> s = std::string("leaf");
  EXPECT_EQ(s->size(), 4u);
  s->append("lets");
  EXPECT_EQ(*s, "leaflets");

  Result<std::unique_ptr<int>> p = std::make_unique<int>(5);
  ASSERT_TRUE(p.ok());
  std::unique_ptr<int> owned = std::move(p).value();
  ASSERT_NE(owned, nullptr);
  EXPECT_EQ(*owned, 5);
}

// ---- AVP_RETURN_IF_ERROR / AVP_ASSIGN_OR_RETURN ------------------------------------------------

Status Step(bool fail, int* calls) {
  ++*calls;
  return fail ? InvalidArgumentError("step failed") : Status::Ok();
}

Status TwoSteps(bool fail_first, int* calls) {
  AVP_RETURN_IF_ERROR(Step(fail_first, calls));
  AVP_RETURN_IF_ERROR(Step(false, calls));
  return Status::Ok();
}

Result<int> StepsThenValue(bool fail) {
  int calls = 0;
  AVP_RETURN_IF_ERROR(Step(fail, &calls).WithContext("first"));
  return calls;
}

TEST(StatusMacroTest, ReturnIfErrorStopsAtTheFirstError) {
  int calls = 0;
  EXPECT_TRUE(TwoSteps(false, &calls).ok());
  EXPECT_EQ(calls, 2);
  calls = 0;
  const Status s = TwoSteps(true, &calls);
  EXPECT_EQ(s, InvalidArgumentError("step failed"));
  EXPECT_EQ(calls, 1);  // the second step never ran

  EXPECT_EQ(StepsThenValue(false).value(), 1);
  EXPECT_EQ(StepsThenValue(true).status(), InvalidArgumentError("first: step failed"));
}

Result<int> ParsePositive(int x) {
  if (x <= 0) return OutOfRangeError("x (" + std::to_string(x) + ") must be > 0");
  return x;
}

Result<int> SumOfTwo(int a, int b) {
  AVP_ASSIGN_OR_RETURN(const int x, ParsePositive(a));
  AVP_ASSIGN_OR_RETURN(const int y, ParsePositive(b));  // a second use in the same scope
  return x + y;
}

Status AssignToExisting(int a, int* out) {
  int value = -1;
  AVP_ASSIGN_OR_RETURN(value, ParsePositive(a));
  *out = value;
  return Status::Ok();
}

Result<std::unique_ptr<int>> MakeOwned(bool fail) {
  if (fail) return InternalError("no memory");
  return std::make_unique<int>(9);
}

Result<int> UnwrapOwned(bool fail) {
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<int> owned, MakeOwned(fail));
  return *owned;
}

TEST(StatusMacroTest, AssignOrReturn) {
  EXPECT_EQ(SumOfTwo(2, 3).value(), 5);
  EXPECT_EQ(SumOfTwo(-1, 3).status(), OutOfRangeError("x (-1) must be > 0"));
  EXPECT_EQ(SumOfTwo(2, 0).status(), OutOfRangeError("x (0) must be > 0"));

  int out = 0;
  EXPECT_TRUE(AssignToExisting(4, &out).ok());
  EXPECT_EQ(out, 4);
  out = 0;
  EXPECT_EQ(AssignToExisting(-4, &out).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(out, 0);  // untouched on error

  EXPECT_EQ(UnwrapOwned(false).value(), 9);
  EXPECT_EQ(UnwrapOwned(true).status(), InternalError("no memory"));
}

// ---- AVP_THROW_UNLESS --------------------------------------------------------------------------

std::string ThrowUnlessMessage(int width, double fx) {
  try {
    AVP_THROW_UNLESS(width > 0 && fx > 0, width, fx);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(ThrowUnlessTest, PassingConditionDoesNotThrow) {
  EXPECT_EQ(ThrowUnlessMessage(640, 615.0), "");
  EXPECT_NO_THROW(AVP_THROW_UNLESS(true));
}

TEST(ThrowUnlessTest, MessageNamesTheConditionAndEachValue) {
  const std::string message = ThrowUnlessMessage(-13, 2.5);
  EXPECT_THAT(message,
              StartsWith("requirement failed: width > 0 && fx > 0 (width = -13, fx = 2.5)"));
  EXPECT_THAT(message, HasSubstr(" at "));
  EXPECT_THAT(message, HasSubstr("status_test.cpp:"));
}

TEST(ThrowUnlessTest, WithoutValues) {
  try {
    AVP_THROW_UNLESS(1 + 1 == 3);
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), StartsWith("requirement failed: 1 + 1 == 3 at "));
  }
}

TEST(ThrowUnlessTest, ExpressionsWithCommasInsideParentheses) {
  const int a = 5;
  const int b = 3;
  try {
    AVP_THROW_UNLESS(a < b, std::max(a, b), a, std::min({a, b, 1}));
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("(std::max(a, b) = 5, a = 5, std::min({a, b, 1}) = 1)"));
  }
}

TEST(ThrowUnlessTest, FormatsStringsAndEigenValues) {
  const std::string name = "orchard";
  const Eigen::Vector3d p(1, 2.5, -3);
  try {
    AVP_THROW_UNLESS(name.empty(), name, p.transpose());
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("name = orchard"));
    EXPECT_THAT(e.what(), ContainsRegex("p\\.transpose\\(\\) = +1 +2\\.5 +-3\\)"));
  }
}

TEST(ThrowUnlessTest, SplitMacroArgNamesSplitsOnlyTopLevelCommas) {
  EXPECT_THAT(internal::SplitMacroArgNames("a, f(b, c), d"), ElementsAre("a", "f(b, c)", "d"));
  EXPECT_THAT(internal::SplitMacroArgNames("v[i, j], T{1, 2}"), ElementsAre("v[i, j]", "T{1, 2}"));
  EXPECT_THAT(internal::SplitMacroArgNames("x"), ElementsAre("x"));
  EXPECT_TRUE(internal::SplitMacroArgNames("").empty());
}

}  // namespace
}  // namespace avp

#include <cerrno>
#include <cstdlib>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <avp/report/progress.h>

namespace avp::report {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

/// Sets (or unsets, nullopt) an environment variable for the test's lifetime.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, std::optional<std::string> value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    if (value) {
      ::setenv(name, value->c_str(), 1);
    } else {
      ::unsetenv(name);
    }
  }
  ~ScopedEnv() {
    if (old_) {
      ::setenv(name_, old_->c_str(), 1);
    } else {
      ::unsetenv(name_);
    }
  }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  const char* name_;
  std::optional<std::string> old_;
};

TEST(ProgressFormatTest, DurationsRatesAndTimes) {
  EXPECT_EQ(FormatProgressDuration(0.0), "0 s");
  EXPECT_EQ(FormatProgressDuration(52.4), "52 s");
  EXPECT_EQ(FormatProgressDuration(468.0), "8 min");
  EXPECT_EQ(FormatProgressDuration(5400.0), "1.5 h");
  EXPECT_EQ(FormatProgressRate(0, 10.0), "");
  EXPECT_EQ(FormatProgressRate(5, 0.0), "");
  EXPECT_EQ(FormatProgressRate(5, 2.0), "2.5/s");
  EXPECT_EQ(FormatProgressRate(12, 232.0), "3.1/min");
  EXPECT_EQ(FormatProgressRate(1, 7200.0), "0.5/h");
  // One run keeps the unit of its first rate, as it slows down or speeds up.
  RateUnit unit = RateUnit::kAuto;
  EXPECT_EQ(FormatProgressRate(5, 2.0, &unit), "2.5/s");
  EXPECT_EQ(unit, RateUnit::kPerSecond);
  EXPECT_EQ(FormatProgressRate(6, 14.0, &unit), "0.43/s");
  EXPECT_EQ(FormatProgressTimes(6, 8, 14.0, &unit), "0.43/s, 14 s elapsed, ~5 s left");
  RateUnit slow = RateUnit::kAuto;
  EXPECT_EQ(FormatProgressRate(1, 30.0, &slow), "2.0/min");
  EXPECT_EQ(FormatProgressRate(30, 10.0, &slow), "180.0/min");
  EXPECT_EQ(FormatProgressCounts(12, 120, 232.0),
            "12/120 (10 %) 3.1/min, 4 min elapsed, ~35 min left");
  EXPECT_EQ(FormatProgressCounts(0, 4, 0.0), "0/4 (0 %) 0 s elapsed");
  EXPECT_EQ(FormatProgressCounts(4, 4, 8.0), "4/4 (100 %) 30.0/min, 8 s elapsed");
}

/// A fake clock the test advances, and the text written.
struct Capture {
  double now = 100.0;
  std::string text;
  ProgressOptions Options(std::string what, size_t total, ProgressStyle style, bool color) {
    ProgressOptions o;
    o.what = std::move(what);
    o.total = total;
    o.style = style;
    o.color = color;
    o.clock = [this] { return now; };
    o.write = [this](std::string_view t) { text += t; };
    return o;
  }
};

TEST(ProgressTest, LinesAreGolden) {
  Capture c;
  {
    Progress p(c.Options("episodes", 4, ProgressStyle::kLines, /*color=*/true));
    c.now += 20.0;
    p.Done("tomato-full-occlusion avp-nbv seed 3 ok");
    c.now += 40.0;
    p.Done("tomato-full-occlusion random seed 3 ok");
    c.now += 60.0;
    p.Done("apple-espalier avp-nbv seed 1 failed");
    c.now += 120.0;
    p.Done();
  }
  EXPECT_EQ(c.text,
            "episodes 1/4 (25 %) 3.0/min, 20 s elapsed, ~60 s left: tomato-full-occlusion avp-nbv "
            "seed 3 ok\n"
            "episodes 2/4 (50 %) 2.0/min, 60 s elapsed, ~60 s left: tomato-full-occlusion random "
            "seed 3 ok\n"
            "episodes 3/4 (75 %) 1.5/min, 2 min elapsed, ~40 s left: apple-espalier avp-nbv seed 1 "
            "failed\n"
            "episodes 4/4 (100 %) 1.0/min, 4 min elapsed\n");
}

TEST(ProgressTest, OffWritesNothingButCounts) {
  Capture c;
  Progress p(c.Options("episodes", 2, ProgressStyle::kOff, true));
  p.Done("a");
  p.Done("b");
  p.Finish();
  EXPECT_EQ(c.text, "");
  EXPECT_EQ(p.done(), 2u);
}

TEST(ProgressTest, BarRedrawsInPlaceRateLimitedAndEndsTheLine) {
  Capture c;
  {
    ProgressOptions o = c.Options("views", 4, ProgressStyle::kBar, /*color=*/false);
    o.bar_width = 8;
    o.redraw_s = 1.0;
    Progress p(std::move(o));
    c.now += 2.0;
    p.Done();  // drawn (a second since the first draw)
    c.now += 0.1;
    p.Done();  // skipped: 0.1 s since the last redraw
    c.now += 2.0;
    p.Done();  // drawn
    c.now += 0.1;
    p.Done();  // the last job: always drawn
  }
  EXPECT_EQ(c.text,
            "\rviews [--------] 0/4 (0 %) 0 s elapsed"
            "\rviews [##------] 1/4 (25 %) 30.0/min, 2 s elapsed, ~6 s left"
            "\rviews [######--] 3/4 (75 %) 43.9/min, 4 s elapsed, ~1 s left"
            // The bar keeps its first rate's unit as the rate passes one a second.
            "\rviews [########] 4/4 (100 %) 57.1/min, 4 s elapsed          \n");
}

TEST(ProgressTest, ThreadSafeLinesOnePerJob) {
  Capture c;
  constexpr size_t kJobs = 200;
  {
    Progress p(c.Options("jobs", kJobs, ProgressStyle::kLines, false));
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t) {
      threads.emplace_back([&p] {
        for (size_t i = 0; i < kJobs / 4; ++i) p.Done("x");
      });
    }
    for (std::thread& t : threads) t.join();
  }
  size_t lines = 0;
  for (char ch : c.text) lines += ch == '\n' ? 1 : 0;
  EXPECT_EQ(lines, kJobs);
  EXPECT_THAT(c.text, HasSubstr("jobs 200/200 (100 %)"));
  EXPECT_THAT(c.text, HasSubstr("jobs 1/200 (0 %)"));
}

TEST(ProgressEnvironmentTest, CiAndNoColorAndDumbTerminal) {
  {
    ScopedEnv ci("CI", std::nullopt), nc("NO_COLOR", std::nullopt), term("TERM", "xterm");
    const ProgressEnvironment e = DetectProgressEnvironment(-1);
    EXPECT_FALSE(e.terminal);
    EXPECT_FALSE(e.ci);
    EXPECT_TRUE(e.color);
    EXPECT_EQ(ProgressStyleFor(e), ProgressStyle::kLines);
  }
  {
    ScopedEnv ci("CI", "false"), nc("NO_COLOR", ""), term("TERM", "dumb");
    const ProgressEnvironment e = DetectProgressEnvironment(-1);
    EXPECT_FALSE(e.ci);
    EXPECT_FALSE(e.color);
  }
  {
    ScopedEnv ci("CI", "1"), nc("NO_COLOR", "1"), term("TERM", "xterm");
    const ProgressEnvironment e = DetectProgressEnvironment(-1);
    EXPECT_TRUE(e.ci);
    EXPECT_FALSE(e.color);
  }
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  EXPECT_FALSE(DetectProgressEnvironment(fds[1]).terminal);
  ::close(fds[0]);
  ::close(fds[1]);
}

/// Runs three jobs through ProgressOn on a pseudo-terminal (raw mode: bytes as written) and
/// returns what the terminal received.
std::string OnPseudoTerminal() {
  int master = -1, slave = -1;
  EXPECT_EQ(::openpty(&master, &slave, nullptr, nullptr, nullptr), 0) << errno;
  if (master < 0) return {};
  termios raw{};
  EXPECT_EQ(::tcgetattr(slave, &raw), 0);
  ::cfmakeraw(&raw);
  EXPECT_EQ(::tcsetattr(slave, TCSANOW, &raw), 0);
  std::FILE* out = ::fdopen(slave, "w");
  EXPECT_NE(out, nullptr);
  {
    ProgressOptions o = ProgressOn(out, "pty-test", 3);
    double now = 0.0;
    o.clock = [&now] { return now; };
    o.redraw_s = 0.0;
    Progress p(std::move(o));
    for (int i = 0; i < 3; ++i) {
      now += 1.0;
      p.Done("job ok");
    }
  }
  std::fclose(out);
  std::string text;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(master, buf, sizeof buf);
    if (n <= 0) break;  // EIO once the slave is closed and everything is read
    text.append(buf, static_cast<size_t>(n));
  }
  ::close(master);
  return text;
}

TEST(ProgressPseudoTerminalTest, BarWithColour) {
  ScopedEnv ci("CI", std::nullopt), nc("NO_COLOR", std::nullopt), term("TERM", "xterm");
  const std::string text = OnPseudoTerminal();
  EXPECT_THAT(text, HasSubstr("\rpty-test ["));
  EXPECT_THAT(text, HasSubstr("] 3/3 (100 %) 1.0/s, 3 s elapsed"));
  EXPECT_THAT(text, HasSubstr("\x1b[32m"));
  EXPECT_THAT(text, Not(HasSubstr("job ok")));  // labels are for the lines
  EXPECT_EQ(text.back(), '\n');
}

TEST(ProgressPseudoTerminalTest, NoColorMeansNoEscapes) {
  ScopedEnv ci("CI", std::nullopt), nc("NO_COLOR", "1"), term("TERM", "xterm");
  const std::string text = OnPseudoTerminal();
  EXPECT_THAT(text, HasSubstr("\rpty-test [########################] 3/3 (100 %)"));
  EXPECT_EQ(text.find('\x1b'), std::string::npos) << text;
}

TEST(ProgressPseudoTerminalTest, CiGivesPlainLinesEvenOnATerminal) {
  ScopedEnv ci("CI", "true"), nc("NO_COLOR", std::nullopt), term("TERM", "xterm");
  const std::string text = OnPseudoTerminal();
  EXPECT_EQ(text,
            "pty-test 1/3 (33 %) 1.0/s, 1 s elapsed, ~2 s left: job ok\n"
            "pty-test 2/3 (66 %) 1.0/s, 2 s elapsed, ~1 s left: job ok\n"
            "pty-test 3/3 (100 %) 1.0/s, 3 s elapsed: job ok\n");
}

}  // namespace
}  // namespace avp::report

#pragma once

// Progress of a command that runs longer than a few seconds (avp bench, run, map build): on a
// terminal a bar redrawn in place (count, rate, elapsed, time left; colour unless NO_COLOR is set
// or TERM is "dumb"), otherwise (a log file, a pipe, CI) one plain line per finished job:
//
//   episodes 12/120 (10 %) 3.1/min, 52 s elapsed, ~8 min left: tomato avp-nbv seed 3 ok
//
// The lines' format is stable (no carriage returns, no escape codes) so logs can be read by
// scripts. Thread-safe: jobs may finish on worker threads.

#include <cstddef>
#include <cstdio>
#include <functional>
#include <mutex>
#include <string>
#include <string_view>

namespace avp::report {

enum class ProgressStyle {
  kOff,    ///< nothing
  kLines,  ///< one plain line per finished job
  kBar,    ///< a bar redrawn in place ("\r"), a few times a second at most
};

/// What the environment says about progress output to a file descriptor.
struct ProgressEnvironment {
  bool terminal = false;  ///< isatty(fd)
  bool ci = false;        ///< CI is set, not empty, not "false" and not "0"
  bool color = false;     ///< NO_COLOR unset or empty (no-color.org), TERM not "dumb"
};

/// Reads isatty(fd) and the environment variables CI, NO_COLOR and TERM.
ProgressEnvironment DetectProgressEnvironment(int fd);

/// A bar on a terminal not under CI, else lines.
ProgressStyle ProgressStyleFor(const ProgressEnvironment& environment);

/// A duration for people: "52 s" (under 90 s), "8 min" (under 90 min), "1.5 h".
std::string FormatProgressDuration(double seconds);

/// The unit of a progress rate: chosen by the first rate shown, then kept, so that one run's
/// lines do not switch from "/s" to "/min" as it slows down.
enum class RateUnit { kAuto, kPerSecond, kPerMinute, kPerHour };

/// `done` jobs in `elapsed_s` as a rate: "2.5/s" (at least one a second), "3.1/min", "0.5/h";
/// empty when nothing is done or no time has passed. With `unit`: an automatic one is set by this
/// rate, a set one is used ("0.42/s"); without, each rate picks its own.
std::string FormatProgressRate(size_t done, double elapsed_s, RateUnit* unit = nullptr);

/// "3.1/min, 52 s elapsed, ~8 min left" (no rate and no time left before the first job, no time
/// left once done == total); `unit` as FormatProgressRate.
std::string FormatProgressTimes(size_t done, size_t total, double elapsed_s,
                                RateUnit* unit = nullptr);

/// "12/120 (10 %) 3.1/min, 52 s elapsed, ~8 min left"; total 0 (not known): "12 3.1/min, 52 s
/// elapsed".
std::string FormatProgressCounts(size_t done, size_t total, double elapsed_s,
                                 RateUnit* unit = nullptr);

struct ProgressOptions {
  /// What is counted ("episodes", "ground truth"), the start of every line.
  std::string what;
  size_t total = 0;
  ProgressStyle style = ProgressStyle::kLines;
  /// ANSI colour in the bar (never in lines).
  bool color = false;
  /// Where the text goes (written as is; the bar's text holds "\r"). Empty = stderr, flushed.
  std::function<void(std::string_view)> write;
  /// Seconds on a monotonic clock. Empty = std::chrono::steady_clock.
  std::function<double()> clock;
  /// The bar is redrawn at most this often (and always for the last job).
  double redraw_s = 0.25;
  /// Characters of the bar itself.
  int bar_width = 24;
};

/// Options for progress on `stream` (stderr by default): the style and colour from
/// DetectProgressEnvironment(fileno(stream)); ProgressStyle::kOff unless `enabled`.
ProgressOptions ProgressOn(std::FILE* stream, std::string what, size_t total, bool enabled = true);

class Progress {
 public:
  /// On a bar, draws "0/total" at once.
  explicit Progress(ProgressOptions options);
  /// Finish().
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// One more job finished; `label` says which and how it ended (shown in lines).
  void Done(std::string_view label = {});
  /// Ends the bar's line (a newline after the last redraw); lines need nothing. Idempotent.
  void Finish();

  size_t done() const;

 private:
  double Now() const;
  void Write(std::string_view text);
  void DrawBar(double elapsed_s);

  ProgressOptions options_;
  double start_s_ = 0.0;
  mutable std::mutex mu_;
  size_t done_ = 0;
  double last_draw_s_ = -1.0;
  size_t last_width_ = 0;
  size_t drawn_done_ = 0;
  bool line_open_ = false;
  RateUnit unit_ = RateUnit::kAuto;
};

}  // namespace avp::report

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>

#include <fmt/format.h>
#include <unistd.h>

#include <avp/report/progress.h>

namespace avp::report {

namespace {

std::string_view Env(const char* name) {
  const char* v = std::getenv(name);
  return v == nullptr ? std::string_view() : std::string_view(v);
}

}  // namespace

ProgressEnvironment DetectProgressEnvironment(int fd) {
  ProgressEnvironment e;
  e.terminal = fd >= 0 && ::isatty(fd) == 1;
  const std::string_view ci = Env("CI");
  e.ci = !ci.empty() && ci != "false" && ci != "0";
  e.color = Env("NO_COLOR").empty() && Env("TERM") != "dumb";
  return e;
}

ProgressStyle ProgressStyleFor(const ProgressEnvironment& environment) {
  return environment.terminal && !environment.ci ? ProgressStyle::kBar : ProgressStyle::kLines;
}

std::string FormatProgressDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0.0) seconds = 0.0;
  if (seconds < 89.5) return fmt::format("{:.0f} s", seconds);
  if (seconds < 89.5 * 60.0) return fmt::format("{:.0f} min", seconds / 60.0);
  return fmt::format("{:.1f} h", seconds / 3600.0);
}

std::string FormatProgressRate(size_t done, double elapsed_s, RateUnit* unit) {
  if (done == 0 || !(elapsed_s > 0.0) || !std::isfinite(elapsed_s)) return {};
  const double per_s = static_cast<double>(done) / elapsed_s;
  RateUnit chosen = unit != nullptr ? *unit : RateUnit::kAuto;
  if (chosen == RateUnit::kAuto) {
    chosen = per_s >= 0.95          ? RateUnit::kPerSecond
             : per_s * 60.0 >= 0.95 ? RateUnit::kPerMinute
                                    : RateUnit::kPerHour;
    if (unit != nullptr) *unit = chosen;
  }
  const double value = chosen == RateUnit::kPerSecond   ? per_s
                       : chosen == RateUnit::kPerMinute ? per_s * 60.0
                                                        : per_s * 3600.0;
  const char* name = chosen == RateUnit::kPerSecond   ? "s"
                     : chosen == RateUnit::kPerMinute ? "min"
                                                      : "h";
  // Two significant digits below 1 in a kept unit ("0.42/s"), one decimal otherwise.
  return value >= 0.95 ? fmt::format("{:.1f}/{}", value, name)
                       : fmt::format("{:.2g}/{}", value, name);
}

std::string FormatProgressTimes(size_t done, size_t total, double elapsed_s, RateUnit* unit) {
  std::string out;
  const std::string rate = FormatProgressRate(done, elapsed_s, unit);
  if (!rate.empty()) out = rate + ", ";
  out += FormatProgressDuration(elapsed_s) + " elapsed";
  if (!rate.empty() && done < total) {
    const double left = elapsed_s / static_cast<double>(done) * static_cast<double>(total - done);
    out += ", ~" + FormatProgressDuration(left) + " left";
  }
  return out;
}

std::string FormatProgressCounts(size_t done, size_t total, double elapsed_s, RateUnit* unit) {
  // An unknown total (a bag read as it streams): the count, the rate and the time so far.
  if (total == 0)
    return fmt::format("{} {}", done, FormatProgressTimes(done, done, elapsed_s, unit));
  const size_t percent = total == 0 ? 100 : std::min<size_t>(done, total) * 100 / total;
  return fmt::format("{}/{} ({} %) {}", done, total, percent,
                     FormatProgressTimes(done, total, elapsed_s, unit));
}

ProgressOptions ProgressOn(std::FILE* stream, std::string what, size_t total, bool enabled) {
  ProgressOptions o;
  o.what = std::move(what);
  o.total = total;
  const ProgressEnvironment e = DetectProgressEnvironment(::fileno(stream));
  o.style = !enabled ? ProgressStyle::kOff : ProgressStyleFor(e);
  o.color = e.color;
  o.write = [stream](std::string_view text) {
    std::fwrite(text.data(), 1, text.size(), stream);
    std::fflush(stream);
  };
  return o;
}

Progress::Progress(ProgressOptions options) : options_(std::move(options)) {
  if (!options_.clock) {
    options_.clock = [] {
      return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
          .count();
    };
  }
  if (!options_.write) {
    options_.write = [](std::string_view text) {
      std::fwrite(text.data(), 1, text.size(), stderr);
      std::fflush(stderr);
    };
  }
  options_.bar_width = std::max(options_.bar_width, 1);
  start_s_ = Now();
  if (options_.style == ProgressStyle::kBar) {
    const std::lock_guard<std::mutex> lock(mu_);
    DrawBar(0.0);
  }
}

Progress::~Progress() { Finish(); }

double Progress::Now() const { return options_.clock(); }

void Progress::Write(std::string_view text) { options_.write(text); }

size_t Progress::done() const {
  const std::lock_guard<std::mutex> lock(mu_);
  return done_;
}

void Progress::Done(std::string_view label) {
  const std::lock_guard<std::mutex> lock(mu_);
  ++done_;
  if (options_.style == ProgressStyle::kOff) return;
  const double now = Now();
  const double elapsed = now - start_s_;
  if (options_.style == ProgressStyle::kLines) {
    std::string line =
        options_.what + " " + FormatProgressCounts(done_, options_.total, elapsed, &unit_);
    if (!label.empty()) line += fmt::format(": {}", label);
    line += "\n";
    Write(line);
    return;
  }
  if (done_ >= options_.total || last_draw_s_ < 0.0 || now - last_draw_s_ >= options_.redraw_s) {
    DrawBar(elapsed);
  }
}

void Progress::DrawBar(double elapsed_s) {
  const size_t total = options_.total;
  const size_t width = static_cast<size_t>(options_.bar_width);
  const size_t filled =
      total == 0 ? width : std::min(done_, total) * width / std::max<size_t>(total, 1);
  const std::string counts = FormatProgressCounts(done_, total, elapsed_s, &unit_);
  const std::string full(filled, '#'), empty(width - filled, '-');
  std::string text = "\r" + options_.what + " [";
  if (options_.color) {
    text += "\x1b[32m" + full + "\x1b[2;37m" + empty + "\x1b[0m";
  } else {
    text += full + empty;
  }
  text += "] " + counts;
  // What is visible (no "\r", no escapes): pad over what the previous redraw left.
  const size_t visible = options_.what.size() + 2 + width + 2 + counts.size();
  if (visible < last_width_) text += std::string(last_width_ - visible, ' ');
  last_width_ = visible;
  line_open_ = true;
  drawn_done_ = done_;
  last_draw_s_ = Now();
  Write(text);
}

void Progress::Finish() {
  const std::lock_guard<std::mutex> lock(mu_);
  if (options_.style != ProgressStyle::kBar || !line_open_) return;
  // The last job's state is on screen unless a redraw was skipped.
  if (drawn_done_ != done_) DrawBar(Now() - start_s_);
  Write("\n");
  line_open_ = false;
}

}  // namespace avp::report

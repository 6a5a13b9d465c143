#include "bench_report.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string_view>
#include <thread>
#include <utility>

#include <benchmark/benchmark.h>
#include <fcntl.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

namespace avp::bench {
namespace {

using Json = nlohmann::ordered_json;  // keeps the record fields in schema order

Json Number(double v) { return std::isfinite(v) ? Json(v) : Json(); }

template <typename T>
Json Optional(const std::optional<T>& v) {
  if (!v) return Json();
  if constexpr (std::is_same_v<T, double>) {
    return Number(*v);
  } else {
    return Json(*v);
  }
}

/// The run name without the "/iterations:N" and "/real_time" parts that Iterations() and
/// UseRealTime() append (before any aggregate suffix such as "_mean").
std::string BaseName(std::string name) {
  static const std::string kRealTime = "/real_time";
  size_t at = name.find(kRealTime);
  if (at != std::string::npos) name.erase(at, kRealTime.size());
  static const std::string kIterations = "/iterations:";
  at = name.find(kIterations);
  if (at != std::string::npos) {
    size_t end = at + kIterations.size();
    while (end < name.size() && name[end] >= '0' && name[end] <= '9') ++end;
    name.erase(at, end - at);
  }
  return name;
}

/// The console reporter, plus a copy of every run for the records.
class CollectingReporter : public benchmark::ConsoleReporter {
 public:
  explicit CollectingReporter(OutputOptions options) : ConsoleReporter(options) {}
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& run : runs) runs_.push_back(run);
    ConsoleReporter::ReportRuns(runs);
  }
  const std::vector<Run>& runs() const { return runs_; }

 private:
  std::vector<Run> runs_;
};

}  // namespace

std::optional<bool> EvaluateTarget(const std::string& target, double value,
                                   std::optional<double> ratio) {
  std::string t = target;
  bool on_ratio = false;
  if (!t.empty() && (t.back() == 'x' || t.back() == 'X')) {
    on_ratio = true;
    t.pop_back();
  }
  std::string_view op;
  for (const std::string_view candidate : {">=", "<=", ">", "<", "=="}) {
    if (std::string_view(t).substr(0, candidate.size()) == candidate) {
      op = candidate;
      break;
    }
  }
  if (op.empty()) return std::nullopt;
  const std::string number = t.substr(op.size());
  char* end = nullptr;
  const double bound = std::strtod(number.c_str(), &end);
  if (number.empty() || end == nullptr || *end != '\0') return std::nullopt;
  if (on_ratio && !ratio) return std::nullopt;
  const double x = on_ratio ? *ratio : value;
  if (!std::isfinite(x)) return false;
  if (op == ">=") return x >= bound;
  if (op == "<=") return x <= bound;
  if (op == ">") return x > bound;
  if (op == "<") return x < bound;
  return x == bound;
}

BenchRecord MakeRecord(std::string name, double value, std::string unit,
                       std::optional<std::string> reference, std::optional<double> reference_value,
                       std::optional<double> ratio, std::optional<std::string> target) {
  BenchRecord r;
  r.name = std::move(name);
  r.value = value;
  r.unit = std::move(unit);
  r.reference = std::move(reference);
  r.reference_value = reference_value;
  r.ratio = ratio;
  r.target = std::move(target);
  if (r.target) r.meets_target = EvaluateTarget(*r.target, r.value, r.ratio);
  return r;
}

bool WriteBenchRecords(const std::string& path, const std::vector<BenchRecord>& records) {
  Json list = Json::array();
  for (const BenchRecord& r : records) {
    list.push_back({{"name", r.name},
                    {"value", Number(r.value)},
                    {"unit", r.unit},
                    {"reference", Optional(r.reference)},
                    {"reference_value", Optional(r.reference_value)},
                    {"ratio", Optional(r.ratio)},
                    {"target", Optional(r.target)},
                    {"meets_target", Optional(r.meets_target)}});
  }
  // Atomic and durable (a temporary file, every write checked, fsync, rename): a killed or
  // disk-full benchmark never leaves a truncated record file. (avp_bench_support does not see
  // avp::io, whose io::WriteFileAtomic does the same.)
  const std::string text = list.dump(1, ' ', false, Json::error_handler_t::replace) + "\n";
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const auto fail = [&](const char* step) {
    const int e = errno;
    std::fprintf(stderr, "cannot write benchmark records to '%s' (%s '%s'): %s\n", path.c_str(),
                 step, tmp.c_str(), e != 0 ? std::strerror(e) : "unknown error");
    std::remove(tmp.c_str());
    return false;
  };
  errno = 0;
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) return fail("creating");
  std::string_view rest = text;
  while (!rest.empty()) {
    const ssize_t n = ::write(fd, rest.data(), rest.size());
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      ::close(fd);
      return fail("writing");
    }
    rest.remove_prefix(static_cast<size_t>(n));
  }
  if (::fsync(fd) != 0 && errno != EINVAL) {
    ::close(fd);
    return fail("flushing");
  }
  if (::close(fd) != 0) return fail("closing");
  if (std::rename(tmp.c_str(), path.c_str()) != 0) return fail("renaming");
  return true;
}

std::string TakeJsonPathArgument(int& argc, char** argv) {
  static constexpr char kFlag[] = "--avp_json";
  std::string path;
  int out = 1;
  for (int i = 1; i < argc; ++i) {
    const char* a = argv[i];
    if (std::strncmp(a, kFlag, sizeof(kFlag) - 1) == 0 && a[sizeof(kFlag) - 1] == '=') {
      path = a + sizeof(kFlag);
    } else if (std::strcmp(a, kFlag) == 0 && i + 1 < argc) {
      path = argv[++i];
    } else {
      argv[out++] = argv[i];
    }
  }
  argc = out;
  argv[argc] = nullptr;
  return path;
}

int GoogleBenchmarkMain(int argc, char** argv, const std::vector<GoogleBenchmarkTarget>& targets) {
  const std::string json_path = TakeJsonPathArgument(argc, argv);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  CollectingReporter reporter(isatty(STDOUT_FILENO) != 0 ? benchmark::ConsoleReporter::OO_Defaults
                                                         : benchmark::ConsoleReporter::OO_Tabular);
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  if (json_path.empty()) return 0;

  std::vector<BenchRecord> records;
  for (const auto& run : reporter.runs()) {
    if (run.error_occurred) continue;
    const std::string name = run.benchmark_name();
    const std::string unit = benchmark::GetTimeUnitString(run.time_unit);
    const std::string base = BaseName(name);
    std::optional<std::string> target;
    for (const GoogleBenchmarkTarget& t : targets) {
      // Aggregates (mean/median/stddev of --benchmark_repetitions) carry the target only on
      // the mean and median.
      if (base == t.benchmark || base == t.benchmark + "_mean" || base == t.benchmark + "_median")
        target = t.target;
    }
    records.push_back(MakeRecord(base, run.GetAdjustedRealTime(), unit, std::nullopt, std::nullopt,
                                 std::nullopt, target));
    records.push_back(MakeRecord(base + "/cpu_time", run.GetAdjustedCPUTime(), unit));
    for (const auto& [counter, value] : run.counters) {
      records.push_back(MakeRecord(base + "/" + counter, value.value, ""));
    }
  }
  return WriteBenchRecords(json_path, records) ? 0 : 1;
}

double Percentile(std::vector<double> values, double q) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const size_t i =
      std::min(values.size() - 1, static_cast<size_t>(q * static_cast<double>(values.size())));
  return values[i];
}

ClientLoad RunClientLoad(int clients, double seconds,
                         const std::function<ClientCall(int client)>& make_client) {
  std::mutex mu;
  std::vector<double> ms;
  ClientLoad load;
  std::atomic<uint64_t> errors{0};
  std::atomic<bool> stop{false};
  std::vector<std::thread> workers;
  const auto t0 = std::chrono::steady_clock::now();
  for (int c = 0; c < clients; ++c) {
    workers.emplace_back([&, c] {
      const ClientCall call = make_client(c);
      std::vector<double> mine;
      std::string error;
      while (!stop.load()) {
        const auto a = std::chrono::steady_clock::now();
        const bool ok = call(error);
        const double dt =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count();
        if (ok) {
          mine.push_back(dt);
        } else if (errors.fetch_add(1) == 0) {
          const std::lock_guard<std::mutex> lock(mu);
          load.first_error = error;
        }
      }
      const std::lock_guard<std::mutex> lock(mu);
      ms.insert(ms.end(), mine.begin(), mine.end());
    });
  }
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  stop = true;
  for (std::thread& w : workers) w.join();
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  load.requests_per_s = static_cast<double>(ms.size()) / elapsed;
  load.p50_ms = Percentile(ms, 0.50);
  load.p99_ms = Percentile(ms, 0.99);
  load.errors = errors.load();
  return load;
}

std::vector<BenchRecord> ClientLoadRecords(const std::string& prefix, const ClientLoad& load) {
  return {MakeRecord(prefix + "/requests_per_s", load.requests_per_s, "1/s"),
          MakeRecord(prefix + "/p50", load.p50_ms, "ms"),
          MakeRecord(prefix + "/p99", load.p99_ms, "ms"),
          MakeRecord(prefix + "/errors", static_cast<double>(load.errors), "", std::nullopt,
                     std::nullopt, std::nullopt, "<1")};
}

}  // namespace avp::bench

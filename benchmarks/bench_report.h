#pragma once

// Machine-readable benchmark results: every benchmark program writes ONE JSON file holding a list
// of records (see docs/benchmarks.md):
//
//   {"name": "...", "value": 12.3, "unit": "ms", "reference": "octomap-1.9.7-debian",
//    "reference_value": 245.0, "ratio": 19.9, "target": ">=20x", "meets_target": false}
//
// `reference`, `reference_value`, `ratio`, `target` and `meets_target` are null where they do
// not apply. `ratio` is the improvement factor over the reference (> 1: better than the
// reference): reference / value for times and sizes, value / reference for rates. A `target`
// ending in "x" applies to `ratio`, any other target ("<=25", ">=99.9") to `value`.

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace avp::bench {

struct BenchRecord {
  std::string name;
  double value = 0.0;
  std::string unit;
  std::optional<std::string> reference;
  std::optional<double> reference_value;
  std::optional<double> ratio;
  std::optional<std::string> target;
  std::optional<bool> meets_target;
};

/// Evaluates `target` (">=20x", "<=25", ">=99.9", "<1") against the record's ratio (targets
/// ending in 'x') or value; nullopt when the target is malformed or the operand is missing.
std::optional<bool> EvaluateTarget(const std::string& target, double value,
                                   std::optional<double> ratio);

/// A record with its target evaluated (meets_target left null when there is no target).
BenchRecord MakeRecord(std::string name, double value, std::string unit,
                       std::optional<std::string> reference = std::nullopt,
                       std::optional<double> reference_value = std::nullopt,
                       std::optional<double> ratio = std::nullopt,
                       std::optional<std::string> target = std::nullopt);

/// Writes the records as a JSON list (non-finite numbers become null). Returns false (and prints
/// why on stderr) when the file cannot be written.
bool WriteBenchRecords(const std::string& path, const std::vector<BenchRecord>& records);

/// Removes "--avp_json=PATH" / "--avp_json PATH" from argv (so other parsers never see it) and
/// returns PATH, or an empty string when absent.
std::string TakeJsonPathArgument(int& argc, char** argv);

/// A target on one Google Benchmark run, matched on the run's name without its "/iterations:N"
/// and "/real_time" parts (e.g. "BM_SolveIk/20"), compared in the benchmark's own time unit.
struct GoogleBenchmarkTarget {
  std::string benchmark;
  std::string target;  ///< e.g. "<=25"
};

/// main() of a Google Benchmark program: strips --avp_json=PATH, runs the registered benchmarks
/// (console output and --benchmark_out as usual) and, when PATH was given, writes records per run:
/// "<name>" (real time), "<name>/cpu_time" and "<name>/<counter>", where <name> is the run name
/// without "/iterations:N" and "/real_time"; targets are attached to the real-time records.
/// Returns the process exit code.
int GoogleBenchmarkMain(int argc, char** argv, const std::vector<GoogleBenchmarkTarget>& targets);

/// The value below which a fraction `q` (0..1) of `values` lies (the nearest rank); 0 when empty.
double Percentile(std::vector<double> values, double q);

/// What RunClientLoad measured.
struct ClientLoad {
  double requests_per_s = 0.0;
  double p50_ms = 0.0, p99_ms = 0.0;  ///< latency of the answered requests
  uint64_t errors = 0;
  std::string first_error;  ///< the first error's text
};

/// One call of a client: true when answered, false with `error` set otherwise.
using ClientCall = std::function<bool(std::string& error)>;

/// `clients` threads, each with its own call from `make_client(c)` (made in the thread: one
/// connection each), calling it back to back for `seconds`: requests answered per second over
/// the whole time, and the answered ones' p50 / p99 latency.
ClientLoad RunClientLoad(int clients, double seconds,
                         const std::function<ClientCall(int client)>& make_client);

/// The records of one load: `<prefix>/requests_per_s`, `/p50`, `/p99` and `/errors` (target
/// "<1").
std::vector<BenchRecord> ClientLoadRecords(const std::string& prefix, const ClientLoad& load);

}  // namespace avp::bench

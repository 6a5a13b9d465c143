// avp.run / avp.bench (through the pure-Python wrappers in python/avp/__init__.py): an episode or
// a bench from a configuration, into the folder the CLI writes, interruptible with Ctrl-C.
#include <chrono>
#include <exception>
#include <future>
#include <map>
#include <optional>
#include <stop_token>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <pybind11/functional.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>
#include <yaml-cpp/yaml.h>

#include <avp/core/options.h>
#include <avp/experiment/bench.h>
#include <avp/experiment/run_config.h>
#include <avp/experiment/run_folder.h>
#include <avp/io/options_yaml.h>
#include <avp/io/yaml.h>
#include <avp/report/progress.h>
#include <avp/report/run_report.h>

#include "bindings.h"

namespace avp::python {

namespace {

namespace fs = std::filesystem;

/// Runs `work(stop)` on a worker thread with the GIL released; the calling thread checks for
/// Ctrl-C (PyErr_CheckSignals) ten times a second and asks the work to stop when it comes. The
/// work's result is returned; after an interrupt, `*interrupted` is set (the caller raises
/// KeyboardInterrupt once it has said where the results are). An exception the work raised
/// (a Python callback's among them) is raised here.
template <typename T>
T RunInterruptibly(const std::function<T(std::stop_token)>& work, bool* interrupted) {
  std::stop_source stop;
  std::packaged_task<T(std::stop_token)> task(work);
  std::future<T> result = task.get_future();
  {
    py::gil_scoped_release release;
    std::thread worker(std::move(task), stop.get_token());
    while (result.wait_for(std::chrono::milliseconds(100)) != std::future_status::ready) {
      py::gil_scoped_acquire acquire;
      if (PyErr_CheckSignals() != 0) {
        PyErr_Clear();
        *interrupted = true;
        stop.request_stop();
      }
    }
    worker.join();
  }
  return result.get();
}

/// A Python callable called from the worker thread: with the GIL, its exception kept (and the
/// work asked to stop) to be raised in the calling thread.
struct PyCallback {
  py::object fn;
  std::exception_ptr error;
  std::stop_source stop_on_error;

  template <typename... Args>
  void operator()(Args&&... args) {
    if (fn.is_none() || error) return;
    py::gil_scoped_acquire acquire;
    try {
      fn(std::forward<Args>(args)...);
    } catch (py::error_already_set&) {
      error = std::current_exception();
      stop_on_error.request_stop();
    }
  }
};

/// The run configuration: a YAML file (`config_file`), then a YAML/JSON text of the same tree
/// (`config_text`, e.g. a dict as JSON), then KEY=VALUE items (`set`, as `--set`), checked.
experiment::CheckedRunConfig ResolveRunConfig(
    const std::optional<fs::path>& config_file, const std::string& config_text,
    const std::vector<std::pair<std::string, std::string>>& set) {
  experiment::RunConfig c;
  if (config_file) {
    CheckFileExists(*config_file, "run configuration");
    const YAML::Node root = Unwrap(io::LoadYamlFile(*config_file));
    ThrowIfError(experiment::ReadRunConfigYaml(root, config_file->string(), c));
  }
  if (!config_text.empty()) {
    YAML::Node root;
    try {
      root = YAML::Load(config_text);
    } catch (const YAML::Exception& e) {
      throw py::value_error(fmt::format("config: {}", e.what()));
    }
    ThrowIfError(experiment::ReadRunConfigYaml(root, "config", c));
  }
  for (const auto& [key, value] : set) {
    ThrowIfError(experiment::SetRunConfigKey(c, key, value));
  }
  return Unwrap(experiment::CheckedRunConfig::Check(std::move(c), ProgramRegistries()));
}

std::string EffectiveConfig(const std::optional<fs::path>& config_file,
                            const std::string& config_text,
                            const std::vector<std::pair<std::string, std::string>>& set) {
  const experiment::CheckedRunConfig checked = ResolveRunConfig(config_file, config_text, set);
  return io::YamlText(Unwrap(experiment::RunConfigToYaml(*checked, ProgramRegistries())));
}

py::dict Run(const std::optional<fs::path>& config_file, const std::string& config_text,
             const std::vector<std::pair<std::string, std::string>>& set, const fs::path& out,
             bool force, bool record, const std::string& record_compression,
             const py::object& on_step) {
  const experiment::CheckedRunConfig checked = ResolveRunConfig(config_file, config_text, set);
  PyCallback callback{on_step, nullptr, {}};
  experiment::RunFolderOptions options;
  options.out_dir = out;
  options.force = force;
  options.record = record;
  options.record_compression = record_compression;
  if (config_file) options.inputs.emplace_back(*config_file, "configuration file");
  const auto t0 = std::chrono::steady_clock::now();
  auto unit = std::make_shared<report::RateUnit>(report::RateUnit::kAuto);
  options.on_step = [&](const pipeline::StepRecord& s) {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    callback(report::FormatStepLine(
        s, report::FormatProgressTimes(static_cast<size_t>(s.view + 1),
                                       static_cast<size_t>(std::max(s.views_total, 0)), elapsed,
                                       &*unit)));
  };
  bool interrupted = false;
  const std::function<Result<experiment::RunSummary>(std::stop_token)> work =
      [&](std::stop_token stop) {
        std::stop_source both;
        const std::stop_callback a(stop, [&] { both.request_stop(); });
        const std::stop_callback b(callback.stop_on_error.get_token(),
                                   [&] { both.request_stop(); });
        options.stop = both.get_token();
        return experiment::RunToFolder(checked, options);
      };
  Result<experiment::RunSummary> summary = RunInterruptibly(work, &interrupted);
  if (callback.error) std::rethrow_exception(callback.error);
  const experiment::RunSummary s = Unwrap(std::move(summary));
  if (interrupted) {
    PyErr_SetString(
        PyExc_KeyboardInterrupt,
        fmt::format("the episode was interrupted; its results so far are in {}", out.string())
            .c_str());
    throw py::error_already_set();
  }
  py::dict d;
  d["folder"] = out;
  d["scene"] = s.scene_name;
  d["seconds"] = s.seconds;
  d["files"] = s.files;
  d["end"] = std::string(pipeline::ToString(s.result.episode.end));
  d["end_reason"] = s.result.episode.end_reason;
  d["nothing_found"] = experiment::WhyNothingFound(*checked, s.result);
  // As `avp run`: a segmenter that failed the episode fails the call, its results saved.
  if (const Status failed = experiment::SegmenterFailure(s.result); !failed.ok()) {
    throw std::runtime_error(
        fmt::format("{} (the results are in {})", failed.ToString(), out.string()));
  }
  return d;
}

/// The bench: a YAML file, then a YAML/JSON text of the same tree, then the lists and the
/// options given; the defaults (FillBenchDefaults) for the lists neither names.
struct BenchArgs {
  std::optional<fs::path> config_file;
  std::string config_text;
  std::optional<std::vector<std::string>> scenarios, planners;
  std::optional<std::vector<uint64_t>> seeds;
  std::vector<std::pair<std::string, std::string>> set;
  std::map<std::string, OptionValues> planner_options;
};

experiment::BenchConfig ResolveBench(const BenchArgs& a) {
  experiment::BenchConfig b;
  if (a.config_file) {
    CheckFileExists(*a.config_file, "bench configuration");
    b = Unwrap(experiment::LoadBenchConfig(*a.config_file));
    b.inputs.emplace_back(*a.config_file, "bench configuration file");
  } else if (!a.config_text.empty()) {
    YAML::Node root;
    try {
      root = YAML::Load(a.config_text);
    } catch (const YAML::Exception& e) {
      throw py::value_error(fmt::format("config: {}", e.what()));
    }
    b = Unwrap(experiment::ReadBenchConfigYaml(root, "config", fs::current_path()));
  }
  if (a.scenarios) b.scenarios = *a.scenarios;
  if (a.planners) b.planners = *a.planners;
  if (a.seeds) b.seeds = *a.seeds;
  if (!a.config_file && a.config_text.empty()) {
    experiment::FillBenchDefaults(b, ProgramRegistries());
  }
  for (const auto& [key, value] : a.set)
    ThrowIfError(experiment::SetRunConfigKey(b.base, key, value));
  for (const auto& [planner, values] : a.planner_options) {
    for (const auto& kv : values) b.planner_options[planner].push_back(kv);
  }
  return b;
}

py::dict Bench(const BenchArgs& args, const fs::path& out, int jobs, bool force, bool resume,
               bool record, const std::string& record_compression, bool progress) {
  experiment::BenchConfig b = ResolveBench(args);
  b.out_dir = out;
  b.jobs = jobs;
  b.force = force;
  b.resume = resume;
  b.record = record;
  b.record_compression = record_compression;
  b.progress = progress;
  ThrowIfError(b.Validate(ProgramRegistries()));
  bool interrupted = false;
  const std::function<Result<experiment::BenchSummary>(std::stop_token)> work =
      [&](std::stop_token stop) {
        b.stop = stop;
        return experiment::RunBench(b, ProgramRegistries());
      };
  Result<experiment::BenchSummary> summary = RunInterruptibly(work, &interrupted);
  if (interrupted) {
    PyErr_SetString(PyExc_KeyboardInterrupt,
                    fmt::format("the bench was interrupted; avp.bench(..., resume=True) into {} "
                                "runs the rest",
                                out.string())
                        .c_str());
    throw py::error_already_set();
  }
  const experiment::BenchSummary s = Unwrap(std::move(summary));
  py::dict d;
  d["folder"] = out;
  d["episodes"] = s.episodes;
  d["failed"] = s.failed;
  d["resumed"] = s.resumed;
  d["seconds"] = s.seconds;
  d["files"] = s.files;
  d["report"] = s.report_html;
  return d;
}

}  // namespace

void BindRuns(py::module_& m) {
  m.def("_effective_config", &EffectiveConfig, py::arg("config_file"), py::arg("config_text"),
        py::arg("set"));
  m.def("_run", &Run, py::arg("config_file"), py::arg("config_text"), py::arg("set"),
        py::arg("out"), py::arg("force"), py::arg("record"), py::arg("record_compression"),
        py::arg("on_step"));
  m.def(
      "_bench",
      [](const std::optional<fs::path>& config_file, const std::string& config_text,
         const std::optional<std::vector<std::string>>& scenarios,
         const std::optional<std::vector<std::string>>& planners,
         const std::optional<std::vector<uint64_t>>& seeds,
         const std::vector<std::pair<std::string, std::string>>& set,
         const std::map<std::string, std::map<std::string, std::string>>& planner_options,
         const fs::path& out, int jobs, bool force, bool resume, bool record,
         const std::string& record_compression, bool progress) {
        BenchArgs a{config_file, config_text, scenarios, planners, seeds, set, {}};
        for (const auto& [planner, values] : planner_options) {
          for (const auto& [k, v] : values) a.planner_options[planner].emplace_back(k, v);
        }
        return Bench(a, out, jobs, force, resume, record, record_compression, progress);
      },
      py::arg("config_file"), py::arg("config_text"), py::arg("scenarios"), py::arg("planners"),
      py::arg("seeds"), py::arg("set"), py::arg("planner_options"), py::arg("out"), py::arg("jobs"),
      py::arg("force"), py::arg("resume"), py::arg("record"), py::arg("record_compression"),
      py::arg("progress"));
  m.def(
      "planners",
      [] {
        py::list out;
        for (const planning::PlannerEntry& e : ProgramRegistries().planners.entries()) {
          py::dict d;
          d["name"] = e.name;
          d["description"] = e.description;
          d["needs_ground_truth"] = e.needs_ground_truth;
          out.append(d);
        }
        return out;
      },
      "The registered view planners: name, description, whether it needs the ground truth.");
}

}  // namespace avp::python

#include <algorithm>
#include <chrono>
#include <ctime>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <avp/core/text.h>
#include <avp/experiment/output_folder.h>
#include <avp/io/file.h>
#include <avp/io/json.h>

namespace avp::experiment {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

bool StartsWith(const std::string& s, std::string_view prefix) {
  return s.size() >= prefix.size() && s.compare(0, prefix.size(), prefix) == 0;
}
bool EndsWith(const std::string& s, std::string_view suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

/// A temporary file of io::WriteFileAtomic left by a kill ("record.json.tmp.123.0").
bool IsTempOf(const std::string& name, const std::vector<std::string>& files) {
  return std::any_of(files.begin(), files.end(),
                     [&](const std::string& f) { return StartsWith(name, f + ".tmp."); });
}

std::string NowUtc() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

Status WriteState(const fs::path& dir, const FolderState& s) {
  json j{{"kind", s.kind},       {"state", s.state},       {"command", s.command},
         {"started", s.started}, {"finished", s.finished}, {"pid", static_cast<int64_t>(getpid())}};
  if (!s.error.empty()) j["error"] = s.error;
  return io::WriteJsonFile(dir / std::string(kStateFileName), j);
}

/// The folder's entries, sorted.
Result<std::vector<std::string>> Entries(const fs::path& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    names.push_back(it->path().filename().string());
  }
  if (ec) return IoError(fmt::format("cannot list folder '{}': {}", dir.string(), ec.message()));
  std::sort(names.begin(), names.end());
  return names;
}

std::string Listed(const std::vector<std::string>& names) {
  std::vector<std::string> shown;
  for (size_t i = 0; i < names.size() && i < 5; ++i) shown.push_back(QuoteText(names[i]));
  std::string out = fmt::format("{}", fmt::join(shown, ", "));
  if (names.size() > shown.size()) out += fmt::format(" and {} more", names.size() - shown.size());
  return out;
}

}  // namespace

const OutputFolderKind& RunFolderKind() {
  static const OutputFolderKind kind{
      "run", [](const std::string& name) {
        static const std::vector<std::string> files = {
            std::string(kStateFileName), "record.json", "metrics.csv",  "map.avpmap", "map.ot",
            "fruit_voxels.ply",          "metrics.svg", "episode.mcap", "report.html"};
        return std::find(files.begin(), files.end(), name) != files.end() || IsTempOf(name, files);
      }};
  return kind;
}

const OutputFolderKind& BenchFolderKind() {
  static const OutputFolderKind kind{
      "bench", [](const std::string& name) {
        static const std::vector<std::string> files = {std::string(kStateFileName),
                                                       "summary.md",
                                                       "summary.csv",
                                                       "fruits_by_visibility.csv",
                                                       "report.html",
                                                       "runs",
                                                       "bench.json"};
        if (std::find(files.begin(), files.end(), name) != files.end() || IsTempOf(name, files)) {
          return true;
        }
        return (StartsWith(name, "f1_") || StartsWith(name, "fruits_")) &&
               (EndsWith(name, ".svg") || name.find(".svg.tmp.") != std::string::npos);
      }};
  return kind;
}

const OutputFolderKind& RenderFolderKind() {
  static const OutputFolderKind kind{
      "render", [](const std::string& name) {
        static const std::vector<std::string> files = {
            std::string(kStateFileName), "rgb.png",     "depth.png",  "instance.png", "class.png",
            "labels_preview.png",        "camera.json", "fruits.json"};
        return std::find(files.begin(), files.end(), name) != files.end() || IsTempOf(name, files);
      }};
  return kind;
}

OutputFolderKind ConditionsFolderKind(std::vector<std::string> condition_names) {
  return {"bench-conditions", [names = std::move(condition_names)](const std::string& name) {
            static const std::vector<std::string> files = {std::string(kStateFileName),
                                                           "conditions.md", "conditions.csv"};
            return std::find(files.begin(), files.end(), name) != files.end() ||
                   IsTempOf(name, files) ||
                   std::find(names.begin(), names.end(), name) != names.end();
          }};
}

Result<FolderState> ReadFolderState(const fs::path& dir) {
  const fs::path path = dir / std::string(kStateFileName);
  // A state marker is a few hundred bytes: one of more than 64 KiB is not avp's, and is refused
  // before it is read (not read whole up to max_file_bytes). A missing one is ReadJsonFile's
  // NotFound.
  if (const Result<uint64_t> size = io::CheckReadableFile(path, "avp state file", 64 << 10);
      !size.ok() && size.status().code() != StatusCode::kNotFound) {
    return size.status();
  }
  AVP_ASSIGN_OR_RETURN(const json j, io::ReadJsonFile(path));
  FolderState s;
  const auto text = [&](const char* key, std::string& out) {
    if (j.is_object() && j.contains(key) && j.at(key).is_string()) {
      out = j.at(key).get<std::string>();
    }
  };
  text("kind", s.kind);
  text("state", s.state);
  text("command", s.command);
  text("started", s.started);
  text("finished", s.finished);
  text("error", s.error);
  if (s.kind.empty() || s.state.empty()) {
    return ParseError(
        fmt::format("'{}' is not an avp state file (no kind and state)", path.string()));
  }
  return s;
}

namespace {

/// What a non-empty folder holds, and whether --force may empty it.
struct FolderVerdict {
  std::vector<std::string> entries;
  Status refusal;  ///< OK: may be used (empty, missing, or emptied with force)
};

Result<FolderVerdict> Inspect(const fs::path& dir, const OutputFolderKind& kind, bool force) {
  if (dir.empty()) return InvalidArgumentError("the output folder (--out) is empty");
  std::error_code ec;
  const fs::file_status st = fs::status(dir, ec);
  if (ec && ec != std::errc::no_such_file_or_directory) {
    // ENOTDIR: a part of the path is a file.
    return IoError(fmt::format("cannot use output folder '{}': {}", dir.string(), ec.message()));
  }
  FolderVerdict verdict;
  if (!fs::exists(st)) return verdict;
  if (!fs::is_directory(st)) {
    return InvalidArgumentError(
        fmt::format("output folder '{}' is a file, not a folder", dir.string()));
  }
  AVP_ASSIGN_OR_RETURN(verdict.entries, Entries(dir));
  const std::vector<std::string>& entries = verdict.entries;
  if (entries.empty()) return verdict;

  std::vector<std::string> foreign;
  for (const std::string& e : entries) {
    if (!kind.owns(e)) foreign.push_back(e);
  }
  const Result<FolderState> state = ReadFolderState(dir);
  const bool marked = state.ok() && state->kind == kind.kind;
  const bool legacy = !state.ok() && foreign.empty() &&
                      fs::exists(dir / (kind.kind == "bench" ? "summary.md" : "record.json"), ec);
  std::string holds;
  if (!foreign.empty()) {
    holds = fmt::format("files avp does not write there ({})", Listed(foreign));
  } else if (marked && state->state == "complete") {
    holds = fmt::format("the results of a complete {} ({}, finished {})", state->command, kind.kind,
                        state->finished);
  } else if (marked && state->state == "in-progress") {
    holds = fmt::format(
        "the partial results of an {} that did not finish (started {}; killed, or still "
        "running)",
        state->command, state->started);
  } else if (marked) {
    holds = fmt::format("the partial results of an {} that {} ({})", state->command, state->state,
                        EscapeText(state->error, 200));
  } else if (state.ok()) {
    holds = fmt::format("the results of an avp {}, not of an avp {}", state->kind, kind.kind);
  } else if (legacy) {
    holds = fmt::format("the results of an earlier avp {} ({})", kind.kind, Listed(entries));
  } else {
    holds = fmt::format("files ({})", Listed(entries));
  }
  // --force empties only a folder of this kind holding nothing but what avp writes: it is
  // offered only where it works.
  const bool force_works = foreign.empty() && (marked || legacy);
  if (!force && force_works) {
    verdict.refusal = FailedPreconditionError(fmt::format(
        "output folder '{}' already holds {}: give another --out, or --force to replace it",
        dir.string(), holds));
  } else if (!force) {
    verdict.refusal = FailedPreconditionError(
        fmt::format("output folder '{}' already holds {}; it is not an avp {} folder (--force "
                    "would not empty it): give another --out",
                    dir.string(), holds, kind.kind));
  } else if (!force_works) {
    verdict.refusal = FailedPreconditionError(fmt::format(
        "output folder '{}' holds {}; it is not an avp {} folder, so --force does not empty it: "
        "give another --out",
        dir.string(), holds, kind.kind));
  }
  return verdict;
}

}  // namespace

Status CheckOutputFolder(const fs::path& dir, const OutputFolderKind& kind, bool force) {
  AVP_ASSIGN_OR_RETURN(const FolderVerdict verdict, Inspect(dir, kind, force));
  return verdict.refusal;
}

Status PrepareOutputFolder(const fs::path& dir, const OutputFolderKind& kind, bool force) {
  AVP_ASSIGN_OR_RETURN(const FolderVerdict verdict, Inspect(dir, kind, force));
  AVP_RETURN_IF_ERROR(verdict.refusal);
  std::error_code ec;
  if (!fs::exists(dir, ec)) {
    fs::create_directories(dir, ec);
    if (ec) {
      return IoError(
          fmt::format("cannot create output folder '{}': {}", dir.string(), ec.message()));
    }
    return Status::Ok();
  }
  const std::vector<std::string>& entries = verdict.entries;
  // Everything in it is avp's: start clean, the state marker last (a kill half-way leaves a
  // folder that is still recognisably avp's).
  for (const std::string& e : entries) {
    if (e == kStateFileName) continue;
    fs::remove_all(dir / e, ec);
    if (ec) {
      return IoError(
          fmt::format("--force: cannot remove '{}': {}", (dir / e).string(), ec.message()));
    }
  }
  fs::remove(dir / std::string(kStateFileName), ec);
  if (ec) {
    return IoError(fmt::format("--force: cannot remove '{}': {}",
                               (dir / std::string(kStateFileName)).string(), ec.message()));
  }
  return Status::Ok();
}

Status CheckOutputFile(const fs::path& file, bool force) {
  if (file.empty()) return InvalidArgumentError("the output file (--out) is empty");
  std::error_code ec;
  const fs::file_status st = fs::status(file, ec);
  if (fs::is_directory(st)) {
    return InvalidArgumentError(fmt::format("output '{}' is a folder: give a file name (e.g. {})",
                                            file.string(),
                                            (file / ("out" + file.extension().string())).string()));
  }
  const fs::path parent = file.has_parent_path() ? file.parent_path() : fs::path(".");
  if (const Result<FolderState> state = ReadFolderState(parent); state.ok()) {
    return FailedPreconditionError(fmt::format(
        "output file '{}' would go into '{}', the folder of an {} ({}): avp writes nothing into "
        "another command's results; give an --out outside it",
        file.string(), parent.string(), state->command, state->kind));
  }
  if (fs::exists(st) && !force) {
    return FailedPreconditionError(
        fmt::format("output file '{}' already exists: give another --out, or --force to replace it",
                    file.string()));
  }
  return Status::Ok();
}

Status MarkInProgress(const fs::path& dir, const OutputFolderKind& kind, std::string_view command) {
  return WriteState(dir, {kind.kind, "in-progress", std::string(command), NowUtc(), "", ""});
}

Status MarkComplete(const fs::path& dir, const OutputFolderKind& kind, std::string_view command) {
  const Result<FolderState> before = ReadFolderState(dir);
  return WriteState(dir, {kind.kind, "complete", std::string(command),
                          before.ok() ? before->started : "", NowUtc(), ""});
}

void MarkFailed(const fs::path& dir, const OutputFolderKind& kind, std::string_view command,
                const Status& error) {
  const Result<FolderState> before = ReadFolderState(dir);
  (void)WriteState(dir, {kind.kind, "failed", std::string(command),
                         before.ok() ? before->started : "", NowUtc(), error.ToString()});
}

}  // namespace avp::experiment

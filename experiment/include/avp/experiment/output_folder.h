#pragma once

// The lifecycle of a folder avp writes results into (a run folder of avp run / avp live, an
// avp bench folder, each of a bench's per-run folders), docs/experiments.md "Run folders":
//
//   avp-state.json   {"kind": "run", "state": "in-progress", "command": "avp run", ...}
//
// written (atomically) before the first result, and rewritten "complete" after the last one (or
// "failed" with the error when a result could not be written). A folder killed half-way still
// says "in-progress", so it is never mistaken for a finished one, and a rerun into a folder that
// holds results refuses unless told to start clean (--force), which removes only what avp writes.
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>

namespace avp::experiment {

/// The state marker's file name in every output folder.
inline constexpr std::string_view kStateFileName = "avp-state.json";

/// What an output folder is and what it may hold: its kind ("run", "bench") and the names of the
/// entries avp writes into it (anything else in it is someone else's and is never removed).
struct OutputFolderKind {
  std::string kind;
  /// True for the name of an entry (file or folder) avp writes into this kind of folder.
  std::function<bool(const std::string& name)> owns;
};

/// A run folder: record.json, metrics.csv, map.ot, fruit_voxels.ply, metrics.svg, report.html.
const OutputFolderKind& RunFolderKind();
/// A bench folder: bench.json, summary.md, summary.csv, f1_*.svg, fruits_*.svg, report.html, runs/.
const OutputFolderKind& BenchFolderKind();

/// An `avp render` folder: rgb.png, depth.png, instance.png, class.png, labels_preview.png,
/// camera.json, fruits.json.
const OutputFolderKind& RenderFolderKind();
/// A bench folder of conditions (`avp bench` with a config's `conditions`): conditions.md,
/// conditions.csv and one bench folder per condition, named as the conditions are.
OutputFolderKind ConditionsFolderKind(std::vector<std::string> condition_names);

/// What avp-state.json says.
struct FolderState {
  std::string kind;     ///< "run", "bench"
  std::string state;    ///< "in-progress", "complete", "failed"
  std::string command;  ///< "avp run", "avp bench", "avp live"
  std::string started;  ///< UTC, ISO 8601
  std::string finished;
  std::string error;  ///< what failed ("failed" only)
};

/// Reads `dir`/avp-state.json: NotFound when there is none, ParseError when it is not one avp
/// wrote.
Result<FolderState> ReadFolderState(const std::filesystem::path& dir);

/// Makes `dir` ready for a new run of `kind`: creates it when missing; an empty folder is used as
/// it is. A folder that holds anything is refused (FailedPrecondition naming the folder and what
/// it holds: a complete or unfinished avp run, or files avp did not write) unless `force`; with
/// `force` it is emptied first, but only when it is a folder of this kind (its state marker, or
/// its record.json / summary.md) holding nothing but what avp writes: anything else is refused
/// even with `force`. InvalidArgument when `dir` is a file.
Status PrepareOutputFolder(const std::filesystem::path& dir, const OutputFolderKind& kind,
                           bool force);

/// PrepareOutputFolder's checks without changing anything: OK when `dir` may be used (missing,
/// empty, or emptied by `force`), else its refusal. Called before slow work (a scene's ground
/// truth) so that a refusal comes at once.
Status CheckOutputFolder(const std::filesystem::path& dir, const OutputFolderKind& kind,
                         bool force);

/// The rule for a command that writes one file (`avp map build / gt / export --out FILE`): OK
/// when `file` may be written. Refused (FailedPrecondition naming the file and the fix): an
/// existing file unless `force`; a folder; a file inside the folder of another avp command (a
/// run, bench or render folder: its avp-state.json), even with `force`. A missing parent folder
/// is created by the writer.
Status CheckOutputFile(const std::filesystem::path& file, bool force);

/// Writes `dir`/avp-state.json "in-progress" (atomically), with the command and the start time.
Status MarkInProgress(const std::filesystem::path& dir, const OutputFolderKind& kind,
                      std::string_view command);
/// Rewrites it "complete".
Status MarkComplete(const std::filesystem::path& dir, const OutputFolderKind& kind,
                    std::string_view command);
/// Rewrites it "failed" with `error`; best effort (a full disk may refuse it too, then the folder
/// stays "in-progress", which is as recognisable).
void MarkFailed(const std::filesystem::path& dir, const OutputFolderKind& kind,
                std::string_view command, const Status& error);

}  // namespace avp::experiment

#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include <avp/core/limits.h>
#include <avp/core/status.h>

namespace avp::io {

/// Writes `bytes` to `path` atomically and durably: into a temporary file beside it
/// ("<name>.tmp.<pid>"), every write checked, the file flushed to the disk (fsync), then renamed
/// over `path` and the folder flushed, so a reader (or a run killed half-way, or a full disk) never
/// sees a half-written file: `path` holds the old bytes or the new ones. Creates the parent
/// folders. `what` names the file in errors ("map file", "plot", ...): IoError naming the path and
/// the system's reason (never "Success"); InvalidArgument when `path` is a folder. The temporary
/// file is removed on failure.
Status WriteFileAtomic(const std::filesystem::path& path, std::string_view bytes,
                       std::string_view what = "file");

/// Flushes a folder's entries (a rename or a new file in it) to the disk. Filesystems that cannot
/// flush a folder (EINVAL) are not an error.
Status SyncFolder(const std::filesystem::path& folder);

/// A file written step by step (metrics.csv, one row per step): each Write goes to the file at
/// once (no buffer left in the process) and is checked, so a full disk or a failing device stops
/// the writer with IoError naming the file (and `what`) at the step it happened. Close flushes it
/// to the disk (fsync). Movable, not copyable; closes on destruction (errors then are lost: call
/// Close).
class StepFileWriter {
 public:
  /// Creates (truncates) `path`; IoError naming it when it cannot be opened for writing.
  static Result<StepFileWriter> Create(const std::filesystem::path& path, std::string_view what);
  StepFileWriter(StepFileWriter&& other) noexcept;
  StepFileWriter& operator=(StepFileWriter&& other) noexcept;
  StepFileWriter(const StepFileWriter&) = delete;
  StepFileWriter& operator=(const StepFileWriter&) = delete;
  ~StepFileWriter();

  /// Appends `bytes`. After a failure every later Write and Close returns the first error.
  Status Write(std::string_view bytes);
  /// fsync and close; the first error of the writer's life, if any.
  Status Close();
  const std::filesystem::path& path() const { return path_; }

 private:
  StepFileWriter(int fd, std::filesystem::path path, std::string what);
  int fd_ = -1;
  std::filesystem::path path_;
  std::string what_;
  Status error_;
};

/// True when `a` and `b` name the same file or folder: std::filesystem::equivalent when both exist
/// (hard links, symbolic links, "./x" and "x"), else their weakly_canonical forms are equal.
bool SameFile(const std::filesystem::path& a, const std::filesystem::path& b);

/// Outputs never overwrite inputs: InvalidArgument "<output_what> 'out' is the <input_what> 'in'
/// it reads (...)" when SameFile(output, input); OK when either is empty.
Status CheckOutputIsNotInput(const std::filesystem::path& output, std::string_view output_what,
                             const std::filesystem::path& input, std::string_view input_what);

/// The process-wide limit on one file read whole (max_file_bytes, 2 GiB by default): maps, scenes,
/// images, configs. Readers with a smaller natural bound check their own as well.
const Limit& MaxFileBytes();

/// Reads a whole regular file, checking before reading: NotFound "<what> 'path' does not exist",
/// InvalidArgument "'path' is a folder, not a <what>" (or not a regular file), ResourceExhausted
/// when its size passes `max_bytes` (or MaxFileBytes() when 0), IoError naming the path and the
/// system's reason when it cannot be opened or read. `what` names the file: "map file", "PNG
/// image", ...
Result<std::string> ReadFileBounded(const std::filesystem::path& path, std::string_view what,
                                    uint64_t max_bytes = 0);

/// The checks of ReadFileBounded without reading: OK when `path` is a readable regular file of at
/// most `max_bytes` (MaxFileBytes() when 0); its size in bytes.
Result<uint64_t> CheckReadableFile(const std::filesystem::path& path, std::string_view what,
                                   uint64_t max_bytes = 0);

}  // namespace avp::io

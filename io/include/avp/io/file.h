#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include <avp/core/limits.h>
#include <avp/core/status.h>

namespace avp::io {

/// Writes `bytes` to `path` atomically: into `<path>.tmp` beside it, then a rename, so a reader
/// (or a run killed half-way) never sees a half-written file. Creates the parent folders.
/// `what` names the file in errors ("map file", "plot", ...). IoError naming the path otherwise;
/// the temporary file is removed on failure.
Status WriteFileAtomic(const std::filesystem::path& path, std::string_view bytes,
                       std::string_view what = "file");

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

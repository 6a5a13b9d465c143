#pragma once

#include <filesystem>
#include <string_view>

#include <avp/core/status.h>

namespace avp::io {

/// Writes `bytes` to `path` atomically: into `<path>.tmp` beside it, then a rename, so a reader
/// (or a run killed half-way) never sees a half-written file. Creates the parent folders.
/// `what` names the file in errors ("map file", "plot", ...). IoError naming the path otherwise;
/// the temporary file is removed on failure.
Status WriteFileAtomic(const std::filesystem::path& path, std::string_view bytes,
                       std::string_view what = "file");

}  // namespace avp::io

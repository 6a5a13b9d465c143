#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <filesystem>
#include <string>

#include <avp/core/status.h>

namespace avp::zsl {

/// The SHA-256 of a file as 64 lower-case hex digits. Errors: NotFound, IoError.
Result<std::string> FileSha256(const std::filesystem::path& path);

}  // namespace avp::zsl

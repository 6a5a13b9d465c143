#include <cerrno>
#include <cstring>
#include <fstream>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/file.h>

namespace avp::io {

const Limit& MaxFileBytes() {
  static const Limit limit("max_file_bytes", uint64_t{2} << 30, "bytes",
                           "size of one input file read whole (map, scene, image, config)");
  return limit;
}

Result<uint64_t> CheckReadableFile(const std::filesystem::path& path, std::string_view what,
                                   uint64_t max_bytes) {
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(st)) {
    if (ec && ec != std::errc::no_such_file_or_directory) {
      return IoError(fmt::format("cannot read {} '{}': {}", what, path.string(), ec.message()));
    }
    return NotFoundError(fmt::format("{} '{}' does not exist", what, path.string()));
  }
  if (std::filesystem::is_directory(st)) {
    return InvalidArgumentError(fmt::format("'{}' is a folder, not a {}", path.string(), what));
  }
  if (!std::filesystem::is_regular_file(st)) {
    return InvalidArgumentError(
        fmt::format("'{}' is not a regular file (expected a {})", path.string(), what));
  }
  const uint64_t size = std::filesystem::file_size(path, ec);
  if (ec) {
    return IoError(fmt::format("cannot read {} '{}': {}", what, path.string(), ec.message()));
  }
  if (max_bytes == 0) {
    AVP_RETURN_IF_ERROR(
        MaxFileBytes().Check(fmt::format("{} '{}' of {} bytes", what, path.string(), size), size));
  } else {
    AVP_RETURN_IF_ERROR(CheckLimit(fmt::format("{} '{}' of {} bytes", what, path.string(), size),
                                   size, fmt::format("max bytes of a {}", what), max_bytes));
  }
  return size;
}

Result<std::string> ReadFileBounded(const std::filesystem::path& path, std::string_view what,
                                    uint64_t max_bytes) {
  AVP_ASSIGN_OR_RETURN(const uint64_t size, CheckReadableFile(path, what, max_bytes));
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return IoError(
        fmt::format("cannot open {} '{}': {}", what, path.string(), std::strerror(errno)));
  }
  std::string bytes(static_cast<size_t>(size), '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(size));
  if (static_cast<uint64_t>(in.gcount()) != size || in.bad()) {
    return IoError(fmt::format("reading {} '{}' failed after {} of {} bytes (changed while read?)",
                               what, path.string(), in.gcount(), size));
  }
  return bytes;
}

Status WriteFileAtomic(const std::filesystem::path& path, std::string_view bytes,
                       std::string_view what) {
  std::error_code ec;
  if (path.has_parent_path()) {
    std::filesystem::create_directories(path.parent_path(), ec);
    if (ec) {
      return IoError(fmt::format("cannot create folder '{}' for {} '{}': {}",
                                 path.parent_path().string(), what, path.string(), ec.message()));
    }
  }
  std::filesystem::path tmp = path;
  tmp += ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) {
      return IoError(
          fmt::format("cannot open '{}' for writing: {}", tmp.string(), std::strerror(errno)));
    }
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) {
      std::filesystem::remove(tmp, ec);
      return IoError(fmt::format("writing {} '{}' failed", what, tmp.string()));
    }
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    return IoError(
        fmt::format("cannot move '{}' to '{}': {}", tmp.string(), path.string(), ec.message()));
  }
  return Status::Ok();
}

}  // namespace avp::io

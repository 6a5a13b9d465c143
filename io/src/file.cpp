#include <cerrno>
#include <cstring>
#include <fstream>

#include <fmt/format.h>

#include <avp/io/file.h>

namespace avp::io {

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

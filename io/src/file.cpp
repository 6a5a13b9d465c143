#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <utility>

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <avp/core/text.h>
#include <avp/io/file.h>

namespace avp::io {

namespace {

/// The system's reason for the last failed call; never "Success" (errno 0 says "unknown").
std::string Reason(int error) {
  return error == 0 ? std::string("unknown error") : std::string(std::strerror(error));
}

}  // namespace

namespace {

/// "an" before a vowel ("an image file"), else "a".
std::string_view Article(std::string_view noun) {
  return !noun.empty() &&
                 std::string_view("aeiouAEIOU").find(noun.front()) != std::string_view::npos
             ? "an"
             : "a";
}

}  // namespace

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
    return InvalidArgumentError(
        fmt::format("'{}' is a folder, not {} {}", path.string(), Article(what), what));
  }
  if (!std::filesystem::is_regular_file(st)) {
    return InvalidArgumentError(fmt::format("'{}' is not a regular file (expected {} {})",
                                            path.string(), Article(what), what));
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
  errno = 0;
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    const int e = errno;
    return IoError(fmt::format("cannot open {} '{}': {}", what, path.string(), Reason(e)));
  }
  std::string bytes(static_cast<size_t>(size), '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(size));
  if (static_cast<uint64_t>(in.gcount()) != size || in.bad()) {
    return IoError(fmt::format("reading {} '{}' failed after {} of {} bytes (changed while read?)",
                               what, path.string(), in.gcount(), size));
  }
  return bytes;
}

namespace {

/// Writes all of `bytes` to `fd`, retrying short writes and EINTR; the errno of a failure (ENOSPC
/// for a full disk) or 0.
int WriteAll(int fd, std::string_view bytes) {
  while (!bytes.empty()) {
    const ssize_t n = ::write(fd, bytes.data(), bytes.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno != 0 ? errno : EIO;
    }
    if (n == 0) return ENOSPC;
    bytes.remove_prefix(static_cast<size_t>(n));
  }
  return 0;
}

/// fsync that tolerates devices and filesystems that cannot sync (EINVAL, ENOTSUP: /dev/null).
int SyncFd(int fd) {
  while (::fsync(fd) != 0) {
    if (errno == EINTR) continue;
    if (errno == EINVAL || errno == ENOTSUP || errno == EROFS) return 0;
    return errno != 0 ? errno : EIO;
  }
  return 0;
}

std::filesystem::path TempPathFor(const std::filesystem::path& path) {
  static std::atomic<uint64_t> counter{0};
  std::filesystem::path tmp = path;
  tmp += fmt::format(".tmp.{}.{}", ::getpid(), counter.fetch_add(1));
  return tmp;
}

}  // namespace

Status SyncFolder(const std::filesystem::path& folder) {
  const std::filesystem::path dir = folder.empty() ? std::filesystem::path(".") : folder;
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) {
    const int e = errno;
    return IoError(fmt::format("cannot open folder '{}' to flush it: {}", dir.string(), Reason(e)));
  }
  const int e = SyncFd(fd);
  ::close(fd);
  if (e != 0) {
    return IoError(
        fmt::format("cannot flush folder '{}' to the disk: {}", dir.string(), Reason(e)));
  }
  return Status::Ok();
}

Status WriteFileAtomic(const std::filesystem::path& path, std::string_view bytes,
                       std::string_view what) {
  std::error_code ec;
  if (path.empty()) return InvalidArgumentError(fmt::format("no path given for the {}", what));
  if (std::filesystem::is_directory(path, ec)) {
    return InvalidArgumentError(
        fmt::format("cannot write {} '{}': it is a folder", what, path.string()));
  }
  if (path.has_parent_path()) {
    std::filesystem::create_directories(path.parent_path(), ec);
    if (ec) {
      return IoError(fmt::format("cannot create folder '{}' for {} '{}': {}",
                                 path.parent_path().string(), what, path.string(), ec.message()));
    }
  }
  const std::filesystem::path tmp = TempPathFor(path);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) {
    const int e = errno;
    return IoError(fmt::format("cannot write {} '{}': cannot create '{}': {}", what, path.string(),
                               tmp.string(), Reason(e)));
  }
  int e = WriteAll(fd, bytes);
  if (e == 0) e = SyncFd(fd);
  if (::close(fd) != 0 && e == 0) e = errno != 0 ? errno : EIO;
  if (e != 0) {
    std::filesystem::remove(tmp, ec);
    return IoError(fmt::format("writing {} '{}' failed ({} bytes into '{}'): {}", what,
                               path.string(), bytes.size(), tmp.string(), Reason(e)));
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    const std::string reason = ec.message();  // before remove() reuses ec
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    return IoError(fmt::format("cannot write {} '{}': moving '{}' over it failed: {}", what,
                               path.string(), tmp.string(), reason));
  }
  const Status synced =
      SyncFolder(path.has_parent_path() ? path.parent_path() : std::filesystem::path("."));
  if (!synced.ok()) {
    return IoError(fmt::format("{} '{}' was written but may not survive a power cut: {}", what,
                               path.string(), synced.message()));
  }
  return Status::Ok();
}

// ---- StepFileWriter

StepFileWriter::StepFileWriter(int fd, std::filesystem::path path, std::string what)
    : fd_(fd), path_(std::move(path)), what_(std::move(what)) {}

StepFileWriter::StepFileWriter(StepFileWriter&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)),
      path_(std::move(other.path_)),
      what_(std::move(other.what_)),
      error_(std::move(other.error_)) {}

StepFileWriter& StepFileWriter::operator=(StepFileWriter&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = std::exchange(other.fd_, -1);
    path_ = std::move(other.path_);
    what_ = std::move(other.what_);
    error_ = std::move(other.error_);
  }
  return *this;
}

StepFileWriter::~StepFileWriter() {
  if (fd_ >= 0) ::close(fd_);
}

Result<StepFileWriter> StepFileWriter::Create(const std::filesystem::path& path,
                                              std::string_view what) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return InvalidArgumentError(
        fmt::format("cannot write {} '{}': it is a folder", what, path.string()));
  }
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) {
    const int e = errno;
    return IoError(fmt::format("cannot write {} '{}': {}", what, path.string(), Reason(e)));
  }
  return StepFileWriter(fd, path, std::string(what));
}

Status StepFileWriter::Write(std::string_view bytes) {
  if (!error_.ok()) return error_;
  if (fd_ < 0) {
    error_ = InternalError(fmt::format("{} '{}' is closed", what_, path_.string()));
    return error_;
  }
  const int e = WriteAll(fd_, bytes);
  if (e != 0) {
    error_ = IoError(fmt::format("writing {} '{}' failed: {}", what_, path_.string(), Reason(e)));
  }
  return error_;
}

Status StepFileWriter::Close() {
  if (fd_ < 0) return error_;
  int e = SyncFd(fd_);
  if (::close(fd_) != 0 && e == 0) e = errno != 0 ? errno : EIO;
  fd_ = -1;
  if (e != 0 && error_.ok()) {
    error_ = IoError(fmt::format("writing {} '{}' failed: {}", what_, path_.string(), Reason(e)));
  }
  return error_;
}

// ---- outputs and inputs

bool SameFile(const std::filesystem::path& a, const std::filesystem::path& b) {
  if (a.empty() || b.empty()) return false;
  std::error_code ec;
  if (std::filesystem::exists(a, ec) && std::filesystem::exists(b, ec)) {
    const bool same = std::filesystem::equivalent(a, b, ec);
    if (!ec) return same;
  }
  const std::filesystem::path ca = std::filesystem::weakly_canonical(a, ec);
  if (ec) return a.lexically_normal() == b.lexically_normal();
  const std::filesystem::path cb = std::filesystem::weakly_canonical(b, ec);
  if (ec) return a.lexically_normal() == b.lexically_normal();
  return ca == cb;
}

Status CheckOutputIsNotInput(const std::filesystem::path& output, std::string_view output_what,
                             const std::filesystem::path& input, std::string_view input_what) {
  if (!SameFile(output, input)) return Status::Ok();
  return InvalidArgumentError(fmt::format(
      "{} '{}' is the {} '{}' it reads: outputs never overwrite inputs; give another output path",
      output_what, output.string(), input_what, input.string()));
}

}  // namespace avp::io

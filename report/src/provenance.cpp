#include <cstdio>
#include <filesystem>
#include <thread>

#include <fmt/format.h>
#include <sys/utsname.h>
#include <unistd.h>

#include <avp/report/provenance.h>

#ifndef AVP_SOURCE_DIR
#define AVP_SOURCE_DIR ""
#endif

namespace avp::report {

namespace fs = std::filesystem;

namespace {

std::string RunShell(const std::string& command) {
  std::string out;
  std::FILE* p = ::popen(command.c_str(), "r");
  if (p == nullptr) return out;
  char buf[256];
  while (std::fgets(buf, sizeof buf, p) != nullptr) out += buf;
  ::pclose(p);
  while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
  return out;
}

}  // namespace

std::string SourceRevision() {
  const std::string dir = AVP_SOURCE_DIR;
  if (dir.empty() || !fs::exists(fs::path(dir) / ".git")) return "unknown";
  const std::string rev = RunShell(fmt::format("git -C '{}' rev-parse HEAD 2>/dev/null", dir));
  if (rev.empty()) return "unknown";
  const std::string dirty =
      RunShell(fmt::format("git -C '{}' status --porcelain --untracked-files=no 2>/dev/null", dir));
  return dirty.empty() ? rev : rev + "-dirty";
}

std::string HostDescription() {
  char host[256] = {0};
  ::gethostname(host, sizeof host - 1);
  utsname u{};
  ::uname(&u);
  return fmt::format("{} ({} {} {}, {} hardware threads)", host, u.sysname, u.release, u.machine,
                     std::thread::hardware_concurrency());
}

}  // namespace avp::report

#pragma once

// Runs a command line through the shell for tests that drive the built `avp` program.

#include <cstdio>
#include <string>

#include <sys/wait.h>

namespace avp::test {

/// What a command printed (stdout and stderr, as the command line redirects them) and its exit
/// code (-1 when it could not be started or did not exit normally).
struct Ran {
  int exit_code = -1;
  std::string output;
};

/// Runs `command` with popen and collects its standard output; append " 2>&1" to the command to
/// collect its errors too.
inline Ran RunShell(const std::string& command) {
  Ran r;
  std::FILE* p = ::popen(command.c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  const int status = ::pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace avp::test

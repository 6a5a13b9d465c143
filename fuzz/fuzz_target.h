#pragma once

// Shared by the fuzz targets (fuzz/*_fuzz.cpp): the libFuzzer entry points, which each target
// defines, and a per-process scratch folder for targets whose reader only takes a path.

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>

#include <unistd.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);
// Optional: called once before the first input (libFuzzer and the replay main both call it).
extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv);

namespace avp::fuzz {

/// Stops the process with a message: a property the target checks does not hold (libFuzzer
/// reports it as a crash and saves the input).
[[noreturn]] inline void Fail(std::string_view what) {
  std::fprintf(stderr, "avp fuzz: property violated: %.*s\n", static_cast<int>(what.size()),
               what.data());
  std::abort();
}

/// A folder of its own under $TMPDIR for this process, removed at exit.
inline const std::filesystem::path& ScratchDir() {
  static const std::filesystem::path dir = [] {
    std::error_code ec;
    std::filesystem::path base = std::filesystem::temp_directory_path(ec);
    if (ec) base = "/tmp";
    std::filesystem::path d = base / ("avp-fuzz-" + std::to_string(::getpid()));
    std::filesystem::create_directories(d, ec);
    if (ec) Fail("cannot create the scratch folder " + d.string() + ": " + ec.message());
    static struct Cleanup {
      std::filesystem::path p;
      ~Cleanup() {
        std::error_code ignored;
        std::filesystem::remove_all(p, ignored);
      }
    } cleanup{d};
    return d;
  }();
  return dir;
}

/// Writes `bytes` to `path` (replacing it).
inline void WriteFile(const std::filesystem::path& path, std::string_view bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) Fail("cannot write " + path.string());
}

}  // namespace avp::fuzz

#pragma once

// The one file-reading helper of the test suites: a file's whole contents as a string.

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace avp::test {

/// Every byte of the file at `path` (read in binary mode: no newline translation); empty when it
/// cannot be opened (tests then fail on the contents, naming what they expected).
inline std::string ReadWholeFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace avp::test

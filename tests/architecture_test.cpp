// Checks the dependency rules of docs/architecture.md by reading every source file's includes:
// modules include only modules below them, and only apps/ (and later interop/) may include
// command-line, middleware or network headers.
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace {

namespace fs = std::filesystem;

const fs::path kSourceRoot = fs::path(AVP_CONFIG_DIR).parent_path();

// Which avp modules each module may include.
const std::map<std::string, std::set<std::string>> kAllowed = {
    {"core", {"core"}},
    {"io", {"core", "io"}},
    {"sim", {"core", "io", "sim"}},
    {"robot", {"core", "io", "robot"}},
    {"mapping", {"core", "io", "mapping"}},
    {"segmentation", {"core", "io", "segmentation"}},
    {"planning", {"core", "io", "robot", "mapping", "planning"}},
    {"pipeline", {"core", "io", "sim", "robot", "segmentation", "mapping", "planning", "pipeline"}},
    {"eval",
     {"core", "io", "sim", "robot", "segmentation", "mapping", "planning", "pipeline", "eval"}},
    // Zero-shot segmentation backends (ONNX Runtime) and the segmentation service (gRPC): both
    // implement segmentation's Segmenter and are registered with it by apps/.
    {"zsl", {"core", "io", "segmentation", "zsl"}},
    {"interop", {"core", "io", "segmentation", "interop"}},
};

// The external headers a module may include although they are in kForbiddenPrefixes.
const std::map<std::string, std::set<std::string>> kAllowedExternal = {
    {"zsl", {"onnxruntime"}},
    {"interop", {"grpc", "grpcpp/"}},
};

const std::vector<std::string> kForbiddenPrefixes = {"CLI/",  "grpc",        "grpcpp/", "dds/",
                                                     "ddsc/", "rclcpp",      "ros/",    "httplib",
                                                     "curl/", "onnxruntime", "spdlog/"};

struct Include {
  fs::path file;
  int line;
  std::string header;
};

std::vector<Include> IncludesOf(const std::string& module) {
  std::vector<Include> out;
  const std::regex include_re(R"(^\s*#\s*include\s*[<"]([^>"]+)[>"])");
  for (const auto& entry : fs::recursive_directory_iterator(kSourceRoot / module)) {
    const std::string ext = entry.path().extension().string();
    if (ext != ".h" && ext != ".cpp") continue;
    std::ifstream in(entry.path());
    std::string line;
    int number = 0;
    while (std::getline(in, line)) {
      ++number;
      std::smatch m;
      if (std::regex_search(line, m, include_re)) out.push_back({entry.path(), number, m[1]});
    }
  }
  return out;
}

TEST(ArchitectureTest, ModulesIncludeOnlyModulesBelowThem) {
  for (const auto& [module, allowed] : kAllowed) {
    const auto includes = IncludesOf(module);
    ASSERT_FALSE(includes.empty()) << "no sources found for module " << module;
    for (const Include& inc : includes) {
      if (inc.header.rfind("avp/", 0) != 0) continue;
      const std::string target = inc.header.substr(4, inc.header.find('/', 4) - 4);
      // Unit tests (<module>/test/) may also use the shared test support (tests/support/) and
      // the simulator, which renders their analytic test scenes (a test-only dependency: the
      // library itself still may not include sim).
      const bool is_unit_test = inc.file.parent_path().filename() == "test";
      if ((target == "test" || target == "sim") && is_unit_test) continue;
      EXPECT_TRUE(allowed.count(target) > 0)
          << inc.file.string() << ":" << inc.line << " (module " << module << ") includes <"
          << inc.header << ">, but " << module << " may not depend on " << target;
    }
  }
}

TEST(ArchitectureTest, CoreModulesIncludeNoMiddlewareOrCommandLineHeaders) {
  for (const auto& [module, allowed] : kAllowed) {
    for (const Include& inc : IncludesOf(module)) {
      for (const std::string& prefix : kForbiddenPrefixes) {
        const auto exempt = kAllowedExternal.find(module);
        if (exempt != kAllowedExternal.end() && exempt->second.count(prefix) > 0) continue;
        EXPECT_NE(inc.header.rfind(prefix, 0), 0u)
            << inc.file.string() << ":" << inc.line << " includes <" << inc.header
            << ">: only apps/ and interop/ may include " << prefix << "* headers";
      }
    }
  }
}

}  // namespace

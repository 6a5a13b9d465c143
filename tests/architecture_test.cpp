// Checks the dependency rules of docs/architecture.md: by reading every source file's includes
// (modules include only modules below them, and only apps/ and the modules that wrap them may
// include command-line, middleware or network headers), and by reading the link graph CMake writes
// (avp_link_graph.txt: what linking each module pulls in), so that, e.g., the loop a real robot
// runs (avp::pipeline) links no simulator and no Embree (assimp it may: avp::motion reads the
// robot's URDF meshes with it).
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace {

namespace fs = std::filesystem;

const fs::path kSourceRoot = fs::path(AVP_CONFIG_DIR).parent_path();

/// Per library target ("avp_pipeline"), everything linking it pulls in.
using LinkGraph = std::map<std::string, std::set<std::string>>;

/// Parses avp_link_graph.txt: "target: item item ..." per line.
LinkGraph ReadLinkGraph(const fs::path& file) {
  LinkGraph graph;
  std::ifstream in(file);
  for (std::string line; std::getline(in, line);) {
    const size_t colon = line.find(':');
    if (colon == std::string::npos) continue;
    std::istringstream items(line.substr(colon + 1));
    std::set<std::string>& closure = graph[line.substr(0, colon)];
    for (std::string item; items >> item;) closure.insert(item);
  }
  return graph;
}

/// The items of `target`'s closure that contain any of `forbidden` (case-insensitive): e.g.
/// {"avp_sim", "embree", "assimp"}.
std::vector<std::string> ForbiddenLinks(const LinkGraph& graph, const std::string& target,
                                        const std::vector<std::string>& forbidden) {
  std::vector<std::string> found;
  const auto it = graph.find(target);
  if (it == graph.end()) return found;
  auto lower = [](std::string t) {
    for (char& c : t) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return t;
  };
  for (const std::string& item : it->second) {
    for (const std::string& f : forbidden) {
      if (lower(item).find(f) != std::string::npos) found.push_back(item);
    }
  }
  return found;
}

const LinkGraph& TheLinkGraph() {
  static const LinkGraph graph = ReadLinkGraph(AVP_LINK_GRAPH_FILE);
  return graph;
}

// Which avp modules each module may include.
const std::map<std::string, std::set<std::string>> kAllowed = {
    {"core", {"core"}},
    {"io", {"core", "io"}},
    {"robot", {"core", "io", "robot"}},
    // The simulator implements the robot interfaces (sim::SimRgbdSource, sim::SimArm).
    // It counts the arm's contacts with the true scene with the robot's collision model (motion).
    {"sim", {"core", "io", "robot", "motion", "sim"}},
    {"mapping", {"core", "io", "mapping"}},
    // Collision-free motion: the robot's collision model, the map as obstacles, OMPL and FCL.
    {"motion", {"core", "io", "robot", "mapping", "motion"}},
    {"segmentation", {"core", "io", "segmentation"}},
    {"planning", {"core", "io", "robot", "mapping", "motion", "planning"}},
    // The loop knows no simulator: a real robot runs it.
    {"pipeline",
     {"core", "io", "robot", "segmentation", "mapping", "motion", "planning", "pipeline"}},
    {"eval",
     {"core", "io", "sim", "robot", "segmentation", "mapping", "motion", "planning", "eval"}},
    {"report", {"core", "io", "mapping", "pipeline", "eval", "report"}},
    // The segmentation service, KServe v2 over gRPC: the `remote://` segmenter and `avp serve`.
    // Zero-shot segmentation backends (ONNX Runtime): zsl runs its networks on a model server
    // through the service's tensor client (tensor_service.h, no gRPC header), and serves them with
    // its tensor server (avp serve models). Both implement segmentation's Segmenter and are
    // registered with it by apps/.
    {"segmentation_service", {"core", "io", "segmentation", "segmentation_service"}},
    {"zsl", {"core", "io", "segmentation", "segmentation_service", "zsl"}},
    // The ROS wing (ros/): the messages and all their conversions (no middleware), the MCAP
    // container, the bag (avp's recording layout: the recorder and the replay's reader), the DDS
    // transport, the live robot (no simulator) and the simulator as a ROS 2 robot.
    {"ros/msg", {"core", "ros/msg"}},
    // The MCAP container links core only; its npm read-back test writes ros/msg messages.
    {"ros/mcap", {"core", "io", "ros/msg", "ros/mcap"}},
    {"ros/bag",
     {"core", "io", "robot", "mapping", "segmentation", "motion", "planning", "pipeline", "ros/msg",
      "ros/mcap", "ros/bag"}},
    {"ros/dds", {"core", "ros/msg", "ros/dds"}},
    {"ros/live",
     {"core", "io", "robot", "segmentation", "mapping", "motion", "planning", "pipeline", "ros/msg",
      "ros/dds", "ros/live"}},
    {"ros/simrobot",
     {"core", "io", "robot", "motion", "sim", "ros/msg", "ros/dds", "ros/live", "ros/simrobot"}},
    // RunLiveToFolder (avp live, built with AVP_WITH_ROS2) drives the ROS 2 robot of ros/live/.
    {"experiment",
     {"core", "io", "sim", "robot", "segmentation", "mapping", "motion", "planning", "pipeline",
      "eval", "report", "ros/mcap", "ros/bag", "ros/msg", "ros/dds", "ros/live", "experiment"}},
};

// The external headers a module may include although they are in kForbiddenPrefixes.
const std::map<std::string, std::set<std::string>> kAllowedExternal = {
    {"zsl", {"onnxruntime"}},
    // The learned gain's ONNX model (planning/src/learned_gain.cpp, the only file that does).
    {"planning", {"onnxruntime"}},
    {"segmentation_service", {"grpc", "grpcpp/"}},
    {"ros/dds", {"dds/", "ddsc/", "spdlog/"}},
    {"ros/live", {"spdlog/"}},
    {"ros/simrobot", {"spdlog/"}},
};

/// A module's library target: its folder with "_" for "/" ("ros/msg" -> "avp_ros_msg").
std::string TargetOf(const std::string& module) {
  std::string target = "avp_" + module;
  for (char& c : target) c = c == '/' ? '_' : c;
  return target;
}

/// The module a library target belongs to ("avp_ros_msg" -> "ros/msg"); "" for other targets.
std::string ModuleOfTarget(const std::string& target) {
  for (const auto& [module, allowed] : kAllowed) {
    if (TargetOf(module) == target) return module;
  }
  return "";
}

/// The module whose headers `header` ("avp/ros/msg/images.h") is among: the longest module
/// folder it starts with ("ros/msg"); else its first folder after avp/.
std::string ModuleOfHeader(const std::string& header) {
  const std::string path = header.substr(4);
  std::string best;
  for (const auto& [module, allowed] : kAllowed) {
    if (path.rfind(module + "/", 0) == 0 && module.size() > best.size()) best = module;
  }
  return best.empty() ? path.substr(0, path.find('/')) : best;
}

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
      const std::string target = ModuleOfHeader(inc.header);
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
            << ">: only apps/ and the modules that wrap them may include " << prefix << "* headers";
      }
    }
  }
}

TEST(ArchitectureTest, ThePipelineLinksNoSimulator) {
  const LinkGraph& graph = TheLinkGraph();
  ASSERT_TRUE(graph.count("avp_pipeline")) << "no link graph at " << AVP_LINK_GRAPH_FILE;
  EXPECT_THAT(ForbiddenLinks(graph, "avp_pipeline", {"avp_sim", "embree"}), ::testing::IsEmpty())
      << "avp::pipeline runs on a real robot: it may not link the simulator";
  // The check sees the simulator where it is: the simulator itself, and the experiment runner.
  EXPECT_THAT(ForbiddenLinks(graph, "avp_sim", {"embree", "assimp"}), ::testing::SizeIs(2));
  EXPECT_THAT(ForbiddenLinks(graph, "avp_experiment", {"avp_sim"}),
              ::testing::ElementsAre("avp_sim"));
}

TEST(ArchitectureTest, TheLiveRobotLinksNoSimulator) {
  const LinkGraph& graph = TheLinkGraph();
  if (!graph.count("avp_ros_live")) {
    GTEST_SKIP() << "built without AVP_WITH_ROS2: no avp_ros_live in " << AVP_LINK_GRAPH_FILE;
  }
  EXPECT_THAT(ForbiddenLinks(graph, "avp_ros_live", {"avp_sim", "embree"}), ::testing::IsEmpty())
      << "avp::ros::live drives a real robot: it may not link the simulator";
  EXPECT_THAT(ForbiddenLinks(graph, "avp_ros_simrobot", {"avp_sim"}),
              ::testing::ElementsAre("avp_sim"));
}

TEST(ArchitectureTest, ForbiddenLinksFindsASimulatorInTheClosure) {
  // What the test above would see if pipeline linked sim (CMake writes the closure).
  std::istringstream text(
      "avp_pipeline: Eigen3::Eigen avp_core avp_robot avp_sim assimp::assimp embree\n"
      "avp_robot: avp_core\n");
  const fs::path file = fs::temp_directory_path() / "avp_link_graph_test.txt";
  std::ofstream(file) << text.str();
  const LinkGraph graph = ReadLinkGraph(file);
  fs::remove(file);
  EXPECT_THAT(ForbiddenLinks(graph, "avp_pipeline", {"avp_sim", "embree", "assimp"}),
              ::testing::ElementsAre("assimp::assimp", "avp_sim", "embree"));
  EXPECT_THAT(ForbiddenLinks(graph, "avp_robot", {"avp_sim"}), ::testing::IsEmpty());
}

/// The modules `module` may reach through its dependencies (kAllowed, transitively).
std::set<std::string> TransitivelyAllowed(const std::string& module) {
  std::set<std::string> reached;
  std::vector<std::string> work = {module};
  while (!work.empty()) {
    const std::string m = work.back();
    work.pop_back();
    if (!reached.insert(m).second) continue;
    const auto it = kAllowed.find(m);
    if (it != kAllowed.end()) work.insert(work.end(), it->second.begin(), it->second.end());
  }
  return reached;
}

TEST(ArchitectureTest, HeadersAndTargetsNameTheirModules) {
  EXPECT_EQ(ModuleOfHeader("avp/ros/msg/images.h"), "ros/msg");
  EXPECT_EQ(ModuleOfHeader("avp/ros/bag/bag_reader.h"), "ros/bag");
  EXPECT_EQ(ModuleOfHeader("avp/pipeline/view_fusion.h"), "pipeline");
  EXPECT_EQ(ModuleOfHeader("avp/nowhere/x.h"), "nowhere");  // not a module: the rules refuse it
  EXPECT_EQ(TargetOf("ros/simrobot"), "avp_ros_simrobot");
  EXPECT_EQ(ModuleOfTarget("avp_ros_dds"), "ros/dds");
  EXPECT_EQ(ModuleOfTarget("avp_opencv"), "");
}

// Every library CMake builds is a module the rules know: a new module must be placed in kAllowed.
TEST(ArchitectureTest, EveryLibraryIsAModuleOfTheRules) {
  const LinkGraph& graph = TheLinkGraph();
  ASSERT_FALSE(graph.empty()) << "no link graph at " << AVP_LINK_GRAPH_FILE;
  for (const auto& [target, closure] : graph) {
    EXPECT_NE(ModuleOfTarget(target), "")
        << target << " is a library but not a module of kAllowed (tests/architecture_test.cpp)";
  }
}

TEST(ArchitectureTest, ModulesLinkOnlyModulesBelowThem) {
  const LinkGraph& graph = TheLinkGraph();
  for (const auto& [module, direct] : kAllowed) {
    const std::set<std::string> allowed = TransitivelyAllowed(module);
    const auto it = graph.find(TargetOf(module));
    // The ROS 2 modules are built only with AVP_WITH_ROS2 (Cyclone DDS found).
    const bool optional = module == "ros/dds" || module == "ros/live" || module == "ros/simrobot";
    if (it == graph.end() && optional) continue;
    ASSERT_NE(it, graph.end()) << TargetOf(module) << " is not in the link graph";
    for (const std::string& item : it->second) {
      if (item.rfind("avp_", 0) != 0) continue;
      const std::string target = ModuleOfTarget(item);
      if (target.empty()) continue;  // helpers: avp_opencv, avp_segmentation_service_proto
      EXPECT_TRUE(allowed.count(target) > 0) << TargetOf(module) << " links " << item << ", but "
                                             << module << " may not depend on " << target;
    }
  }
}

/// The lines of `text` (a source file) that use the integrator: name the type
/// `mapping::Integrator` or call an `Integrate(` method, outside comments and string literals.
std::vector<int> IntegratingLines(std::istream& text) {
  const std::regex uses(R"(\bIntegrator\b|(\.|->)\s*Integrate\s*\()");
  const std::regex literal(R"("([^"\\]|\\.)*")");
  std::vector<int> lines;
  int number = 0;
  for (std::string line; std::getline(text, line);) {
    ++number;
    line = std::regex_replace(line, literal, "\"\"");
    const size_t comment = line.find("//");
    if (comment != std::string::npos) line.resize(comment);
    if (std::regex_search(line, uses)) lines.push_back(number);
  }
  return lines;
}

// One loop: pipeline::ViewFusion is the only code that fuses a view into a map (the episode,
// `avp replay` and `avp map build` all go through it). The integrator's own module and the
// unit tests and benchmarks that measure it are the exceptions.
TEST(ArchitectureTest, OnlyThePipelineIntegratesAView) {
  std::vector<std::string> modules = {"apps"};
  for (const auto& [module, allowed] : kAllowed) modules.push_back(module);
  for (const std::string& module : modules) {
    if (module == "mapping" || module == "pipeline") continue;
    for (const auto& entry : fs::recursive_directory_iterator(kSourceRoot / module)) {
      const std::string ext = entry.path().extension().string();
      if ((ext != ".h" && ext != ".cpp") || entry.path().parent_path().filename() == "test") {
        continue;
      }
      std::ifstream in(entry.path());
      for (int line : IntegratingLines(in)) {
        ADD_FAILURE() << entry.path().string() << ":" << line << " (module " << module
                      << ") integrates into a map: fuse views through pipeline::ViewFusion "
                         "(pipeline/view_fusion.h)";
      }
    }
  }
}

TEST(ArchitectureTest, IntegratingLinesFindsAnIntegrator) {
  std::istringstream text(
      "const mapping::Integrator integrator(options);  // line 1\n"
      "auto stats = integrator.Integrate(frame, &seg, map);\n"
      "mapping::IntegratorOptions o;  // the options are fine\n"
      "// a mapping::Integrator in a comment is fine\n"
      "p->Integrate (frame, nullptr, map);\n"
      "AddOption(\"--threads\", \"Integrator threads\");  // a string is fine\n");
  EXPECT_THAT(IntegratingLines(text), ::testing::ElementsAre(1, 2, 5));
}

}  // namespace

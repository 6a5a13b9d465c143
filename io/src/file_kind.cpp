#include <algorithm>
#include <string>
#include <string_view>

#include <avp/io/file_kind.h>

namespace avp::io {

std::string DescribeFileKind(std::string_view text) {
  const auto starts = [&](std::string_view magic) { return text.substr(0, magic.size()) == magic; };
  const std::string_view head = text.substr(0, 4096);
  if (starts("\x89PNG\r\n\x1a\n")) return "a PNG image";
  if (starts("\xff\xd8\xff")) return "a JPEG image";
  if (starts("\x89MCAP")) return "an MCAP recording";
  if (starts("\x89"
             "AVPMAP\n"))
    return "an avp map (.avpmap)";
  if (starts("SQLite format 3")) return "an SQLite database (a rosbag2 .db3?)";
  if (starts("# Octomap OcTree")) return "an OctoMap map (.bt / .ot)";
  if (starts("ply\n") || starts("ply\r\n")) return "a PLY mesh or point cloud";
  if (starts("glTF")) return "a binary glTF mesh (.glb)";
  if (starts("PK\x03\x04")) return "a zip archive";
  if (head.find("<COLLADA") != std::string_view::npos) return "a COLLADA mesh (.dae)";
  if (starts("solid ") && head.find("facet normal") != std::string_view::npos) {
    return "an STL mesh";
  }
  if (head.find('\0') != std::string_view::npos) return "a binary file";
  // The JSON files avp writes, by the keys only they have.
  const size_t first = head.find_first_not_of(" \t\r\n");
  if (first != std::string_view::npos && head[first] == '{') {
    const std::string_view json =
        text.substr(0, 1 << 16);  // bench.json's format follows its job list
    const auto has = [&](std::string_view key) { return json.find(key) != std::string_view::npos; };
    if (has("\"avp-bench")) return "an avp bench record (bench.json)";
    if (has("\"end_reason\"") && has("\"planner\"")) return "an avp run record (record.json)";
    if (has("\"state\"") && has("\"kind\"") && has("\"command\"")) {
      return "an avp folder state file (avp-state.json)";
    }
    return "";
  }
  // A Wavefront OBJ: lines "v x y z", "f a b c", "mtllib ...", none with a YAML colon.
  size_t obj_lines = 0, lines = 0;
  for (size_t pos = 0; pos < head.size() && lines < 64; ++lines) {
    const size_t end = std::min(head.find('\n', pos), head.size());
    const std::string_view line = head.substr(pos, end - pos);
    pos = end + 1;
    if (!line.empty() && line[0] == '#') continue;  // comments (an exporter's URL) say nothing
    if (line.find(':') != std::string_view::npos) return "";
    for (const std::string_view tag : {"v ", "vn ", "vt ", "f ", "mtllib ", "usemtl ", "o "}) {
      if (line.substr(0, tag.size()) == tag) ++obj_lines;
    }
  }
  if (obj_lines >= 3) return "a Wavefront OBJ mesh";
  return "";
}

}  // namespace avp::io

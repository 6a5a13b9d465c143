#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include <fmt/format.h>
#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/parser.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/file_kind.h>
#include <avp/io/yaml.h>

namespace avp::io {

namespace {

std::string Where(std::string_view context, std::string_view key) {
  return fmt::format("{}: {}", context, QuoteText(key));
}

std::string Mark(const YAML::Node& node) {
  const YAML::Mark m = node.Mark();
  if (m.line < 0) return "";
  return fmt::format(" (line {}, column {})", m.line + 1, m.column + 1);
}

/// The node's text as it may appear in a message: escaped and shortened (QuoteText), quotes
/// included.
std::string Text(const YAML::Node& node) {
  if (node.IsScalar()) return QuoteText(node.Scalar());
  YAML::Emitter out;
  out << YAML::Flow << node;
  return QuoteText(out.c_str());
}

// node[key] without yaml-cpp's exceptions, which operator[] throws for an invalid node (a const
// lookup of a missing section) and for a scalar. A missing or null section gives an undefined
// node (reported as "missing"); a scalar or sequence is an error that shows it.
Result<YAML::Node> Child(const YAML::Node& node, std::string_view key, std::string_view context) {
  if (!node.IsDefined() || node.IsNull()) return YAML::Node(YAML::NodeType::Undefined);
  if (!node.IsMap()) {
    return InvalidArgumentError(fmt::format("{}: expected a map with key '{}', got {}{}", context,
                                            key, Text(node), Mark(node)));
  }
  return node[std::string(key)];
}

}  // namespace

const Limit& MaxYamlBytes() {
  static const Limit limit("max_yaml_bytes", uint64_t{1} << 20, "bytes",
                           "size of one YAML file (run configuration, scene, arm)");
  return limit;
}

const Limit& MaxYamlDepth() {
  static const Limit limit("max_yaml_depth", 64, "levels",
                           "nesting of collections in one YAML document");
  return limit;
}

namespace {

// Registered when the program starts, so `avp --limit NAME=N` knows them before the first read.
[[maybe_unused]] const Limit& kRegisterMaxYamlBytes = MaxYamlBytes();
[[maybe_unused]] const Limit& kRegisterMaxYamlDepth = MaxYamlDepth();

bool IsSpace(char c) { return c == ' ' || c == '\t'; }

/// What a file that is not YAML is, from its first bytes ("a PNG image"), or "" for text that may
/// be YAML: so that a mesh, an image, a map or a recording given where a scene file or a
/// configuration is expected is named, not met with a parser's error.
}  // namespace

namespace {

/// What CheckYamlDepth carries from line to line.
struct YamlDepthScan {
  std::vector<size_t> block;  // indentation of the open block levels
  uint64_t flow = 0;          // open flow collections
  uint64_t flow_base = 0;     // block depth where the open flow collection started
  char quote = 0;             // inside a quoted scalar: ' or "
  bool block_scalar = false;
  size_t block_scalar_indent = 0;

  /// The block levels open at a line outside flow collections and quotes: those of deeper
  /// indentation closed, one for the line, one per compact "- " / "? " indicator ("- - x",
  /// "- ? x"); a document marker closes them all. Returns where the line's tokens start.
  size_t OpenBlockLevels(std::string_view line, size_t indent) {
    if (indent == 0 && (line.starts_with("---") || line.starts_with("..."))) {
      block.clear();
      return 3;
    }
    while (!block.empty() && block.back() >= indent) block.pop_back();
    block.push_back(indent);
    size_t at = indent;
    while (at + 1 <= line.size() && (line[at] == '-' || line[at] == '?') &&
           (at + 1 == line.size() || IsSpace(line[at + 1]))) {
      at += 1;
      while (at < line.size() && IsSpace(line[at])) ++at;
      block.push_back(at);
    }
    return at;
  }

  /// The line's tokens from `at`: quotes, comments, flow brackets (raising `depth`; the scan
  /// stops once it passes `limit`) and a block scalar header.
  void ScanTokens(std::string_view line, size_t at, size_t indent, uint64_t limit,
                  uint64_t& depth) {
    bool token_start = true;
    for (; at < line.size(); ++at) {
      const char c = line[at];
      if (quote == '\'') {
        if (c == '\'') {
          if (at + 1 < line.size() && line[at + 1] == '\'') {
            ++at;
          } else {
            quote = 0;
          }
        }
        continue;
      }
      if (quote == '"') {
        if (c == '\\') {
          ++at;
        } else if (c == '"') {
          quote = 0;
        }
        continue;
      }
      if (c == '#' && (at == 0 || IsSpace(line[at - 1]))) break;
      if ((c == '\'' || c == '"') && token_start) {
        quote = c;
        continue;
      }
      if ((c == '[' || c == '{') && (flow > 0 || token_start)) {
        ++flow;
        if (flow_base + flow > depth) depth = flow_base + flow;
        if (depth > limit) break;
        token_start = true;
        continue;
      }
      if ((c == ']' || c == '}') && flow > 0) {
        --flow;
        token_start = false;
        continue;
      }
      if (flow == 0 && (c == '|' || c == '>') && token_start) {
        // A block scalar header: its content is the following, more indented lines.
        block_scalar = true;
        block_scalar_indent = indent;
        break;
      }
      token_start = IsSpace(c) || c == ',' || c == ':' || c == '-' || c == '?';
    }
  }
};

}  // namespace

Status CheckYamlDepth(std::string_view text, std::string_view name) {
  // An upper estimate of the collections open at each point, without parsing: block collections
  // from the indentation (each deeper indentation and each compact "- " / "? " indicator opens
  // one), flow collections from the brackets outside quotes and comments. Block scalars (| >)
  // are skipped. A document that passes cannot make yaml-cpp's recursive parser (or anything
  // that walks the nodes) go deeper than this.
  const uint64_t limit = MaxYamlDepth().value();
  YamlDepthScan scan;
  size_t line_no = 0;
  size_t start = 0;
  while (start <= text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(start, end - start);
    start = end + 1;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    size_t indent = 0;
    while (indent < line.size() && line[indent] == ' ') ++indent;
    const bool blank = indent == line.size();
    if (scan.block_scalar) {
      if (blank || indent > scan.block_scalar_indent) continue;
      scan.block_scalar = false;
    }
    size_t at = 0;
    uint64_t depth = scan.flow_base + scan.flow;
    if (scan.flow == 0 && scan.quote == 0) {
      if (blank || line[indent] == '#') continue;
      at = scan.OpenBlockLevels(line, indent);
      depth = scan.block.size();
      scan.flow_base = depth;
    }
    scan.ScanTokens(line, at, indent, limit, depth);
    if (depth > limit) {
      return MaxYamlDepth().Check(
          fmt::format("YAML {}: collections nested at line {}", name, line_no), depth);
    }
  }
  return Status::Ok();
}

namespace {

/// Finds a key given twice in one map, from the parser's events (aliases are not expanded, so an
/// alias bomb costs nothing here). yaml-cpp keeps both entries and every lookup finds the first:
/// a later value would be ignored silently.
class DuplicateKeyFinder final : public YAML::EventHandler {
 public:
  /// "key 'a' is given twice (lines 1 and 3)", or "" when every map's keys differ.
  const std::string& problem() const { return problem_; }

  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& mark, YAML::anchor_t) override { Element(mark, nullptr); }
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t) override { Element(mark, nullptr); }
  void OnScalar(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                const std::string& value) override {
    Element(mark, &value);
  }
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {
    frames_.push_back({false, true, {}});
  }
  void OnSequenceEnd() override { End(); }
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {
    frames_.push_back({true, true, {}});
  }
  void OnMapEnd() override { End(); }

 private:
  struct Frame {
    bool is_map;
    bool expecting_key;
    /// Scalar keys and their lines (1-based): one hash lookup per key, so that a map of many
    /// keys (as many as MaxYamlBytes allows) costs linear time, not quadratic.
    std::unordered_map<std::string, int> keys;
  };

  /// A complete element of the enclosing collection: a key or a value of a map alternately.
  void Element(const YAML::Mark& mark, const std::string* scalar) {
    if (frames_.empty() || !frames_.back().is_map) return;
    Frame& f = frames_.back();
    if (f.expecting_key && scalar != nullptr && problem_.empty()) {
      const auto [it, added] = f.keys.emplace(*scalar, mark.line + 1);
      if (!added) {
        problem_ = fmt::format("key {} is given twice (lines {} and {})", QuoteText(*scalar),
                               it->second, mark.line + 1);
      }
    }
    f.expecting_key = !f.expecting_key;
  }

  void End() {
    if (!frames_.empty()) frames_.pop_back();
    Element(YAML::Mark(), nullptr);  // the collection was an element of its parent
  }

  std::vector<Frame> frames_;
  std::string problem_;
};

}  // namespace

Result<YAML::Node> ParseYaml(std::string_view text, std::string_view name) {
  AVP_RETURN_IF_ERROR(
      MaxYamlBytes().Check(fmt::format("YAML {} of {} bytes", name, text.size()), text.size()));
  AVP_RETURN_IF_ERROR(CheckYamlDepth(text, name));
  try {
    std::istringstream in{std::string(text)};
    YAML::Parser parser(in);
    DuplicateKeyFinder duplicates;
    // The first document only, as YAML::Load reads it. (Looping until HandleNextDocument returns
    // false never ends on some malformed input: yaml-cpp 0.7 then keeps returning true without
    // reading on; fuzz/regressions/scene_file/flow-end-then-question-mark-yaml-cpp-loop.yaml.)
    parser.HandleNextDocument(duplicates);
    if (!duplicates.problem().empty()) {
      return InvalidArgumentError(
          fmt::format("YAML {}: {}; remove one (YAML would keep the first and ignore the other)",
                      name, duplicates.problem()));
    }
    return YAML::Load(std::string(text));
  } catch (const YAML::DeepRecursion& e) {
    return ResourceExhaustedError(
        fmt::format("YAML {} nests deeper than yaml-cpp allows ({} levels at line {}, column {})",
                    name, e.depth(), e.mark.line + 1, e.mark.column + 1));
  } catch (const YAML::ParserException& e) {
    return ParseError(fmt::format("malformed YAML in {} at line {}, column {}: {}", name,
                                  e.mark.line + 1, e.mark.column + 1, EscapeText(e.msg)));
  } catch (const YAML::Exception& e) {
    return ParseError(fmt::format("cannot read YAML {}: {}", name, EscapeText(e.what())));
  }
}

Result<YAML::Node> LoadYamlFile(const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(const uint64_t size, CheckReadableFile(path, "YAML file"));
  AVP_RETURN_IF_ERROR(
      MaxYamlBytes().Check(fmt::format("YAML file '{}' of {} bytes", path.string(), size), size));
  AVP_ASSIGN_OR_RETURN(const std::string text, ReadFileBounded(path, "YAML file"));
  if (const std::string kind = DescribeFileKind(text); !kind.empty()) {
    return InvalidArgumentError(fmt::format(
        "'{}' is {}, not a YAML file (scene files, run and bench configurations and arm configs "
        "are YAML; docs/scene-format.md, docs/experiments.md)",
        path.string(), kind));
  }
  return ParseYaml(text, fmt::format("'{}'", path.string()));
}

Status RejectUnknownKeys(const YAML::Node& node, std::initializer_list<std::string_view> allowed,
                         std::string_view context) {
  if (!node.IsDefined() || node.IsNull()) return Status::Ok();
  if (!node.IsMap()) {
    return InvalidArgumentError(
        fmt::format("{}: expected a map of keys, got {}{}", context, Text(node), Mark(node)));
  }
  std::vector<std::string> unknown;
  for (const auto& kv : node) {
    if (!kv.first.IsScalar()) {
      return InvalidArgumentError(fmt::format("{}: a key must be a name, got {}{}", context,
                                              Text(kv.first), Mark(kv.first)));
    }
    const std::string key = kv.first.Scalar();
    if (std::find(allowed.begin(), allowed.end(), key) == allowed.end()) unknown.push_back(key);
  }
  if (unknown.empty()) return Status::Ok();
  std::vector<std::string> sorted(allowed.begin(), allowed.end());
  std::sort(sorted.begin(), sorted.end());
  std::vector<std::string> quoted;
  for (const std::string& k : unknown) quoted.push_back(QuoteText(k));
  return InvalidArgumentError(fmt::format("{}: unknown key{} {}{} (allowed: {})", context,
                                          unknown.size() > 1 ? "s" : "", fmt::join(quoted, ", "),
                                          Mark(node), fmt::join(sorted, ", ")));
}

Result<double> ReadDouble(const YAML::Node& node, std::string_view key, std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node v, Child(node, key, context));
  if (!v.IsDefined() || v.IsNull()) {
    return InvalidArgumentError(fmt::format("{} is missing", Where(context, key)));
  }
  double out = 0.0;
  if (!v.IsScalar() || !YAML::convert<double>::decode(v, out) || !std::isfinite(out)) {
    return InvalidArgumentError(
        fmt::format("{} must be a finite number, got {}{}", Where(context, key), Text(v), Mark(v)));
  }
  return out;
}

Result<int64_t> ReadInt(const YAML::Node& node, std::string_view key, std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node v, Child(node, key, context));
  if (!v.IsDefined() || v.IsNull()) {
    return InvalidArgumentError(fmt::format("{} is missing", Where(context, key)));
  }
  int64_t out = 0;
  if (!v.IsScalar() || !YAML::convert<int64_t>::decode(v, out)) {
    return InvalidArgumentError(
        fmt::format("{} must be an integer, got {}{}", Where(context, key), Text(v), Mark(v)));
  }
  return out;
}

Result<std::string> ReadString(const YAML::Node& node, std::string_view key,
                               std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node v, Child(node, key, context));
  if (!v.IsDefined() || v.IsNull()) {
    return InvalidArgumentError(fmt::format("{} is missing", Where(context, key)));
  }
  if (!v.IsScalar()) {
    return InvalidArgumentError(
        fmt::format("{} must be a string, got {}{}", Where(context, key), Text(v), Mark(v)));
  }
  return v.Scalar();
}

Result<bool> ReadBool(const YAML::Node& node, std::string_view key, std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node v, Child(node, key, context));
  if (!v.IsDefined() || v.IsNull()) {
    return InvalidArgumentError(fmt::format("{} is missing", Where(context, key)));
  }
  bool out = false;
  if (!v.IsScalar() || !YAML::convert<bool>::decode(v, out)) {
    return InvalidArgumentError(
        fmt::format("{} must be true or false, got {}{}", Where(context, key), Text(v), Mark(v)));
  }
  return out;
}

Result<std::vector<double>> ReadDoubles(const YAML::Node& node, std::string_view key,
                                        std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node v, Child(node, key, context));
  if (!v.IsDefined() || v.IsNull()) {
    return InvalidArgumentError(fmt::format("{} is missing", Where(context, key)));
  }
  if (!v.IsSequence()) {
    return InvalidArgumentError(fmt::format("{} must be a list of numbers, got {}{}",
                                            Where(context, key), Text(v), Mark(v)));
  }
  std::vector<double> out;
  for (size_t i = 0; i < v.size(); ++i) {
    double x = 0.0;
    if (!v[i].IsScalar() || !YAML::convert<double>::decode(v[i], x) || !std::isfinite(x)) {
      return InvalidArgumentError(fmt::format("{}[{}] must be a finite number, got {}{}",
                                              Where(context, key), i, Text(v[i]), Mark(v[i])));
    }
    out.push_back(x);
  }
  return out;
}

Result<Eigen::VectorXd> ReadVector(const YAML::Node& node, std::string_view key, int size,
                                   std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const std::vector<double> values, ReadDoubles(node, key, context));
  if (static_cast<int>(values.size()) != size) {
    return InvalidArgumentError(fmt::format("{} must have {} numbers, got {}: [{}]",
                                            Where(context, key), size, values.size(),
                                            fmt::join(values, ", ")));
  }
  return Eigen::Map<const Eigen::VectorXd>(values.data(), size).eval();
}

Result<RigidTransform> ReadPose(const YAML::Node& node, std::string_view key,
                                std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const YAML::Node v, Child(node, key, context));
  if (!v.IsDefined() || v.IsNull()) {
    return InvalidArgumentError(fmt::format("{} is missing", Where(context, key)));
  }
  const std::string ctx = fmt::format("{}.{}", context, key);
  AVP_RETURN_IF_ERROR(RejectUnknownKeys(v, {"xyz", "rpy", "rpy_deg"}, ctx));
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();
  if (v["xyz"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(xyz, ReadVector(v, "xyz", 3, ctx));
  }
  if (v["rpy"].IsDefined() && v["rpy_deg"].IsDefined()) {
    return InvalidArgumentError(fmt::format("{}: give either 'rpy' or 'rpy_deg', not both", ctx));
  }
  if (v["rpy"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(rpy, ReadVector(v, "rpy", 3, ctx));
  } else if (v["rpy_deg"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(rpy, ReadVector(v, "rpy_deg", 3, ctx));
    rpy *= EIGEN_PI / 180.0;
  }
  return RigidTransform::FromRpy(rpy, xyz);
}

}  // namespace avp::io

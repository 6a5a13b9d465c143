#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <limits>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <system_error>
#include <unordered_map>
#include <vector>

#include <Eigen/Geometry>
#include <assimp/DefaultLogger.hpp>
#include <assimp/Importer.hpp>
#include <assimp/Logger.hpp>
#include <assimp/config.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <yaml-cpp/yaml.h>

#include <avp/core/error.h>
#include <avp/core/semantic_class.h>
#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/yaml.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>

#include "scene_textures.h"

namespace avp::sim {

const Limit& MaxMeshVertices() {
  static const Limit limit("max_mesh_vertices", uint64_t{1} << 24, "vertices",
                           "vertices of one mesh file of a scene, and of all of them together");
  return limit;
}

const Limit& MaxMeshFaces() {
  static const Limit limit("max_mesh_faces", uint64_t{1} << 25, "faces",
                           "faces of one mesh file of a scene, and triangles of all of them");
  return limit;
}

const Limit& MaxMeshFileBytes() {
  static const Limit limit("max_mesh_file_bytes", uint64_t{1} << 30, "bytes",
                           "size of one mesh file of a scene");
  return limit;
}

const Limit& MaxSceneTexturePixels() {
  static const Limit limit("max_scene_texture_pixels", uint64_t{256} << 20, "pixels",
                           "texture pixels one mesh file of a scene keeps decoded, all images");
  return limit;
}

namespace {

namespace fs = std::filesystem;

// Registered when the program starts, so `avp --limit NAME=N` knows them before a scene is read.
[[maybe_unused]] const Limit& kRegisterMaxMeshVertices = MaxMeshVertices();
[[maybe_unused]] const Limit& kRegisterMaxMeshFaces = MaxMeshFaces();
[[maybe_unused]] const Limit& kRegisterMaxMeshFileBytes = MaxMeshFileBytes();

enum class UpAxis { kAuto, kY, kZ };
enum class FruitInstances { kObjects, kComponents };
/// `materials:` use: material colours (and textures) win over class defaults; ignore: class
/// defaults; auto: as use, except placeholder colours (docs/scene-format.md).
enum class MaterialMode { kAuto, kUse, kIgnore };
enum class SmallParts { kMerge, kDrop };

/// `merge: [{match: "Fruit*_calyx", into: "Fruit*"}]`: a part whose node or mesh name matches
/// `match` joins the part named `into`, with each '*' of `into` replaced by what the
/// corresponding '*' of `match` matched.
struct MergeRule {
  std::string match;
  std::string into;
};

struct ClassRule {
  std::string pattern;
  SemanticClass semantic_class = SemanticClass::kOther;
  std::optional<Eigen::Vector3f> color;
};

struct MeshEntry {
  fs::path file;  // resolved
  std::string file_text;
  RigidTransform X_WM;
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
  UpAxis up_axis = UpAxis::kAuto;
  SemanticClass default_class = SemanticClass::kOther;
  std::optional<Eigen::Vector3f> color;
  FruitInstances fruit_instances = FruitInstances::kObjects;
  std::vector<ClassRule> rules;
  MaterialMode materials = MaterialMode::kAuto;
  /// A fruit instance whose bounding box is under this volume, or that has fewer vertices, is a
  /// fragment: it joins its nearest fruit within fruit_merge_reach_mm (merge) or is dropped.
  double fruit_min_volume_cm3 = 0.0;
  int64_t fruit_min_vertices = 0;
  SmallParts fruit_small_parts = SmallParts::kMerge;
  double fruit_merge_reach_mm = 10.0;
  std::vector<MergeRule> merge;
};

}  // namespace

Eigen::Vector3f DefaultClassColor(SemanticClass c) {
  switch (c) {
    case SemanticClass::kFruit:
      return {0.55f, 0.05f, 0.03f};
    case SemanticClass::kLeaf:
      return {0.08f, 0.25f, 0.05f};
    case SemanticClass::kStem:
      return {0.16f, 0.30f, 0.07f};
    case SemanticClass::kSupport:
      return {0.33f, 0.22f, 0.11f};
    case SemanticClass::kGround:
      return {0.15f, 0.10f, 0.065f};
    default:
      return {0.5f, 0.5f, 0.5f};
  }
}

bool IsAchromatic(const Eigen::Vector3f& rgb) {
  const float hi = rgb.maxCoeff();
  const float lo = rgb.minCoeff();
  return hi < 0.01f || (hi - lo) < kAchromaticSaturation * hi;
}

std::string_view ToString(ColorSource source) {
  switch (source) {
    case ColorSource::kRule:
      return "rule";
    case ColorSource::kEntry:
      return "entry";
    case ColorSource::kTexture:
      return "texture";
    case ColorSource::kMaterial:
      return "material";
    case ColorSource::kClassDefault:
      return "class default";
    case ColorSource::kPlaceholder:
      return "placeholder replaced";
  }
  return "?";
}

namespace {

/// A class whose default colour has a hue: an achromatic material colour shared by all its parts
/// is taken for a placeholder under `materials: auto`.
bool ChromaticClass(SemanticClass c) { return !IsAchromatic(DefaultClassColor(c)); }

std::string KnownClasses() {
  std::vector<std::string> names;
  for (const SemanticClass c : AllSemanticClasses()) names.emplace_back(ToString(c));
  return fmt::format("{}", fmt::join(names, ", "));
}

Result<SemanticClass> ReadClass(const YAML::Node& node, std::string_view key,
                                std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const std::string name, io::ReadString(node, key, context));
  const std::optional<SemanticClass> c = SemanticClassFromString(name);
  if (!c) {
    return InvalidArgumentError(fmt::format("{}.{}: unknown semantic class {} (known: {})", context,
                                            key, QuoteText(name), KnownClasses()));
  }
  return *c;
}

Result<Eigen::Vector3f> ReadColor(const YAML::Node& node, std::string_view key,
                                  std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd v, io::ReadVector(node, key, 3, context));
  if ((v.array() < 0.0).any() || (v.array() > 1.0).any()) {
    return InvalidArgumentError(
        fmt::format("{}.{}: colour [{}, {}, {}] must be linear RGB with every value in [0, 1]",
                    context, key, v[0], v[1], v[2]));
  }
  return Eigen::Vector3f(v.cast<float>());
}

Result<MeshEntry> ReadMeshEntry(const YAML::Node& node, const fs::path& base_dir,
                                const std::string& context) {
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(
      node,
      {"file", "pose", "scale", "up_axis", "default_class", "color", "fruit_instances", "classes",
       "materials", "fruit_min_volume_cm3", "fruit_min_vertices", "fruit_small_parts",
       "fruit_merge_reach_mm", "merge"},
      context));
  MeshEntry entry;
  AVP_ASSIGN_OR_RETURN(entry.file_text, io::ReadString(node, "file", context));
  const fs::path file(entry.file_text);
  entry.file = file.is_absolute() ? file : base_dir / file;
  std::error_code ec;
  if (!fs::is_regular_file(entry.file, ec)) {
    return NotFoundError(fmt::format(
        "{}.file: mesh file '{}' does not exist (given as {})", context,
        EscapeText(entry.file.lexically_normal().string(), 300), QuoteText(entry.file_text)));
  }
  if (node["pose"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.X_WM, io::ReadPose(node, "pose", context));
  }
  if (const YAML::Node scale = node["scale"]; scale.IsDefined()) {
    if (scale.IsSequence()) {
      AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd s, io::ReadVector(node, "scale", 3, context));
      entry.scale = s;
    } else {
      AVP_ASSIGN_OR_RETURN(const double s, io::ReadDouble(node, "scale", context));
      entry.scale = Eigen::Vector3d::Constant(s);
    }
    if ((entry.scale.array() <= 0.0).any()) {
      return InvalidArgumentError(fmt::format("{}.scale: [{}, {}, {}] must be > 0", context,
                                              entry.scale.x(), entry.scale.y(), entry.scale.z()));
    }
  }
  if (node["up_axis"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(const std::string up, io::ReadString(node, "up_axis", context));
    if (up == "y") {
      entry.up_axis = UpAxis::kY;
    } else if (up == "z") {
      entry.up_axis = UpAxis::kZ;
    } else {
      return InvalidArgumentError(
          fmt::format("{}.up_axis: must be 'y' or 'z', got {}", context, QuoteText(up)));
    }
  }
  if (node["default_class"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.default_class, ReadClass(node, "default_class", context));
  }
  if (node["color"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.color, ReadColor(node, "color", context));
  }
  if (node["fruit_instances"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(const std::string mode, io::ReadString(node, "fruit_instances", context));
    if (mode == "objects") {
      entry.fruit_instances = FruitInstances::kObjects;
    } else if (mode == "components") {
      entry.fruit_instances = FruitInstances::kComponents;
    } else {
      return InvalidArgumentError(
          fmt::format("{}.fruit_instances: must be 'objects' or 'components', got {}", context,
                      QuoteText(mode)));
    }
  }
  if (const YAML::Node classes = node["classes"]; classes.IsDefined()) {
    if (!classes.IsSequence()) {
      return InvalidArgumentError(
          fmt::format("{}.classes: must be a list of {{match, class, color}} rules", context));
    }
    for (size_t i = 0; i < classes.size(); ++i) {
      const std::string rule_context = fmt::format("{}.classes[{}]", context, i);
      const YAML::Node r = classes[i];
      AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(r, {"match", "class", "color"}, rule_context));
      ClassRule rule;
      AVP_ASSIGN_OR_RETURN(rule.pattern, io::ReadString(r, "match", rule_context));
      AVP_ASSIGN_OR_RETURN(rule.semantic_class, ReadClass(r, "class", rule_context));
      if (r["color"].IsDefined()) {
        AVP_ASSIGN_OR_RETURN(rule.color, ReadColor(r, "color", rule_context));
      }
      entry.rules.push_back(std::move(rule));
    }
  }
  if (node["materials"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(const std::string mode, io::ReadString(node, "materials", context));
    if (mode == "auto") {
      entry.materials = MaterialMode::kAuto;
    } else if (mode == "use") {
      entry.materials = MaterialMode::kUse;
    } else if (mode == "ignore") {
      entry.materials = MaterialMode::kIgnore;
    } else {
      return InvalidArgumentError(fmt::format(
          "{}.materials: must be 'auto', 'use' or 'ignore', got {}", context, QuoteText(mode)));
    }
  }
  if (node["fruit_min_volume_cm3"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.fruit_min_volume_cm3,
                         io::ReadDouble(node, "fruit_min_volume_cm3", context));
    if (!std::isfinite(entry.fruit_min_volume_cm3) || entry.fruit_min_volume_cm3 < 0.0) {
      return InvalidArgumentError(fmt::format("{}.fruit_min_volume_cm3: must be >= 0, got {}",
                                              context, entry.fruit_min_volume_cm3));
    }
  }
  if (node["fruit_min_vertices"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.fruit_min_vertices,
                         io::ReadInt(node, "fruit_min_vertices", context));
    if (entry.fruit_min_vertices < 0) {
      return InvalidArgumentError(fmt::format("{}.fruit_min_vertices: must be >= 0, got {}",
                                              context, entry.fruit_min_vertices));
    }
  }
  if (node["fruit_small_parts"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(const std::string mode,
                         io::ReadString(node, "fruit_small_parts", context));
    if (mode == "merge") {
      entry.fruit_small_parts = SmallParts::kMerge;
    } else if (mode == "drop") {
      entry.fruit_small_parts = SmallParts::kDrop;
    } else {
      return InvalidArgumentError(fmt::format(
          "{}.fruit_small_parts: must be 'merge' or 'drop', got {}", context, QuoteText(mode)));
    }
  }
  if (node["fruit_merge_reach_mm"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(entry.fruit_merge_reach_mm,
                         io::ReadDouble(node, "fruit_merge_reach_mm", context));
    if (!std::isfinite(entry.fruit_merge_reach_mm) || entry.fruit_merge_reach_mm < 0.0) {
      return InvalidArgumentError(fmt::format("{}.fruit_merge_reach_mm: must be >= 0, got {}",
                                              context, entry.fruit_merge_reach_mm));
    }
  }
  if (const YAML::Node merge = node["merge"]; merge.IsDefined()) {
    if (!merge.IsSequence()) {
      return InvalidArgumentError(
          fmt::format("{}.merge: must be a list of {{match, into}} rules", context));
    }
    for (size_t i = 0; i < merge.size(); ++i) {
      const std::string rule_context = fmt::format("{}.merge[{}]", context, i);
      const YAML::Node r = merge[i];
      AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(r, {"match", "into"}, rule_context));
      MergeRule rule;
      AVP_ASSIGN_OR_RETURN(rule.match, io::ReadString(r, "match", rule_context));
      AVP_ASSIGN_OR_RETURN(rule.into, io::ReadString(r, "into", rule_context));
      if (rule.match.size() > 256 || rule.into.size() > 256) {
        return InvalidArgumentError(
            fmt::format("{}: 'match' and 'into' hold at most 256 characters (got {} and {})",
                        rule_context, rule.match.size(), rule.into.size()));
      }
      if (rule.match.empty() || rule.into.empty()) {
        return InvalidArgumentError(
            fmt::format("{}: 'match' and 'into' must not be empty (got {} and {})", rule_context,
                        QuoteText(rule.match), QuoteText(rule.into)));
      }
      entry.merge.push_back(std::move(rule));
    }
  }
  return entry;
}

std::string LowerExtension(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

Eigen::Matrix4d ToEigen(const aiMatrix4x4& m) {
  Eigen::Matrix4d out;
  for (unsigned r = 0; r < 4; ++r) {
    for (unsigned c = 0; c < 4; ++c) out(r, c) = m[r][c];
  }
  return out;
}

/// Collects what assimp logs (warnings and errors) while alive, for the error message of a failed
/// import. Assimp's logger is process-wide: one import at a time holds it (a mutex).
class AssimpMessages {
 public:
  AssimpMessages() : lock_(Mutex()) { Assimp::DefaultLogger::set(new Collector(&text_)); }
  ~AssimpMessages() { Assimp::DefaultLogger::kill(); }
  AssimpMessages(const AssimpMessages&) = delete;
  AssimpMessages& operator=(const AssimpMessages&) = delete;
  /// "; assimp said: '...'" (escaped, shortened) or empty.
  std::string Quote() const {
    return text_.empty() ? std::string() : "; assimp said: " + QuoteText(text_, 300);
  }

 private:
  class Collector : public Assimp::Logger {
   public:
    explicit Collector(std::string* text) : Assimp::Logger(Assimp::Logger::NORMAL), text_(text) {}
    bool attachStream(Assimp::LogStream*, unsigned int) override { return false; }
    bool detachStream(Assimp::LogStream*, unsigned int) override { return false; }

   private:
    void OnDebug(const char*) override {}
    void OnVerboseDebug(const char*) override {}
    void OnInfo(const char*) override {}
    void OnWarn(const char* message) override { Add("warning", message); }
    void OnError(const char* message) override { Add("error", message); }
    void Add(std::string_view kind, const char* message) {
      if (text_->size() > 4096) return;
      if (!text_->empty()) *text_ += " | ";
      *text_ += fmt::format("{}: {}", kind, message);
    }
    std::string* text_;
  };
  static std::mutex& Mutex() {
    static std::mutex mutex;
    return mutex;
  }
  std::lock_guard<std::mutex> lock_;
  std::string text_;
};

/// Bytes of one value of a PLY scalar type, 0 for an unknown type name.
size_t PlyTypeBytes(std::string_view type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "int32" || type == "uint32" || type == "float" ||
      type == "float32") {
    return 4;
  }
  if (type == "double" || type == "float64") return 8;
  return 0;
}

/// A PLY file's header, read and checked before assimp sees the file: every element's count
/// against what the rest of the file can hold (each element needs at least its fixed-size
/// properties and list counts in a binary file, two characters per property in an ASCII one), the
/// vertex count against max_mesh_vertices and the face count against max_mesh_faces. A header
/// that declares 10^9 vertices in a small file is refused here instead of making assimp reserve
/// for them.
Status CheckPlyHeader(const fs::path& file, uint64_t file_bytes, const std::string& context) {
  constexpr size_t kMaxHeaderBytes = 65536;
  std::ifstream in(file, std::ios::binary);
  std::string head(static_cast<size_t>(std::min<uint64_t>(file_bytes, kMaxHeaderBytes)), '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  if (!in && !in.eof()) {
    return IoError(fmt::format("{}.file: cannot read mesh '{}'", context, file.string()));
  }
  head.resize(static_cast<size_t>(in.gcount()));
  const auto bad = [&](const std::string& what) {
    return ParseError(
        fmt::format("{}.file: PLY mesh '{}' has a bad header: {}", context, file.string(), what));
  };
  struct Element {
    std::string name;
    uint64_t count = 0;
    uint64_t min_bytes = 0;  // per element
    size_t line = 0;
  };
  std::vector<Element> elements;
  bool binary = false;
  size_t at = 0;
  size_t line_no = 0;
  bool ended = false;
  while (!ended) {
    const size_t end = head.find('\n', at);
    if (end == std::string::npos) {
      return bad(head.size() >= kMaxHeaderBytes
                     ? fmt::format("no 'end_header' in its first {} bytes", kMaxHeaderBytes)
                     : std::string("it ends before 'end_header'"));
    }
    std::string_view line(head.data() + at, end - at);
    at = end + 1;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    std::vector<std::string_view> words;
    for (size_t i = 0; i < line.size();) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
      const size_t j = i;
      while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
      if (i > j) words.push_back(line.substr(j, i - j));
    }
    if (line_no == 1) {
      // assimp reads any file that starts with "ply" in any case as PLY, and its header parser is
      // lenient ("ply(" and "element$vertex 1000000000" pass, and then it loops over the count
      // whatever the file holds): such a file must meet this check, which wants the spec's line.
      const auto lower = [](char c) { return static_cast<char>(c | 0x20); };
      const bool ply_magic = line.size() >= 3 && lower(line[0]) == 'p' && lower(line[1]) == 'l' &&
                             lower(line[2]) == 'y';
      if (!ply_magic) return Status::Ok();  // not a PLY: assimp says so in its own words
      if (line.size() != 3) {
        return bad(fmt::format("line 1 is {}, not 'ply'", QuoteText(line)));
      }
      continue;
    }
    if (words.empty() || words[0] == "comment" || words[0] == "obj_info") continue;
    if (words[0] == "format") {
      if (words.size() != 3) return bad(fmt::format("line {}: {}", line_no, QuoteText(line)));
      if (words[1] == "ascii") {
        binary = false;
      } else if (words[1] == "binary_little_endian" || words[1] == "binary_big_endian") {
        binary = true;
      } else {
        return bad(fmt::format("line {}: unknown format {}", line_no, QuoteText(words[1])));
      }
    } else if (words[0] == "element") {
      uint64_t count = 0;
      const std::string_view n = words.size() == 3 ? words[2] : std::string_view();
      const auto [ptr, ec] = std::from_chars(n.data(), n.data() + n.size(), count);
      if (n.empty() || ec != std::errc() || ptr != n.data() + n.size()) {
        return bad(fmt::format("line {}: {} is not 'element <name> <count>' with a whole count",
                               line_no, QuoteText(line)));
      }
      elements.push_back({std::string(words[1]), count, 0, line_no});
    } else if (words[0] == "property") {
      if (elements.empty())
        return bad(fmt::format("line {}: a property before any element", line_no));
      Element& e = elements.back();
      if (words.size() == 5 && words[1] == "list") {
        const size_t count_bytes = PlyTypeBytes(words[2]);
        if (count_bytes == 0 || PlyTypeBytes(words[3]) == 0) {
          return bad(fmt::format("line {}: unknown type in {}", line_no, QuoteText(line)));
        }
        e.min_bytes += binary ? count_bytes : 2;
      } else if (words.size() == 3) {
        const size_t bytes = PlyTypeBytes(words[1]);
        if (bytes == 0) {
          return bad(fmt::format("line {}: unknown type {}", line_no, QuoteText(words[1])));
        }
        e.min_bytes += binary ? bytes : 2;
      } else {
        return bad(fmt::format("line {}: {}", line_no, QuoteText(line)));
      }
    } else if (words[0] == "end_header") {
      ended = true;
    } else {
      return bad(fmt::format("line {} is {}", line_no, QuoteText(line)));
    }
  }
  const uint64_t body = file_bytes - at;
  for (const Element& e : elements) {
    const std::string what = fmt::format("{}.file: PLY mesh '{}': element '{}' of {}", context,
                                         file.string(), EscapeText(e.name), e.count);
    if (e.name == "vertex") AVP_RETURN_IF_ERROR(MaxMeshVertices().Check(what, e.count));
    if (e.name == "face") AVP_RETURN_IF_ERROR(MaxMeshFaces().Check(what, e.count));
    // What the rest of the file can hold (elements without properties count as one byte).
    const uint64_t min_bytes = std::max<uint64_t>(e.min_bytes, 1);
    if (e.count > body / min_bytes) {
      return ParseError(fmt::format(
          "{}.file: PLY mesh '{}' declares {} '{}' elements on header line {}, but the {} bytes "
          "after its header hold at most {} of them (at least {} bytes each): truncated or "
          "corrupt",
          context, file.string(), e.count, EscapeText(e.name), e.line, body, body / min_bytes,
          min_bytes));
    }
  }
  return Status::Ok();
}

/// OBJ and STL files declare no counts: before assimp reads one, its vertex and face lines are
/// counted in one streaming pass (OBJ "v" and "f" lines, ASCII STL "facet" lines; a binary STL's
/// triangle count against the file's size), and checked against max_mesh_vertices /
/// max_mesh_faces, so a file of 100 million short lines is refused before assimp holds them.
Status CheckObjOrStlCounts(const fs::path& file, uint64_t file_bytes, const std::string& ext,
                           const std::string& context) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return IoError(fmt::format("{}.file: cannot read mesh '{}'", context, file.string()));
  std::string chunk(1 << 16, '\0');
  if (ext == ".stl") {
    in.read(chunk.data(), 84);
    const auto got = static_cast<size_t>(in.gcount());
    const bool ascii = got >= 5 && chunk.compare(0, 5, "solid") == 0;
    if (!ascii) {
      if (got < 84) {
        return ParseError(
            fmt::format("{}.file: STL mesh '{}' is truncated ({} bytes, a binary STL "
                        "header needs 84)",
                        context, file.string(), got));
      }
      const uint64_t triangles = uint64_t{static_cast<uint8_t>(chunk[80])} |
                                 (uint64_t{static_cast<uint8_t>(chunk[81])} << 8) |
                                 (uint64_t{static_cast<uint8_t>(chunk[82])} << 16) |
                                 (uint64_t{static_cast<uint8_t>(chunk[83])} << 24);
      const std::string what =
          fmt::format("{}.file: STL mesh '{}': {} triangles", context, file.string(), triangles);
      AVP_RETURN_IF_ERROR(MaxMeshFaces().Check(what, triangles));
      AVP_RETURN_IF_ERROR(MaxMeshVertices().Check(what + " (3 vertices each)", 3 * triangles));
      if (84 + 50 * triangles > file_bytes) {
        return ParseError(fmt::format(
            "{}.file: STL mesh '{}' declares {} triangles ({} bytes) in a file of {} bytes: "
            "truncated or corrupt",
            context, file.string(), triangles, 84 + 50 * triangles, file_bytes));
      }
      return Status::Ok();
    }
    in.clear();
    in.seekg(0);
  }
  uint64_t vertices = 0, faces = 0;
  bool line_start = true;
  std::string first;  // the first token of the current line, up to 6 characters
  bool in_first = true;
  const auto end_token = [&] {
    if (ext == ".obj") {
      if (first == "v") ++vertices;
      if (first == "f") ++faces;
    } else if (first == "facet") {
      ++faces;
      vertices += 3;
    }
  };
  while (in) {
    in.read(chunk.data(), static_cast<std::streamsize>(chunk.size()));
    const auto n = static_cast<size_t>(in.gcount());
    for (size_t i = 0; i < n; ++i) {
      const char c = chunk[i];
      if (c == '\n') {
        if (in_first) end_token();
        line_start = true;
        in_first = true;
        first.clear();
        continue;
      }
      if (!in_first) continue;
      if (c == ' ' || c == '\t' || c == '\r') {
        if (!line_start) {
          end_token();
          in_first = false;
        }
        continue;
      }
      line_start = false;
      if (first.size() < 6) first.push_back(c);
    }
  }
  if (in_first && !line_start) end_token();
  AVP_RETURN_IF_ERROR(MaxMeshVertices().Check(
      fmt::format("{}.file: vertex lines of mesh '{}'", context, file.string()), vertices));
  AVP_RETURN_IF_ERROR(MaxMeshFaces().Check(
      fmt::format("{}.file: face lines of mesh '{}'", context, file.string()), faces));
  return Status::Ok();
}

/// Everything one mesh file contributes, before it is added to the scene.
struct ImportedPart {
  std::string name;
  std::string node_name;
  std::string mesh_name;
  std::string material;  // the material's name, "" when none
  SemanticClass semantic_class = SemanticClass::kOther;
  int rule = -1;  // the class rule that gave the class, -1: default_class
  Eigen::Vector3f albedo;
  ColorSource color_source = ColorSource::kClassDefault;
  Eigen::Vector3f material_color = Eigen::Vector3f::Zero();  // when kPlaceholder
  TriangleMesh mesh;
};

Result<std::vector<ImportedPart>> ImportMesh(const MeshEntry& entry, const std::string& context,
                                             std::vector<std::string>& warnings) {
  // The file's size, and a PLY's declared counts, before assimp reads anything.
  AVP_ASSIGN_OR_RETURN(const uint64_t file_bytes, io::CheckReadableFile(entry.file, "mesh file"));
  AVP_RETURN_IF_ERROR(MaxMeshFileBytes().Check(
      fmt::format("{}.file: mesh '{}' of {} bytes", context, entry.file.string(), file_bytes),
      file_bytes));
  const std::string ext = LowerExtension(entry.file);
  if (ext == ".ply") AVP_RETURN_IF_ERROR(CheckPlyHeader(entry.file, file_bytes, context));
  if (ext == ".obj" || ext == ".stl") {
    AVP_RETURN_IF_ERROR(CheckObjOrStlCounts(entry.file, file_bytes, ext, context));
  }
  Assimp::Importer importer;
  const bool is_collada = ext == ".dae";
  const bool is_gltf = ext == ".gltf" || ext == ".glb";
  // Up axis: COLLADA declares one (assimp turns the file into its Y-up convention unless told to
  // ignore it), glTF is Y-up by specification, other formats are taken as Z-up (ROS/URDF habit).
  // An explicit up_axis describes the raw file coordinates and switches assimp's conversion off.
  bool y_up = is_collada || is_gltf;
  if (entry.up_axis != UpAxis::kAuto) {
    importer.SetPropertyBool(AI_CONFIG_IMPORT_COLLADA_IGNORE_UP_DIRECTION, true);
    y_up = entry.up_axis == UpAxis::kY;
  }
  importer.SetPropertyBool(AI_CONFIG_IMPORT_COLLADA_USE_COLLADA_NAMES, true);
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                              aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  const aiScene* ai = nullptr;
  std::string assimp_said;
  {
    AssimpMessages messages;
    // Read and validated first, post-processed after: a malformed file can leave a mesh with a
    // face of no vertex, or primitive types that disagree with its faces (an ASCII PLY face list
    // cut short), and assimp's triangulation then aborts the process on an assertion
    // (fuzz/regressions/scene_file). Such a face is refused and the types are recomputed from the
    // faces before it runs.
    ai = importer.ReadFile(entry.file.string(), aiProcess_ValidateDataStructure);
    if (ai != nullptr && (ai->mFlags & AI_SCENE_FLAGS_INCOMPLETE) == 0) {
      for (unsigned i = 0; i < ai->mNumMeshes; ++i) {
        aiMesh* m = ai->mMeshes[i];
        if (m == nullptr) continue;
        unsigned types = 0;
        for (unsigned f = 0; f < m->mNumFaces; ++f) {
          const unsigned n = m->mFaces[f].mNumIndices;
          if (n == 0) {
            return ParseError(
                fmt::format("{}.file: mesh '{}': face {} of mesh {} has no vertex (a corrupt face "
                            "list){}",
                            context, entry.file.string(), f, i, messages.Quote()));
          }
          types |= n == 1   ? aiPrimitiveType_POINT
                   : n == 2 ? aiPrimitiveType_LINE
                   : n == 3 ? aiPrimitiveType_TRIANGLE
                            : aiPrimitiveType_POLYGON;
        }
        m->mPrimitiveTypes = types;
      }
      ai = importer.ApplyPostProcessing(aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                                        aiProcess_SortByPType);
    }
    assimp_said = messages.Quote();
  }
  if (ai == nullptr || ai->mRootNode == nullptr || (ai->mFlags & AI_SCENE_FLAGS_INCOMPLETE) != 0) {
    return ParseError(
        fmt::format("{}.file: cannot import mesh '{}': {}{}", context, entry.file.string(),
                    ai == nullptr ? EscapeText(importer.GetErrorString(), 300) : "incomplete scene",
                    assimp_said));
  }
  // What assimp read: the counts against the limits, every vertex finite, every index in range.
  uint64_t vertices = 0, faces = 0;
  for (unsigned i = 0; i < ai->mNumMeshes; ++i) {
    const aiMesh* m = ai->mMeshes[i];
    if (m == nullptr) {
      return ParseError(fmt::format("{}.file: mesh '{}': assimp returned an empty mesh {}{}",
                                    context, entry.file.string(), i, assimp_said));
    }
    vertices += m->mNumVertices;
    faces += m->mNumFaces;
  }
  AVP_RETURN_IF_ERROR(MaxMeshVertices().Check(
      fmt::format("{}.file: vertices of mesh '{}'", context, entry.file.string()), vertices));
  AVP_RETURN_IF_ERROR(MaxMeshFaces().Check(
      fmt::format("{}.file: faces of mesh '{}'", context, entry.file.string()), faces));
  for (unsigned i = 0; i < ai->mNumMeshes; ++i) {
    const aiMesh* m = ai->mMeshes[i];
    for (unsigned v = 0; v < m->mNumVertices; ++v) {
      const aiVector3D& p = m->mVertices[v];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
        return ParseError(fmt::format(
            "{}.file: mesh '{}': vertex {} of mesh {} is ({}, {}, {}); coordinates must be finite",
            context, entry.file.string(), v, i, p.x, p.y, p.z));
      }
    }
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const aiFace& face = m->mFaces[f];
      for (unsigned k = 0; k < face.mNumIndices; ++k) {
        if (face.mIndices[k] >= m->mNumVertices) {
          return ParseError(
              fmt::format("{}.file: mesh '{}': face {} of mesh {} uses vertex {} of {}", context,
                          entry.file.string(), f, i, face.mIndices[k], m->mNumVertices));
        }
      }
    }
  }

  // p_W = X_WM * diag(scale) * U * M_node * p_file, U: the up-axis correction.
  Eigen::Matrix4d pre = Eigen::Matrix4d::Identity();
  if (y_up) {
    pre.topLeftCorner<3, 3>() =
        Eigen::AngleAxisd(EIGEN_PI / 2.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
  }
  pre.topLeftCorner<3, 3>() = entry.scale.asDiagonal() * pre.topLeftCorner<3, 3>();
  const Eigen::Matrix4d X_WM = entry.X_WM.ToMatrix4() * pre;

  std::vector<ImportedPart> parts;
  const std::string stem = entry.file.stem().string();
  internal::TextureLoader textures(*ai, entry.file);
  // Iterative depth-first traversal (children in file order) with accumulated transforms.
  struct Item {
    const aiNode* node;
    Eigen::Matrix4d X;
  };
  std::vector<Item> stack = {{ai->mRootNode, X_WM * ToEigen(ai->mRootNode->mTransformation)}};
  while (!stack.empty()) {
    const Item item = std::move(stack.back());
    stack.pop_back();
    const std::string node_name = item.node->mName.C_Str();
    for (unsigned k = 0; k < item.node->mNumMeshes; ++k) {
      const aiMesh* m = ai->mMeshes[item.node->mMeshes[k]];
      if ((m->mPrimitiveTypes & aiPrimitiveType_TRIANGLE) == 0 || m->mNumFaces == 0) continue;
      const aiMaterial* material =
          m->mMaterialIndex < ai->mNumMaterials ? ai->mMaterials[m->mMaterialIndex] : nullptr;
      aiString material_name;
      if (material != nullptr) material->Get(AI_MATKEY_NAME, material_name);
      const std::string mat = material_name.C_Str();
      const std::string mesh_name = m->mName.C_Str();

      // Class: the first rule matching the node, mesh or material name.
      ImportedPart part;
      part.node_name = node_name;
      part.mesh_name = mesh_name;
      part.material = mat;
      part.semantic_class = entry.default_class;
      std::optional<Eigen::Vector3f> color;
      for (size_t r = 0; r < entry.rules.size(); ++r) {
        const ClassRule& rule = entry.rules[r];
        if (GlobMatch(rule.pattern, node_name) || GlobMatch(rule.pattern, mesh_name) ||
            (!mat.empty() && GlobMatch(rule.pattern, mat))) {
          part.semantic_class = rule.semantic_class;
          part.rule = static_cast<int>(r);
          if (rule.color) {
            color = rule.color;
            part.color_source = ColorSource::kRule;
          }
          break;
        }
      }
      if (!color && entry.color) {
        color = entry.color;
        part.color_source = ColorSource::kEntry;
      }
      // The material (texture, then diffuse colour) unless `materials: ignore`; assimp's default
      // material (a mesh without one) gives nothing. Placeholders (`materials: auto`) are
      // replaced after every part of the file is read (ReplacePlaceholderColors).
      if (!color && entry.materials != MaterialMode::kIgnore && material != nullptr) {
        // A diffuse / base-colour texture: texture coordinates and image onto the part's mesh,
        // its colour over the part as albedo (scene_textures.h; unusable: a warning, then Kd).
        const std::string label = fmt::format(
            "{}/{}{}", stem, node_name.empty() ? stem : node_name,
            mesh_name.empty() || mesh_name == node_name ? std::string() : "/" + mesh_name);
        if (const std::optional<Eigen::Vector3f> mean =
                textures.Attach(*material, *m, label, &part.mesh)) {
          color = *mean;
          part.color_source = ColorSource::kTexture;
        }
      }
      if (!color && entry.materials != MaterialMode::kIgnore && material != nullptr &&
          !mat.empty() && mat != AI_DEFAULT_MATERIAL_NAME) {
        aiColor3D kd;
        if (material->Get(AI_MATKEY_COLOR_DIFFUSE, kd) == AI_SUCCESS) {
          color = Eigen::Vector3f(std::clamp(kd.r, 0.0f, 1.0f), std::clamp(kd.g, 0.0f, 1.0f),
                                  std::clamp(kd.b, 0.0f, 1.0f));
          part.color_source = ColorSource::kMaterial;
        }
      }
      part.albedo = color.value_or(DefaultClassColor(part.semantic_class));

      for (unsigned v = 0; v < m->mNumVertices; ++v) {
        const aiVector3D& p = m->mVertices[v];
        const Eigen::Vector4d p_W = item.X * Eigen::Vector4d(p.x, p.y, p.z, 1.0);
        part.mesh.vertices.emplace_back(p_W.head<3>().cast<float>());
      }
      for (unsigned f = 0; f < m->mNumFaces; ++f) {
        const aiFace& face = m->mFaces[f];
        if (face.mNumIndices != 3) continue;
        part.mesh.triangles.emplace_back(static_cast<int>(face.mIndices[0]),
                                         static_cast<int>(face.mIndices[1]),
                                         static_cast<int>(face.mIndices[2]));
      }
      if (part.mesh.empty()) continue;
      std::string name = fmt::format("{}/{}", stem, node_name.empty() ? stem : node_name);
      if (!mesh_name.empty() && mesh_name != node_name) name += "/" + mesh_name;
      if (item.node->mNumMeshes > 1 && mesh_name.empty()) name += fmt::format("/{}", k);
      part.name = std::move(name);
      parts.push_back(std::move(part));
    }
    for (unsigned c = item.node->mNumChildren; c-- > 0;) {
      const aiNode* child = item.node->mChildren[c];
      stack.push_back({child, item.X * ToEigen(child->mTransformation)});
    }
  }
  if (parts.empty()) {
    return ParseError(
        fmt::format("{}.file: mesh '{}' contains no triangles", context, entry.file.string()));
  }
  for (const std::string& w : textures.Warnings()) warnings.push_back(context + ": " + w);
  return parts;
}

Result<RigidTransform> ReadStartCamera(const YAML::Node& node, const std::string& context) {
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(node, {"eye", "target", "up"}, context));
  AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd eye, io::ReadVector(node, "eye", 3, context));
  AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd target, io::ReadVector(node, "target", 3, context));
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  if (node["up"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(const Eigen::VectorXd u, io::ReadVector(node, "up", 3, context));
    up = u;
  }
  const Eigen::Vector3d forward = target - eye;
  if (forward.norm() < 1e-6 || forward.normalized().cross(up).norm() < 1e-6) {
    return InvalidArgumentError(fmt::format(
        "{}: eye [{}, {}, {}] and target [{}, {}, {}] must differ and the view must not be "
        "parallel to up [{}, {}, {}]",
        context, eye[0], eye[1], eye[2], target[0], target[1], target[2], up[0], up[1], up[2]));
  }
  return RigidTransform::LookAt(eye, target, up);
}

std::string FileSafe(std::string_view name) {
  std::string out;
  for (const char c : name) {
    out +=
        (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.') ? c : '_';
  }
  return out.empty() ? "scene" : out;
}

/// OBJ object names: no whitespace (assimp would split them).
std::string ObjSafe(std::string_view name) {
  std::string out;
  for (const char c : name) out += std::isspace(static_cast<unsigned char>(c)) ? '_' : c;
  return out;
}

}  // namespace

bool GlobMatch(std::string_view pattern, std::string_view text) {
  // Iterative matcher with single-star backtracking: O(|pattern| * |text|) worst case.
  size_t p = 0;
  size_t t = 0;
  size_t star = std::string_view::npos;
  size_t star_t = 0;
  while (t < text.size()) {
    if (p < pattern.size() && (pattern[p] == '?' || pattern[p] == text[t])) {
      ++p;
      ++t;
    } else if (p < pattern.size() && pattern[p] == '*') {
      star = p++;
      star_t = t;
    } else if (star != std::string_view::npos) {
      p = star + 1;
      t = ++star_t;
    } else {
      return false;
    }
  }
  while (p < pattern.size() && pattern[p] == '*') ++p;
  return p == pattern.size();
}

bool GlobCapture(std::string_view pattern, std::string_view text,
                 std::vector<std::string>* captures) {
  // Depth-first search, each '*' trying the shortest text first, with the (pattern, text)
  // positions known to fail remembered: O(|pattern| * |text|^2) time at worst, recursion depth
  // at most |pattern|.
  const size_t np = pattern.size();
  const size_t nt = text.size();
  std::vector<char> failed((np + 1) * (nt + 1), 0);
  std::vector<std::pair<size_t, size_t>> spans;
  const auto match = [&](const auto& self, size_t p, size_t t) -> bool {
    char& known_bad = failed[p * (nt + 1) + t];
    if (known_bad != 0) return false;
    bool ok = false;
    if (p == np) {
      ok = t == nt;
    } else if (pattern[p] == '*') {
      for (size_t k = t; k <= nt && !ok; ++k) {
        spans.emplace_back(t, k);
        ok = self(self, p + 1, k);
        if (!ok) spans.pop_back();
      }
    } else if (t < nt && (pattern[p] == '?' || pattern[p] == text[t])) {
      ok = self(self, p + 1, t + 1);
    }
    if (!ok) known_bad = 1;
    return ok;
  };
  const bool ok = match(match, 0, 0);
  if (captures != nullptr) {
    captures->clear();
    if (ok) {
      for (const auto& [a, b] : spans) captures->emplace_back(text.substr(a, b - a));
    }
  }
  return ok;
}

namespace {

std::string FormatColor(const Eigen::Vector3f& c) {
  return fmt::format("[{:.3g}, {:.3g}, {:.3g}]", c.x(), c.y(), c.z());
}

/// Equal within half an 8-bit step.
bool SameColor(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return (a - b).cwiseAbs().maxCoeff() <= 0.5f / 255.0f;
}

/// Up to three names quoted, then "and N more".
std::string NameList(const std::vector<std::string>& names) {
  std::vector<std::string> shown;
  for (size_t i = 0; i < names.size() && i < 3; ++i) shown.push_back(QuoteText(names[i], 80));
  std::string out = fmt::format("{}", fmt::join(shown, ", "));
  if (names.size() > 3) out += fmt::format(" and {} more", names.size() - 3);
  return out;
}

/// `materials: auto`: an achromatic material colour shared by every part of a chromatic class
/// whose colour comes from its material is a placeholder; those parts get the class default.
void ReplacePlaceholderColors(const MeshEntry& entry, const std::string& context,
                              std::vector<ImportedPart>& parts,
                              std::vector<std::string>& warnings) {
  if (entry.materials != MaterialMode::kAuto) return;
  // One warning per (materials, colour): the usual single placeholder material is one sentence
  // naming every class it was replaced in.
  struct Group {
    std::string materials;
    Eigen::Vector3f color;
    std::vector<std::string> classes;  // "fruit (25 parts)"
  };
  std::vector<Group> groups;
  for (const SemanticClass c : AllSemanticClasses()) {
    if (!ChromaticClass(c)) continue;
    std::vector<ImportedPart*> from_material;
    for (ImportedPart& part : parts) {
      if (part.semantic_class == c && part.color_source == ColorSource::kMaterial) {
        from_material.push_back(&part);
      }
    }
    if (from_material.empty()) continue;
    const Eigen::Vector3f color = from_material.front()->albedo;
    if (!IsAchromatic(color)) continue;
    if (!std::all_of(from_material.begin(), from_material.end(),
                     [&](const ImportedPart* p) { return SameColor(p->albedo, color); })) {
      continue;
    }
    std::vector<std::string> materials;
    for (ImportedPart* part : from_material) {
      if (std::find(materials.begin(), materials.end(), part->material) == materials.end()) {
        materials.push_back(part->material);
      }
      part->material_color = part->albedo;
      part->albedo = DefaultClassColor(c);
      part->color_source = ColorSource::kPlaceholder;
    }
    const std::string names = NameList(materials);
    const std::string what =
        fmt::format("{} ({} part{}, now {})", ToString(c), from_material.size(),
                    from_material.size() == 1 ? "" : "s", FormatColor(DefaultClassColor(c)));
    auto it = std::find_if(groups.begin(), groups.end(), [&](const Group& g) {
      return g.materials == names && SameColor(g.color, color);
    });
    if (it == groups.end()) {
      groups.push_back({names, color, {what}});
    } else {
      it->classes.push_back(what);
    }
  }
  for (const Group& g : groups) {
    warnings.push_back(fmt::format(
        "{} ({}): material {} colour {} looks like a placeholder (every part of the class coloured "
        "by its material has this one achromatic colour), replaced by the class default in {} "
        "('materials: use' keeps the material colour, a class rule's 'color' sets another)",
        context, QuoteText(entry.file_text, 80), g.materials, FormatColor(g.color),
        fmt::join(g.classes, ", ")));
  }
}

/// Distance between two boxes (0 when they touch or overlap), metres.
double BoxGap(const Box3& a, const Box3& b) {
  const Eigen::Vector3d d =
      (a.min() - b.max()).cwiseMax(b.min() - a.max()).cwiseMax(Eigen::Vector3d::Zero());
  return d.norm();
}

double VolumeCm3(const Box3& box) { return box.Volume() * 1e6; }

/// Without a size rule, fruit instances whose bounding box is under this fraction of the largest
/// fruit's are pointed out (a warning), as likely fragments.
constexpr double kTinyFruitFraction = 0.02;

/// One future scene object of a mesh entry: a part, or one connected component of a fruit part.
struct Piece {
  TriangleMesh mesh;
  size_t part = 0;
  std::string name;
  std::vector<std::string> merged;  // fragments joined to it
  std::string fate = "object";
  bool removed = false;  // merged into another piece or dropped
};

/// Per-entry results of the merge and size rules, for warnings and the report.
struct FragmentCounts {
  size_t name_merged = 0;
  size_t small_merged = 0;
  size_t small_dropped = 0;
  size_t dropped_out_of_reach = 0;
};

/// Parts joined by `merge` rules (part index -> target part index, -1: none), with the warnings
/// for rules that match nothing or whose target is missing.
std::vector<int> ResolveMergeRules(const MeshEntry& entry, const std::string& context,
                                   const std::vector<ImportedPart>& parts,
                                   std::vector<int>& rule_of_part,
                                   std::vector<std::string>& warnings) {
  std::vector<int> target(parts.size(), -1);
  rule_of_part.assign(parts.size(), -1);
  if (entry.merge.empty()) return target;
  // Which parts are sources (they never become targets themselves), with their captures.
  std::vector<std::vector<std::string>> captures(parts.size());
  for (size_t i = 0; i < parts.size(); ++i) {
    for (size_t m = 0; m < entry.merge.size(); ++m) {
      if (GlobCapture(entry.merge[m].match, parts[i].node_name, &captures[i]) ||
          GlobCapture(entry.merge[m].match, parts[i].mesh_name, &captures[i])) {
        rule_of_part[i] = static_cast<int>(m);
        break;
      }
    }
  }
  // Targets by exact node or mesh name (the first part of each name), for `into` without
  // wildcards once substituted: no scan over every part per fragment.
  std::unordered_map<std::string, size_t> by_name;
  for (size_t j = 0; j < parts.size(); ++j) {
    if (rule_of_part[j] >= 0) continue;
    by_name.emplace(parts[j].node_name, j);
    by_name.emplace(parts[j].mesh_name, j);
  }
  std::vector<size_t> matched(entry.merge.size(), 0);
  std::vector<std::vector<std::string>> unresolved(entry.merge.size());
  for (size_t i = 0; i < parts.size(); ++i) {
    if (rule_of_part[i] < 0) continue;
    const MergeRule& rule = entry.merge[static_cast<size_t>(rule_of_part[i])];
    ++matched[static_cast<size_t>(rule_of_part[i])];
    std::string into;
    size_t k = 0;
    for (const char c : rule.into) {
      if (c == '*' && k < captures[i].size()) {
        into += captures[i][k++];
      } else {
        into += c;
      }
    }
    if (into.find_first_of("*?") == std::string::npos) {
      if (const auto it = by_name.find(into); it != by_name.end()) {
        target[i] = static_cast<int>(it->second);
      }
    } else {
      for (size_t j = 0; j < parts.size(); ++j) {
        if (rule_of_part[j] >= 0) continue;
        if (GlobMatch(into, parts[j].node_name) || GlobMatch(into, parts[j].mesh_name)) {
          target[i] = static_cast<int>(j);
          break;
        }
      }
    }
    if (target[i] < 0) unresolved[static_cast<size_t>(rule_of_part[i])].push_back(parts[i].name);
  }
  for (size_t m = 0; m < entry.merge.size(); ++m) {
    if (matched[m] == 0) {
      warnings.push_back(fmt::format(
          "{}.merge[{}]: 'match' {} matches no part of {} ({} parts; node and mesh names are "
          "tested)",
          context, m, QuoteText(entry.merge[m].match, 80), QuoteText(entry.file_text, 80),
          parts.size()));
    } else if (!unresolved[m].empty()) {
      warnings.push_back(fmt::format(
          "{}.merge[{}]: {} of the {} parts matching {} found no part named by 'into' {} and stay "
          "on their own: {}",
          context, m, unresolved[m].size(), matched[m], QuoteText(entry.merge[m].match, 80),
          QuoteText(entry.merge[m].into, 80), NameList(unresolved[m])));
    }
  }
  return target;
}

/// Warnings about the loaded scene as a whole: no fruit; classes a colour segmenter cannot tell
/// apart (every part of one class has a colour another class has too); a one-colour plant.
void SceneWarnings(const Scene& scene, std::vector<std::string>& warnings) {
  size_t fruits = 0;
  std::vector<std::pair<SemanticClass, std::vector<Eigen::Vector3f>>> colors;
  std::vector<size_t> parts_of;
  std::vector<const SceneObject*> plant;
  for (const SceneObject& o : scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) ++fruits;
    if (o.semantic_class == SemanticClass::kBackground) continue;
    // A textured object counts with its albedo, the texture's mean over it.
    if (o.semantic_class != SemanticClass::kGround) plant.push_back(&o);
    auto it = std::find_if(colors.begin(), colors.end(),
                           [&](const auto& c) { return c.first == o.semantic_class; });
    if (it == colors.end()) {
      colors.push_back({o.semantic_class, {}});
      parts_of.push_back(0);
      it = std::prev(colors.end());
    }
    ++parts_of[static_cast<size_t>(it - colors.begin())];
    if (std::none_of(it->second.begin(), it->second.end(),
                     [&](const Eigen::Vector3f& c) { return SameColor(c, o.albedo); })) {
      it->second.push_back(o.albedo);
    }
  }
  // Class order (fruit first), whatever the order of the objects.
  std::vector<size_t> order(colors.size());
  for (size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return colors[a].first < colors[b].first; });
  {
    decltype(colors) sorted_colors;
    std::vector<size_t> sorted_parts;
    for (const size_t k : order) {
      sorted_colors.push_back(std::move(colors[k]));
      sorted_parts.push_back(parts_of[k]);
    }
    colors = std::move(sorted_colors);
    parts_of = std::move(sorted_parts);
  }
  // A plant under the ground (or under the robot base's plane when there is none) is almost
  // always a wrong up axis, unit or pose.
  double ground_z = 0.0;
  for (const SceneObject& o : scene.objects) {
    if (o.semantic_class == SemanticClass::kGround) ground_z = o.Bounds().max().z();
  }
  Box3 plant_box;
  for (const SceneObject* o : plant) plant_box.Extend(o->Bounds());
  constexpr double kBelowGroundToleranceM = 0.01;
  if (!plant_box.IsEmpty() && plant_box.min().z() < ground_z - kBelowGroundToleranceM) {
    warnings.push_back(fmt::format(
        "the plant reaches z = {:.3f} m, {:.3f} m below the {} at z = {:.3f} m (its extent is "
        "{:.3f} x {:.3f} x {:.3f} m in x, y, z): check the mesh's up axis (up_axis), units "
        "(scale) and pose",
        plant_box.min().z(), ground_z - plant_box.min().z(),
        scene.objects.end() != std::find_if(scene.objects.begin(), scene.objects.end(),
                                            [](const SceneObject& o) {
                                              return o.semantic_class == SemanticClass::kGround;
                                            })
            ? "ground"
            : "robot base plane",
        ground_z, plant_box.size().x(), plant_box.size().y(), plant_box.size().z()));
  }
  if (fruits == 0) {
    warnings.push_back(
        "no part is of class fruit: the scene has no fruit ground truth (check the class rules "
        "with 'avp scene check FILE')");
  }
  const bool one_color_plant =
      plant.size() >= 2 && std::all_of(plant.begin(), plant.end(), [&](const SceneObject* o) {
        return SameColor(o->albedo, plant.front()->albedo);
      });
  if (one_color_plant) {
    std::vector<std::string> names;
    for (const auto& [c, list] : colors) {
      if (c != SemanticClass::kGround) names.emplace_back(ToString(c));
    }
    warnings.push_back(fmt::format(
        "the whole plant ({} parts, classes {}) is one colour {}: a colour segmenter cannot find "
        "fruit in it (give the class rules colours, or check 'materials:')",
        plant.size(), fmt::join(names, ", "), FormatColor(plant.front()->albedo)));
  }
  std::vector<std::pair<SemanticClass, SemanticClass>> reported;
  for (size_t a = 0; a < colors.size(); ++a) {
    if (colors[a].second.size() != 1) continue;
    const Eigen::Vector3f& color = colors[a].second.front();
    for (size_t b = 0; b < colors.size(); ++b) {
      if (b == a) continue;
      const SemanticClass ca = colors[a].first;
      const SemanticClass cb = colors[b].first;
      if (one_color_plant && ca != SemanticClass::kGround && cb != SemanticClass::kGround) continue;
      if (std::find(reported.begin(), reported.end(), std::make_pair(cb, ca)) != reported.end()) {
        continue;
      }
      if (std::none_of(colors[b].second.begin(), colors[b].second.end(),
                       [&](const Eigen::Vector3f& c) { return SameColor(c, color); })) {
        continue;
      }
      reported.emplace_back(ca, cb);
      warnings.push_back(fmt::format(
          "every {} part ({}) is {}, a colour {} parts have too: a colour segmenter cannot tell "
          "{} from {} (give the class rules colours, or check 'materials:')",
          ToString(ca), parts_of[a], FormatColor(color), ToString(cb), ToString(ca), ToString(cb)));
    }
  }
}

}  // namespace

Result<Scene> LoadSceneFile(const fs::path& yaml) { return LoadSceneFile(yaml, nullptr); }

Result<Scene> LoadSceneFile(const fs::path& yaml, SceneFileReport* report) {
  SceneFileReport local_report;
  SceneFileReport& rep = report != nullptr ? *report : local_report;
  rep = SceneFileReport();
  AVP_ASSIGN_OR_RETURN(const YAML::Node root, io::LoadYamlFile(yaml));
  const std::string file = yaml.filename().string();
  AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(
      root,
      {"version", "name", "description", "start_joints_deg", "start_camera", "ground", "meshes"},
      file));
  if (!root.IsMap()) {
    return InvalidArgumentError(fmt::format("{}: a scene file must be a YAML map", file));
  }
  AVP_ASSIGN_OR_RETURN(const int64_t version, io::ReadInt(root, "version", file));
  if (version != kSceneFileVersion) {
    return InvalidArgumentError(fmt::format("{}: unsupported scene file version {} (supported: {})",
                                            file, version, kSceneFileVersion));
  }

  Scene scene;
  scene.name = yaml.stem().string();
  if (root["name"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(scene.name, io::ReadString(root, "name", file));
  }
  if (root["description"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(scene.description, io::ReadString(root, "description", file));
  }

  // Start configuration: joints default to the reference start; the camera defaults to the
  // reference camera for the reference joints (any joint-1 yaw) and must be given otherwise.
  std::vector<double> joints_deg(std::begin(kReferenceStartJointsDeg),
                                 std::end(kReferenceStartJointsDeg));
  if (root["start_joints_deg"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(joints_deg, io::ReadDoubles(root, "start_joints_deg", file));
    if (joints_deg.empty()) {
      return InvalidArgumentError(fmt::format("{}: 'start_joints_deg' must not be empty", file));
    }
  }
  for (const double deg : joints_deg) scene.start_joints_rad.push_back(DegToRad(deg));
  if (root["start_camera"].IsDefined()) {
    AVP_ASSIGN_OR_RETURN(scene.X_WC_start,
                         ReadStartCamera(root["start_camera"], file + ": start_camera"));
  } else {
    bool reference = joints_deg.size() == 6;
    for (size_t i = 1; reference && i < 6; ++i) {
      reference = std::abs(joints_deg[i] - kReferenceStartJointsDeg[i]) < 1e-9;
    }
    if (!reference) {
      return InvalidArgumentError(fmt::format(
          "{}: 'start_camera' (eye, target) is required when start_joints_deg [{}] differs from "
          "the reference start [{}] in joints 2-6",
          file, fmt::join(joints_deg, ", "), fmt::join(kReferenceStartJointsDeg, ", ")));
    }
    scene.X_WC_start = ReferenceStartCameraPose(joints_deg[0]);
  }

  // Ground: `ground: true`, or a map {z_m, color}; absent or false: none.
  if (const YAML::Node ground = root["ground"]; ground.IsDefined() && !ground.IsNull()) {
    bool on = true;
    double z_m = 0.0;
    std::optional<Eigen::Vector3f> color;
    if (ground.IsScalar()) {
      AVP_ASSIGN_OR_RETURN(on, io::ReadBool(root, "ground", file));
    } else {
      const std::string context = file + ": ground";
      AVP_RETURN_IF_ERROR(io::RejectUnknownKeys(ground, {"z_m", "color"}, context));
      if (ground["z_m"].IsDefined()) {
        AVP_ASSIGN_OR_RETURN(z_m, io::ReadDouble(ground, "z_m", context));
      }
      if (ground["color"].IsDefined()) {
        AVP_ASSIGN_OR_RETURN(color, ReadColor(ground, "color", context));
      }
    }
    if (on) {
      AddGroundPlane(scene, z_m);
      if (color) scene.objects.back().albedo = *color;
    }
  }

  const YAML::Node meshes = root["meshes"];
  if (!meshes.IsDefined() || !meshes.IsSequence() || meshes.size() == 0) {
    return InvalidArgumentError(
        fmt::format("{}: 'meshes' must be a non-empty list of mesh entries", file));
  }
  const fs::path base_dir = yaml.parent_path();
  uint64_t total_vertices = 0, total_triangles = 0;
  uint16_t last_id = 0;
  for (const SceneObject& o : scene.objects) last_id = std::max(last_id, o.instance_id);
  for (size_t i = 0; i < meshes.size(); ++i) {
    const std::string context = fmt::format("{}: meshes[{}]", file, i);
    AVP_ASSIGN_OR_RETURN(const MeshEntry entry, ReadMeshEntry(meshes[i], base_dir, context));
    AVP_ASSIGN_OR_RETURN(std::vector<ImportedPart> parts, ImportMesh(entry, context, rep.warnings));
    // The limits hold for all meshes of the scene together, too.
    for (const ImportedPart& part : parts) {
      total_vertices += part.mesh.vertices.size();
      total_triangles += part.mesh.triangles.size();
    }
    AVP_RETURN_IF_ERROR(MaxMeshVertices().Check(
        fmt::format("{}: vertices of the scene's meshes up to this one", context), total_vertices));
    AVP_RETURN_IF_ERROR(MaxMeshFaces().Check(
        fmt::format("{}: triangles of the scene's meshes up to this one", context),
        total_triangles));
    ReplacePlaceholderColors(entry, context, parts, rep.warnings);

    // Rules: how many parts each classified, and how many it matches that an earlier one took.
    for (size_t r = 0; r < entry.rules.size(); ++r) {
      SceneRuleReport rule_report;
      rule_report.mesh_entry = i;
      rule_report.index = r;
      rule_report.match = entry.rules[r].pattern;
      rule_report.semantic_class = entry.rules[r].semantic_class;
      for (const ImportedPart& part : parts) {
        if (part.rule == static_cast<int>(r)) {
          ++rule_report.parts;
        } else if (part.rule >= 0 && part.rule < static_cast<int>(r) &&
                   (GlobMatch(rule_report.match, part.node_name) ||
                    GlobMatch(rule_report.match, part.mesh_name) ||
                    (!part.material.empty() && GlobMatch(rule_report.match, part.material)))) {
          ++rule_report.shadowed;
        }
      }
      if (rule_report.parts == 0) {
        rep.warnings.push_back(fmt::format(
            "{}.classes[{}]: rule {} (class {}) classifies no part of {} ({} parts; node, mesh "
            "and material names are tested){}",
            context, r, QuoteText(rule_report.match, 80), ToString(rule_report.semantic_class),
            QuoteText(entry.file_text, 80), parts.size(),
            rule_report.shadowed > 0
                ? fmt::format("; it matches {} parts an earlier rule took", rule_report.shadowed)
                : std::string()));
      }
      rep.rules.push_back(std::move(rule_report));
    }

    // Part reports (fates are filled in below).
    const size_t first_report = rep.parts.size();
    for (const ImportedPart& part : parts) {
      ScenePartReport pr;
      pr.name = part.name;
      pr.mesh_entry = i;
      pr.file = entry.file_text;
      pr.material = part.material;
      pr.semantic_class = part.semantic_class;
      pr.rule = part.rule;
      if (part.rule >= 0) pr.rule_match = entry.rules[static_cast<size_t>(part.rule)].pattern;
      pr.color = part.albedo;
      pr.color_source = part.color_source;
      pr.material_color = part.material_color;
      pr.vertices = part.mesh.vertices.size();
      pr.triangles = part.mesh.triangles.size();
      pr.bounds = part.mesh.Bounds();
      rep.parts.push_back(std::move(pr));
    }

    // Merge rules by name, then the pieces: a part, or each connected component of a fruit part.
    std::vector<int> merge_rule_of;
    const std::vector<int> merge_target =
        ResolveMergeRules(entry, context, parts, merge_rule_of, rep.warnings);
    FragmentCounts counts;
    std::vector<Piece> pieces;
    std::vector<std::vector<size_t>> pieces_of(parts.size());
    for (size_t p = 0; p < parts.size(); ++p) {
      if (merge_target[p] >= 0) continue;
      std::vector<TriangleMesh> meshes_of_part;
      if (parts[p].semantic_class == SemanticClass::kFruit &&
          entry.fruit_instances == FruitInstances::kComponents) {
        meshes_of_part = ConnectedComponents(parts[p].mesh);
      } else {
        meshes_of_part.push_back(std::move(parts[p].mesh));
      }
      for (size_t k = 0; k < meshes_of_part.size(); ++k) {
        Piece piece;
        piece.mesh = std::move(meshes_of_part[k]);
        piece.part = p;
        piece.name =
            meshes_of_part.size() > 1 ? fmt::format("{}#{}", parts[p].name, k) : parts[p].name;
        pieces_of[p].push_back(pieces.size());
        pieces.push_back(std::move(piece));
      }
    }
    // A part merged by name joins the nearest piece of its target part (the target may have been
    // split into components).
    for (size_t p = 0; p < parts.size(); ++p) {
      if (merge_target[p] < 0) continue;
      const std::vector<size_t>& candidates = pieces_of[static_cast<size_t>(merge_target[p])];
      const Box3 box = parts[p].mesh.Bounds();
      size_t best = candidates.front();
      double best_gap = std::numeric_limits<double>::infinity();
      for (const size_t c : candidates) {
        const double gap = BoxGap(box, pieces[c].mesh.Bounds());
        if (gap < best_gap) {
          best_gap = gap;
          best = c;
        }
      }
      const MergeRule& rule = entry.merge[static_cast<size_t>(merge_rule_of[p])];
      SceneFragmentReport fragment;
      fragment.name = parts[p].name;
      fragment.into = pieces[best].name;
      fragment.reason = fmt::format("merge[{}] {}", merge_rule_of[p], QuoteText(rule.match, 80));
      fragment.vertices = parts[p].mesh.vertices.size();
      fragment.volume_cm3 = VolumeCm3(box);
      fragment.gap_mm = best_gap * 1000.0;
      rep.parts[first_report + p].fate.push_back(
          fmt::format("merged into {} (merge[{}])", pieces[best].name, merge_rule_of[p]));
      rep.parts[first_report + p].semantic_class =
          parts[static_cast<size_t>(merge_target[p])].semantic_class;
      // Each part keeps its own colour (per-triangle colours where they differ).
      pieces[best].mesh.Append(parts[p].mesh, RigidTransform::Identity(),
                               parts[pieces[best].part].albedo, parts[p].albedo);
      pieces[best].merged.push_back(parts[p].name);
      rep.fragments.push_back(std::move(fragment));
      ++counts.name_merged;
    }
    // Fruit pieces under the minimum size join their nearest fruit within reach, or are dropped.
    std::vector<size_t> fruit_pieces;
    for (size_t k = 0; k < pieces.size(); ++k) {
      if (parts[pieces[k].part].semantic_class == SemanticClass::kFruit) fruit_pieces.push_back(k);
    }
    const bool size_rule = entry.fruit_min_volume_cm3 > 0.0 || entry.fruit_min_vertices > 0;
    if (size_rule) {
      std::vector<size_t> small, anchors;
      std::vector<Box3> bounds(pieces.size());
      for (const size_t k : fruit_pieces) {
        bounds[k] = pieces[k].mesh.Bounds();
        const bool is_small =
            VolumeCm3(bounds[k]) < entry.fruit_min_volume_cm3 ||
            static_cast<int64_t>(pieces[k].mesh.vertices.size()) < entry.fruit_min_vertices;
        (is_small ? small : anchors).push_back(k);
      }
      for (const size_t k : small) {
        SceneFragmentReport fragment;
        fragment.name = pieces[k].name;
        fragment.vertices = pieces[k].mesh.vertices.size();
        fragment.volume_cm3 = VolumeCm3(bounds[k]);
        size_t best = 0;
        double best_gap = std::numeric_limits<double>::infinity();
        for (const size_t a : anchors) {
          const double gap = BoxGap(bounds[k], bounds[a]);
          if (gap < best_gap) {
            best_gap = gap;
            best = a;
          }
        }
        pieces[k].removed = true;
        if (entry.fruit_small_parts == SmallParts::kMerge &&
            best_gap * 1000.0 <= entry.fruit_merge_reach_mm) {
          fragment.into = pieces[best].name;
          fragment.reason = "small";
          fragment.gap_mm = best_gap * 1000.0;
          pieces[k].fate = fmt::format("merged into {} (small, {:.1f} mm away)", pieces[best].name,
                                       fragment.gap_mm);
          pieces[best].mesh.Append(pieces[k].mesh, RigidTransform::Identity(),
                                   parts[pieces[best].part].albedo, parts[pieces[k].part].albedo);
          pieces[best].merged.push_back(pieces[k].name);
          for (const std::string& inner : pieces[k].merged) pieces[best].merged.push_back(inner);
          ++counts.small_merged;
        } else if (entry.fruit_small_parts == SmallParts::kMerge) {
          fragment.reason = "small, no fruit within reach";
          pieces[k].fate =
              fmt::format("dropped (small, no fruit within {} mm)", entry.fruit_merge_reach_mm);
          ++counts.small_dropped;
          ++counts.dropped_out_of_reach;
        } else {
          fragment.reason = "small";
          pieces[k].fate = "dropped (small)";
          ++counts.small_dropped;
        }
        rep.fragments.push_back(std::move(fragment));
      }
      if (counts.small_merged + counts.small_dropped > 0) {
        std::vector<std::string> minimum;
        if (entry.fruit_min_volume_cm3 > 0.0) {
          minimum.push_back(fmt::format("a bounding box under {} cm3", entry.fruit_min_volume_cm3));
        }
        if (entry.fruit_min_vertices > 0) {
          minimum.push_back(fmt::format("fewer than {} vertices", entry.fruit_min_vertices));
        }
        rep.warnings.push_back(fmt::format(
            "{} ({}): {} fruit fragments under the minimum size ({}): {} joined their nearest "
            "fruit, {} dropped{}; {} fruits remain",
            context, QuoteText(entry.file_text, 80), small.size(), fmt::join(minimum, " or "),
            counts.small_merged, counts.small_dropped,
            counts.dropped_out_of_reach > 0
                ? fmt::format(" ({} with no fruit within {} mm)", counts.dropped_out_of_reach,
                              entry.fruit_merge_reach_mm)
                : std::string(),
            anchors.size()));
      }
    } else if (fruit_pieces.size() >= 2) {
      // No size rule: point at fragments far smaller than the largest fruit.
      std::vector<double> volumes;
      for (const size_t k : fruit_pieces) volumes.push_back(VolumeCm3(pieces[k].mesh.Bounds()));
      const double largest = *std::max_element(volumes.begin(), volumes.end());
      std::vector<std::string> tiny;
      for (size_t f = 0; f < fruit_pieces.size(); ++f) {
        if (volumes[f] < kTinyFruitFraction * largest) {
          tiny.push_back(pieces[fruit_pieces[f]].name);
        }
      }
      if (!tiny.empty()) {
        rep.warnings.push_back(fmt::format(
            "{} ({}): {} of its {} fruit instances have a bounding box under 2% of the largest "
            "fruit's ({:.3g} cm3): {}; if they are fragments of fruit, set fruit_min_volume_cm3 "
            "(they then join their nearest fruit) or a 'merge' rule",
            context, QuoteText(entry.file_text, 80), tiny.size(), fruit_pieces.size(), largest,
            NameList(tiny)));
      }
    }
    // Part reports: what became of each piece.
    for (size_t p = 0; p < parts.size(); ++p) {
      for (const size_t k : pieces_of[p]) {
        rep.parts[first_report + p].fate.push_back(
            pieces_of[p].size() > 1 ? fmt::format("{}: {}", pieces[k].name, pieces[k].fate)
                                    : pieces[k].fate);
      }
    }

    // Instance ids are 16-bit: a scene holds at most 65535 objects (a mesh split into
    // components could otherwise ask for millions).
    size_t kept = 0;
    for (const Piece& piece : pieces) kept += piece.removed ? 0 : 1;
    constexpr size_t kMaxObjects = std::numeric_limits<uint16_t>::max();
    if (last_id + kept > kMaxObjects) {
      return ResourceExhaustedError(fmt::format(
          "{}: mesh '{}' adds {} objects to the {} of the scene; a scene holds at most {} "
          "(instance ids are 16-bit)",
          context, entry.file.string(), kept, scene.objects.size(), kMaxObjects));
    }
    for (Piece& piece : pieces) {
      if (piece.removed) continue;
      const ImportedPart& part = parts[piece.part];
      SceneObject object;
      object.name = piece.name;
      object.semantic_class = part.semantic_class;
      object.albedo = part.albedo;
      object.shape = std::move(piece.mesh);
      // Scene::Add's id (the largest + 1) without its scan over every object: linear time for
      // a mesh split into tens of thousands of fruits.
      object.instance_id = ++last_id;
      if (object.semantic_class == SemanticClass::kFruit) {
        const TriangleMesh& mesh = std::get<TriangleMesh>(object.shape);
        SceneFruitReport fruit;
        fruit.instance_id = object.instance_id;
        fruit.name = object.name;
        fruit.vertices = mesh.vertices.size();
        fruit.triangles = mesh.triangles.size();
        fruit.bounds = mesh.Bounds();
        fruit.volume_cm3 = VolumeCm3(fruit.bounds);
        fruit.merged = std::move(piece.merged);
        rep.fruits.push_back(std::move(fruit));
      }
      scene.objects.push_back(std::move(object));
    }
  }
  SceneWarnings(scene, rep.warnings);
  scene.warnings = rep.warnings;
  AVP_RETURN_IF_ERROR(scene.Validate().WithContext(file));
  scene.UpdatePlantBounds();
  return scene;
}

Status SaveSceneFiles(const Scene& scene, const fs::path& dir) {
  AVP_RETURN_IF_ERROR(scene.Validate());
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) {
    return IoError(fmt::format("cannot create directory '{}': {}", dir.string(), ec.message()));
  }
  const std::string stem = FileSafe(scene.name);
  const fs::path obj_path = dir / (stem + ".obj");
  const fs::path mtl_path = dir / (stem + ".mtl");
  const fs::path yaml_path = dir / (stem + ".yaml");

  // Both meshes in memory first, then each file atomically: the YAML last, so it never names a
  // mesh that is not complete.
  std::string mtl;
  std::string obj;
  obj += fmt::format("# avp scene {} (seed {}), world frame, metres\nmtllib {}\n",
                     QuoteText(scene.name), scene.seed, mtl_path.filename().string());
  std::vector<SemanticClass> classes_used;
  size_t vertex_base = 1;
  for (const SceneObject& o : scene.objects) {
    const TriangleMesh mesh = std::holds_alternative<TriangleMesh>(o.shape)
                                  ? std::get<TriangleMesh>(o.shape)
                                  : TessellateEllipsoid(std::get<Ellipsoid>(o.shape), 3);
    const std::string material = fmt::format("m{}", o.instance_id);
    fmt::format_to(std::back_inserter(mtl), "newmtl {}\nKd {:.6f} {:.6f} {:.6f}\n", material,
                   o.albedo.x(), o.albedo.y(), o.albedo.z());
    fmt::format_to(std::back_inserter(obj), "o {}__{}__{}\nusemtl {}\n", ToString(o.semantic_class),
                   o.instance_id, ObjSafe(o.name), material);
    for (const Eigen::Vector3f& v : mesh.vertices) {
      fmt::format_to(std::back_inserter(obj), "v {:.7g} {:.7g} {:.7g}\n", v.x(), v.y(), v.z());
    }
    for (const Eigen::Vector3i& t : mesh.triangles) {
      fmt::format_to(
          std::back_inserter(obj), "f {} {} {}\n", vertex_base + static_cast<size_t>(t[0]),
          vertex_base + static_cast<size_t>(t[1]), vertex_base + static_cast<size_t>(t[2]));
    }
    vertex_base += mesh.vertices.size();
    if (std::find(classes_used.begin(), classes_used.end(), o.semantic_class) ==
        classes_used.end()) {
      classes_used.push_back(o.semantic_class);
    }
  }
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(mtl_path, mtl, "scene materials (MTL)"));
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(obj_path, obj, "scene mesh (OBJ)"));

  YAML::Emitter out;
  out.SetDoublePrecision(10);
  out << YAML::BeginMap;
  out << YAML::Key << "version" << YAML::Value << kSceneFileVersion;
  out << YAML::Key << "name" << YAML::Value << scene.name;
  out << YAML::Key << "description" << YAML::Value << scene.description;
  if (!scene.start_joints_rad.empty()) {
    std::vector<double> deg;
    for (const double q : scene.start_joints_rad) deg.push_back(RadToDeg(q));
    out << YAML::Key << "start_joints_deg" << YAML::Value << YAML::Flow << deg;
  }
  const Eigen::Vector3d eye = scene.X_WC_start.translation();
  const Eigen::Vector3d target = eye + scene.X_WC_start.rotation().col(2);
  const Eigen::Vector3d up = -scene.X_WC_start.rotation().col(1);
  const auto vec = [](const Eigen::Vector3d& v) {
    return std::vector<double>{v.x(), v.y(), v.z()};
  };
  out << YAML::Key << "start_camera" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "eye" << YAML::Value << YAML::Flow << vec(eye);
  out << YAML::Key << "target" << YAML::Value << YAML::Flow << vec(target);
  out << YAML::Key << "up" << YAML::Value << YAML::Flow << vec(up);
  out << YAML::EndMap;
  out << YAML::Key << "ground" << YAML::Value << false;  // a ground object is saved as a mesh
  out << YAML::Key << "meshes" << YAML::Value << YAML::BeginSeq << YAML::BeginMap;
  out << YAML::Key << "file" << YAML::Value << obj_path.filename().string();
  out << YAML::Key << "up_axis" << YAML::Value << "z";
  out << YAML::Key << "fruit_instances" << YAML::Value << "objects";
  out << YAML::Key << "default_class" << YAML::Value << "other";
  // The materials are the objects' own colours: never taken for placeholders.
  out << YAML::Key << "materials" << YAML::Value << "use";
  out << YAML::Key << "classes" << YAML::Value << YAML::BeginSeq;
  for (const SemanticClass c : classes_used) {
    out << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "match" << YAML::Value << fmt::format("{}__*", ToString(c));
    out << YAML::Key << "class" << YAML::Value << std::string(ToString(c));
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap << YAML::EndSeq << YAML::EndMap;
  const std::string yaml_text =
      std::string("# Written by avp::sim::SaveSceneFiles (format: docs/scene-format.md)\n") +
      out.c_str() + "\n";
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(yaml_path, yaml_text, "scene file"));
  return Status::Ok();
}

}  // namespace avp::sim

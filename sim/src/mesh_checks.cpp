// A mesh file's declared sizes, checked before assimp reads it: a PLY header's element counts, an
// OBJ's or ASCII STL's vertex and face lines, a binary STL's triangle count, against the file's
// size and the limits max_mesh_vertices / max_mesh_faces.

#include <algorithm>
#include <charconv>
#include <cstdint>
#include <fstream>
#include <istream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/sim/scene_file.h>

#include "scene_file_internal.h"

namespace avp::sim::internal {

namespace {

namespace fs = std::filesystem;

constexpr size_t kMaxPlyHeaderBytes = 65536;

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

/// The PLY file being checked, for its error messages.
struct PlyFile {
  const fs::path& file;
  const std::string& context;

  Status Bad(const std::string& what) const {
    return ParseError(
        fmt::format("{}.file: PLY mesh '{}' has a bad header: {}", context, file.string(), what));
  }
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  uint64_t min_bytes = 0;  // per element
  size_t line = 0;
};

/// What the header declares; `end`: the offset of the body (after "end_header\n").
struct PlyHeader {
  bool is_ply = true;
  bool binary = false;
  bool ended = false;
  size_t end = 0;
  std::vector<PlyElement> elements;
};

/// The file's first bytes, up to kMaxPlyHeaderBytes.
Result<std::string> ReadPlyHead(const PlyFile& ply, uint64_t file_bytes) {
  std::ifstream in(ply.file, std::ios::binary);
  std::string head(static_cast<size_t>(std::min<uint64_t>(file_bytes, kMaxPlyHeaderBytes)), '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  if (!in && !in.eof()) {
    return IoError(fmt::format("{}.file: cannot read mesh '{}'", ply.context, ply.file.string()));
  }
  head.resize(static_cast<size_t>(in.gcount()));
  return head;
}

/// A header line's words, split at spaces and tabs.
std::vector<std::string_view> Words(std::string_view line) {
  std::vector<std::string_view> words;
  for (size_t i = 0; i < line.size();) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    const size_t j = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    if (i > j) words.push_back(line.substr(j, i - j));
  }
  return words;
}

/// Line 1: assimp reads any file that starts with "ply" in any case as PLY, and its header parser
/// is lenient ("ply(" and "element$vertex 1000000000" pass, and then it loops over the count
/// whatever the file holds): such a file must meet this check, which wants the spec's line.
Status CheckPlyMagic(const PlyFile& ply, std::string_view line, PlyHeader& header) {
  const auto lower = [](char c) { return static_cast<char>(c | 0x20); };
  const bool ply_magic =
      line.size() >= 3 && lower(line[0]) == 'p' && lower(line[1]) == 'l' && lower(line[2]) == 'y';
  if (!ply_magic) {
    header.is_ply = false;  // not a PLY: assimp says so in its own words
    return Status::Ok();
  }
  if (line.size() != 3) return ply.Bad(fmt::format("line 1 is {}, not 'ply'", QuoteText(line)));
  return Status::Ok();
}

/// A "property" line: the bytes (binary) or characters (ASCII) it adds to its element at least.
Status AddPlyProperty(const PlyFile& ply, const std::vector<std::string_view>& words,
                      std::string_view line, size_t line_no, PlyHeader& header) {
  if (header.elements.empty()) {
    return ply.Bad(fmt::format("line {}: a property before any element", line_no));
  }
  PlyElement& e = header.elements.back();
  if (words.size() == 5 && words[1] == "list") {
    const size_t count_bytes = PlyTypeBytes(words[2]);
    if (count_bytes == 0 || PlyTypeBytes(words[3]) == 0) {
      return ply.Bad(fmt::format("line {}: unknown type in {}", line_no, QuoteText(line)));
    }
    e.min_bytes += header.binary ? count_bytes : 2;
  } else if (words.size() == 3) {
    const size_t bytes = PlyTypeBytes(words[1]);
    if (bytes == 0) {
      return ply.Bad(fmt::format("line {}: unknown type {}", line_no, QuoteText(words[1])));
    }
    e.min_bytes += header.binary ? bytes : 2;
  } else {
    return ply.Bad(fmt::format("line {}: {}", line_no, QuoteText(line)));
  }
  return Status::Ok();
}

/// One header line after the first: format, element, property, end_header (comments skipped).
Status ReadPlyHeaderLine(const PlyFile& ply, std::string_view line, size_t line_no,
                         PlyHeader& header) {
  const std::vector<std::string_view> words = Words(line);
  if (words.empty() || words[0] == "comment" || words[0] == "obj_info") return Status::Ok();
  if (words[0] == "format") {
    if (words.size() != 3) return ply.Bad(fmt::format("line {}: {}", line_no, QuoteText(line)));
    if (words[1] == "ascii") {
      header.binary = false;
    } else if (words[1] == "binary_little_endian" || words[1] == "binary_big_endian") {
      header.binary = true;
    } else {
      return ply.Bad(fmt::format("line {}: unknown format {}", line_no, QuoteText(words[1])));
    }
  } else if (words[0] == "element") {
    uint64_t count = 0;
    const std::string_view n = words.size() == 3 ? words[2] : std::string_view();
    const auto [ptr, ec] = std::from_chars(n.data(), n.data() + n.size(), count);
    if (n.empty() || ec != std::errc() || ptr != n.data() + n.size()) {
      return ply.Bad(fmt::format("line {}: {} is not 'element <name> <count>' with a whole count",
                                 line_no, QuoteText(line)));
    }
    header.elements.push_back({std::string(words[1]), count, 0, line_no});
  } else if (words[0] == "property") {
    return AddPlyProperty(ply, words, line, line_no, header);
  } else if (words[0] == "end_header") {
    header.ended = true;
  } else {
    return ply.Bad(fmt::format("line {} is {}", line_no, QuoteText(line)));
  }
  return Status::Ok();
}

/// The header's lines up to "end_header"; is_ply false when the file is no PLY at all.
Result<PlyHeader> ParsePlyHeader(const PlyFile& ply, const std::string& head) {
  PlyHeader header;
  size_t line_no = 0;
  while (!header.ended) {
    const size_t end = head.find('\n', header.end);
    if (end == std::string::npos) {
      return ply.Bad(head.size() >= kMaxPlyHeaderBytes
                         ? fmt::format("no 'end_header' in its first {} bytes", kMaxPlyHeaderBytes)
                         : std::string("it ends before 'end_header'"));
    }
    std::string_view line(head.data() + header.end, end - header.end);
    header.end = end + 1;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line_no == 1) {
      AVP_RETURN_IF_ERROR(CheckPlyMagic(ply, line, header));
      if (!header.is_ply) return header;
      continue;
    }
    AVP_RETURN_IF_ERROR(ReadPlyHeaderLine(ply, line, line_no, header));
  }
  return header;
}

/// Each element's count against the limits and against what the body can hold.
Status CheckPlyElementCounts(const PlyFile& ply, const PlyHeader& header, uint64_t file_bytes) {
  const uint64_t body = file_bytes - header.end;
  for (const PlyElement& e : header.elements) {
    const std::string what = fmt::format("{}.file: PLY mesh '{}': element '{}' of {}", ply.context,
                                         ply.file.string(), EscapeText(e.name), e.count);
    if (e.name == "vertex") AVP_RETURN_IF_ERROR(MaxMeshVertices().Check(what, e.count));
    if (e.name == "face") AVP_RETURN_IF_ERROR(MaxMeshFaces().Check(what, e.count));
    // What the rest of the file can hold (elements without properties count as one byte).
    const uint64_t min_bytes = std::max<uint64_t>(e.min_bytes, 1);
    if (e.count > body / min_bytes) {
      return ParseError(fmt::format(
          "{}.file: PLY mesh '{}' declares {} '{}' elements on header line {}, but the {} bytes "
          "after its header hold at most {} of them (at least {} bytes each): truncated or "
          "corrupt",
          ply.context, ply.file.string(), e.count, EscapeText(e.name), e.line, body,
          body / min_bytes, min_bytes));
    }
  }
  return Status::Ok();
}

/// An STL file's first 84 bytes: a binary STL's triangle count is checked (true); an ASCII one
/// ("solid") leaves `in` at its start for the line count (false).
Result<bool> CheckBinaryStl(std::istream& in, const fs::path& file, uint64_t file_bytes,
                            const std::string& context) {
  std::string head(84, '\0');
  in.read(head.data(), 84);
  const auto got = static_cast<size_t>(in.gcount());
  const bool ascii = got >= 5 && head.compare(0, 5, "solid") == 0;
  if (ascii) {
    in.clear();
    in.seekg(0);
    return false;
  }
  if (got < 84) {
    return ParseError(
        fmt::format("{}.file: STL mesh '{}' is truncated ({} bytes, a binary STL "
                    "header needs 84)",
                    context, file.string(), got));
  }
  const uint64_t triangles = uint64_t{static_cast<uint8_t>(head[80])} |
                             (uint64_t{static_cast<uint8_t>(head[81])} << 8) |
                             (uint64_t{static_cast<uint8_t>(head[82])} << 16) |
                             (uint64_t{static_cast<uint8_t>(head[83])} << 24);
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
  return true;
}

struct LineCounts {
  uint64_t vertices = 0;
  uint64_t faces = 0;
};

/// Vertex and face lines in one streaming pass: OBJ "v" and "f" lines, or ASCII STL "facet"
/// lines (three vertices each).
LineCounts CountMeshLines(std::istream& in, bool obj) {
  LineCounts counts;
  std::string chunk(1 << 16, '\0');
  bool line_start = true;
  std::string first;  // the first token of the current line, up to 6 characters
  bool in_first = true;
  const auto end_token = [&] {
    if (obj) {
      if (first == "v") ++counts.vertices;
      if (first == "f") ++counts.faces;
    } else if (first == "facet") {
      ++counts.faces;
      counts.vertices += 3;
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
  return counts;
}

}  // namespace

Status CheckPlyHeader(const fs::path& file, uint64_t file_bytes, const std::string& context) {
  const PlyFile ply{file, context};
  AVP_ASSIGN_OR_RETURN(const std::string head, ReadPlyHead(ply, file_bytes));
  AVP_ASSIGN_OR_RETURN(const PlyHeader header, ParsePlyHeader(ply, head));
  if (!header.is_ply) return Status::Ok();
  return CheckPlyElementCounts(ply, header, file_bytes);
}

Status CheckObjOrStlCounts(const fs::path& file, uint64_t file_bytes, const std::string& ext,
                           const std::string& context) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return IoError(fmt::format("{}.file: cannot read mesh '{}'", context, file.string()));
  if (ext == ".stl") {
    AVP_ASSIGN_OR_RETURN(const bool binary, CheckBinaryStl(in, file, file_bytes, context));
    if (binary) return Status::Ok();
  }
  const LineCounts counts = CountMeshLines(in, ext == ".obj");
  AVP_RETURN_IF_ERROR(MaxMeshVertices().Check(
      fmt::format("{}.file: vertex lines of mesh '{}'", context, file.string()), counts.vertices));
  AVP_RETURN_IF_ERROR(MaxMeshFaces().Check(
      fmt::format("{}.file: face lines of mesh '{}'", context, file.string()), counts.faces));
  return Status::Ok();
}

}  // namespace avp::sim::internal

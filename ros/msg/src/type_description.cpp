// ros2msg schema text (DefinitionOf) and the REP-2011 type hash (TypeHashOf), both derived from the
// .msg texts of MessageTraits.

#include <algorithm>
#include <cctype>
#include <charconv>
#include <map>
#include <set>

#include <fmt/format.h>
#include <openssl/evp.h>

#include <avp/ros/msg/messages.h>

namespace avp::ros::msg {
namespace {

// type_description_interfaces/msg/FieldType.msg
constexpr uint8_t kNestedType = 1;
constexpr uint8_t kBoundedString = 21;
constexpr uint8_t kArrayOffset = 48;
constexpr uint8_t kBoundedSequenceOffset = 96;
constexpr uint8_t kUnboundedSequenceOffset = 144;

/// .msg primitive names and their FieldType ids. `char` is uint8 and `byte` is octet once rosidl
/// converts .msg to IDL, and the hash is computed from the IDL.
const std::map<std::string_view, uint8_t>& PrimitiveTypeIds() {
  static const std::map<std::string_view, uint8_t> kIds = {
      {"int8", 2},     {"uint8", 3},  {"char", 3},  {"int16", 4},   {"uint16", 5},
      {"int32", 6},    {"uint32", 7}, {"int64", 8}, {"uint64", 9},  {"float32", 10},
      {"float64", 11}, {"bool", 15},  {"byte", 16}, {"string", 17}, {"wstring", 18},
  };
  return kIds;
}

struct FieldDescription {
  std::string name;
  int type_id = 0;
  uint64_t capacity = 0;
  uint64_t string_capacity = 0;
  std::string nested_type_name;  // "pkg/msg/Type"
};

struct TypeDescription {
  std::string type_name;
  std::vector<FieldDescription> fields;
};

const MessageInfo* FindMessage(std::string_view ros_name) {
  for (const MessageInfo& info : AllMessages()) {
    if (info.ros_name == ros_name) return &info;
  }
  return nullptr;
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

Result<uint64_t> ParseCount(std::string_view s, std::string_view line) {
  uint64_t n = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), n);
  if (ec != std::errc() || end != s.data() + s.size()) {
    return InternalError(fmt::format("bad size '{}' in .msg line '{}'", s, line));
  }
  return n;
}

/// The fields of a .msg text (constants and comments skipped). `package` resolves unqualified
/// nested type names.
Result<std::vector<FieldDescription>> ParseMsg(std::string_view text, std::string_view package) {
  std::vector<FieldDescription> fields;
  while (!text.empty()) {
    const size_t eol = text.find('\n');
    std::string_view line = text.substr(0, eol);
    text.remove_prefix(eol == std::string_view::npos ? text.size() : eol + 1);
    if (const size_t hash = line.find('#'); hash != std::string_view::npos) {
      line = line.substr(0, hash);
    }
    line = Trim(line);
    if (line.empty()) continue;
    const size_t space = line.find_first_of(" \t");
    if (space == std::string_view::npos) {
      return InternalError(fmt::format(".msg line '{}' has no field name", line));
    }
    std::string_view type = line.substr(0, space);
    const std::string_view rest = Trim(line.substr(space));
    if (rest.find('=') != std::string_view::npos) continue;  // a constant
    const std::string_view name = rest.substr(0, rest.find_first_of(" \t"));

    FieldDescription field;
    field.name = std::string(name);
    int offset = 0;
    if (const size_t bracket = type.find('['); bracket != std::string_view::npos) {
      std::string_view inside = type.substr(bracket + 1);
      if (inside.empty() || inside.back() != ']') {
        return InternalError(fmt::format("bad array type in .msg line '{}'", line));
      }
      inside.remove_suffix(1);
      type = type.substr(0, bracket);
      if (inside.empty()) {
        offset = kUnboundedSequenceOffset;
      } else if (inside.starts_with("<=")) {
        offset = kBoundedSequenceOffset;
        AVP_ASSIGN_OR_RETURN(field.capacity, ParseCount(inside.substr(2), line));
      } else {
        offset = kArrayOffset;
        AVP_ASSIGN_OR_RETURN(field.capacity, ParseCount(inside, line));
      }
    }
    if (type.starts_with("string<=")) {
      field.type_id = kBoundedString;
      AVP_ASSIGN_OR_RETURN(field.string_capacity, ParseCount(type.substr(8), line));
    } else if (const auto it = PrimitiveTypeIds().find(type); it != PrimitiveTypeIds().end()) {
      field.type_id = it->second;
    } else {
      field.type_id = kNestedType;
      const size_t slash = type.find('/');
      field.nested_type_name =
          slash == std::string_view::npos
              ? fmt::format("{}/msg/{}", package, type)
              : fmt::format("{}/msg/{}", type.substr(0, slash), type.substr(slash + 1));
    }
    field.type_id += offset;
    fields.push_back(std::move(field));
  }
  return fields;
}

std::string_view PackageOf(std::string_view ros_name) {
  return ros_name.substr(0, ros_name.find('/'));
}

/// "pkg/msg/Type" -> "pkg/Type", as the MSG: lines of a ros2msg schema spell it.
std::string ShortName(std::string_view ros_name) {
  const size_t first = ros_name.find('/');
  const size_t last = ros_name.rfind('/');
  return fmt::format("{}/{}", ros_name.substr(0, first), ros_name.substr(last + 1));
}

Result<TypeDescription> Describe(std::string_view ros_name, RosDistro distro) {
  const MessageInfo* info = FindMessage(ros_name);
  if (info == nullptr) {
    return NotFoundError(fmt::format("no ROS message type '{}' in avp::ros::msg", ros_name));
  }
  TypeDescription description;
  description.type_name = std::string(ros_name);
  AVP_ASSIGN_OR_RETURN(description.fields,
                       ParseMsg(distro == RosDistro::kHumble ? info->msg_humble : info->msg_jazzy,
                                PackageOf(ros_name)));
  return description;
}

/// The nested types `ros_name` references, transitively, each once, depth first in field order.
Status CollectReferences(std::string_view ros_name, RosDistro distro,
                         std::vector<TypeDescription>& out, std::set<std::string>& seen) {
  AVP_ASSIGN_OR_RETURN(const TypeDescription description, Describe(ros_name, distro));
  for (const FieldDescription& field : description.fields) {
    if (field.nested_type_name.empty() || !seen.insert(field.nested_type_name).second) continue;
    AVP_ASSIGN_OR_RETURN(TypeDescription nested, Describe(field.nested_type_name, distro));
    out.push_back(std::move(nested));
    AVP_RETURN_IF_ERROR(CollectReferences(field.nested_type_name, distro, out, seen));
  }
  return Status::Ok();
}

/// Python's json.dumps(..., separators=(', ', ': ')) of an IndividualTypeDescription without
/// default values. Names are ROS identifiers: no escaping needed.
std::string Json(const TypeDescription& t) {
  std::string out = fmt::format("{{\"type_name\": \"{}\", \"fields\": [", t.type_name);
  for (size_t i = 0; i < t.fields.size(); ++i) {
    const FieldDescription& f = t.fields[i];
    out += fmt::format(
        "{}{{\"name\": \"{}\", \"type\": {{\"type_id\": {}, \"capacity\": {}, "
        "\"string_capacity\": {}, \"nested_type_name\": \"{}\"}}}}",
        i == 0 ? "" : ", ", f.name, f.type_id, f.capacity, f.string_capacity, f.nested_type_name);
  }
  return out + "]}";
}

}  // namespace

Result<std::string> DefinitionOf(std::string_view ros_name, RosDistro distro) {
  const MessageInfo* info = FindMessage(ros_name);
  if (info == nullptr) {
    return NotFoundError(fmt::format("no ROS message type '{}' in avp::ros::msg", ros_name));
  }
  std::vector<TypeDescription> references;
  std::set<std::string> seen;
  AVP_RETURN_IF_ERROR(CollectReferences(ros_name, distro, references, seen));
  std::string out(distro == RosDistro::kHumble ? info->msg_humble : info->msg_jazzy);
  for (const TypeDescription& ref : references) {
    const MessageInfo* ref_info = FindMessage(ref.type_name);
    out += std::string(80, '=');
    out += fmt::format("\nMSG: {}\n", ShortName(ref.type_name));
    out += distro == RosDistro::kHumble ? ref_info->msg_humble : ref_info->msg_jazzy;
  }
  return out;
}

Result<std::string> TypeDescriptionJsonOf(std::string_view ros_name) {
  AVP_ASSIGN_OR_RETURN(const TypeDescription top, Describe(ros_name, RosDistro::kJazzy));
  std::vector<TypeDescription> references;
  std::set<std::string> seen;
  AVP_RETURN_IF_ERROR(CollectReferences(ros_name, RosDistro::kJazzy, references, seen));
  std::sort(
      references.begin(), references.end(),
      [](const TypeDescription& a, const TypeDescription& b) { return a.type_name < b.type_name; });
  std::string out = "{\"type_description\": " + Json(top) + ", \"referenced_type_descriptions\": [";
  for (size_t i = 0; i < references.size(); ++i) {
    if (i > 0) out += ", ";
    out += Json(references[i]);
  }
  return out + "]}";
}

Result<std::string> TypeHashOf(std::string_view ros_name) {
  AVP_ASSIGN_OR_RETURN(const std::string json, TypeDescriptionJsonOf(ros_name));
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int digest_bytes = 0;
  if (EVP_Digest(json.data(), json.size(), digest, &digest_bytes, EVP_sha256(), nullptr) != 1 ||
      digest_bytes != 32) {
    return InternalError(fmt::format("SHA-256 of the type description of {} failed", ros_name));
  }
  std::string out = "RIHS01_";
  for (unsigned int i = 0; i < digest_bytes; ++i) out += fmt::format("{:02x}", digest[i]);
  return out;
}

}  // namespace avp::ros::msg

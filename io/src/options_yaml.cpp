#include <algorithm>
#include <charconv>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <system_error>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/options_yaml.h>

namespace avp::io {

namespace {

/// Sets `value` at the dotted `key` below `map`, creating the maps on the way. (A YAML::Node
/// variable is never re-assigned: yaml-cpp's Node::operator= writes through to the node it refers
/// to.)
void Insert(YAML::Node map, std::string_view key, const YAML::Node& value) {
  const size_t dot = key.find('.');
  if (dot == std::string_view::npos) {
    map[std::string(key)] = value;
    return;
  }
  const std::string head(key.substr(0, dot));
  if (!map[head]) map[head] = YAML::Node(YAML::NodeType::Map);
  Insert(map[head], key.substr(dot + 1), value);
}

YAML::Node Scalar(const std::string& value, OptionKind kind) {
  if (kind == OptionKind::kRealList || kind == OptionKind::kTextList) {
    YAML::Node list(YAML::NodeType::Sequence);
    for (const std::string& item : options_internal::SplitList(value)) list.push_back(item);
    list.SetStyle(YAML::EmitterStyle::Flow);
    return list;
  }
  return YAML::Node(value);
}

Status Flatten(const YAML::Node& node, const std::string& prefix, std::string_view context,
               OptionValues& out) {
  for (const auto& kv : node) {
    if (!kv.first.IsScalar()) {
      return InvalidArgumentError(
          fmt::format("{}: a key below {} is not a name", context,
                      prefix.empty() ? std::string("the top level") : QuoteText(prefix)));
    }
    const std::string key = prefix + kv.first.Scalar();
    const YAML::Node& v = kv.second;
    if (v.IsMap()) {
      AVP_RETURN_IF_ERROR(Flatten(v, key + ".", context, out));
    } else if (v.IsSequence()) {
      std::vector<std::string> items;
      for (const YAML::Node& item : v) {
        if (!item.IsScalar()) {
          return InvalidArgumentError(
              fmt::format("{}: {} must be a list of numbers or names", context, QuoteText(key)));
        }
        items.push_back(item.Scalar());
      }
      out.emplace_back(key, options_internal::Join(items, ","));
    } else if (v.IsNull()) {
      out.emplace_back(key, "");
    } else {
      out.emplace_back(key, v.Scalar());
    }
  }
  return Status::Ok();
}

}  // namespace

YAML::Node OptionsToYaml(const OptionValues& values, const std::vector<OptionInfo>& info) {
  std::map<std::string, OptionKind> kinds;
  for (const OptionInfo& i : info) kinds[i.key] = i.kind;
  YAML::Node root(YAML::NodeType::Map);
  for (const auto& [key, value] : values) {
    const auto kind = kinds.find(key);
    Insert(root, key, Scalar(value, kind == kinds.end() ? OptionKind::kText : kind->second));
  }
  return root;
}

namespace {

nlohmann::json JsonValue(const std::string& value, OptionKind kind) {
  switch (kind) {
    case OptionKind::kReal:
    case OptionKind::kInteger: {
      const std::optional<double> v = options_internal::ParseReal(value);
      if (!v) return value;
      if (kind == OptionKind::kInteger) {
        // Whole numbers only, exactly (no wrap-around, no partial parse); anything else stays text.
        const char* first = value.data();
        const char* last = value.data() + value.size();
        if (value.front() == '-') {
          int64_t i = 0;
          const auto [end, ec] = std::from_chars(first, last, i);
          return ec == std::errc() && end == last ? nlohmann::json(i) : nlohmann::json(value);
        }
        uint64_t u = 0;
        const auto [end, ec] = std::from_chars(first, last, u);
        return ec == std::errc() && end == last ? nlohmann::json(u) : nlohmann::json(value);
      }
      return *v;
    }
    case OptionKind::kFlag:
      return value == "true";
    case OptionKind::kRealList: {
      nlohmann::json list = nlohmann::json::array();
      for (const std::string& item : options_internal::SplitList(value)) {
        list.push_back(options_internal::ParseReal(item).value_or(0.0));
      }
      return list;
    }
    case OptionKind::kTextList: {
      nlohmann::json list = nlohmann::json::array();
      for (const std::string& item : options_internal::SplitList(value)) list.push_back(item);
      return list;
    }
    case OptionKind::kText:
    case OptionKind::kChoice:
      break;
  }
  return value;
}

}  // namespace

nlohmann::json OptionsToJson(const OptionValues& values, const std::vector<OptionInfo>& info) {
  std::map<std::string, OptionKind> kinds;
  for (const OptionInfo& i : info) kinds[i.key] = i.kind;
  nlohmann::json root = nlohmann::json::object();
  for (const auto& [key, value] : values) {
    const auto kind = kinds.find(key);
    std::string path = "/" + key;
    std::replace(path.begin(), path.end(), '.', '/');
    root[nlohmann::json::json_pointer(path)] =
        JsonValue(value, kind == kinds.end() ? OptionKind::kText : kind->second);
  }
  return root;
}

Result<OptionValues> FlattenYaml(const YAML::Node& node, std::string_view context) {
  OptionValues out;
  if (!node.IsDefined() || node.IsNull()) return out;
  if (!node.IsMap()) {
    return InvalidArgumentError(fmt::format("{}: expected a map of option: value", context));
  }
  AVP_RETURN_IF_ERROR(Flatten(node, "", context, out));
  return out;
}

Status ReadOptionsYaml(AnyOptions& options, const YAML::Node& node, std::string_view context,
                       std::string_view component) {
  AVP_ASSIGN_OR_RETURN(const OptionValues values, FlattenYaml(node, context));
  for (const auto& [key, value] : values) {
    if (Status s = options.Set(key, value, component); !s.ok()) return s.WithContext(context);
  }
  return Status::Ok();
}

std::string YamlText(const YAML::Node& node) {
  YAML::Emitter out;
  out << node;
  return std::string(out.c_str()) + "\n";
}

}  // namespace avp::io

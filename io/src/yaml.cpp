#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/io/yaml.h>

namespace avp::io {

namespace {

std::string Where(std::string_view context, std::string_view key) {
  return fmt::format("{}: '{}'", context, key);
}

std::string Mark(const YAML::Node& node) {
  const YAML::Mark m = node.Mark();
  if (m.line < 0) return "";
  return fmt::format(" (line {}, column {})", m.line + 1, m.column + 1);
}

std::string Text(const YAML::Node& node) {
  if (node.IsScalar()) return node.Scalar();
  YAML::Emitter out;
  out << YAML::Flow << node;
  return out.c_str();
}

// node[key] without yaml-cpp's exceptions, which operator[] throws for an invalid node (a const
// lookup of a missing section) and for a scalar. A missing or null section gives an undefined
// node (reported as "missing"); a scalar or sequence is an error that shows it.
Result<YAML::Node> Child(const YAML::Node& node, std::string_view key, std::string_view context) {
  if (!node.IsDefined() || node.IsNull()) return YAML::Node(YAML::NodeType::Undefined);
  if (!node.IsMap()) {
    return InvalidArgumentError(fmt::format("{}: expected a map with key '{}', got '{}'{}", context,
                                            key, Text(node), Mark(node)));
  }
  return node[std::string(key)];
}

}  // namespace

Result<YAML::Node> LoadYamlFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return NotFoundError(fmt::format("YAML file '{}' does not exist", path.string()));
  }
  if (std::filesystem::is_directory(path, ec)) {
    return InvalidArgumentError(fmt::format("'{}' is a directory, not a YAML file", path.string()));
  }
  try {
    return YAML::LoadFile(path.string());
  } catch (const YAML::ParserException& e) {
    return ParseError(fmt::format("malformed YAML in '{}' at line {}, column {}: {}", path.string(),
                                  e.mark.line + 1, e.mark.column + 1, e.msg));
  } catch (const YAML::Exception& e) {
    return IoError(fmt::format("cannot read YAML file '{}': {}", path.string(), e.what()));
  }
}

Status RejectUnknownKeys(const YAML::Node& node, std::initializer_list<std::string_view> allowed,
                         std::string_view context) {
  if (!node.IsDefined() || node.IsNull()) return Status::Ok();
  if (!node.IsMap()) {
    return InvalidArgumentError(
        fmt::format("{}: expected a map of keys, got '{}'{}", context, Text(node), Mark(node)));
  }
  std::vector<std::string> unknown;
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    if (std::find(allowed.begin(), allowed.end(), key) == allowed.end()) unknown.push_back(key);
  }
  if (unknown.empty()) return Status::Ok();
  std::vector<std::string> sorted(allowed.begin(), allowed.end());
  std::sort(sorted.begin(), sorted.end());
  std::vector<std::string> quoted;
  for (const std::string& k : unknown) quoted.push_back("'" + k + "'");
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
    return InvalidArgumentError(fmt::format("{} must be a finite number, got '{}'{}",
                                            Where(context, key), Text(v), Mark(v)));
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
        fmt::format("{} must be an integer, got '{}'{}", Where(context, key), Text(v), Mark(v)));
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
        fmt::format("{} must be a string, got '{}'{}", Where(context, key), Text(v), Mark(v)));
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
        fmt::format("{} must be true or false, got '{}'{}", Where(context, key), Text(v), Mark(v)));
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
    return InvalidArgumentError(fmt::format("{} must be a list of numbers, got '{}'{}",
                                            Where(context, key), Text(v), Mark(v)));
  }
  std::vector<double> out;
  for (size_t i = 0; i < v.size(); ++i) {
    double x = 0.0;
    if (!v[i].IsScalar() || !YAML::convert<double>::decode(v[i], x) || !std::isfinite(x)) {
      return InvalidArgumentError(fmt::format("{}[{}] must be a finite number, got '{}'{}",
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

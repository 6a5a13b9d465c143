#pragma once

#include <filesystem>
#include <initializer_list>
#include <string>
#include <string_view>

#include <Eigen/Core>
#include <yaml-cpp/yaml.h>

#include <avp/core/status.h>
#include <avp/core/transform.h>

namespace avp::io {

/// Loads a YAML file; NotFound if missing, ParseError with file, line and column if malformed.
Result<YAML::Node> LoadYamlFile(const std::filesystem::path& path);

/// InvalidArgument naming `context` and every key of the map `node` not in `allowed`
/// ("scene.yaml: objects[2]: unknown key 'colour' (allowed: class, color, file, pose)").
/// Also fails if `node` is defined but not a map.
Status RejectUnknownKeys(const YAML::Node& node, std::initializer_list<std::string_view> allowed,
                         std::string_view context);

/// Typed readers: the value at node[key], or an error naming `context`, the key and the bad text.
Result<double> ReadDouble(const YAML::Node& node, std::string_view key, std::string_view context);
Result<int64_t> ReadInt(const YAML::Node& node, std::string_view key, std::string_view context);
Result<std::string> ReadString(const YAML::Node& node, std::string_view key,
                               std::string_view context);
Result<bool> ReadBool(const YAML::Node& node, std::string_view key, std::string_view context);
/// A sequence of exactly N finite numbers.
Result<Eigen::VectorXd> ReadVector(const YAML::Node& node, std::string_view key, int size,
                                   std::string_view context);
/// A sequence of any length of finite numbers.
Result<std::vector<double>> ReadDoubles(const YAML::Node& node, std::string_view key,
                                        std::string_view context);
/// A pose as {xyz: [x, y, z], rpy: [r, p, y]} (radians) or {xyz, rpy_deg}; both keys optional.
Result<RigidTransform> ReadPose(const YAML::Node& node, std::string_view key,
                                std::string_view context);

}  // namespace avp::io

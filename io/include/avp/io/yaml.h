#pragma once

#include <filesystem>
#include <initializer_list>
#include <string>
#include <string_view>

#include <Eigen/Core>
#include <yaml-cpp/yaml.h>

#include <avp/core/limits.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>

namespace avp::io {

/// max_yaml_bytes: the size of one YAML file or text, 1 MiB by default (yaml-cpp holds a few
/// hundred bytes per node, so a megabyte of YAML already takes about 250 MB).
const Limit& MaxYamlBytes();
/// max_yaml_depth: how deeply collections may nest in one YAML document, 64 by default (yaml-cpp
/// parses recursively).
const Limit& MaxYamlDepth();

/// OK when no collection of `text` nests deeper than max_yaml_depth (an upper estimate from the
/// indentation, the "- " indicators and the brackets outside quotes, comments and block scalars;
/// linear time, no parsing); ResourceExhausted naming the line and the limit otherwise. `name`
/// names the document in the message ("'scene.yaml'").
Status CheckYamlDepth(std::string_view text, std::string_view name);

/// Parses YAML text after checking max_yaml_bytes and max_yaml_depth. ParseError with `name`,
/// line and column (yaml-cpp's message escaped) when malformed; safe on any bytes.
Result<YAML::Node> ParseYaml(std::string_view text, std::string_view name);

/// Loads a YAML file: NotFound if missing, InvalidArgument for a folder, ResourceExhausted over
/// max_yaml_bytes or max_yaml_depth (checked before parsing), ParseError with file, line and
/// column if malformed.
Result<YAML::Node> LoadYamlFile(const std::filesystem::path& path);

/// InvalidArgument naming `context` and every key of the map `node` not in `allowed`
/// ("scene.yaml: objects[2]: unknown key 'colour' (allowed: class, color, file, pose)").
/// Also fails if `node` is defined but not a map.
Status RejectUnknownKeys(const YAML::Node& node, std::initializer_list<std::string_view> allowed,
                         std::string_view context);

/// Typed readers: the value at node[key], or an error naming `context`, the key and the bad text
/// (escaped and shortened, QuoteText). Numbers are parsed strictly: no wrap-around (an integer
/// outside int64 is an error), no trailing text, finite reals only.
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

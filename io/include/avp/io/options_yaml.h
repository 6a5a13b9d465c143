#pragma once

// Options tables (core/options.h) <-> YAML: a table's keys become nested maps ("candidates.radii_m"
// is `candidates: {radii_m: [...]}`), list fields become sequences, everything else a scalar.

#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include <avp/core/options.h>
#include <avp/core/status.h>

namespace avp::io {

/// The values as a nested YAML map, in table order; `info` (the same table's OptionTable::Info)
/// tells which values are lists. Reals, integers and flags are plain scalars.
YAML::Node OptionsToYaml(const OptionValues& values, const std::vector<OptionInfo>& info);

/// The same values as nested JSON (run records): reals and integers as numbers, flags as
/// booleans, lists as arrays, the rest as strings.
nlohmann::json OptionsToJson(const OptionValues& values, const std::vector<OptionInfo>& info);

/// A YAML map flattened into dotted KEY=VALUE text pairs in document order: nested maps give
/// "a.b" keys, sequences of scalars become "x,y,z", null becomes "". InvalidArgument naming
/// `context` and the key for anything else (a sequence of maps, a non-map root).
Result<OptionValues> FlattenYaml(const YAML::Node& node, std::string_view context);

/// Sets every field `node` names (FlattenYaml, then OptionTable::Set); fields it does not name
/// keep their value. Errors name `context`: an unknown key (with the known ones) or a bad value.
template <typename T>
Status ReadOptionsYaml(const OptionTable<T>& table, T& options, const YAML::Node& node,
                       std::string_view context) {
  AVP_ASSIGN_OR_RETURN(const OptionValues values, FlattenYaml(node, context));
  for (const auto& [key, value] : values) {
    if (Status s = table.Set(options, key, value); !s.ok()) return s.WithContext(context);
  }
  return Status::Ok();
}

/// The same for a type-erased options value (a registered component's).
Status ReadOptionsYaml(AnyOptions& options, const YAML::Node& node, std::string_view context,
                       std::string_view component);

/// The YAML text of a node in block style, ending with a newline.
std::string YamlText(const YAML::Node& node);

}  // namespace avp::io

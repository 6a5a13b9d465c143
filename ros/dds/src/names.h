#pragma once

#include <string>
#include <string_view>

#include <avp/core/status.h>

namespace avp::ros::dds {

/// [A-Za-z_][A-Za-z0-9_]*, at most 255 characters.
Status ValidateNodeName(std::string_view name);
/// "/" or "/a/b" (a relative namespace gets a leading '/'); an error naming a bad one.
Result<std::string> NormalizeNamespace(std::string_view ns);

}  // namespace avp::ros::dds

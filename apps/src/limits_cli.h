// The command line's side of the process-wide limits (core/limits.h): `avp limits`, the global
// `--limit NAME=VALUE` option and the AVP_LIMITS environment variable (internal to apps/).
#pragma once

#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include <avp/core/limits.h>
#include <avp/core/status.h>

#include "commands.h"

namespace avp::apps {

/// Registers every process-wide limit the program has (each registers when its accessor first
/// runs), so that --limit, AVP_LIMITS and `avp limits` know them all.
void RegisterKnownLimits();

/// AVP_LIMITS="NAME=VALUE,NAME=VALUE" applied with SetLimits; the error names the variable and
/// the bad item. OK when it is not set.
Status ApplyLimitsFromEnvironment();

/// The repeatable global `--limit NAME=VALUE` of `app`: each applied (SetLimits) as it is parsed,
/// before any command runs; a bad item is a command-line error naming it.
void AddLimitOption(CLI::App& app);

/// `avp limits`'s table: limit, value, default, unit, what it bounds.
std::string LimitsTable(const std::vector<LimitInfo>& limits);

}  // namespace avp::apps

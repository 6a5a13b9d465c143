#pragma once

#include <string>

namespace avp::report {

/// The build's identity for run records: the git revision of the source tree (with "-dirty" when
/// it had changes), or "unknown" when the source tree is not a git checkout.
std::string SourceRevision();

/// "hostname (OS release, N hardware threads)".
std::string HostDescription();

}  // namespace avp::report

#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/mapping/sensor_model.h>

namespace avp::mapping {

Status SensorModel::Validate() const {
  std::vector<std::string> errors;
  const auto check_prob = [&](const char* name, double p) {
    if (!std::isfinite(p) || p <= 0.0 || p >= 1.0) {
      errors.push_back(fmt::format("{} ({}) must be in (0, 1)", name, p));
    }
  };
  check_prob("hit", hit);
  check_prob("miss", miss);
  check_prob("clamp_min", clamp_min);
  check_prob("clamp_max", clamp_max);
  check_prob("occupied_threshold", occupied_threshold);
  if (errors.empty()) {
    if (!(hit > occupied_threshold)) {
      errors.push_back(
          fmt::format("hit ({}) must be > occupied_threshold ({})", hit, occupied_threshold));
    }
    if (!(miss < occupied_threshold)) {
      errors.push_back(
          fmt::format("miss ({}) must be < occupied_threshold ({})", miss, occupied_threshold));
    }
    if (!(clamp_min < occupied_threshold && occupied_threshold < clamp_max)) {
      errors.push_back(
          fmt::format("occupied_threshold ({}) must lie between clamp_min ({}) and "
                      "clamp_max ({})",
                      occupied_threshold, clamp_min, clamp_max));
    }
  }
  if (errors.empty()) return Status::Ok();
  return InvalidArgumentError("invalid sensor model: " +
                              fmt::format("{}", fmt::join(errors, "; ")));
}

}  // namespace avp::mapping

#pragma once

#include <cmath>

#include <avp/core/options.h>
#include <avp/core/status.h>

namespace avp::mapping {

/// log(p / (1 - p)) rounded to float, exactly as OctoMap's `octomap::logodds`.
inline float LogOdds(double probability) {
  return static_cast<float>(std::log(probability / (1.0 - probability)));
}
/// Inverse of LogOdds.
inline double Probability(double log_odds) { return 1.0 - 1.0 / (1.0 + std::exp(log_odds)); }

/// OctoMap's occupancy sensor model: a return in a voxel adds log-odds(hit), a ray passing through
/// adds log-odds(miss), the result is clamped to [log-odds(clamp_min), log-odds(clamp_max)], and a
/// voxel is occupied when its log-odds is >= log-odds(occupied_threshold). The defaults are the
/// reference system's (and the benchmark protocol's) values.
struct SensorModel {
  double hit = 0.7;
  double miss = 0.4;
  double clamp_min = 0.12;
  double clamp_max = 0.97;
  double occupied_threshold = 0.5;

  /// 0 < clamp_min <= miss < occupied_threshold < hit <= clamp_max < 1, all finite; the error
  /// names every bad value.
  Status Validate() const;

  float hit_log_odds() const { return LogOdds(hit); }
  float miss_log_odds() const { return LogOdds(miss); }
  float clamp_min_log_odds() const { return LogOdds(clamp_min); }
  float clamp_max_log_odds() const { return LogOdds(clamp_max); }
  float occupied_log_odds() const { return LogOdds(occupied_threshold); }

  bool operator==(const SensorModel&) const = default;
};

/// The fields of SensorModel (core/options.h): hit, miss, clamp_min, clamp_max,
/// occupied_threshold, and the ordering rule between them.
const OptionTable<SensorModel>& SensorModelTable();

}  // namespace avp::mapping

#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/mapping/sensor_model.h>

namespace avp::mapping {

const OptionTable<SensorModel>& SensorModelTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<SensorModel>("sensor model option");
    const ValueRange p = ValueRange::Open(0, 1);
    t->Real("hit", &SensorModel::hit, "", p, "occupancy probability of a return's voxel");
    t->Real("miss", &SensorModel::miss, "", p, "occupancy probability of a voxel a ray crosses");
    t->Real("clamp_min", &SensorModel::clamp_min, "", p, "lower clamp of the probability");
    t->Real("clamp_max", &SensorModel::clamp_max, "", p, "upper clamp of the probability");
    t->Real("occupied_threshold", &SensorModel::occupied_threshold, "", p,
            "a voxel at or above it is occupied");
    // 0 < clamp_min <= miss < occupied_threshold < hit <= clamp_max < 1, checked once every
    // probability is valid.
    t->AddRule([p](const SensorModel& m, std::vector<std::string>& errors) {
      for (double v : {m.hit, m.miss, m.clamp_min, m.clamp_max, m.occupied_threshold}) {
        if (!std::isfinite(v) || !p.Contains(v)) return;
      }
      if (!(m.hit > m.occupied_threshold)) {
        errors.push_back(
            fmt::format("hit ({}) must be > occupied_threshold ({})", m.hit, m.occupied_threshold));
      }
      if (!(m.miss < m.occupied_threshold)) {
        errors.push_back(fmt::format("miss ({}) must be < occupied_threshold ({})", m.miss,
                                     m.occupied_threshold));
      }
      if (!(m.clamp_min < m.occupied_threshold && m.occupied_threshold < m.clamp_max)) {
        errors.push_back(
            fmt::format("occupied_threshold ({}) must lie between clamp_min ({}) and "
                        "clamp_max ({})",
                        m.occupied_threshold, m.clamp_min, m.clamp_max));
      }
    });
    return t;
  }();
  return *table;
}

Status SensorModel::Validate() const { return SensorModelTable().Validate(*this); }

}  // namespace avp::mapping
